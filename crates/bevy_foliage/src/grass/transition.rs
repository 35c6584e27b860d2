//! Which representation draws a grass blade at a distance, and how opaque (Boulanger 2008,
//! thesis ch. 4, §4.2.5 and §4.2.7.3): the seamless transitions between blade geometry, vertical
//! volume slices and the horizontal slice.
//!
//! Each representation weights the local density by a function of the distance `d` to the
//! viewer (eq. 4.3–4.5; eq. 4.14 adds vertical slices on hill silhouettes). A blade whose density
//! threshold `dth` exceeds the local density `ld` is not drawn at all; of the others, those with
//! `dth < w_vs(d)·ld` go to the slices and the rest stay geometry, with opacity ramps over a
//! window `±ω·ld` around the split (algorithm 1, eq. 4.6). The two ramps are complementary, so at
//! every distance a blade's geometry and slice opacities sum to one: the coverage stays whole as
//! blades change representation. ω narrows near the ends of the weight's range (fig. 4.13) so no
//! blade stays semi-transparent once the transition is over.

use bevy::reflect::Reflect;

/// The user distances of fig. 4.11 (m) and the transition window of fig. 4.13.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
#[reflect(Debug, PartialEq)]
pub struct TransitionDistances {
    /// Geometry alone up to here.
    pub min_geom: f32,
    /// No geometry beyond here: slices alone.
    pub max_geom: f32,
    /// Vertical slices at full weight up to here.
    pub min_btf: f32,
    /// No vertical slices beyond here (except on silhouettes): the horizontal slice alone.
    pub max_btf: f32,
    /// Vertical slices on hill silhouettes up to here (eq. 4.13–4.14): beyond, a blade is under a
    /// pixel.
    pub max_silhouettes: f32,
    /// ε of eq. 4.13: a point is on a silhouette where `|N·V̂| < ε`.
    pub silhouette_epsilon: f32,
    /// ω_max of fig. 4.13: the half-width of the transition window (a fraction of the local
    /// density) at its widest.
    pub omega_max: f32,
    /// ω₀ of fig. 4.13: the window's floor as a fraction of ω_max (0.05 in the thesis).
    pub omega_0: f32,
}

impl Default for TransitionDistances {
    fn default() -> Self {
        Self {
            min_geom: 8.0,
            max_geom: 16.0,
            min_btf: 40.0,
            max_btf: 80.0,
            max_silhouettes: 400.0,
            silhouette_epsilon: 0.2,
            omega_max: 0.25,
            omega_0: 0.05,
        }
    }
}

/// Why a [`TransitionDistances`] cannot be used as it is.
#[derive(Clone, Debug, PartialEq)]
pub enum TransitionError {
    /// A distance or fraction is not finite.
    NotFinite(&'static str),
    /// The distances must satisfy `0 ≤ min_geom < max_geom ≤ min_btf < max_btf ≤ max_silhouettes`.
    Order,
    /// `omega_max` must be in `(0, 0.5]`, `omega_0` in `(0, 1]`, `silhouette_epsilon` in `[0, 1]`.
    Window,
}

impl std::fmt::Display for TransitionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotFinite(what) => write!(f, "grass transition {what} is not finite"),
            Self::Order => write!(
                f,
                "grass transition distances must satisfy 0 ≤ min_geom < max_geom ≤ min_btf < \
                 max_btf ≤ max_silhouettes"
            ),
            Self::Window => write!(
                f,
                "grass transition window: omega_max in (0, 0.5], omega_0 in (0, 1], \
                 silhouette_epsilon in [0, 1]"
            ),
        }
    }
}

impl std::error::Error for TransitionError {}

