//! Settings of the clip stack (Seoane et al. 2007, §3–4).

use bevy::prelude::*;

/// How much updating a virtual texture may do per frame.
///
/// The paper spends 1 ms per texture per frame; a subtile or byte budget is the deterministic
/// equivalent that tests and benchmarks use.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
#[reflect(Debug, PartialEq)]
pub enum UpdateBudget {
    /// Milliseconds of update work per frame per virtual texture.
    Millis(f32),
    /// Subtiles uploaded per frame per virtual texture.
    Subtiles(u32),
    /// Bytes uploaded per frame per virtual texture.
    Bytes(u64),
}

impl Default for UpdateBudget {
    fn default() -> Self {
        Self::Millis(1.0)
    }
}

/// Global settings of the clipmap virtual textures.
#[derive(Resource, Clone, Debug, PartialEq, Reflect)]
#[reflect(Resource, Default, Debug, PartialEq)]
pub struct ClipmapSettings {
    /// Clip size c: each stack layer is c × c texels (power of two).
    pub clip_size: u32,
    /// Subtile size s: the unit of update (power of two, smaller than `clip_size`).
    pub subtile_size: u32,
    /// Mips kept per finer layer for trilinear filtering (m in the paper).
    pub layer_mips: u32,
    /// Tiles the RAM cache holds (n).
    pub cache_tiles: u32,
    /// Per-frame update budget per virtual texture.
    pub budget: UpdateBudget,
    /// What the terrain shows where the pyramid has no data: outside its extent (never repeated
    /// copies of it), over transparent padding, and where the base level's tiles are missing or
    /// failed (a finer layer's missing subtile shows the coarser level instead).
    pub no_data_color: Color,
}

/// The default [`ClipmapSettings::no_data_color`]: a neutral grey-beige, plainly not imagery.
pub const NO_DATA_COLOR: Color = Color::srgb(0.55, 0.53, 0.49);

impl Default for ClipmapSettings {
    fn default() -> Self {
        Self {
            clip_size: 1024,
            subtile_size: 128,
            layer_mips: 3,
            cache_tiles: 256,
            budget: UpdateBudget::default(),
            no_data_color: NO_DATA_COLOR,
        }
    }
}

impl ClipmapSettings {
    /// Slots per side of a layer's toroidal grid: c / s.
    pub fn slots_per_side(&self) -> u32 {
        self.clip_size / self.subtile_size
    }

    /// Returns valid settings and the corrections made: sizes rounded up to powers of two, the
    /// subtile made smaller than the clip, mips bounded by the subtile size, budgets positive.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let mut out = self.clone();
        let mut fixes = Vec::new();
        let pow2 = |v: u32, min: u32| v.max(min).checked_next_power_of_two().unwrap_or(1 << 31);
        let clip = pow2(out.clip_size, 64).min(16384);
        if clip != out.clip_size {
            fixes.push(format!(
                "clip_size {} -> {clip} (power of two in 64..=16384)",
                out.clip_size
            ));
            out.clip_size = clip;
        }
        let subtile = pow2(out.subtile_size, 16).min(out.clip_size / 2);
        if subtile != out.subtile_size {
            fixes.push(format!(
                "subtile_size {} -> {subtile} (power of two, at most clip_size / 2)",
                out.subtile_size
            ));
            out.subtile_size = subtile;
        }
        let max_mips = out.subtile_size.trailing_zeros() + 1;
        if out.layer_mips == 0 || out.layer_mips > max_mips {
            let m = out.layer_mips.clamp(1, max_mips);
            fixes.push(format!(
                "layer_mips {} -> {m} (1..={max_mips})",
                out.layer_mips
            ));
            out.layer_mips = m;
        }
        if out.cache_tiles < 16 {
            fixes.push(format!("cache_tiles {} -> 16", out.cache_tiles));
            out.cache_tiles = 16;
        }
        let budget_ok = match out.budget {
            UpdateBudget::Millis(ms) => ms.is_finite() && ms > 0.0,
            UpdateBudget::Subtiles(n) => n > 0,
            UpdateBudget::Bytes(b) => b > 0,
        };
        let colour = out.no_data_color.to_linear();
        if ![colour.red, colour.green, colour.blue, colour.alpha]
            .iter()
            .all(|c| c.is_finite())
        {
            fixes.push(format!(
                "no_data_color {:?} -> {NO_DATA_COLOR:?} (not finite)",
                out.no_data_color
            ));
            out.no_data_color = NO_DATA_COLOR;
        }
        if !budget_ok {
            fixes.push(format!(
                "budget {:?} -> {:?}",
                out.budget,
                UpdateBudget::default()
            ));
            out.budget = UpdateBudget::default();
        }
        (out, fixes)
    }
}

/// Replaces invalid settings with corrected ones, logging each correction.
pub(crate) fn sanitize_clipmap_settings(mut settings: ResMut<ClipmapSettings>) {
    let (fixed, fixes) = settings.sanitized();
    if !fixes.is_empty() {
        for fix in &fixes {
            warn!("ClipmapSettings: {fix}");
        }
        *settings = fixed;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_match_the_paper_test_configuration_and_are_valid() {
        let s = ClipmapSettings::default();
        assert_eq!((s.clip_size, s.subtile_size), (1024, 128));
        assert_eq!(s.slots_per_side(), 8);
        let (same, fixes) = s.sanitized();
        assert!(fixes.is_empty(), "{fixes:?}");
        assert_eq!(same, s);
    }

    #[test]
    fn absurd_sizes_and_budgets_are_corrected() {
        let bad = ClipmapSettings {
            clip_size: 1000,
            subtile_size: 4096,
            layer_mips: 0,
            cache_tiles: 0,
            budget: UpdateBudget::Millis(f32::NAN),
            no_data_color: Color::srgb(f32::NAN, 0.5, 0.5),
        };
        let (s, fixes) = bad.sanitized();
        assert_eq!(fixes.len(), 6, "{fixes:?}");
        assert_eq!(s.no_data_color, NO_DATA_COLOR);
        assert_eq!(s.clip_size, 1024);
        assert_eq!(s.subtile_size, 512);
        assert!(s.layer_mips >= 1);
        assert_eq!(s.cache_tiles, 16);
        assert_eq!(s.budget, UpdateBudget::Millis(1.0));
        assert_eq!(s.clip_size % s.subtile_size, 0);
    }
}
