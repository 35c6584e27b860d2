//! The main-world side of SSSS: the screen-sized textures the passes write, the material that
//! feeds the soft visibility — or, where SSSS is off, the filterable shadow map's visibility —
//! into Bevy's lighting, and the plugin glue that turns it on for a scene (prepasses on the
//! cameras, receivers on the meshes).

use crate::filterable::receiver::{
    FilteredShadowActive, FilteredShadowImages, FilteredShadowSystems,
};
use crate::foliage::receiver::{TreeOpacityActive, TreeOpacityImages, TreeOpacitySystems};
use crate::settings::ScreenSpaceSoftShadows;
use bevy::asset::{RenderAssetUsages, embedded_asset};
use bevy::core_pipeline::prepass::{DepthPrepass, NormalPrepass};
use bevy::pbr::{ExtendedMaterial, MaterialExtension, MaterialPlugin};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::extract_component::ExtractComponent;
use bevy::render::render_resource::{
    AsBindGroup, Extent3d, TextureDimension, TextureFormat, TextureUsages,
};
use bevy::render::storage::ShaderBuffer;
use bevy::shader::ShaderRef;

/// What the receiving materials read: the soft visibility of the SSSS light, per pixel, and the
/// filterable shadow map with the buffer that says which light it is for. Made by the plugin
/// from [`SsssTextures`] and [`FilteredShadowImages`] (see [`SoftShadowReceiver::new`]).
#[derive(Asset, AsBindGroup, Reflect, Debug, Clone)]
pub struct SoftShadowReceiver {
    /// The SSSS output (Rg32Float, the camera's size): the soft visibility (−1 where SSSS is
    /// inactive) and the light (a spot light's clustered index `i`, a point light's as `−2 − i`,
    /// −1 for a directional light).
    #[texture(100, sample_type = "float", filterable = false)]
    pub visibility: Handle<Image>,
    /// The directional light's filterable shadow map ([`FilteredShadowImages::moments`]; `None`
    /// reads a fallback and must come with a buffer saying no map).
    #[texture(101, dimension = "2d_array", sample_type = "float", filterable = false)]
    pub moments: Option<Handle<Image>>,
    /// Which lights the filterable shadow maps are for ([`FilteredShadowImages::receiver`]).
    #[storage(102, read_only)]
    pub filtered: Handle<ShaderBuffer>,
    /// The spot light's filterable shadow map ([`FilteredShadowImages::spot_moments`]; `None`
    /// as for `moments`).
    #[texture(103, dimension = "2d_array", sample_type = "float", filterable = false)]
    pub spot_moments: Option<Handle<Image>>,
    /// The trees' opacity shadow map ([`TreeOpacityImages::map`]; `None` reads a fallback and
    /// must come with a buffer saying no map), sampled trilinearly.
    #[texture(104)]
    #[sampler(105)]
    pub tree_map: Option<Handle<Image>>,
    /// How to look the trees' map up and for which light ([`TreeOpacityImages::receiver`]).
    #[storage(106, read_only)]
    pub tree: Handle<ShaderBuffer>,
}

impl SoftShadowReceiver {
    /// The receiver of the plugin's SSSS textures, filterable shadow maps and trees' opacity
    /// shadow map.
    pub fn new(
        textures: &SsssTextures,
        maps: &FilteredShadowImages,
        trees: &TreeOpacityImages,
    ) -> Self {
        Self {
            visibility: textures.visibility.clone(),
            moments: Some(maps.moments.clone()),
            filtered: maps.receiver.clone(),
            spot_moments: Some(maps.spot_moments.clone()),
            tree_map: Some(trees.map.clone()),
            tree: trees.receiver.clone(),
        }
    }
}

/// A `StandardMaterial` receiving Screen Space Soft Shadows from the SSSS light, or where SSSS is
/// off, the filterable shadow map of the light with a
/// [`FilteredShadowMap`](crate::filterable::FilteredShadowMap).
pub type SoftShadowMaterial = ExtendedMaterial<StandardMaterial, SoftShadowReceiver>;

const SHADER: &str = "embedded://bevy_soft_shadows/ssss/receiver.wgsl";

impl MaterialExtension for SoftShadowReceiver {
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Path(SHADER.into())
    }
}

