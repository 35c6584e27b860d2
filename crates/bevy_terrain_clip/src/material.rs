//! The terrain material: Bevy's `StandardMaterial` (lighting, shadows) whose base colour is
//! sampled from a clip stack — the finest layer that covers the point, falling back to coarser
//! ones and to the resident base level (`clipmap.wgsl`). A stack with a world
//! [`mapping`](crate::stack_gpu::ClipStackTexture::mapping) is sampled at each fragment's
//! position (straight down onto the texture); one without, at the mesh's texture coordinates
//! (virtual-texture coordinates, which [`flat_patch_mesh`] computes in f64). Make one with
//! [`ClipStackTexture::material`](crate::stack_gpu::ClipStackTexture::material).

use bevy::asset::{RenderAssetUsages, embedded_asset};
use bevy::math::{DVec2, Vec2, Vec4};
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::pbr::{ExtendedMaterial, MaterialExtension, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::render_resource::{AsBindGroup, ShaderType};
use bevy::shader::ShaderRef;

/// Most windowed layers the material handles.
pub const MAX_LAYERS: usize = 16;

/// What the fragment stage needs to know about the stack.
///
/// It samples at a point of its *sampling space*: the fragment's render-space (x, z) for a stack
/// with a world [`mapping`](crate::stack_gpu::ClipStackTexture::mapping), the mesh's texture
/// coordinates otherwise. Each layer's valid rectangle is given by where its corner lies in that
/// space (computed in f64 on the CPU) and its size in level texels, so the level texel a
/// fragment falls in is its short offset from a nearby corner over the texel size — exact to
/// f32's precision near the camera even 2^20 texels from the texture's corner, where absolute
/// texture coordinates would keep only an eighth of a texel.
#[derive(Clone, Copy, Debug, PartialEq, ShaderType, Reflect)]
pub struct ClipmapParams {
    /// Per windowed layer: xy where its valid rectangle's min corner lies in sampling space, zw
    /// the rectangle's size in level texels (zero when none).
    pub windows: [Vec4; MAX_LAYERS],
    /// Per windowed layer: xy the corner's level texel modulo c (its toroidal slot), z the
    /// level's texel size in sampling space.
    pub slots: [Vec4; MAX_LAYERS],
    /// Where the texture's (0, 0) lies in sampling space.
    pub texture_origin: Vec2,
    /// The texture's side in sampling space.
    pub texture_size: f32,
    /// 1: sampling space is render space (x, z); 0: the mesh's texture coordinates.
    pub by_position: u32,
    /// Base level l_b.
    pub base_level: u32,
    /// Windowed layers.
    pub layer_count: u32,
    /// Clip size c.
    pub clip_size: f32,
    /// Mip levels per layer sampled (1: mip 0 only, nearest).
    pub mips: u32,
    /// Linear colour shown where there is no data (outside the texture, transparent texels).
    pub no_data: Vec4,
}

impl Default for ClipmapParams {
    fn default() -> Self {
        Self {
            windows: [Vec4::ZERO; MAX_LAYERS],
            slots: [Vec4::ZERO; MAX_LAYERS],
            texture_origin: Vec2::ZERO,
            texture_size: 1.0,
            by_position: 0,
            base_level: 0,
            layer_count: 0,
            clip_size: 1.0,
            mips: 1,
            no_data: Vec4::from(crate::settings::NO_DATA_COLOR.to_linear().to_f32_array()),
        }
    }
}

/// What the vertex stage needs to know about the height stack, for a material with relief
/// (`relief.wgsl`; CPU reference [`crate::geometry::relief`]).
#[derive(Clone, Copy, Debug, PartialEq, ShaderType, Reflect)]
pub struct ReliefParams {
    /// Per windowed layer of the height stack, the valid level texels `[min.xy, max.xy)`.
    pub coverage: [Vec4; MAX_LAYERS],
    /// The height stack's base level l_b.
    pub base_level: u32,
    /// Its windowed layers.
    pub layer_count: u32,
    /// Its clip size c.
    pub clip_size: f32,
    /// Lattice steps along the height texture's side (the terrain's
    /// [`PatchGrid::lattice_side`](crate::geometry::patch::PatchGrid::lattice_side), a power
    /// of two).
    pub lattice_side: f32,
    /// The lattice point the tiles are placed relative to ([`PatchGrid::anchor`](crate::geometry::patch::PatchGrid::anchor)).
    pub anchor: Vec2,
    /// Render-space (x, z) of the anchor (computed in f64).
    pub anchor_render: Vec2,
    /// Metres per lattice step.
    pub lattice_step: f32,
    /// Render-space y of height 0: minus the [`RenderOrigin`](crate::RenderOrigin)'s y.
    pub height_offset: f32,
    /// Render-space (x, z) of the colour texture's (0, 0): the vertex stage gives the fragment
    /// stage of a colour stack without a world mapping its texture coordinates.
    pub color_origin: Vec2,
    /// World side of the colour texture (m).
    pub color_size: f32,
}

impl Default for ReliefParams {
    fn default() -> Self {
        Self {
            coverage: [Vec4::ZERO; MAX_LAYERS],
            base_level: 0,
            layer_count: 0,
            clip_size: 1.0,
            lattice_side: 1.0,
            anchor: Vec2::ZERO,
            anchor_render: Vec2::ZERO,
            lattice_step: 1.0,
            height_offset: 0.0,
            color_origin: Vec2::ZERO,
            color_size: 1.0,
        }
    }
}

impl ReliefParams {
    /// As the CPU reference reads it.
    pub fn height_layers(&self) -> crate::geometry::relief::HeightLayers {
        crate::geometry::relief::HeightLayers {
            coverage: self.coverage[..self.layer_count as usize]
                .iter()
                .map(|c| c.to_array())
                .collect(),
            base_level: self.base_level,
            lattice_side: self.lattice_side,
            lattice_step: self.lattice_step,
        }
    }
}

/// The clip stack's textures and coverage (kept up to date by the plugin).
#[derive(Asset, AsBindGroup, Reflect, Debug, Clone, Default)]
#[bind_group_data(ClipmapKey)]
pub struct ClipmapExtension {
    /// The windowed layers.
    #[texture(100, dimension = "2d_array")]
    #[sampler(101)]
    pub layers: Handle<Image>,
    /// The base level.
    #[texture(102)]
    #[sampler(103)]
    pub base: Handle<Image>,
    /// Coverage and sizes.
    #[uniform(104)]
    pub params: ClipmapParams,
    /// A screen-space soft-shadow visibility texture (R32Float, one value per pixel, negative
    /// where inactive) to use as the sun's shadow term — `bevy_soft_shadows`'
    /// `SsssTextures::visibility`. With one, the fragment stage is `clipmap_soft_fragment.wgsl`,
    /// which imports `bevy_soft_shadows::receiver_functions` (so that plugin must be added);
    /// without, the terrain is lit with Bevy's own shadows and needs nothing from it.
    #[texture(105, sample_type = "float", filterable = false)]
    pub soft_visibility: Option<Handle<Image>>,
    /// The windowed layers of a height clip stack (R32Float): with them, the vertex stage
    /// displaces the mesh to the terrain's heights (`terrain_vertex.wgsl`, main pass and
    /// prepasses, shadow maps included) and gives the fragment stage the colour stack's
    /// coordinates from the world position; [`TerrainGeometry`](crate::terrain::TerrainGeometry)
    /// sets them up. Without, the mesh is drawn as it is.
    #[texture(106, dimension = "2d_array", sample_type = "float", filterable = false)]
    pub height_layers: Option<Handle<Image>>,
    /// The height stack's base level (R32Float, with its mips).
    #[texture(107, sample_type = "float", filterable = false)]
    pub height_base: Option<Handle<Image>>,
    /// The height stack's coverage and the textures' places in the world.
    #[uniform(108)]
    pub relief: ReliefParams,
}

/// What the terrain pipeline is specialised on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ClipmapKey {
    /// The material receives screen-space soft shadows.
    pub soft_shadows: bool,
    /// The vertex stage reads heights from a height stack.
    pub relief: bool,
}

