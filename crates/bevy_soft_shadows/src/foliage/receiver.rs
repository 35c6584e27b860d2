//! The main-world side of the trees' opacity shadow map: where it lies this frame (the plane
//! fitted to the casters' box and the sun), the map as an `Image` the receiving materials bind,
//! and the small buffer that tells them how to look it up.

use super::opacity_map::OpacityShadowPlane;
use super::settings::TreeOpacityShadows;
use bevy::asset::RenderAssetUsages;
use bevy::diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy::image::{ImageAddressMode, ImageFilterMode, ImageSampler, ImageSamplerDescriptor};
use bevy::prelude::*;
use bevy::render::extract_resource::{ExtractResource, ExtractResourcePlugin};
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat, TextureUsages};
use bevy::render::storage::ShaderBuffer;
use bevy::transform::TransformSystems;

/// The map and the receivers' buffer, shared by every receiving material.
#[derive(Resource, Clone, Debug, Default)]
pub struct TreeOpacityImages {
    /// Per texel (height of the highest occluder above the plane, transmittance, 0, 0) with a
    /// mip chain of maximum heights and mean transmittances (`Rgba16Float`; a 1 × 1 placeholder
    /// while no light asks for a map).
    pub map: Handle<Image>,
    /// `TreeOpacityReceiver` of `opacity_receiver.wgsl`, written by the render world each frame.
    pub receiver: Handle<ShaderBuffer>,
    /// The map's side while a light asks for one.
    pub resolution: Option<u32>,
}

/// The light the map is made for this frame and where it lies; `None`: no map (no shadow-casting
/// directional light has [`TreeOpacityShadows`], or its sun is lower than
/// [`MIN_SUN_HEIGHT`](super::opacity_map::MIN_SUN_HEIGHT)).
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, ExtractResource)]
pub struct TreeOpacityFrame(pub Option<TreeOpacityLight>);

/// A light's opacity shadow map for one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeOpacityLight {
    /// The main-world light.
    pub light: Entity,
    /// Where the map lies (eq. 5.27).
    pub plane: OpacityShadowPlane,
    /// The sun's angular diameter (radians).
    pub sun_angle: f32,
}

/// The map's texture: `side`² texels with a full mip chain, written by the passes (storage), read
/// by the receivers through a trilinear sampler, copyable for tests.
pub fn tree_map_image(side: u32) -> Image {
    let side = side.max(1);
    let mut image = Image::new_uninit(
        Extent3d {
            width: side,
            height: side,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        TextureFormat::Rgba16Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.mip_level_count = side.ilog2() + 1;
    image.texture_descriptor.usage =
        TextureUsages::TEXTURE_BINDING | TextureUsages::STORAGE_BINDING | TextureUsages::COPY_SRC;
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::ClampToEdge,
        address_mode_v: ImageAddressMode::ClampToEdge,
        mag_filter: ImageFilterMode::Linear,
        min_filter: ImageFilterMode::Linear,
        mipmap_filter: ImageFilterMode::Linear,
        ..default()
    });
    image
}

/// The GPU bytes of a map of `side`²: the accumulation buffer (two words a texel) and the
/// `Rgba16Float` map with its mips.
pub fn tree_map_bytes(side: u32) -> u64 {
    let texels = side as u64 * side as u64;
    let mut mips = 0;
    let mut s = side.max(1) as u64;
    loop {
        mips += s * s * 8;
        if s == 1 {
            break;
        }
        s /= 2;
    }
    texels * 8 + mips
}

/// Whether a light has a map this frame (and so receivers are converted).
#[derive(Resource, Clone, Copy, Default, Debug, PartialEq, Eq)]
pub struct TreeOpacityActive(pub bool);

/// The system set that fits the map (in `PostUpdate`, after transforms propagate; the receivers
/// are converted after it).
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TreeOpacitySystems;

/// Fits the map of the first shadow-casting directional light with [`TreeOpacityShadows`] to its
/// casters' box and its sun, and sizes the image.
fn fit_tree_map(
    lights: Query<(
        Entity,
        &DirectionalLight,
        &TreeOpacityShadows,
        &GlobalTransform,
    )>,
    mut images_res: ResMut<TreeOpacityImages>,
    mut images: ResMut<Assets<Image>>,
    mut buffers: ResMut<Assets<ShaderBuffer>>,
    mut frame: ResMut<TreeOpacityFrame>,
    mut active: ResMut<TreeOpacityActive>,
    mut warned_low: Local<bool>,
) {
    let maps = &mut *images_res;
    if maps.receiver == Handle::default() || !buffers.contains(maps.receiver.id()) {
        maps.receiver = buffers.add(ShaderBuffer::new(
            &inactive_receiver_bytes(),
            RenderAssetUsages::RENDER_WORLD,
        ));
    }
    if maps.map == Handle::default() || !images.contains(maps.map.id()) {
        maps.map = images.add(tree_map_image(1));
        maps.resolution = None;
    }
    let light = lights
        .iter()
        .find(|(_, light, ..)| light.shadow_maps_enabled);
    let fitted = light.and_then(|(entity, _, settings, transform)| {
        let s = settings.sanitized().0;
        let to_light = transform.back().as_vec3();
        let plane = OpacityShadowPlane::fit(
            s.bounds_min,
            s.bounds_max,
            to_light,
            s.plane_y,
            (s.resolution, s.resolution),
        );
        if plane.is_none() && !*warned_low {
            warn!(
                "TreeOpacityShadows on {entity}: the sun is lower than {:.1}° above the horizon; \
                 the trees' opacity shadow map is off until it rises",
                super::opacity_map::MIN_SUN_HEIGHT.asin().to_degrees()
            );
            *warned_low = true;
        }
        plane.map(|plane| TreeOpacityLight {
            light: entity,
            plane,
            sun_angle: s.sun_angle,
        })
    });
    if fitted.is_some() {
        *warned_low = false;
    }
    frame.set_if_neq(TreeOpacityFrame(fitted));
    active.set_if_neq(TreeOpacityActive(fitted.is_some()));
    let resolution = fitted.map(|f| f.plane.resolution.0);
    // No light: the map keeps its texture until one asks again (receivers are told "no map").
    if let Some(side) = resolution
        && maps.resolution != resolution
        && let Some(mut image) = images.get_mut(maps.map.id())
    {
        *image = tree_map_image(side);
        maps.resolution = resolution;
    }
}

