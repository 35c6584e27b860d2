//! Image test of the sub-pixel fade (§3.4): a tree with alpha-masked, mip-mapped leaf textures
//! seen from far enough that its leaves are about two pixels across. In the coarse mips the mask
//! averages below the alpha cutoff and the crown thins out; the fade draws such leaves solid and
//! shrunk to their opaque area. The reference is the same view rendered at 4× the resolution
//! with the exact (un-mipped) mask and box-filtered down, in the same run. Images are written under `target/nature-artifacts/subpixel_fade/`.

use bevy::asset::RenderAssetUsages;
use bevy::image::{ImageSampler, ImageSamplerDescriptor};
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy_foliage::pruning::bake::{BakeSettings, BakedFoliage, CellCount, bake};
use bevy_foliage::pruning::components::PrunedFoliage;
use bevy_foliage::pruning::material::opaque_fraction;
use bevy_foliage::pruning::material::{LeafMaterial, leaf_material_textured};
use bevy_foliage::pruning::procedural::{TreeSpecies, generate};
use bevy_foliage::{FoliagePlugin, FoliagePruningSettings};
use bevy_nature_harness::compare::{Comparison, RgbaImage};
use bevy_nature_harness::{RenderHarness, artifacts_dir};

const SIZE: u32 = 128;
const SUPERSAMPLE: u32 = 4;
const TEXTURE: u32 = 64;

/// A white leaf texture whose alpha is an ellipse (semi-axes 0.45 × 0.28 of the square, 40 % of
/// it opaque), with its full mip chain box-filtered like any baked texture (`mips`): in the
/// coarse levels the mean alpha (0.4) is under the 0.5 cutoff and the leaf disappears. Without
/// mips every sample reads level 0, the exact mask: with supersampling, the reference coverage.
fn leaf_texture(mips: bool) -> Image {
    let mut levels: Vec<Vec<u8>> = Vec::new();
    let mut base = vec![0u8; (TEXTURE * TEXTURE * 4) as usize];
    for y in 0..TEXTURE {
        for x in 0..TEXTURE {
            let u = (x as f32 + 0.5) / TEXTURE as f32 - 0.5;
            let v = (y as f32 + 0.5) / TEXTURE as f32 - 0.5;
            let inside = (u / 0.28).powi(2) + (v / 0.45).powi(2) <= 1.0;
            let i = ((y * TEXTURE + x) * 4) as usize;
            base[i..i + 4].copy_from_slice(&[255, 255, 255, if inside { 255 } else { 0 }]);
        }
    }
    levels.push(base);
    let mut size = TEXTURE;
    while mips && size > 1 {
        let prev = levels.last().unwrap();
        let half = size / 2;
        let mut next = vec![0u8; (half * half * 4) as usize];
        for y in 0..half {
            for x in 0..half {
                for c in 0..4 {
                    let at = |dx: u32, dy: u32| {
                        prev[(((2 * y + dy) * size + 2 * x + dx) * 4 + c) as usize] as u32
                    };
                    next[((y * half + x) * 4 + c) as usize] =
                        ((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1) + 2) / 4) as u8;
                }
            }
        }
        levels.push(next);
        size = half;
    }
    let mut image = Image::new_uninit(
        Extent3d {
            width: TEXTURE,
            height: TEXTURE,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::all(),
    );
    image.texture_descriptor.mip_level_count = levels.len() as u32;
    image.data = Some(levels.concat());
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor::linear());
    image
}

/// A harness showing `baked` with white unlit leaves on black, so a pixel's brightness is the
/// fraction of it covered by leaves.
fn scene(size: u32, mips: bool, baked: &BakedFoliage, camera: Transform) -> Option<RenderHarness> {
    let mut harness = RenderHarness::for_test("subpixel_fade", size, size)?;
    harness.app_mut().add_plugins(FoliagePlugin);
    harness.app_mut().insert_resource(FoliagePruningSettings {
        // Every leaf drawn: only the fade is under test.
        enabled: false,
        ..default()
    });
    harness.app_mut().insert_resource(ClearColor(Color::BLACK));
    let texture = leaf_texture(mips);
    let opaque = opaque_fraction(&texture, 0.5).unwrap();
    assert!((opaque - 0.4).abs() < 0.02, "opaque fraction {opaque}");
    let world = harness.world_mut();
    let texture = world.resource_mut::<Assets<Image>>().add(texture);
    let handle = world
        .resource_mut::<Assets<BakedFoliage>>()
        .add(baked.clone());
    let material = world
        .resource_mut::<Assets<LeafMaterial>>()
        .add(leaf_material_textured(
            StandardMaterial {
                base_color_texture: Some(texture),
                alpha_mode: AlphaMode::Mask(0.5),
                unlit: true,
                ..default()
            },
            opaque,
        ));
    world.spawn((
        PrunedFoliage {
            baked: handle,
            material,
        },
        Transform::IDENTITY,
    ));
    world.spawn((Camera3d::default(), Msaa::Off, camera));
    harness.wait_until_ready().unwrap();
    Some(harness)
}