/// Marks a camera whose view runs the SSSS passes (added automatically to the scene's camera —
/// the active 3D camera of the lowest order — while a light has [`ScreenSpaceSoftShadows`], with
/// the depth and normal prepasses it needs).
#[derive(Component, Clone, Copy, Default, Debug, ExtractComponent)]
pub struct SoftShadowCamera;

/// Keeps a mesh on its `StandardMaterial` (no soft shadows) when receivers are converted
/// automatically.
#[derive(Component, Clone, Copy, Default, Debug, Reflect)]
#[reflect(Component, Default)]
pub struct NoSoftShadowReceiver;

/// The screen-sized textures of the SSSS passes, sized to the scene camera's target. Readable for tests and debugging views.
#[derive(Resource, Clone, Debug, Default)]
pub struct SsssTextures {
    /// Per pixel (hard shadow, σx, σy, eye depth) — the distance map of §6.2.2 (Rgba32Float),
    /// its σ the upper bound the tile classification runs on (the dilated map's blocker).
    pub distance: Handle<Image>,
    /// The same on the active tiles with the refined blocker's σ, which the blur uses; −1
    /// elsewhere (Rgba32Float).
    pub refined: Handle<Image>,
    /// The hard shadow after the horizontal pass, with the eye depth (Rg32Float).
    pub horizontal: Handle<Image>,
    /// The soft visibility after the vertical pass and the light it is for (Rg32Float), read by
    /// the receivers.
    pub visibility: Handle<Image>,
    /// Their size in pixels.
    pub size: UVec2,
}