/// The receivers' buffer while no map is made (`light` = `0xffffffff`).
pub(crate) fn inactive_receiver_bytes() -> Vec<u8> {
    let mut bytes = vec![0u8; RECEIVER_BYTES];
    bytes[48..52].copy_from_slice(&u32::MAX.to_le_bytes());
    bytes
}

/// The plane as the WGSL structs start it: the direction to the sun, the plane's height, the
/// map's origin and extent.
pub(crate) fn plane_floats(p: &OpacityShadowPlane) -> [f32; 8] {
    [
        p.to_light.x,
        p.to_light.y,
        p.to_light.z,
        p.plane_y,
        p.origin.x,
        p.origin.y,
        p.extent.x,
        p.extent.y,
    ]
}

/// Size of `TreeOpacityReceiver` in `opacity_receiver.wgsl`.
pub(crate) const RECEIVER_BYTES: usize = 64;

/// The receivers' buffer for `map` of `mips` levels, for Bevy's directional light `light_index`.
pub(crate) fn receiver_bytes(map: &TreeOpacityLight, mips: u32, light_index: u32) -> Vec<u8> {
    let p = &map.plane;
    let tail = [
        p.texel_size().min_element(),
        map.sun_angle,
        mips as f32,
        0.0,
    ];
    let mut bytes: Vec<u8> = plane_floats(p)
        .iter()
        .chain(&tail)
        .flat_map(|f| f.to_le_bytes())
        .collect();
    for word in [light_index, 0, 0, 0] {
        bytes.extend_from_slice(&word.to_le_bytes());
    }
    bytes
}

/// Diagnostic: the GPU memory the trees' opacity shadow map takes, in MiB (0 while off).
pub const TREE_MAP_MIB: DiagnosticPath = DiagnosticPath::const_new("tree_opacity/memory_mib");

fn measure_tree_map(frame: Res<TreeOpacityFrame>, mut diagnostics: Diagnostics) {
    let side = frame.0.map(|f| f.plane.resolution.0);
    diagnostics.add_measurement(&TREE_MAP_MIB, || {
        side.map_or(0.0, |s| tree_map_bytes(s) as f64 / (1u64 << 20) as f64)
    });
}

/// Registers the main-world side.
pub(crate) fn build(app: &mut App) {
    app.add_plugins(ExtractResourcePlugin::<TreeOpacityFrame>::default())
        .init_resource::<TreeOpacityImages>()
        .init_resource::<TreeOpacityFrame>()
        .init_resource::<TreeOpacityActive>()
        .register_diagnostic(Diagnostic::new(TREE_MAP_MIB))
        .add_systems(
            PostUpdate,
            (fit_tree_map, measure_tree_map)
                .chain()
                .in_set(TreeOpacitySystems)
                .after(TransformSystems::Propagate),
        );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_receivers_buffer_matches_the_wgsl_struct() {
        assert_eq!(inactive_receiver_bytes().len(), RECEIVER_BYTES);
        let plane = OpacityShadowPlane::fit(
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(1.0, 2.0, 1.0),
            Vec3::new(0.0, 1.0, 0.0),
            0.0,
            (64, 64),
        )
        .unwrap();
        let map = TreeOpacityLight {
            light: Entity::PLACEHOLDER,
            plane,
            sun_angle: 0.03,
        };
        let bytes = receiver_bytes(&map, 7, 2);
        assert_eq!(bytes.len(), RECEIVER_BYTES);
        let word = |i: usize| f32::from_le_bytes(bytes[i * 4..i * 4 + 4].try_into().unwrap());
        assert_eq!(word(1), 1.0); // to_light.y
        assert_eq!(word(8), 2.0 / 64.0); // texel
        assert_eq!(word(9), 0.03);
        assert_eq!(word(10), 7.0);
        assert_eq!(u32::from_le_bytes(bytes[48..52].try_into().unwrap()), 2);
    }

    #[test]
    fn memory_counts_the_accumulation_and_the_mips() {
        // 4² texels: 16 × 8 accumulation bytes, and 16 + 4 + 1 texels of 8 bytes.
        assert_eq!(tree_map_bytes(4), 16 * 8 + 21 * 8);
    }
}
