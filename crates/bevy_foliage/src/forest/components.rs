//! The forest on the ECS: what a game puts on its tree instances ([`ForestTree`]), what the
//! manager writes back ([`TreeLod`]), and its settings ([`ForestSettings`]).

use super::cache::LodSlots;
use super::feedback::FeedbackSettings;
use crate::pruning::bake::BakedFoliage;
use crate::pruning::material::LeafMaterial;
use bevy::prelude::*;

/// A tree of a forest. Its leaves are drawn from its type's LoD cache as the forest manager
/// decides; its bark, if any, is an ordinary child mesh.
#[derive(Component, Clone, Debug)]
#[require(Transform, Visibility, TreeLod)]
pub struct ForestTree {
    /// The tree type's baked pruning data.
    pub baked: Handle<BakedFoliage>,
    /// How its leaves look.
    pub material: Handle<LeafMaterial>,
}

/// The manager's view of one tree (written by the plugin; read it to inspect).
#[derive(Component, Clone, Copy, Debug, Default, PartialEq, Reflect)]
#[reflect(Component, Default, Debug)]
pub struct TreeLod {
    /// Cache slot it draws (`None`: nothing yet).
    pub slot: Option<u32>,
    /// LoD of the extraction it draws.
    pub stored_lod: f32,
    /// Desired LoD this frame (eq. 4.3).
    pub desired_lod: f32,
    /// Frames since it was last served.
    pub frames_since_update: u32,
    /// Urgency this frame (eq. 3.12).
    pub urgency: f32,
    /// In the view frustum this frame.
    pub visible: bool,
    /// With [`MixedLodSettings`]: how far it has faded over to its billboard cloud (0 pruned
    /// geometry, 1 impostor).
    pub impostor_weight: f32,
    /// The manager's whole memory of the tree, kept on the tree so that a forest of 100,000
    /// trees needs no per-frame map from entities to states.
    #[reflect(ignore)]
    pub(crate) state: super::manager::TreeLodState,
}

/// The time-critical mixed level of detail (seed 001, ch. 8; [`crate::forest::mixed`]): every
/// frame, under a budget of triangles, every visible tree is drawn either by pruned geometry at
/// the resolution the benefit-per-cost selection gives it, or by its billboard cloud
/// ([`TreeImpostor`](crate::impostor::systems::TreeImpostor)). A tree that changes
/// representation cross-fades over `fade_frames` frames: its impostor dithers in (Bevy's
/// visibility-range dithering, driven by time) while its leaves thin out by pruning.
///
/// Off (the default): the distance LoD of eq. 4.2–4.3, impostors beyond `far`.
#[derive(Clone, Debug, PartialEq, Reflect)]
#[reflect(Default, Debug, PartialEq)]
pub struct MixedLodSettings {
    /// Use it.
    pub enabled: bool,
    /// Cost allowed per frame, in leaf-triangle units.
    pub budget_triangles: f32,
    /// The geometry resolution a billboard cloud is worth.
    pub impostor_equivalent_lod: f32,
    /// The smallest geometry resolution.
    pub min_lod: f32,
    /// Draw overhead of one tree, in triangles.
    pub tree_cost: f32,
    /// Cost of an impostor triangle in leaf triangles (large alpha-tested quads).
    pub impostor_fill_weight: f32,
    /// Frames a change of representation fades over.
    pub fade_frames: u32,
}

impl Default for MixedLodSettings {
    fn default() -> Self {
        let m = super::mixed::MixedSettings::default();
        Self {
            enabled: false,
            budget_triangles: m.budget,
            impostor_equivalent_lod: m.impostor_equivalent_lod,
            min_lod: m.min_lod,
            tree_cost: m.tree_cost,
            impostor_fill_weight: m.impostor_fill_weight,
            fade_frames: 8,
        }
    }
}

impl MixedLodSettings {
    /// The selection's settings.
    pub fn selection(&self) -> super::mixed::MixedSettings {
        super::mixed::MixedSettings {
            budget: self.budget_triangles,
            k: 50.0,
            impostor_equivalent_lod: self.impostor_equivalent_lod,
            min_lod: self.min_lod,
            tree_cost: self.tree_cost,
            impostor_fill_weight: self.impostor_fill_weight,
        }
    }
}

/// Work allowed per frame.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
#[reflect(Debug, PartialEq)]
pub enum ForestBudget {
    /// At most this many extractions per frame (deterministic).
    Extractions(u32),
    /// Stop serving trees after the manager ran this many milliseconds.
    Milliseconds(f32),
}

