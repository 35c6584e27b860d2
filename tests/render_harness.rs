//! The first render tests: they prove the harness renders for real and that its comparisons can
//! fail. They run on whatever adapter the machine has (a software Vulkan driver in CI); with
//! `CI=true` a missing adapter fails them.

use bevy::prelude::*;
use bevy_nature::showcase::{ShowcaseCamera, ShowcaseOptions, build_showcase, layout};
use bevy_nature_harness::compare::{Comparison, RgbaImage};
use bevy_nature_harness::{ExampleArgs, ExampleRunner, RenderHarness};

const W: u32 = 192;
const H: u32 = 128;

fn test_options() -> ShowcaseOptions {
    ShowcaseOptions {
        msaa: false,
        // Streamed terrain makes a frame depend on how far streaming got: plain ground here.
        terrain: false,
        // So does when the billboard-cloud bakes finish.
        impostors: false,
        // And when the grass slice bake finishes.
        grass: false,
        // Nothing here looks at the tree lighting's precision: the cheaper bake of its bins.
        tree_light_bins: bevy_foliage::lighting::traced_bins::BinEstimate::Neighbours,
        ..default()
    }
}

/// Renders the showcase with `options`; returns the image and the harness (for camera queries).
fn render_showcase(test: &str, options: ShowcaseOptions) -> Option<(RgbaImage, RenderHarness)> {
    let mut harness = RenderHarness::for_test(test, W, H)?;
    build_showcase(harness.app_mut(), options);
    let image = harness.render().unwrap_or_else(|e| panic!("{test}: {e}"));
    Some((image, harness))
}

/// Pixel position of a world point as seen by the showcase camera.
fn to_pixel(harness: &mut RenderHarness, world: Vec3) -> UVec2 {
    let world_ref = harness.world_mut();
    let mut query = world_ref.query_filtered::<(&Camera, &GlobalTransform), With<ShowcaseCamera>>();
    let (camera, transform) = query.single(world_ref).expect("one showcase camera");
    let p = camera
        .world_to_viewport(transform, world)
        .expect("point projects onto the screen");
    UVec2::new(p.x.round() as u32, p.y.round() as u32)
}

fn mean_luma_around(image: &RgbaImage, p: UVec2, radius: u32) -> f64 {
    image.mean_luma(
        p.x.saturating_sub(radius),
        p.y.saturating_sub(radius),
        p.x + radius + 1,
        p.y + radius + 1,
    )
}

