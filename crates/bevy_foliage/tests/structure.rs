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
    "src/forest/mixed.rs",
    "src/impostor/atlas.rs",
    "src/impostor/cloud.rs",
    "src/impostor/format.rs",
    "src/impostor/texture.rs",
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

/// `text` with every `#[cfg(test)]` item (up to its matching closing brace) blanked out, line
/// breaks kept so line numbers still match.
fn without_test_modules(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find("#[cfg(test)]") {
        out.push_str(&rest[..at]);
        let item = &rest[at..];
        let Some(open) = item.find('{') else {
            rest = "";
            break;
        };
        let mut depth = 0usize;
        let mut end = item.len();
        for (i, c) in item.char_indices().skip_while(|(i, _)| *i < open) {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = i + 1;
                        break;
                    }
                }
                _ => {}
            }
        }
        out.extend(item[..end].chars().filter(|&c| c == '\n'));
        rest = &item[end..];
    }
    out.push_str(rest);
    out
}

#[test]
fn test_modules_are_skipped_and_code_after_them_is_not() {
    let text = "a\n#[cfg(test)]\nmod tests {\n  fn f() { Mesh3d }\n}\nHandle<X>\n";
    let code = without_test_modules(text);
    assert!(!code.contains("Mesh3d"));
    assert_eq!(code.lines().nth(5), Some("Handle<X>"), "line numbers kept");
}

#[test]
fn algorithm_modules_use_no_render_types() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut found = Vec::new();
    for file in PURE {
        let text = std::fs::read_to_string(root.join(file))
            .unwrap_or_else(|e| panic!("{file}: {e} (update the list of algorithm modules)"));
        // Tests may build whatever they like.
        let code = without_test_modules(&text);
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
