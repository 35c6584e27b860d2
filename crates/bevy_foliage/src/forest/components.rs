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