impl TransitionDistances {
    /// Checks the distances and the window.
    pub fn validate(&self) -> Result<(), TransitionError> {
        for (name, v) in [
            ("min_geom", self.min_geom),
            ("max_geom", self.max_geom),
            ("min_btf", self.min_btf),
            ("max_btf", self.max_btf),
            ("max_silhouettes", self.max_silhouettes),
            ("silhouette_epsilon", self.silhouette_epsilon),
            ("omega_max", self.omega_max),
            ("omega_0", self.omega_0),
        ] {
            if !v.is_finite() {
                return Err(TransitionError::NotFinite(name));
            }
        }
        if !(0.0 <= self.min_geom
            && self.min_geom < self.max_geom
            && self.max_geom <= self.min_btf
            && self.min_btf < self.max_btf
            && self.max_btf <= self.max_silhouettes)
        {
            return Err(TransitionError::Order);
        }
        if !(self.omega_max > 0.0
            && self.omega_max <= 0.5
            && self.omega_0 > 0.0
            && self.omega_0 <= 1.0
            && (0.0..=1.0).contains(&self.silhouette_epsilon))
        {
            return Err(TransitionError::Window);
        }
        Ok(())
    }

    /// Eq. 4.3: the weight of blade geometry at distance `d`.
    pub fn geometry_weight(&self, d: f32) -> f32 {
        ramp(d, self.max_geom, self.min_geom)
    }

    /// Eq. 4.14 (eq. 4.4 off silhouettes): the weight of the vertical slices at distance `d`,
    /// where the ground's normal and the unit view vector make `n_dot_v`.
    pub fn vertical_weight(&self, d: f32, n_dot_v: f32) -> f32 {
        let distance = ramp(d, self.min_geom, self.max_geom) * ramp(d, self.max_btf, self.min_btf);
        let silhouette = if d >= self.max_btf && d <= self.max_silhouettes {
            let e = self.silhouette_epsilon.max(1e-6);
            1.0 - (n_dot_v.abs() / e).min(1.0)
        } else {
            0.0
        };
        (distance + silhouette).min(1.0)
    }

    /// Whether the vertical slices' weight (eq. 4.4 / 4.14) can be above zero somewhere in a
    /// region whose points lie `near` to `far` from the eye, where `|N·V̂|` is at least
    /// `min_n_dot_v` — else the region needs only its horizontal slice, and the vertical quads
    /// there would rasterise fragments that all discard (a view along the ground crosses
    /// hundreds of them).
    pub fn vertical_may_show(&self, near: f32, far: f32, min_n_dot_v: f32) -> bool {
        let between_transitions = near < self.max_btf && far > self.min_geom;
        let silhouette = far >= self.max_btf
            && near <= self.max_silhouettes
            && min_n_dot_v < self.silhouette_epsilon;
        between_transitions || silhouette
    }

    /// Eq. 4.5: the weight of the horizontal slice at distance `d`.
    pub fn horizontal_weight(&self, d: f32) -> f32 {
        ramp(d, self.min_geom, self.max_geom)
    }

    /// Fig. 4.13: the window's half-width for weight `w` (a fraction of the local density),
    /// narrowest at `w = 0` and `w = 1` so the transition region stays inside `[0, ld]`.
    pub fn omega(&self, w: f32) -> f32 {
        self.omega_max * (self.omega_0 + (1.0 - self.omega_0) * (1.0 - (2.0 * w - 1.0).abs()))
    }
}

/// `clamp((d − from)/(to − from), 0, 1)`: 0 at `from`, 1 at `to` (either way round).
fn ramp(d: f32, from: f32, to: f32) -> f32 {
    ((d - from) / (to - from)).clamp(0.0, 1.0)
}

/// Below this local density nothing is drawn, and a fragment under this opacity is discarded
/// (algorithm 1).
pub const DISCARD: f32 = 0.01;

/// Algorithm 1: the opacity of a blade of threshold `dth` drawn by a slice of weight `w` where
/// the local density is `ld` — before the discard of fragments under [`DISCARD`]. Zero where
/// the blade is not drawn at all (`dth > ld`, or `ld < DISCARD`).
pub fn slice_opacity(t: &TransitionDistances, w: f32, ld: f32, dth: f32) -> f32 {
    if ld < DISCARD || dth > ld {
        return 0.0;
    }
    let omega = t.omega(w);
    (((w + omega) * ld - dth) / (2.0 * omega * ld)).clamp(0.0, 1.0)
}

