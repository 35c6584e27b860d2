//! Spawning procedural pruned trees in one call: generate, bake, and spawn the bark as an
//! ordinary mesh with the leaves as a [`PrunedFoliage`] set.

use super::bake::{BakeError, BakeSettings, BakedFoliage, bake};
use super::gpu::PrunedFoliage;
use super::material::{LeafMaterial, leaf_material};
use super::procedural::{TreeSpecies, generate};
use bevy::ecs::system::SystemParam;
use bevy::prelude::*;

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

/// The default look of procedural leaves and bark.
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
        Ok((self.baked.add(baked), self.meshes.add(tree.bark.to_mesh())))
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
        let bark_material = self.materials.add(StandardMaterial {
            base_color: Color::srgb(0.35, 0.27, 0.2),
            perceptual_roughness: 0.95,
            ..default()
        });
        commands
            .spawn((
                Name::new(name.to_string()),
                PrunedFoliage { baked, material },
                transform,
            ))
            .with_child((
                Name::new("bark"),
                Mesh3d(bark),
                MeshMaterial3d(bark_material),
            ))
            .id()
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