/// Settings of the forest manager. Near/far distances are
/// [`FoliagePruningSettings::distances`](crate::FoliagePruningSettings::distances).
#[derive(Resource, Clone, Debug, PartialEq, Reflect)]
#[reflect(Resource, Default, Debug, PartialEq)]
pub struct ForestSettings {
    /// Run the manager. Off: every tree the manager would show (in the frustum and nearer than
    /// `far`) draws every leaf, for comparison.
    pub enabled: bool,
    /// Uniform range slots per type (eq. 4.4), used when `slot_bounds` is empty.
    pub slots: u32,
    /// Non-uniform slot bounds `[0, …, 1]` (finer near LoD 1 puts more slots near the camera).
    pub slot_bounds: Vec<f32>,
    /// Frames an extraction stays borrowable (extractions are view-dependent).
    pub max_age_frames: u32,
    /// Share extractions between trees of a type (the LoD cache). Off: chapter 3's manager,
    /// one extraction per tree.
    pub borrowing: bool,
    /// Two GPU copies per slot; borrow only last frame's.
    pub double_buffered: bool,
    /// Work per frame.
    pub budget: ForestBudget,
    /// Steer detail with the frame-rate feedback exponent (eq. 4.3).
    pub feedback: bool,
    /// The exponent n of eq. 4.3 while `feedback` is off (1: the linear LoD of eq. 4.2; above 1
    /// less detail, below 1 more).
    pub exponent: f32,
    /// The feedback controller's settings.
    pub feedback_settings: FeedbackSettings,
    /// The time-critical mixed LoD (off by default).
    pub mixed: MixedLodSettings,
}

impl Default for ForestSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            slots: 8,
            slot_bounds: Vec::new(),
            max_age_frames: 30,
            borrowing: true,
            double_buffered: false,
            budget: ForestBudget::Extractions(16),
            feedback: false,
            exponent: 1.0,
            feedback_settings: FeedbackSettings::default(),
            mixed: MixedLodSettings::default(),
        }
    }
}

impl ForestSettings {
    /// These settings with unusable values replaced (and what was replaced, for the log).
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let d = Self::default();
        let mut s = self.clone();
        let mut fixes = Vec::new();
        if !(1..=1024).contains(&s.slots) {
            fixes.push(format!(
                "slots = {} must be in 1..=1024: using {}",
                s.slots, d.slots
            ));
            s.slots = d.slots;
        }
        if !s.slot_bounds.is_empty()
            && let Err(e) = LodSlots::from_bounds(s.slot_bounds.clone())
        {
            fixes.push(format!("{e}: using {} uniform slots", s.slots));
            s.slot_bounds.clear();
        }
        match s.budget {
            ForestBudget::Extractions(0) => {
                fixes.push("an extraction budget of 0 would never update a tree: using 1".into());
                s.budget = ForestBudget::Extractions(1);
            }
            ForestBudget::Milliseconds(ms) if !(ms.is_finite() && ms > 0.0) => {
                fixes.push(format!(
                    "a time budget of {ms} ms must be positive and finite: using {:?}",
                    d.budget
                ));
                s.budget = d.budget;
            }
            _ => {}
        }
        if !(s.exponent.is_finite() && s.exponent > 0.0) {
            fixes.push(format!(
                "exponent = {} must be positive: using 1",
                s.exponent
            ));
            s.exponent = 1.0;
        }
        let (selection, mixed_fixes) = s.mixed.selection().sanitized();
        if !mixed_fixes.is_empty() {
            fixes.extend(mixed_fixes.into_iter().map(|f| format!("mixed: {f}")));
            s.mixed = MixedLodSettings {
                enabled: s.mixed.enabled,
                budget_triangles: selection.budget,
                impostor_equivalent_lod: selection.impostor_equivalent_lod,
                min_lod: selection.min_lod,
                tree_cost: selection.tree_cost,
                impostor_fill_weight: selection.impostor_fill_weight,
                fade_frames: s.mixed.fade_frames,
            };
        }
        if !(1..=120).contains(&s.mixed.fade_frames) {
            fixes.push(format!(
                "mixed: fade_frames = {} must be in 1..=120: using 8",
                s.mixed.fade_frames
            ));
            s.mixed.fade_frames = 8;
        }
        let (feedback, feedback_fixes) = s.feedback_settings.sanitized();
        s.feedback_settings = feedback;
        fixes.extend(
            feedback_fixes
                .into_iter()
                .map(|f| format!("feedback_settings: {f}")),
        );
        (s, fixes)
    }

    /// The slot layout, or the reason the bounds are unusable.
    pub fn lod_slots(&self) -> Result<LodSlots, super::cache::SlotBoundsError> {
        if self.slot_bounds.is_empty() {
            Ok(LodSlots::uniform(self.slots.clamp(1, 1024)))
        } else {
            LodSlots::from_bounds(self.slot_bounds.clone())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_forest_settings_are_replaced() {
        let bad = ForestSettings {
            slots: 0,
            slot_bounds: vec![0.0, 0.7, 0.3, 1.0],
            budget: ForestBudget::Extractions(0),
            exponent: f32::NAN,
            ..default()
        };
        let (fixed, fixes) = bad.sanitized();
        assert_eq!(fixes.len(), 4, "{fixes:?}");
        assert_eq!(fixed.slots, 8);
        assert!(fixed.slot_bounds.is_empty());
        assert_eq!(fixed.budget, ForestBudget::Extractions(1));
        assert_eq!(fixed.exponent, 1.0);
        let (time, fixes) = ForestSettings {
            budget: ForestBudget::Milliseconds(-2.0),
            ..default()
        }
        .sanitized();
        assert_eq!(fixes.len(), 1);
        assert_eq!(time.budget, ForestSettings::default().budget);
        let (same, none) = ForestSettings::default().sanitized();
        assert!(none.is_empty());
        assert_eq!(same, ForestSettings::default());
    }
}
