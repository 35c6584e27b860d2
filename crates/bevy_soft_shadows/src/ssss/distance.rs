//! The distance map of §6.2.2, per pixel: the blocker found in the coarse dilated shadow map,
//! the penumbra's world width by eq. 6.1, its width on screen by eq. 6.2, the mask of pixels
//! that can never be in penumbra, and the kernel's σ — the CPU reference of the `distance` pass
//! in `ssss.wgsl` (tested against it pixel by pixel in `tests/ssss_spot.rs`).
//!
//! For spot lights the light space is Bevy's spot shadow projection ([`SpotProjection`]): an
//! infinite reverse-Z perspective whose stored depth is `near / d`, `d` the distance along the
//! spot's axis — so depths turn back into distances exactly, and eq. 6.1 applies as written.
//! A point light's six cube faces ([`PointProjection`]) are the same projection at 90°, each
//! dilated on its own. For a directional light it is a cascade's orthographic projection
//! ([`DirectionalCascade`]), whose depth is linear along the light; eq. 6.1 takes its limit for
//! a light at infinity.

use super::kernel::KERNEL_REACH_SIGMAS;
use super::penumbra::{own_surface_gap, penumbra_sigma, penumbra_width, screen_penumbra_px};
use bevy::math::{Mat3, Mat4, Vec2, Vec3};

/// Bevy's spot-light shadow projection, as `fetch_spot_shadow` builds it from the clustered
/// light (without its depth and normal biases, which only the hard shadow lookup applies).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotProjection {
    /// The light's position.
    pub position: Vec3,
    /// Where it points (its transform's forward, unit length).
    pub forward: Vec3,
    /// `tan(outer_angle)`: the map spans ±this at unit distance.
    pub tan_outer: f32,
    /// `SpotLight::shadow_map_near_z`.
    pub near: f32,
}

/// Bevy's `orthonormalize` (`bevy_render::maths`): a basis whose third column is `z`.
fn orthonormalize(z: Vec3) -> Mat3 {
    let sign = 1f32.copysign(z.z);
    let a = -1.0 / (sign + z.z);
    let b = z.x * z.y * a;
    let x_basis = Vec3::new(1.0 + sign * z.x * z.x * a, sign * b, -sign * z.x);
    let y_basis = Vec3::new(b, sign + z.y * z.y * a, -z.y);
    Mat3::from_cols(x_basis, y_basis, z)
}

impl SpotProjection {
    /// The shadow-map coordinates of `world` (uv in [0, 1]², v down) and its distance from the
    /// light along the axis; `None` behind the near plane.
    pub fn project(&self, world: Vec3) -> Option<(Vec2, f32)> {
        let basis = orthonormalize(-self.forward);
        let offset = world - self.position;
        // `offset * basis` in WGSL: the offset in the basis' coordinates.
        let local = Vec3::new(
            offset.dot(basis.x_axis),
            offset.dot(basis.y_axis),
            offset.dot(basis.z_axis),
        );
        let distance = -local.z;
        if distance <= self.near {
            return None;
        }
        let ndc = Vec2::new(local.x, local.y) / (self.tan_outer * distance);
        Some((ndc * Vec2::new(0.5, -0.5) + Vec2::splat(0.5), distance))
    }

    /// The stored (reverse-Z) depth of a point `distance` along the axis.
    pub fn depth(&self, distance: f32) -> f32 {
        self.near / distance
    }

    /// The distance along the axis of a stored depth.
    pub fn distance(&self, depth: f32) -> f32 {
        self.near / depth
    }

    /// Metres one texel of a `map_size`² shadow map spans at `distance`.
    pub fn texel_size(&self, distance: f32, map_size: f32) -> f32 {
        2.0 * distance * self.tan_outer / map_size
    }
}

/// A local light's perspective shadow projection, as the distance pass reads it: a spot light's
/// map or a point light's cube faces — infinite reverse-Z perspective maps whose stored depth is
/// `near / d`, `d` the distance along the map's axis.
pub trait LocalProjection {
    /// The light's position.
    fn position(&self) -> Vec3;
    /// The near plane of its maps (`shadow_map_near_z`).
    fn near(&self) -> f32;
    /// Tangent of a map's half angle: a map spans ±this at unit distance.
    fn tan_half_angle(&self) -> f32;
    /// Which of the light's maps sees `world` (0 for a spot light, the cube face for a point
    /// light), its coordinates there (uv in [0, 1]², v down) and its distance along that map's
    /// axis; `None` within the near plane.
    fn project_local(&self, world: Vec3) -> Option<(usize, Vec2, f32)>;
}