fn screen_image(size: UVec2, format: TextureFormat) -> Image {
    let mut image = Image::new_uninit(
        Extent3d {
            width: size.x.max(1),
            height: size.y.max(1),
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        format,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.usage =
        TextureUsages::TEXTURE_BINDING | TextureUsages::RENDER_ATTACHMENT | TextureUsages::COPY_SRC;
    image
}

/// A 1 × 1 visibility texture reading "inactive" (−1).
fn inactive_visibility() -> Image {
    let mut image = screen_image(UVec2::ONE, TextureFormat::Rg32Float);
    image.data = Some([(-1.0f32).to_le_bytes(), (-1.0f32).to_le_bytes()].concat());
    image
}

/// Whether any light has SSSS on.
#[derive(Resource, Clone, Copy, Default, Debug, PartialEq, Eq)]
pub struct SsssActive(pub bool);

/// On the SSSS camera: which prepasses SSSS added to it (and takes away again when no light has
/// SSSS any more, so that switching SSSS off leaves the camera as it was — and costs nothing).
#[derive(Component, Clone, Copy, Debug)]
pub struct SsssAddedPrepasses {
    /// SSSS added `DepthPrepass`.
    pub depth: bool,
    /// SSSS added `NormalPrepass`.
    pub normal: bool,
}

/// Adds the prepasses and the camera marker, and (re)sizes the textures to the camera.
#[allow(clippy::type_complexity)]
fn prepare_cameras_and_textures(
    mut commands: Commands,
    lights: Query<
        (),
        (
            With<ScreenSpaceSoftShadows>,
            Or<(With<DirectionalLight>, With<SpotLight>, With<PointLight>)>,
        ),
    >,
    cameras: Query<
        (
            Entity,
            &Camera,
            Has<SoftShadowCamera>,
            Has<DepthPrepass>,
            Has<NormalPrepass>,
            Option<&SsssAddedPrepasses>,
        ),
        With<Camera3d>,
    >,
    mut textures: ResMut<SsssTextures>,
    mut images: ResMut<Assets<Image>>,
    mut active: ResMut<SsssActive>,
) {
    let any = !lights.is_empty();
    if active.0 != any {
        active.0 = any;
    }
    if !images.contains(textures.visibility.id()) || textures.visibility == Handle::default() {
        // Until SSSS first runs (or while only a filterable shadow map is on), receivers read a
        // 1 × 1 "inactive" texture.
        textures.visibility = images.add(inactive_visibility());
    }
    if !any {
        // SSSS is off: its camera goes back to what it was.
        for (entity, _, marked, _, _, added) in &cameras {
            if !marked {
                continue;
            }
            let mut camera = commands.entity(entity);
            camera.remove::<(SoftShadowCamera, SsssAddedPrepasses)>();
            if let Some(added) = added {
                if added.depth {
                    camera.remove::<DepthPrepass>();
                }
                if added.normal {
                    camera.remove::<NormalPrepass>();
                }
            }
        }
        return;
    }
    let cameras = cameras
        .iter()
        .map(|(entity, camera, marked, depth, normal, _)| {
            (entity, camera, (marked, depth, normal))
        });
    // The scene's camera is the active 3D camera of the lowest order (as for the foliage and the
    // terrain); cameras drawing after it into other targets (offscreen bakes, overlays) are left
    // alone: the passes' screen textures are sized to one camera.
    let Some((entity, camera, (marked, depth, normal))) = cameras
        .filter(|(_, c, _)| c.is_active)
        .min_by_key(|(_, c, _)| c.order)
    else {
        return;
    };
    if !marked {
        info!("Screen Space Soft Shadows: adding depth and normal prepasses to camera {entity}");
        commands.entity(entity).insert((
            SoftShadowCamera,
            DepthPrepass,
            NormalPrepass,
            SsssAddedPrepasses {
                depth: !depth,
                normal: !normal,
            },
        ));
    }
    let Some(size) = camera.physical_target_size() else {
        return;
    };
    if textures.size == size && images.contains(&textures.visibility) {
        return;
    }
    textures.size = size;
    let mut put = |handle: &mut Handle<Image>, format| {
        let image = screen_image(size, format);
        // The default handle names Bevy's default image: never overwrite that one.
        let ours = *handle != Handle::default() && images.contains(handle.id());
        if ours {
            if let Some(mut existing) = images.get_mut(handle.id()) {
                *existing = image;
            }
        } else {
            *handle = images.add(image);
        }
    };
    put(&mut textures.distance, TextureFormat::Rgba32Float);
    put(&mut textures.refined, TextureFormat::Rgba32Float);
    put(&mut textures.horizontal, TextureFormat::Rg32Float);
    put(&mut textures.visibility, TextureFormat::Rg32Float);
}

/// SSSS replaces Bevy's PCSS for its light: the hard shadow it blurs is Bevy's shadow lookup,
/// which PCSS would already have softened. A light with both gets PCSS switched off (warned).
fn switch_off_pcss_under_ssss(
    mut suns: Query<(Entity, &mut DirectionalLight), With<ScreenSpaceSoftShadows>>,
    mut spots: Query<(Entity, &mut SpotLight), With<ScreenSpaceSoftShadows>>,
    mut points: Query<(Entity, &mut PointLight), With<ScreenSpaceSoftShadows>>,
) {
    for (entity, mut light) in &mut suns {
        if light.soft_shadow_size.is_some() {
            warn!(
                "light {entity} has both ScreenSpaceSoftShadows and PCSS (soft_shadow_size): \
                 SSSS replaces PCSS, soft_shadow_size set to None"
            );
            light.soft_shadow_size = None;
        }
    }
    for (entity, mut light) in &mut spots {
        if light.soft_shadows_enabled {
            warn!(
                "spot light {entity} has both ScreenSpaceSoftShadows and PCSS \
                 (soft_shadows_enabled): SSSS replaces PCSS, soft_shadows_enabled set to false"
            );
            light.soft_shadows_enabled = false;
        }
    }
    for (entity, mut light) in &mut points {
        if light.soft_shadows_enabled {
            warn!(
                "point light {entity} has both ScreenSpaceSoftShadows and PCSS \
                 (soft_shadows_enabled): SSSS replaces PCSS, soft_shadows_enabled set to false"
            );
            light.soft_shadows_enabled = false;
        }
    }
}

/// Whether [`SoftShadowsPlugin`](crate::SoftShadowsPlugin) converts meshes' `StandardMaterial`s
/// into [`SoftShadowMaterial`]s while SSSS is on (default: yes; opt a mesh out with
/// [`NoSoftShadowReceiver`]).
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq, Reflect)]
#[reflect(Resource)]
pub struct ConvertStandardMaterials(pub bool);

impl Default for ConvertStandardMaterials {
    fn default() -> Self {
        Self(true)
    }
}