impl From<&ClipmapExtension> for ClipmapKey {
    fn from(material: &ClipmapExtension) -> Self {
        Self {
            soft_shadows: material.soft_visibility.is_some(),
            relief: material.height_layers.is_some() && material.height_base.is_some(),
        }
    }
}

/// The terrain material.
pub type ClipmapMaterial = ExtendedMaterial<StandardMaterial, ClipmapExtension>;

const SHADER: &str = "embedded://bevy_terrain_clip/clipmap_fragment.wgsl";

/// The soft-shadow variant of the fragment stage, loaded at start-up; swapped in by
/// `specialize` for materials with a soft-visibility texture. (Its import of
/// `bevy_soft_shadows::receiver_functions` only has to resolve when a pipeline uses it.)
static SOFT_SHADER: std::sync::OnceLock<Handle<bevy::shader::Shader>> = std::sync::OnceLock::new();

/// The vertex stage with relief (main pass and prepasses), swapped in by `specialize` for
/// materials with a height stack.
static RELIEF_VERTEX_SHADER: std::sync::OnceLock<Handle<bevy::shader::Shader>> =
    std::sync::OnceLock::new();

impl MaterialExtension for ClipmapExtension {
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Path(SHADER.into())
    }

    fn specialize(
        _pipeline: &bevy::pbr::MaterialExtensionPipeline,
        descriptor: &mut bevy::render::render_resource::RenderPipelineDescriptor,
        _layout: &bevy::mesh::MeshVertexBufferLayoutRef,
        key: bevy::pbr::MaterialExtensionKey<Self>,
    ) -> Result<(), bevy::render::render_resource::SpecializedMeshPipelineError> {
        // Relief: the vertex stage of every pass (main, prepasses, shadow maps), so the depth,
        // the normals and the shadows follow the heights too.
        if key.bind_group_data.relief
            && let Some(relief) = RELIEF_VERTEX_SHADER.get()
        {
            descriptor.vertex.shader = relief.clone();
        }
        // Only the main pass's fragment stage: the prepass and shadow pipelines run Bevy's
        // prepass shader (`PREPASS_PIPELINE`) and must keep it.
        if key.bind_group_data.soft_shadows
            && let (Some(fragment), Some(soft)) = (descriptor.fragment.as_mut(), SOFT_SHADER.get())
            && !fragment
                .shader_defs
                .iter()
                .any(|d| *d == bevy::shader::ShaderDefVal::from("PREPASS_PIPELINE"))
        {
            fragment.shader = soft.clone();
        }
        Ok(())
    }
}