impl LocalProjection for SpotProjection {
    fn position(&self) -> Vec3 {
        self.position
    }
    fn near(&self) -> f32 {
        self.near
    }
    fn tan_half_angle(&self) -> f32 {
        self.tan_outer
    }
    fn project_local(&self, world: Vec3) -> Option<(usize, Vec2, f32)> {
        self.project(world).map(|(uv, d)| (0, uv, d))
    }
}

/// Bevy's point-light shadow projection (`fetch_point_shadow`): six 90° infinite reverse-Z
/// perspective faces in a cube texture, face `f` of the light of clustered index `i` in layer
/// `6i + f`, looked up along the light-to-point direction with z negated (Bevy's cube maps are
/// left-handed). Which face and where on it follow the cube-map face selection of Vulkan and
/// Direct3D (Vulkan spec, "Cube Map Face Selection"); the stored depth is `near / m`, `m` the
/// major axis' magnitude — the distance along the face's axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointProjection {
    /// The light's position.
    pub position: Vec3,
    /// `PointLight::shadow_map_near_z`.
    pub near: f32,
}

impl PointProjection {
    /// The cube face seeing `world` (+x, −x, +y, −y, +z, −z in the cube texture's own,
    /// z-negated, space), its coordinates on the face (v down) and the distance along the face's
    /// axis; `None` within the near plane.
    pub fn project(&self, world: Vec3) -> Option<(usize, Vec2, f32)> {
        let d = world - self.position;
        let r = Vec3::new(d.x, d.y, -d.z);
        let a = r.abs();
        let (face, sc, tc, major) = if a.x >= a.y && a.x >= a.z {
            if r.x >= 0.0 {
                (0, -r.z, -r.y, a.x)
            } else {
                (1, r.z, -r.y, a.x)
            }
        } else if a.y >= a.z {
            if r.y >= 0.0 {
                (2, r.x, r.z, a.y)
            } else {
                (3, r.x, -r.z, a.y)
            }
        } else if r.z >= 0.0 {
            (4, r.x, -r.y, a.z)
        } else {
            (5, -r.x, -r.y, a.z)
        };
        if major <= self.near {
            return None;
        }
        let uv = Vec2::new(sc, tc) / major * 0.5 + Vec2::splat(0.5);
        Some((face, uv, major))
    }
}

impl LocalProjection for PointProjection {
    fn position(&self) -> Vec3 {
        self.position
    }
    fn near(&self) -> f32 {
        self.near
    }
    fn tan_half_angle(&self) -> f32 {
        1.0
    }
    fn project_local(&self, world: Vec3) -> Option<(usize, Vec2, f32)> {
        self.project(world)
    }
}

/// One cascade of a directional light's shadow map, as Bevy uploads it (`Cascade`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionalCascade {
    /// World to the cascade's clip space (orthographic, reverse Z).
    pub clip_from_world: Mat4,
    /// World size of one shadow-map texel.
    pub texel_size: f32,
}

impl DirectionalCascade {
    /// Shadow-map coordinates (uv, v down) and stored depth of `world`, as Bevy's
    /// `world_to_directional_light_local`; `None` outside the cascade's volume.
    pub fn project(&self, world: Vec3) -> Option<(Vec2, f32)> {
        let clip = self.clip_from_world * world.extend(1.0);
        if clip.w <= 0.0 {
            return None;
        }
        let ndc = clip.truncate() / clip.w;
        if ndc.x < -1.0 || ndc.y < -1.0 || ndc.z < 0.0 || ndc.cmpgt(Vec3::ONE).any() {
            return None;
        }
        Some((
            Vec2::new(ndc.x, ndc.y) * Vec2::new(0.5, -0.5) + Vec2::splat(0.5),
            ndc.z,
        ))
    }

    /// Stored depth per metre along the light.
    pub fn depth_per_metre(&self) -> f32 {
        let m = self.clip_from_world;
        Vec3::new(m.x_axis.z, m.y_axis.z, m.z_axis.z).length()
    }
}