/// Eq. 4.6: the opacity of a blade of threshold `dth` drawn as geometry at distance `d` where
/// the local density is `ld`: the complement of [`slice_opacity`] at the slices' weight
/// `1 − w_g(d)`.
pub fn geometry_opacity(t: &TransitionDistances, d: f32, ld: f32, dth: f32) -> f32 {
    if ld < DISCARD || dth > ld {
        return 0.0;
    }
    let w = 1.0 - t.geometry_weight(d);
    let omega = t.omega(w);
    ((dth - (w - omega) * ld) / (2.0 * omega * ld)).clamp(0.0, 1.0)
}

/// The 4 × 4 ordered-dither threshold of pixel `(x, y)`, in ]0, 1[: a fragment of opacity `α`
/// is kept where `α` exceeds it, so a fraction `α` of an evenly covered region's pixels stay —
/// how the shaders turn the opacities above into coverage without sorting.
pub fn ordered_dither(x: u32, y: u32) -> f32 {
    const M: [u32; 16] = [0, 8, 2, 10, 12, 4, 14, 6, 3, 11, 1, 9, 15, 7, 13, 5];
    (M[((y & 3) * 4 + (x & 3)) as usize] as f32 + 0.5) / 16.0
}

/// [`ordered_dither`] shifted by `key`'s low four bits (sixteenths): each slice quad of each cell
/// dithers with its own shift, so the layers a view ray crosses keep their blades independently
/// — their coverages combine as `1 − Π(1 − αᵢ)`, as the blades' do — where one shared
/// threshold would keep the same pixels of every layer and show only the densest.
pub fn shifted_dither(x: u32, y: u32, key: u32) -> f32 {
    (ordered_dither(x, y) + (key & 15) as f32 / 16.0).fract()
}

/// The opacities a blade gets from each representation at distance `d` (before the discard).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BladeOpacity {
    /// Drawn as geometry.
    pub geometry: f32,
    /// In the vertical slices.
    pub vertical: f32,
    /// In the horizontal slice.
    pub horizontal: f32,
}

