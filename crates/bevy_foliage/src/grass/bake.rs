//! The GPU bake of a species' volume slices (Boulanger 2008, thesis §4.3.2): the base patch's
//! blade mesh seen by one orthographic camera per slice, side and layer
//! ([`super::slices::SliceLayout::project`]), each writing its image into one tile of an
//! `Rgba16Float` atlas — slices across, layers down — through `slice_bake.wgsl`, read back, and
//! cached in a `*.grassslices` file. [`super::slices::bake_reference`] is the CPU reference of
//! what this renders.
//!
//! Spawn a [`GrassSliceBakeRequest`]; a few frames later the entity gets a
//! [`GrassSliceBakeResult`]. The cameras and meshes live on render layers of their own
//! ([`SLICE_BAKE_LAYER_BASE`] and up). A bake is accepted as `gpu_bake.rs` decides:
//! every part marked changed once it has drawn, then two alike readbacks with pipelines idle for
//! long enough.

use super::field::GrassSpecies;
use super::mesh::patch_mesh;
use super::patch::BasePatch;
use super::slice_format::{FORMAT_VERSION, SliceBake, load, save};
use super::slices::{LAYER_THRESHOLD, LAYER_UNLIT, LAYERS, SliceLayout, SliceTextures, lit_layer};
use crate::gpu_bake::{BakePipelinesIdle, ReadbackSettling, track_pipelines_idle, unpad_rows};
use crate::pruning::format::fnv1a64;
use bevy::asset::{RenderAssetUsages, embedded_asset};
use bevy::camera::Hdr;
use bevy::camera::visibility::{NoFrustumCulling, RenderLayers};
use bevy::camera::{CameraOutputMode, ClearColorConfig, RenderTarget, ScalingMode, Viewport};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::light::NotShadowCaster;
use bevy::pbr::{MaterialPipeline, MaterialPipelineKey, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::gpu_readback::{Readback, ReadbackComplete};
use bevy::render::render_resource::{
    AsBindGroup, Extent3d, RenderPipelineDescriptor, ShaderType, SpecializedMeshPipelineError,
    TextureDimension, TextureFormat, TextureUsages,
};
use bevy::shader::ShaderRef;
use half::f16;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The first render layer the slice bake uses (one per camera above it).
pub const SLICE_BAKE_LAYER_BASE: usize = 1 << 13;

/// Asks for a species' slices to be baked on the GPU. With `save_to`, a file there baked from
/// the same species and layout (same hash) is loaded instead, and a new bake is written there.
#[derive(Component, Clone, Debug)]
pub struct GrassSliceBakeRequest {
    /// Names the species in messages.
    pub label: String,
    /// What to bake.
    pub species: GrassSpecies,
    /// Vertical slices per axis (1..=32).
    pub per_axis: u32,
    /// Texels a side of each slice image (8..=1024).
    pub resolution: u32,
    /// Where to cache the bake.
    pub save_to: Option<PathBuf>,
}

/// The outcome of a [`GrassSliceBakeRequest`].
#[derive(Component, Clone, Debug)]
pub struct GrassSliceBakeResult(pub Result<Arc<SliceBake>, String>);

/// Marks the bake's cameras, and holds where each must stand: a game's camera controller that
/// moves every `Camera3d` would otherwise move them too, and the bake would never settle; the
/// pose is put back before transforms propagate.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct GrassSliceBakeCamera(pub Transform);

/// Puts the bake cameras back where the bake placed them.
fn hold_bake_cameras(
    mut cameras: Query<(&mut Transform, &GrassSliceBakeCamera), Changed<Transform>>,
) {
    for (mut transform, pose) in &mut cameras {
        if *transform != pose.0 {
            *transform = pose.0;
        }
    }
}

/// The bake's unlit material: one layer's value of the blades (see `slice_bake.wgsl`).
#[derive(Asset, TypePath, AsBindGroup, Clone, Debug)]
pub struct SliceBakeMaterial {
    /// What to write.
    #[uniform(0)]
    pub params: SliceBakeParams,
}

/// Uniforms of [`SliceBakeMaterial`].
#[derive(Clone, Copy, Debug, ShaderType)]
pub struct SliceBakeParams {
    /// xyz: unit direction to the camera; w: the layer.
    pub view: Vec4,
    /// rgb: root colour; w: ambient occlusion at the root.
    pub root_color: Vec4,
    /// rgb: tip colour; w: transmission γ.
    pub tip_color: Vec4,
}

const SLICE_BAKE_SHADER: &str = "embedded://bevy_foliage/grass/slice_bake.wgsl";

impl Material for SliceBakeMaterial {
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Path(SLICE_BAKE_SHADER.into())
    }
    fn enable_prepass() -> bool {
        false
    }
    fn enable_shadows() -> bool {
        false
    }
    fn specialize(
        _pipeline: &MaterialPipeline,
        descriptor: &mut RenderPipelineDescriptor,
        _layout: &bevy::mesh::MeshVertexBufferLayoutRef,
        _key: MaterialPipelineKey<Self>,
    ) -> Result<(), SpecializedMeshPipelineError> {
        // Blades are two-sided.
        descriptor.primitive.cull_mode = None;
        Ok(())
    }
}