/// Eq. 6.1 for a light at infinity (angular diameter `angular_diameter`): the world width of the
/// penumbra at receiver `world` (unit `normal`; `direction_to_light` unit) behind the blocker
/// found for it, the gap measured along the light from the cascade's linear depth: the coarse
/// map's blocker at its texel, refined on the fine map ([`refined_gap`]) when `fine` is given —
/// the `refine` pass on the active tiles; without, the distance pass's upper bound, which the
/// tile classification runs on. Zero outside the cascade, with no blocker nearer the light, or
/// when the "blocker" is the receiver's own surface across the dilation footprint
/// ([`own_surface_gap`]).
pub fn directional_penumbra_width(
    cascade: &DirectionalCascade,
    coarse: &CoarseMap,
    fine: Option<&FineMap>,
    world: Vec3,
    normal: Vec3,
    direction_to_light: Vec3,
    angular_diameter: f32,
) -> f32 {
    let Some((uv, depth)) = cascade.project(world) else {
        return 0.0;
    };
    let depth_per_metre = cascade.depth_per_metre();
    let gap = (coarse.at(uv) - depth) / depth_per_metre.max(1e-8);
    let reach = ((coarse.radius + 1) * coarse.block) as f32 * cascade.texel_size;
    let cos_nl = normal.dot(direction_to_light);
    if cos_nl > 0.0 && gap <= own_surface_gap(reach, cos_nl) {
        return 0.0;
    }
    let gap = match fine {
        Some(fine) => refined_gap(
            fine,
            uv,
            depth,
            gap,
            cascade.texel_size,
            depth_per_metre,
            cos_nl,
            angular_diameter,
        ),
        None => gap,
    };
    directional_penumbra_width_of_gap(gap, angular_diameter)
}

/// Half-width in samples of the grid [`refined_gap`] searches (`BLOCKER_GRID` in
/// `ssss_types.wgsl`): 7×7 samples.
pub const BLOCKER_GRID: i32 = 3;

/// One layer of the fine shadow map, as the distance pass reads it.
#[derive(Clone, Copy, Debug)]
pub struct FineMap<'a> {
    /// Row-major depths (reverse Z).
    pub depth: &'a [f32],
    /// Size in texels.
    pub width: usize,
    /// Size in texels.
    pub height: usize,
}

impl FineMap<'_> {
    /// The texels of the refined blocker search around `uv`: a (2·[`BLOCKER_GRID`] + 1)² grid
    /// spanning `reach_texels` each way (offsets rounded as WGSL's `round`, halves to even),
    /// each as (offset in texels, stored depth); texels off the map are left out.
    fn blocker_grid(&self, uv: Vec2, reach_texels: f32) -> impl Iterator<Item = (Vec2, f32)> + '_ {
        let (w, h) = (self.width as i32, self.height as i32);
        let centre_x = ((uv.x * w as f32).floor() as i32).clamp(0, w - 1);
        let centre_y = ((uv.y * h as f32).floor() as i32).clamp(0, h - 1);
        let offset =
            move |k: i32| (k as f32 * reach_texels / BLOCKER_GRID as f32).round_ties_even() as i32;
        (-BLOCKER_GRID..=BLOCKER_GRID)
            .flat_map(|j| (-BLOCKER_GRID..=BLOCKER_GRID).map(move |i| (i, j)))
            .filter_map(move |(i, j)| {
                let (ox, oy) = (offset(i), offset(j));
                let (x, y) = (centre_x + ox, centre_y + oy);
                (x >= 0 && y >= 0 && x < w && y < h).then(|| {
                    (
                        Vec2::new(ox as f32, oy as f32),
                        self.depth[(y * w + x) as usize],
                    )
                })
            })
    }
}

