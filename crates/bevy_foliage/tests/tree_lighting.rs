//! Render test of the tree lighting in the leaf shaders (Boulanger 2008, ch. 5): a small tree
//! drawn with `TreeLightingSettings::enabled`, every pixel inside a leaf compared with the CPU
//! reference (`lighting::model::leaf_radiance`) of the leaf a ray through that pixel hits first
//! — sky and ground through the crown, the sun through the crown, one bounce of sunlight.

use bevy::camera::Exposure;
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::light::{CascadeShadowConfig, CascadeShadowConfigBuilder, Cascades};
use bevy::prelude::*;
use bevy_foliage::lighting::bins::{DARKEST_LIGHT, light_of};
use bevy_foliage::lighting::bounce_ring::{
    BounceRing, RING_NODES, ratio_with_ring, ratio_with_ring_nodes, ring_shares_at,
    sun_through_with_ring,
};
use bevy_foliage::lighting::gathered_bounce::BounceRatios;
use bevy_foliage::lighting::hotspot::{HOTSPOT_NODES, Hotspot};
use bevy_foliage::lighting::model::{
    SkyLight, SunBounce, SunThroughCrown, bounce_radiance, bounce_radiance_by_face, open_share,
    sky_radiance, sun_radiance, sun_through_crown,
};
use bevy_foliage::lighting::open_map::{self, LeafOpenMap, StoredOpenMap};
use bevy_foliage::lighting::path_trace::LeafScene;
use bevy_foliage::lighting::seen_part::{covered_gain, gain_of, quantize_gain, seen_gain};
use bevy_foliage::lighting::settings::BounceRingSettings;
use bevy_foliage::lighting::sun_maps::{LEAF_SHADOW_FINE, LeafShadowPlane};
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage, CellCount, bake};
use bevy_foliage::pruning::components::{PrunedFoliage, PruningParams};
use bevy_foliage::pruning::extract::kept_index_total;
use bevy_foliage::pruning::leaves::LeafSet;
use bevy_foliage::pruning::material::{LeafMaterial, leaf_material};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_foliage::{FoliagePlugin, FoliagePruningSettings, LodDistances, TreeLightingSettings};
use bevy_nature_harness::compare::RgbaImage;
use bevy_nature_harness::{RenderHarness, artifacts_dir};
use common::render_with_settings;

mod common;

const SIZE: u32 = 96;
const SKY: f32 = 1.2;
const SUN: f32 = 3.0;
/// The leaves' base colour (linear): the optics are multiples of it.
const BASE: Vec3 = Vec3::new(0.9, 0.8, 0.6);
/// How far a crown pruned to about half its leaves (area compensated) may move the crown's light
/// from full detail's at the same view.
const TOLERANCE: f64 = 0.08;
/// Every octant's seen-part gain in the check of the bounce's covered-part gain: strong enough
/// that the bounce of the test crown's leaves, most of their sphere covered, falls visibly.
const STRONG_GAIN: f32 = 3.0;
/// The strong stage's hotspot: the exponent on the blended sun (darker where the crown's blend,
/// scaled by the strong gains, stays below 1) and the factor on the bounce.
const STRONG_HOTSPOT: (f32, f32) = (3.0, 2.0);
/// Open-map cell gains for the strong bake, row by row: no two alike, the grid not symmetric
/// about either axis or its diagonal.
const STRONG_CELLS: [f32; 9] = [0.4, 1.0, 2.6, 1.7, 0.6, 2.1, 0.8, 3.2, 0.5];

fn srgb(linear: f32) -> f32 {
    let c = linear.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// The baked tree's stored leaves as a leaf set (leaf `l` = stored leaf `l`).
fn stored_leaves(baked: &BakedFoliage) -> LeafSet {
    LeafSet {
        positions: baked.positions.clone(),
        normals: baked.normals.clone(),
        uvs: baked.uvs.clone(),
        indices: baked.indices.clone(),
        leaves: baked
            .leaf_index_start
            .windows(2)
            .map(|w| w[0]..w[1])
            .collect(),
    }
}

/// The texel side of the sun's shadow cascade that holds world point `p`, as the leaf shader
/// picks it (the first cascade whose far bound lies beyond the point's view depth); 0 without
/// cascades. Every texel the crown may use must let the shader read the map alone at the leaf
/// (at most `LEAF_SHADOW_FINE` of the smallest leaf), as the CPU model here assumes.
fn cascade_texels(world: &mut World, camera: &GlobalTransform) -> impl Fn(Vec3) -> f32 + use<> {
    let bounds: Vec<(f32, f32)> = world
        .query::<(&Cascades, &CascadeShadowConfig)>()
        .iter(world)
        .next()
        .and_then(|(cascades, config)| {
            let per_view = cascades.cascades.values().next()?;
            Some(
                config
                    .bounds
                    .iter()
                    .zip(per_view)
                    .map(|(bound, cascade)| (*bound, cascade.texel_size))
                    .collect(),
            )
        })
        .unwrap_or_default();
    let (origin, forward) = (camera.translation(), camera.forward());
    move |p: Vec3| {
        let depth = (p - origin).dot(*forward);
        bounds
            .iter()
            .find(|(bound, _)| depth < *bound)
            .map_or(0.0, |(_, texel)| *texel)
    }
}

/// The test scene: a small olive, turned, under a sky and a sun, its leaves lit as a volume,
/// seen from a camera at exposure 1 with no tone mapping.
struct Scene {
    harness: RenderHarness,
    baked: BakedFoliage,
    lighting: TreeLightingSettings,
    instance: Transform,
    to_sun_world: Vec3,
    eye: Vec3,
    tree: Entity,
    radius: f32,
}

/// Adds the foliage plugin to `harness` with `lighting`, a black background and a sky of
/// radiance [`SKY`].
fn lit_app(harness: &mut RenderHarness, lighting: &TreeLightingSettings) {
    harness
        .app_mut()
        .add_plugins(FoliagePlugin)
        .insert_resource(lighting.clone())
        .insert_resource(ClearColor(Color::BLACK))
        .insert_resource(GlobalAmbientLight {
            color: Color::WHITE,
            brightness: SKY,
            ..default()
        });
}

/// A camera at exposure 1 (ev100 = log2(1 / 1.2)) with no tone mapping, dithering or MSAA: a
/// pixel is the sRGB encoding of the radiance the shader wrote.
fn unit_exposure_camera(transform: Transform) -> impl Bundle {
    (
        Camera3d::default(),
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
        Exposure {
            ev100: -(1.2f32).log2(),
        },
        transform,
    )
}

/// `ring`: the bounce ratios re-gathered on a ring at the sun's elevation
/// (`TreeLightingSettings::bounce_ring`) on; off, the leaves take the bake's blend alone.
fn scene(name: &str, sun_shadows: bool, ring: bool) -> Option<Scene> {
    let mut harness = RenderHarness::for_test(name, SIZE, SIZE)?;
    let lighting = TreeLightingSettings {
        enabled: true,
        // Bright optics (multiples of the base colour), so the bounce is a visible share of the
        // light.
        optics: bevy_foliage::lighting::model::LeafMaterial {
            reflectance_front: Vec3::new(0.25, 0.45, 0.15),
            reflectance_back: Vec3::new(0.3, 0.5, 0.2),
            transmittance_front: Vec3::new(0.2, 0.4, 0.1),
            transmittance_back: Vec3::new(0.2, 0.4, 0.1),
        },
        ground_albedo: Vec3::new(0.3, 0.25, 0.2),
        sun_through_crown: SunThroughCrown::BlendedAttenuation,
        bounce: true,
        gathered_bounce: true,
        seen_part: true,
        bounce_ring: BounceRingSettings {
            enabled: ring,
            ..default()
        },
    };
    lit_app(&mut harness, &lighting);
    harness.app_mut().insert_resource(FoliagePruningSettings {
        enabled: false,
        subpixel_fade: false,
        area_compensation: false,
        ..default()
    });
    let tree = generate(&TreeSpecies::olea().with_leaf_count(400));
    let (baked, _) = bake(
        &tree.leaves,
        &BakeSettings {
            cells: CellCount::Depth(4),
            resolution: 48,
            ..default()
        },
        &|_| {},
    )
    .unwrap();
    assert!(baked.extinction > 0.0, "the crown has leaves behind leaves");
    let crown = baked.crown_center();
    let radius = baked
        .positions
        .iter()
        .map(|p| p.distance(crown))
        .fold(0.0f32, f32::max);
    let handle = harness
        .world_mut()
        .resource_mut::<Assets<BakedFoliage>>()
        .add(baked.clone());
    let material = harness
        .world_mut()
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(StandardMaterial {
            base_color: Color::linear_rgb(BASE.x, BASE.y, BASE.z),
            ..default()
        }));
    // A turned instance: the shader must carry the sun and the eye into the tree's frame.
    let instance = Transform::from_rotation(Quat::from_rotation_y(0.7));
    let tree = harness
        .world_mut()
        .spawn((
            PrunedFoliage {
                baked: handle,
                material,
            },
            instance,
        ))
        .id();
    let to_sun_world = Vec3::new(0.5, 0.8, 0.3).normalize();
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: SUN,
            shadow_maps_enabled: sun_shadows,
            ..default()
        },
        Transform::default().looking_to(-to_sun_world, Vec3::Y),
    ));
    let centre_world = instance.transform_point(crown);
    let eye = centre_world + Vec3::new(-0.6, 0.25, 0.75).normalize() * radius * 3.2;
    harness.world_mut().spawn(unit_exposure_camera(
        Transform::from_translation(eye).looking_at(centre_world, Vec3::Y),
    ));
    harness.wait_until_ready().unwrap();
    Some(Scene {
        harness,
        baked,
        lighting,
        instance,
        to_sun_world,
        eye,
        tree,
        radius,
    })
}

/// What comparing a render with the CPU model found.
struct Check {
    compared: u32,
    within: u32,
    worst: f32,
    bounce_visible: u32,
    /// Compared pixels the covered part's gain on the bounce moves by more than 3/255.
    covered_visible: u32,
    /// Compared pixels the leaves' gathered bounce ratios move by more than 3/255.
    ratios_visible: u32,
    /// Compared pixels the type's ring of re-gathered ratios moves by more than 3/255 from the
    /// bake's blend.
    ring_visible: u32,
    /// Compared pixels the ring's sunlit shares move by more than 3/255 from the bake's blend.
    shares_visible: u32,
    /// Compared pixels the shares' slopes across their leaves move by more than 3/255 from
    /// the shares alone.
    slopes_visible: u32,
    /// Compared pixels the ring's own hotspot on its shares moves by more than 3/255 from the
    /// bake's hotspot on them.
    ring_hotspot_visible: u32,
    /// Compared pixels the leaves' open maps move by more than 3/255 from the eight gains, and
    /// pixels inside a leaf not compared for straddling two of its map's cells.
    map_visible: u32,
    map_edges: u32,
    /// Compared pixels the crown's hotspot moves by more than 3/255, and those its exponent on
    /// the sun alone moves so.
    hotspot_visible: u32,
    hotspot_sun_visible: u32,
    /// Compared pixels the sun reaches from outside the crown, and those it does not.
    sunlit: u32,
    shaded: u32,
    /// The compared pixels' shadow-map texels as shares of their leaf's size (with leaf
    /// shadows): the smallest and the largest.
    texel_in_leaves: (f32, f32),
    /// Compared pixels shaded only by leaves at most three texels of their cascade away along
    /// the sun (with leaf shadows: where a depth offset growing with the texel lets the sun
    /// through), and those of them within 3/255 of the model.
    close_shaded: u32,
    close_within: u32,
    image: RgbaImage,
    reference: RgbaImage,
}

impl Check {
    /// Writes the render and the CPU model's image under `nature-artifacts/tree_lighting/`.
    fn save(&self, name: &str) {
        let dir = artifacts_dir().join("tree_lighting");
        std::fs::create_dir_all(&dir).ok();
        self.image
            .save_png(dir.join(format!("{name}_gpu.png")))
            .ok();
        self.reference
            .save_png(dir.join(format!("{name}_cpu.png")))
            .ok();
    }
}

