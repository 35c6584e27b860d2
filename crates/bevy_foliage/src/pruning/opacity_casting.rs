//! How a pruned tree's leaves are drawn into the trees' world-space opacity shadow map
//! (Boulanger 2008, §5.5.2.1; the map itself is `bevy_soft_shadows::foliage::opacity_map`):
//! plain Rust, the CPU reference of `opacity_shadow.wgsl`.
//!
//! The map draws what the tree's shadow views draw — the light's own pruned selection
//! ([`super::selection`]) — with each kept leaf enlarged about its centroid by the area
//! compensation of eq. 3.9, so that the pruned crown keeps its darkness (the leaves a sun ray
//! meets stay Poisson distributed with the same mean), and shrunk to its texture's opaque area:
//! the map has no alpha test, so a leaf card counts as the fraction of it that is leaf
//! (statistically the same shadow, the argument of the compensation run backwards).

use super::appearance::compensation_scale;
use super::bake::BakedFoliage;
use super::extract::Extraction;
use bevy::math::{Affine3A, Vec3};
use bevy_soft_shadows::foliage::opacity_map::{LEAF_TRANSPARENCY, OpacityShadowMap};

/// How a tree's leaves cast into the map (from its leaf material's parameters).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeafCasting {
    /// Enlarge kept leaves to preserve the crown's leaf area (eq. 3.7–3.9).
    pub area_compensation: bool,
    /// Cap of the linear compensation scale.
    pub max_scale: f32,
    /// Fraction of the leaf texture that is opaque (1 for untextured leaves).
    pub opaque_fraction: f32,
}

impl LeafCasting {
    /// The linear scale about its centroid of a kept leaf of a cell at `LoD(cell) = lod`.
    pub fn scale(&self, lod: u32) -> f32 {
        let opaque = self.opaque_fraction.clamp(1e-3, 1.0).sqrt();
        if self.area_compensation {
            opaque * compensation_scale(lod, self.max_scale)
        } else {
            opaque
        }
    }
}