/// A bake in flight.
#[derive(Component)]
struct SliceBakeJob {
    layout: SliceLayout,
    target: Handle<Image>,
    started: Instant,
    settling: ReadbackSettling,
    hash: u64,
    latest: Arc<Mutex<Option<Vec<u8>>>>,
    parts: Vec<Entity>,
}

/// Registers the bake.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "slice_bake.wgsl");
    track_pipelines_idle(app);
    app.add_plugins(MaterialPlugin::<SliceBakeMaterial>::default())
        .add_systems(Update, (start_slice_bakes, finish_slice_bakes).chain())
        .add_systems(
            PostUpdate,
            hold_bake_cameras.before(bevy::transform::TransformSystems::Propagate),
        );
}

/// The hash a cached bake of `species` at this layout must carry.
pub fn source_hash(species: &GrassSpecies, per_axis: u32, resolution: u32) -> u64 {
    fnv1a64(format!("{FORMAT_VERSION} {species:?} {per_axis} {resolution}").as_bytes())
}

/// The layers each side of slice `s` writes.
fn side_layers(layout: &SliceLayout, s: u32, back: bool) -> Vec<u32> {
    if back {
        if layout.has_back(s) {
            (0..5).map(|d| lit_layer(d, true)).collect()
        } else {
            Vec::new()
        }
    } else {
        [LAYER_UNLIT, LAYER_THRESHOLD]
            .into_iter()
            .chain((0..5).map(|d| lit_layer(d, false)))
            .collect()
    }
}

/// The camera of slice `s`'s side: where it stands, where it looks, its up, the ortho extent.
fn slice_camera(layout: &SliceLayout, s: u32, back: bool) -> (Transform, Vec2, f32) {
    use super::slices::SliceAxis;
    let (axis, k) = layout.slice(s);
    let (size, height) = (layout.size, layout.height);
    let (lo, hi) = layout.slab(k);
    let mid = size / 2.0;
    let (eye, forward, up) = match (axis, back) {
        (SliceAxis::X, false) => (Vec3::new(hi, height / 2.0, mid), Vec3::NEG_X, Vec3::Y),
        (SliceAxis::X, true) => (Vec3::new(lo, height / 2.0, mid), Vec3::X, Vec3::Y),
        (SliceAxis::Z, false) => (Vec3::new(mid, height / 2.0, hi), Vec3::NEG_Z, Vec3::Y),
        (SliceAxis::Z, true) => (Vec3::new(mid, height / 2.0, lo), Vec3::Z, Vec3::Y),
        (SliceAxis::Horizontal, _) => (Vec3::new(mid, height, mid), Vec3::NEG_Y, Vec3::NEG_Z),
    };
    let extent = match axis {
        SliceAxis::Horizontal => Vec2::splat(size),
        _ => Vec2::new(size, height),
    };
    (
        Transform::from_translation(eye).looking_to(forward, up),
        extent,
        layout.depth_range(s),
    )
}