/// Compares the pixels of the next render that lie inside one leaf (a ray through the pixel's
/// centre and its four corners all hit it first) with the CPU model of that leaf's light.
/// `outside_blocked(p)` says whether something outside the crown stands between world point `p`
/// and the sun. With `leaf_shadows` (Bevy's shadow map resolves leaves), the sun's share at the
/// leaf is the shadow ray's answer — leaves and what is outside — instead of the baked blend
/// under the outside shadow. Points within `margin` of a shadow's edge (the answer changes
/// across the sun's light within it) are not compared. `ring`: the type's ring of re-gathered
/// bounce ratios the leaves hold (with `lighting.bounce_ring` on).
#[allow(clippy::too_many_arguments)]
fn compare_with_model(
    harness: &mut RenderHarness,
    baked: &BakedFoliage,
    lighting: &TreeLightingSettings,
    instance: Transform,
    to_sun_world: Vec3,
    eye: Vec3,
    outside_blocked: impl Fn(Vec3) -> bool,
    leaf_shadows: bool,
    margin: f32,
    ring: Option<&BounceRing>,
) -> Check {
    let image = harness.render().unwrap();
    let world = harness.world_mut();
    let (camera, camera_transform) = world
        .query::<(&Camera, &GlobalTransform)>()
        .single(world)
        .unwrap();
    let (camera, camera_transform) = (camera.clone(), *camera_transform);
    let scene = LeafScene::new(&stored_leaves(baked));
    let from_world = instance.compute_affine().inverse();
    let ray_leaf = |px: Vec2| -> Option<(u32, Vec3)> {
        let ray = camera.viewport_to_world(&camera_transform, px).ok()?;
        let origin = from_world.transform_point3(ray.origin);
        let dir = from_world.transform_vector3(*ray.direction).normalize();
        scene
            .hit(origin, dir, u32::MAX)
            .map(|(t, leaf)| (leaf, instance.transform_point(origin + dir * t)))
    };
    // The leaves' optics: the settings' multiples of the base colour.
    let optics = bevy_foliage::lighting::model::LeafMaterial {
        reflectance_front: lighting.optics.reflectance_front * BASE,
        reflectance_back: lighting.optics.reflectance_back * BASE,
        transmittance_front: lighting.optics.transmittance_front * BASE,
        transmittance_back: lighting.optics.transmittance_back * BASE,
    };
    let to_sun = from_world.transform_vector3(to_sun_world).normalize();
    let tau = baked.extinction;
    let sky = SkyLight::uniform(Vec3::splat(SKY), lighting.ground_albedo);
    let bounce = SunBounce::new(&optics, to_sun, tau);
    let eye_local = from_world.transform_point3(eye);
    let e_sun = Vec3::splat(SUN);
    // Where model point `p` of `leaf` lies among the vertices of its triangle: each vertex's
    // offset from the leaf's centroid in units of the leaf's radius (what the leaf vertex
    // shader reads the ring's sunlit shares along) with its barycentric weight, with which
    // the rasteriser carries the vertices' shares to the pixel.
    let radii = baked.leaf_radii();
    let (centroids, open_maps) = (baked.leaf_centroids(), baked.leaf_open_maps());
    // Which cell of its leaf's open map a model point reads, by the gain there (equal gains
    // read alike): a pixel whose centre lies within a tenth of a pixel of a cell's edge is not
    // compared (the rasteriser's interpolation and the ray may fall on either side).
    let map_cell = |leaf: u32, p: Vec3| -> u8 {
        open_maps.get(leaf as usize).map_or(0, |m| {
            let g = m
                .map
                .gain_at(p - centroids[leaf as usize], radii[leaf as usize]);
            open_map::quantize_cell_gain(g)
        })
    };
    let corners_at = |leaf: u32, p: Vec3| -> Vec<(Vec3, f32)> {
        let leaf = leaf as usize;
        let range =
            baked.leaf_index_start[leaf] as usize..baked.leaf_index_start[leaf + 1] as usize;
        let mut best: Option<(f32, [u32; 3], [f32; 3])> = None;
        for t in baked.indices[range].chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| baked.positions[i as usize]);
            let (v0, v1, v2) = (b - a, c - a, p - a);
            let (d00, d01, d11) = (v0.dot(v0), v0.dot(v1), v1.dot(v1));
            let (d20, d21) = (v2.dot(v0), v2.dot(v1));
            let det = d00 * d11 - d01 * d01;
            if det <= 0.0 {
                continue;
            }
            let v = (d11 * d20 - d01 * d21) / det;
            let w = (d00 * d21 - d01 * d20) / det;
            let weights = [1.0 - v - w, v, w];
            let inside = weights.iter().copied().fold(f32::INFINITY, f32::min);
            if best.is_none_or(|(b, _, _)| inside > b) {
                best = Some((inside, [t[0], t[1], t[2]], weights));
            }
        }
        let radius = radii[leaf].max(1e-6);
        best.map_or(vec![(Vec3::ZERO, 1.0)], |(_, t, weights)| {
            (0..3)
                .map(|i| (baked.centroid_offsets[t[i] as usize] / radius, weights[i]))
                .collect()
        })
    };
    // The light of `leaf` when the sun reaches it from outside the crown by `outside` and, with
    // leaf shadows, reaches the point by `at_leaf`.
    let expected = |leaf: u32,
                    bounce_on: bool,
                    covered_on: bool,
                    hotspot_on: bool,
                    ratios_on: bool,
                    ring_on: bool,
                    shares_on: bool,
                    slopes_on: bool,
                    ring_spot_on: bool,
                    map_on: bool,
                    corners: &[(Vec3, f32)],
                    at: Vec3,
                    outside: f32,
                    at_leaf: Option<f32>|
     -> Vec3 {
        let a = baked.leaf_light[leaf as usize].map(light_of);
        let s_max = a.map(|a| -a.max(DARKEST_LIGHT).ln() / tau);
        let first = baked.indices[baked.leaf_index_start[leaf as usize] as usize] as usize;
        let n = baked.normals[first].normalize();
        let wo = (eye_local - baked.positions[first]).normalize();
        let baked_through =
            sun_through_crown(SunThroughCrown::BlendedAttenuation, tau, &a, &s_max, to_sun);
        // The part of the leaf in view: its sky and its blended sun scaled by the gain towards
        // the eye (not the sun a shadow map resolves at the leaf), its bounce by the covered
        // part's gain.
        let seen = match baked.leaf_seen.get(leaf as usize) {
            Some(g) if lighting.seen_part => seen_gain(&g.map(gain_of), wo),
            _ => 1.0,
        };
        // The crown's hotspot by the angle between the eye and the sun, with the gains.
        let spot = if lighting.seen_part && hotspot_on {
            baked.hotspot
        } else {
            Hotspot::default()
        };
        // Where the type's ring holds the leaves' sunlit shares, those at its elevation, read
        // at each vertex of the pixel's triangle along their slopes across the leaf and
        // carried to the pixel by its barycentric weights (the fragment then caps and bends
        // the share there).
        let shares = ring
            .filter(|r| lighting.bounce_ring.enabled && shares_on && !r.sunlit.is_empty())
            .map(|r| {
                let slopes = r.sunlit_slopes.get(leaf as usize).filter(|_| slopes_on);
                (r.sun_height, &r.sunlit[leaf as usize], slopes)
            });
        let blend = spot.sun_through((baked_through * seen).min(1.0), wo, to_sun);
        let through = at_leaf.unwrap_or_else(|| {
            let read = shares.map(|(h, s, slopes)| {
                let mut at = [0.0; RING_NODES];
                for &(across, weight) in corners {
                    for (a, v) in
                        at.iter_mut()
                            .zip(ring_shares_at(s, slopes.map(|s| s.as_slice()), across))
                    {
                        *a += weight * v;
                    }
                }
                (h, at)
            });
            // The shares' exponent: the ring's own hotspot where it has one, else the bake's.
            let exponent = match ring {
                Some(r) if lighting.seen_part && hotspot_on && ring_spot_on => {
                    r.sun_exponent(spot.sun_at(wo, to_sun), wo, to_sun)
                }
                _ => spot.sun_at(wo, to_sun),
            };
            sun_through_with_ring(
                blend,
                read.as_ref().map(|(h, s)| (*h, s)),
                seen,
                exponent,
                to_sun,
            ) * outside
        });
        let bounced = if bounce_on {
            let covered = if lighting.seen_part && covered_on {
                covered_gain(seen, open_share(n, &a))
            } else {
                1.0
            };
            // Each face's bins by the leaf's gathered ratios towards the sun (read off the
            // type's ring where the sun is at its elevation).
            let basis = baked
                .leaf_bounce
                .get(leaf as usize)
                .map_or_else(BounceRatios::default, BounceRatios::from_stored);
            let ring = ring
                .filter(|_| lighting.bounce_ring.enabled && ring_on)
                .map(|r| (r.sun_height, &r.leaves[leaf as usize]));
            let faces = if lighting.gathered_bounce && ratios_on {
                ratio_with_ring(&basis, ring, to_sun)
            } else {
                [1.0; 2]
            };
            bounce_radiance_by_face(&optics, n, wo, &bounce, baked_through, &s_max, e_sun, faces)
                * (covered * outside * spot.bounce_at(wo, to_sun))
        } else {
            Vec3::ZERO
        };
        // The sky from the leaf's open map where it has one: the cell at the point (`at`, from
        // the leaf's centroid) times the residual gains blended towards the eye at each vertex
        // of the pixel's triangle and carried to the pixel by its barycentric weights, as the
        // vertex stage blends them.
        let sky_gain = match open_maps.get(leaf as usize) {
            Some(m) if lighting.seen_part && map_on && m.is_map() => {
                let (centroid, radius) = (centroids[leaf as usize], radii[leaf as usize]);
                let residual: f32 = corners
                    .iter()
                    .map(|&(across, weight)| {
                        let vertex = centroid + across * radius.max(1e-6);
                        weight * seen_gain(&m.residual_gains(), (eye_local - vertex).normalize())
                    })
                    .sum();
                m.map.gain_at(at, radius) * residual
            }
            _ => seen,
        };
        sky_radiance(&optics, n, wo, &a, &sky) * sky_gain
            + sun_radiance(&optics, n, wo, to_sun, through, e_sun)
            + bounced
    };
    // Whether the sun reaches world point p on `leaf`: nothing outside and, with leaf shadows,
    // no other leaf in the way from the point (moved towards the sun by the receiver-plane
    // comparison's slack, `LeafShadowPlane::SHADERS`, in texels of its cascade: what lies
    // within it counts as the leaf itself); `None` near the edge of a shadow.
    let (across_a, across_b) = to_sun_world.any_orthonormal_pair();
    let texel_at = cascade_texels(harness.world_mut(), &camera_transform);
    let leaves = stored_leaves(baked);
    let reaches = |leaf: u32, p: Vec3| -> bool {
        let moved = p + to_sun_world * (LeafShadowPlane::SHADERS.slack_texels * texel_at(p));
        !outside_blocked(p)
            && (!leaf_shadows
                || scene
                    .hit(from_world.transform_point3(moved), to_sun, leaf)
                    .is_none())
    };
    // Whether every leaf that shades p (with leaf shadows) lies within three texels of it
    // along the sun: the shadow map's nearest leaf there is then one just in front of p.
    let shaded_close = |leaf: u32, p: Vec3| -> bool {
        let moved = p + to_sun_world * (LeafShadowPlane::SHADERS.slack_texels * texel_at(p));
        let (mut origin, mut skip) = (from_world.transform_point3(moved), leaf);
        let mut outermost = None;
        for _ in 0..256 {
            let Some((t, hit)) = scene.hit(origin, to_sun, skip) else {
                break;
            };
            origin += to_sun * t;
            skip = hit;
            outermost = Some(origin);
        }
        leaf_shadows
            && outermost
                .is_some_and(|o| instance.transform_point(o).distance(moved) <= 3.0 * texel_at(p))
    };
    let sun_at = |leaf: u32, p: Vec3| -> Option<bool> {
        let here = reaches(leaf, p);
        [across_a, -across_a, across_b, -across_b]
            .iter()
            .all(|d| reaches(leaf, p + *d * margin) == here)
            .then_some(here)
    };
    let mut check = Check {
        compared: 0,
        within: 0,
        worst: 0.0,
        bounce_visible: 0,
        covered_visible: 0,
        ratios_visible: 0,
        ring_visible: 0,
        shares_visible: 0,
        ring_hotspot_visible: 0,
        slopes_visible: 0,
        hotspot_visible: 0,
        hotspot_sun_visible: 0,
        map_visible: 0,
        map_edges: 0,
        sunlit: 0,
        shaded: 0,
        texel_in_leaves: (f32::INFINITY, 0.0),
        close_shaded: 0,
        close_within: 0,
        image: RgbaImage::filled(SIZE, SIZE, [0, 0, 0, 255]),
        reference: RgbaImage::filled(SIZE, SIZE, [0, 0, 0, 255]),
    };
    for y in 0..SIZE {
        for x in 0..SIZE {
            let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let Some((leaf, point)) = ray_leaf(centre) else {
                continue;
            };
            let corners = [
                Vec2::new(-0.5, -0.5),
                Vec2::new(0.5, -0.5),
                Vec2::new(-0.5, 0.5),
                Vec2::new(0.5, 0.5),
            ];
            if corners
                .iter()
                .any(|c| ray_leaf(centre + *c).map(|h| h.0) != Some(leaf))
            {
                continue;
            }
            let local = from_world.transform_point3(point);
            let cell = map_cell(leaf, local);
            if corners.iter().any(|c| {
                ray_leaf(centre + *c * 0.1)
                    .is_none_or(|h| map_cell(leaf, from_world.transform_point3(h.1)) != cell)
            }) {
                check.map_edges += 1;
                continue;
            }
            if leaf_shadows {
                let (texel, size) = (texel_at(point), leaves.diameter(leaf as usize));
                assert!(
                    texel > 0.0 && texel <= LEAF_SHADOW_FINE * size,
                    "the shader reads the map alone at the leaf only at texels up to {LEAF_SHADOW_FINE} of a leaf: texel {texel}, leaf {size}"
                );
                let share = texel / size;
                check.texel_in_leaves = (
                    check.texel_in_leaves.0.min(share),
                    check.texel_in_leaves.1.max(share),
                );
            }
            let Some(lit) = sun_at(leaf, point) else {
                continue;
            };
            let outside = (!outside_blocked(point)) as u32 as f32;
            let at_leaf = leaf_shadows.then_some(lit as u32 as f32);
            if lit {
                check.sunlit += 1;
            } else {
                check.shaded += 1;
            }
            // The pixel the model gives with the bounce, the covered part's gain and the
            // hotspot each on or off, in 255ths of sRGB.
            let corners = corners_at(leaf, local);
            let at = local - centroids[leaf as usize];
            let pixel = |bounce: bool,
                         covered: bool,
                         hotspot: bool,
                         ratios: bool,
                         ring: bool,
                         shares: bool,
                         slopes: bool| {
                expected(
                    leaf, bounce, covered, hotspot, ratios, ring, shares, slopes, true, true,
                    &corners, at, outside, at_leaf,
                )
                .to_array()
                .map(|c| srgb(c) * 255.0)
            };
            let bake_spot_on_shares = expected(
                leaf, true, true, true, true, true, true, true, false, true, &corners, at, outside,
                at_leaf,
            )
            .to_array()
            .map(|c| srgb(c) * 255.0);
            let no_map = expected(
                leaf, true, true, true, true, true, true, true, true, false, &corners, at, outside,
                at_leaf,
            )
            .to_array()
            .map(|c| srgb(c) * 255.0);
            let want = pixel(true, true, true, true, true, true, true);
            let plain = pixel(false, true, true, true, true, true, true);
            let uncovered = pixel(true, false, true, true, true, true, true);
            let no_hotspot = pixel(true, true, false, true, true, true, true);
            let plain_no_hotspot = pixel(false, true, false, true, true, true, true);
            let no_ratios = pixel(true, true, true, false, true, true, true);
            let no_ring = pixel(true, true, true, true, false, true, true);
            let no_shares = pixel(true, true, true, true, true, false, true);
            let no_slopes = pixel(true, true, true, true, true, true, false);
            let got = image.pixel(x, y);
            let [r, g, b] = want.map(|c| c.round() as u8);
            check.reference.set_pixel(x, y, [r, g, b, 255]);
            let error = (0..3)
                .map(|c| (got[c] as f32 - want[c]).abs())
                .fold(0.0f32, f32::max);
            check.compared += 1;
            if error <= 3.0 {
                check.within += 1;
            }
            if !lit && shaded_close(leaf, point) {
                check.close_shaded += 1;
                check.close_within += (error <= 3.0) as u32;
            }
            check.worst = check.worst.max(error);
            if (0..3).any(|c| (want[c] - plain[c]).abs() > 6.0) {
                check.bounce_visible += 1;
            }
            if (0..3).any(|c| (want[c] - uncovered[c]).abs() > 3.0) {
                check.covered_visible += 1;
            }
            if (0..3).any(|c| (want[c] - no_ratios[c]).abs() > 3.0) {
                check.ratios_visible += 1;
            }
            if (0..3).any(|c| (want[c] - no_ring[c]).abs() > 3.0) {
                check.ring_visible += 1;
            }
            if (0..3).any(|c| (want[c] - no_shares[c]).abs() > 3.0) {
                check.shares_visible += 1;
            }
            if (0..3).any(|c| (want[c] - no_slopes[c]).abs() > 3.0) {
                check.slopes_visible += 1;
            }
            if (0..3).any(|c| (want[c] - bake_spot_on_shares[c]).abs() > 3.0) {
                check.ring_hotspot_visible += 1;
            }
            if (0..3).any(|c| (want[c] - no_map[c]).abs() > 3.0) {
                check.map_visible += 1;
            }
            if (0..3).any(|c| (want[c] - no_hotspot[c]).abs() > 3.0) {
                check.hotspot_visible += 1;
            }
            if (0..3).any(|c| (plain[c] - plain_no_hotspot[c]).abs() > 3.0) {
                check.hotspot_sun_visible += 1;
            }
        }
    }
    check.image = image;
    check
}

