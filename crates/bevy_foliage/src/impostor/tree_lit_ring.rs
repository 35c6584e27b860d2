//! Gives each tree-lit billboard cloud its tree type's ring of re-gathered bounce ratios, as the
//! crown's mean ([`crate::lighting::bounce_ring::crown_mean_ring`]): near the cloud's hand-over
//! the leaves read their own ring where the sun is at its elevation, so the cloud, whose texels
//! have no room for their leaves' own ratios, reads the crown's mean of it (and the crown's mean
//! of the bake's ratios where not), and the crown keeps its light when the cloud takes over.

use super::assets::BillboardCloudAsset;
use super::systems::TreeImpostor;
use super::tree_lit::{TreeLitImpostorMaterial, ratios_as_vectors};
use crate::forest::components::ForestTree;
use crate::lighting::bounce_ring::NO_RING;
use crate::pruning::bake::BakedFoliage;
use crate::pruning::regather::BounceRings;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;

/// Writes each tree-lit cloud material's ring (its sun height and crown-mean ratios, or none)
/// from the [`BounceRings`] of the type its forest trees are drawn with (the first such tree's,
/// where trees of several types share a cloud), when a ring has come in or trees have taken
/// impostors, and while a tree's cloud is still loading.
pub fn ring_tree_lit_impostors(
    rings: Res<BounceRings>,
    trees: Query<(&ForestTree, &TreeImpostor)>,
    changed: Query<(), Changed<TreeImpostor>>,
    clouds: Res<Assets<BillboardCloudAsset>>,
    mut materials: ResMut<Assets<TreeLitImpostorMaterial>>,
    mut last: Local<(Option<u64>, bool)>,
) {
    let (generation, pending) = *last;
    if generation == Some(rings.generation()) && !pending && changed.is_empty() {
        return;
    }
    let mut of: HashMap<AssetId<TreeLitImpostorMaterial>, AssetId<BakedFoliage>> =
        HashMap::default();
    let mut loading = false;
    for (tree, impostor) in &trees {
        match clouds.get(&impostor.0) {
            Some(cloud) => {
                of.entry(cloud.tree_lit.id()).or_insert(tree.baked.id());
            }
            None => loading = true,
        }
    }
    for (material, baked) in of {
        let (height, ratios) = match rings.crown_mean(baked) {
            Some((height, mean)) => (
                height,
                ratios_as_vectors(&mean.map(|n| n[0]), &mean.map(|n| n[1])),
            ),
            None => (NO_RING, [Vec4::ONE; 7]),
        };
        let Some(current) = materials.get(material) else {
            continue;
        };
        let params = &current.extension.params;
        if (params.ring_height != height || params.ring_ratios != ratios)
            && let Some(mut m) = materials.get_mut(material)
        {
            m.extension.params.ring_height = height;
            m.extension.params.ring_ratios = ratios;
        }
    }
    *last = (Some(rings.generation()), loading);
}

/// Registers [`ring_tree_lit_impostors`], after the rings are collected.
pub(crate) fn build(app: &mut App) {
    app.add_systems(
        PostUpdate,
        ring_tree_lit_impostors.after(crate::pruning::systems::FoliageSystems::Store),
    );
}
