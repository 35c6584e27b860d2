//! The foliage loaders fuzzed with seeded mutations (`bevy_nature_harness::fuzz`): the `.foliage`
//! decoder (seeds: bakes of two procedural trees), the billboard-cloud and grass-slice cache
//! decoders (their length and checksum made right after each mutation, so the damage reaches
//! the parsers), and glTF leaf extraction (seeds: a small generated tree with bark,
//! alpha-masked leaf cards, an embedded PNG texture and a node hierarchy, as JSON with an
//! embedded buffer and as binary glTF). Every input must give a value or an error — never a
//! panic or a hang — and what is accepted must be usable: a decoded file re-encodes to the same
//! content; an extracted tree's leaves, masks and bark are read, and its leaves bake.
//!
//! More cases: `NATURE_FUZZ_CASES=100000 cargo test --release -p bevy_foliage --test fuzz`.
//! Found and fixed so far, each a panic inside the gltf crate on a malformed file, now a clear
//! error: an accessor of zero elements, indices of a non-integer type, attributes of the wrong
//! element size (`regression_empty_and_overlong_accessors_are_errors`), and a binary glTF
//! declaring fewer bytes than its header (`regression_a_glb_shorter_than_its_header_is_an_error`),
//! an attribute naming an accessor that does not exist (a panic in gltf-json's validation,
//! `regression_an_attribute_naming_a_missing_accessor_is_an_error`), an image with no source or
//! no MIME type (`regression_an_image_without_a_source_is_noted_not_a_panic`); and a grass-slice
//! cache with a NaN bake time was accepted
//! (`regression_a_slice_cache_with_a_nan_bake_time_is_refused`).

use bevy::math::{Vec2, Vec3};
use bevy_foliage::corpus::{
    AlphaModeDesc, GltfBuilder, MaterialDesc, NodeDesc, PrimitiveDesc, leaf_card_texture,
};
use bevy_foliage::grass::slice_format::{self, SliceBake};
use bevy_foliage::grass::slices::{SliceLayout, SliceTextures};
use bevy_foliage::impostor::format::{self as impostor_format, ImpostorData, ImpostorPlane};
use bevy_foliage::pruning::bake::{BakeSettings, CellCount, bake, bake_masked};
use bevy_foliage::pruning::format::{decode, encode, fnv1a64};
use bevy_foliage::pruning::gltf::{GltfLeafSettings, load_gltf_tree};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_nature_harness::fuzz::{cases, fuzz, fuzz_with};

/// The suite's cache files share one layout — magic (8 bytes), version (4), payload length (8),
/// payload, FNV-1a checksum of the payload (8): after each mutation the length and checksum are
/// made right, so the damage reaches the parser and the validator.
fn fix_header(bytes: &mut [u8]) {
    if bytes.len() >= 28 {
        let len = bytes.len() - 28;
        bytes[12..20].copy_from_slice(&(len as u64).to_le_bytes());
        let sum = fnv1a64(&bytes[20..20 + len]);
        bytes[20 + len..].copy_from_slice(&sum.to_le_bytes());
    }
}

fn tiny_bake_settings() -> BakeSettings {
    BakeSettings {
        cells: CellCount::Depth(2),
        resolution: 16,
        views: 6,
        ..Default::default()
    }
}

#[test]
fn fuzz_foliage_decoder() {
    let seeds: Vec<Vec<u8>> = [120usize, 300]
        .iter()
        .map(|&n| {
            let tree = generate(&TreeSpecies::fraxinus().with_leaf_count(n));
            let settings = BakeSettings {
                cells: CellCount::Depth(3),
                resolution: 24,
                ..Default::default()
            };
            encode(&bake(&tree.leaves, &settings, &|_| {}).unwrap().0)
        })
        .collect();
    let report = fuzz_with(
        "foliage_decoder",
        &seeds,
        cases(4_000),
        |b: &mut Vec<u8>| fix_header(b),
        |bytes| {
            let Ok(baked) = decode(bytes) else {
                return false;
            };
            // Accepted: a usable bake that survives its own encoding.
            assert_eq!(decode(&encode(&baked)).expect("re-decodes"), baked);
            true
        },
    );
    eprintln!("foliage decoder: {report:?}");
    assert!(report.accepted > 100, "{report:?}");
}

