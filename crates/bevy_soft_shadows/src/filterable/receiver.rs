//! The main-world side of filterable shadow maps: the map itself as an `Image` (so materials can
//! bind it), the small buffer that tells receivers which light and method it is for, and the
//! camera it is made for. The receiving material is the suite's
//! [`SoftShadowMaterial`](crate::SoftShadowMaterial), which reads SSSS where SSSS is on and the
//! filtered map elsewhere.

use super::filter::FilterableMethod;
use super::settings::FilteredShadowMap;
use bevy::asset::RenderAssetUsages;
use bevy::diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy::light::{CascadeShadowConfig, DirectionalLightShadowMap};
use bevy::pbr::MAX_CASCADES_PER_LIGHT;
use bevy::prelude::*;
use bevy::render::extract_component::{ExtractComponent, ExtractComponentPlugin};
use bevy::render::render_resource::{
    Extent3d, TextureDimension, TextureFormat, TextureUsages, TextureViewDescriptor,
    TextureViewDimension,
};
use bevy::render::storage::ShaderBuffer;

/// Marks the camera whose view the filterable shadow map is made for (added automatically to the
/// scene's camera — the active 3D camera of the lowest order — while a light has a
/// [`FilteredShadowMap`]): the map follows that view's cascades.
#[derive(Component, Clone, Copy, Default, Debug, ExtractComponent)]
pub struct FilteredShadowCamera;

/// The maps and the receivers' buffer, shared by every receiving material.
#[derive(Resource, Clone, Debug, Default)]
pub struct FilteredShadowImages {
    /// The directional light's filterable shadow map: a 2D array, one layer per cascade of the
    /// light, with mips, in the method's texel format (a 1 × 1 placeholder while no directional
    /// light asks for one).
    pub moments: Handle<Image>,
    /// The spot light's filterable shadow map: one layer, with mips (a 1 × 1 placeholder while
    /// no spot light asks for one).
    pub spot_moments: Handle<Image>,
    /// `FilteredReceiver` of `filtered_receiver.wgsl`, written by the render world each frame:
    /// for the directional light, its index among the view's directional lights (`0xffffffff`
    /// while no map is made), the method, the mip count and the methods' constants; the same for
    /// the spot light, with its index among Bevy's clustered lights and its range.
    pub receiver: Handle<ShaderBuffer>,
    /// The directional map's size (texels across and down, cascades) and format, while a light
    /// asks for one.
    pub layout: Option<(UVec3, TextureFormat)>,
    /// The spot map's size and format, while a spot light asks for one.
    pub spot_layout: Option<(UVec3, TextureFormat)>,
}

/// The texel format holding `method`'s statistics: as few channels as they need — one for ESM,
/// two for VSM and the Gaussian CDF, four for the power CDF's mean and range and for four
/// moments.
pub fn texel_format(method: FilterableMethod) -> TextureFormat {
    match method {
        FilterableMethod::Exponential { .. } => TextureFormat::R32Float,
        FilterableMethod::GaussianCdf | FilterableMethod::Variance => TextureFormat::Rg32Float,
        FilterableMethod::PowerCdf | FilterableMethod::Moments4 => TextureFormat::Rgba32Float,
    }
}

/// The receivers' buffer while no map is made: no directional and no spot light
/// (`0xffffffff`).
pub(crate) fn inactive_receiver_bytes() -> Vec<u8> {
    let mut bytes = vec![0u8; 64];
    bytes[..4].copy_from_slice(&u32::MAX.to_le_bytes());
    bytes[32..36].copy_from_slice(&u32::MAX.to_le_bytes());
    bytes
}

