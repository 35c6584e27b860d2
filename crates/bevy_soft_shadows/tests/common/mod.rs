//! The pole scene shared by the soft-shadow render tests: a 1 m wide, 4 m tall pole on a white
//! ground under a directional light 45° up from +x, seen from straight above (image right = +x,
//! down = +z), the shadow falling towards −x. Across the shadow's side edge at z = 0.5, `s`
//! metres behind the pole, the blocker is `Δ = s·√2` from the ground along the light.
#![allow(dead_code)]

use bevy::camera::{OrthographicProjection, Projection, ScalingMode};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::light::{
    CascadeShadowConfigBuilder, DirectionalLightShadowMap, GlobalAmbientLight,
    ShadowFilteringMethod,
};
use bevy::prelude::*;
use bevy::render::render_resource::{Texture, TextureDimension, TextureFormat};
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy_nature_harness::RenderHarness;
use bevy_nature_harness::compare::RgbaImage;
use bevy_nature_harness::headless::read_texture_now;
use bevy_soft_shadows::filterable::filter::MomentMap;
use bevy_soft_shadows::reference::{LinearAverage, jittered_directions, srgb_to_linear};

pub const SIZE: u32 = 160;
/// World width of the view (m): x from −4.5 to 0.5, z from −2.5 to 2.5.
pub const VIEW_M: f32 = 5.0;
pub const CENTRE: Vec3 = Vec3::new(-2.0, 0.0, 0.0);
/// Angular diameter of the light (rad).
pub const THETA: f32 = 0.15;
pub const JITTERS: usize = 48;

#[derive(Component)]
pub struct Sun;

pub fn sun_direction() -> Vec3 {
    // From the ground towards the light: 45° up, from +x, so the shadow falls towards −x.
    Vec3::new(1.0, 1.0, 0.0).normalize()
}

pub fn setup(harness: &mut RenderHarness) {
    setup_scene(
        harness,
        Cuboid::new(0.2, 4.0, 1.0),
        Vec3::new(0.0, 2.0, 0.0),
        sun_direction(),
        CENTRE,
    );
}

/// The ground, one blocker (`shape` at `at`), the sun towards `sun` and the top-down camera
/// centred on `centre`.
pub fn setup_scene(harness: &mut RenderHarness, shape: Cuboid, at: Vec3, sun: Vec3, centre: Vec3) {
    spawn_ground_blocker_and_camera(harness, shape, at, centre);
    harness.world_mut().spawn((
        Sun,
        DirectionalLight {
            illuminance: 3000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        CascadeShadowConfigBuilder {
            num_cascades: 1,
            minimum_distance: 0.1,
            maximum_distance: 14.0,
            first_cascade_far_bound: 14.0,
            ..default()
        }
        .build(),
        Transform::default().looking_to(-sun, Vec3::Y),
    ));
}

/// The ground (no ambient light, 2048² shadow maps), one blocker (`shape` at `at`, marked
/// [`Blocker`]) and the orthographic top-down camera centred on `centre`; no light.
pub fn spawn_ground_blocker_and_camera(
    harness: &mut RenderHarness,
    shape: Cuboid,
    at: Vec3,
    centre: Vec3,
) {
    let world = harness.world_mut();
    world.insert_resource(GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    });
    world.insert_resource(DirectionalLightShadowMap { size: 2048 });
    let (ground, pole) = {
        let mut meshes = world.resource_mut::<Assets<Mesh>>();
        (
            meshes.add(Plane3d::default().mesh().size(40.0, 40.0)),
            meshes.add(shape),
        )
    };
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::srgb(0.8, 0.8, 0.8),
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        });
    world.spawn((Mesh3d(ground), MeshMaterial3d(material.clone())));
    world.spawn((
        Blocker,
        Mesh3d(pole),
        MeshMaterial3d(material),
        Transform::from_translation(at),
    ));
    world.spawn((
        Camera3d::default(),
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
        ShadowFilteringMethod::Hardware2x2,
        Projection::Orthographic(OrthographicProjection {
            scaling_mode: ScalingMode::Fixed {
                width: VIEW_M,
                height: VIEW_M,
            },
            ..OrthographicProjection::default_3d()
        }),
        Transform::from_translation(centre + Vec3::Y * 10.0).looking_at(centre, Vec3::NEG_Z),
    ));
}

