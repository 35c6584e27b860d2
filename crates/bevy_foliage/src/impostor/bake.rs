//! The GPU bake of a billboard cloud's textures (seed 001 §4.2): every plane's member triangles
//! rendered by an orthographic camera looking down the plane's normal into the plane's rectangle
//! of one image holding the five atlases in three columns of two — albedo and coverage, then
//! tangent-space normals, then the three light atlases of the tree lighting — read back, and
//! written to a `*.bbcloud` file.
//!
//! Spawn an [`ImpostorBakeRequest`]; a few frames later the entity gets an
//! [`ImpostorBakeResult`]. The bake cameras and meshes live on render layers of their own
//! ([`BAKE_LAYER_BASE`] and up), so no game camera sees them. A bake is accepted as
//! `gpu_bake.rs` decides: every part marked changed once it has drawn, then two alike readbacks
//! with pipelines idle for long enough — an image missing a part is never taken.
//! [`super::texture::bake_reference`] is the CPU reference of what this renders.

use super::atlas::{AtlasLayout, pack};
use super::cloud::{BillboardCloud, CloudSettings, build_cloud};
use super::format::{ImpostorData, load, save};
use super::texture::{
    ImpostorSource, LIGHT_ATLASES, dilate, impostor_planes, min_extent, plane_extent,
    srgb_to_linear,
};
pub use crate::gpu_bake::BakePipelinesIdle;
use crate::gpu_bake::{ReadbackSettling, unpad_rows};
use crate::lighting::traced_bins::BinEstimate;
use bevy::asset::{RenderAssetUsages, embedded_asset};
use bevy::camera::visibility::{NoFrustumCulling, RenderLayers};
use bevy::camera::{CameraOutputMode, ClearColorConfig, RenderTarget, ScalingMode, Viewport};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor};
use bevy::light::NotShadowCaster;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::pbr::{MaterialPipeline, MaterialPipelineKey, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::gpu_readback::{Readback, ReadbackComplete};
use bevy::render::render_resource::{
    AsBindGroup, Extent3d, RenderPipelineDescriptor, ShaderType, SpecializedMeshPipelineError,
    TextureDimension, TextureFormat, TextureUsages,
};
use bevy::shader::ShaderRef;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The first render layer the bake uses (one layer per plane and pass above it).
pub const BAKE_LAYER_BASE: usize = 1 << 12;

/// The largest atlas side a bake takes: the bake renders its five atlases three abreast into one
/// image, which must stay within the 8,192 texels a side every wgpu adapter allows.
pub const MAX_ATLAS_SIZE: u32 = 2688;

/// Settings of a billboard-cloud bake.
#[derive(Clone, Debug, PartialEq, Reflect)]
#[reflect(Debug, PartialEq)]
pub struct ImpostorBakeSettings {
    /// Plane selection.
    #[reflect(ignore)]
    pub cloud: CloudSettings,
    /// Side of each atlas in texels (a multiple of 64, 64..=[`MAX_ATLAS_SIZE`]).
    pub atlas_size: u32,
    /// Gutter between rectangles, in texels.
    pub padding: u32,
    /// How the light atlases' bins are estimated (the tree lighting, §5.6): as the leaves' own
    /// bake does, so that a crown keeps its light when its cloud takes over.
    pub bins: BinEstimate,
}

impl Default for ImpostorBakeSettings {
    fn default() -> Self {
        Self {
            cloud: CloudSettings::default(),
            atlas_size: 512,
            padding: 2,
            bins: BinEstimate::default(),
        }
    }
}

impl ImpostorBakeSettings {
    /// These settings with unusable values replaced, and what was replaced.
    pub fn sanitized(&self) -> (Self, Vec<String>) {
        let (cloud, mut fixes) = self.cloud.sanitized();
        let mut s = Self {
            cloud,
            ..self.clone()
        };
        if !(64..=MAX_ATLAS_SIZE).contains(&s.atlas_size) || !s.atlas_size.is_multiple_of(64) {
            let fixed = (s.atlas_size.clamp(64, MAX_ATLAS_SIZE) / 64) * 64;
            fixes.push(format!(
                "atlas_size = {} must be a multiple of 64 in 64..={MAX_ATLAS_SIZE}: using {fixed}",
                s.atlas_size
            ));
            s.atlas_size = fixed;
        }
        if let Err(why) = s.bins.checked() {
            fixes.push(format!("{why}: using the default"));
            s.bins = BinEstimate::default();
        }
        if s.padding > 16 {
            fixes.push(format!(
                "padding = {} is over 16 texels: using 16",
                s.padding
            ));
            s.padding = 16;
        }
        (s, fixes)
    }

    /// A tag of these settings for the source hash.
    pub fn tag(&self) -> String {
        format!("{:?}", self)
    }
}

/// Asks for a billboard cloud to be baked on the GPU. The entity gets an
/// [`ImpostorBakeResult`] when it is done (or has failed). With `save_to`, a file there baked
/// from the same source and settings (same hash) is loaded instead of baking again, and a new
/// bake is written there.
#[derive(Component, Clone, Debug)]
pub struct ImpostorBakeRequest {
    /// Names the tree in messages (a file path or a species name).
    pub label: String,
    /// The tree.
    pub source: Arc<ImpostorSource>,
    /// How to bake it.
    pub settings: ImpostorBakeSettings,
    /// Where to write the `*.bbcloud` file (none: keep it in memory only).
    pub save_to: Option<PathBuf>,
}

/// The outcome of an [`ImpostorBakeRequest`].
#[derive(Component, Clone, Debug)]
pub struct ImpostorBakeResult(pub Result<Arc<ImpostorData>, String>);

/// The raw atlases as rendered, before dilation (for tests against the CPU reference).
#[derive(Component, Clone, Debug)]
pub struct ImpostorBakeRaw {
    /// The plane selection.
    pub cloud: BillboardCloud,
    /// The atlas layout.
    pub layout: AtlasLayout,
    /// Albedo atlas, RGBA8 sRGB.
    pub albedo: Vec<u8>,
    /// Normal atlas, RGBA8 linear.
    pub normal: Vec<u8>,
    /// The light atlases, as `texture::encode_light` stores them.
    pub light: [Vec<u8>; LIGHT_ATLASES],
}

/// Marks the bake's cameras (so a game's camera controllers can leave them alone).
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct ImpostorBakeCamera;

/// A bake in flight.
#[derive(Component)]
struct BakeJob {
    cloud: BillboardCloud,
    layout: AtlasLayout,
    target: Handle<Image>,
    started: Instant,
    settling: ReadbackSettling,
    hash: u64,
    extinction: f32,
    seen_gains: [f32; 8],
    bounce_ratios: crate::lighting::gathered_bounce::BounceRatios,
    hotspot: crate::lighting::hotspot::Hotspot,
    latest: Arc<Mutex<Option<Vec<u8>>>>,
    parts: Vec<Entity>,
}

/// The bake's unlit material: a surface's colour (albedo pass), its tangent-space normal (normal
/// pass) or its leaf's light values (light passes, from the vertex colours), alpha-tested.
#[derive(Asset, TypePath, AsBindGroup, Clone, Debug)]
pub struct ImpostorBakeMaterial {
    /// Colour, plane frame and pass.
    #[uniform(0)]
    pub params: BakeParams,
    /// Optional colour texture.
    #[texture(1)]
    #[sampler(2)]
    pub texture: Option<Handle<Image>>,
}

/// Uniforms of [`ImpostorBakeMaterial`] (see `impostor_bake.wgsl`).
#[derive(Clone, Copy, Debug, ShaderType)]
pub struct BakeParams {
    /// Linear RGBA base colour.
    pub base_color: Vec4,
    /// The plane's tangent; w: the pass (0 albedo, 1 normal, 2 and up light).
    pub tangent: Vec4,
    /// The plane's bitangent; w: alpha cutoff.
    pub bitangent: Vec4,
    /// The plane's normal; w: 1 if the texture is used.
    pub normal: Vec4,
}

/// The bake's passes: albedo, normals, then the light atlases.
const PASSES: u32 = 2 + LIGHT_ATLASES as u32;

/// Where pass `pass` writes in the bake image (three atlases wide, two high): its atlas's
/// top-left corner.
fn quadrant(pass: u32, size: u32) -> UVec2 {
    UVec2::new((pass >> 1) * size, (pass & 1) * size)
}

const BAKE_SHADER: &str = "embedded://bevy_foliage/impostor/impostor_bake.wgsl";

impl Material for ImpostorBakeMaterial {
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Path(BAKE_SHADER.into())
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
        // Leaves are two-sided.
        descriptor.primitive.cull_mode = None;
        Ok(())
    }
}

