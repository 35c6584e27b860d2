//! The terrain material: Bevy's `StandardMaterial` (lighting, shadows) whose base colour is
//! sampled from a clip stack by the mesh's virtual-texture coordinates — the finest layer that
//! covers the point, falling back to coarser ones and to the resident base level
//! (`clipmap.wgsl`). Make one with [`ClipStackTexture::material`](crate::stack_gpu::ClipStackTexture::material); build meshes whose texture
//! coordinates are virtual-texture coordinates computed in f64 with [`flat_patch_mesh`].

use bevy::asset::{RenderAssetUsages, embedded_asset};
use bevy::math::{DVec2, Vec4};
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::pbr::{ExtendedMaterial, MaterialExtension, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::render_resource::{AsBindGroup, ShaderType};
use bevy::shader::ShaderRef;

/// Most windowed layers the material handles.
pub const MAX_LAYERS: usize = 16;

/// What the fragment stage needs to know about the stack.
#[derive(Clone, Copy, Debug, PartialEq, ShaderType, Reflect)]
pub struct ClipmapParams {
    /// Per windowed layer, the valid level texels `[min.xy, max.xy)` (empty when none).
    pub coverage: [Vec4; MAX_LAYERS],
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
            coverage: [Vec4::ZERO; MAX_LAYERS],
            base_level: 0,
            layer_count: 0,
            clip_size: 1.0,
            mips: 1,
            no_data: Vec4::from(crate::settings::NO_DATA_COLOR.to_linear().to_f32_array()),
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
}

/// What the terrain pipeline is specialised on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ClipmapKey {
    /// The material receives screen-space soft shadows.
    pub soft_shadows: bool,
}

impl From<&ClipmapExtension> for ClipmapKey {
    fn from(material: &ClipmapExtension) -> Self {
        Self {
            soft_shadows: material.soft_visibility.is_some(),
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
/// texture coordinates `uv_of(world point)` evaluated in f64 — exact however far the patch is
/// from the world origin.
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
struct ClipmapShaders(
    Handle<bevy::shader::Shader>,
    Handle<bevy::shader::Shader>,
    Handle<bevy::shader::Shader>,
);

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
    let _ = SOFT_SHADER.set(soft.clone());
    app.insert_resource(ClipmapShaders(module, soft, forward));
    app.add_plugins(MaterialPlugin::<ClipmapMaterial>::default());
}
