//! Billboard clouds as Bevy assets: `*.bbcloud` files load through the `AssetServer`
//! ([`BillboardCloudLoader`]) into a [`BillboardCloudAsset`] — a mesh of textured quads and a
//! `StandardMaterial` (albedo atlas, normal atlas, alpha mask) — so impostors are lit by Bevy's
//! lights and cast alpha-masked shadows with no shader of their own; and the same material
//! extended with the light atlases ([`TreeLitImpostorMaterial`]) for the tree lighting.

use super::format::{ImpostorData, ImpostorFormatError, decode};
use super::texture::preserve_alpha_coverage;
use super::tree_lit::{TreeLitImpostor, TreeLitImpostorMaterial, TreeLitImpostorParams};
use crate::pruning::spawn::box_mip_chain;
use bevy::asset::RenderAssetUsages;
use bevy::image::{ImageSampler, ImageSamplerDescriptor};
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};

/// A loaded billboard cloud, ready to draw.
#[derive(Asset, TypePath, Clone, Debug)]
pub struct BillboardCloudAsset {
    /// The quads.
    pub mesh: Handle<Mesh>,
    /// Their material (albedo and normal atlases, alpha mask, two-sided).
    pub material: Handle<StandardMaterial>,
    /// The same with the light atlases, drawn while the tree lighting is on.
    pub tree_lit: Handle<TreeLitImpostorMaterial>,
    /// Centre of the tree's bounding sphere (model space).
    pub center: Vec3,
    /// Radius of the tree's bounding sphere.
    pub radius: f32,
    /// Number of planes.
    pub planes: u32,
    /// GPU texture bytes of the atlases with mips (the light atlases included).
    pub texture_bytes: u64,
    /// The source hash the file was baked from.
    pub source_hash: u64,
}

/// Alpha below this is cut (of 255).
pub const ALPHA_CUTOFF: u8 = 128;