#[allow(clippy::too_many_arguments)]
fn start_slice_bakes(
    mut commands: Commands,
    requests: Query<(Entity, &GrassSliceBakeRequest), Added<GrassSliceBakeRequest>>,
    mut images: ResMut<Assets<Image>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<SliceBakeMaterial>>,
) {
    for (entity, request) in &requests {
        let (species, fixes) = request.species.sanitized();
        for fix in fixes {
            warn!("grass slice bake of {}: {fix}", request.label);
        }
        let per_axis = request.per_axis.clamp(1, super::slice_format::MAX_PER_AXIS);
        let resolution = request
            .resolution
            .clamp(8, super::slice_format::MAX_RESOLUTION);
        if (per_axis, resolution) != (request.per_axis, request.resolution) {
            warn!(
                "grass slice bake of {}: {} slices per axis of {}² texels out of range: using \
                 {per_axis} of {resolution}²",
                request.label, request.per_axis, request.resolution
            );
        }
        let started = Instant::now();
        let hash = source_hash(&species, per_axis, resolution);
        if let Some(path) = &request.save_to
            && path.exists()
        {
            match load(path) {
                Ok(bake) if bake.source_hash == hash => {
                    info!(
                        "grass slices of {} loaded from {} ({:.1} MiB)",
                        request.label,
                        path.display(),
                        std::fs::metadata(path).map_or(0, |m| m.len()) as f64 / (1 << 20) as f64
                    );
                    commands
                        .entity(entity)
                        .insert(GrassSliceBakeResult(Ok(Arc::new(bake))));
                    continue;
                }
                Ok(_) => info!("{}: stale grass slice cache, re-baking", path.display()),
                Err(e) => warn!("{}: {e}; re-baking", path.display()),
            }
        }
        let patch = BasePatch::generate(&species.patch);
        let layout = SliceLayout::new(&patch, per_axis, resolution);
        let (width, height) = (layout.slices() * resolution, LAYERS * resolution);
        let mut image = Image::new_fill(
            Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            TextureDimension::D2,
            &[0; 8],
            TextureFormat::Rgba16Float,
            RenderAssetUsages::RENDER_WORLD,
        );
        image.texture_descriptor.usage = TextureUsages::RENDER_ATTACHMENT
            | TextureUsages::COPY_SRC
            | TextureUsages::TEXTURE_BINDING;
        let target = images.add(image);
        let mesh = meshes.add(patch_mesh(
            &patch,
            species.patch.width,
            species.patch.segments,
        ));
        let c = |c: LinearRgba| Vec3::new(c.red, c.green, c.blue);
        let mut parts = Vec::new();
        let mut index = 0usize;
        for s in 0..layout.slices() {
            for back in [false, true] {
                let (transform, extent, depth) = slice_camera(&layout, s, back);
                let view = layout.view_direction(s, back);
                for layer in side_layers(&layout, s, back) {
                    let render_layer = SLICE_BAKE_LAYER_BASE + index;
                    let first = index == 0;
                    let material = materials.add(SliceBakeMaterial {
                        params: SliceBakeParams {
                            view: view.extend(layer as f32),
                            root_color: c(species.root_color).extend(species.root_ao),
                            tip_color: c(species.tip_color).extend(species.transmission),
                        },
                    });
                    parts.push(
                        commands
                            .spawn((
                                Name::new(format!("grass slice bake {}", request.label)),
                                Mesh3d(mesh.clone()),
                                MeshMaterial3d(material),
                                Transform::IDENTITY,
                                RenderLayers::none().with(render_layer),
                                NotShadowCaster,
                                NoFrustumCulling,
                            ))
                            .id(),
                    );
                    let clear = if first {
                        ClearColorConfig::Custom(Color::NONE)
                    } else {
                        ClearColorConfig::None
                    };
                    parts.push(
                        commands
                            .spawn((
                                Name::new(format!("grass slice bake camera {}", request.label)),
                                Camera3d::default(),
                                Camera {
                                    order: (1 << 21) + index as isize,
                                    viewport: Some(Viewport {
                                        physical_position: UVec2::new(
                                            s * resolution,
                                            layer * resolution,
                                        ),
                                        physical_size: UVec2::splat(resolution),
                                        depth: 0.0..1.0,
                                    }),
                                    clear_color: clear,
                                    output_mode: CameraOutputMode::Write {
                                        blend_state: None,
                                        clear_color: clear,
                                    },
                                    ..default()
                                },
                                RenderTarget::Image(target.clone().into()),
                                Projection::Orthographic(OrthographicProjection {
                                    near: 0.0,
                                    far: depth,
                                    scaling_mode: ScalingMode::Fixed {
                                        width: extent.x,
                                        height: extent.y,
                                    },
                                    ..OrthographicProjection::default_3d()
                                }),
                                transform,
                                GrassSliceBakeCamera(transform),
                                Hdr,
                                Tonemapping::None,
                                DebandDither::Disabled,
                                Msaa::Off,
                                RenderLayers::none().with(render_layer),
                            ))
                            .id(),
                    );
                    index += 1;
                }
            }
        }
        let latest: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();
        let sink = latest.clone();
        commands
            .entity(entity)
            .insert((
                SliceBakeJob {
                    layout,
                    target: target.clone(),
                    started,
                    settling: ReadbackSettling::default(),
                    hash,
                    latest,
                    parts,
                },
                Readback::texture(target),
            ))
            .observe(move |done: On<ReadbackComplete>| {
                *sink.lock().unwrap() = Some(done.data.clone());
            });
    }
}