#[test]
fn leaves_show_the_light_the_cpu_model_gives_them() {
    let Some(Scene {
        mut harness,
        baked,
        lighting,
        instance,
        to_sun_world,
        eye,
        tree,
        ..
    }) = scene("tree_lighting", false, false)
    else {
        return;
    };
    for _ in 0..8 {
        harness.step();
    }
    let check = compare_with_model(
        &mut harness,
        &baked,
        &lighting,
        instance,
        to_sun_world,
        eye,
        |_| false,
        false,
        0.0,
        None,
    );
    check.save("tree");
    let Check {
        compared,
        within,
        worst,
        bounce_visible,
        ratios_visible,
        map_visible,
        map_edges,
        ..
    } = check;
    println!(
        "the bake's own bounce ratios move {ratios_visible} of {compared} leaf pixels by > 3/255"
    );
    // The leaves' open maps are a visible part of what is checked: the sky read from the cell
    // under the pixel, against the eight gains.
    println!(
        "the bake's open maps move {map_visible} of {compared} leaf pixels by > 3/255 ({map_edges} pixels on cell edges not compared)"
    );
    let mapped = baked.leaf_open_maps().iter().filter(|m| m.is_map()).count();
    println!("{mapped} of {} leaves have an open map", baked.leaf_count());
    assert!(
        mapped * 10 >= baked.leaf_count() * 9,
        "the bake stores only {mapped} of {} leaves' open maps",
        baked.leaf_count()
    );
    assert!(
        map_visible * 2 >= compared,
        "the open maps show in too few pixels ({map_visible} of {compared}) for the test to see them"
    );
    println!(
        "tree lighting: {compared} pixels inside leaves compared, {within} within 3/255, worst {worst:.1}/255; the bounce moves {bounce_visible} of them by > 6/255; the crown's hotspot {:?}",
        baked.hotspot
    );
    assert!(
        compared >= 800,
        "too few leaf pixels to compare: {compared}"
    );
    assert!(
        within as f32 >= 0.99 * compared as f32,
        "{within} of {compared} leaf pixels within 3/255 of the CPU model (worst {worst:.1})"
    );

    // Without the seen-part gains and the gathered ratios the leaves show the model without
    // them (eq. 5.24 as it is), and many pixels move.
    let without = TreeLightingSettings {
        seen_part: false,
        gathered_bounce: false,
        ..lighting.clone()
    };
    harness.world_mut().insert_resource(without.clone());
    for _ in 0..4 {
        harness.step();
    }
    let plain = compare_with_model(
        &mut harness,
        &baked,
        &without,
        instance,
        to_sun_world,
        eye,
        |_| false,
        false,
        0.0,
        None,
    );
    let moved = (0..check.image.height)
        .flat_map(|y| (0..check.image.width).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let (a, b) = (check.image.pixel(x, y), plain.image.pixel(x, y));
            (0..3).any(|c| (a[c] as i32 - b[c] as i32).abs() > 3)
        })
        .count();
    println!(
        "without the seen-part gains and the bounce ratios: {} of {} within 3/255 of the model without them, worst {:.1}/255; {moved} pixels moved by > 3/255",
        plain.within, plain.compared, plain.worst
    );
    assert!(
        plain.within as f32 >= 0.99 * plain.compared as f32,
        "{} of {} leaf pixels within 3/255 of the CPU model without the gains",
        plain.within,
        plain.compared
    );
    assert!(
        moved * 4 >= compared as usize,
        "the gains move only {moved} pixels"
    );
    // The bounce is a visible part of what is checked: here, where the gains, the ratios (on
    // this crown below 1 on average) and the crown's hotspot leave it whole.
    println!(
        "without them the bounce moves {} of {} by > 6/255",
        plain.bounce_visible, plain.compared
    );
    assert!(
        plain.bounce_visible * 4 >= plain.compared,
        "the bounce shows in too few pixels ({} of {}) for the test to see it",
        plain.bounce_visible,
        plain.compared
    );

    // The bounce takes the covered part's gain: with strong gains (every leaf's seen part much
    // more open than the leaf) it falls, and the leaves show the model with it — in pixels
    // where a bounce without it would be off by more than the tolerance.
    harness.world_mut().insert_resource(lighting.clone());
    // And a strong hotspot: the blended sun raised to 1/3 (brighter) and the bounce doubled,
    // which the model with them must follow too.
    // And strong bounce ratios, different on each face and for each basis sun (so a shader
    // that reads them out of order, or blends them towards the wrong sun, fails).
    let strong_ratios = BounceRatios {
        front: std::array::from_fn(|k| 0.5 + 0.1 * k as f32),
        back: std::array::from_fn(|k| 6.0 + 0.3 * k as f32),
    }
    .quantized();
    // And strong open maps, each cell and each octant's residual gain its own (so a shader
    // that reads the cells on the wrong axes or in the wrong order, or the residual gains out
    // of order, fails), on each leaf's own grid.
    let strong_open: Vec<LeafOpenMap> = baked
        .leaf_open
        .iter()
        .map(|m| LeafOpenMap {
            map: StoredOpenMap {
                cells: STRONG_CELLS.map(open_map::quantize_cell_gain),
                axes: m.map.axes,
            },
            residual: std::array::from_fn(|j| quantize_gain(0.6 + 0.15 * j as f32)),
        })
        .collect();
    let strong = BakedFoliage {
        leaf_seen: vec![[quantize_gain(STRONG_GAIN); 8]; baked.leaf_count()],
        leaf_open: strong_open,
        leaf_bounce: vec![strong_ratios; baked.leaf_count()],
        hotspot: Hotspot {
            sun: [STRONG_HOTSPOT.0; HOTSPOT_NODES],
            bounce: [STRONG_HOTSPOT.1; HOTSPOT_NODES],
        }
        .sanitized()
        .0,
        ..baked.clone()
    };
    let material = harness
        .world_mut()
        .get::<PrunedFoliage>(tree)
        .unwrap()
        .material
        .clone();
    let handle = harness
        .world_mut()
        .resource_mut::<Assets<BakedFoliage>>()
        .add(strong.clone());
    harness.world_mut().despawn(tree);
    harness.world_mut().spawn((
        PrunedFoliage {
            baked: handle,
            material,
        },
        instance,
    ));
    for _ in 0..4 {
        harness.step();
    }
    harness.wait_until_ready().unwrap();
    let covered = compare_with_model(
        &mut harness,
        &strong,
        &lighting,
        instance,
        to_sun_world,
        eye,
        |_| false,
        false,
        0.0,
        None,
    );
    covered.save("tree_strong_gains");
    println!(
        "with every gain {STRONG_GAIN}: {} of {} within 3/255 of the model, worst {:.1}/255; the covered part's gain moves {} of them by > 3/255",
        covered.within, covered.compared, covered.worst, covered.covered_visible
    );
    assert!(
        covered.covered_visible * 4 >= covered.compared,
        "the covered part's gain shows in too few pixels ({} of {}) for the test to see it",
        covered.covered_visible,
        covered.compared
    );
    println!(
        "the strong bounce ratios move {} of {} by > 3/255",
        covered.ratios_visible, covered.compared
    );
    assert!(
        covered.ratios_visible * 4 >= covered.compared,
        "the bounce ratios show in too few pixels ({} of {}) for the test to see it",
        covered.ratios_visible,
        covered.compared
    );
    println!(
        "the crown's hotspot (sun exponent {}, bounce × {}) moves {} of {} by > 3/255 ({} by its sun alone)",
        STRONG_HOTSPOT.0,
        STRONG_HOTSPOT.1,
        covered.hotspot_visible,
        covered.compared,
        covered.hotspot_sun_visible
    );
    assert!(
        covered.hotspot_visible * 4 >= covered.compared
            && covered.hotspot_sun_visible * 5 >= covered.compared,
        "the hotspot shows in too few pixels ({} of {}, {} by its sun alone) for the test to see it",
        covered.hotspot_visible,
        covered.compared,
        covered.hotspot_sun_visible
    );
    println!(
        "the strong open maps move {} of {} by > 3/255 ({} on cell edges not compared)",
        covered.map_visible, covered.compared, covered.map_edges
    );
    assert!(
        covered.map_visible * 4 >= covered.compared * 3,
        "the strong open maps show in too few pixels ({} of {}) for the test to see them",
        covered.map_visible,
        covered.compared
    );
    assert!(
        covered.within as f32 >= 0.99 * covered.compared as f32,
        "{} of {} leaf pixels within 3/255 of the CPU model with strong gains (worst {:.1})",
        covered.within,
        covered.compared,
        covered.worst
    );
}

/// Steps `harness` until the bounce ring of tree type `id` is in and none is being gathered
/// (at most a minute of frames), and returns it.
fn wait_for_ring(harness: &mut RenderHarness, id: AssetId<BakedFoliage>) -> BounceRing {
    use bevy_foliage::pruning::regather::BounceRings;
    let started = std::time::Instant::now();
    loop {
        harness.step();
        let rings = harness.world_mut().resource::<BounceRings>();
        if let (Some(ring), false) = (rings.ring(id), rings.is_gathering(id)) {
            return ring.clone();
        }
        assert!(
            started.elapsed().as_secs() < 60,
            "no bounce ring gathered within a minute"
        );
    }
}

