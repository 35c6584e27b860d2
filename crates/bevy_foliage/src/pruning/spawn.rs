//! Spawning pruned trees in one call — procedural species or glTF files: read or generate,
//! bake, and spawn the bark as an ordinary mesh with the leaves as a [`PrunedFoliage`] set.
//! glTF trees keep the file's own materials and textures ([`super::gltf`]): the leaf texture's
//! alpha drives the bake's visibility and the sub-pixel fade's opaque fraction, and textures get
//! a box-filtered mip chain (the file's are single images; leaves shimmer without mips).
//!
//! Baking at spawn time suits a few trees and tools. For shipped games bake once with the
//! `foliage_bake` binary and load the `.foliage` file through the `AssetServer`.

use super::bake::{BakeError, BakeSettings, BakedFoliage, bake, bake_masked};
use super::components::PrunedFoliage;
use super::gltf::{
    DecodedImage, GltfAlpha, GltfLeafSettings, GltfMaterial, GltfTree, GltfTreeError, GltfWrap,
    load_gltf_tree,
};
use super::material::{LeafMaterial, leaf_material, leaf_material_textured};
use super::procedural::{TreeSpecies, generate};
use crate::meshes::bark_mesh;
use bevy::asset::RenderAssetUsages;
use bevy::ecs::system::SystemParam;
use bevy::image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor};
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use std::path::{Path, PathBuf};

/// Why a glTF tree could not be spawned.
#[derive(Debug)]
pub enum TreeSpawnError {
    /// The file could not be read.
    Io(PathBuf, std::io::Error),
    /// The file is not a usable tree.
    Gltf(PathBuf, GltfTreeError),
    /// The leaves could not be baked.
    Bake(PathBuf, BakeError),
}

impl std::fmt::Display for TreeSpawnError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Io(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Gltf(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Bake(p, e) => write!(f, "{}: {e}", p.display()),
        }
    }
}

impl std::error::Error for TreeSpawnError {}

/// The assets a procedural tree needs.
#[derive(SystemParam)]
pub struct TreeAssets<'w> {
    /// Bark meshes.
    pub meshes: ResMut<'w, Assets<Mesh>>,
    /// Bark materials.
    pub materials: ResMut<'w, Assets<StandardMaterial>>,
    /// Baked pruning data.
    pub baked: ResMut<'w, Assets<BakedFoliage>>,
    /// Leaf materials.
    pub leaf_materials: ResMut<'w, Assets<LeafMaterial>>,
    /// Textures of glTF trees.
    pub images: ResMut<'w, Assets<Image>>,
}

/// The assets of a baked glTF tree ([`TreeAssets::bake_gltf`]).
#[derive(Clone, Debug, Default)]
pub struct GltfTreeAssets {
    /// Per leaf material: the baked leaves and their material.
    pub leaves: Vec<(Handle<BakedFoliage>, Handle<LeafMaterial>)>,
    /// Per bark material: the mesh and its material.
    pub bark: Vec<(Handle<Mesh>, Handle<StandardMaterial>)>,
    /// What the reader left out or changed (also logged).
    pub notes: Vec<String>,
    /// Per leaf material, in the order of `leaves`: what its bake made and took.
    pub stats: Vec<GltfBakeStats>,
}

/// What one leaf material's bake made and took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GltfBakeStats {
    /// Leaves baked.
    pub leaves: usize,
    /// Cells.
    pub cells: usize,
    /// Bake time per stage.
    pub timings: super::bake::BakeTimings,
    /// Opaque share of the leaves' texture (1 for opaque leaves).
    pub opaque_fraction: f32,
}

/// The default look of bark.
pub fn default_bark_material() -> StandardMaterial {
    StandardMaterial {
        base_color: Color::srgb(0.35, 0.27, 0.2),
        perceptual_roughness: 0.95,
        ..default()
    }
}

/// The default look of procedural leaves.
pub fn default_leaf_material() -> StandardMaterial {
    StandardMaterial {
        base_color: Color::srgb(0.32, 0.42, 0.2),
        perceptual_roughness: 0.8,
        ..default()
    }
}