/// The scene's blocker.
#[derive(Component)]
pub struct Blocker;

pub fn aim_sun(harness: &mut RenderHarness, direction_to_light: Vec3) {
    let world = harness.world_mut();
    let mut q = world.query_filtered::<&mut Transform, With<Sun>>();
    for mut t in q.iter_mut(world) {
        *t = Transform::default().looking_to(-direction_to_light, Vec3::Y);
    }
}

/// Pixel column of world x, pixel row of world z (image right = +x, down = +z).
pub fn pixel_of(x: f32, z: f32) -> (u32, u32) {
    let m_per_px = VIEW_M / SIZE as f32;
    (
        ((x - (CENTRE.x - VIEW_M / 2.0)) / m_per_px) as u32,
        ((z - (CENTRE.z - VIEW_M / 2.0)) / m_per_px) as u32,
    )
}

/// Visibility down the column at world x, from the pole's middle (z = 0) outwards across its
/// edge at z = 0.5, relative to the lit ground.
pub fn profile(linear: &[f32], x: f32, lit: f32) -> Vec<f32> {
    let (col, row0) = pixel_of(x, 0.0);
    let (_, row1) = pixel_of(x, 1.4);
    (row0..row1)
        .map(|row| linear[((row * SIZE + col) * 4 + 1) as usize] / lit)
        .collect()
}

/// The render in linear light.
pub fn to_linear(image: &RgbaImage) -> Vec<f32> {
    image.data.iter().map(|&v| srgb_to_linear(v)).collect()
}

/// The area-light reference of the current scene: `JITTERS` renders with the sun jittered over
/// its disk, averaged in linear light (the sun is aimed back at its centre afterwards).
pub fn area_light_reference(harness: &mut RenderHarness) -> LinearAverage {
    area_light_reference_towards(harness, sun_direction(), THETA)
}

/// The area-light reference for a sun towards `sun` of angular diameter `theta`.
pub fn area_light_reference_towards(
    harness: &mut RenderHarness,
    sun: Vec3,
    theta: f32,
) -> LinearAverage {
    let mut average = LinearAverage::default();
    for d in jittered_directions(sun, theta, JITTERS) {
        aim_sun(harness, d);
        average.add(&harness.render().unwrap().data);
    }
    aim_sun(harness, sun);
    average
}

/// Linear green of the lit ground, away from the shadow.
pub fn lit(image: &[f32]) -> f32 {
    let (lx, lz) = pixel_of(-1.5, 2.2);
    image[((lz * SIZE + lx) * 4 + 1) as usize]
}

/// The scene's sun.
pub fn sun_entity(harness: &mut RenderHarness) -> Entity {
    let world = harness.world_mut();
    world
        .query_filtered::<Entity, With<Sun>>()
        .single(world)
        .unwrap()
}

/// Towards the sun of the hovering-panel scene: almost straight above.
pub fn panel_sun() -> Vec3 {
    Vec3::new(0.02, 1.0, 0.01).normalize()
}

/// A harness for `test` with the soft shadows plugin and the hovering-panel scene (the thesis'
/// fig. 6.6: a 2 m panel 1.5 m over the ground, the sun almost straight above, so the panel hides
/// its own shadow from the camera above it), ready.
pub fn panel_harness(test: &str) -> Option<RenderHarness> {
    let mut harness = RenderHarness::for_test(test, SIZE, SIZE)?;
    harness
        .app_mut()
        .add_plugins(bevy_soft_shadows::SoftShadowsPlugin);
    setup_scene(
        &mut harness,
        Cuboid::new(2.0, 0.05, 2.0),
        Vec3::new(0.0, 1.5, 0.0),
        panel_sun(),
        Vec3::ZERO,
    );
    harness.wait_until_ready().unwrap();
    Some(harness)
}