/// The leaves read the bounce ratios their type's ring holds where the sun is at its elevation:
/// the ring the app re-gathers and refines is the CPU's [`gather_ring_refined`] of the loaded
/// bake for the sun's elevation, byte for byte (its ratios refined to the settings' passes,
/// unlike its first pass, its sunlit shares and their slopes, its own hotspot on them); the
/// render matches the CPU model with it; a ring of strong ratios, shares, slopes
/// and hotspot, distinct per node and face, moves many pixels and the render follows; the
/// bake's hotspot bends the shares of a ring without one; and an instance tilted
/// so that the sun stands 4° off the ring's elevation in its frame takes the ring and the
/// bake's blend half and half, as the model does. Then the sun's elevation moves and a new
/// ring is gathered for it; and a ring asked for more passes than it has, having let go of its
/// passes' sums, is gathered anew and refined to them.
///
/// [`gather_ring_refined`]: bevy_foliage::lighting::bounce_ring::gather_ring_refined
#[test]
fn leaves_read_the_bounce_ring_regathered_at_the_suns_elevation() {
    use bevy_foliage::lighting::bounce_ring::{
        RING_FULL_DEGREES, RING_GONE_DEGREES, RING_HOTSPOT, gather_ring_refined, ring_weight,
    };
    use bevy_foliage::lighting::gathered_bounce::quantize_ratio;
    use bevy_foliage::pruning::regather::BounceRings;
    let Some(Scene {
        mut harness,
        baked,
        lighting,
        instance,
        to_sun_world,
        eye,
        tree,
        ..
    }) = scene("tree_lighting_ring", false, true)
    else {
        return;
    };
    let id = harness
        .world_mut()
        .get::<PrunedFoliage>(tree)
        .unwrap()
        .baked
        .id();
    // The render of the next frame against the CPU model with `ring` and the instance as
    // `instance`, 99 % of its leaf pixels within 3/255 of the model.
    let compare = |harness: &mut RenderHarness, instance: Transform, ring: &BounceRing, name| {
        let check = compare_with_model(
            harness,
            &baked,
            &lighting,
            instance,
            to_sun_world,
            eye,
            |_| false,
            false,
            0.0,
            Some(ring),
        );
        check.save(name);
        println!(
            "{name}: {} of {} leaf pixels within 3/255 of the CPU model (worst {:.1}/255); the ring moves {} of them from the bake's blend by > 3/255, its sunlit shares {}, their slopes across the leaves {}, its own hotspot on them (against the bake's) {}",
            check.within,
            check.compared,
            check.worst,
            check.ring_visible,
            check.shares_visible,
            check.slopes_visible,
            check.ring_hotspot_visible
        );
        assert!(
            check.compared >= 800,
            "too few leaf pixels: {}",
            check.compared
        );
        assert!(
            check.within as f32 >= 0.99 * check.compared as f32,
            "{name}: {} of {} leaf pixels within 3/255 of the CPU model (worst {:.1})",
            check.within,
            check.compared,
            check.worst
        );
        check
    };
    let ring = wait_for_ring(&mut harness, id);
    // The CPU's gather of the loaded bake at the sun's elevation (the instance is turned about
    // its vertical only: its frame's elevation is the world's).
    let all: Vec<u32> = (0..baked.leaf_count() as u32).collect();
    let opacity = baked.leaf_opacity;
    // Refined to `passes` passes (1: the first pass alone).
    let cpu_ring = |passes: u32| {
        gather_ring_refined(
            &baked.leaf_scene(),
            &lighting.optics,
            &all,
            &baked.leaf_envelopes(),
            baked.extinction,
            ring.sun_height,
            lighting.bounce_ring.rays,
            passes,
            lighting.bounce_ring.sunlit_points,
            &baked.leaf_radii(),
            &baked.leaf_seen_gains(),
            &RING_HOTSPOT,
            &|_| opacity,
            2,
        )
    };
    let cpu = cpu_ring(lighting.bounce_ring.passes);
    assert!(
        (ring.sun_height - to_sun_world.y).abs() < 1e-5,
        "ring at sun height {} for the sun at {}",
        ring.sun_height,
        to_sun_world.y
    );
    assert_eq!(ring.leaves.len(), baked.leaf_count());
    let same = ring
        .leaves
        .iter()
        .zip(&cpu.leaves)
        .filter(|(a, b)| a == b)
        .count();
    assert_eq!(
        same,
        baked.leaf_count(),
        "leaves whose ring ratios the app gathered as the CPU does"
    );
    // Refined: the app's ring is the mean of its passes, not its first pass alone; with all
    // of them in, it lets go of what would refine it further.
    assert_eq!(
        harness.world_mut().resource::<BounceRings>().passes(id),
        Some(lighting.bounce_ring.passes)
    );
    assert_eq!(
        harness
            .world_mut()
            .resource::<BounceRings>()
            .refinement_bytes(id),
        0,
        "bytes held to refine a ring that has its passes"
    );
    let pass_seconds = harness
        .world_mut()
        .resource::<BounceRings>()
        .last_pass_seconds();
    assert!(
        pass_seconds.is_some_and(|s| s > 0.0 && s.is_finite()),
        "seconds a further pass took: {pass_seconds:?}"
    );
    let first = cpu_ring(1);
    let refined = ring
        .leaves
        .iter()
        .zip(&first.leaves)
        .filter(|(a, b)| a != b)
        .count();
    println!(
        "the ring refined to {} passes: {refined} of {} leaves' ratios moved from its first pass",
        lighting.bounce_ring.passes,
        baked.leaf_count()
    );
    assert!(
        refined * 2 >= baked.leaf_count(),
        "the refinement moved only {refined} of {} leaves' ratios",
        baked.leaf_count()
    );
    assert!(ring.sunlit == first.sunlit && ring.sunlit_hotspot == first.sunlit_hotspot);
    assert_eq!(
        ring.sunlit.len(),
        baked.leaf_count(),
        "the ring holds sunlit shares"
    );
    assert!(
        ring.sunlit == cpu.sunlit,
        "the leaves' sunlit shares on the ring as the CPU traces them"
    );
    assert!(
        ring.sunlit_slopes.len() == baked.leaf_count() && ring.sunlit_slopes == cpu.sunlit_slopes,
        "the shares' slopes across the leaves as the CPU fits them"
    );
    assert!(
        ring.sun_hotspot().is_some() && ring.sunlit_hotspot == cpu.sunlit_hotspot,
        "the ring's own hotspot on its shares as the CPU fits it: {:?} against {:?}",
        ring.sunlit_hotspot,
        cpu.sunlit_hotspot
    );
    for _ in 0..4 {
        harness.step();
    }
    compare(&mut harness, instance, &ring, "tree_ring");

    // A ring of strong ratios, distinct per node and face (a shader that reads the nodes out of
    // order, by another azimuth or with the faces swapped fails), put in at the sun's height.
    let strong = BounceRing {
        sun_height: ring.sun_height,
        leaves: vec![
            std::array::from_fn(|i| {
                if i < RING_NODES {
                    quantize_ratio(0.3 + 0.25 * i as f32)
                } else {
                    quantize_ratio(6.0 - 0.35 * (i - RING_NODES) as f32)
                }
            });
            baked.leaf_count()
        ],
        // Sunlit shares distinct per node and per leaf (a shader that reads another leaf's,
        // another node's or none fails).
        sunlit: (0..baked.leaf_count())
            .map(|l| std::array::from_fn(|k| (20 + (l * 37 + k * 61) % 215) as u8))
            .collect(),
        // Slopes distinct per leaf, node and component (a shader that reads them from another
        // place, another component or with the wrong sign fails).
        sunlit_slopes: (0..baked.leaf_count())
            .map(|l| {
                std::array::from_fn(|k| {
                    [0usize, 1, 2].map(|c| (((l * 29 + k * 47 + c * 83) % 161) as i32 - 80) as i8)
                })
            })
            .collect(),
        // A hotspot on the shares distinct per node and far from the bake's (a shader that
        // reads the bake's, or the nodes out of order, fails).
        sunlit_hotspot: std::array::from_fn(|k| Hotspot::quantize(2.6 - 0.3 * k as f32)),
        crown_weights: Vec::new(),
    };
    harness
        .world_mut()
        .resource_mut::<BounceRings>()
        .insert(id, strong.clone());
    for _ in 0..4 {
        harness.step();
    }
    let completed = harness.world_mut().resource::<BounceRings>().completed();
    let strong_check = compare(&mut harness, instance, &strong, "tree_ring_strong");
    assert_eq!(
        harness.world_mut().resource::<BounceRings>().completed(),
        completed,
        "a ring at the sun's elevation is not gathered again"
    );
    assert!(
        strong_check.ring_visible * 4 >= strong_check.compared,
        "the ring shows in too few pixels ({} of {}) for the test to see it",
        strong_check.ring_visible,
        strong_check.compared
    );
    assert!(
        strong_check.shares_visible * 2 >= strong_check.compared,
        "the ring's sunlit shares show in too few pixels ({} of {}) for the test to see them",
        strong_check.shares_visible,
        strong_check.compared
    );
    assert!(
        strong_check.slopes_visible * 3 >= strong_check.compared,
        "the shares' slopes show in too few pixels ({} of {}) for the test to see them",
        strong_check.slopes_visible,
        strong_check.compared
    );
    assert!(
        strong_check.ring_hotspot_visible * 5 >= strong_check.compared,
        "the ring's own hotspot shows in too few pixels ({} of {}) for the test to see it",
        strong_check.ring_hotspot_visible,
        strong_check.compared
    );

    // The crown's hotspot on the ring's shares where the ring has none of its own: the same
    // tree with a strong sun exponent, its strong ring put in for it (without slopes, which
    // would carry most vertices' shares to 0 or 1, where no exponent shows, and without its
    // hotspot), against the model with that exponent (a shader that left the hotspot off the
    // ring's shares fails).
    let flat = BounceRing {
        sunlit_slopes: Vec::new(),
        sunlit_hotspot: [0; HOTSPOT_NODES],
        ..strong.clone()
    };
    let hot = BakedFoliage {
        hotspot: Hotspot {
            sun: [STRONG_HOTSPOT.0; HOTSPOT_NODES],
            bounce: [1.0; HOTSPOT_NODES],
        }
        .sanitized()
        .0,
        ..baked.clone()
    };
    let material = harness
        .world_mut()
        .get::<PrunedFoliage>(tree)
        .unwrap()
        .material
        .clone();
    let hot_handle = harness
        .world_mut()
        .resource_mut::<Assets<BakedFoliage>>()
        .add(hot.clone());
    harness
        .world_mut()
        .resource_mut::<BounceRings>()
        .insert(hot_handle.id(), flat.clone());
    let original = harness
        .world_mut()
        .get::<PrunedFoliage>(tree)
        .unwrap()
        .clone();
    harness.world_mut().entity_mut(tree).insert(PrunedFoliage {
        baked: hot_handle,
        material,
    });
    for _ in 0..4 {
        harness.step();
    }
    let hot_check = compare_with_model(
        &mut harness,
        &hot,
        &lighting,
        instance,
        to_sun_world,
        eye,
        |_| false,
        false,
        0.0,
        Some(&flat),
    );
    hot_check.save("tree_ring_hotspot");
    println!(
        "tree_ring_hotspot: {} of {} leaf pixels within 3/255 of the CPU model (worst {:.1}/255); the hotspot's sun exponent moves {} of them",
        hot_check.within, hot_check.compared, hot_check.worst, hot_check.hotspot_sun_visible
    );
    assert!(
        hot_check.compared >= 800 && hot_check.within as f32 >= 0.99 * hot_check.compared as f32,
        "with the hotspot on the ring's shares: {} of {} leaf pixels within 3/255 (worst {:.1})",
        hot_check.within,
        hot_check.compared,
        hot_check.worst
    );
    assert!(
        hot_check.hotspot_sun_visible * 4 >= hot_check.compared,
        "the hotspot on the ring's shares shows in too few pixels ({} of {})",
        hot_check.hotspot_sun_visible,
        hot_check.compared
    );
    harness.world_mut().entity_mut(tree).insert(original);
    for _ in 0..4 {
        harness.step();
    }

    // Tilted so that the sun stands midway between the ring's whole and gone spans of elevation
    // in the instance's frame: half ring, half blend.
    let across = Vec3::Y
        .cross(Vec3::new(to_sun_world.x, 0.0, to_sun_world.z))
        .normalize();
    let tilt = (0.5 * (RING_FULL_DEGREES + RING_GONE_DEGREES)).to_radians();
    let tilted = Transform::from_rotation(Quat::from_axis_angle(across, tilt) * instance.rotation);
    let local_sun = tilted.rotation.inverse() * to_sun_world;
    let w = ring_weight(to_sun_world.y, local_sun);
    assert!(
        (w - 0.5).abs() < 0.05,
        "ring weight {w} in the tilted frame"
    );
    harness.world_mut().entity_mut(tree).insert(tilted);
    for _ in 0..4 {
        harness.step();
    }
    println!("tilted: ring weight {w:.2}");
    let half = compare(&mut harness, tilted, &strong, "tree_ring_tilted");
    assert!(
        half.ring_visible * 5 >= half.compared,
        "the half ring shows in too few pixels ({} of {})",
        half.ring_visible,
        half.compared
    );

    // The sun's elevation moves by 10°: a new ring is gathered for it.
    let lower = {
        let e = to_sun_world.y.asin() - 10f32.to_radians();
        let flat = Vec3::new(to_sun_world.x, 0.0, to_sun_world.z).normalize();
        (flat * e.cos() + Vec3::Y * e.sin()).normalize()
    };
    let world = harness.world_mut();
    let sun = world
        .query_filtered::<Entity, With<DirectionalLight>>()
        .single(world)
        .unwrap();
    world
        .entity_mut(sun)
        .insert(Transform::default().looking_to(-lower, Vec3::Y));
    let started = std::time::Instant::now();
    let moved = loop {
        harness.step();
        let rings = harness.world_mut().resource::<BounceRings>();
        match rings.ring(id) {
            Some(r) if r.sun_height != strong.sun_height && !rings.is_gathering(id) => {
                break r.clone();
            }
            _ => assert!(
                started.elapsed().as_secs() < 60,
                "no new ring within a minute"
            ),
        }
    };
    assert!(
        (moved.sun_height - lower.y).abs() < 1e-4,
        "the new ring's sun height {} for a sun at {}",
        moved.sun_height,
        lower.y
    );
    assert!(moved.leaves != strong.leaves && moved.leaves != ring.leaves);

    // Sunlit shares turned off: the ring is gathered again without them, and the leaves take
    // the bake's blend for the sun (a shader that read the missing shares as zeros would draw
    // the sun out).
    harness
        .world_mut()
        .resource_mut::<TreeLightingSettings>()
        .bounce_ring
        .sunlit_points = 0;
    let started = std::time::Instant::now();
    let bare = loop {
        harness.step();
        let rings = harness.world_mut().resource::<BounceRings>();
        match rings.ring(id) {
            Some(r) if r.sunlit.is_empty() && !rings.is_gathering(id) => break r.clone(),
            _ => assert!(
                started.elapsed().as_secs() < 60,
                "no ring without shares within a minute"
            ),
        }
    };
    // Without the shares' planes the gather casts shadow rays at its neighbour hits: the
    // CPU's gather so, at the same height, byte for byte, and not the ring gathered through
    // the planes.
    let shadowed = gather_ring_refined(
        &baked.leaf_scene(),
        &lighting.optics,
        &all,
        &baked.leaf_envelopes(),
        baked.extinction,
        moved.sun_height,
        lighting.bounce_ring.rays,
        lighting.bounce_ring.passes,
        0,
        &baked.leaf_radii(),
        &baked.leaf_seen_gains(),
        &RING_HOTSPOT,
        &|_| opacity,
        2,
    );
    assert_eq!(
        bare.leaves, shadowed.leaves,
        "the ratios gathered with shadow rays"
    );
    assert!(bare.leaves != moved.leaves, "the planes moved the ratios");
    for _ in 0..4 {
        harness.step();
    }
    let mut bare_lighting = lighting.clone();
    bare_lighting.bounce_ring.sunlit_points = 0;
    let check = compare_with_model(
        &mut harness,
        &baked,
        &bare_lighting,
        tilted,
        lower,
        eye,
        |_| false,
        false,
        0.0,
        Some(&bare),
    );
    check.save("tree_ring_no_shares");
    println!(
        "no shares: {} of {} leaf pixels within 3/255 of the CPU model (worst {:.1}/255)",
        check.within, check.compared, check.worst
    );
    assert!(
        check.compared >= 800 && check.within as f32 >= 0.99 * check.compared as f32,
        "without shares: {} of {} leaf pixels within 3/255 of the CPU model (worst {:.1})",
        check.within,
        check.compared,
        check.worst
    );

    // More passes asked of a ring that let go of its sums: it is gathered anew and refined to
    // them, holding its sums while it is refined and letting go of them at the end.
    let more = lighting.bounce_ring.passes + 2;
    let gathers = harness.world_mut().resource::<BounceRings>().completed();
    harness
        .world_mut()
        .resource_mut::<TreeLightingSettings>()
        .bounce_ring
        .passes = more;
    let started = std::time::Instant::now();
    let mut held_while_refining = 0;
    let again = loop {
        harness.step();
        let rings = harness.world_mut().resource::<BounceRings>();
        if rings.passes(id).is_some_and(|p| p < more) {
            held_while_refining = held_while_refining.max(rings.refinement_bytes(id));
        }
        match (rings.ring(id), rings.passes(id)) {
            (Some(r), Some(p)) if p == more && !rings.is_gathering(id) => break r.clone(),
            _ => assert!(
                started.elapsed().as_secs() < 60,
                "no ring of {more} passes within a minute"
            ),
        }
    };
    println!(
        "refined again to {more} passes: {held_while_refining} bytes held while refining {} leaves, none after",
        baked.leaf_count()
    );
    let rings = harness.world_mut().resource::<BounceRings>();
    assert_eq!(rings.completed(), gathers + 1, "the ring gathered anew");
    assert_eq!(rings.refinement_bytes(id), 0);
    assert!(
        held_while_refining >= baked.leaf_count() * RING_NODES * 8,
        "{held_while_refining} bytes held while refining {} leaves",
        baked.leaf_count()
    );
    let refined_more = gather_ring_refined(
        &baked.leaf_scene(),
        &lighting.optics,
        &all,
        &baked.leaf_envelopes(),
        baked.extinction,
        bare.sun_height,
        lighting.bounce_ring.rays,
        more,
        0,
        &baked.leaf_radii(),
        &baked.leaf_seen_gains(),
        &RING_HOTSPOT,
        &|_| opacity,
        2,
    );
    assert_eq!(
        again.leaves, refined_more.leaves,
        "the ring refined to {more} passes as the CPU refines it"
    );
}

