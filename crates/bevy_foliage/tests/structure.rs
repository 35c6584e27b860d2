//! The crate is split by role: the algorithm modules are plain Rust that reads like the papers
//! and tests without a renderer. This test keeps them that way: none of them may use a render
//! type (meshes, images, GPU buffers, materials) or an ECS system parameter.

const PURE: &[&str] = &[
    "src/distance.rs",
    "src/rng.rs",
    "src/corpus.rs",
    "src/pruning/appearance.rs",
    "src/pruning/bake.rs",
    "src/pruning/cells.rs",
    "src/pruning/extract.rs",
    "src/pruning/format.rs",
    "src/pruning/gltf.rs",
    "src/pruning/leaves.rs",
    "src/pruning/mask.rs",
    "src/pruning/procedural.rs",
    "src/pruning/selection.rs",
    "src/pruning/visibility.rs",
    "src/forest/cache.rs",
    "src/forest/feedback.rs",
    "src/forest/hlod.rs",
    "src/forest/lod.rs",
    "src/forest/manager.rs",
];

const RENDER: &[&str] = &[
    "bevy::render",
    "bevy::pbr",
    "bevy::mesh",
    "bevy::image",
    "bevy::shader",
    "bevy::camera",
    "RenderAssetUsages",
    "ShaderBuffer",
    "Handle<",
    "Mesh3d",
    "Commands",
    "Query<",
    "ResMut<",
    "bevy::prelude::*",
];

#[test]
fn algorithm_modules_use_no_render_types() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut found = Vec::new();
    for file in PURE {
        let text = std::fs::read_to_string(root.join(file))
            .unwrap_or_else(|e| panic!("{file}: {e} (update the list of algorithm modules)"));
        // Tests may build whatever they like.
        let code = text.split("#[cfg(test)]").next().unwrap();
        for (n, line) in code.lines().enumerate() {
            let line = line.trim_start();
            if line.starts_with("//") {
                continue;
            }
            for pattern in RENDER {
                if line.contains(pattern) {
                    found.push(format!("{file}:{}: {pattern}", n + 1));
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "algorithm modules reach for render or ECS types:\n{}",
        found.join("\n")
    );
}