/// A harness for `test` with the soft shadows plugin and the pole scene (not yet ready).
pub fn pole_harness(test: &str) -> Option<RenderHarness> {
    let mut harness = RenderHarness::for_test(test, SIZE, SIZE)?;
    harness
        .app_mut()
        .add_plugins(bevy_soft_shadows::SoftShadowsPlugin);
    setup(&mut harness);
    Some(harness)
}

/// Renders until the receivers draw the lit ground as `hard` does and `done` holds for the
/// frame (pipelines for new materials and passes compile asynchronously); fails after 100.
pub fn render_until(
    harness: &mut RenderHarness,
    hard: &[f32],
    done: impl Fn(&[f32]) -> bool,
) -> Vec<f32> {
    for _ in 0..100 {
        // A screenshot can miss its 30-frame window while new pipelines compile on a loaded
        // machine: try again (the loop still fails after 100 tries).
        let Ok(img) = harness.render() else {
            continue;
        };
        let img = to_linear(&img);
        if (lit(&img) - lit(hard)).abs() < 0.02 * lit(hard) && done(&img) {
            return img;
        }
    }
    panic!("the soft shadow never showed");
}

/// A screen-sized SSSS texture (`bytes_per_texel` bytes of f32 channels a texel) read back.
pub fn screen_floats(
    harness: &mut RenderHarness,
    image: &Handle<Image>,
    bytes_per_texel: u32,
) -> Vec<f32> {
    floats(
        &harness
            .read_image(image.clone(), SIZE, SIZE, bytes_per_texel)
            .unwrap(),
    )
}