/// A ring landing rewrites the leaves' light buffer (a new buffer, which the leaf materials are
/// prepared anew with); the leaves stay drawn, and as they were, in the frame it lands in and
/// the two after it (a frame drawn before the materials are prepared again would have none).
#[test]
fn leaves_stay_drawn_in_the_frames_a_ring_lands() {
    use bevy_foliage::pruning::regather::BounceRings;
    let Some(Scene {
        mut harness, tree, ..
    }) = scene("tree_lighting_ring_landing", false, true)
    else {
        return;
    };
    let id = harness
        .world_mut()
        .get::<PrunedFoliage>(tree)
        .unwrap()
        .baked
        .id();
    let ring = wait_for_ring(&mut harness, id);
    for _ in 0..4 {
        harness.step();
    }
    let settled = harness.render().expect("render");
    let lit = |image: &RgbaImage| {
        image
            .data
            .chunks_exact(4)
            .filter(|p| p[0].max(p[1]).max(p[2]) > 8)
            .count()
    };
    let leaf_pixels = lit(&settled);
    assert!(leaf_pixels > 800, "too few leaf pixels: {leaf_pixels}");
    // The same ring put in again: the buffer is rewritten with the same words, so every frame
    // from the one it lands in must be the settled one. It is rewritten in place: the leaf
    // materials keep their buffer (a new one has them prepared again, which Bevy may leave a
    // frame behind the buffer, every leaf undrawn in that frame).
    let bound = |harness: &mut bevy_nature_harness::RenderHarness| {
        let store = harness
            .world_mut()
            .resource::<bevy_foliage::pruning::store::FoliageStore>();
        (store.buffers.leaf_light.clone(), store.generation)
    };
    let before = bound(&mut harness);
    for landing in 0..3 {
        harness
            .world_mut()
            .resource_mut::<BounceRings>()
            .insert(id, ring.clone());
        for frame in 0..3 {
            let image = harness.render().expect("render");
            assert_eq!(
                bound(&mut harness),
                before,
                "landing {landing}: the leaf light buffer was replaced, not rewritten"
            );
            let moved = image
                .data
                .chunks_exact(4)
                .zip(settled.data.chunks_exact(4))
                .filter(|(a, b)| (0..3).any(|c| a[c].abs_diff(b[c]) > 3))
                .count();
            assert_eq!(
                moved,
                0,
                "landing {landing}, frame {frame}: {moved} pixels changed ({} leaf pixels, {leaf_pixels} settled)",
                lit(&image)
            );
        }
    }
}