/// A small tree: a bark triangle under a root node, two child nodes of leaf cards (alpha-masked,
/// textured with an embedded PNG, one node rotated and scaled).
fn gltf_seed() -> GltfBuilder {
    let mut b = GltfBuilder::new();
    let bark = b.material(&MaterialDesc::opaque("Bark", [0.3, 0.2, 0.1, 1.0]));
    let texture = b.texture_png("leaf", 16, 16, &leaf_card_texture(16));
    let leaf = b.material(&MaterialDesc {
        name: "Leaf".into(),
        base_color: [0.2, 0.6, 0.2, 1.0],
        texture: Some(texture),
        alpha: AlphaModeDesc::Mask(0.5),
        double_sided: true,
        roughness: 0.8,
    });
    let trunk = b.mesh(
        "trunk",
        &[PrimitiveDesc {
            material: Some(bark),
            positions: vec![
                Vec3::new(-0.1, 0.0, 0.0),
                Vec3::new(0.1, 0.0, 0.0),
                Vec3::new(0.0, 3.0, 0.0),
            ],
            normals: vec![Vec3::Z; 3],
            uvs: vec![Vec2::ZERO, Vec2::X, Vec2::Y],
            indices: vec![0, 1, 2],
        }],
    );
    let mut cards = PrimitiveDesc {
        material: Some(leaf),
        ..Default::default()
    };
    for k in 0..12 {
        let c = Vec3::new(
            (k % 4) as f32 * 0.3 - 0.45,
            2.5 + (k / 4) as f32 * 0.3,
            0.1 * k as f32,
        );
        let base = cards.positions.len() as u32;
        for (dx, dy, uv) in [
            (-0.1, -0.1, Vec2::new(0.0, 1.0)),
            (0.1, -0.1, Vec2::new(1.0, 1.0)),
            (0.1, 0.1, Vec2::new(1.0, 0.0)),
            (-0.1, 0.1, Vec2::new(0.0, 0.0)),
        ] {
            cards.positions.push(c + Vec3::new(dx, dy, 0.0));
            cards.normals.push(Vec3::Z);
            cards.uvs.push(uv);
        }
        cards
            .indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    let crown = b.mesh("crown leaves", &[cards]);
    let left = b.node(&NodeDesc::mesh("leaves left", crown));
    let right = b.node(&NodeDesc {
        translation: Vec3::new(0.5, 0.2, 0.0),
        rotation: bevy::math::Quat::from_rotation_y(0.7),
        scale: 0.8,
        ..NodeDesc::mesh("leaves right", crown)
    });
    let root = b.node(&NodeDesc {
        children: vec![left, right],
        ..NodeDesc::mesh("trunk", trunk)
    });
    b.root(root);
    b
}

/// The binary seed holds the same tree as the text one.
#[test]
fn the_glb_seed_is_the_json_seed() {
    let b = gltf_seed();
    let settings = GltfLeafSettings::default();
    let from_json = load_gltf_tree(b.to_json().as_bytes(), None, &settings).unwrap();
    let from_glb = load_gltf_tree(&b.to_glb(), None, &settings).unwrap();
    let (a, g) = (from_json.leaves(), from_glb.leaves());
    assert_eq!(a.positions, g.positions);
    assert_eq!(a.indices, g.indices);
    assert_eq!(a.leaves.len(), 24);
    assert_eq!(from_glb.bark.len(), 1);
}

/// Found by the glTF target: an accessor of zero elements made the gltf crate's reader
/// underflow (a panic); an accessor reaching past its buffer view, or a view past its buffer,
/// is refused as well.
#[test]
fn regression_empty_and_overlong_accessors_are_errors() {
    let json: serde_json::Value = serde_json::from_str(&gltf_seed().to_json()).unwrap();
    let settings = GltfLeafSettings::default();
    let load_with = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut doc = json.clone();
        edit(&mut doc);
        load_gltf_tree(doc.to_string().as_bytes(), None, &settings)
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    // The leaves' index accessor (the last) with no elements.
    let last = json["accessors"].as_array().unwrap().len() - 1;
    let err = load_with(&|doc| doc["accessors"][last]["count"] = 0.into());
    assert!(
        err.contains("indices accessor") && err.contains("no elements"),
        "{err}"
    );
    // The trunk's positions claim a thousand elements in a 36-byte view.
    let err = load_with(&|doc| doc["accessors"][0]["count"] = 1000.into());
    assert!(
        err.contains("POSITION accessor 0") && err.contains("do not fit"),
        "{err}"
    );
    // A view past the end of the buffer.
    let err = load_with(&|doc| doc["bufferViews"][0]["byteOffset"] = 1_000_000.into());
    assert!(err.contains("do not fit"), "{err}");
    // Indices of floats (the gltf crate's reader has no case for them: `unreachable!`), and
    // normals of two components (its reader asserts the element size).
    let err = load_with(&|doc| doc["accessors"][last]["componentType"] = 5126.into());
    assert!(
        err.contains("indices accessor") && err.contains("F32"),
        "{err}"
    );
    let err = load_with(&|doc| doc["accessors"][1]["type"] = "VEC2".into());
    assert!(err.contains("NORMAL accessor 1"), "{err}");
}

/// Found by the glTF target: a POSITION accessor index past the accessors panicked inside the
/// gltf crate's own validation.
#[test]
fn regression_an_attribute_naming_a_missing_accessor_is_an_error() {
    let mut doc: serde_json::Value = serde_json::from_str(&gltf_seed().to_json()).unwrap();
    doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 65535.into();
    let err = load_gltf_tree(
        doc.to_string().as_bytes(),
        None,
        &GltfLeafSettings::default(),
    )
    .map(|_| ())
    .unwrap_err();
    assert!(err.to_string().contains("malformed glTF"), "{err}");
}

/// Found by the glTF target: an image with neither a uri nor a buffer view, or in a buffer view
/// without a MIME type, panicked inside the gltf crate (`Image::source` unwraps); now the tree
/// loads and the material is drawn untextured, with a note saying why.
#[test]
fn regression_an_image_without_a_source_is_noted_not_a_panic() {
    let json: serde_json::Value = serde_json::from_str(&gltf_seed().to_json()).unwrap();
    let settings = GltfLeafSettings::default();
    let notes = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut doc = json.clone();
        edit(&mut doc);
        load_gltf_tree(doc.to_string().as_bytes(), None, &settings)
            .expect("the tree loads")
            .notes
            .join("; ")
    };
    let text = notes(&|doc| {
        doc["images"][0].as_object_mut().unwrap().remove("uri");
    });
    assert!(text.contains("neither a uri nor a bufferView"), "{text}");
    let text = notes(&|doc| {
        let image = doc["images"][0].as_object_mut().unwrap();
        image.remove("uri");
        image.remove("mimeType");
        image.insert("bufferView".into(), 0.into());
    });
    assert!(text.contains("without a mimeType"), "{text}");
}