fn render(harness: &mut RenderHarness, fade: bool) -> RgbaImage {
    harness
        .world_mut()
        .resource_mut::<FoliagePruningSettings>()
        .subpixel_fade = fade;
    for _ in 0..8 {
        harness.step();
    }
    harness.render().unwrap()
}

/// Fraction of the image covered by leaves (mean brightness of white-on-black).
fn leaf_coverage(image: &RgbaImage) -> f64 {
    image.mean_luma(0, 0, image.width, image.height)
}

#[test]
fn subpixel_fade_keeps_the_density_that_alpha_mips_lose() {
    let species = TreeSpecies::fraxinus().with_leaf_count(6000);
    let tree = generate(&species);
    let (baked, _) = bake(
        &tree.leaves,
        &BakeSettings {
            cells: CellCount::Depth(6),
            resolution: 64,
            ..default()
        },
        &|_| {},
    )
    .unwrap();
    let crown = baked.crown_center();
    // The crown spans about 60 % of the frame: leaves (0.25 m) are about 2 px across at 128².
    let fov = std::f32::consts::FRAC_PI_4;
    let d = species.crown_radius / 0.6 / (fov / 2.0).tan();
    let camera = Transform::from_translation(crown + Vec3::new(0.8, 0.15, 0.6).normalize() * d)
        .looking_at(crown, Vec3::Y);

    let Some(mut fine) = scene(SIZE * SUPERSAMPLE, false, &baked, camera) else {
        return;
    };
    let reference = render(&mut fine, false).box_downsample(SUPERSAMPLE);
    drop(fine);
    let mut harness = scene(SIZE, true, &baked, camera).unwrap();
    let plain = render(&mut harness, false);
    let faded = render(&mut harness, true);

    let dir = artifacts_dir().join("subpixel_fade");
    for (name, image) in [
        ("reference_4x", &reference),
        ("plain", &plain),
        ("faded", &faded),
    ] {
        image.save_png(dir.join(format!("{name}.png"))).unwrap();
    }
    let (c_ref, c_plain, c_faded) = (
        leaf_coverage(&reference),
        leaf_coverage(&plain),
        leaf_coverage(&faded),
    );
    let (loss_plain, loss_faded) = ((c_ref - c_plain) / c_ref, (c_ref - c_faded) / c_ref);
    let block = |a: &RgbaImage, name: &str| {
        Comparison::new(
            format!("subpixel_fade/{name}_8x8"),
            &a.box_downsample(8),
            &reference.box_downsample(8),
        )
    };
    let (cmp_plain, cmp_faded) = (block(&plain, "plain"), block(&faded, "faded"));
    let line = format!(
        "leaf coverage: reference (4x supersampled) {c_ref:.4}, alpha mips only {c_plain:.4} (loss {:+.1} %, 8x8 rmse {:.4}), faded {c_faded:.4} (loss {:+.1} %, 8x8 rmse {:.4})",
        loss_plain * 100.0,
        cmp_plain.rmse,
        loss_faded * 100.0,
        cmp_faded.rmse
    );
    eprintln!("{line}");
    std::fs::write(dir.join("report.txt"), &line).unwrap();
    assert!(c_ref > 0.03, "the crown should be visible ({c_ref})");
    cmp_plain.assert(
        loss_plain > 0.15,
        "without the fade, the alpha mips should visibly thin the crown",
    );
    cmp_faded.assert(
        loss_faded.abs() < 0.5 * loss_plain,
        &format!("faded coverage loss {loss_faded:.3} should be well under {loss_plain:.3}"),
    );
    cmp_faded.assert(
        cmp_faded.rmse < cmp_plain.rmse,
        "at 8x8 blocks the faded crown should be closer to the reference",
    );
}