/// The crown's light summed over the image: the mean linear luminance of every pixel (the black
/// background adds nothing), so leaves lost, leaves shrunk and leaves lit darker all lower it.
fn crown_light(image: &RgbaImage) -> f64 {
    let linear = |c: u8| {
        let c = c as f64 / 255.0;
        if c <= 0.040_45 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let mut sum = 0.0;
    for y in 0..image.height {
        for x in 0..image.width {
            let p = image.pixel(x, y);
            sum += 0.2126 * linear(p[0]) + 0.7152 * linear(p[1]) + 0.0722 * linear(p[2]);
        }
    }
    sum / (image.width * image.height) as f64
}

#[test]
fn a_pruned_crown_keeps_its_light() {
    let Some(Scene {
        mut harness,
        baked,
        eye,
        instance,
        tree,
        ..
    }) = scene("tree_lighting_pruned", false, false)
    else {
        return;
    };
    let distance = eye.distance(instance.transform_point(baked.crown_center()));
    let full = render_with_settings(&mut harness, |_| {});
    // Pruned at the same view: under half the leaves kept (eq. 3.4 between near and far; the
    // leaves kept are the visible ones first).
    let distances = LodDistances::World {
        near: 0.7 * distance,
        far: 3.0 * distance,
    };
    let compensated = render_with_settings(&mut harness, |s| {
        s.enabled = true;
        s.distances = distances;
        s.area_compensation = true;
    });
    let params = *harness
        .world_mut()
        .get::<PruningParams>(tree)
        .expect("pruning parameters");
    let kept = kept_index_total(
        &baked.pruning_input(),
        &params.camera.weights,
        params.camera.distance_fixed,
    ) as f64
        / baked.indices.len() as f64;
    let plain = render_with_settings(&mut harness, |s| s.area_compensation = false);
    let dir = artifacts_dir().join("tree_lighting");
    std::fs::create_dir_all(&dir).ok();
    for (name, image) in [
        ("full", &full),
        ("pruned", &compensated),
        ("pruned_plain", &plain),
    ] {
        image.save_png(dir.join(format!("crown_{name}.png"))).ok();
    }
    let (l_full, l_pruned, l_plain) = (
        crown_light(&full),
        crown_light(&compensated),
        crown_light(&plain),
    );
    let change = (l_pruned - l_full) / l_full;
    let plain_change = (l_plain - l_full) / l_full;
    println!(
        "tree lighting under pruning: {:.0} % of the leaves kept; crown light {l_full:.5} full, {l_pruned:.5} pruned ({:+.1} %), {l_plain:.5} pruned without area compensation ({:+.1} %)",
        kept * 100.0,
        change * 100.0,
        plain_change * 100.0
    );
    assert!(
        (0.2..0.6).contains(&kept),
        "the view should prune a good part of the leaves, kept {kept:.2}"
    );
    assert!(
        change.abs() < TOLERANCE,
        "the pruned crown's light moved {:+.1} % (tolerance {:.0} %)",
        change * 100.0,
        TOLERANCE * 100.0
    );
    // The measure sees what pruning without compensation loses.
    assert!(
        plain_change < -2.0 * TOLERANCE,
        "pruning without area compensation should lose clearly more light: {:+.1} %",
        plain_change * 100.0
    );
}

/// The sun's shadow cascades of a [`sun_shadows`] scene.
#[derive(Clone, Copy, PartialEq)]
enum SunCascades {
    /// Bevy's default cascades: texels under a sixteenth of a leaf here.
    Default,
    /// One cascade whose texels are about this share of the leaves' median diameter (at most
    /// `LEAF_SHADOW_FINE` of every leaf: the shader still reads the map alone at the leaf).
    LeafShare(f32),
    /// One cascade of texels of metres, larger than a leaf: the baked blend alone.
    Coarse,
}

/// The tree with the sun's shadows on: under a plate shading half its crown, in `cascades`
/// (Bevy's default ones, texels under a sixteenth of a leaf here, or one cascade of texels a
/// given share of a leaf, which the comparison checks: the shadow map read at the leaf), or
/// alone in one coarse cascade (texels of metres, larger than a leaf: the baked blend, under
/// the map read where the light enters the crown, which must not see the crown's own leaves).
fn sun_shadows(name: &str, cascades: SunCascades) -> Option<Check> {
    let Scene {
        mut harness,
        baked,
        lighting,
        instance,
        to_sun_world,
        eye,
        radius,
        ..
    } = scene(name, true, false)?;
    let coarse = cascades == SunCascades::Coarse;
    let one_cascade = |harness: &mut RenderHarness, distance: f32| {
        let world = harness.world_mut();
        let sun = world
            .query_filtered::<Entity, With<DirectionalLight>>()
            .single(world)
            .unwrap();
        world.entity_mut(sun).insert(
            CascadeShadowConfigBuilder {
                num_cascades: 1,
                first_cascade_far_bound: distance,
                maximum_distance: distance,
                ..default()
            }
            .build(),
        );
    };
    match cascades {
        SunCascades::Default => {}
        SunCascades::Coarse => one_cascade(&mut harness, 5000.0),
        SunCascades::LeafShare(share) => {
            // The cascade's texel grows with its far bound (the bounding sphere of the view
            // frustum's slice over the map's texels): set a far bound, read the texel Bevy
            // made, and scale the bound to the texel wanted, twice.
            let leaves = stored_leaves(&baked);
            let mut diameters: Vec<f32> = (0..leaves.len()).map(|l| leaves.diameter(l)).collect();
            diameters.sort_by(f32::total_cmp);
            let wanted = share * diameters[diameters.len() / 2];
            let camera = Transform::from_translation(eye)
                .looking_at(instance.transform_point(baked.crown_center()), Vec3::Y);
            let mut distance = 50.0;
            for _ in 0..2 {
                one_cascade(&mut harness, distance);
                for _ in 0..3 {
                    harness.step();
                }
                let texel = cascade_texels(harness.world_mut(), &GlobalTransform::from(camera))(
                    instance.transform_point(baked.crown_center()),
                );
                assert!(texel > 0.0, "no cascade texel read back");
                distance *= wanted / texel;
            }
        }
    }
    // A thin plate across the sun's light above the crown, shading the half of it on one side
    // of a plane through the crown's centre.
    let centre = instance.transform_point(baked.crown_center());
    // The edge of the plate's shadow runs through the crown's centre in a plane holding the
    // sun's direction and the view's, so the camera sees both halves.
    let across = to_sun_world.cross(eye - centre).normalize();
    let along = across.cross(to_sun_world).normalize();
    let plate_centre = centre + to_sun_world * (2.5 * radius) + across * (2.0 * radius);
    let plate = Transform::from_translation(plate_centre).with_rotation(Quat::from_mat3(
        &Mat3::from_cols(across, to_sun_world, along),
    ));
    let half = Vec3::new(2.0 * radius, 0.02 * radius, 3.0 * radius);
    if !coarse {
        let world = harness.world_mut();
        let mesh = world
            .resource_mut::<Assets<Mesh>>()
            .add(Cuboid::from_size(half * 2.0));
        let material = world
            .resource_mut::<Assets<StandardMaterial>>()
            .add(StandardMaterial::default());
        world.spawn((Mesh3d(mesh), MeshMaterial3d(material), plate));
    }
    // The plate's pipelines (its main pass and its shadow pass) are queued within a few frames
    // and compile asynchronously: a frame rendered before they are ready has no plate in the
    // shadow map. Under a loaded software rasteriser twelve frames were once not enough (268
    // of 704 pixels within 3/255), so after them the harness waits for every pipeline.
    for _ in 0..12 {
        harness.step();
    }
    harness.wait_until_ready().unwrap();
    // Whether the ray from p towards the sun (the plate's normal) crosses the plate.
    let blocked = |p: Vec3| {
        let o = p - plate_centre;
        !coarse
            && o.dot(to_sun_world) < 0.0
            && o.dot(across).abs() <= half.x
            && o.dot(along).abs() <= half.z
    };
    // Shadow edges, the leaves' and the plate's, blurred over a texel or two (the bilinear lookup).
    let margin = match cascades {
        SunCascades::LeafShare(_) => {
            let camera = Transform::from_translation(eye)
                .looking_at(instance.transform_point(baked.crown_center()), Vec3::Y);
            let texel = cascade_texels(harness.world_mut(), &GlobalTransform::from(camera))(
                instance.transform_point(baked.crown_center()),
            );
            (1.5 * texel).max(0.02 * radius)
        }
        _ => 0.02 * radius,
    };
    let check = compare_with_model(
        &mut harness,
        &baked,
        &lighting,
        instance,
        to_sun_world,
        eye,
        blocked,
        !coarse,
        margin,
        None,
    );
    check.save(name);
    println!(
        "{name}: {} leaf pixels compared ({} sunlit, {} shaded), {} within 3/255 of the CPU model (worst {:.1}/255); shadow-map texels {:.3}–{:.3} of a leaf; shaded by a leaf within three texels: {}, {} of them within 3/255",
        check.compared,
        check.sunlit,
        check.shaded,
        check.within,
        check.worst,
        check.texel_in_leaves.0,
        check.texel_in_leaves.1,
        check.close_shaded,
        check.close_within
    );
    Some(check)
}

#[test]
fn coarse_shadow_texels_leave_the_sun_to_the_baked_blend() {
    let Some(check) = sun_shadows("tree_lighting_coarse_cascade", SunCascades::Coarse) else {
        return;
    };
    assert!(
        check.compared >= 800,
        "too few leaf pixels: {}",
        check.compared
    );
    assert!(
        check.within as f32 >= 0.99 * check.compared as f32,
        "{} of {} leaf pixels within 3/255 of the CPU model's baked blend (worst {:.1})",
        check.within,
        check.compared,
        check.worst
    );
}

#[test]
fn a_fine_shadow_map_gives_each_leaf_the_sun_its_shadow_ray_finds() {
    // Texels far under a leaf: the sun's share at each leaf point from the shadow map, which
    // the CPU answers with a shadow ray through the leaves and past the plate.
    let Some(check) = sun_shadows("tree_lighting_plate", SunCascades::Default) else {
        return;
    };
    assert!(
        check.sunlit >= 150 && check.shaded >= 150,
        "leaves and the plate should shade part of the crown: {} sunlit, {} shaded pixels",
        check.sunlit,
        check.shaded
    );
    assert!(
        check.within as f32 >= 0.95 * check.compared as f32,
        "{} of {} leaf pixels within 3/255 of the CPU model with the leaves' and the plate's shadows (worst {:.1})",
        check.within,
        check.compared,
        check.worst
    );
}

#[test]
fn the_shadow_map_resolves_leaves_in_cascades_of_texels_a_quarter_of_a_leaf() {
    // Texels about a quarter of a leaf wide (where a depth offset that grows with the texel
    // lets the leaves just in front through, and a comparison with the point's own depth
    // shades a tilted leaf with its own texels): the shader's receiver-plane comparison still
    // gives each leaf the sun its shadow ray finds, away from shadow edges (a texel and a half).
    let Some(check) = sun_shadows(
        "tree_lighting_quarter_leaf_texels",
        SunCascades::LeafShare(0.25),
    ) else {
        return;
    };
    assert!(
        check.texel_in_leaves.1 > 0.125,
        "the cascade's texels should be coarser than an eighth of a leaf: {:?}",
        check.texel_in_leaves
    );
    // Shaded by a leaf just in front (within three texels along the sun): what a depth
    // offset growing with the texel gets wrong.
    assert!(
        check.close_shaded >= 40,
        "too few pixels shaded by a leaf within three texels: {}",
        check.close_shaded
    );
    assert!(
        check.close_within as f32 >= 0.9 * check.close_shaded as f32,
        "{} of {} pixels shaded by a leaf within three texels are within 3/255 of the CPU model",
        check.close_within,
        check.close_shaded
    );
    // The sunlit pixels a texel and a half from any shadow edge are few (55 when written).
    assert!(
        check.sunlit >= 40 && check.shaded >= 300,
        "leaves and the plate should shade part of the crown: {} sunlit, {} shaded pixels",
        check.sunlit,
        check.shaded
    );
    assert!(
        check.within as f32 >= 0.95 * check.compared as f32,
        "{} of {} leaf pixels within 3/255 of the CPU model with the leaves' and the plate's shadows (worst {:.1})",
        check.within,
        check.compared,
        check.worst
    );
}

/// The light values of one block of the synthetic billboard cloud's atlas.
struct ImpostorBlock {
    albedo: Vec3,
    /// Tangent-space normal (x along the plane's tangent, y its bitangent, z its normal).
    normal: Vec3,
    attenuation: [f32; 8],
    leaf: bool,
}

/// A billboard cloud of one 2 × 2 m plane facing +z whose 64² atlas is four uniform 32²
/// blocks: three leaves with their own albedo, tilted normal and attenuations, and bark.
fn block_cloud() -> (
    bevy_foliage::impostor::format::ImpostorData,
    Vec<ImpostorBlock>,
) {
    use bevy_foliage::impostor::format::{ImpostorData, ImpostorPlane};
    use bevy_foliage::impostor::texture::{encode_light, linear_to_srgb};
    let blocks = vec![
        ImpostorBlock {
            albedo: Vec3::new(0.35, 0.5, 0.2),
            normal: Vec3::new(0.3, 0.2, 0.93).normalize(),
            attenuation: [0.9, 0.2, 0.6, 0.05, 0.8, 0.4, 0.7, 0.3],
            leaf: true,
        },
        ImpostorBlock {
            albedo: Vec3::new(0.6, 0.45, 0.15),
            normal: Vec3::new(-0.45, 0.1, 0.89).normalize(),
            attenuation: [0.3, 0.7, 0.1, 0.95, 0.5, 0.02, 0.6, 0.85],
            leaf: true,
        },
        ImpostorBlock {
            albedo: Vec3::new(0.2, 0.4, 0.3),
            normal: Vec3::Z,
            attenuation: [0.08, 0.1, 0.12, 0.15, 0.2, 0.25, 0.3, 0.35],
            leaf: true,
        },
        ImpostorBlock {
            albedo: Vec3::new(0.3, 0.2, 0.12),
            normal: Vec3::new(0.2, -0.3, 0.93).normalize(),
            attenuation: [1.0; 8],
            leaf: false,
        },
    ];
    let size = 64u32;
    let mut albedo = vec![0u8; (size * size * 4) as usize];
    let mut normal = albedo.clone();
    let mut light = [albedo.clone(), albedo.clone(), albedo.clone()];
    for y in 0..size {
        for x in 0..size {
            let b = &blocks[((y / 32) * 2 + x / 32) as usize];
            let o = ((y * size + x) * 4) as usize;
            let a = b.albedo;
            albedo[o..o + 4].copy_from_slice(&[
                linear_to_srgb(a.x),
                linear_to_srgb(a.y),
                linear_to_srgb(a.z),
                255,
            ]);
            let enc = |c: f32| ((c * 0.5 + 0.5) * 255.0 + 0.5) as u8;
            normal[o..o + 4].copy_from_slice(&[
                enc(b.normal.x),
                enc(b.normal.y),
                enc(b.normal.z),
                255,
            ]);
            let v = b.attenuation;
            let leaf = b.leaf as u32 as f32;
            let values = [v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], leaf];
            for (k, atlas) in light.iter_mut().enumerate() {
                atlas[o..o + 4].copy_from_slice(&encode_light([
                    values[3 * k],
                    values[3 * k + 1],
                    values[3 * k + 2],
                ]));
            }
        }
    }
    let data = ImpostorData {
        center: Vec3::new(0.0, 1.0, 0.0),
        radius: 1.5,
        planes: vec![ImpostorPlane {
            corners: [
                Vec3::new(-1.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 2.0, 0.0),
                Vec3::new(-1.0, 2.0, 0.0),
            ],
            normal: Vec3::Z,
            tangent: Vec3::X,
            uv_min: Vec2::new(0.0, 1.0),
            uv_max: Vec2::new(1.0, 0.0),
            role: 0,
        }],
        atlas_size: size,
        albedo,
        normal,
        light,
        extinction: 1.3,
        seen_gains: CLOUD_SEEN_GAINS,
        bounce_ratios: cloud_bounce_ratios(),
        hotspot: CLOUD_HOTSPOT,
        source_hash: 1,
        bake_ms: 0.0,
    };
    (data, blocks)
}

/// What comparing a tree-lit billboard cloud with the CPU model found.
struct CloudCheck {
    compared: u32,
    within: u32,
    worst: f32,
    /// Compared leaf pixels the sun reaches from outside the crown, and those it does not.
    sunlit: u32,
    shaded: u32,
    leaves_unlike_pbr: u32,
    /// Compared leaf pixels the covered part's gain on the bounce moves by more than 3/255.
    covered_visible: u32,
    /// Compared leaf pixels the crown's bounce ratios move by more than 3/255.
    ratios_visible: u32,
    /// Compared leaf pixels the crown's mean ring moves from the blend by more than 3/255.
    ring_visible: u32,
    bark: u32,
    bark_same: u32,
}

