//! Grass on the GPU against its CPU references: the blade pass keeps exactly the blade points
//! the density test and the geometry opacity of eq. 4.6 keep on the CPU (`grass::transition`,
//! `grass::density`), pixel by pixel, under a density gradient and inside a transition window.

use bevy::camera::ScalingMode;
use bevy::light::NotShadowCaster;
use bevy::mesh::{Indices, VertexAttributeValues};
use bevy::prelude::*;
use bevy_foliage::grass::density::DensityMap;
use bevy_foliage::grass::mesh::patch_mesh;
use bevy_foliage::grass::patch::{BasePatch, Mirror, PatchSettings};
use bevy_foliage::grass::systems::{GrassCell, field_grid};
use bevy_foliage::grass::transition::{
    DISCARD, TransitionDistances, geometry_opacity, ordered_dither,
};
use bevy_foliage::grass::{GrassField, GrassPlugin, GrassSettings, GrassSpecies};
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::compare::RgbaImage;

const SIZE: u32 = 96;
const VIEW: f32 = 2.2;
const EYE: Vec3 = Vec3::new(0.0, 10.0, 0.0);
const BACKGROUND: Color = Color::srgb(1.0, 0.0, 1.0);

/// No wind: the blades stand as the base patch has them.
fn still_air() -> bevy_foliage::grass::GrassWind {
    bevy_foliage::grass::GrassWind {
        strength: 0.0,
        ..default()
    }
}

fn species() -> GrassSpecies {
    GrassSpecies {
        patch: PatchSettings {
            strata: 12,
            width: 0.05,
            ..default()
        },
        ..default()
    }
}

/// A 2 × 1 density map over the field: 0.25 at −x rising to 1 at +x.
fn gradient_image() -> Image {
    Image::new(
        bevy::render::render_resource::Extent3d {
            width: 2,
            height: 1,
            depth_or_array_layers: 1,
        },
        bevy::render::render_resource::TextureDimension::D2,
        vec![64, 255],
        bevy::render::render_resource::TextureFormat::R8Unorm,
        bevy::asset::RenderAssetUsages::all(),
    )
}

/// An orthographic camera at [`EYE`] looking straight down over `view` metres: image x along
/// +x, image y along +z.
fn spawn_top_down_camera(harness: &mut RenderHarness, view: f32) -> Entity {
    spawn_ortho_camera(
        harness,
        Transform::from_translation(EYE).looking_to(Vec3::NEG_Y, Vec3::NEG_Z),
        Vec2::splat(view),
    )
}

/// An orthographic camera, no MSAA, placed by `transform`, seeing `view` metres across.
fn spawn_ortho_camera(harness: &mut RenderHarness, transform: Transform, view: Vec2) -> Entity {
    harness
        .world_mut()
        .spawn((
            Camera3d::default(),
            Msaa::Off,
            Projection::Orthographic(OrthographicProjection {
                scaling_mode: ScalingMode::Fixed {
                    width: view.x,
                    height: view.y,
                },
                ..OrthographicProjection::default_3d()
            }),
            transform,
        ))
        .id()
}

/// Blade geometry only, in full, out to 30 m.
fn geometry_only() -> TransitionDistances {
    TransitionDistances {
        min_geom: 30.0,
        max_geom: 40.0,
        min_btf: 50.0,
        max_btf: 80.0,
        ..default()
    }
}

/// Steps until every field has its slices (or gave up on them) and the pipelines are ready,
/// then a few frames more.
fn settle(harness: &mut RenderHarness) {
    for _ in 0..300 {
        harness.step();
        if bevy_foliage::grass::systems::grass_ready(harness.world_mut()) {
            break;
        }
    }
    harness.wait_until_ready().expect("pipelines");
    for _ in 0..3 {
        harness.step();
    }
}

/// Renders, and keeps the image in the artifacts folder as `name.png`.
fn render_saved(harness: &mut RenderHarness, name: &str) -> RgbaImage {
    let image = harness.render().unwrap();
    image
        .save_png(bevy_nature_harness::compare::artifacts_dir().join(format!("{name}.png")))
        .ok();
    image
}

fn add_image(harness: &mut RenderHarness, image: Image) -> Handle<Image> {
    harness
        .world_mut()
        .resource_mut::<Assets<Image>>()
        .add(image)
}

/// The pixels the blades cover, seen straight down from `EYE` over `VIEW` metres, as the CPU
/// computes them: every strip triangle of every cell (mirrored as eq. 4.9 places it), each
/// pixel centre inside it kept where the blade point there passes the density test and its
/// geometry opacity beats the pixel's dither.
fn cpu_coverage(field_size: Vec2, density: &DensityMap, t: &TransitionDistances) -> Vec<bool> {
    let to_pixel = |p: Vec3| {
        Vec2::new(
            ((p.x - EYE.x) / VIEW + 0.5) * SIZE as f32,
            ((p.z - EYE.z) / VIEW + 0.5) * SIZE as f32,
        )
    };
    rasterize_blades(
        field_size,
        UVec2::splat(SIZE),
        to_pixel,
        |p, _| p,
        |p, threshold, px, py| {
            let ld = density.density_at(p.x, p.z);
            let opacity = geometry_opacity(t, p.distance(EYE), ld, threshold);
            opacity >= DISCARD && opacity > ordered_dither(px, py)
        },
    )
}

/// The pixels of an image `pixels` across covered by the blades of a field of `field_size`
/// centred on the origin ([`blade_fragments`]), each pixel centre inside a triangle covered
/// where `keep(point, blade threshold, px, py)`.
fn rasterize_blades(
    field_size: Vec2,
    pixels: UVec2,
    to_pixel: impl Fn(Vec3) -> Vec2,
    deform: impl Fn(Vec3, f32) -> Vec3,
    keep: impl Fn(Vec3, f32, u32, u32) -> bool,
) -> Vec<bool> {
    let mut covered = vec![false; (pixels.x * pixels.y) as usize];
    blade_fragments(
        field_size,
        pixels,
        to_pixel,
        deform,
        |px, py, p, threshold| {
            if keep(p, threshold, px, py) {
                covered[(py * pixels.x + px) as usize] = true;
            }
        },
    );
    covered
}