/// The bake's systems (in `Update`).
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BakeSystems;

/// Registers the bake.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "impostor_bake.wgsl");
    crate::gpu_bake::track_pipelines_idle(app);
    app.add_plugins(MaterialPlugin::<ImpostorBakeMaterial>::default())
        .add_systems(
            Update,
            (start_impostor_bakes, finish_impostor_bakes).chain(),
        );
}

/// The plane selection and atlas layout of a source, or why there is none.
pub fn plan(
    source: &ImpostorSource,
    settings: &ImpostorBakeSettings,
) -> Result<(BillboardCloud, AtlasLayout), String> {
    if source.triangles.is_empty() {
        return Err("the tree has no triangles to bake".into());
    }
    let cloud =
        build_cloud(&source.cloud_triangles(), &settings.cloud).map_err(|e| e.to_string())?;
    let min = min_extent(&cloud);
    let sizes: Vec<Vec2> = cloud
        .planes
        .iter()
        .map(|p| {
            let (lo, hi) = plane_extent(p, min);
            hi - lo
        })
        .collect();
    let layout =
        pack(&sizes, settings.atlas_size, settings.padding).map_err(|e| format!("{e:?}"))?;
    if layout
        .rects
        .iter()
        .any(|r| r.size[0] == 0 || r.size[1] == 0)
    {
        return Err("a plane got a zero-area atlas rectangle".into());
    }
    Ok((cloud, layout))
}