/// Swaps `StandardMaterial`s for [`SoftShadowMaterial`]s sharing their parameters (one receiver
/// material per standard material) while SSSS or a filterable shadow map is on. They stay
/// swapped when both go off: they then read "inactive" and shade as Bevy would. (Swapping back in
/// the frame the camera loses its prepasses leaves Bevy 0.19's prepass phase drawing with the
/// other material's bind group.)
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn convert_receivers(
    mut commands: Commands,
    convert: Res<ConvertStandardMaterials>,
    active: Res<SsssActive>,
    filtered: Res<FilteredShadowActive>,
    trees_active: Res<TreeOpacityActive>,
    textures: Res<SsssTextures>,
    maps: Res<FilteredShadowImages>,
    trees: Res<TreeOpacityImages>,
    meshes: Query<(Entity, &MeshMaterial3d<StandardMaterial>), Without<NoSoftShadowReceiver>>,
    standard: Res<Assets<StandardMaterial>>,
    mut receivers: ResMut<Assets<SoftShadowMaterial>>,
    mut converted: Local<HashMap<AssetId<StandardMaterial>, Handle<SoftShadowMaterial>>>,
    mut bound: Local<BoundTextures>,
) {
    refresh_bind_groups(&mut bound, &textures, &maps, &trees, &mut receivers);
    let ssss_ready = active.0 && textures.size != UVec2::ZERO;
    if !convert.0 || !(ssss_ready || filtered.0 || trees_active.0) {
        return;
    }
    for (entity, material) in &meshes {
        let Some(base) = standard.get(&material.0) else {
            continue;
        };
        let handle = converted
            .entry(material.0.id())
            .or_insert_with(|| {
                receivers.add(SoftShadowMaterial {
                    base: base.clone(),
                    extension: SoftShadowReceiver::new(&textures, &maps, &trees),
                })
            })
            .clone();
        commands
            .entity(entity)
            .remove::<MeshMaterial3d<StandardMaterial>>()
            .insert(MeshMaterial3d(handle));
    }
}

/// A filterable map's layout (`FilteredShadowImages::layout`).
type MapLayout = Option<(UVec3, TextureFormat)>;

/// The textures' layouts the receivers' bind groups were last made with: the SSSS textures'
/// size, the directional and the spot light's filterable maps, the trees' map's side.
#[derive(Default)]
struct BoundTextures {
    layouts: Option<(UVec2, [MapLayout; 2], Option<u32>)>,
    /// A frame after a change the bind groups are made again.
    pending: bool,
}

/// Bevy makes a material's bind group when the material changes, not when an image it binds is
/// replaced: after the SSSS textures are resized or the filterable map changes its layout, every
/// receiver is touched — a frame later, once the render world holds the new textures (Bevy 0.19
/// orders the two preparations in no particular way).
fn refresh_bind_groups(
    bound: &mut BoundTextures,
    textures: &SsssTextures,
    maps: &FilteredShadowImages,
    trees: &TreeOpacityImages,
    receivers: &mut Assets<SoftShadowMaterial>,
) {
    if bound.pending {
        let ids: Vec<_> = receivers.ids().collect();
        for id in ids {
            // A mutable borrow is what marks the material modified.
            if let Some(mut material) = receivers.get_mut(id) {
                let _ = &mut *material;
            }
        }
        bound.pending = false;
    }
    let layouts = Some((
        textures.size,
        [maps.layout, maps.spot_layout],
        trees.resolution,
    ));
    if bound.layouts != layouts {
        bound.pending = bound.layouts.is_some();
        bound.layouts = layouts;
    }
}

/// Registers the main-world side.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "receiver.wgsl");
    app.add_plugins(MaterialPlugin::<SoftShadowMaterial>::default())
        .init_resource::<SsssTextures>()
        .init_resource::<SsssActive>()
        .init_resource::<ConvertStandardMaterials>()
        .register_type::<NoSoftShadowReceiver>()
        .add_systems(
            PostUpdate,
            (
                switch_off_pcss_under_ssss,
                prepare_cameras_and_textures,
                convert_receivers,
            )
                .chain()
                .after(FilteredShadowSystems)
                .after(TreeOpacitySystems),
        );
}