/// The blocker's gap for eq. 6.1 at a receiver of shadow-map coordinates `uv` and stored depth
/// `receiver_depth`, given the coarse map's gap `gap_max` (`refined_gap` in `ssss.wgsl`).
///
/// The coarse map holds the blocker nearest the light within the dilation window (§6.2.1). For a
/// long thin blocker — a trunk, a pole — that is its far end, not the part in front of the
/// light's centre, so the penumbra comes out too wide and the thin shadow too faint. Here the
/// fine map is searched on a (2·[`BLOCKER_GRID`] + 1)² grid spanning the reach of that farthest
/// blocker, `gap_max · tan(θ/2)`; a texel counts when its blocker hides part of the light's disk
/// from the receiver — at gap `g` the disk spans `g · tan(θ/2)` around the receiver's light ray
/// — and is not the receiver's own plane (rising by `tan` of its angle to the light per metre,
/// plus one texel) nor within a texel of it (depth precision). Their gaps are averaged weighted by
/// the share of the light's disk each hides — a texel at gap `g` covers `texel² / (π (g·tan(θ/2))²)`
/// of it, so the weight is `1/g²`: a thin blocker right over the receiver outweighs the farther
/// parts of the same pole or the fronds high above, whose penumbra only grazes it. With none,
/// `gap_max` stands.
#[allow(clippy::too_many_arguments)]
pub fn refined_gap(
    fine: &FineMap,
    uv: Vec2,
    receiver_depth: f32,
    gap_max: f32,
    texel_size: f32,
    depth_per_metre: f32,
    cos_nl: f32,
    angular_diameter: f32,
) -> f32 {
    let t = (0.5 * angular_diameter).tan();
    let reach_texels = gap_max * t / texel_size.max(1e-6);
    let slope = (1.0 - cos_nl * cos_nl).max(0.0).sqrt() / cos_nl.max(0.05);
    let (mut sum, mut count) = (0.0f32, 0.0f32);
    for (offset, depth) in fine.blocker_grid(uv, reach_texels) {
        let gap = (depth - receiver_depth) / depth_per_metre.max(1e-8);
        let r = offset.length() * texel_size;
        if gap > texel_size && r <= gap * t && (cos_nl <= 0.0 || gap > (r + texel_size) * slope) {
            let share = 1.0 / (gap * gap);
            sum += gap * share;
            count += share;
        }
    }
    // Never past the coarse map's blocker, so the unrefined width stays an upper bound.
    if count > 0.0 {
        (sum / count).min(gap_max)
    } else {
        gap_max
    }
}

fn directional_penumbra_width_of_gap(gap: f32, angular_diameter: f32) -> f32 {
    super::penumbra::directional_penumbra_width(gap.max(0.0), angular_diameter)
}

/// The coarse dilated map of one light, as the distance pass reads it.
#[derive(Clone, Copy, Debug)]
pub struct CoarseMap<'a> {
    /// Row-major nearest depths (reverse Z).
    pub depth: &'a [f32],
    /// Size in coarse texels.
    pub width: usize,
    /// Size in coarse texels.
    pub height: usize,
    /// The fine shadow map's size in texels.
    pub map_size: f32,
    /// The dilation's coarse radius `R`.
    pub radius: usize,
    /// Shadow-map texels a side per coarse texel.
    pub block: usize,
}

impl CoarseMap<'_> {
    /// The texel under `uv` (clamped to the map).
    pub fn at(&self, uv: Vec2) -> f32 {
        let x = (uv.x * self.width as f32).clamp(0.0, self.width as f32 - 1.0) as usize;
        let y = (uv.y * self.height as f32).clamp(0.0, self.height as f32 - 1.0) as usize;
        self.depth[y * self.width + x]
    }
}

/// Eq. 6.1 for a spot light of diameter `light_size`: the world width of the penumbra at
/// receiver `world` (unit `normal`), behind the blocker the coarse map holds at its texel,
/// refined on `fine` when given ([`refined_local_blocker`]; see [`directional_penumbra_width`]).
/// Zero outside the map, with no blocker nearer the light, or when the "blocker" is only the
/// receiver's own surface across the dilation footprint ([`own_surface_gap`]).
pub fn spot_penumbra_width(
    projection: &SpotProjection,
    coarse: &CoarseMap,
    fine: Option<&FineMap>,
    world: Vec3,
    normal: Vec3,
    light_size: f32,
) -> f32 {
    local_penumbra_width(
        projection,
        std::slice::from_ref(coarse),
        fine.map(std::slice::from_ref),
        world,
        normal,
        light_size,
    )
}

/// [`spot_penumbra_width`] for a point light: `coarse` and `fine` hold its six cube faces, each
/// dilated on its own — so a receiver near a face's edge does not see blockers across it, and
/// its penumbra from those is cut at the edge (the limit of a per-face dilation).
pub fn point_penumbra_width(
    projection: &PointProjection,
    coarse: &[CoarseMap],
    fine: Option<&[FineMap]>,
    world: Vec3,
    normal: Vec3,
    light_size: f32,
) -> f32 {
    local_penumbra_width(projection, coarse, fine, world, normal, light_size)
}