/// Little-endian f32s.
pub fn floats(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// Root mean square difference of the green channel of two linear RGBA images.
pub fn rmse(a: &[f32], b: &[f32]) -> f32 {
    let mut sum = 0.0;
    let mut n = 0;
    for i in (0..a.len()).step_by(4) {
        let d = a[i + 1] - b[i + 1];
        sum += d * d;
        n += 1;
    }
    (sum / n as f32).sqrt()
}

/// Linear renders side by side (sRGB, 4 px white gaps), for the comparison images in the docs.
pub fn strip(images: &[&[f32]]) -> RgbaImage {
    const GAP: u32 = 4;
    let n = images.len() as u32;
    let width = n * SIZE + (n - 1) * GAP;
    let mut data = vec![255u8; (width * SIZE * 4) as usize];
    for (k, image) in images.iter().enumerate() {
        let x0 = k as u32 * (SIZE + GAP);
        for y in 0..SIZE {
            for x in 0..SIZE {
                let src = ((y * SIZE + x) * 4) as usize;
                let dst = ((y * width + x0 + x) * 4) as usize;
                for c in 0..3 {
                    data[dst + c] = bevy_soft_shadows::reference::linear_to_srgb(image[src + c]);
                }
            }
        }
    }
    RgbaImage::new(width, SIZE, data)
}

/// A dilation readback (`SsssDilationReadback`) of the last frame: layer 0 of the shadow map
/// (`coarse` false) or of the coarse dilated map, unpadded, with its size.
pub fn read_dilation(harness: &mut RenderHarness, coarse: bool) -> (Vec<f32>, UVec2) {
    use bevy_soft_shadows::ssss::render::SsssDilationReadback;
    let mut size = UVec2::ZERO;
    let bytes = harness
        .read_render_buffer(|world| {
            let r = world.get_resource::<SsssDilationReadback>()?;
            let (buffer, s) = if coarse {
                r.coarse.clone()?
            } else {
                r.fine.clone()?
            };
            size = s;
            Some(buffer)
        })
        .unwrap();
    let stride = (size.x as usize * 4).div_ceil(256) * 256;
    let texels = (0..size.y as usize)
        .flat_map(|y| floats(&bytes[y * stride..y * stride + size.x as usize * 4]))
        .collect();
    (texels, size)
}

/// The distance pass (its σ bound, on every ground pixel) and the refine pass (its σ, on the
/// ground pixels of the active tiles) against their CPU references: `bound_at` and `refined_at`
/// give the penumbra's world width at a ground point without and with the refined blocker. The
/// refined σ never exceeds the bound. Returns (agreeing, ground, penumbra) pixels of the bound.
pub fn assert_distance_pass_matches(
    harness: &mut RenderHarness,
    settings: &bevy_soft_shadows::ScreenSpaceSoftShadows,
    bound_at: impl Fn(Vec3) -> f32,
    refined_at: impl Fn(Vec3) -> f32,
) -> (u32, u32, u32) {
    use bevy_soft_shadows::ssss::distance::pixel_sigma;
    use bevy_soft_shadows::ssss::receiver::SsssTextures;
    let textures = harness.world_mut().resource::<SsssTextures>().clone();
    let distance = screen_floats(harness, &textures.distance, 16);
    let refined = screen_floats(harness, &textures.refined, 16);
    let m_per_px = VIEW_M / SIZE as f32;
    let sigma_of = |width: f32| {
        pixel_sigma(
            width,
            SIZE as f32 / VIEW_M,
            None,
            settings.min_kernel_px,
            settings.max_kernel_px,
        )
    };
    let (mut ground, mut agree, mut penumbra, mut worst) = (0u32, 0u32, 0u32, 0.0f32);
    let (mut refined_px, mut refined_agree, mut refined_worst) = (0u32, 0u32, 0.0f32);
    for row in 0..SIZE {
        for col in 0..SIZE {
            let i = (row * SIZE + col) as usize * 4;
            // Ground pixels only: the camera is 10 m above the ground.
            if (distance[i + 3] - 10.0).abs() > 1e-3 {
                continue;
            }
            ground += 1;
            let world = Vec3::new(
                CENTRE.x - VIEW_M / 2.0 + (col as f32 + 0.5) * m_per_px,
                0.0,
                CENTRE.z - VIEW_M / 2.0 + (row as f32 + 0.5) * m_per_px,
            );
            let sigma = sigma_of(bound_at(world));
            let error = (distance[i + 1] - sigma)
                .abs()
                .max((distance[i + 2] - sigma).abs());
            agree += (error <= 1e-3 * (1.0 + sigma)) as u32;
            worst = worst.max(error);
            penumbra += (sigma > 0.0) as u32;
            // Refined where the refine pass ran (−1 elsewhere).
            if refined[i + 3] >= 0.0 {
                refined_px += 1;
                let sigma = sigma_of(refined_at(world));
                let error = (refined[i + 1] - sigma)
                    .abs()
                    .max((refined[i + 2] - sigma).abs());
                refined_agree += (error <= 1e-3 * (1.0 + sigma)) as u32;
                refined_worst = refined_worst.max(error);
                assert!(
                    refined[i + 1] <= distance[i + 1] + 1e-4,
                    "refined σ {} over the bound {} at ({col}, {row})",
                    refined[i + 1],
                    distance[i + 1]
                );
            }
        }
    }
    println!(
        "distance pass vs CPU: {agree} of {ground} ground pixels agree ({penumbra} in penumbra), \
         worst σ difference {worst:.3} px; refine pass: {refined_agree} of {refined_px} agree, \
         worst {refined_worst:.3} px"
    );
    assert!(
        ground > SIZE * SIZE / 2 && penumbra > 500 && refined_px > 200,
        "{ground} / {penumbra} / {refined_px}"
    );
    assert!(
        agree as f32 >= 0.995 * ground as f32,
        "the distance pass differs from its CPU reference at {} pixels",
        ground - agree
    );
    assert!(
        refined_agree as f32 >= 0.995 * refined_px as f32,
        "the refine pass differs from its CPU reference at {} pixels",
        refined_px - refined_agree
    );
    (agree, ground, penumbra)
}

/// The last frame's SSSS soft visibility (per pixel), its distance map as the CPU blur takes
/// it (hard shadow, the σ the blur used — the refined one on the active tiles, the distance
/// pass's bound elsewhere, where the blur leaves the hard shadow either way —, eye depth), and
/// the distance pass's σ bounds the classification ran on; read back from `SsssTextures`.
pub fn read_ssss_screen(
    harness: &mut RenderHarness,
) -> (
    Vec<f32>,
    bevy_soft_shadows::ssss::blur::ScreenBuffers,
    Vec<[f32; 2]>,
) {
    use bevy_soft_shadows::ssss::receiver::SsssTextures;
    let textures = harness.world_mut().resource::<SsssTextures>().clone();
    let distance = screen_floats(harness, &textures.distance, 16);
    let refined = screen_floats(harness, &textures.refined, 16);
    // (visibility, light) per pixel: keep the visibility.
    let visibility: Vec<f32> = screen_floats(harness, &textures.visibility, 8)
        .into_iter()
        .step_by(2)
        .collect();
    let n = (SIZE * SIZE) as usize;
    let bounds: Vec<[f32; 2]> = (0..n)
        .map(|i| [distance[4 * i + 1], distance[4 * i + 2]])
        .collect();
    let buffers = bevy_soft_shadows::ssss::blur::ScreenBuffers {
        width: SIZE as usize,
        height: SIZE as usize,
        hard: (0..n).map(|i| distance[4 * i]).collect(),
        sigma: (0..n)
            .map(|i| {
                if refined[4 * i + 3] >= 0.0 {
                    [refined[4 * i + 1], refined[4 * i + 2]]
                } else {
                    bounds[i]
                }
            })
            .collect(),
        depth: (0..n).map(|i| distance[4 * i + 3]).collect(),
    };
    (visibility, buffers, bounds)
}

/// Each pixel's green over the unshadowed render's (a local light's falloff varies over the
/// view, so its visibility is each pixel over the render with the blocker hidden).
pub fn visibility(img: &[f32], unshadowed: &[f32]) -> Vec<f32> {
    img.iter()
        .zip(unshadowed)
        .enumerate()
        .map(|(i, (&v, &u))| if i % 4 == 1 { v / u.max(1e-4) } else { v })
        .collect()
}

/// The 10–90 % penumbra width (m) across the side edge at ground x, from a visibility image.
pub fn width_at(visibility: &[f32], x: f32) -> f32 {
    bevy_soft_shadows::reference::rise_width(&profile(visibility, x, 1.0), 0.1, 0.9)
        .expect("the penumbra rises")
        * VIEW_M
        / SIZE as f32
}

/// The scene rendered with its blocker hidden (each pixel's light, for [`visibility`]); the
/// blocker is shown again afterwards.
pub fn render_without_blocker(harness: &mut RenderHarness) -> Vec<f32> {
    let blocker = {
        let world = harness.world_mut();
        world
            .query_filtered::<Entity, With<Blocker>>()
            .single(world)
            .unwrap()
    };
    harness
        .world_mut()
        .entity_mut(blocker)
        .insert(Visibility::Hidden);
    harness.render().unwrap();
    let unshadowed = to_linear(&harness.render().unwrap());
    harness
        .world_mut()
        .entity_mut(blocker)
        .insert(Visibility::Inherited);
    harness.render().unwrap();
    unshadowed
}

/// Bevy's PCSS on a local light at the best of a sweep of its `radius` (`set` switches it on
/// with a radius, or off with `None`; off again afterwards): (RMSE against `reference`, the
/// radius, the image). Bevy's local-light PCSS kernel is in units of a fixed texel size times an
/// empirical factor, not metres, so the light's true radius is only where the sweep starts.
pub fn best_local_pcss(
    harness: &mut RenderHarness,
    set: impl Fn(&mut RenderHarness, Option<f32>),
    radii: &[f32],
    reference: &[f32],
) -> (f32, f32, Vec<f32>) {
    let mut best = (f32::INFINITY, 0.0, Vec::new());
    for &radius in radii {
        set(harness, Some(radius));
        // Two frames: the light uniform of the first may still be the previous one.
        harness.render().unwrap();
        let image = to_linear(&harness.render().unwrap());
        let e = rmse(&image, reference);
        println!("PCSS radius {radius:.2} m: RMSE {e:.4}");
        if e < best.0 {
            best = (e, radius, image);
        }
    }
    set(harness, None);
    best
}

/// Saves hard, Bevy's PCSS, SSSS and the reference (linear light) under `artifacts/<test>/`, and
/// the four side by side as `comparison.png`.
pub fn save_comparison(test: &str, hard: &[f32], pcss: &[f32], ssss: &[f32], reference: &[f32]) {
    let dir = bevy_nature_harness::artifacts_dir().join(test);
    std::fs::create_dir_all(&dir).ok();
    for (name, linear) in [
        ("hard.png", hard),
        ("reference.png", reference),
        ("pcss.png", pcss),
        ("ssss.png", ssss),
    ] {
        RgbaImage::new(
            SIZE,
            SIZE,
            linear
                .iter()
                .map(|&v| bevy_soft_shadows::reference::linear_to_srgb(v))
                .collect(),
        )
        .save_png(dir.join(name))
        .ok();
    }
    strip(&[hard, pcss, ssss, reference])
        .save_png(dir.join("comparison.png"))
        .ok();
}

/// Layer 0 of mip `level` of `texture` (one, two or four 32-bit float channels), read back as
/// four channels (the missing ones 0).
pub fn read_level(
    device: &RenderDevice,
    queue: &RenderQueue,
    texture: &Texture,
    level: u32,
) -> MomentMap {
    let size = texture.size().mip_level_size(level, TextureDimension::D2);
    let channels = match texture.format() {
        TextureFormat::R32Float => 1,
        TextureFormat::Rg32Float => 2,
        TextureFormat::Rgba32Float => 4,
        other => panic!("unexpected format {other:?}"),
    };
    let bytes = read_texture_now(device, queue, texture, level, 1, 4 * channels).expect("readback");
    let texels = bytes
        .chunks_exact(4 * channels as usize)
        .map(|texel| {
            std::array::from_fn(|c| {
                if c < channels as usize {
                    f32::from_le_bytes(texel[4 * c..4 * c + 4].try_into().unwrap())
                } else {
                    0.0
                }
            })
        })
        .collect();
    MomentMap {
        width: size.width,
        height: size.height,
        texels,
    }
}

/// The five filterable methods, in the order the tests switch through them.
pub const FILTERED_METHODS: [bevy_soft_shadows::filterable::filter::FilterableMethod; 5] = {
    use bevy_soft_shadows::filterable::filter::FilterableMethod::*;
    [
        GaussianCdf,
        PowerCdf,
        Variance,
        Exponential { c: 80.0 },
        Moments4,
    ]
};

/// Gives `sun` a filterable shadow map of `method`, pre-filtered by a Gaussian of 3 texels.
pub fn use_filtered_map(
    harness: &mut RenderHarness,
    sun: Entity,
    method: bevy_soft_shadows::filterable::filter::FilterableMethod,
) {
    harness
        .world_mut()
        .entity_mut(sun)
        .insert(bevy_soft_shadows::filterable::FilteredShadowMap {
            method,
            blur_sigma: 3.0,
        });
}

/// A shadow-casting directional light that gives no light: its four cascades take the first
/// layers of Bevy's directional and spot shadow texture.
pub fn spawn_dark_sun(world: &mut World) {
    world.spawn((
        DirectionalLight {
            illuminance: 0.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(0.3, -1.0, 0.2), Vec3::Y),
    ));
}

/// A shadow-casting point light at `at` that gives no light: it takes a place among Bevy's
/// clustered lights and its cube faces.
pub fn spawn_dark_bulb(world: &mut World, at: Vec3) {
    world.spawn((
        PointLight {
            intensity: 0.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_translation(at),
    ));
}

/// Every ground pixel of the pole scene's view: its index and world point, but for the pole's
/// (x within ±0.1, z within ±0.5) and two pixels around it.
pub fn ground_pixels() -> impl Iterator<Item = (usize, Vec3)> {
    let m_per_px = VIEW_M / SIZE as f32;
    (0..SIZE * SIZE).filter_map(move |i| {
        let (col, row) = (i % SIZE, i / SIZE);
        let x = CENTRE.x - VIEW_M / 2.0 + (col as f32 + 0.5) * m_per_px;
        let z = CENTRE.z - VIEW_M / 2.0 + (row as f32 + 0.5) * m_per_px;
        let on_pole = x.abs() < 0.1 + 2.0 * m_per_px && z.abs() < 0.5 + 2.0 * m_per_px;
        (!on_pole).then_some((i as usize, Vec3::new(x, 0.0, z)))
    })
}