/// The atlas (slices across, layers down, `Rgba16Float`) as slice textures.
fn textures_from_atlas(layout: SliceLayout, pixels: &[u8]) -> SliceTextures {
    let res = layout.resolution;
    let width = (layout.slices() * res) as usize;
    let mut textures = SliceTextures::empty(layout);
    for s in 0..layout.slices() {
        for layer in 0..LAYERS {
            for r in 0..res {
                for c in 0..res {
                    let (x, y) = ((s * res + c) as usize, (layer * res + r) as usize);
                    let at = (y * width + x) * 8;
                    let h = |k: usize| {
                        f16::from_le_bytes([pixels[at + 2 * k], pixels[at + 2 * k + 1]]).to_f32()
                    };
                    textures.texels[layout.index(s, layer, c, r)] = [h(0), h(1), h(2), h(3)];
                }
            }
        }
    }
    textures
}

fn finish_slice_bakes(
    mut commands: Commands,
    mut jobs: Query<(Entity, &GrassSliceBakeRequest, &mut SliceBakeJob)>,
    idle: Res<BakePipelinesIdle>,
    mut images: ResMut<Assets<Image>>,
    mut part_meshes: Query<&mut Mesh3d>,
) {
    for (entity, request, mut job) in &mut jobs {
        let (width, height) = (
            job.layout.slices() * job.layout.resolution,
            LAYERS * job.layout.resolution,
        );
        let latest = job.latest.lock().unwrap().take();
        let pixels = latest.and_then(|padded| unpad_rows(&padded, width, height, 8));
        // Any texel with coverage: half-float alpha 1.0 is 0x3C00.
        let job = &mut *job;
        let has_content = |p: &[u8]| p.chunks_exact(8).any(|p| p[6] != 0 || p[7] != 0);
        let outcome = job.settling.advance(
            idle.get(),
            pixels,
            has_content,
            &job.parts,
            &mut part_meshes,
        );
        let pixels = match outcome {
            None => continue,
            Some(Ok(pixels)) => pixels,
            Some(Err(why)) => {
                warn!("grass slice bake of {} failed: {why}", request.label);
                finish(&mut commands, entity, job, &mut images, Err(why));
                continue;
            }
        };
        let bake = SliceBake {
            textures: textures_from_atlas(job.layout, &pixels),
            source_hash: job.hash,
            bake_ms: job.started.elapsed().as_secs_f32() * 1e3,
        };
        let bytes = bake.textures.texels.len() * 8;
        if let Some(path) = &request.save_to
            && let Err(e) = save(&bake, path)
        {
            warn!("grass slice bake of {}: could not save: {e}", request.label);
        }
        info!(
            "baked the grass slices of {}: {} slices × {LAYERS} layers of {}², {:.0} ms, {:.2} MiB",
            request.label,
            job.layout.slices(),
            job.layout.resolution,
            bake.bake_ms,
            bytes as f64 / (1 << 20) as f64
        );
        finish(&mut commands, entity, job, &mut images, Ok(Arc::new(bake)));
    }
}

fn finish(
    commands: &mut Commands,
    entity: Entity,
    job: &SliceBakeJob,
    images: &mut Assets<Image>,
    result: Result<Arc<SliceBake>, String>,
) {
    for &part in &job.parts {
        commands.entity(part).despawn();
    }
    images.remove(&job.target);
    commands
        .entity(entity)
        .remove::<(SliceBakeJob, Readback)>()
        .insert(GrassSliceBakeResult(result));
}