/// Eq. 6.1 for a local light of diameter `light_size`, `w = light_size · (d_r − d_b) / d_b`,
/// with the distances along the axis of the map seeing the receiver (on one ray from the light
/// their ratio is the distances' own); `coarse[k]` and `fine[k]` are the light's map `k` (see
/// [`LocalProjection::project_local`]).
pub fn local_penumbra_width(
    projection: &impl LocalProjection,
    coarse: &[CoarseMap],
    fine: Option<&[FineMap]>,
    world: Vec3,
    normal: Vec3,
    light_size: f32,
) -> f32 {
    let Some((map, uv, d_receiver)) = projection.project_local(world) else {
        return 0.0;
    };
    let Some(coarse) = coarse.get(map) else {
        return 0.0;
    };
    if uv.cmplt(Vec2::ZERO).any() || uv.cmpgt(Vec2::ONE).any() {
        return 0.0;
    }
    let near = projection.near();
    let blocker = coarse.at(uv);
    if blocker <= near / d_receiver {
        return 0.0;
    }
    let d_blocker = near / blocker;
    let gap = d_receiver - d_blocker;
    let texel_size = 2.0 * d_receiver * projection.tan_half_angle() / coarse.map_size;
    let reach = ((coarse.radius + 1) * coarse.block) as f32 * texel_size;
    let cos_nl = normal.dot((projection.position() - world).normalize());
    if cos_nl > 0.0 && gap <= own_surface_gap(reach, cos_nl) {
        return 0.0;
    }
    let d_blocker = match fine.and_then(|f| f.get(map)) {
        Some(fine) => refined_local_blocker(
            projection, fine, uv, d_receiver, d_blocker, cos_nl, light_size,
        ),
        None => d_blocker,
    };
    penumbra_width(d_receiver, d_blocker, light_size)
}

/// [`refined_gap`] for a local light of diameter `light_size` (`refined_local_blocker` in
/// `ssss.wgsl`): the mean distance from the light of the fine-map blockers hiding part of the
/// lamp's disk from the receiver, weighted as there by the share of the disk each hides (`1/g²`
/// for a blocker `g` in front of the receiver), `d_receiver` from the light — seen from the receiver, the disk
/// spans `light_size/2 · g / d_receiver` around its ray at a blocker `g` in front of it — over a
/// grid spanning the reach of the coarse map's nearest blocker `d_nearest`; with none,
/// `d_nearest` stands.
pub fn refined_local_blocker(
    projection: &impl LocalProjection,
    fine: &FineMap,
    uv: Vec2,
    d_receiver: f32,
    d_nearest: f32,
    cos_nl: f32,
    light_size: f32,
) -> f32 {
    let near = projection.near();
    let half = 0.5 * light_size;
    let texel_per_distance = 2.0 * projection.tan_half_angle() / fine.width as f32;
    let reach_texels =
        half * (d_receiver - d_nearest) / d_receiver / (d_nearest * texel_per_distance).max(1e-8);
    let slope = (1.0 - cos_nl * cos_nl).max(0.0).sqrt() / cos_nl.max(0.05);
    let receiver_texel = d_receiver * texel_per_distance;
    let (mut sum, mut count) = (0.0f32, 0.0f32);
    for (offset, depth) in fine.blocker_grid(uv, reach_texels) {
        if depth <= near / d_receiver {
            continue;
        }
        let d = near / depth;
        let gap = d_receiver - d;
        let texels = offset.length();
        let lateral = texels * d * texel_per_distance;
        let own = (texels * receiver_texel + receiver_texel) * slope;
        if gap > receiver_texel
            && lateral <= half * gap / d_receiver
            && (cos_nl <= 0.0 || gap > own)
        {
            let share = 1.0 / (gap * gap);
            sum += d * share;
            count += share;
        }
    }
    if count > 0.0 {
        (sum / count).max(d_nearest)
    } else {
        d_nearest
    }
}

/// The kernel's σ (pixels) for a penumbra `width_px` wide on screen: σ = width/4, zero when the
/// kernel would reach less than a pixel (the mask of §6.2.2: the blur leaves those pixels
/// alone), else with its reach (2.5 σ) clamped to `[min_kernel_px, max_kernel_px]`.
pub fn kernel_sigma(width_px: f32, min_kernel_px: f32, max_kernel_px: f32) -> f32 {
    let sigma = penumbra_sigma(width_px);
    if KERNEL_REACH_SIGMAS * sigma < 1.0 {
        return 0.0;
    }
    (KERNEL_REACH_SIGMAS * sigma).clamp(min_kernel_px, max_kernel_px) / KERNEL_REACH_SIGMAS
}

