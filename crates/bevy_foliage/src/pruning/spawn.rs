//! Spawning pruned trees in one call — procedural species or glTF files: read or generate,
//! bake, and spawn the bark as an ordinary mesh with the leaves as a [`PrunedFoliage`] set.
//!
//! Baking at spawn time suits a few trees and tools. For shipped games bake once with the
//! `foliage_bake` binary and load the `.foliage` file through the `AssetServer`.

use super::bake::{BakeError, BakeSettings, BakedFoliage, bake};
use super::components::PrunedFoliage;
use super::gltf::{GltfLeafSettings, GltfTreeError, load_gltf_tree};
use super::material::{LeafMaterial, leaf_material};
use super::procedural::{TreeSpecies, generate};
use crate::meshes::bark_mesh;
use bevy::ecs::system::SystemParam;
use bevy::prelude::*;
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

    /// Reads a glTF tree (`.gltf` or `.glb`) from disk, separates its leaves (see
    /// [`super::gltf`]), bakes them and returns the pruning data with the bark mesh (`None` when
    /// the file has nothing but leaves).
    pub fn bake_gltf(
        &mut self,
        path: impl AsRef<Path>,
        leaves: &GltfLeafSettings,
        settings: &BakeSettings,
    ) -> Result<(Handle<BakedFoliage>, Option<Handle<Mesh>>), TreeSpawnError> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| TreeSpawnError::Io(path.into(), e))?;
        let tree = load_gltf_tree(&bytes, path.parent(), leaves)
            .map_err(|e| TreeSpawnError::Gltf(path.into(), e))?;
        let (baked, timings) = bake(&tree.leaves, settings, &|_| {})
            .map_err(|e| TreeSpawnError::Bake(path.into(), e))?;
        if baked.skipped.total() > 0 {
            warn!("{}: skipped {:?} leaves", path.display(), baked.skipped);
        }
        info!(
            "baked {} ({} leaves, {} cells) in {:.0} ms",
            path.display(),
            baked.leaf_count(),
            baked.cell_count(),
            timings.total().as_secs_f64() * 1e3
        );
        let bark = (!tree.bark.indices.is_empty()).then(|| self.meshes.add(bark_mesh(&tree.bark)));
        Ok((self.baked.add(baked), bark))
    }

    /// Reads, bakes (default [`BakeSettings`]) and spawns a glTF tree in one call; `leaves` is
    /// the look of its leaves (the file's own textures are not read: give the leaf texture here,
    /// with [`leaf_material_textured`](super::material::leaf_material_textured)'s opaque fraction
    /// if it is alpha-masked). The bark gets a plain bark material.
    pub fn spawn_gltf(
        &mut self,
        commands: &mut Commands,
        path: impl AsRef<Path>,
        leaf_settings: &GltfLeafSettings,
        leaves: StandardMaterial,
        transform: Transform,
    ) -> Result<Entity, TreeSpawnError> {
        let path = path.as_ref();
        let (baked, bark) = self.bake_gltf(path, leaf_settings, &BakeSettings::default())?;
        let name = path
            .file_stem()
            .map_or_else(|| "tree".into(), |s| s.to_string_lossy().into_owned());
        let material = self.leaf_materials.add(leaf_material(leaves));
        Ok(self.spawn_parts(commands, &name, baked, bark, material, transform))
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

#[cfg(test)]
mod tests {
    use super::*;
    use bevy::ecs::system::RunSystemOnce;

    fn app() -> App {
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, AssetPlugin::default()))
            .init_asset::<Mesh>()
            .init_asset::<StandardMaterial>()
            .init_asset::<BakedFoliage>()
            .init_asset::<LeafMaterial>();
        app
    }

    #[test]
    fn a_gltf_tree_spawns_in_one_call_with_bark_and_pruned_leaves() {
        let dir = std::env::temp_dir().join(format!("bevy_foliage_spawn_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("sample.gltf");
        std::fs::write(&path, super::super::gltf::tests::sample_tree()).unwrap();
        let mut app = app();
        let spawned = app
            .world_mut()
            .run_system_once(move |mut commands: Commands, mut assets: TreeAssets| {
                assets.spawn_gltf(
                    &mut commands,
                    &path,
                    &GltfLeafSettings::default(),
                    default_leaf_material(),
                    Transform::from_xyz(1.0, 0.0, 0.0),
                )
            })
            .unwrap()
            .unwrap();
        app.update();
        let world = app.world_mut();
        let pruned = world.get::<PrunedFoliage>(spawned).unwrap().clone();
        let baked = world
            .resource::<Assets<BakedFoliage>>()
            .get(&pruned.baked)
            .unwrap();
        // The sample's 3 usable leaves (a degenerate and a NaN leaf are skipped and counted).
        assert_eq!(baked.leaf_count(), 3);
        assert_eq!(baked.skipped.total(), 2);
        assert_eq!(world.get::<Name>(spawned).unwrap().as_str(), "sample");
        let children = world.get::<Children>(spawned).unwrap().to_vec();
        assert_eq!(children.len(), 1);
        let bark = world.get::<Mesh3d>(children[0]).unwrap().0.clone();
        let mesh = world.resource::<Assets<Mesh>>().get(&bark).unwrap();
        assert_eq!(mesh.indices().unwrap().len(), 3, "the bark triangle");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn missing_and_leafless_files_are_errors() {
        let mut app = app();
        let missing = app
            .world_mut()
            .run_system_once(|mut commands: Commands, mut assets: TreeAssets| {
                assets.spawn_gltf(
                    &mut commands,
                    "/nonexistent/tree.glb",
                    &GltfLeafSettings::default(),
                    default_leaf_material(),
                    Transform::IDENTITY,
                )
            })
            .unwrap();
        assert!(
            matches!(missing, Err(TreeSpawnError::Io(..))),
            "{missing:?}"
        );
        let dir =
            std::env::temp_dir().join(format!("bevy_foliage_spawn_bad_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bad.gltf");
        std::fs::write(&path, "{ not gltf").unwrap();
        let bad = app
            .world_mut()
            .run_system_once(move |mut commands: Commands, mut assets: TreeAssets| {
                assets.spawn_gltf(
                    &mut commands,
                    &path,
                    &GltfLeafSettings::default(),
                    default_leaf_material(),
                    Transform::IDENTITY,
                )
            })
            .unwrap();
        let message = bad.unwrap_err().to_string();
        assert!(
            message.contains("bad.gltf") && message.contains("not a valid glTF"),
            "{message}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