/// A flat terrain patch in the XZ plane: `quads × quads` cells over the world square
/// `[world_min, world_min + size]`, positions relative to `anchor` (place the entity there), and
/// texture coordinates `uv_of(world point)` evaluated in f64. The texture coordinates are what
/// a stack *without* a mapping is sampled by; a stack with one samples at the fragment's
/// position, so the patch only has to lie where the ground is (in render space under the
/// [`RenderOrigin`](crate::RenderOrigin)).
pub fn flat_patch_mesh(
    world_min: DVec2,
    size: f64,
    quads: u32,
    anchor: DVec2,
    uv_of: impl Fn(DVec2) -> DVec2,
) -> Mesh {
    let quads = quads.max(1);
    let n = quads + 1;
    let (mut positions, mut uvs, mut normals) = (Vec::new(), Vec::new(), Vec::new());
    for j in 0..n {
        for i in 0..n {
            let world = world_min + DVec2::new(i as f64, j as f64) * (size / quads as f64);
            let local = world - anchor;
            positions.push([local.x as f32, 0.0, local.y as f32]);
            let uv = uv_of(world);
            uvs.push([uv.x as f32, uv.y as f32]);
            normals.push([0.0, 1.0, 0.0]);
        }
    }
    let mut indices = Vec::new();
    for j in 0..quads {
        for i in 0..quads {
            let a = j * n + i;
            indices.extend_from_slice(&[a, a + n, a + 1, a + 1, a + n, a + n + 1]);
        }
    }
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    );
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, uvs);
    mesh.insert_indices(Indices::U32(indices));
    mesh
}

/// Keeps the terrain's shader modules loaded.
#[derive(Resource)]
#[allow(dead_code)]
struct ClipmapShaders(Vec<Handle<bevy::shader::Shader>>);

/// Registers the material.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "clipmap.wgsl");
    embedded_asset!(app, "clipmap_fragment.wgsl");
    embedded_asset!(app, "clipmap_soft_fragment.wgsl");
    // The module imported by both fragment stages, and the soft variant, kept loaded.
    let module: Handle<bevy::shader::Shader> =
        bevy::asset::load_embedded_asset!(app, "clipmap.wgsl");
    let soft: Handle<bevy::shader::Shader> =
        bevy::asset::load_embedded_asset!(app, "clipmap_soft_fragment.wgsl");
    let forward: Handle<bevy::shader::Shader> =
        bevy::asset::load_embedded_asset!(app, "clipmap_fragment.wgsl");
    embedded_asset!(app, "relief.wgsl");
    embedded_asset!(app, "terrain_vertex.wgsl");
    let relief: Handle<bevy::shader::Shader> =
        bevy::asset::load_embedded_asset!(app, "relief.wgsl");
    let vertex: Handle<bevy::shader::Shader> =
        bevy::asset::load_embedded_asset!(app, "terrain_vertex.wgsl");
    let _ = SOFT_SHADER.set(soft.clone());
    let _ = RELIEF_VERTEX_SHADER.set(vertex.clone());
    app.insert_resource(ClipmapShaders(vec![module, soft, forward, relief, vertex]));
    app.add_plugins(MaterialPlugin::<ClipmapMaterial>::default());
}