/// Found by the grass-slice target: a cache whose bake time was NaN decoded (and so differed
/// from itself).
#[test]
fn regression_a_slice_cache_with_a_nan_bake_time_is_refused() {
    let layout = SliceLayout {
        size: 0.5,
        height: 0.4,
        per_axis: 1,
        resolution: 2,
    };
    let bake = SliceBake {
        textures: SliceTextures::empty(layout),
        source_hash: 1,
        bake_ms: f32::NAN,
    };
    assert!(slice_format::decode(&slice_format::encode(&bake)).is_err());
}

/// Found by the glTF target: a binary glTF declaring fewer bytes than its header underflowed the
/// gltf crate's length arithmetic (a panic).
#[test]
fn regression_a_glb_shorter_than_its_header_is_an_error() {
    let mut glb = gltf_seed().to_glb();
    glb[8..12].copy_from_slice(&4u32.to_le_bytes());
    let err = load_gltf_tree(&glb, None, &GltfLeafSettings::default())
        .map(|_| ())
        .unwrap_err();
    assert!(err.to_string().contains("12-byte header"), "{err}");
}

#[test]
fn fuzz_gltf_leaf_extraction() {
    let b = gltf_seed();
    let seeds = vec![b.to_json().into_bytes(), b.to_glb()];
    let settings = GltfLeafSettings::default();
    let report = fuzz("gltf_leaves", &seeds, cases(1_500), |bytes| {
        let Ok(tree) = load_gltf_tree(bytes, None, &settings) else {
            return false;
        };
        // Accepted: everything a user does next works.
        let leaves = tree.leaves();
        assert_eq!(leaves.positions.len(), leaves.normals.len());
        assert_eq!(leaves.positions.len(), leaves.uvs.len());
        assert!(
            leaves
                .indices
                .iter()
                .all(|&i| (i as usize) < leaves.positions.len())
        );
        let mut mask = None;
        for group in &tree.leaf_groups {
            let _ = tree.material_of(group);
            mask = mask.or(tree.leaf_mask(group));
        }
        for part in &tree.bark {
            assert!(
                part.mesh
                    .indices
                    .iter()
                    .all(|&i| (i as usize) < part.mesh.positions.len())
            );
        }
        // Baking may refuse the leaves (an error), but must not panic.
        let _ = bake_masked(&leaves, mask.as_ref(), &tiny_bake_settings(), &|_| {});
        true
    });
    eprintln!("glTF leaves: {report:?}");
    assert!(report.accepted > 20, "{report:?}");
}