/// Draws [`block_cloud`] with the tree lighting from a turned instance and compares every pixel
/// well inside a leaf block with the CPU model's light for that texel's values (attenuations,
/// normal, albedo as the optics), and the bark block with the cloud drawn by its plain material.
/// With `plate`, the sun casts shadow maps and a plate outside the crown shades part of the
/// cloud: the model then takes the sun and the bounce only where a ray from the point where the
/// sun's light enters the crown misses the plate. A board inside the crown, which only the sun
/// sees, shades another part in the shadow map, which the cloud must not count. With `ring`,
/// the cloud's material holds [`cloud_ring`] as its crown's mean ring at the sun's elevation.
fn tree_lit_cloud(name: &str, plate: bool, ring: bool) -> Option<CloudCheck> {
    use bevy_foliage::impostor::assets::BillboardCloudAsset;
    use bevy_foliage::impostor::texture::srgb_to_linear;
    let mut harness = RenderHarness::for_test(name, SIZE, SIZE)?;
    let lighting = TreeLightingSettings {
        enabled: true,
        optics: bevy_foliage::lighting::model::LeafMaterial {
            reflectance_front: Vec3::new(0.8, 0.7, 0.9),
            reflectance_back: Vec3::new(1.0, 0.9, 0.8),
            transmittance_front: Vec3::new(0.6, 0.7, 0.5),
            transmittance_back: Vec3::new(0.6, 0.5, 0.7),
        },
        ground_albedo: Vec3::new(0.3, 0.25, 0.2),
        sun_through_crown: SunThroughCrown::BlendedAttenuation,
        bounce: true,
        gathered_bounce: true,
        seen_part: true,
        bounce_ring: default(),
    };
    lit_app(&mut harness, &lighting);
    let (data, blocks) = block_cloud();
    let asset = BillboardCloudAsset::from_data_in(harness.world_mut(), &data);
    let instance = Transform::from_rotation(Quat::from_rotation_y(0.5));
    let cloud = harness
        .world_mut()
        .spawn((
            Mesh3d(asset.mesh.clone()),
            MeshMaterial3d(asset.tree_lit.clone()),
            instance,
        ))
        .id();
    // The sun from the side and above, so the leaves' own light, the light through them and
    // the bounce all show.
    let to_sun_world = Vec3::new(0.6, 0.7, 0.4).normalize();
    // The instance is turned about its vertical: its frame's elevation is the world's.
    let ring = ring.then(|| (to_sun_world.y, cloud_ring()));
    if let Some((height, nodes)) = ring {
        let mut materials = harness
            .world_mut()
            .resource_mut::<Assets<bevy_foliage::impostor::tree_lit::TreeLitImpostorMaterial>>();
        let mut material = materials.get_mut(&asset.tree_lit).unwrap();
        material.extension.params.ring_height = height;
        material.extension.params.ring_ratios = bevy_foliage::impostor::tree_lit::ratios_as_vectors(
            &nodes.map(|n| n[0]),
            &nodes.map(|n| n[1]),
        );
    }
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: SUN,
            shadow_maps_enabled: plate,
            ..default()
        },
        // One cascade of centimetre texels over the scene.
        CascadeShadowConfigBuilder {
            num_cascades: 1,
            first_cascade_far_bound: 12.0,
            maximum_distance: 12.0,
            ..default()
        }
        .build(),
        Transform::default().looking_to(-to_sun_world, Vec3::Y),
    ));
    let eye = instance.transform_point(Vec3::new(0.5, 1.6, 2.6));
    let target = instance.transform_point(Vec3::new(0.0, 1.0, 0.0));
    // The plate: across the sun's light 3 m from the crown's centre (outside its bounding
    // sphere of 1.5 m), its edge through the crown's centre seen from the camera.
    let centre = instance.transform_point(data.center);
    let across = to_sun_world.cross(eye - centre).normalize();
    let along = across.cross(to_sun_world).normalize();
    let plate_centre = centre + to_sun_world * 3.0 + across * 2.0;
    let half = Vec3::new(2.0, 0.02, 3.0);
    if plate {
        let world = harness.world_mut();
        let mesh = world
            .resource_mut::<Assets<Mesh>>()
            .add(Cuboid::from_size(half * 2.0));
        let material = world
            .resource_mut::<Assets<StandardMaterial>>()
            .add(StandardMaterial::default());
        let rotation = Quat::from_mat3(&Mat3::from_cols(across, to_sun_world, along));
        world.spawn((
            Mesh3d(mesh.clone()),
            MeshMaterial3d(material.clone()),
            Transform::from_translation(plate_centre).with_rotation(rotation),
        ));
        // A stand-in for the crown's own planes: a board inside the crown's bounding sphere on
        // the sun's side of the cloud, casting into the sun's map but unseen by the camera. Its
        // shadow is part of the baked attenuations, so the cloud must not read it again.
        world.spawn((
            Mesh3d(mesh),
            MeshMaterial3d(material),
            Transform::from_translation(centre + to_sun_world * 0.8 - across * 0.6)
                .with_rotation(rotation)
                .with_scale(Vec3::new(0.2, 1.0, 0.15)),
            bevy::camera::visibility::RenderLayers::layer(1),
        ));
        let sun = world
            .query_filtered::<Entity, With<DirectionalLight>>()
            .single(world)
            .unwrap();
        world
            .entity_mut(sun)
            .insert(bevy::camera::visibility::RenderLayers::from_layers(&[0, 1]));
    }
    // Whether a ray from p along `dir` crosses the plate (slabs in the plate's frame).
    let hits_plate = |p: Vec3, dir: Vec3| -> bool {
        if !plate {
            return false;
        }
        let o = p - plate_centre;
        let (mut t0, mut t1) = (0.0f32, f32::INFINITY);
        for (axis, h) in [(across, half.x), (to_sun_world, half.y), (along, half.z)] {
            let (od, dd) = (o.dot(axis), dir.dot(axis));
            if dd.abs() < 1e-9 {
                if od.abs() > h {
                    return false;
                }
                continue;
            }
            let (a, b) = ((-h - od) / dd, (h - od) / dd);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        t0 <= t1
    };
    harness.world_mut().spawn(unit_exposure_camera(
        Transform::from_translation(eye).looking_at(target, Vec3::Y),
    ));
    harness.wait_until_ready().unwrap();
    for _ in 0..4 {
        harness.step();
    }
    let lit = harness.render().unwrap();
    // The same view with the cloud's plain material: Bevy's PBR everywhere.
    harness
        .world_mut()
        .entity_mut(cloud)
        .remove::<MeshMaterial3d<bevy_foliage::impostor::tree_lit::TreeLitImpostorMaterial>>()
        .insert(MeshMaterial3d(asset.material.clone()));
    harness.wait_until_ready().unwrap();
    let pbr = harness.render().unwrap();

    let world = harness.world_mut();
    let (camera, camera_transform) = world
        .query::<(&Camera, &GlobalTransform)>()
        .single(world)
        .unwrap();
    let (camera, camera_transform) = (camera.clone(), *camera_transform);
    let from_world = instance.compute_affine().inverse();
    // The texel a pixel position sees on the plane (model space z = 0), if any.
    let texel = |px: Vec2| -> Option<(Vec3, Vec2)> {
        let ray = camera.viewport_to_world(&camera_transform, px).ok()?;
        let origin = from_world.transform_point3(ray.origin);
        let dir = from_world.transform_vector3(*ray.direction);
        let t = -origin.z / dir.z;
        let q = origin + dir * t;
        let uv = Vec2::new((q.x + 1.0) * 0.5, 1.0 - q.y * 0.5) * 64.0;
        (t > 0.0 && uv.cmpge(Vec2::ZERO).all() && uv.cmplt(Vec2::splat(64.0)).all())
            .then_some((q, uv))
    };
    let to_sun = from_world.transform_vector3(to_sun_world).normalize();
    let eye_local = from_world.transform_point3(eye);
    let tau = data.extinction;
    let sky = SkyLight::uniform(Vec3::splat(SKY), lighting.ground_albedo);
    let e_sun = Vec3::splat(SUN);
    let (mut compared, mut within, mut worst) = (0u32, 0u32, 0.0f32);
    let (mut bark, mut bark_same, mut leaves_unlike_pbr) = (0u32, 0u32, 0u32);
    let mut covered_visible = 0u32;
    let mut ratios_visible = 0u32;
    let mut ring_visible = 0u32;
    let (mut sunlit, mut shaded) = (0u32, 0u32);
    // The sun's light enters the crown on the plane touching its bounding sphere on the sun's
    // side; the plate's shadow edge is blurred over a few texels.
    let entry = |q: Vec3| {
        let reach = ((data.center - q).dot(to_sun) + data.radius).max(0.0);
        instance.transform_point(q + to_sun * reach)
    };
    let (side_a, side_b) = to_sun_world.any_orthonormal_pair();
    let margin = 0.1;
    let mut reference = RgbaImage::filled(SIZE, SIZE, [0, 0, 0, 255]);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let Some((q, uv)) = texel(centre) else {
                continue;
            };
            // Only pixels whose footprint stays three texels inside one block: the filtered
            // atlas is that block's values there.
            let block = |uv: Vec2| ((uv.y / 32.0) as usize) * 2 + (uv.x / 32.0) as usize;
            let b = block(uv);
            let inside = [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)]
                .iter()
                .all(|&(dx, dy)| {
                    texel(centre + Vec2::new(dx, dy)).is_some_and(|(_, c)| {
                        let within_block = c - Vec2::new((b % 2) as f32, (b / 2) as f32) * 32.0;
                        block(c) == b
                            && within_block.cmpge(Vec2::splat(3.0)).all()
                            && within_block.cmple(Vec2::splat(29.0)).all()
                    })
                });
            if !inside {
                continue;
            }
            // Not behind the plate as the camera sees it.
            let world_q = instance.transform_point(q);
            if hits_plate(eye, (world_q - eye).normalize()) {
                continue;
            }
            let got = lit.pixel(x, y);
            if !blocks[b].leaf {
                bark += 1;
                let p = pbr.pixel(x, y);
                bark_same += (0..3).all(|c| (got[c] as i32 - p[c] as i32).abs() <= 2) as u32;
                continue;
            }
            // The texel's values as the GPU reads them back from the atlases.
            let decode_n =
                |c: f32| (((c * 0.5 + 0.5) * 255.0 + 0.5) as u8) as f32 / 255.0 * 2.0 - 1.0;
            let n_ts = blocks[b].normal;
            let n = Vec3::new(decode_n(n_ts.x), decode_n(n_ts.y), decode_n(n_ts.z)).normalize();
            let albedo = blocks[b]
                .albedo
                .to_array()
                .map(|c| srgb_to_linear(bevy_foliage::impostor::texture::linear_to_srgb(c)));
            let albedo = Vec3::from_array(albedo);
            let a = blocks[b]
                .attenuation
                .map(|v| srgb_to_linear(bevy_foliage::impostor::texture::linear_to_srgb(v)));
            let s_max = a.map(|a| -a.max(DARKEST_LIGHT).ln() / tau);
            let optics = bevy_foliage::lighting::model::LeafMaterial {
                reflectance_front: lighting.optics.reflectance_front * albedo,
                reflectance_back: lighting.optics.reflectance_back * albedo,
                transmittance_front: lighting.optics.transmittance_front * albedo,
                transmittance_back: lighting.optics.transmittance_back * albedo,
            };
            let wo = (eye_local - q).normalize();
            let through =
                sun_through_crown(SunThroughCrown::BlendedAttenuation, tau, &a, &s_max, to_sun);
            let bounce = SunBounce::new(&optics, to_sun, tau);
            let from = entry(q);
            let blocked = hits_plate(from, to_sun_world);
            if [side_a, -side_a, side_b, -side_b]
                .iter()
                .any(|d| hits_plate(from + *d * margin, to_sun_world) != blocked)
            {
                continue;
            }
            let outside = (!blocked) as u32 as f32;
            if blocked {
                shaded += 1;
            } else {
                sunlit += 1;
            }
            // The crown's seen-part gain towards the eye on the sky and the blended sun, the
            // covered part's on the bounce.
            // And the crown's hotspot by the eye's angle to the sun.
            let (seen, covered, spot) = if lighting.seen_part {
                let seen = seen_gain(&CLOUD_SEEN_GAINS, wo);
                (seen, covered_gain(seen, open_share(n, &a)), CLOUD_HOTSPOT)
            } else {
                (1.0, 1.0, Hotspot::default())
            };
            // The crown's mean bounce ratios on each face, towards the sun (off its mean ring
            // where the sun is at the ring's elevation).
            let faces_with = |ring: Option<&(f32, [[f32; 2]; RING_NODES])>| {
                if lighting.gathered_bounce {
                    ratio_with_ring_nodes(
                        &cloud_bounce_ratios(),
                        ring.filter(|_| lighting.bounce_ring.enabled)
                            .map(|(h, nodes)| (*h, nodes)),
                        to_sun,
                    )
                } else {
                    [1.0; 2]
                }
            };
            let bounce_by = |faces: [f32; 2]| {
                bounce_radiance_by_face(&optics, n, wo, &bounce, through, &s_max, e_sun, faces)
                    * (outside * spot.bounce_at(wo, to_sun))
            };
            let bounced = bounce_by(faces_with(ring.as_ref()));
            let blended = bounce_by(faces_with(None));
            let unratioed = bounce_radiance(&optics, n, wo, &bounce, through, &s_max, e_sun)
                * (outside * spot.bounce_at(wo, to_sun));
            let radiance = sky_radiance(&optics, n, wo, &a, &sky) * seen
                + sun_radiance(
                    &optics,
                    n,
                    wo,
                    to_sun,
                    spot.sun_through((through * seen).min(1.0), wo, to_sun) * outside,
                    e_sun,
                )
                + bounced * covered;
            let want = radiance.to_array().map(|c| srgb(c) * 255.0);
            let uncovered = (radiance + bounced * (1.0 - covered))
                .to_array()
                .map(|c| srgb(c) * 255.0);
            covered_visible += (0..3).any(|c| (want[c] - uncovered[c]).abs() > 3.0) as u32;
            let without_ratios = (radiance + (unratioed - bounced) * covered)
                .to_array()
                .map(|c| srgb(c) * 255.0);
            ratios_visible += (0..3).any(|c| (want[c] - without_ratios[c]).abs() > 3.0) as u32;
            let without_ring = (radiance + (blended - bounced) * covered)
                .to_array()
                .map(|c| srgb(c) * 255.0);
            ring_visible += (0..3).any(|c| (want[c] - without_ring[c]).abs() > 3.0) as u32;
            reference.set_pixel(x, y, [want[0] as u8, want[1] as u8, want[2] as u8, 255]);
            let off = (0..3)
                .map(|c| (got[c] as f32 - want[c]).abs())
                .fold(0.0f32, f32::max);
            compared += 1;
            within += (off <= 3.0) as u32;
            worst = worst.max(off);
            let p = pbr.pixel(x, y);
            leaves_unlike_pbr += (0..3).any(|c| (got[c] as i32 - p[c] as i32).abs() > 10) as u32;
        }
    }
    let dir = artifacts_dir().join("tree_lighting");
    std::fs::create_dir_all(&dir).ok();
    lit.save_png(dir.join(format!("{name}_gpu.png"))).ok();
    reference.save_png(dir.join(format!("{name}_cpu.png"))).ok();
    pbr.save_png(dir.join(format!("{name}_pbr.png"))).ok();
    eprintln!(
        "{name}: leaf pixels {within} of {compared} within 3/255 (worst {worst:.1}; {sunlit} sunlit, {shaded} shaded), {leaves_unlike_pbr} unlike Bevy's PBR, {covered_visible} moved by > 3/255 by the covered part's gain on the bounce, {ratios_visible} by the crown's bounce ratios, {ring_visible} by its mean ring; bark pixels: {bark_same} of {bark} as Bevy's PBR"
    );
    Some(CloudCheck {
        compared,
        within,
        worst,
        sunlit,
        shaded,
        leaves_unlike_pbr,
        covered_visible,
        ratios_visible,
        ring_visible,
        bark,
        bark_same,
    })
}