impl TreeAssets<'_> {
    /// Bakes `species` (logging the bake time) and returns the asset handle of its pruning data,
    /// with the bark mesh.
    pub fn bake_species(
        &mut self,
        species: &TreeSpecies,
        settings: &BakeSettings,
    ) -> Result<(Handle<BakedFoliage>, Handle<Mesh>), BakeError> {
        let tree = generate(species);
        let (baked, timings) = bake(&tree.leaves, settings, &|_| {})?;
        info!(
            "baked {} ({} leaves, {} cells) in {:.0} ms",
            species.name,
            baked.leaf_count(),
            baked.cell_count(),
            timings.total().as_secs_f64() * 1e3
        );
        Ok((
            self.baked.add(baked),
            self.meshes.add(bark_mesh(&tree.bark)),
        ))
    }

    /// Reads a glTF tree (`.gltf` or `.glb`) from disk (see [`super::gltf`] for what is read as
    /// the tree and as leaves), bakes each leaf material's leaves through its texture's alpha
    /// mask, and makes Bevy materials of the file's own: the leaf materials with the opaque
    /// fraction of their texture measured over the leaves. What the reader left out is logged.
    pub fn bake_gltf(
        &mut self,
        path: impl AsRef<Path>,
        leaves: &GltfLeafSettings,
        settings: &BakeSettings,
    ) -> Result<GltfTreeAssets, TreeSpawnError> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| TreeSpawnError::Io(path.into(), e))?;
        let tree = load_gltf_tree(&bytes, path.parent(), leaves)
            .map_err(|e| TreeSpawnError::Gltf(path.into(), e))?;
        let mut notes = tree.notes.clone();
        let images = self.add_images(&tree);
        let mut out = GltfTreeAssets::default();
        for group in &tree.leaf_groups {
            let mask = tree.leaf_mask(group);
            let (baked, timings) = bake_masked(&group.leaves, mask.as_ref(), settings, &|_| {})
                .map_err(|e| TreeSpawnError::Bake(path.into(), e))?;
            if baked.skipped.total() > 0 {
                notes.push(format!("skipped {:?} leaves", baked.skipped));
            }
            let opaque = mask
                .as_ref()
                .and_then(|m| m.opaque_fraction_of(&group.leaves))
                .unwrap_or(1.0);
            info!(
                "baked {} ({} leaves, {} cells, {:.0} % opaque) in {:.0} ms",
                path.display(),
                baked.leaf_count(),
                baked.cell_count(),
                opaque * 100.0,
                timings.total().as_secs_f64() * 1e3
            );
            let base = match tree.material_of(group) {
                Some(m) => {
                    if m.alpha == GltfAlpha::Blend {
                        notes.push(format!(
                            "leaf material '{}' is alpha-blended: drawn alpha-masked at 0.5, so leaves sort and cast shadows",
                            m.name
                        ));
                    }
                    if m.normal_texture.is_some() {
                        notes.push(format!(
                            "leaf material '{}': its normal map is not used (pruned leaves carry no tangents)",
                            m.name
                        ));
                    }
                    StandardMaterial {
                        alpha_mode: match m.alpha {
                            GltfAlpha::Opaque => AlphaMode::Opaque,
                            GltfAlpha::Mask(c) => AlphaMode::Mask(c),
                            GltfAlpha::Blend => AlphaMode::Mask(0.5),
                        },
                        normal_map_texture: None,
                        ..standard_material(m, &images)
                    }
                }
                None => default_leaf_material(),
            };
            out.stats.push(GltfBakeStats {
                leaves: baked.leaf_count(),
                cells: baked.cell_count(),
                timings,
                opaque_fraction: opaque,
            });
            out.leaves.push((
                self.baked.add(baked),
                self.leaf_materials
                    .add(leaf_material_textured(base, opaque)),
            ));
        }
        for part in &tree.bark {
            let mut mesh = bark_mesh(&part.mesh);
            let mut material = match part.material.and_then(|m| tree.materials.get(m)) {
                Some(m) => standard_material(m, &images),
                None => default_bark_material(),
            };
            if material.normal_map_texture.is_some() && mesh.generate_tangents().is_err() {
                notes.push("a bark normal map was dropped: tangents could not be generated".into());
                material.normal_map_texture = None;
            }
            out.bark
                .push((self.meshes.add(mesh), self.materials.add(material)));
        }
        for note in &notes {
            info!("{}: {note}", path.display());
        }
        out.notes = notes;
        Ok(out)
    }

    /// Bevy images of the tree's decoded images, with mip chains and the file's wrapping.
    fn add_images(&mut self, tree: &GltfTree) -> Vec<Option<Handle<Image>>> {
        // Colour textures are sRGB, data textures (normal, metallic-roughness) linear.
        let mut srgb = vec![true; tree.images.len()];
        let mut wrap = vec![[GltfWrap::Repeat; 2]; tree.images.len()];
        for m in &tree.materials {
            for t in [m.normal_texture, m.metallic_roughness_texture]
                .into_iter()
                .flatten()
            {
                if let Some(s) = srgb.get_mut(t.image) {
                    *s = false;
                }
            }
            for t in [
                m.base_color_texture,
                m.normal_texture,
                m.metallic_roughness_texture,
            ]
            .into_iter()
            .flatten()
            {
                if let Some(w) = wrap.get_mut(t.image) {
                    *w = t.wrap;
                }
            }
        }
        tree.images
            .iter()
            .enumerate()
            .map(|(i, image)| {
                image
                    .as_ref()
                    .map(|image| self.images.add(bevy_image(image, srgb[i], wrap[i])))
            })
            .collect()
    }

    /// Reads, bakes (default [`BakeSettings`]) and spawns a glTF tree in one call, with the
    /// file's own materials and textures: a root entity carrying `transform` and the file's
    /// name, with one [`PrunedFoliage`] child per leaf material and one bark child per bark
    /// material.
    pub fn spawn_gltf(
        &mut self,
        commands: &mut Commands,
        path: impl AsRef<Path>,
        leaf_settings: &GltfLeafSettings,
        transform: Transform,
    ) -> Result<Entity, TreeSpawnError> {
        let path = path.as_ref();
        let assets = self.bake_gltf(path, leaf_settings, &BakeSettings::default())?;
        let name = path
            .file_stem()
            .map_or_else(|| "tree".into(), |s| s.to_string_lossy().into_owned());
        let mut root = commands.spawn((Name::new(name), transform, Visibility::Inherited));
        for (i, (baked, material)) in assets.leaves.into_iter().enumerate() {
            root.with_child((
                Name::new(format!("leaves {i}")),
                PrunedFoliage { baked, material },
            ));
        }
        for (i, (mesh, material)) in assets.bark.into_iter().enumerate() {
            root.with_child((
                Name::new(format!("bark {i}")),
                Mesh3d(mesh),
                MeshMaterial3d(material),
            ));
        }
        Ok(root.id())
    }

    /// Spawns a baked tree: the entity carries [`PrunedFoliage`] and `transform`, its child the
    /// bark.
    pub fn spawn(
        &mut self,
        commands: &mut Commands,
        name: &str,
        baked: Handle<BakedFoliage>,
        bark: Handle<Mesh>,
        leaves: StandardMaterial,
        transform: Transform,
    ) -> Entity {
        let material = self.leaf_materials.add(leaf_material(leaves));
        self.spawn_parts(commands, name, baked, Some(bark), material, transform)
    }

    /// Spawns a tree from its parts: leaves with an existing leaf material (so many trees can
    /// share one), and an optional bark mesh.
    pub fn spawn_parts(
        &mut self,
        commands: &mut Commands,
        name: &str,
        baked: Handle<BakedFoliage>,
        bark: Option<Handle<Mesh>>,
        material: Handle<LeafMaterial>,
        transform: Transform,
    ) -> Entity {
        let mut tree = commands.spawn((
            Name::new(name.to_string()),
            PrunedFoliage { baked, material },
            transform,
        ));
        if let Some(bark) = bark {
            let bark_material = self.materials.add(default_bark_material());
            tree.with_child((
                Name::new("bark"),
                Mesh3d(bark),
                MeshMaterial3d(bark_material),
            ));
        }
        tree.id()
    }

    /// Generates, bakes and spawns one procedural tree.
    pub fn spawn_procedural(
        &mut self,
        commands: &mut Commands,
        species: &TreeSpecies,
        transform: Transform,
    ) -> Result<Entity, BakeError> {
        let (baked, bark) = self.bake_species(species, &BakeSettings::default())?;
        Ok(self.spawn(
            commands,
            species.name,
            baked,
            bark,
            default_leaf_material(),
            transform,
        ))
    }
}