/// The map's texture: `size.z` layers of `size.xy` texels with a full mip chain, written by the
/// passes (storage), read by the receivers, copyable for tests.
pub fn moment_image(size: UVec3, format: TextureFormat) -> Image {
    let mut image = Image::new_uninit(
        Extent3d {
            width: size.x.max(1),
            height: size.y.max(1),
            depth_or_array_layers: size.z.max(1),
        },
        TextureDimension::D2,
        format,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.mip_level_count = size.x.max(size.y).max(1).ilog2() + 1;
    image.texture_descriptor.usage =
        TextureUsages::TEXTURE_BINDING | TextureUsages::STORAGE_BINDING | TextureUsages::COPY_SRC;
    // One layer would otherwise default to a 2D view; the receivers bind an array.
    image.texture_view_descriptor = Some(TextureViewDescriptor {
        dimension: Some(TextureViewDimension::D2Array),
        ..default()
    });
    image
}

/// Whether any shadow-casting light has a [`FilteredShadowMap`] (and so receivers are
/// converted).
#[derive(Resource, Clone, Copy, Default, Debug, PartialEq, Eq)]
pub struct FilteredShadowActive(pub bool);

/// The system set that sizes the map and marks the camera (in `PostUpdate`; the receivers are
/// converted after it).
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FilteredShadowSystems;

/// Makes `handle` a map of `layout` (a placeholder for `None`), replacing the image in place so
/// that the receiving materials keep their handle; `current` is the layout it has.
fn size_map(
    images: &mut Assets<Image>,
    handle: &mut Handle<Image>,
    current: &mut Option<(UVec3, TextureFormat)>,
    layout: Option<(UVec3, TextureFormat)>,
) {
    if *handle == Handle::default() || !images.contains(handle.id()) {
        *handle = images.add(moment_image(UVec3::ONE, TextureFormat::R32Float));
        *current = None;
    }
    if *current == layout {
        return;
    }
    *current = layout;
    // No light: the map keeps its texture until one asks again (receivers are told "no map").
    if let (Some((size, format)), Some(mut existing)) = (layout, images.get_mut(handle.id())) {
        *existing = moment_image(size, format);
    }
}

/// Sizes the maps to the first filtered directional light's cascades and the first filtered
/// spot light, at Bevy's directional shadow-map size (spot lights' maps share Bevy's directional
/// shadow texture), and marks the scene's camera.
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn prepare_camera_and_map(
    mut commands: Commands,
    lights: Query<(&DirectionalLight, &FilteredShadowMap, &CascadeShadowConfig)>,
    spots: Query<(&SpotLight, &FilteredShadowMap)>,
    cameras: Query<(Entity, &Camera, Has<FilteredShadowCamera>), With<Camera3d>>,
    shadow_map: Res<DirectionalLightShadowMap>,
    mut maps: ResMut<FilteredShadowImages>,
    mut images: ResMut<Assets<Image>>,
    mut buffers: ResMut<Assets<ShaderBuffer>>,
    mut active: ResMut<FilteredShadowActive>,
) {
    if maps.receiver == Handle::default() || !buffers.contains(maps.receiver.id()) {
        maps.receiver = buffers.add(ShaderBuffer::new(
            &inactive_receiver_bytes(),
            RenderAssetUsages::RENDER_WORLD,
        ));
    }
    let light = lights.iter().find(|(light, ..)| light.shadow_maps_enabled);
    let spot = spots.iter().find(|(spot, _)| spot.shadow_maps_enabled);
    active.set_if_neq(FilteredShadowActive(light.is_some() || spot.is_some()));
    let side = shadow_map.size.max(1) as u32;
    let layout = light.map(|(_, settings, cascades)| {
        let layers = cascades.bounds.len().clamp(1, MAX_CASCADES_PER_LIGHT) as u32;
        let method = settings.sanitized().0.method;
        (UVec3::new(side, side, layers), texel_format(method))
    });
    let spot_layout = spot.map(|(_, settings)| {
        let method = settings.sanitized().0.method;
        (UVec3::new(side, side, 1), texel_format(method))
    });
    let maps = &mut *maps;
    size_map(&mut images, &mut maps.moments, &mut maps.layout, layout);
    size_map(
        &mut images,
        &mut maps.spot_moments,
        &mut maps.spot_layout,
        spot_layout,
    );
    if light.is_none() && spot.is_none() {
        for (entity, _, marked) in &cameras {
            if marked {
                commands.entity(entity).remove::<FilteredShadowCamera>();
            }
        }
        return;
    }
    // The scene's camera, as for SSSS: the active 3D camera of the lowest order.
    if let Some((entity, _, marked)) = cameras
        .iter()
        .filter(|(_, c, _)| c.is_active)
        .min_by_key(|(_, c, _)| c.order)
        && !marked
    {
        commands.entity(entity).insert(FilteredShadowCamera);
    }
}

/// Diagnostic: how many filterable shadow maps are made (0, 1 or 2: a directional light's and a
/// spot light's).
pub const FILTERED_MAPS: DiagnosticPath = DiagnosticPath::const_new("filtered_shadow/maps");
/// Diagnostic: the GPU memory the filterable shadow maps take, in MiB (for each map its
/// resolved texels, the blur's scratch and the mip-mapped map).
pub const FILTERED_MAP_MIB: DiagnosticPath =
    DiagnosticPath::const_new("filtered_shadow/memory_mib");

/// The bytes one map of `layout` takes on the GPU: two single-level textures (the resolved
/// texels and the blur's scratch) and the map with its full mip chain.
pub fn map_bytes(layout: (UVec3, TextureFormat)) -> u64 {
    let (size, format) = layout;
    let texel = format.block_copy_size(None).unwrap_or(16) as u64;
    let level0 = size.x as u64 * size.y as u64 * size.z as u64 * texel;
    let mut mips = 0u64;
    let (mut w, mut h) = (size.x.max(1) as u64, size.y.max(1) as u64);
    loop {
        mips += w * h * size.z as u64 * texel;
        if w == 1 && h == 1 {
            break;
        }
        w = w.div_ceil(2);
        h = h.div_ceil(2);
    }
    2 * level0 + mips
}

fn measure_maps(maps: Res<FilteredShadowImages>, mut diagnostics: Diagnostics) {
    let made = [maps.layout, maps.spot_layout];
    diagnostics.add_measurement(&FILTERED_MAPS, || {
        made.iter().filter(|l| l.is_some()).count() as f64
    });
    diagnostics.add_measurement(&FILTERED_MAP_MIB, || {
        made.iter().flatten().map(|&l| map_bytes(l)).sum::<u64>() as f64 / (1u64 << 20) as f64
    });
}

/// Registers the main-world side.
pub(crate) fn build(app: &mut App) {
    app.add_plugins(ExtractComponentPlugin::<FilteredShadowCamera>::default())
        .init_resource::<FilteredShadowImages>()
        .init_resource::<FilteredShadowActive>()
        .register_diagnostic(Diagnostic::new(FILTERED_MAPS))
        .register_diagnostic(Diagnostic::new(FILTERED_MAP_MIB))
        .add_systems(
            PostUpdate,
            (prepare_camera_and_map, measure_maps)
                .chain()
                .in_set(FilteredShadowSystems),
        );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The settings' documented memory: four 2048² cascades of a two-channel method take about
    /// 0.45 GB, a four-channel one twice that.
    #[test]
    fn map_memory_counts_three_textures_and_the_mips() {
        let two = map_bytes((UVec3::new(2048, 2048, 4), TextureFormat::Rg32Float));
        let level0 = 2048u64 * 2048 * 4 * 8;
        // Two single-level textures and a chain of 1 + 1/4 + 1/16 + … ≈ 4/3 levels.
        assert!(two > level0 * 3 && two < level0 * 10 / 3 + 4096, "{two}");
        assert!((two as f64 / 1e9 - 0.45).abs() < 0.01, "{two}");
        let four = map_bytes((UVec3::new(2048, 2048, 4), TextureFormat::Rgba32Float));
        assert_eq!(four, 2 * two);
        // A 1 × 1 map: three texels.
        assert_eq!(map_bytes((UVec3::ONE, TextureFormat::R32Float)), 12);
    }
}
