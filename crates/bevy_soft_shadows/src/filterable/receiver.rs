//! The main-world side of filterable shadow maps: the map itself as an `Image` (so materials can
//! bind it), the small buffer that tells receivers which light and method it is for, and the
//! camera it is made for. The receiving material is the suite's
//! [`SoftShadowMaterial`](crate::SoftShadowMaterial), which reads SSSS where SSSS is on and the
//! filtered map elsewhere.

use super::filter::FilterableMethod;
use super::settings::FilteredShadowMap;
use bevy::asset::RenderAssetUsages;
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

/// The map and the receivers' buffer, shared by every receiving material.
#[derive(Resource, Clone, Debug, Default)]
pub struct FilteredShadowImages {
    /// The filterable shadow map: a 2D array, one layer per cascade of the light, with mips, in
    /// the method's texel format (a 1 × 1 placeholder while no light asks for one).
    pub moments: Handle<Image>,
    /// `FilteredReceiver` of `filtered_receiver.wgsl`, written by the render world each frame:
    /// the light's index among the view's directional lights (`0xffffffff` while no map is
    /// made), the method, the mip count and the methods' constants.
    pub receiver: Handle<ShaderBuffer>,
    /// The map's size (texels across and down, cascades) and format, while a light asks for one.
    pub layout: Option<(UVec3, TextureFormat)>,
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

/// The receivers' buffer while no map is made: no light (`0xffffffff`).
pub(crate) fn inactive_receiver_bytes() -> Vec<u8> {
    let mut bytes = vec![0u8; 32];
    bytes[..4].copy_from_slice(&u32::MAX.to_le_bytes());
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

/// Whether any light has a [`FilteredShadowMap`] (and so receivers are converted).
#[derive(Resource, Clone, Copy, Default, Debug, PartialEq, Eq)]
pub struct FilteredShadowActive(pub bool);

/// The system set that sizes the map and marks the camera (in `PostUpdate`; the receivers are
/// converted after it).
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FilteredShadowSystems;

/// Sizes the map to the first filtered light's cascades and Bevy's directional shadow-map size,
/// and marks the scene's camera.
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn prepare_camera_and_map(
    mut commands: Commands,
    lights: Query<(&DirectionalLight, &FilteredShadowMap, &CascadeShadowConfig)>,
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
    if maps.moments == Handle::default() || !images.contains(maps.moments.id()) {
        maps.moments = images.add(moment_image(UVec3::ONE, TextureFormat::R32Float));
    }
    let light = lights.iter().find(|(light, ..)| light.shadow_maps_enabled);
    active.set_if_neq(FilteredShadowActive(light.is_some()));
    let Some((_, settings, cascades)) = light else {
        for (entity, _, marked) in &cameras {
            if marked {
                commands.entity(entity).remove::<FilteredShadowCamera>();
            }
        }
        maps.layout = None;
        return;
    };
    // The scene's camera, as for SSSS: the active 3D camera of the lowest order.
    if let Some((entity, _, marked)) = cameras
        .iter()
        .filter(|(_, c, _)| c.is_active)
        .min_by_key(|(_, c, _)| c.order)
        && !marked
    {
        commands.entity(entity).insert(FilteredShadowCamera);
    }
    let method = settings.sanitized().0.method;
    let layers = cascades.bounds.len().clamp(1, MAX_CASCADES_PER_LIGHT) as u32;
    let side = shadow_map.size.max(1) as u32;
    let layout = (UVec3::new(side, side, layers), texel_format(method));
    if maps.layout == Some(layout) && images.contains(maps.moments.id()) {
        return;
    }
    maps.layout = Some(layout);
    // Replaced in place: the receiving materials keep their handle.
    if let Some(mut existing) = images.get_mut(maps.moments.id()) {
        *existing = moment_image(layout.0, layout.1);
    }
}

/// Registers the main-world side.
pub(crate) fn build(app: &mut App) {
    app.add_plugins(ExtractComponentPlugin::<FilteredShadowCamera>::default())
        .init_resource::<FilteredShadowImages>()
        .init_resource::<FilteredShadowActive>()
        .add_systems(
            PostUpdate,
            prepare_camera_and_map.in_set(FilteredShadowSystems),
        );
}