/// A tree-lit billboard cloud in the open: every leaf pixel is the CPU model's light for its
/// texel; bark is Bevy's PBR, leaves are not.
#[test]
fn a_tree_lit_billboard_cloud_lights_each_leaf_texel_as_the_model_does() {
    let Some(c) = tree_lit_cloud("tree_lit_impostor", false, false) else {
        return;
    };
    assert!(c.compared > 1500, "{} leaf pixels compared", c.compared);
    assert_eq!(c.within, c.compared, "worst {:.1}/255", c.worst);
    // The bounce's covered-part gain is part of what is checked.
    assert!(
        c.covered_visible * 4 >= c.compared,
        "the covered part's gain shows in {} of {} pixels",
        c.covered_visible,
        c.compared
    );
    // So are the crown's bounce ratios.
    assert!(
        c.ratios_visible * 4 >= c.compared,
        "the bounce ratios show in {} of {} pixels",
        c.ratios_visible,
        c.compared
    );
    assert!(c.bark > 300, "{} bark pixels", c.bark);
    assert_eq!(c.bark_same, c.bark);
    // The tree lighting changed the leaves: the comparison is not with Bevy's lighting.
    assert!(
        c.leaves_unlike_pbr * 10 > c.compared * 9,
        "{} of {}",
        c.leaves_unlike_pbr,
        c.compared
    );
}

/// A tree-lit billboard cloud whose crown has a ring of re-gathered bounce ratios at the sun's
/// elevation reads the crown's mean ring, as the CPU model does, not the bake's blend.
#[test]
fn a_tree_lit_billboard_cloud_reads_its_crowns_mean_ring() {
    let Some(c) = tree_lit_cloud("tree_lit_impostor_ring", false, true) else {
        return;
    };
    assert!(c.compared > 1500, "{} leaf pixels compared", c.compared);
    assert_eq!(c.within, c.compared, "worst {:.1}/255", c.worst);
    assert!(
        c.ring_visible * 4 >= c.compared,
        "the ring shows in {} of {} pixels",
        c.ring_visible,
        c.compared
    );
}

/// A tree-lit billboard cloud partly in a plate's shadow: the sun and its bounce reach the leaf
/// texels where the ray from where the sun's light enters the crown misses the plate, as in the
/// CPU model, and the cloud's own planes (which cast into the same shadow map) are not counted.
#[test]
fn a_tree_lit_billboard_cloud_takes_the_sun_shadow_from_outside_its_crown() {
    let Some(c) = tree_lit_cloud("tree_lit_impostor_plate", true, false) else {
        return;
    };
    assert!(
        c.sunlit > 300 && c.shaded > 300,
        "{} sunlit, {} shaded",
        c.sunlit,
        c.shaded
    );
    assert!(
        c.within as f32 >= 0.99 * c.compared as f32,
        "{} of {} within 3/255 (worst {:.1}/255)",
        c.within,
        c.compared,
        c.worst
    );
}

/// Steps until the bake requested by `entity` has its result.
fn impostor_bake_result(
    harness: &mut RenderHarness,
    entity: Entity,
) -> std::sync::Arc<bevy_foliage::impostor::format::ImpostorData> {
    use bevy_foliage::impostor::bake::ImpostorBakeResult;
    for _ in 0..300 {
        harness.step();
        if let Some(result) = harness.world_mut().get::<ImpostorBakeResult>(entity) {
            return result.0.clone().expect("bake");
        }
    }
    panic!("the bake never finished");
}

/// The mean linear luminance of the pixels the tree covers (not the black background): how
/// bright the crown looks, whatever its coverage.
fn crown_brightness(image: &RgbaImage) -> f64 {
    let covered = (0..image.height)
        .flat_map(|y| (0..image.width).map(move |x| (x, y)))
        .filter(|&(x, y)| image.pixel(x, y)[..3].iter().any(|&c| c > 0))
        .count();
    crown_light(image) * (image.width * image.height) as f64 / covered.max(1) as f64
}

/// A forest tree lit as a volume, seen from 40 m: drawn by its pruned leaves (`far` beyond it)
/// and then by its billboard cloud (`far` before it), the crown looks about as bright — the
/// cloud's leaf texels are lit by the same model — where the cloud drawn with Bevy's lighting is
/// far brighter (the pop the hand-over had). Switching the lighting respawns the impostor with
/// the other material.
#[test]
fn a_tree_lit_crown_keeps_its_light_when_its_billboard_cloud_takes_over() {
    use bevy_foliage::ForestTree;
    use bevy_foliage::impostor::assets::BillboardCloudAsset;
    use bevy_foliage::impostor::bake::{ImpostorBakeRequest, ImpostorBakeSettings};
    use bevy_foliage::impostor::systems::{
        ImpostorOf, ImpostorSettings, TreeBark, TreeImpostor, TreeLitImpostorDraw,
    };
    use bevy_foliage::impostor::texture::{BakeSurface, ImpostorSource};
    use bevy_foliage::meshes::bark_mesh;
    let Some(mut harness) = RenderHarness::for_test("tree_lit_handover", SIZE, SIZE) else {
        return;
    };
    let lighting = TreeLightingSettings {
        enabled: true,
        ..default()
    };
    lit_app(&mut harness, &lighting);
    harness
        .app_mut()
        .insert_resource(FoliagePruningSettings {
            distances: LodDistances::World {
                near: 5.0,
                far: 1000.0,
            },
            ..default()
        })
        .insert_resource(ImpostorSettings {
            // No cross-fade: at 40 m the tree is all leaves or all cloud.
            fade_band: 0.0,
            ..default()
        });
    let distance = 40.0;
    harness.world_mut().spawn((
        unit_exposure_camera(
            Transform::from_xyz(0.0, 3.5, distance).looking_at(Vec3::new(0.0, 3.5, 0.0), Vec3::Y),
        ),
        Projection::Perspective(PerspectiveProjection {
            fov: 0.25,
            ..default()
        }),
    ));
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: SUN,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(-0.3, -1.0, -0.5), Vec3::Y),
    ));
    let tree = generate(&TreeSpecies::olea().with_leaf_count(600));
    let bark_colour = Vec3::new(0.3, 0.2, 0.12);
    let solid = |c: Vec3, cutoff: f32| BakeSurface {
        base_color: c.extend(1.0),
        texture: None,
        alpha_cutoff: cutoff,
    };
    let mut source = ImpostorSource::default();
    source.push_leaves(&tree.leaves, solid(BASE, 0.5));
    source.push_bark(&tree.bark, solid(bark_colour, 0.0));
    let request = harness
        .world_mut()
        .spawn(ImpostorBakeRequest {
            label: "handover olive".into(),
            source: std::sync::Arc::new(source),
            settings: ImpostorBakeSettings {
                atlas_size: 512,
                ..default()
            },
            save_to: None,
        })
        .id();
    let data = impostor_bake_result(&mut harness, request);
    let world = harness.world_mut();
    let cloud = BillboardCloudAsset::from_data_in(world, &data);
    let cloud = world
        .resource_mut::<Assets<BillboardCloudAsset>>()
        .add(cloud);
    let (baked, _) = bake(&tree.leaves, &BakeSettings::default(), &|_| {}).unwrap();
    let baked = world.resource_mut::<Assets<BakedFoliage>>().add(baked);
    let baked_id = baked.id();
    let leaves = world
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material(StandardMaterial {
            base_color: Color::linear_rgb(BASE.x, BASE.y, BASE.z),
            double_sided: true,
            cull_mode: None,
            ..default()
        }));
    let bark_material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::linear_rgb(bark_colour.x, bark_colour.y, bark_colour.z),
            ..default()
        });
    let bark = world
        .resource_mut::<Assets<Mesh>>()
        .add(bark_mesh(&tree.bark));
    world
        .spawn((
            ForestTree {
                baked,
                material: leaves,
            },
            TreeImpostor(cloud),
            Transform::IDENTITY,
        ))
        .with_child((Mesh3d(bark), MeshMaterial3d(bark_material), TreeBark));
    let render_with = |harness: &mut RenderHarness, far: f32, tree_lit: bool| {
        harness
            .world_mut()
            .resource_mut::<FoliagePruningSettings>()
            .distances = LodDistances::World { near: 5.0, far };
        harness
            .world_mut()
            .resource_mut::<TreeLightingSettings>()
            .enabled = tree_lit;
        for _ in 0..10 {
            harness.step();
        }
        harness.wait_until_ready().unwrap();
        let image = harness.render().unwrap();
        let world = harness.world_mut();
        let impostors = world
            .query_filtered::<Has<TreeLitImpostorDraw>, With<ImpostorOf>>()
            .iter(world)
            .collect::<Vec<_>>();
        (image, impostors)
    };
    // The leaves with their type's bounce ring re-gathered at the sun's elevation (on by
    // default), which the cloud, lit by the crown's mean of the bake's ratios, does not have.
    render_with(&mut harness, 1000.0, true);
    let ring = wait_for_ring(&mut harness, baked_id);
    let (leaves_lit, _) = render_with(&mut harness, 1000.0, true);
    let (cloud_lit, impostors_lit) = render_with(&mut harness, 20.0, true);
    // The cloud's material holds the crown's mean of the type's ring.
    {
        use bevy_foliage::impostor::tree_lit::{TreeLitImpostorMaterial, ratios_as_vectors};
        let world = harness.world_mut();
        let tree_lit = world
            .resource::<Assets<BillboardCloudAsset>>()
            .iter()
            .next()
            .unwrap()
            .1
            .tree_lit
            .clone();
        let params = world
            .resource::<Assets<TreeLitImpostorMaterial>>()
            .get(&tree_lit)
            .unwrap()
            .extension
            .params;
        let mean = bevy_foliage::lighting::bounce_ring::crown_mean_ring(&ring);
        assert_eq!(params.ring_height, ring.sun_height);
        assert_eq!(
            params.ring_ratios,
            ratios_as_vectors(&mean.map(|n| n[0]), &mean.map(|n| n[1]))
        );
    }
    let (cloud_pbr, impostors_pbr) = render_with(&mut harness, 20.0, false);
    let (leaves_pbr, _) = render_with(&mut harness, 1000.0, false);
    let dir = artifacts_dir().join("tree_lighting");
    std::fs::create_dir_all(&dir).ok();
    for (name, image) in [
        ("handover_leaves_lit", &leaves_lit),
        ("handover_cloud_lit", &cloud_lit),
        ("handover_cloud_pbr", &cloud_pbr),
        ("handover_leaves_pbr", &leaves_pbr),
    ] {
        image.save_png(dir.join(format!("{name}.png"))).ok();
    }
    let light = [&leaves_lit, &cloud_lit, &cloud_pbr, &leaves_pbr].map(crown_brightness);
    let off = |a: f64, b: f64| (a - b).abs() / b;
    eprintln!(
        "crown brightness: tree-lit leaves {:.4}, tree-lit cloud {:.4} ({:+.1} %), Bevy-lit cloud {:.4} ({:+.1} %), Bevy-lit leaves {:.4}",
        light[0],
        light[1],
        100.0 * (light[1] / light[0] - 1.0),
        light[2],
        100.0 * (light[2] / light[0] - 1.0),
        light[3]
    );
    assert_eq!(impostors_lit, vec![true], "one impostor, drawn tree-lit");
    assert_eq!(impostors_pbr, vec![false], "respawned with Bevy's lighting");
    assert!(light[0] > 1e-3, "the crown is in view and lit");
    assert!(
        off(light[1], light[0]) < HANDOVER_TOLERANCE,
        "the tree-lit cloud's brightness is off the leaves' by {:.1} %",
        100.0 * off(light[1], light[0])
    );
    // What the hand-over was before: Bevy's lighting on the cloud is far from the tree-lit
    // crown (the measure sees a pop).
    assert!(off(light[2], light[0]) > 2.0 * HANDOVER_TOLERANCE);
}

/// The test cloud's seen-part gains, distinct per octant so that a shader that ignored them or
/// read them in another order would be off; below 1, so that the bounce's covered-part gain
/// (above 1 then) lifts it by more than the tolerance in most leaf pixels, where gains above 1
/// would saturate the sky first.
const CLOUD_SEEN_GAINS: [f32; 8] = [0.3, 0.4, 0.25, 0.35, 0.45, 0.3, 0.4, 0.35];

/// The test cloud's crown mean bounce ratios: distinct per face and per basis sun, so a shader
/// that skips them, swaps the faces or misreads their order shows.
fn cloud_bounce_ratios() -> BounceRatios {
    BounceRatios {
        front: std::array::from_fn(|k| 2.0 + 0.15 * k as f32),
        back: std::array::from_fn(|k| 0.3 + 0.05 * k as f32),
    }
}

/// The test cloud's crown mean ring: distinct per node and face, far from
/// [`cloud_bounce_ratios`], so a shader that skips it, swaps the faces or reads the nodes by
/// another azimuth shows.
fn cloud_ring() -> [[f32; 2]; RING_NODES] {
    std::array::from_fn(|k| [0.4 + 0.2 * k as f32, 4.0 - 0.2 * k as f32])
}

/// The test cloud's hotspot: distinct nodes, none 1, so a shader that skips or misreads it
/// shows.
const CLOUD_HOTSPOT: Hotspot = Hotspot {
    sun: [0.5, 0.625, 0.75, 1.25, 1.5, 1.625, 1.875, 2.0],
    bounce: [1.75, 1.625, 1.5, 1.25, 0.75, 0.625, 0.5, 0.375],
};

/// How far a tree-lit crown's brightness may move when its billboard cloud takes over: −0.6 %
/// measured with the crown's means weighted by how much an eye sees of each leaf (the ring
/// refined to its sixteen passes; −0.1 % with its first pass alone), +2.8 % with every leaf
/// alike (the hidden leaves' ratios brightening the cloud), which this fails. The
/// leaves' bake and the cloud's draw the same rays for each leaf (each seeded by the leaf
/// itself), so the two differ by what the cloud's means make of the leaves' values, not by two
/// draws of the gathers' noise: with the leaves' bake seeded by the stored index and the
/// cloud's by the source's, −1.9 %.
const HANDOVER_TOLERANCE: f64 = 0.02;