/// Every blade fragment of a field of `field_size` centred on the origin: every strip triangle
/// of every cell (mirrored as eq. 4.9 places it), its vertices moved by `deform(flat point,
/// height above the ground)` and projected by `to_pixel`, each pixel centre inside it visited
/// with the point there and the blade's threshold.
fn blade_fragments(
    field_size: Vec2,
    pixels: UVec2,
    to_pixel: impl Fn(Vec3) -> Vec2,
    deform: impl Fn(Vec3, f32) -> Vec3,
    mut visit: impl FnMut(u32, u32, Vec3, f32),
) {
    let species = species();
    let patch = BasePatch::generate(&species.patch);
    let mesh = patch_mesh(&patch, species.patch.width, species.patch.segments);
    let Some(VertexAttributeValues::Float32x3(positions)) =
        mesh.attribute(Mesh::ATTRIBUTE_POSITION)
    else {
        panic!()
    };
    let Some(VertexAttributeValues::Float32x2(uv1)) = mesh.attribute(Mesh::ATTRIBUTE_UV_1) else {
        panic!()
    };
    let Some(Indices::U32(indices)) = mesh.indices() else {
        panic!()
    };
    let grid = field_grid(Vec2::ZERO, field_size, species.patch.size);
    let cells = (field_size / species.patch.size).ceil().as_uvec2();
    for cz in 0..cells.y {
        for cx in 0..cells.x {
            let mirror = Mirror::of_cell(cx as i64, cz as i64, species.patch.seed);
            let corner = grid.origin + Vec2::new(cx as f32, cz as f32) * species.patch.size;
            let world = |i: u32| {
                let local = Vec3::from_array(positions[i as usize]);
                let p = mirror.place(local, species.patch.size);
                deform(p + Vec3::new(corner.x, 0.0, corner.y), local.y)
            };
            for tri in indices.chunks_exact(3) {
                let w = [world(tri[0]), world(tri[1]), world(tri[2])];
                let threshold = uv1[tri[0] as usize][0];
                let s = w.map(&to_pixel);
                let area = (s[1] - s[0]).perp_dot(s[2] - s[0]);
                if area.abs() < 1e-12 {
                    continue;
                }
                let lo = s[0].min(s[1]).min(s[2]).floor().max(Vec2::ZERO);
                let hi = s[0].max(s[1]).max(s[2]).ceil().min(pixels.as_vec2());
                for py in lo.y as u32..hi.y as u32 {
                    for px in lo.x as u32..hi.x as u32 {
                        let c = Vec2::new(px as f32 + 0.5, py as f32 + 0.5);
                        let b0 = (s[1] - c).perp_dot(s[2] - c) / area;
                        let b1 = (s[2] - c).perp_dot(s[0] - c) / area;
                        let b2 = 1.0 - b0 - b1;
                        if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                            continue;
                        }
                        visit(px, py, w[0] * b0 + w[1] * b1 + w[2] * b2, threshold);
                    }
                }
            }
        }
    }
}

fn gpu_coverage(image: &RgbaImage) -> Vec<bool> {
    covered_pixels(image, UVec2::splat(SIZE))
}

/// The pixels of `image` (`pixels` across) not showing the background.
fn covered_pixels(image: &RgbaImage, pixels: UVec2) -> Vec<bool> {
    let bg = BACKGROUND.to_srgba();
    let bg = [
        (bg.red * 255.0) as i32,
        (bg.green * 255.0) as i32,
        (bg.blue * 255.0) as i32,
    ];
    (0..pixels.x * pixels.y)
        .map(|i| {
            let p = image.pixel(i % pixels.x, i / pixels.x);
            (0..3).any(|k| (p[k] as i32 - bg[k]).abs() > 24)
        })
        .collect()
}

/// Mismatched pixels, and the pixels either covers.
fn compare(gpu: &[bool], cpu: &[bool]) -> (usize, usize, usize) {
    let differ = gpu.iter().zip(cpu).filter(|(a, b)| a != b).count();
    (
        differ,
        gpu.iter().filter(|c| **c).count(),
        cpu.iter().filter(|c| **c).count(),
    )
}

/// Covered fraction of the left and right thirds of the image.
fn thirds(mask: &[bool]) -> (f64, f64) {
    let third = |x0: u32, x1: u32| {
        let n = (x1 - x0) * SIZE;
        let c = (0..SIZE)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| mask[(y * SIZE + x) as usize])
            .count();
        c as f64 / n as f64
    };
    (third(0, SIZE / 3), third(2 * SIZE / 3, SIZE))
}