/// A Bevy material of a glTF material (`images`: the tree's images as Bevy handles).
pub fn standard_material(m: &GltfMaterial, images: &[Option<Handle<Image>>]) -> StandardMaterial {
    let texture = |t: Option<super::gltf::GltfTextureRef>| {
        t.and_then(|t| images.get(t.image).cloned().flatten())
    };
    let [r, g, b, a] = m.base_color;
    StandardMaterial {
        base_color: Color::linear_rgba(r, g, b, a),
        base_color_texture: texture(m.base_color_texture),
        normal_map_texture: texture(m.normal_texture),
        metallic_roughness_texture: texture(m.metallic_roughness_texture),
        metallic: m.metallic,
        perceptual_roughness: m.roughness,
        emissive: LinearRgba::rgb(m.emissive[0], m.emissive[1], m.emissive[2]),
        alpha_mode: match m.alpha {
            GltfAlpha::Opaque => AlphaMode::Opaque,
            GltfAlpha::Mask(c) => AlphaMode::Mask(c),
            GltfAlpha::Blend => AlphaMode::Blend,
        },
        double_sided: m.double_sided,
        cull_mode: if m.double_sided {
            None
        } else {
            Some(bevy::render::render_resource::Face::Back)
        },
        ..default()
    }
}

/// Box-filtered mip levels of RGBA8 texels, level 0 first, down to 1×1 (odd sizes round down,
/// their last row or column folded into the one before).
pub fn box_mip_chain(width: u32, height: u32, rgba: &[u8]) -> Vec<Vec<u8>> {
    let mut levels = vec![rgba.to_vec()];
    let (mut w, mut h) = (width.max(1), height.max(1));
    while w > 1 || h > 1 {
        let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
        let prev = levels.last().unwrap();
        let mut next = vec![0u8; (nw * nh * 4) as usize];
        for y in 0..nh {
            for x in 0..nw {
                // The source texels folding into (x, y): 2×2, wider at an odd edge.
                let xs = (2 * x)..if x + 1 == nw { w } else { 2 * x + 2 }.min(w);
                let ys = (2 * y)..if y + 1 == nh { h } else { 2 * y + 2 }.min(h);
                let n = (xs.len() * ys.len()) as u32;
                for c in 0..4 {
                    let mut sum = 0u32;
                    for sy in ys.clone() {
                        for sx in xs.clone() {
                            sum += prev[((sy * w + sx) * 4 + c) as usize] as u32;
                        }
                    }
                    next[((y * nw + x) * 4 + c) as usize] = ((sum + n / 2) / n) as u8;
                }
            }
        }
        levels.push(next);
        w = nw;
        h = nh;
    }
    levels
}