/// Every representation's opacity for a blade of threshold `dth` at distance `d`, local density
/// `ld`, ground normal · unit view `n_dot_v`.
pub fn blade_opacity(
    t: &TransitionDistances,
    d: f32,
    ld: f32,
    dth: f32,
    n_dot_v: f32,
) -> BladeOpacity {
    BladeOpacity {
        geometry: geometry_opacity(t, d, ld, dth),
        vertical: slice_opacity(t, t.vertical_weight(d, n_dot_v), ld, dth),
        horizontal: slice_opacity(t, t.horizontal_weight(d), ld, dth),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    #[test]
    fn the_weights_follow_fig_4_11() {
        let t = TransitionDistances::default();
        assert_eq!(t.validate(), Ok(()));
        // Near: geometry only; between min and max geom, both ramps; far: the horizontal slice.
        assert_eq!(
            (t.geometry_weight(2.0), t.vertical_weight(2.0, 1.0)),
            (1.0, 0.0)
        );
        assert_eq!(t.geometry_weight(12.0), 0.5);
        assert_eq!(t.vertical_weight(12.0, 1.0), 0.5);
        assert_eq!(t.horizontal_weight(12.0), 0.5);
        assert_eq!(t.vertical_weight(30.0, 1.0), 1.0);
        assert_eq!(t.vertical_weight(60.0, 1.0), 0.5);
        assert_eq!(t.vertical_weight(100.0, 1.0), 0.0);
        assert_eq!(t.horizontal_weight(100.0), 1.0);
        // Eq. 4.14: on a silhouette (N·V = 0) beyond max_btf the vertical slices come back,
        // until max_silhouettes; half way to ε, half weight.
        assert_eq!(t.vertical_weight(100.0, 0.0), 1.0);
        assert!((t.vertical_weight(100.0, 0.1) - 0.5).abs() < 1e-6);
        assert_eq!(t.vertical_weight(500.0, 0.0), 0.0);
        // Fig. 4.13: ω is widest in the middle, ω₀·ω_max at the ends.
        assert!((t.omega(0.5) - 0.25).abs() < 1e-6);
        assert!((t.omega(0.0) - 0.0125).abs() < 1e-6 && (t.omega(1.0) - 0.0125).abs() < 1e-6);
    }

    #[test]
    fn bad_distances_are_refused() {
        let t = TransitionDistances::default();
        for bad in [
            TransitionDistances { max_geom: 4.0, ..t },
            TransitionDistances { min_btf: 10.0, ..t },
            TransitionDistances {
                max_silhouettes: 50.0,
                ..t
            },
        ] {
            assert_eq!(bad.validate(), Err(TransitionError::Order));
        }
        assert_eq!(
            TransitionDistances {
                omega_max: 0.0,
                ..t
            }
            .validate(),
            Err(TransitionError::Window)
        );
        assert_eq!(
            TransitionDistances {
                min_geom: f32::NAN,
                ..t
            }
            .validate(),
            Err(TransitionError::NotFinite("min_geom"))
        );
    }

    /// A region where the vertical slices' weight is above zero at some distance and view angle
    /// inside it is never one `vertical_may_show` rules out; and it does rule regions out
    /// (between the transitions' reach and the silhouettes', and off silhouettes).
    #[test]
    fn vertical_slices_are_ruled_out_only_where_their_weight_is_zero() {
        let t = TransitionDistances {
            max_silhouettes: 200.0,
            ..TransitionDistances::default()
        };
        let mut rng = SplitMix64::new(7);
        let (mut ruled_out, mut showing) = (0, 0);
        for _ in 0..100_000 {
            let near = rng.range(0.0, 250.0);
            let far = near + rng.range(0.0, 40.0);
            let min_n_dot_v = rng.range(0.0, 1.0);
            let may = t.vertical_may_show(near, far, min_n_dot_v);
            if !may {
                ruled_out += 1;
            }
            for _ in 0..8 {
                let d = rng.range(near, far);
                let n_dot_v = rng.range(min_n_dot_v, 1.0);
                if t.vertical_weight(d, n_dot_v) > 0.0 {
                    showing += 1;
                    assert!(may, "weight > 0 at {d} m, N·V {n_dot_v} in {near}..{far}");
                }
            }
        }
        assert!(
            ruled_out > 30_000 && showing > 30_000,
            "{ruled_out} {showing}"
        );
        assert!(!t.vertical_may_show(100.0, 120.0, 0.5));
        assert!(t.vertical_may_show(100.0, 120.0, 0.1));
        assert!(!t.vertical_may_show(0.0, 7.9, 1.0));
        assert!(t.vertical_may_show(70.0, 90.0, 1.0));
    }

    /// The property of §4.2.5: wherever geometry is drawn (d < max_geom), a blade that the local
    /// density keeps gets opacities from geometry and the slices that sum to one, at any
    /// distance, density and threshold; one the density removes gets none. Over the whole field
    /// the fragments discarded under 1 % opacity lose at most 1 % of a blade.
    #[test]
    fn geometry_and_slice_opacities_sum_to_full_coverage() {
        let t = TransitionDistances::default();
        let mut rng = SplitMix64::new(19);
        for _ in 0..200_000 {
            let d = rng.range(0.0, t.max_geom * 1.2);
            let ld = rng.range(0.0, 1.0);
            let dth = rng.range(1e-6, 1.0);
            let n_dot_v = rng.range(-1.0, 1.0);
            let o = blade_opacity(&t, d, ld, dth, n_dot_v);
            if ld < DISCARD || dth > ld {
                assert_eq!((o.geometry, o.vertical, o.horizontal), (0.0, 0.0, 0.0));
                continue;
            }
            // Up to min_btf the vertical and horizontal slices carry the same blades.
            assert!((o.vertical - o.horizontal).abs() < 1e-6, "{o:?} at {d}");
            let sum = o.geometry + o.vertical;
            assert!(
                (sum - 1.0).abs() < 1e-5,
                "d {d} ld {ld} dth {dth}: {o:?} sums to {sum}"
            );
            let kept = |v: f32| if v < DISCARD { 0.0 } else { v };
            assert!(kept(o.geometry) + kept(o.vertical) >= 1.0 - DISCARD - 1e-6);
        }
    }

    /// The split moves with the distance: as d grows through the first transition, the share of
    /// a uniform density's blades drawn as geometry falls from all to none, monotonically, and
    /// the blades left semi-transparent stay a small fraction (ω narrows at the ends).
    #[test]
    fn blades_move_from_geometry_to_slices_monotonically() {
        let t = TransitionDistances::default();
        let ld = 0.8;
        let blades = 4000;
        let share_at = |d: f32| {
            let (mut geometry, mut partial) = (0.0, 0usize);
            for i in 0..blades {
                let dth = (i as f32 + 0.5) / blades as f32;
                let g = geometry_opacity(&t, d, ld, dth);
                geometry += g;
                partial += (g > DISCARD && g < 1.0 - DISCARD) as usize;
            }
            let drawn = blades as f32 * ld;
            (geometry / drawn, partial as f32 / drawn)
        };
        let mut last = f32::INFINITY;
        for k in 0..=40 {
            let d = t.min_geom - 1.0 + k as f32 * (t.max_geom - t.min_geom + 2.0) / 40.0;
            let (share, partial) = share_at(d);
            assert!(share <= last + 1e-6, "{share} after {last} at {d}");
            assert!(partial <= 2.0 * t.omega_max + 1e-3, "{partial} at {d}");
            last = share;
        }
        let (near, near_partial) = share_at(t.min_geom - 1.0);
        let (far, _) = share_at(t.max_geom + 1.0);
        assert!(near > 0.98 && far < 0.02, "{near} … {far}");
        assert!(
            near_partial < 0.03,
            "{near_partial} of the blades semi-transparent near"
        );
    }

    #[test]
    fn the_dither_keeps_the_opacity_s_fraction_of_every_4_by_4_block() {
        for k in 0..=16 {
            let alpha = k as f32 / 16.0;
            let kept = (0..4)
                .flat_map(|y| (0..4).map(move |x| (x, y)))
                .filter(|&(x, y)| alpha > ordered_dither(x + 8, y + 4))
                .count();
            assert_eq!(kept, k, "opacity {alpha}");
        }
    }

    /// Every shift still keeps the opacity's fraction of each 4 × 4 block; two layers under
    /// shifts drawn from two keys cover, on average over the keys, `1 − (1 − α)²` of it — as two
    /// independent layers of blades — where one shared threshold covers only `α`.
    #[test]
    fn shifted_dithers_combine_layers_as_independent_coverage() {
        let block = || (0..4u32).flat_map(|y| (0..4u32).map(move |x| (x, y)));
        for k in 0..=16u32 {
            let alpha = k as f32 / 16.0;
            for key in 0..16 {
                let kept = block()
                    .filter(|&(x, y)| alpha > shifted_dither(x, y, key))
                    .count();
                assert_eq!(kept as u32, k, "opacity {alpha}, key {key}");
            }
            let mut union = 0.0;
            for a in 0..16 {
                for b in 0..16 {
                    union += block()
                        .filter(|&(x, y)| {
                            alpha > shifted_dither(x, y, a) || alpha > shifted_dither(x, y, b)
                        })
                        .count() as f32
                        / 16.0;
                }
            }
            let union = union / 256.0;
            let independent = 1.0 - (1.0 - alpha) * (1.0 - alpha);
            assert!((union - independent).abs() < 1e-5, "{alpha}: {union}");
            let shared = block()
                .filter(|&(x, y)| alpha > shifted_dither(x, y, 3))
                .count() as f32
                / 16.0;
            assert!((shared - alpha).abs() < 1e-6);
        }
    }
}