#[test]
fn fuzz_billboard_cloud_cache_decoder() {
    let size = 8u32;
    let data = ImpostorData {
        center: Vec3::new(0.0, 4.0, 0.0),
        radius: 3.0,
        planes: (0..3)
            .map(|k| ImpostorPlane {
                corners: [
                    Vec3::new(-1.0, 1.0, k as f32),
                    Vec3::new(1.0, 1.0, k as f32),
                    Vec3::new(1.0, 7.0, k as f32),
                    Vec3::new(-1.0, 7.0, k as f32),
                ],
                normal: Vec3::Z,
                tangent: Vec3::X,
                uv_min: Vec2::new(0.3 * k as f32, 0.0),
                uv_max: Vec2::new(0.3 * k as f32 + 0.3, 1.0),
                role: k,
            })
            .collect(),
        atlas_size: size,
        albedo: (0..size * size * 4).map(|i| i as u8).collect(),
        normal: (0..size * size * 4).map(|i| (i * 7) as u8).collect(),
        light: [
            (0..size * size * 4).map(|i| (i * 3) as u8).collect(),
            (0..size * size * 4).map(|i| (i * 5) as u8).collect(),
            (0..size * size * 4).map(|i| (i * 11) as u8).collect(),
        ],
        extinction: 0.8,
        seen_gains: [1.0; 8],
        bounce_ratios: Default::default(),
        hotspot: Default::default(),
        source_hash: 0xDEAD_BEEF,
        bake_ms: 12.5,
    };
    let seeds = vec![impostor_format::encode(&data)];
    assert_eq!(impostor_format::decode(&seeds[0]).unwrap(), data);
    let report = fuzz_with(
        "billboard_cloud",
        &seeds,
        cases(4_000),
        |b: &mut Vec<u8>| fix_header(b),
        |bytes| {
            let Ok(decoded) = impostor_format::decode(bytes) else {
                return false;
            };
            let n = (decoded.atlas_size * decoded.atlas_size * 4) as usize;
            assert_eq!((decoded.albedo.len(), decoded.normal.len()), (n, n));
            assert!(decoded.light.iter().all(|l| l.len() == n));
            assert_eq!(
                impostor_format::decode(&impostor_format::encode(&decoded)).unwrap(),
                decoded
            );
            true
        },
    );
    eprintln!("billboard clouds: {report:?}");
    assert!(report.accepted > 100, "{report:?}");
}

#[test]
fn fuzz_grass_slice_cache_decoder() {
    let layout = SliceLayout {
        size: 0.5,
        height: 0.4,
        per_axis: 1,
        resolution: 2,
    };
    let mut textures = SliceTextures::empty(layout);
    for (i, t) in textures.texels.iter_mut().enumerate() {
        *t = [i as f32 / 64.0, 0.25, 0.5, (i % 2) as f32];
    }
    let bake = SliceBake {
        textures,
        source_hash: 77,
        bake_ms: 12.5,
    };
    let seeds = vec![slice_format::encode(&bake)];
    let report = fuzz_with(
        "grass_slices",
        &seeds,
        cases(4_000),
        |b| fix_header(b),
        |bytes| {
            let Ok(decoded) = slice_format::decode(bytes) else {
                return false;
            };
            assert_eq!(
                slice_format::decode(&slice_format::encode(&decoded)).unwrap(),
                decoded
            );
            true
        },
    );
    eprintln!("grass slices: {report:?}");
    assert!(report.accepted > 100, "{report:?}");
}