/// Draws the leaves `extraction` keeps of `baked`, placed by `world_from_local`, into `map`.
pub fn draw_pruned_leaves(
    map: &mut OpacityShadowMap,
    baked: &BakedFoliage,
    extraction: &Extraction,
    world_from_local: Affine3A,
    casting: &LeafCasting,
) {
    for (cell, (&offset, &count)) in extraction
        .offsets
        .iter()
        .zip(&extraction.kept_indices)
        .enumerate()
    {
        let scale = casting.scale(extraction.lods[cell]);
        let indices = &extraction.indices[offset as usize..(offset + count) as usize];
        for triangle in indices.chunks_exact(3) {
            let corner = |i: u32| -> Vec3 {
                let i = i as usize;
                let e = baked.centroid_offsets[i];
                world_from_local.transform_point3(baked.positions[i] - e + e * scale)
            };
            map.draw(
                [
                    corner(triangle[0]),
                    corner(triangle[1]),
                    corner(triangle[2]),
                ],
                LEAF_TRANSPARENCY,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pruning::bake::{BakeSettings, CellCount, bake};
    use crate::pruning::extract::{
        FIXED_ONE, KEEP_ALL, UNIFORM_DISTANCE, extract_indices, view_weights,
    };
    use crate::pruning::procedural::{TreeSpecies, generate};
    use crate::settings::ViewWeighting;
    use bevy_soft_shadows::foliage::opacity_map::OpacityShadowPlane;

    fn tree() -> BakedFoliage {
        let tree = generate(&TreeSpecies::olea().with_leaf_count(2000));
        let settings = BakeSettings {
            cells: CellCount::Depth(6),
            resolution: 96,
            ..BakeSettings::default()
        };
        bake(&tree.leaves, &settings, &|_| {}).unwrap().0
    }

    /// Mean transmittance over the texels some leaf shades in the full crown's map.
    fn shadow_of(baked: &BakedFoliage, distance_fixed: u32, casting: &LeafCasting) -> (f32, f32) {
        let to_light = Vec3::new(0.3, 1.0, 0.2).normalize();
        let (lo, hi) = baked
            .positions
            .iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
                (lo.min(p), hi.max(p))
            });
        let plane = OpacityShadowPlane::fit(lo - 0.5, hi + 0.5, to_light, 0.0, (128, 128)).unwrap();
        let full = extract_indices(
            &baked.pruning_input(),
            &view_weights(
                to_light,
                &baked.view_directions,
                ViewWeighting::InverseAngle,
            ),
            KEEP_ALL,
        );
        let mut reference = OpacityShadowMap::new(plane);
        draw_pruned_leaves(&mut reference, baked, &full, Affine3A::IDENTITY, casting);
        let weights = view_weights(
            to_light,
            &baked.view_directions,
            ViewWeighting::InverseAngle,
        );
        let pruned = extract_indices(&baked.pruning_input(), &weights, distance_fixed);
        let mut map = OpacityShadowMap::new(plane);
        draw_pruned_leaves(&mut map, baked, &pruned, Affine3A::IDENTITY, casting);
        let shaded: Vec<usize> = (0..reference.texels.texels.len())
            .filter(|&i| reference.texels.texels[i][1] < 1.0)
            .collect();
        let mean = |m: &OpacityShadowMap| {
            shaded.iter().map(|&i| m.texels.texels[i][1]).sum::<f32>() / shaded.len() as f32
        };
        (mean(&reference), mean(&map))
    }

    /// A crown pruned to a half, a third and a fifth of its leaves without the view term keeps
    /// the darkness of its shadow with the area compensation, and loses it without; the view
    /// term (the selection for a depth map) drops the cells the sun does not see, and with them
    /// their attenuation.
    #[test]
    fn a_pruned_crown_keeps_its_darkness() {
        let baked = tree();
        let compensated = LeafCasting {
            area_compensation: true,
            max_scale: 4.0,
            opaque_fraction: 1.0,
        };
        let bare = LeafCasting {
            area_compensation: false,
            ..compensated
        };
        for fraction in [FIXED_ONE / 2, FIXED_ONE / 3, FIXED_ONE / 5] {
            let uniform = fraction | UNIFORM_DISTANCE;
            let (full, pruned) = shadow_of(&baked, uniform, &compensated);
            assert!(full < 0.6, "the full crown's shadow is dark: {full}");
            assert!(
                (pruned - full).abs() < 0.02,
                "{fraction}: compensated {pruned} vs full {full}"
            );
            let (_, thin) = shadow_of(&baked, uniform, &bare);
            assert!(
                thin > full + 0.1,
                "{fraction}: uncompensated {thin} vs full {full}"
            );
            let (_, seen) = shadow_of(&baked, fraction, &compensated);
            assert!(
                seen > full + 0.1,
                "{fraction}: with the view term {seen} vs full {full}"
            );
        }
    }

    /// A leaf texture half opaque casts as a card of half the area: a lighter shadow, placed
    /// where the full card's is.
    #[test]
    fn cards_cast_their_opaque_area() {
        let casting = LeafCasting {
            area_compensation: true,
            max_scale: 4.0,
            opaque_fraction: 1.0,
        };
        assert_eq!(casting.scale(FIXED_ONE), 1.0);
        assert!((casting.scale(FIXED_ONE / 4) - 2.0).abs() < 1e-6);
        let half = LeafCasting {
            opaque_fraction: 0.5,
            ..casting
        };
        assert!((half.scale(FIXED_ONE) - 0.5f32.sqrt()).abs() < 1e-6);
        let baked = tree();
        let (card, _) = shadow_of(&baked, KEEP_ALL, &casting);
        let (half_card, _) = shadow_of(&baked, KEEP_ALL, &half);
        assert!(half_card > card + 0.05, "{half_card} vs {card}");
    }
}