/// Ground point `(x, 0, z)` is in the box's shadow iff it lies in the projection of the box
/// along the sun direction onto the ground (the box is convex, so the projection of its
/// corners bounds it: for the sun direction (1, -1, 0) the shadow spans x ∈ [x0 - ½, x0 + ½ + 1]).
fn in_box_shadow(p: Vec3) -> bool {
    let d = layout::SUN_DIRECTION;
    let half = layout::BOX_SIZE / 2.0;
    // A point on the ground is shadowed if the ray from it toward the sun hits the box.
    let to_sun = -d.normalize();
    let min = layout::BOX_CENTER - Vec3::splat(half);
    let max = layout::BOX_CENTER + Vec3::splat(half);
    let (mut t0, mut t1) = (0.0f32, f32::INFINITY);
    for axis in 0..3 {
        let (o, dir) = (p[axis], to_sun[axis]);
        if dir.abs() < 1e-6 {
            if o < min[axis] || o > max[axis] {
                return false;
            }
        } else {
            let (a, b) = ((min[axis] - o) / dir, (max[axis] - o) / dir);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
    }
    t0 <= t1
}

#[test]
fn box_casts_a_clearly_darker_shadow_on_the_lit_ground() {
    let Some((image, mut harness)) = render_showcase("shadow_region", test_options()) else {
        return;
    };
    // Points on the ground: one in the shadow beside the box (visible to the camera), two lit.
    let shadowed = Vec3::new(1.05, 0.0, 0.1);
    let lit = [Vec3::new(-1.6, 0.0, 0.1), Vec3::new(1.05, 0.0, 1.6)];
    assert!(
        in_box_shadow(shadowed),
        "test geometry: {shadowed} must be shadowed"
    );
    for p in lit {
        assert!(!in_box_shadow(p), "test geometry: {p} must be lit");
    }
    let shadow_px = to_pixel(&mut harness, shadowed);
    let shadow_luma = mean_luma_around(&image, shadow_px, 2);
    let cmp = Comparison::new("shadow_region", &image, &image);
    for p in lit {
        let px = to_pixel(&mut harness, p);
        let lit_luma = mean_luma_around(&image, px, 2);
        eprintln!("shadow {shadow_px} luma {shadow_luma:.3}; lit {px} luma {lit_luma:.3}");
        cmp.assert(
            shadow_luma < 0.6 * lit_luma && lit_luma - shadow_luma > 0.1,
            &format!(
                "shadow at {shadow_px} (luma {shadow_luma:.3}) should be clearly darker than lit \
                 ground at {px} (luma {lit_luma:.3})"
            ),
        );
    }
    // The box itself is drawn: its sunlit top face is red.
    let box_px = to_pixel(&mut harness, layout::BOX_CENTER + Vec3::new(0.0, 0.5, 0.0));
    let [r, g, _, _] = image.pixel(box_px.x, box_px.y);
    cmp.assert(
        r > g.saturating_add(40),
        &format!(
            "box face at {box_px} should be red, got {:?}",
            image.pixel(box_px.x, box_px.y)
        ),
    );
    eprintln!("{}", harness.run_stats("shadow_region").to_json());
}

#[test]
fn different_scenes_compare_as_different_and_equal_scenes_as_equal() {
    let Some((a, _)) = render_showcase("compare_a", test_options()) else {
        return;
    };
    let Some((a_again, _)) = render_showcase("compare_a_again", test_options()) else {
        return;
    };
    let moved = ShowcaseOptions {
        box_offset: Vec3::new(-1.5, 0.0, 0.5),
        box_color: Color::srgb(0.2, 0.3, 0.85),
        ..test_options()
    };
    let Some((b, _)) = render_showcase("compare_b", moved) else {
        return;
    };

    // The same scene rendered twice is (near) identical: the comparison can pass.
    let same = Comparison::new("same_scene", &a_again, &a);
    eprintln!(
        "same scene: rmse {:.5} psnr {:.1} ssim {:.4}",
        same.rmse, same.psnr, same.ssim
    );
    same.assert_rmse_at_most(0.01);
    same.assert(same.ssim > 0.98, "same scene should have ssim > 0.98");

    // A moved, recoloured box is a different image: the comparison can fail.
    let different = Comparison::new("different_scene", &b, &a);
    eprintln!(
        "different scenes: rmse {:.5} psnr {:.1} ssim {:.4}",
        different.rmse, different.psnr, different.ssim
    );
    different.assert_rmse_at_least(0.03);
    different.assert(
        different.ssim < 0.95,
        "different scenes should have ssim < 0.95",
    );
    different.assert(
        different.rmse > 5.0 * same.rmse.max(1e-4),
        "scene difference should dwarf render-to-render noise",
    );
}

#[test]
fn example_runner_headless_writes_screenshot_and_stats() {
    if bevy_nature_harness::require_adapter("example_runner").is_none() {
        return;
    }
    let dir = bevy_nature_harness::artifacts_dir().join("example_runner");
    let screenshot = dir.join("nature.png");
    let stats = dir.join("nature.json");
    let _ = std::fs::remove_file(&screenshot);
    let _ = std::fs::remove_file(&stats);
    let args = ExampleArgs::parse_from([
        "--headless",
        "--frames",
        "4",
        "--size",
        "96x64",
        "--screenshot",
        screenshot.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
    ])
    .unwrap();
    let exit =
        ExampleRunner::with_args("nature", args).run(|app| build_showcase(app, test_options()));
    assert_eq!(exit, AppExit::Success);

    let image = RgbaImage::load(&screenshot).expect("screenshot written");
    assert_eq!((image.width, image.height), (96, 64));
    // Not a blank frame: the sky, the ground and the box are all there.
    let distinct: std::collections::HashSet<[u8; 4]> = image
        .data
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect();
    assert!(
        distinct.len() > 20,
        "screenshot looks blank ({} colours)",
        distinct.len()
    );

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats written")).unwrap();
    assert_eq!(json["name"], "nature");
    assert_eq!(json["mode"], "headless");
    assert_eq!(json["frame_time"]["frames"], 4);
    let median = json["frame_time"]["median_ms"].as_f64().unwrap();
    let p95 = json["frame_time"]["p95_ms"].as_f64().unwrap();
    assert!(median > 0.0 && p95 >= median, "median {median} p95 {p95}");
    assert!(json["diagnostics"].is_object() && json["gpu_pass_ms"].is_object());
}

/// The main scene shows Screen Space Soft Shadows: the sun has them, the camera runs the passes
/// (with the prepasses they need) and the plain `StandardMaterial` surfaces became receivers.
#[test]
fn showcase_has_screen_space_soft_shadows() {
    use bevy_nature::soft_shadows::ScreenSpaceSoftShadows;
    use bevy_nature::soft_shadows::ssss::receiver::{SoftShadowCamera, SoftShadowMaterial};
    let Some((_, mut harness)) = render_showcase("showcase_ssss", test_options()) else {
        return;
    };
    harness.run_frames(2).unwrap();
    let world = harness.world_mut();
    assert_eq!(
        world.query::<&ScreenSpaceSoftShadows>().iter(world).count(),
        1
    );
    let cameras = world
        .query_filtered::<(), (With<ShowcaseCamera>, With<SoftShadowCamera>)>()
        .iter(world)
        .count();
    assert_eq!(cameras, 1, "the showcase camera runs the SSSS passes");
    let receivers = world
        .query::<&MeshMaterial3d<SoftShadowMaterial>>()
        .iter(world)
        .count();
    let standard = world
        .query::<&MeshMaterial3d<StandardMaterial>>()
        .iter(world)
        .count();
    assert!(
        receivers >= 2,
        "ground and box receive soft shadows: {receivers}"
    );
    assert_eq!(standard, 0, "no StandardMaterial left unconverted");
}

/// With the clipmap-textured ground with relief (the README's scene), the terrain and leaf
/// materials receive the soft shadows too: their soft-shadow fragment stages (with the relief
/// vertex stage) compile and render, every clipmap material holds the SSSS visibility texture,
/// and the ground is drawn as relief patches whose material reads the height stack.
#[test]
fn showcase_terrain_receives_soft_shadows() {
    use bevy_nature::soft_shadows::ssss::receiver::SsssTextures;
    use bevy_nature::terrain_clip::material::ClipmapMaterial;
    let options = ShowcaseOptions {
        terrain: true,
        forest: false,
        ..test_options()
    };
    let Some((_, mut harness)) = render_showcase("showcase_terrain_ssss", options) else {
        return;
    };
    harness.run_frames(3).unwrap();
    // A pipeline error (e.g. the soft variant failing to compile) fails `render`.
    harness.render().unwrap();
    let world = harness.world_mut();
    let visibility = world.resource::<SsssTextures>().visibility.clone();
    let materials = world.resource::<Assets<ClipmapMaterial>>();
    assert!(!materials.is_empty());
    for (_, material) in materials.iter() {
        assert_eq!(
            material.extension.soft_visibility.as_ref(),
            Some(&visibility)
        );
    }
    use bevy_nature::terrain_clip::terrain::{TerrainGeometry, TerrainPatches};
    let (handle, patches, triangles) = {
        let (geometry, patches) = world
            .query::<(&TerrainGeometry, &TerrainPatches)>()
            .single(world)
            .expect("the ground is a terrain with relief");
        (
            geometry.material.clone(),
            patches.selection.patches.len(),
            patches.triangles,
        )
    };
    assert!(patches > 0 && triangles > 0, "{patches} patches drawn");
    let materials = world.resource::<Assets<ClipmapMaterial>>();
    let material = &materials.get(&handle).unwrap().extension;
    assert!(material.height_layers.is_some() && material.height_base.is_some());
}

/// The main scene's meadow receives the soft shadows: the blade and slice materials hold the
/// SSSS visibility texture, and their soft-shadow fragment stages compile and render.
#[test]
fn showcase_grass_receives_soft_shadows() {
    use bevy_nature::foliage::grass::GrassSettings;
    use bevy_nature::foliage::grass::material::GrassBladeMaterial;
    use bevy_nature::foliage::grass::slice_material::GrassSliceMaterial;
    use bevy_nature::foliage::grass::systems::{GrassFieldState, grass_ready};
    use bevy_nature::soft_shadows::ssss::receiver::SsssTextures;
    let Some(mut harness) = RenderHarness::for_test("showcase_grass_ssss", W, H) else {
        return;
    };
    build_showcase(
        harness.app_mut(),
        ShowcaseOptions {
            grass: true,
            forest: false,
            ..test_options()
        },
    );
    // Blades only within 8 m of the camera (4.5 m up): a few hundred cells, so the software
    // rasteriser keeps up.
    harness
        .app_mut()
        .world_mut()
        .resource_mut::<GrassSettings>()
        .transitions
        .min_geom = 6.0;
    harness
        .app_mut()
        .world_mut()
        .resource_mut::<GrassSettings>()
        .transitions
        .max_geom = 8.0;
    // The slices too, once baked: their soft-shadow pipeline must compile before the render.
    for _ in 0..300 {
        harness.step();
        if grass_ready(harness.world_mut()) {
            break;
        }
    }
    harness.run_frames(2).unwrap();
    harness.wait_until_ready().unwrap();
    harness.run_frames(3).unwrap();
    harness.render().unwrap();
    let world = harness.world_mut();
    let state = world
        .query::<&GrassFieldState>()
        .single(world)
        .expect("one meadow");
    let (cells, (blocks, _)) = (state.geometry_cells, state.slice_nodes);
    assert!(cells > 20, "{cells} cells of blades");
    assert!(blocks > 0, "no slice blocks");
    let visibility = world.resource::<SsssTextures>().visibility.clone();
    let materials = world.resource::<Assets<GrassBladeMaterial>>();
    assert!(!materials.is_empty());
    for (_, material) in materials.iter() {
        assert_eq!(
            material.extension.soft_visibility.as_ref(),
            Some(&visibility)
        );
    }
    let slices = world.resource::<Assets<GrassSliceMaterial>>();
    assert!(!slices.is_empty());
    for (_, material) in slices.iter() {
        assert_eq!(material.soft_visibility.as_ref(), Some(&visibility));
    }
}

/// The main scene's distant backdrop trees are drawn by their billboard clouds: once the bakes
/// are done every backdrop tree has exactly one impostor, and some are on screen.
#[test]
fn showcase_distant_trees_are_billboard_clouds() {
    use bevy_nature::foliage::ForestTree;
    use bevy_nature::foliage::impostor::systems::{IMPOSTORS_DRAWN, ImpostorOf, TreeImpostor};
    let Some(mut harness) = RenderHarness::for_test("showcase_impostors", 160, 90) else {
        return;
    };
    build_showcase(
        harness.app_mut(),
        ShowcaseOptions {
            impostors: true,
            ..test_options()
        },
    );
    let mut done = false;
    for _ in 0..200 {
        harness.step();
        let world = harness.world_mut();
        let trees = world
            .query_filtered::<(), With<ForestTree>>()
            .iter(world)
            .count();
        let with = world
            .query_filtered::<(), (With<ForestTree>, With<TreeImpostor>)>()
            .iter(world)
            .count();
        let impostors = world
            .query_filtered::<(), With<ImpostorOf>>()
            .iter(world)
            .count();
        assert!(
            impostors <= trees,
            "{impostors} impostors for {trees} trees"
        );
        if trees > 40 && with == trees && impostors == trees {
            done = true;
            break;
        }
    }
    assert!(done, "the backdrop never got its billboard clouds");
    for _ in 0..4 {
        harness.step();
    }
    let drawn = harness.diagnostic(&IMPOSTORS_DRAWN).unwrap_or(0.0);
    assert!(drawn > 20.0, "{drawn} impostors drawn");
}

/// The whole-frame GPU timer brackets every pass: a frame takes at least as long as its main pass,
/// and without timestamp queries there is no figure rather than another clock's.
#[test]
fn whole_frame_gpu_time_covers_the_main_pass() {
    let Some(mut harness) = RenderHarness::for_test("frame_timer", 96, 64) else {
        return;
    };
    {
        let world = harness.world_mut();
        let mesh = world
            .resource_mut::<Assets<Mesh>>()
            .add(Sphere::new(1.0).mesh().uv(64, 32));
        let material = world
            .resource_mut::<Assets<StandardMaterial>>()
            .add(StandardMaterial::default());
        world.spawn((Mesh3d(mesh), MeshMaterial3d(material)));
        world.spawn((
            DirectionalLight {
                shadow_maps_enabled: true,
                ..default()
            },
            Transform::default().looking_to(Vec3::new(-1.0, -1.0, -0.5), Vec3::Y),
        ));
        world.spawn((
            Camera3d::default(),
            Transform::from_xyz(0.0, 0.0, 4.0).looking_at(Vec3::ZERO, Vec3::Y),
        ));
    }
    harness.wait_until_ready().unwrap();
    if !harness.has_gpu_timestamps() {
        assert!(harness.gpu_frame_time_ms().is_err());
        assert!(harness.gpu_pass_time_ms("main_opaque_pass_3d").is_err());
        return;
    }
    harness.run_frames(4).unwrap();
    harness.reset_timing();
    assert!(
        harness.gpu_frame_time_ms().is_err(),
        "no figure before any frame was timed"
    );
    harness.run_frames(10).unwrap();
    let frame = harness.gpu_frame_time_ms().unwrap();
    let main = harness.gpu_pass_time_ms("main_opaque_pass_3d").unwrap();
    println!("whole frame {frame:.3} ms, main pass {main:.3} ms");
    assert!(
        frame > 0.0 && frame >= 0.9 * main,
        "frame {frame} vs main pass {main}"
    );
    assert!(harness.gpu_pass_time_ms("no_such_pass").is_err());
}