/// A Bevy image of a decoded glTF image, with its mip chain and the file's wrapping.
fn bevy_image(image: &DecodedImage, srgb: bool, wrap: [GltfWrap; 2]) -> Image {
    let levels = box_mip_chain(image.width, image.height, &image.rgba);
    let mut out = Image::new_uninit(
        Extent3d {
            width: image.width,
            height: image.height,
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
    out.texture_descriptor.mip_level_count = levels.len() as u32;
    out.data = Some(levels.concat());
    let address = |w: GltfWrap| match w {
        GltfWrap::Repeat => ImageAddressMode::Repeat,
        GltfWrap::MirroredRepeat => ImageAddressMode::MirrorRepeat,
        GltfWrap::Clamp => ImageAddressMode::ClampToEdge,
    };
    out.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: address(wrap[0]),
        address_mode_v: address(wrap[1]),
        ..ImageSamplerDescriptor::linear()
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy::ecs::system::RunSystemOnce;

    fn app() -> App {
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, AssetPlugin::default()))
            .init_asset::<Mesh>()
            .init_asset::<Image>()
            .init_asset::<StandardMaterial>()
            .init_asset::<BakedFoliage>()
            .init_asset::<LeafMaterial>();
        app
    }

    fn spawn(app: &mut App, path: PathBuf) -> Result<Entity, TreeSpawnError> {
        app.world_mut()
            .run_system_once(move |mut commands: Commands, mut assets: TreeAssets| {
                assets.spawn_gltf(
                    &mut commands,
                    &path,
                    &GltfLeafSettings::default(),
                    Transform::from_xyz(1.0, 0.0, 0.0),
                )
            })
            .unwrap()
    }

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("bevy_foliage_{name}_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_gltf_tree_spawns_in_one_call_with_bark_and_pruned_leaves() {
        let dir = temp_dir("spawn");
        let path = dir.join("sample.gltf");
        std::fs::write(&path, super::super::gltf::tests::sample_tree()).unwrap();
        let mut app = app();
        let spawned = spawn(&mut app, path).unwrap();
        app.update();
        let world = app.world_mut();
        assert_eq!(world.get::<Name>(spawned).unwrap().as_str(), "sample");
        let children = world.get::<Children>(spawned).unwrap().to_vec();
        assert_eq!(children.len(), 2, "one leaf group, one bark part");
        let pruned = world.get::<PrunedFoliage>(children[0]).unwrap().clone();
        let baked = world
            .resource::<Assets<BakedFoliage>>()
            .get(&pruned.baked)
            .unwrap();
        // The sample's 3 usable leaves (a degenerate and a NaN leaf are skipped and counted).
        assert_eq!(baked.leaf_count(), 3);
        assert_eq!(baked.skipped.total(), 2);
        let bark = world.get::<Mesh3d>(children[1]).unwrap().0.clone();
        let mesh = world.resource::<Assets<Mesh>>().get(&bark).unwrap();
        assert_eq!(mesh.indices().unwrap().len(), 3, "the bark triangle");
        // The file's own materials: the bark's colour, the needles' mask.
        let bark_material = world
            .get::<MeshMaterial3d<StandardMaterial>>(children[1])
            .unwrap();
        let bark_material = world
            .resource::<Assets<StandardMaterial>>()
            .get(&bark_material.0)
            .unwrap();
        assert_eq!(
            bark_material.base_color,
            Color::linear_rgba(0.3, 0.2, 0.1, 1.0)
        );
        let leaves = world
            .resource::<Assets<LeafMaterial>>()
            .get(&pruned.material)
            .unwrap();
        assert_eq!(leaves.base.alpha_mode, AlphaMode::Mask(0.5));
        assert_eq!(
            leaves.base.base_color,
            Color::linear_rgba(0.2, 0.5, 0.1, 1.0)
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_card_tree_keeps_its_texture_and_measures_its_opaque_fraction() {
        let dir = temp_dir("spawn_cards");
        let path = crate::corpus::alpha_card_tree().write(&dir).unwrap();
        let mut app = app();
        let spawned = spawn(&mut app, path).unwrap();
        app.update();
        let world = app.world_mut();
        let children = world.get::<Children>(spawned).unwrap().to_vec();
        let pruned = world.get::<PrunedFoliage>(children[0]).unwrap().clone();
        let leaves = world
            .resource::<Assets<LeafMaterial>>()
            .get(&pruned.material)
            .unwrap()
            .clone();
        let o = leaves.extension.params.opaque_fraction;
        assert!(
            (0.15..0.25).contains(&o),
            "cluster cards are a fifth opaque: {o}"
        );
        let texture = leaves.base.base_color_texture.clone().unwrap();
        let image = world.resource::<Assets<Image>>().get(&texture).unwrap();
        assert_eq!(image.texture_descriptor.size.width, 64);
        assert_eq!(
            image.texture_descriptor.mip_level_count, 7,
            "64² has 7 levels"
        );
        assert_eq!(
            image.texture_descriptor.format,
            TextureFormat::Rgba8UnormSrgb
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn mip_chains_average_and_reach_one_texel() {
        // 3×2 texels: odd width folds the last column into the one before.
        let rgba: Vec<u8> = (0..6).flat_map(|i| [i * 10, 0, 0, 255]).collect();
        let levels = box_mip_chain(3, 2, &rgba);
        assert_eq!(levels.len(), 2);
        assert_eq!(levels[1].len(), 4);
        assert_eq!(levels[1][0], 25, "mean of 0..50 step 10");
        let square = box_mip_chain(64, 64, &vec![200; 64 * 64 * 4]);
        assert_eq!(square.len(), 7);
        assert!(square.iter().all(|l| l.iter().all(|&v| v == 200)));
    }

    #[test]
    fn missing_and_malformed_files_are_errors() {
        let mut app = app();
        let missing = spawn(&mut app, "/nonexistent/tree.glb".into());
        assert!(
            matches!(missing, Err(TreeSpawnError::Io(..))),
            "{missing:?}"
        );
        let dir = temp_dir("spawn_bad");
        let path = dir.join("bad.gltf");
        std::fs::write(&path, "{ not gltf").unwrap();
        let message = spawn(&mut app, path).unwrap_err().to_string();
        assert!(
            message.contains("bad.gltf") && message.contains("not a valid glTF"),
            "{message}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