/// The quads of a billboard cloud: four vertices per plane, with normals, atlas uvs and tangents
/// (`w = 1`: Bevy's bitangent `n × t` is the plane's bitangent, the texture's up).
pub fn impostor_mesh(data: &ImpostorData) -> Mesh {
    let (mut positions, mut normals, mut uvs, mut tangents, mut indices) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for plane in &data.planes {
        let base = positions.len() as u32;
        let (a, b) = (plane.uv_min, plane.uv_max);
        let corner_uvs = [
            Vec2::new(a.x, a.y),
            Vec2::new(b.x, a.y),
            Vec2::new(b.x, b.y),
            Vec2::new(a.x, b.y),
        ];
        for (corner, uv) in plane.corners.iter().zip(corner_uvs) {
            positions.push(corner.to_array());
            normals.push(plane.normal.to_array());
            uvs.push(uv.to_array());
            tangents.push(plane.tangent.extend(1.0).to_array());
        }
        indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
    .with_inserted_attribute(Mesh::ATTRIBUTE_TANGENT, tangents)
    .with_inserted_indices(Indices::U32(indices))
}

/// An atlas as a Bevy image with its mip chain (alpha coverage kept per level for the albedo).
pub fn atlas_image(size: u32, rgba: &[u8], srgb: bool) -> Image {
    let mut levels = box_mip_chain(size, size, rgba);
    if srgb {
        preserve_alpha_coverage(&mut levels, ALPHA_CUTOFF);
    }
    let mut image = Image::new_uninit(
        Extent3d {
            width: size,
            height: size,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        if srgb {
            TextureFormat::Rgba8UnormSrgb
        } else {
            TextureFormat::Rgba8Unorm
        },
        RenderAssetUsages::default(),
    );
    image.texture_descriptor.mip_level_count = levels.len() as u32;
    image.data = Some(levels.concat());
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor::linear());
    image
}

/// The impostor's material: albedo and coverage, tangent-space normals, alpha mask, two-sided.
pub fn impostor_material(albedo: Handle<Image>, normal: Handle<Image>) -> StandardMaterial {
    StandardMaterial {
        base_color_texture: Some(albedo),
        normal_map_texture: Some(normal),
        alpha_mode: AlphaMode::Mask(ALPHA_CUTOFF as f32 / 255.0),
        double_sided: true,
        cull_mode: None,
        perceptual_roughness: 0.9,
        reflectance: 0.3,
        ..default()
    }
}

/// Eight gains as the shader's two vectors.
fn gains_as_vectors(g: &[f32; 8]) -> [Vec4; 2] {
    [
        Vec4::new(g[0], g[1], g[2], g[3]),
        Vec4::new(g[4], g[5], g[6], g[7]),
    ]
}

/// The tree lighting's extension of a cloud's material: its light atlases (sRGB: the bake
/// stores the values sRGB-encoded), its crown and extinction; the scene's lights are filled in
/// by `tree_lit::refresh_tree_lit_impostors`.
pub fn tree_lit_extension(data: &ImpostorData, light: [Handle<Image>; 3]) -> TreeLitImpostor {
    let [light0, light1, light2] = light;
    TreeLitImpostor {
        params: TreeLitImpostorParams {
            crown_sphere: data.center.extend(data.radius),
            extinction: data.extinction,
            seen_gains: gains_as_vectors(&data.seen_gains),
            hotspot: data.hotspot.packed().into(),
            bounce_ratios: super::tree_lit::ratios_as_vectors(
                &data.bounce_ratios.front,
                &data.bounce_ratios.back,
            ),
            ..default()
        },
        light0,
        light1,
        light2,
    }
}

impl BillboardCloudAsset {
    /// Adds the mesh, images and materials of `data` to the asset collections.
    pub fn from_data(
        data: &ImpostorData,
        meshes: &mut Assets<Mesh>,
        images: &mut Assets<Image>,
        materials: &mut Assets<StandardMaterial>,
        tree_lit: &mut Assets<TreeLitImpostorMaterial>,
    ) -> Self {
        let albedo = images.add(atlas_image(data.atlas_size, &data.albedo, true));
        let normal = images.add(atlas_image(data.atlas_size, &data.normal, false));
        let light: [Handle<Image>; 3] =
            std::array::from_fn(|k| images.add(atlas_image(data.atlas_size, &data.light[k], true)));
        let base = impostor_material(albedo, normal);
        Self {
            mesh: meshes.add(impostor_mesh(data)),
            material: materials.add(base.clone()),
            tree_lit: tree_lit.add(TreeLitImpostorMaterial {
                base,
                extension: tree_lit_extension(data, light),
            }),
            center: data.center,
            radius: data.radius,
            planes: data.planes.len() as u32,
            texture_bytes: data.texture_bytes() + data.light_texture_bytes(),
            source_hash: data.source_hash,
        }
    }

    /// [`Self::from_data`] with the asset collections of `world`.
    pub fn from_data_in(world: &mut World, data: &ImpostorData) -> Self {
        world.resource_scope(|world, mut meshes: Mut<Assets<Mesh>>| {
            world.resource_scope(|world, mut images: Mut<Assets<Image>>| {
                world.resource_scope(
                    |world, mut tree_lit: Mut<Assets<TreeLitImpostorMaterial>>| {
                        let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
                        Self::from_data(
                            data,
                            &mut meshes,
                            &mut images,
                            &mut materials,
                            &mut tree_lit,
                        )
                    },
                )
            })
        })
    }
}

/// Loads `*.bbcloud` files into [`BillboardCloudAsset`]s (mesh, atlases and material as labelled
/// sub-assets); a corrupt or mismatched file fails the load with an [`ImpostorFormatError`]
/// naming the file, never a panic.
#[derive(Default, TypePath)]
pub struct BillboardCloudLoader;

impl bevy::asset::AssetLoader for BillboardCloudLoader {
    type Asset = BillboardCloudAsset;
    type Settings = ();
    type Error = ImpostorFormatError;

    async fn load(
        &self,
        reader: &mut dyn bevy::asset::io::Reader,
        _settings: &(),
        load_context: &mut bevy::asset::LoadContext<'_>,
    ) -> Result<BillboardCloudAsset, ImpostorFormatError> {
        let mut bytes = Vec::new();
        reader
            .read_to_end(&mut bytes)
            .await
            .map_err(|e| ImpostorFormatError::Io(format!("{}: {e}", load_context.path())))?;
        let data = decode(&bytes).map_err(|e| match e {
            ImpostorFormatError::Invalid(s) => {
                ImpostorFormatError::Invalid(format!("{}: {s}", load_context.path()))
            }
            other => other,
        })?;
        let albedo = load_context.add_labeled_asset(
            "albedo".to_string(),
            atlas_image(data.atlas_size, &data.albedo, true),
        );
        let normal = load_context.add_labeled_asset(
            "normal".to_string(),
            atlas_image(data.atlas_size, &data.normal, false),
        );
        let light: [Handle<Image>; 3] = std::array::from_fn(|k| {
            load_context.add_labeled_asset(
                format!("light{k}"),
                atlas_image(data.atlas_size, &data.light[k], true),
            )
        });
        let base = impostor_material(albedo, normal);
        let material = load_context.add_labeled_asset("material".to_string(), base.clone());
        let tree_lit = load_context.add_labeled_asset(
            "tree_lit_material".to_string(),
            TreeLitImpostorMaterial {
                base,
                extension: tree_lit_extension(&data, light),
            },
        );
        let mesh = load_context.add_labeled_asset("mesh".to_string(), impostor_mesh(&data));
        Ok(BillboardCloudAsset {
            mesh,
            material,
            tree_lit,
            center: data.center,
            radius: data.radius,
            planes: data.planes.len() as u32,
            texture_bytes: data.texture_bytes() + data.light_texture_bytes(),
            source_hash: data.source_hash,
        })
    }

    fn extensions(&self) -> &[&str] {
        &["bbcloud"]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::impostor::format::save;
    use crate::impostor::format::tests::sample;

    #[test]
    fn the_mesh_has_one_quad_per_plane_with_the_atlas_uvs() {
        let data = sample();
        let mesh = impostor_mesh(&data);
        assert_eq!(mesh.count_vertices(), 4);
        assert_eq!(mesh.indices().unwrap().len(), 6);
        let Some(bevy::mesh::VertexAttributeValues::Float32x2(uvs)) =
            mesh.attribute(Mesh::ATTRIBUTE_UV_0)
        else {
            panic!("uvs");
        };
        assert_eq!(uvs[0], [0.0, 0.0]);
        assert_eq!(uvs[2], [0.5, 1.0]);
    }

    #[test]
    fn asset_server_loads_good_files_and_fails_corrupt_ones() {
        use bevy::asset::{AssetPlugin, AssetServer, LoadState};
        let dir = std::env::temp_dir().join(format!("bbcloud-assets-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        save(&sample(), &dir.join("good.bbcloud")).unwrap();
        let mut corrupt = super::super::format::encode(&sample());
        let middle = corrupt.len() / 2;
        corrupt[middle] ^= 0xFF;
        std::fs::write(dir.join("corrupt.bbcloud"), corrupt).unwrap();
        let mut app = App::new();
        app.add_plugins((
            MinimalPlugins,
            AssetPlugin {
                file_path: dir.to_string_lossy().into_owned(),
                ..default()
            },
        ))
        .init_asset::<BillboardCloudAsset>()
        .init_asset::<Mesh>()
        .init_asset::<Image>()
        .init_asset::<StandardMaterial>()
        .init_asset::<TreeLitImpostorMaterial>()
        .init_asset_loader::<BillboardCloudLoader>();
        let server = app.world().resource::<AssetServer>().clone();
        let good: Handle<BillboardCloudAsset> = server.load("good.bbcloud");
        let bad: Handle<BillboardCloudAsset> = server.load("corrupt.bbcloud");
        let settled = |s: LoadState| matches!(s, LoadState::Loaded | LoadState::Failed(_));
        for _ in 0..500 {
            app.update();
            if settled(server.load_state(&good)) && settled(server.load_state(&bad)) {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        assert!(matches!(server.load_state(&good), LoadState::Loaded));
        let loaded = app
            .world()
            .resource::<Assets<BillboardCloudAsset>>()
            .get(&good)
            .unwrap();
        assert_eq!(loaded.planes, 1);
        assert_eq!(loaded.source_hash, 0xDEAD_BEEF);
        assert!(matches!(server.load_state(&bad), LoadState::Failed(_)));
        std::fs::remove_dir_all(dir).ok();
    }
}