#[test]
fn blade_pass_keeps_the_blades_the_cpu_keeps() {
    let Some(mut harness) = RenderHarness::for_test("grass_blades", SIZE, SIZE) else {
        return;
    };
    let field_size = Vec2::splat(2.0);
    let near = geometry_only();
    harness
        .app_mut()
        .add_plugins(GrassPlugin)
        .insert_resource(ClearColor(BACKGROUND))
        .insert_resource(GrassSettings {
            transitions: near,
            // The blade pass alone, in still air.
            slices: false,
            wind: still_air(),
            ..default()
        });
    let density = add_image(&mut harness, gradient_image());
    harness.world_mut().spawn(GrassField {
        size: field_size,
        species: species(),
        density: Some(density),
        ground: None,
        ambient_occlusion: None,
    });
    harness.world_mut().spawn((
        DirectionalLight::default(),
        Transform::from_xyz(1.0, 3.0, 2.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    spawn_top_down_camera(&mut harness, VIEW);
    harness.wait_until_ready().expect("pipelines");
    let map = DensityMap::new(2, 1, vec![64.0 / 255.0, 1.0], [-1.0, -1.0], [2.0, 2.0]).unwrap();

    // Geometry only: the density gradient alone thins the blades.
    let image = render_saved(&mut harness, "grass_blades_near");
    let gpu = gpu_coverage(&image);
    let cpu = cpu_coverage(field_size, &map, &near);
    let (differ, g, c) = compare(&gpu, &cpu);
    let (gl, gr) = thirds(&gpu);
    let (cl, cr) = thirds(&cpu);
    eprintln!(
        "near: differ {differ}, GPU {g} px, CPU {c} px; thirds GPU {gl:.3}/{gr:.3} CPU {cl:.3}/{cr:.3}"
    );
    assert!(c > 2000, "the CPU reference covers {c} px");
    // Pixel centres on a strip edge may go either way; nothing else may differ.
    assert!(differ * 100 < c, "{differ} px differ of {c}");
    // The gradient shows: the sparse third is clearly thinner.
    assert!(cl < 0.75 * cr, "{cl} vs {cr}");

    // The cells cast into the shadow maps by default; switched off, every drawn cell (those
    // already there too) stops casting, and casts again when switched back on.
    let casting = |harness: &mut RenderHarness| {
        let world = harness.world_mut();
        let cells = world
            .query_filtered::<Has<NotShadowCaster>, With<GrassCell>>()
            .iter(world)
            .collect::<Vec<_>>();
        (cells.len(), cells.iter().filter(|not| !**not).count())
    };
    let (cells, cast) = casting(&mut harness);
    assert!(cells > 0 && cast == cells, "{cast} of {cells} cells cast");
    harness
        .world_mut()
        .resource_mut::<GrassSettings>()
        .cast_shadow_maps = false;
    harness.step();
    harness.step();
    assert_eq!(casting(&mut harness), (cells, 0));
    harness
        .world_mut()
        .resource_mut::<GrassSettings>()
        .cast_shadow_maps = true;
    harness.step();
    harness.step();
    assert_eq!(casting(&mut harness), (cells, cells));

    // Inside the geometry's transition window (d ≈ 10 m between min_geom 8 and max_geom 12):
    // eq. 4.6's partial opacities, dithered.
    let window = TransitionDistances {
        min_geom: 8.0,
        max_geom: 12.0,
        min_btf: 50.0,
        max_btf: 80.0,
        ..default()
    };
    harness
        .world_mut()
        .resource_mut::<GrassSettings>()
        .transitions = window;
    for _ in 0..4 {
        harness.step();
    }
    let image = render_saved(&mut harness, "grass_blades_window");
    let gpu = gpu_coverage(&image);
    let cpu_window = cpu_coverage(field_size, &map, &window);
    let (differ, g, c2) = compare(&gpu, &cpu_window);
    eprintln!("window: differ {differ}, GPU {g} px, CPU {c2} px");
    assert!(differ * 100 < c2, "{differ} px differ of {c2}");
    // The window removes a real share of the blades (and the test would see a pass that ignored
    // it: the near coverage differs from the window's by more than the tolerance).
    assert!(c2 * 10 < c * 9, "{c2} vs {c}");
}

/// The slice bake renders, layer by layer, what its CPU reference rasterises: the same texels
/// covered, the same threshold, colour and lighting where both cover one.
#[test]
fn slice_bake_matches_the_cpu_reference() {
    use bevy_foliage::grass::bake::{GrassSliceBakeRequest, GrassSliceBakeResult};
    use bevy_foliage::grass::mesh::bake_triangles;
    use bevy_foliage::grass::slices::{LAYERS, bake_reference};
    let Some(mut harness) = RenderHarness::for_test("grass_slice_bake", 32, 32) else {
        return;
    };
    harness.app_mut().add_plugins(GrassPlugin);
    harness.world_mut().spawn(Camera3d::default());
    let cache =
        std::env::temp_dir().join(format!("grass_slices_{}.grassslices", std::process::id()));
    std::fs::remove_file(&cache).ok();
    let species = GrassSpecies {
        patch: PatchSettings {
            strata: 8,
            width: 0.03,
            ..default()
        },
        ..default()
    };
    let entity = harness
        .world_mut()
        .spawn(GrassSliceBakeRequest {
            label: "test grass".into(),
            species: species.clone(),
            per_axis: 2,
            resolution: 32,
            save_to: Some(cache.clone()),
        })
        .id();
    let mut result = None;
    for _ in 0..400 {
        // A naive camera controller moving every `Camera3d`: the bake holds its own cameras.
        let world = harness.world_mut();
        let mut cameras = world.query_filtered::<&mut Transform, With<Camera3d>>();
        for mut transform in cameras.iter_mut(world) {
            transform.translation.x += 0.01;
        }
        harness.step();
        if let Some(r) = harness.world_mut().get::<GrassSliceBakeResult>(entity) {
            result = Some(r.0.clone());
            break;
        }
    }
    let bake = result.expect("the bake finished").expect("the bake worked");
    // The cache: the same request again is answered from the file at once, texel for texel as
    // the file holds it (half floats, as baked).
    let again = harness
        .world_mut()
        .spawn(GrassSliceBakeRequest {
            label: "test grass again".into(),
            species: species.clone(),
            per_axis: 2,
            resolution: 32,
            save_to: Some(cache.clone()),
        })
        .id();
    harness.step();
    let cached = harness
        .world_mut()
        .get::<GrassSliceBakeResult>(again)
        .expect("answered from the cache in one frame")
        .0
        .clone()
        .expect("cached bake");
    assert_eq!(cached.textures, bake.textures);
    std::fs::remove_file(&cache).ok();
    let layout = bake.textures.layout;
    let patch = BasePatch::generate(&species.patch);
    let reference = bake_reference(
        &layout,
        &species,
        &bake_triangles(&patch, species.patch.width, species.patch.segments),
    );
    let mut worst = (0usize, 0usize, 0usize, String::new());
    let (mut total_covered, mut total_differ, mut total_off) = (0, 0, 0);
    for s in 0..layout.slices() {
        for layer in 0..LAYERS {
            let (gpu, cpu) = (bake.textures.layer(s, layer), reference.layer(s, layer));
            let covered = cpu.iter().filter(|t| t[3] > 0.5).count();
            let differ = gpu
                .iter()
                .zip(cpu)
                .filter(|(g, c)| (g[3] > 0.5) != (c[3] > 0.5))
                .count();
            let off = gpu
                .iter()
                .zip(cpu)
                .filter(|(g, c)| g[3] > 0.5 && c[3] > 0.5)
                .filter(|(g, c)| (0..3).any(|k| (g[k] - c[k]).abs() > 0.004 + 0.01 * c[k].abs()))
                .count();
            total_covered += covered;
            total_differ += differ;
            total_off += off;
            if differ + off > worst.1 + worst.2 {
                worst = (covered, differ, off, format!("slice {s} layer {layer}"));
            }
        }
    }
    eprintln!(
        "covered {total_covered}, coverage differs {total_differ}, values off {total_off}; worst {worst:?}"
    );
    assert!(total_covered > 5000, "{total_covered}");
    assert!(
        total_differ * 100 < total_covered,
        "{total_differ} of {total_covered}"
    );
    assert!(
        total_off * 100 < total_covered,
        "{total_off} of {total_covered}"
    );
}

/// Coverage (non-background fraction) of `regions.0 × regions.1` screen regions.
fn region_coverage(image: &RgbaImage, regions: (u32, u32)) -> Vec<f64> {
    let (w, h) = (image.width / regions.0, image.height / regions.1);
    let mask = {
        let bg = BACKGROUND.to_srgba();
        let bg = [bg.red * 255.0, bg.green * 255.0, bg.blue * 255.0].map(|c| c as i32);
        move |p: [u8; 4]| (0..3).any(|k| (p[k] as i32 - bg[k]).abs() > 24)
    };
    let mut out = Vec::new();
    for ry in 0..regions.1 {
        for rx in 0..regions.0 {
            let mut covered = 0;
            for y in ry * h..(ry + 1) * h {
                for x in rx * w..(rx + 1) * w {
                    covered += mask(image.pixel(x, y)) as u32;
                }
            }
            out.push(covered as f64 / (w * h) as f64);
        }
    }
    out
}

/// A slow dolly over a field across both transition distances: at every step the coverage of
/// each screen region with geometry, vertical slices and the horizontal slice stays close to the
/// all-geometry render of the same view — the transitions keep the grass whole. The tolerance is
/// asymmetric: a region may lose at most 0.05 of its coverage (a hole where one representation
/// fades before the next comes in is what the transitions exist to prevent), and gain at most
/// 0.2 — the slices cover a little more than the blades by design: the horizontal slice fills in
/// behind the vertical ones, and the slices' mips keep the maximum alpha (§4.3.3) so distant
/// grass does not thin out.
#[test]
fn transitions_keep_the_coverage_of_the_all_geometry_field() {
    let (width, height) = (96u32, 64u32);
    let Some(mut harness) = RenderHarness::for_test("grass_dolly", width, height) else {
        return;
    };
    let transitions = TransitionDistances {
        min_geom: 3.0,
        max_geom: 6.0,
        min_btf: 9.0,
        max_btf: 14.0,
        max_silhouettes: 30.0,
        ..default()
    };
    let all_geometry = TransitionDistances {
        min_geom: 100.0,
        max_geom: 101.0,
        min_btf: 102.0,
        max_btf: 103.0,
        max_silhouettes: 104.0,
        ..default()
    };
    harness
        .app_mut()
        .add_plugins(GrassPlugin)
        .insert_resource(ClearColor(BACKGROUND))
        .insert_resource(GrassSettings {
            transitions,
            max_distance: 24.0,
            slice_per_axis: 4,
            slice_resolution: 32,
            wind: still_air(),
            ..default()
        });
    let species = GrassSpecies {
        patch: PatchSettings {
            strata: 6,
            width: 0.02,
            ..default()
        },
        ..default()
    };
    harness.world_mut().spawn(GrassField {
        size: Vec2::new(12.0, 48.0),
        species,
        density: None,
        ground: None,
        ambient_occlusion: None,
    });
    harness.world_mut().spawn((
        DirectionalLight::default(),
        Transform::from_xyz(1.0, 3.0, 2.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let camera = harness
        .world_mut()
        .spawn((
            Camera3d::default(),
            Msaa::Off,
            Transform::from_xyz(0.0, 1.2, -20.0).looking_to(Vec3::new(0.0, -0.12, 1.0), Vec3::Y),
        ))
        .id();
    harness.wait_until_ready().expect("pipelines");
    // Wait for the slice bake.
    for _ in 0..200 {
        harness.step();
        let drawn = harness
            .world_mut()
            .query::<&bevy_foliage::grass::systems::GrassFieldState>()
            .iter(harness.world_mut())
            .any(|s| s.slice_nodes.0 > 0);
        if drawn {
            break;
        }
    }
    let regions = (6, 4);
    let (mut worst_loss, mut worst_gain): (f64, f64) = (0.0, 0.0);
    for step in 0..4 {
        let z = -20.0 + 2.5 * step as f32;
        harness
            .world_mut()
            .get_mut::<Transform>(camera)
            .unwrap()
            .translation
            .z = z;
        let render = |harness: &mut RenderHarness, t: TransitionDistances, name: &str| {
            harness
                .world_mut()
                .resource_mut::<GrassSettings>()
                .transitions = t;
            for _ in 0..6 {
                harness.step();
            }
            harness.wait_until_ready().expect("pipelines");
            let image = harness.render().unwrap();
            image
                .save_png(
                    bevy_nature_harness::compare::artifacts_dir()
                        .join(format!("grass_dolly_{step}_{name}.png")),
                )
                .ok();
            image
        };
        let mixed = render(&mut harness, transitions, "mixed");
        let geometry = render(&mut harness, all_geometry, "geometry");
        let (a, b) = (
            region_coverage(&mixed, regions),
            region_coverage(&geometry, regions),
        );
        let diffs: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x - y).collect();
        eprintln!(
            "step {step}: mixed {:?}\n        geometry {:?}",
            a.iter().map(|v| format!("{v:.2}")).collect::<Vec<_>>(),
            b.iter().map(|v| format!("{v:.2}")).collect::<Vec<_>>()
        );
        worst_loss = diffs.iter().fold(worst_loss, |w, d| w.max(-d));
        worst_gain = diffs.iter().fold(worst_gain, |w, d| w.max(*d));
    }
    eprintln!("worst region loss {worst_loss:.3}, gain {worst_gain:.3}");
    assert!(
        worst_loss <= 0.05,
        "a region lost {worst_loss} of its coverage"
    );
    assert!(worst_gain <= 0.2, "a region gained {worst_gain}");
}

/// The slice tests' scene, known light and no tone mapping so the colour can be checked: a 2 m
/// field of [`species`] (its slices K = 2 at 32 texels a side, `density`), seen by an
/// orthographic camera at `camera` over `view` metres, under a sun (no shadow maps) and an
/// ambient light; stepped until the slices are baked and the pipelines ready.
struct SliceScene {
    bake: std::sync::Arc<bevy_foliage::grass::slice_format::SliceBake>,
    to_light: Vec3,
    sun: f32,
    ambient: f32,
    exposure: f32,
}

const SLICE_RESOLUTION: u32 = 32;

fn slice_scene(
    harness: &mut RenderHarness,
    transitions: TransitionDistances,
    density: Option<Image>,
    camera: Transform,
    view: f32,
) -> SliceScene {
    use bevy::camera::Exposure;
    use bevy::core_pipeline::tonemapping::Tonemapping;
    use bevy_foliage::grass::bake::GrassSliceBakeResult;
    harness
        .app_mut()
        .add_plugins(GrassPlugin)
        .insert_resource(ClearColor(BACKGROUND))
        .insert_resource(GrassSettings {
            transitions,
            slice_per_axis: 2,
            slice_resolution: SLICE_RESOLUTION,
            wind: still_air(),
            ..default()
        });
    let density = density.map(|image| add_image(harness, image));
    harness.world_mut().spawn(GrassField {
        size: Vec2::splat(2.0),
        species: species(),
        density,
        ground: None,
        ambient_occlusion: None,
    });
    let camera = spawn_ortho_camera(harness, camera, Vec2::splat(view));
    let to_light = Vec3::new(0.4, 0.8, -0.3).normalize();
    let (sun, ambient) = (2000.0, 300.0);
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: sun,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::default().looking_to(-to_light, Vec3::Y),
    ));
    harness.app_mut().insert_resource(GlobalAmbientLight {
        brightness: ambient,
        ..default()
    });
    harness
        .world_mut()
        .entity_mut(camera)
        .insert(Tonemapping::None);
    let mut bake = None;
    for _ in 0..300 {
        harness.step();
        let mut q = harness.world_mut().query::<&GrassSliceBakeResult>();
        if let Some(r) = q.iter(harness.world_mut()).next() {
            bake = Some(r.0.clone().expect("slices baked"));
            break;
        }
    }
    let bake = bake.expect("the bake finished");
    harness.wait_until_ready().expect("pipelines");
    for _ in 0..4 {
        harness.step();
    }
    SliceScene {
        bake,
        to_light,
        sun,
        ambient,
        exposure: Exposure::default().exposure(),
    }
}

/// How many of the pixels both the GPU and the CPU cover come within 3 levels of the CPU's
/// radiance (linear, before the sRGB encoding), and of how many.
fn colour_agreement(
    image: &RgbaImage,
    gpu: &[bool],
    cpu: &[bool],
    colour: &[Option<Vec3>],
) -> (usize, usize) {
    let encode = |v: f32| {
        let v = v.clamp(0.0, 1.0);
        let e = if v <= 0.0031308 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        e * 255.0
    };
    let (mut both, mut close) = (0, 0);
    for i in 0..(SIZE * SIZE) as usize {
        let (true, true, Some(want)) = (gpu[i], cpu[i], colour[i]) else {
            continue;
        };
        let got = image.pixel(i as u32 % SIZE, i as u32 / SIZE);
        both += 1;
        if (0..3).all(|k| (got[k] as f32 - encode(want[k])).abs() <= 3.0) {
            close += 1;
        }
    }
    (close, both)
}

/// The slice pass keeps, pixel for pixel, the horizontal-slice texels its CPU reference keeps:
/// seen straight down from far enough that only the horizontal slice is drawn, each pixel
/// centre on a texel centre, every cell's mirrored version, the density gradient and algorithm
/// 1's opacity dithered under each quad's own shift (to within 0.1 % of the pixels: a shared
/// threshold differs on 0.6 %); and lights them as `slice_shading::slice_radiance` does (the
/// five baked directions blended by appendix A, the blade shadow mask, the ambient light as
/// Bevy's PBR gives it to the blades), within 3 levels.
#[test]
fn slice_pass_keeps_the_texels_the_cpu_keeps() {
    use bevy_foliage::grass::mesh::HORIZONTAL_SLICE_LIFT;
    use bevy_foliage::grass::slice_shading::{
        blade_n_dot_v, fragment_opacity, light_in_patch, slice_point, slice_radiance,
    };
    use bevy_foliage::grass::slices::{LAYER_THRESHOLD, LAYER_UNLIT, SliceAxis};
    use bevy_foliage::grass::transition::shifted_dither;
    let Some(mut harness) = RenderHarness::for_test("grass_slice_pass", SIZE, SIZE) else {
        return;
    };
    let resolution = SLICE_RESOLUTION;
    let texel = 0.5 / resolution as f32;
    let view = texel * SIZE as f32;
    let far = TransitionDistances {
        min_geom: 1.0,
        max_geom: 2.0,
        min_btf: 3.0,
        max_btf: 4.0,
        max_silhouettes: 5.0,
        ..default()
    };
    let species = species();
    let scene = slice_scene(
        &mut harness,
        far,
        Some(gradient_image()),
        Transform::from_translation(EYE).looking_to(Vec3::NEG_Y, Vec3::NEG_Z),
        view,
    );
    let (bake, to_light) = (&scene.bake, scene.to_light);
    let image = render_saved(&mut harness, "grass_slice_pass");
    let gpu = gpu_coverage(&image);
    let layout = bake.textures.layout;
    let grid = field_grid(Vec2::ZERO, Vec2::splat(2.0), 0.5);
    let map = DensityMap::new(2, 1, vec![64.0 / 255.0, 1.0], [-1.0, -1.0], [2.0, 2.0]).unwrap();
    let mut cpu = vec![false; (SIZE * SIZE) as usize];
    let mut colour = vec![None; (SIZE * SIZE) as usize];
    let mask = bake.textures.shadow_mask();
    for py in 0..SIZE {
        for px in 0..SIZE {
            let p = Vec3::new(
                -view / 2.0 + (px as f32 + 0.5) * texel,
                HORIZONTAL_SLICE_LIFT,
                -view / 2.0 + (py as f32 + 0.5) * texel,
            );
            let sp = slice_point(
                &layout,
                &grid,
                0.0,
                species.patch.seed,
                p,
                SliceAxis::Horizontal,
                EYE,
            );
            let (c, r) = (
                ((sp.uv.x * resolution as f32) as u32).min(resolution - 1),
                ((sp.uv.y * resolution as f32) as u32).min(resolution - 1),
            );
            let at = (r * resolution + c) as usize;
            let coverage = bake.textures.layer(sp.slice, LAYER_UNLIT)[at][3];
            let dth = bake.textures.layer(sp.slice, LAYER_THRESHOLD)[at][0];
            let ld = map.density_at(p.x, p.z);
            let o = fragment_opacity(
                &far,
                SliceAxis::Horizontal,
                coverage,
                dth,
                p.distance(EYE),
                ld,
                1.0,
            );
            cpu[(py * SIZE + px) as usize] =
                o >= DISCARD && o > shifted_dither(px, py, sp.dither_key);
            // `slice_shading::slice_radiance` under the sun (through the blade shadow mask at the
            // slice's height) and the ambient light.
            let layer = |l: u32| bake.textures.layer(sp.slice, l)[at];
            let to_eye = (EYE - p).normalize();
            let radiance = slice_radiance(
                &sp,
                layer,
                species.transmission,
                blade_n_dot_v(SliceAxis::Horizontal, to_eye),
                Vec3::splat(scene.ambient),
                Vec3::splat(scene.sun),
                mask.light_through(HORIZONTAL_SLICE_LIFT, to_light, ld),
                light_in_patch(to_light, sp.mirror),
            ) * scene.exposure;
            colour[(py * SIZE + px) as usize] = Some(radiance);
        }
    }
    let (differ, g, c) = compare(&gpu, &cpu);
    let (cl, cr) = thirds(&cpu);
    eprintln!("slice pass: differ {differ}, GPU {g} px, CPU {c} px, CPU thirds {cl:.3}/{cr:.3}");
    assert!(c > 1500, "{c}");
    assert!(cl < 0.75 * cr, "{cl} vs {cr}");
    assert!(differ * 1000 < c, "{differ} px differ of {c}");
    let (close, both) = colour_agreement(&image, &gpu, &cpu, &colour);
    eprintln!("slice colour: {close} of {both} pixels within 3 levels of the CPU radiance");
    assert!(close * 100 >= both * 95, "{close} of {both}");
}

/// The vertical slices, seen side on: an orthographic camera level with the field looks along
/// −z through every slice across z (those across x and the horizontal slice are edge-on), and
/// each pixel shows the nearest slice texel that algorithm 1's opacity keeps under that quad's
/// own dither shift — the texels read bilinearly, as the GPU's sampler does, every cell's
/// mirrored version and the eye's side of the slice — lit as `slice_radiance` lights it (the
/// five baked directions of the side seen, the shadow mask at the texel's height, the ambient
/// light at the blades' angle to the view). Within 0.5 % of the pixels (one dither threshold
/// shared by every quad differs on 2.5 %) and 3 levels of colour.
#[test]
fn vertical_slices_show_the_nearest_texels_the_cpu_keeps() {
    use bevy_foliage::grass::slice_shading::{
        blade_n_dot_v, fragment_opacity, light_in_patch, slice_point, slice_radiance,
    };
    use bevy_foliage::grass::slices::{LAYER_THRESHOLD, LAYER_UNLIT, SliceAxis};
    use bevy_foliage::grass::transition::shifted_dither;
    let Some(mut harness) = RenderHarness::for_test("grass_vertical_slices", SIZE, SIZE) else {
        return;
    };
    let res = SLICE_RESOLUTION;
    // A pixel a texel wide; the view 1.5 m across, the ground a few pixels above its bottom.
    let pixel = 0.5 / res as f32;
    let view = pixel * SIZE as f32;
    let eye = Vec3::new(0.0, view / 2.0 - 4.0 * pixel, 50.0);
    // The vertical slices at full weight around 50 m (and the horizontal one, edge-on).
    let side_on = TransitionDistances {
        min_geom: 0.1,
        max_geom: 0.2,
        min_btf: 500.0,
        max_btf: 600.0,
        max_silhouettes: 700.0,
        ..default()
    };
    let species = species();
    let scene = slice_scene(
        &mut harness,
        side_on,
        None,
        Transform::from_translation(eye).looking_to(Vec3::NEG_Z, Vec3::Y),
        view,
    );
    let image = render_saved(&mut harness, "grass_vertical_slices");
    let gpu = gpu_coverage(&image);
    let bake = &scene.bake;
    let layout = bake.textures.layout;
    let grid = field_grid(Vec2::ZERO, Vec2::splat(2.0), 0.5);
    let k = layout.per_axis;
    // Layer `l` of slice `s` at uv, bilinear between texel centres, clamped at the edges.
    let bilinear = |s: u32, l: u32, uv: Vec2| -> [f32; 4] {
        let texels = bake.textures.layer(s, l);
        let t = uv * res as f32 - 0.5;
        let base = t.floor();
        let f = t - base;
        let at = |dx: i32, dy: i32| {
            let c = (base.x as i32 + dx).clamp(0, res as i32 - 1) as u32;
            let r = (base.y as i32 + dy).clamp(0, res as i32 - 1) as u32;
            texels[(r * res + c) as usize]
        };
        let (a, b, c, d) = (at(0, 0), at(1, 0), at(0, 1), at(1, 1));
        std::array::from_fn(|i| {
            let top = a[i] + (b[i] - a[i]) * f.x;
            let bottom = c[i] + (d[i] - c[i]) * f.x;
            top + (bottom - top) * f.y
        })
    };
    let mask = bake.textures.shadow_mask();
    let mut cpu = vec![false; (SIZE * SIZE) as usize];
    let mut colour = vec![None; (SIZE * SIZE) as usize];
    for py in 0..SIZE {
        for px in 0..SIZE {
            let (x, y) = (
                eye.x - view / 2.0 + (px as f32 + 0.5) * pixel,
                eye.y + view / 2.0 - (py as f32 + 0.5) * pixel,
            );
            if !(0.0..=layout.height).contains(&y) {
                continue;
            }
            // The quads across z, nearest (largest z) first.
            'quads: for cz in (0..4).rev() {
                for slab in (0..k).rev() {
                    let z = grid.origin.y + (cz as f32 + (slab as f32 + 0.5) / k as f32) * 0.5;
                    let p = Vec3::new(x, y, z);
                    let sp = slice_point(
                        &layout,
                        &grid,
                        0.0,
                        species.patch.seed,
                        p,
                        SliceAxis::Z,
                        eye,
                    );
                    let to_eye = (eye - p).normalize();
                    let coverage = bilinear(sp.slice, LAYER_UNLIT, sp.uv)[3];
                    let dth = bilinear(sp.slice, LAYER_THRESHOLD, sp.uv)[0];
                    let o = fragment_opacity(
                        &side_on,
                        SliceAxis::Z,
                        coverage,
                        dth,
                        p.distance(eye),
                        1.0,
                        to_eye.y,
                    );
                    if !(o >= DISCARD && o > shifted_dither(px, py, sp.dither_key)) {
                        continue;
                    }
                    cpu[(py * SIZE + px) as usize] = true;
                    let radiance = slice_radiance(
                        &sp,
                        |l| bilinear(sp.slice, l, sp.uv),
                        species.transmission,
                        blade_n_dot_v(SliceAxis::Z, to_eye),
                        Vec3::splat(scene.ambient),
                        Vec3::splat(scene.sun),
                        mask.light_through(y, scene.to_light, 1.0),
                        light_in_patch(scene.to_light, sp.mirror),
                    ) * scene.exposure;
                    colour[(py * SIZE + px) as usize] = Some(radiance);
                    break 'quads;
                }
            }
        }
    }
    let (differ, g, c) = compare(&gpu, &cpu);
    eprintln!("vertical slices: differ {differ}, GPU {g} px, CPU {c} px");
    assert!(c > 1000, "{c}");
    assert!(differ * 200 < c, "{differ} px differ of {c}");
    let (close, both) = colour_agreement(&image, &gpu, &cpu, &colour);
    eprintln!(
        "vertical slice colour: {close} of {both} pixels within 3 levels of the CPU radiance"
    );
    assert!(close * 100 >= both * 95, "{close} of {both}");
}

/// A density map that cannot be read (here an `Rgba8Snorm` image) is an error on the field naming
/// the format, and the field grows at full density meanwhile; a readable one replaces nothing
/// but the map.
#[test]
fn an_unreadable_density_map_is_an_error_and_the_field_still_grows() {
    use bevy_foliage::grass::GrassFieldError;
    use bevy_foliage::grass::systems::GrassFieldState;
    let Some(mut harness) = RenderHarness::for_test("grass_bad_density", 32, 32) else {
        return;
    };
    harness.app_mut().add_plugins(GrassPlugin);
    let mut bad = gradient_image();
    bad.texture_descriptor.format = bevy::render::render_resource::TextureFormat::Rgba8Snorm;
    bad.data = Some(vec![0; 8]);
    // Kept on the CPU only: nothing of it goes to the GPU.
    bad.asset_usage = bevy::asset::RenderAssetUsages::MAIN_WORLD;
    let bad = add_image(&mut harness, bad);
    let good = add_image(&mut harness, gradient_image());
    let field = |density| GrassField {
        size: Vec2::splat(2.0),
        species: species(),
        density: Some(density),
        ground: None,
        ambient_occlusion: None,
    };
    let (broken, fine) = (
        harness.world_mut().spawn(field(bad)).id(),
        harness.world_mut().spawn(field(good)).id(),
    );
    spawn_top_down_camera(&mut harness, VIEW);
    for _ in 0..4 {
        harness.step();
    }
    let world = harness.world_mut();
    let error = world
        .get::<GrassFieldError>(broken)
        .expect("an error on the field");
    assert!(error.0.contains("Rgba8Snorm"), "{}", error.0);
    assert!(world.get::<GrassFieldError>(fine).is_none());
    let full = world.get::<GrassFieldState>(broken).unwrap();
    assert_eq!(full.density.values(), &[1.0]);
    assert!(full.geometry_cells > 0);
    let read = world.get::<GrassFieldState>(fine).unwrap();
    assert_eq!(read.density.dimensions(), (2, 1));
}

/// The blade pass on relief and in the wind: seen side-on, the blades stand where the CPU puts
/// them — lifted onto the ground by eq. 4.10 from the field's height map sampled at its cell
/// corners (`GroundGrid`), and sheared by the corner winds of the wind map (`GrassWind::offset`)
/// — pixel by pixel. The field stands 1.5 m up, out of the view of its flat bounds, so cells
/// whose bounds were not lifted would be culled.
#[test]
fn blades_stand_on_the_ground_and_lean_in_the_wind() {
    use bevy_foliage::grass::GrassWindMap;
    use bevy_foliage::grass::ground::{GrassWind, GroundGrid};
    use bevy_foliage::grass::ground_map::{HeightMap, height_map_image};
    const W: u32 = 160;
    const H: u32 = 64;
    let (view_w, view_h, centre_y) = (4.4, 1.76, 1.75);
    let Some(mut harness) = RenderHarness::for_test("grass_relief", W, H) else {
        return;
    };
    let field_size = Vec2::new(4.0, 0.5);
    let wind = GrassWind {
        direction: Vec2::X,
        strength: 0.15,
        // Still gusts: the time the frame is drawn at does not matter.
        speed: 0.0,
        scale: 3.0,
    };
    let near = geometry_only();
    harness
        .app_mut()
        .add_plugins(GrassPlugin)
        .insert_resource(ClearColor(BACKGROUND))
        .insert_resource(GrassSettings {
            transitions: near,
            slices: false,
            wind,
            ..default()
        });
    let height = |p: Vec2| 1.5 + 0.3 * (p.x * 1.5).sin() + 0.05 * p.x;
    let heights = height_map_image(field_size, UVec2::new(16, 2), height);
    let heights_handle = add_image(&mut harness, heights.clone());
    harness.world_mut().spawn(GrassField {
        size: field_size,
        species: species(),
        density: None,
        ground: Some(heights_handle),
        ambient_occlusion: None,
    });
    harness.world_mut().spawn((
        DirectionalLight::default(),
        Transform::from_xyz(1.0, 3.0, 2.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    // Side-on, looking along −z: image x along +x, image y down −y.
    spawn_ortho_camera(
        &mut harness,
        Transform::from_xyz(0.0, centre_y, 10.0).looking_to(Vec3::NEG_Z, Vec3::Y),
        Vec2::new(view_w, view_h),
    );
    harness.wait_until_ready().expect("pipelines");
    let image = render_saved(&mut harness, "grass_relief");
    let gpu = covered_pixels(&image, UVec2::new(W, H));

    // The CPU's ground and wind, from the same inputs.
    let species = species();
    let grid = field_grid(Vec2::ZERO, field_size, species.patch.size);
    let map = HeightMap::from_image(&heights, -field_size / 2.0, field_size).unwrap();
    let (ground, _) = GroundGrid::sample(&grid, |p| map.height_at(p));
    let wind_map = harness.world_mut().resource::<GrassWindMap>().map.clone();
    let volume = species.patch.height.1;
    let to_pixel = |p: Vec3| {
        Vec2::new(
            (p.x / view_w + 0.5) * W as f32,
            ((centre_y - p.y) / view_h + 0.5) * H as f32,
        )
    };
    // Full density inside the field's rectangle and none outside: blades leaning out of it are
    // cut at its edge.
    let full =
        DensityMap::uniform(1.0, (-field_size / 2.0).to_array(), field_size.to_array()).unwrap();
    let keep_all = |p: Vec3, _: f32, _: u32, _: u32| full.density_at(p.x, p.z) >= DISCARD;
    let lifted = |p: Vec3, h: f32| {
        let push = wind.offset(&wind_map, &grid, p.xz(), h, volume, 0.0);
        Vec3::new(p.x + push.x, p.y + ground.height_at(p.xz()), p.z + push.y)
    };
    let still = |p: Vec3, _: f32| Vec3::new(p.x, p.y + ground.height_at(p.xz()), p.z);
    let pixels = UVec2::new(W, H);
    let cpu = rasterize_blades(field_size, pixels, to_pixel, lifted, keep_all);
    let cpu_still = rasterize_blades(field_size, pixels, to_pixel, still, keep_all);
    let cpu_flat = rasterize_blades(
        field_size,
        pixels,
        to_pixel,
        |p, _| p + Vec3::Y * 1.5,
        keep_all,
    );
    let (differ, g, c) = compare(&gpu, &cpu);
    let (differ_still, ..) = compare(&gpu, &cpu_still);
    let (differ_flat, ..) = compare(&gpu, &cpu_flat);
    eprintln!(
        "relief: differ {differ} (without wind {differ_still}, on a plane {differ_flat}), GPU {g} px, CPU {c} px"
    );
    assert!(c > 1500, "the CPU reference covers {c} px");
    // Pixel centres on a strip edge may go either way; nothing else may differ.
    assert!(differ * 100 < c, "{differ} px differ of {c}");
    // And the test sees both: without the wind, or on a plane, far more would differ.
    assert!(
        differ_still > 5 * differ.max(10),
        "{differ_still} vs {differ}"
    );
    assert!(
        differ_flat > 5 * differ.max(10),
        "{differ_flat} vs {differ}"
    );
}

/// The slice pass on the ground: vertical and horizontal slices of a field lifted 1.5 m by its
/// height map draw exactly what the same field on a plane 1.5 m up draws — the vertex stage
/// lifts every quad, the fragment stage reads the slices at the unlifted point. Without the lift
/// nothing would show: the view starts 0.87 m up.
#[test]
fn slices_on_lifted_ground_match_slices_on_a_raised_plane() {
    use bevy_foliage::grass::ground_map::height_map_image;
    const W: u32 = 128;
    const H: u32 = 48;
    let Some(mut harness) = RenderHarness::for_test("grass_slice_relief", W, H) else {
        return;
    };
    let field_size = Vec2::new(4.0, 0.5);
    harness
        .app_mut()
        .add_plugins(GrassPlugin)
        .insert_resource(ClearColor(BACKGROUND))
        .insert_resource(GrassSettings {
            // Slices only, the vertical ones in full at the camera's 10 m.
            transitions: TransitionDistances {
                min_geom: 1.0,
                max_geom: 2.0,
                min_btf: 30.0,
                max_btf: 40.0,
                ..default()
            },
            geometry: false,
            slice_per_axis: 2,
            slice_resolution: 32,
            wind: still_air(),
            ..default()
        });
    harness.world_mut().spawn((
        DirectionalLight::default(),
        Transform::from_xyz(1.0, 3.0, 2.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    spawn_ortho_camera(
        &mut harness,
        Transform::from_xyz(0.3, 2.7, 10.0).looking_to(Vec3::new(-0.03, -0.1, -1.0), Vec3::Y),
        Vec2::new(4.4, 1.65),
    );
    let render_field = |harness: &mut RenderHarness, y: f32, ground: Option<Handle<Image>>| {
        let field = harness
            .world_mut()
            .spawn((
                GrassField {
                    size: field_size,
                    species: species(),
                    density: None,
                    ground,
                    ambient_occlusion: None,
                },
                Transform::from_xyz(0.0, y, 0.0),
            ))
            .id();
        settle(harness);
        let image = harness.render().unwrap();
        harness.world_mut().entity_mut(field).despawn();
        image
    };
    let raised = render_field(&mut harness, 1.5, None);
    let heights = add_image(
        &mut harness,
        height_map_image(field_size, UVec2::new(4, 2), |_| 1.5),
    );
    let lifted = render_field(&mut harness, 0.0, Some(heights));
    for (name, image) in [
        ("grass_slices_raised", &raised),
        ("grass_slices_lifted", &lifted),
    ] {
        image
            .save_png(bevy_nature_harness::compare::artifacts_dir().join(format!("{name}.png")))
            .ok();
    }
    let pixels = UVec2::new(W, H);
    let (a, b) = (
        covered_pixels(&raised, pixels),
        covered_pixels(&lifted, pixels),
    );
    let covered = a.iter().filter(|c| **c).count();
    let mut off = 0;
    for y in 0..H {
        for x in 0..W {
            let (p, q) = (raised.pixel(x, y), lifted.pixel(x, y));
            if (0..3).any(|k| (p[k] as i32 - q[k] as i32).abs() > 2) {
                off += 1;
            }
        }
    }
    let (differ, ..) = compare(&a, &b);
    eprintln!(
        "slices on the ground: covered {covered} px, coverage differs {differ}, colour off {off}"
    );
    assert!(covered > 600, "the raised field covers {covered} px");
    assert!(off * 200 < covered, "{off} px differ of {covered}");
}

/// The blade shadow mask on the GPU against its CPU reference (`ShadowMask::light_through`, the
/// mask read from the field's own slices): seen side-on under a low sun, with no ambient light,
/// no shadow map and no tone mapping, the blade points the mask leaves fully lit keep their
/// colour when the mask is switched on, and those it shades to under a third of the light lose
/// most of it. The field stands 0.7 m up on its height map, so the mask must be read at the
/// height above the ground, not above the world's origin.
#[test]
fn the_blade_shadow_mask_darkens_the_points_the_cpu_shades() {
    use bevy::core_pipeline::tonemapping::Tonemapping;
    use bevy_foliage::grass::bake::GrassSliceBakeResult;
    use bevy_foliage::grass::ground_map::height_map_image;
    const W: u32 = 160;
    const H: u32 = 48;
    let (view_w, view_h, centre_y) = (4.4, 1.32, 0.9);
    let Some(mut harness) = RenderHarness::for_test("grass_shadow_mask", W, H) else {
        return;
    };
    let field_size = Vec2::new(4.0, 0.5);
    let lift = 0.7;
    harness
        .app_mut()
        .add_plugins(GrassPlugin)
        .insert_resource(ClearColor(BACKGROUND))
        .insert_resource(GlobalAmbientLight {
            brightness: 0.0,
            ..default()
        })
        .insert_resource(GrassSettings {
            transitions: geometry_only(),
            slices: false,
            wind: still_air(),
            ..default()
        });
    let heights = add_image(
        &mut harness,
        height_map_image(field_size, UVec2::new(4, 2), |_| lift),
    );
    harness.world_mut().spawn(GrassField {
        size: field_size,
        species: species(),
        density: None,
        ground: Some(heights),
        ambient_occlusion: None,
    });
    // A sun from the right and in front, 46° up: the camera sees the lit faces.
    let to_light = Vec3::new(1.0, 1.2, 0.6).normalize();
    harness.world_mut().spawn((
        DirectionalLight {
            illuminance: 8000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::default().looking_to(-to_light, Vec3::Y),
    ));
    let camera = spawn_ortho_camera(
        &mut harness,
        Transform::from_xyz(0.0, centre_y, 10.0).looking_to(Vec3::NEG_Z, Vec3::Y),
        Vec2::new(view_w, view_h),
    );
    harness
        .world_mut()
        .entity_mut(camera)
        .insert(Tonemapping::None);
    settle(&mut harness);
    let render = |harness: &mut RenderHarness, mask: bool, name: &str| {
        harness
            .world_mut()
            .resource_mut::<GrassSettings>()
            .shadow_mask = mask;
        for _ in 0..3 {
            harness.step();
        }
        render_saved(harness, name)
    };
    let masked = render(&mut harness, true, "grass_shadow_mask_on");
    let plain = render(&mut harness, false, "grass_shadow_mask_off");
    let mask = {
        let world = harness.world_mut();
        let mut q = world.query::<&GrassSliceBakeResult>();
        let bake = q
            .iter(world)
            .next()
            .expect("a bake")
            .0
            .clone()
            .expect("baked");
        bake.textures.shadow_mask()
    };

    // The nearest blade point behind each pixel (the camera looks along −z).
    let pixels = UVec2::new(W, H);
    let mut nearest: Vec<Option<Vec3>> = vec![None; (W * H) as usize];
    let to_pixel = |p: Vec3| {
        Vec2::new(
            (p.x / view_w + 0.5) * W as f32,
            ((centre_y - p.y) / view_h + 0.5) * H as f32,
        )
    };
    let half = field_size / 2.0;
    blade_fragments(
        field_size,
        pixels,
        to_pixel,
        |p, _| p + Vec3::Y * lift,
        |px, py, p, _| {
            if p.x.abs() > half.x || p.z.abs() > half.y {
                return;
            }
            let slot = &mut nearest[(py * W + px) as usize];
            if slot.is_none_or(|q| p.z > q.z) {
                *slot = Some(p);
            }
        },
    );
    let (mut lit, mut lit_kept, mut shaded, mut shaded_dark) = (0, 0, 0, 0);
    for (i, p) in nearest.iter().enumerate() {
        let Some(p) = p else { continue };
        let (x, y) = (i as u32 % W, i as u32 / W);
        let (on, off) = (masked.pixel(x, y), plain.pixel(x, y));
        let luma = |c: [u8; 4]| c[0] as f32 + c[1] as f32 + c[2] as f32;
        // Skip pixels showing the background in either (edge ties).
        if luma(off) < 1.0 || (off[0] > 200 && off[2] > 200) {
            continue;
        }
        let through = mask.light_through(p.y - lift, to_light, 1.0);
        if through >= 0.999 {
            lit += 1;
            if (luma(on) - luma(off)).abs() <= 6.0 {
                lit_kept += 1;
            }
        } else if through < 0.33 {
            shaded += 1;
            // sRGB-encoded: a third of the linear light is about 0.6 of the encoded value.
            if luma(on) < 0.8 * luma(off) {
                shaded_dark += 1;
            }
        }
    }
    eprintln!(
        "shadow mask: fully lit {lit} px ({lit_kept} unchanged), shaded {shaded} px ({shaded_dark} darker)"
    );
    assert!(lit > 150 && shaded > 150, "lit {lit}, shaded {shaded}");
    assert!(lit_kept * 100 >= lit * 97, "{lit_kept} of {lit}");
    assert!(
        shaded_dark * 100 >= shaded * 90,
        "{shaded_dark} of {shaded}"
    );
}

/// The terrain's ambient occlusion on the blades (§4.2.6): under ambient light alone, with no
/// tone mapping, each blade pixel drawn with an occlusion map is the same pixel drawn without it
/// with its reflected ambient (the 1 − γ Bevy does not transmit) times the map's value there
/// (bilinear between texel centres, as `DensityMap::density_at`) — 1 at −x falling to 0.5 at +x.
#[test]
fn terrain_occlusion_scales_the_blades_ambient_light() {
    use bevy::core_pipeline::tonemapping::Tonemapping;
    let Some(mut harness) = RenderHarness::for_test("grass_terrain_ao", SIZE, SIZE) else {
        return;
    };
    harness
        .app_mut()
        .add_plugins(GrassPlugin)
        .insert_resource(ClearColor(BACKGROUND))
        .insert_resource(GlobalAmbientLight {
            brightness: 4000.0,
            ..default()
        })
        .insert_resource(GrassSettings {
            transitions: geometry_only(),
            slices: false,
            wind: still_air(),
            ..default()
        });
    let camera = spawn_ortho_camera(
        &mut harness,
        Transform::from_translation(EYE).looking_to(Vec3::NEG_Y, Vec3::NEG_Z),
        Vec2::new(VIEW, VIEW),
    );
    harness
        .world_mut()
        .entity_mut(camera)
        .insert(Tonemapping::None);
    let occlusion = add_image(
        &mut harness,
        Image::new(
            bevy::render::render_resource::Extent3d {
                width: 2,
                height: 1,
                depth_or_array_layers: 1,
            },
            bevy::render::render_resource::TextureDimension::D2,
            vec![255, 128],
            bevy::render::render_resource::TextureFormat::R8Unorm,
            bevy::asset::RenderAssetUsages::all(),
        ),
    );
    let render = |harness: &mut RenderHarness, ao: Option<Handle<Image>>| {
        let field = harness
            .world_mut()
            .spawn(GrassField {
                size: Vec2::splat(2.0),
                species: species(),
                density: None,
                ground: None,
                ambient_occlusion: ao,
            })
            .id();
        settle(harness);
        let image = harness.render().unwrap();
        harness.world_mut().entity_mut(field).despawn();
        image
    };
    let open = render(&mut harness, None);
    let occluded = render(&mut harness, Some(occlusion));
    let map = DensityMap::new(2, 1, vec![1.0, 128.0 / 255.0], [-1.0, -1.0], [2.0, 2.0]).unwrap();
    let linear = |v: u8| {
        let c = v as f32 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let (mut checked, mut agree) = (0, 0);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let (a, b) = (open.pixel(x, y), occluded.pixel(x, y));
            // Blade pixels in both, bright enough for 8 bits to carry a ratio.
            let green = |p: [u8; 4]| p[1] > 60 && p[2] < 200;
            if !(green(a) && green(b)) {
                continue;
            }
            let world = Vec2::new(
                (x as f32 + 0.5) / SIZE as f32 * VIEW - VIEW / 2.0,
                (y as f32 + 0.5) / SIZE as f32 * VIEW - VIEW / 2.0,
            );
            // Bevy lights the share γ transmitted through a blade without its occlusion
            // (`bevy_pbr`'s transmitted ambient): the occlusion darkens the reflected 1 − γ.
            let gamma = species().transmission;
            let want = (1.0 - gamma) * map.density_at(world.x, world.y) + gamma;
            let got = linear(b[1]) / linear(a[1]);
            checked += 1;
            if (got - want).abs() < 0.06 {
                agree += 1;
            }
        }
    }
    eprintln!("terrain occlusion: {agree} of {checked} blade pixels scaled as the map says");
    assert!(checked > 1000, "{checked}");
    assert!(agree * 100 >= checked * 90, "{agree} of {checked}");
}