#[allow(clippy::too_many_arguments)]
fn start_impostor_bakes(
    mut commands: Commands,
    requests: Query<(Entity, &ImpostorBakeRequest), Added<ImpostorBakeRequest>>,
    mut images: ResMut<Assets<Image>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<ImpostorBakeMaterial>>,
) {
    for (entity, request) in &requests {
        let (settings, fixes) = request.settings.sanitized();
        for fix in fixes {
            warn!("impostor bake of {}: {fix}", request.label);
        }
        let started = Instant::now();
        // A cached bake of the same source and settings is taken as it is.
        let hash = request.source.hash(&settings.tag());
        if let Some(path) = &request.save_to
            && path.exists()
        {
            match load(path) {
                Ok(data) if data.source_hash == hash => {
                    commands
                        .entity(entity)
                        .insert(ImpostorBakeResult(Ok(Arc::new(data))));
                    continue;
                }
                Ok(_) => info!("{}: stale billboard cloud cache, re-baking", path.display()),
                Err(e) => warn!("{}: {e}; re-baking", path.display()),
            }
        }
        let (cloud, layout) = match plan(&request.source, &settings) {
            Ok(p) => p,
            Err(e) => {
                warn!(
                    "impostor bake of {} failed: {e}; the tree keeps its pruned geometry",
                    request.label
                );
                commands.entity(entity).insert(ImpostorBakeResult(Err(e)));
                continue;
            }
        };
        let size = layout.size;
        // The tree lighting's envelope of the leaves (§5.6), for the light passes.
        let light = request.source.leaf_light(settings.bins);
        let mut image = Image::new_fill(
            Extent3d {
                width: size * 3,
                height: size * 2,
                depth_or_array_layers: 1,
            },
            TextureDimension::D2,
            &[0, 0, 0, 0],
            TextureFormat::Rgba8UnormSrgb,
            RenderAssetUsages::RENDER_WORLD,
        );
        image.texture_descriptor.usage = TextureUsages::RENDER_ATTACHMENT
            | TextureUsages::COPY_SRC
            | TextureUsages::TEXTURE_BINDING;
        let target = images.add(image);
        // Surface textures, once per surface.
        let textures: Vec<Option<Handle<Image>>> = request
            .source
            .surfaces
            .iter()
            .map(|s| {
                s.texture.as_ref().map(|t| {
                    let mut image = Image::new(
                        Extent3d {
                            width: t.width,
                            height: t.height,
                            depth_or_array_layers: 1,
                        },
                        TextureDimension::D2,
                        t.rgba.clone(),
                        TextureFormat::Rgba8UnormSrgb,
                        RenderAssetUsages::RENDER_WORLD,
                    );
                    // Nearest texel, repeating: what the CPU reference samples.
                    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
                        address_mode_u: ImageAddressMode::Repeat,
                        address_mode_v: ImageAddressMode::Repeat,
                        ..ImageSamplerDescriptor::nearest()
                    });
                    images.add(image)
                })
            })
            .collect();
        let min = min_extent(&cloud);
        let mut parts = Vec::new();
        for (k, (plane, rect)) in cloud.planes.iter().zip(&layout.rects).enumerate() {
            let (lo, hi) = plane_extent(plane, min);
            let epsilon = cloud.epsilon.max(cloud.branch_epsilon) + cloud.radius * 0.01;
            let mid = plane.point((lo + hi) * 0.5);
            let eye = mid + plane.normal * epsilon;
            // Per surface, the plane's member triangles as one mesh.
            let mut by_surface: Vec<Vec<u32>> = vec![Vec::new(); request.source.surfaces.len()];
            for &t in &plane.triangles {
                if let Some(tri) = request.source.triangles.get(t as usize)
                    && let Some(list) = by_surface.get_mut(tri.surface as usize)
                {
                    list.push(t);
                }
            }
            for pass in 0..PASSES {
                let layer = BAKE_LAYER_BASE + PASSES as usize * k + pass as usize;
                for (surface_index, members) in by_surface.iter().enumerate() {
                    if members.is_empty() {
                        continue;
                    }
                    let surface = &request.source.surfaces[surface_index];
                    let (mut positions, mut normals, mut uvs, mut colors) =
                        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
                    for &t in members {
                        let tri = &request.source.triangles[t as usize];
                        // The light passes carry the leaf's light values as vertex colours.
                        let v = light.texel_of_triangle(tri);
                        let first = 3 * pass.saturating_sub(2) as usize;
                        for c in 0..3 {
                            positions.push(tri.positions[c].to_array());
                            normals.push(tri.normals[c].normalize_or(plane.normal).to_array());
                            uvs.push(tri.uvs[c].to_array());
                            colors.push([v[first], v[first + 1], v[first + 2], 1.0]);
                        }
                    }
                    let count = positions.len() as u32;
                    let mut mesh = Mesh::new(
                        PrimitiveTopology::TriangleList,
                        RenderAssetUsages::RENDER_WORLD,
                    )
                    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
                    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
                    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
                    .with_inserted_indices(Indices::U32((0..count).collect()));
                    if pass >= 2 {
                        mesh.insert_attribute(Mesh::ATTRIBUTE_COLOR, colors);
                    }
                    let texture = textures[surface_index].clone();
                    let material = materials.add(ImpostorBakeMaterial {
                        params: BakeParams {
                            base_color: surface.base_color,
                            tangent: plane.tangent.extend(pass as f32),
                            bitangent: plane.bitangent.extend(surface.alpha_cutoff),
                            normal: plane
                                .normal
                                .extend(if texture.is_some() { 1.0 } else { 0.0 }),
                        },
                        texture,
                    });
                    parts.push(
                        commands
                            .spawn((
                                Name::new(format!("impostor bake {} plane {k}", request.label)),
                                Mesh3d(meshes.add(mesh)),
                                MeshMaterial3d(material),
                                Transform::IDENTITY,
                                RenderLayers::none().with(layer),
                                NotShadowCaster,
                                NoFrustumCulling,
                            ))
                            .id(),
                    );
                }
                let first = k == 0 && pass == 0;
                parts.push(
                    commands
                        .spawn((
                            Name::new(format!("impostor bake camera {} plane {k}", request.label)),
                            Camera3d::default(),
                            Camera {
                                // After every game camera, and never the one pruning picks (the lowest order).
                                order: (1 << 20) + (PASSES as isize * k as isize) + pass as isize,
                                viewport: Some(Viewport {
                                    physical_position: UVec2::new(rect.min[0], rect.min[1])
                                        + quadrant(pass, size),
                                    physical_size: UVec2::new(rect.size[0], rect.size[1]),
                                    depth: 0.0..1.0,
                                }),
                                // The first camera clears the whole atlas; the others draw on.
                                clear_color: if first {
                                    ClearColorConfig::Custom(Color::NONE)
                                } else {
                                    ClearColorConfig::None
                                },
                                // The final write clears the target (gutters included) to
                                // transparent too, not to the world's clear colour.
                                output_mode: CameraOutputMode::Write {
                                    blend_state: None,
                                    clear_color: if first {
                                        ClearColorConfig::Custom(Color::NONE)
                                    } else {
                                        ClearColorConfig::None
                                    },
                                },
                                ..default()
                            },
                            RenderTarget::Image(target.clone().into()),
                            Projection::Orthographic(OrthographicProjection {
                                near: 0.0,
                                far: 2.0 * epsilon,
                                scaling_mode: ScalingMode::Fixed {
                                    width: hi.x - lo.x,
                                    height: hi.y - lo.y,
                                },
                                ..OrthographicProjection::default_3d()
                            }),
                            Transform::from_translation(eye)
                                .looking_to(-plane.normal, plane.bitangent),
                            ImpostorBakeCamera,
                            Tonemapping::None,
                            DebandDither::Disabled,
                            Msaa::Off,
                            RenderLayers::none().with(layer),
                        ))
                        .id(),
                );
            }
        }
        let latest: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();
        let sink = latest.clone();
        commands
            .entity(entity)
            .insert((
                BakeJob {
                    cloud,
                    layout,
                    target: target.clone(),
                    started,
                    settling: ReadbackSettling::default(),
                    hash,
                    extinction: light.extinction,
                    seen_gains: light.seen,
                    bounce_ratios: light.bounce,
                    hotspot: light.hotspot,
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

fn finish_impostor_bakes(
    mut commands: Commands,
    mut jobs: Query<(Entity, &ImpostorBakeRequest, &mut BakeJob)>,
    idle: Res<BakePipelinesIdle>,
    mut images: ResMut<Assets<Image>>,
    mut part_meshes: Query<&mut Mesh3d>,
) {
    for (entity, request, mut job) in &mut jobs {
        let size = job.layout.size;
        let latest = job.latest.lock().unwrap().take();
        let pixels = latest.and_then(|padded| unpad_rows(&padded, size * 3, size * 2, 4));
        let job = &mut *job;
        let has_content = |p: &[u8]| p.chunks_exact(4).any(|p| p[3] > 0);
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
                warn!(
                    "impostor bake of {} failed: {why}; the tree keeps its pruned geometry",
                    request.label
                );
                finish(&mut commands, entity, job, &mut images, Err(why));
                continue;
            }
        };
        // Each pass's quadrant as an atlas of its own.
        let atlas = |pass: u32| -> Vec<u8> {
            let at = quadrant(pass, size);
            let row = (size * 4) as usize;
            (0..size)
                .flat_map(|y| {
                    let start = (((at.y + y) * size * 3 + at.x) * 4) as usize;
                    pixels[start..start + row].iter().copied()
                })
                .collect()
        };
        let albedo_raw = atlas(0);
        // The normal pass wrote `0.5 + 0.5·n` as a colour into an sRGB target: undo the encoding
        // (alpha is never encoded). The light passes' bytes are kept as the target encoded them,
        // which is how `texture::encode_light` stores them.
        let light_raw: [Vec<u8>; LIGHT_ATLASES] = std::array::from_fn(|k| atlas(2 + k as u32));
        let normal_raw: Vec<u8> = atlas(1)
            .chunks_exact(4)
            .flat_map(|p| {
                let lin = |c: u8| (srgb_to_linear(c) * 255.0 + 0.5) as u8;
                [lin(p[0]), lin(p[1]), lin(p[2]), p[3]]
            })
            .collect();
        let (mut albedo, mut normal) = (albedo_raw.clone(), normal_raw.clone());
        let mut light = light_raw.clone();
        for l in &mut light {
            dilate(l, size, 4);
        }
        dilate(&mut albedo, size, 4);
        dilate(&mut normal, size, 4);
        let data = ImpostorData {
            center: job.cloud.center,
            radius: job.cloud.radius,
            planes: impostor_planes(&job.cloud, &job.layout, min_extent(&job.cloud)),
            atlas_size: size,
            albedo,
            normal,
            light,
            extinction: job.extinction,
            seen_gains: job.seen_gains,
            bounce_ratios: job.bounce_ratios,
            hotspot: job.hotspot,
            source_hash: job.hash,
            bake_ms: job.started.elapsed().as_secs_f32() * 1e3,
        };
        if let Some(path) = &request.save_to
            && let Err(e) = save(&data, path)
        {
            warn!("impostor bake of {}: could not save: {e}", request.label);
        }
        info!(
            "baked the billboard cloud of {}: {} planes, {}² atlas, {:.0} ms, {:.1} MiB of textures",
            request.label,
            data.planes.len(),
            size,
            data.bake_ms,
            data.texture_bytes() as f64 / (1 << 20) as f64
        );
        commands.entity(entity).insert(ImpostorBakeRaw {
            cloud: job.cloud.clone(),
            layout: job.layout.clone(),
            albedo: albedo_raw,
            normal: normal_raw,
            light: light_raw,
        });
        finish(&mut commands, entity, job, &mut images, Ok(Arc::new(data)));
    }
}

fn finish(
    commands: &mut Commands,
    entity: Entity,
    job: &BakeJob,
    images: &mut Assets<Image>,
    result: Result<Arc<ImpostorData>, String>,
) {
    for &part in &job.parts {
        commands.entity(part).despawn();
    }
    images.remove(&job.target);
    commands
        .entity(entity)
        .remove::<(BakeJob, Readback)>()
        .insert(ImpostorBakeResult(result));
}