/// The distance pass's σ at a pixel: eq. 6.2 (`pixels_per_unit` = the projection's pixels per
/// metre at unit eye distance; divided by `eye_depth` for perspective views) on a penumbra
/// `world_width` wide, through [`kernel_sigma`].
pub fn pixel_sigma(
    world_width: f32,
    pixels_per_unit: f32,
    eye_depth: Option<f32>,
    min_kernel_px: f32,
    max_kernel_px: f32,
) -> f32 {
    let px = match eye_depth {
        Some(z) => screen_penumbra_px(world_width, z.max(1e-4), pixels_per_unit),
        None => world_width * pixels_per_unit,
    };
    kernel_sigma(px, min_kernel_px, max_kernel_px)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lamp() -> SpotProjection {
        SpotProjection {
            position: Vec3::new(3.0, 6.0, 0.0),
            forward: Vec3::new(-4.5, -6.0, 0.0).normalize(),
            tan_outer: 0.6f32.tan(),
            near: 0.1,
        }
    }

    #[test]
    fn the_spot_projection_maps_its_axis_to_the_centre_and_its_cone_to_the_edge() {
        let p = lamp();
        let (uv, d) = p.project(p.position + 5.0 * p.forward).unwrap();
        assert!(uv.distance(Vec2::splat(0.5)) < 1e-5, "{uv}");
        assert!((d - 5.0).abs() < 1e-4);
        // A point at the outer angle, off the axis along the basis' x axis, lands on the edge.
        let basis = orthonormalize(-p.forward);
        let edge = p.position + 4.0 * p.forward + 4.0 * p.tan_outer * basis.x_axis;
        let (uv, d) = p.project(edge).unwrap();
        assert!(
            (uv.x - 1.0).abs() < 1e-4 && (uv.y - 0.5).abs() < 1e-4,
            "{uv}"
        );
        assert!((d - 4.0).abs() < 1e-4);
        assert!(
            p.project(p.position - p.forward).is_none(),
            "behind the light"
        );
        // Depth and distance are inverse: the reverse-Z infinite projection.
        assert!((p.distance(p.depth(7.5)) - 7.5).abs() < 1e-5);
        assert!(p.depth(2.0) > p.depth(3.0), "nearer is larger");
        // The basis is orthonormal.
        assert!((basis.determinant().abs() - 1.0).abs() < 1e-5);
        assert!(basis.x_axis.dot(basis.y_axis).abs() < 1e-6);
    }

    #[test]
    fn a_blocker_halfway_to_the_light_gives_a_penumbra_as_wide_as_the_light() {
        let p = lamp();
        let receiver = p.position + 8.0 * p.forward;
        let (uv, _) = p.project(receiver).unwrap();
        // A 1×1 coarse map holding a blocker at 4 m along the axis.
        let depth = [p.depth(4.0)];
        let coarse = CoarseMap {
            depth: &depth,
            width: 1,
            height: 1,
            map_size: 2048.0,
            radius: 2,
            block: crate::ssss::min_filter::DILATION_BLOCK,
        };
        assert_eq!(coarse.at(uv), depth[0]);
        // Facing the light: no own-surface gap to discount. The fine map holds only the
        // receiver's own plane: the coarse map's blocker stands.
        let normal = -p.forward;
        let plane = vec![p.depth(8.0); 64 * 64];
        let fine = FineMap {
            depth: &plane,
            width: 64,
            height: 64,
        };
        let w = spot_penumbra_width(&p, &coarse, Some(&fine), receiver, normal, 0.5);
        assert!((w - 0.5).abs() < 1e-4, "{w}");
        // A fine map holding a plank at 6 m over everything: the plank hides the lamp's disk
        // around the receiver's ray, and eq. 6.1 takes it instead of the coarse 4 m blocker.
        let plank = vec![p.depth(6.0); 64 * 64];
        let planked = FineMap {
            depth: &plank,
            ..fine
        };
        let w = spot_penumbra_width(&p, &coarse, Some(&planked), receiver, normal, 0.5);
        assert!((w - penumbra_width(8.0, 6.0, 0.5)).abs() < 1e-4, "{w}");
        // Unrefined, the coarse blocker's width: an upper bound of the refined one.
        let bound = spot_penumbra_width(&p, &coarse, None, receiver, normal, 0.5);
        assert!((bound - penumbra_width(8.0, 4.0, 0.5)).abs() < 1e-4 && bound >= w);
        // The blocker behind the receiver casts nothing; nor does a gap within the receiver's
        // own slope across the footprint, at grazing light.
        let behind = [p.depth(9.0)];
        let coarse_behind = CoarseMap {
            depth: &behind,
            ..coarse
        };
        assert_eq!(
            spot_penumbra_width(&p, &coarse_behind, Some(&fine), receiver, normal, 0.5),
            0.0
        );
        let near = [p.depth(7.99)];
        let grazing = (normal + 20.0 * normal.any_orthonormal_vector()).normalize();
        let coarse_near = CoarseMap {
            depth: &near,
            ..coarse
        };
        assert_eq!(
            spot_penumbra_width(&p, &coarse_near, Some(&fine), receiver, grazing, 0.5),
            0.0
        );
        assert!(spot_penumbra_width(&p, &coarse_near, Some(&fine), receiver, normal, 0.5) > 0.0);
    }

    #[test]
    fn a_directional_blocker_one_metre_up_gives_eq_6_1() {
        // A cascade looking straight down: 20 m wide, depth 1 at y = 10 down to 0 at y = −10.
        let view = Mat4::look_to_rh(Vec3::new(0.0, 10.0, 0.0), Vec3::NEG_Y, Vec3::Z);
        let projection = Mat4::orthographic_rh(-10.0, 10.0, -10.0, 10.0, 20.0, 0.0);
        let cascade = DirectionalCascade {
            clip_from_world: projection * view,
            texel_size: 20.0 / 2048.0,
        };
        assert!((cascade.depth_per_metre() - 0.05).abs() < 1e-6);
        let (uv, depth) = cascade.project(Vec3::ZERO).unwrap();
        assert!(uv.distance(Vec2::splat(0.5)) < 1e-5 && (depth - 0.5).abs() < 1e-5);
        assert!(
            cascade.project(Vec3::new(11.0, 0.0, 0.0)).is_none(),
            "outside"
        );
        // A blocker 1 m above the receiver, a 0.1 rad light straight above.
        let blocker = [0.5 + 0.05];
        let coarse = CoarseMap {
            depth: &blocker,
            width: 1,
            height: 1,
            map_size: 2048.0,
            radius: 2,
            block: crate::ssss::min_filter::DILATION_BLOCK,
        };
        // The fine map: nothing but the receiver's own plane, so the coarse map's blocker stands.
        let plane = vec![0.5f32; 64 * 64];
        let fine = FineMap {
            depth: &plane,
            width: 64,
            height: 64,
        };
        let w = directional_penumbra_width(
            &cascade,
            &coarse,
            Some(&fine),
            Vec3::ZERO,
            Vec3::Y,
            Vec3::Y,
            0.1,
        );
        assert!((w - 2.0 * 0.05f32.tan()).abs() < 1e-4, "{w}");
        // No blocker above: nothing.
        let none = [0.5];
        let coarse_none = CoarseMap {
            depth: &none,
            ..coarse
        };
        let w = directional_penumbra_width(
            &cascade,
            &coarse_none,
            Some(&fine),
            Vec3::ZERO,
            Vec3::Y,
            Vec3::Y,
            0.1,
        );
        assert_eq!(w, 0.0);
    }

    #[test]
    fn the_refined_blocker_is_the_one_hiding_the_lights_disk() {
        // A receiver at the centre of a 64² map of 1 cm texels, a 0.2 rad light straight above
        // (depth 1 per metre). A plank 0.5 m above it over the whole map, and the coarse map's
        // blocker 3.7 m up (a post somewhere in the dilation window): the plank hides the
        // light's disk only within 0.5·tan(0.1) = 5 cm of the receiver's ray — the grid's centre
        // sample — and its gap is the blocker's.
        let (n, texel) = (64usize, 0.01f32);
        let plank = vec![0.5f32; n * n];
        let fine = FineMap {
            depth: &plank,
            width: n,
            height: n,
        };
        let uv = Vec2::splat(32.5 / n as f32);
        assert_eq!(refined_gap(&fine, uv, 0.0, 3.7, texel, 1.0, 1.0, 0.2), 0.5);
        // A 3 m post 12 cm to the side hides part of the disk too (3·tan(0.1) = 30 cm): the
        // mean of both, each weighted by the share of the disk a texel hides there (1/g²).
        let mut post = plank.clone();
        let grid_step = (3.7 * 0.1f32.tan() / texel / 3.0).round_ties_even() as usize;
        post[32 * n + 32 + grid_step] = 3.0;
        let with_post = FineMap {
            depth: &post,
            ..fine
        };
        let refined = refined_gap(&with_post, uv, 0.0, 3.7, texel, 1.0, 1.0, 0.2);
        let expected = (0.5 / 0.25 + 3.0 / 9.0) / (1.0 / 0.25 + 1.0 / 9.0);
        assert!((refined - expected).abs() < 1e-5, "{refined} vs {expected}");
        // Nothing but the receiver's plane nearby: the coarse gap stands.
        let flat = vec![0.0f32; n * n];
        let empty = FineMap {
            depth: &flat,
            ..fine
        };
        assert_eq!(refined_gap(&empty, uv, 0.0, 3.7, texel, 1.0, 1.0, 0.2), 3.7);
    }

    #[test]
    fn kernel_sigma_masks_sub_pixel_kernels_and_clamps_the_reach() {
        // σ = w/4; a 1.6 px penumbra reaches exactly 1 px.
        assert_eq!(kernel_sigma(1.5, 0.0, 60.0), 0.0);
        assert!((kernel_sigma(8.0, 0.0, 60.0) - 2.0).abs() < 1e-6);
        // Reach 2.5σ clamped to [min, max].
        assert!((kernel_sigma(80.0, 0.0, 10.0) - 4.0).abs() < 1e-6);
        assert!((kernel_sigma(2.0, 5.0, 60.0) - 2.0).abs() < 1e-6);
        // Eq. 6.2: perspective divides by the eye depth, orthographic does not.
        let ortho = pixel_sigma(0.4, 32.0, None, 0.0, 60.0);
        let persp = pixel_sigma(0.4, 32.0, Some(2.0), 0.0, 60.0);
        assert!((ortho - 2.0 * persp).abs() < 1e-5, "{ortho} {persp}");
    }

    /// The point projection is where Bevy renders each cube face: face `f` is drawn into layer
    /// `f` from `Transform::looking_at(CUBE_MAP_FACES[f])` at the light with a 90° infinite
    /// reverse-Z perspective (`create_point_shadow_maps`), NDC y up and rows down. For points all
    /// around the light, the face the projection picks sees the point inside its frustum, at the
    /// same uv and with the depth Bevy stores.
    #[test]
    fn the_point_projection_matches_the_faces_bevy_renders() {
        use bevy::camera::primitives::CUBE_MAP_FACES;
        let p = PointProjection {
            position: Vec3::new(1.0, 4.0, -2.0),
            near: 0.1,
        };
        let clip = Mat4::perspective_infinite_reverse_rh(std::f32::consts::FRAC_PI_2, 1.0, p.near);
        let mut faces_seen = [0usize; 6];
        let mut seed = 7u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
        };
        for _ in 0..600 {
            let world = p.position + 6.0 * Vec3::new(next(), next(), next());
            let Some((face, uv, distance)) = p.project(world) else {
                continue;
            };
            faces_seen[face] += 1;
            let f = &CUBE_MAP_FACES[face];
            let view = bevy::prelude::Transform::from_translation(p.position)
                .looking_at(p.position + f.target, f.up)
                .to_matrix();
            let c = clip * view.inverse() * world.extend(1.0);
            let ndc = c.truncate() / c.w;
            assert!(
                ndc.x.abs() <= 1.0 + 1e-4 && ndc.y.abs() <= 1.0 + 1e-4,
                "{world} on face {face} is outside it: {ndc}"
            );
            let rendered = Vec2::new(0.5 + 0.5 * ndc.x, 0.5 - 0.5 * ndc.y);
            assert!(
                rendered.distance(uv) < 1e-4,
                "{world}, face {face}: uv {uv} vs rendered at {rendered}"
            );
            assert!(
                (ndc.z - p.near / distance).abs() < 1e-5,
                "stored depth {} vs near / distance {}",
                ndc.z,
                p.near / distance
            );
        }
        assert!(faces_seen.iter().all(|&n| n > 30), "{faces_seen:?}");
    }
}
