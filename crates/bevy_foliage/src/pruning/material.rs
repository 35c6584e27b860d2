//! Drawing pruned leaves with Bevy's PBR material: [`LeafMaterial`] is a `StandardMaterial`
//! extended with a vertex stage (`leaf.wgsl`, `leaf_prepass.wgsl`, both pulling vertices through
//! `leaf_pulling.wgsl`) that draws the kept leaves written by the pruning pass, so leaves get
//! Bevy's lighting, shadows (cast and received) and prepasses unchanged. Trees are drawn with
//! slot meshes ([`super::slot_mesh`]).

use crate::settings::FoliagePruningSettings;
use bevy::asset::embedded_asset;
use bevy::pbr::{ExtendedMaterial, MaterialExtension, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::render_resource::{AsBindGroup, ShaderType, TextureFormat};
use bevy::render::storage::ShaderBuffer;
use bevy::shader::ShaderRef;
use bevy::shader::{ShaderDefVal, load_shader_library};

/// The material of pruned leaves: a `StandardMaterial` (colour, texture, alpha mode) whose vertex
/// stage draws the pruned leaf set. Make one with [`leaf_material`].
pub type LeafMaterial = ExtendedMaterial<StandardMaterial, LeafExtension>;

/// Per-material parameters of the leaf vertex stage (see [`super::appearance`]). The switches and
/// fade thresholds follow [`FoliagePruningSettings`]; `opaque_fraction` is the material's own.
#[derive(Clone, Copy, Debug, PartialEq, ShaderType, Reflect)]
pub struct LeafParams {
    /// 1 to enlarge kept leaves so total leaf area is preserved (eq. 3.7–3.9).
    pub area_compensation: u32,
    /// 1 to fade sub-pixel leaves to a solid colour.
    pub subpixel_fade: u32,
    /// Cap of the linear compensation scale.
    pub max_scale: f32,
    /// Fraction of the leaf texture that is opaque (1 for untextured leaves); a fully faded leaf
    /// shrinks to this fraction of its area.
    pub opaque_fraction: f32,
    /// Projected diameter (pixels) where the fade starts.
    pub fade_start: f32,
    /// Projected diameter (pixels) where leaves are fully solid.
    pub fade_end: f32,
    /// 1 to scale the bounce on each leaf face by the leaf's gathered ratios
    /// ([`crate::lighting::gathered_bounce`]).
    pub gathered_bounce: u32,
    /// 1 to take the bounce ratios from the type's ring of ratios re-gathered at the sun's
    /// elevation where the sun is at it ([`crate::lighting::bounce_ring`]).
    pub bounce_ring: u32,
    /// 1 to light the leaves as a volume ([`TreeLightingSettings`](crate::TreeLightingSettings)) instead of by Bevy's PBR.
    pub tree_lighting: u32,
    /// 1: the sun through the crown by eq. 5.7's envelope blend
    /// ([`SunThroughCrown::SmoothEnvelope`](crate::lighting::model::SunThroughCrown::SmoothEnvelope)); 0: the attenuations' blend.
    pub smooth_envelope: u32,
    /// 1 to add one bounce of sunlight (eq. 5.24).
    pub bounce: u32,
    /// 1 to scale the sky and the blended sun by the leaf's seen-part gain towards the eye,
    /// the bounce by the covered part's gain ([`crate::lighting::seen_part`]), and both by the
    /// crown's hotspot ([`crate::lighting::hotspot`]).
    pub seen_part: u32,
    /// The tree lighting's optics and the scene's lights.
    pub lights: TreeLightUniform,
    /// The material's base colour (linear rgb): the optics are multiples of it.
    pub albedo: Vec4,
}

/// What the tree lighting's shaders take from the CPU (`tree_lighting.wgsl`'s
/// `TreeLightUniform`): the leaves' optics as multiples of their colour, and the scene's sun,
/// sky and ground. Shared by the leaves' and the billboard clouds' materials.
#[derive(Clone, Copy, Debug, PartialEq, ShaderType, Reflect)]
pub struct TreeLightUniform {
    /// The leaves' ρ_rf over their colour (rgb).
    pub reflectance_front: Vec4,
    /// ρ_rb (rgb).
    pub reflectance_back: Vec4,
    /// ρ_tf (rgb).
    pub transmittance_front: Vec4,
    /// ρ_tb (rgb).
    pub transmittance_back: Vec4,
    /// World direction towards the sun (xyz).
    pub to_sun: Vec4,
    /// The sun's irradiance (rgb; zero for no sun), as Bevy's lights carry it: colour times
    /// illuminance.
    pub sun: Vec4,
    /// The sky's radiance (rgb): the ambient light's colour times its brightness.
    pub sky: Vec4,
    /// The ground's radiance (rgb).
    pub ground: Vec4,
}

impl Default for TreeLightUniform {
    /// No light at all, the sun straight above.
    fn default() -> Self {
        Self {
            reflectance_front: Vec4::ZERO,
            reflectance_back: Vec4::ZERO,
            transmittance_front: Vec4::ZERO,
            transmittance_back: Vec4::ZERO,
            to_sun: Vec4::Y,
            sun: Vec4::ZERO,
            sky: Vec4::ZERO,
            ground: Vec4::ZERO,
        }
    }
}

impl Default for LeafParams {
    fn default() -> Self {
        let s = FoliagePruningSettings::default();
        Self {
            area_compensation: s.area_compensation as u32,
            subpixel_fade: s.subpixel_fade as u32,
            max_scale: s.max_leaf_scale,
            opaque_fraction: 1.0,
            fade_start: s.fade_start_pixels,
            fade_end: s.fade_end_pixels,
            gathered_bounce: 1,
            bounce_ring: 0,
            tree_lighting: 0,
            smooth_envelope: 0,
            bounce: 1,
            seen_part: 1,
            lights: TreeLightUniform::default(),
            albedo: Vec4::ONE,
        }
    }
}

/// The extension binding the pruning buffers (managed by the plugin: leave them default).
#[derive(Asset, AsBindGroup, Reflect, Debug, Clone, Default)]
#[bind_group_data(LeafKey)]
pub struct LeafExtension {
    /// Instance records.
    #[storage(100, read_only, visibility(vertex))]
    pub instances: Handle<ShaderBuffer>,
    /// Kept indices.
    #[storage(101, read_only, visibility(vertex))]
    pub output: Handle<ShaderBuffer>,
    /// Indirect draw arguments (kept counts).
    #[storage(102, read_only, visibility(vertex))]
    pub draws: Handle<ShaderBuffer>,
    /// Per instance and cell kept counts.
    #[storage(103, read_only, visibility(vertex))]
    pub cell_offsets: Handle<ShaderBuffer>,
    /// Packed leaf vertices.
    #[storage(104, read_only, visibility(vertex))]
    pub leaf_vertices: Handle<ShaderBuffer>,
    /// Per leaf, the light its neighbours let through in eight directions (tree lighting).
    #[storage(105, read_only, visibility(vertex))]
    pub leaf_light: Handle<ShaderBuffer>,
    /// Switches, and the tree lighting's inputs (read by the tree-lit fragment stage too).
    #[uniform(106, visibility(vertex, fragment))]
    pub params: LeafParams,
    /// A screen-space soft-shadow visibility texture (`bevy_soft_shadows`'
    /// `SsssTextures::visibility`) to use as the sun's shadow term. With one, the main pass's
    /// fragment stage is `leaf_soft_fragment.wgsl`, which imports
    /// `bevy_soft_shadows::receiver_functions` (so that plugin must be added); without, leaves
    /// use Bevy's PBR fragment stage and shadows.
    #[texture(107, sample_type = "float", filterable = false)]
    pub soft_visibility: Option<Handle<Image>>,
}

/// What the leaf pipeline is specialised on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct LeafKey {
    /// The leaves receive screen-space soft shadows.
    pub soft_shadows: bool,
    /// The leaves are lit as a volume ([`TreeLightingSettings`](crate::TreeLightingSettings)).
    pub tree_lighting: bool,
}

impl From<&LeafExtension> for LeafKey {
    fn from(material: &LeafExtension) -> Self {
        Self {
            soft_shadows: material.soft_visibility.is_some(),
            tree_lighting: material.params.tree_lighting != 0,
        }
    }
}

/// The soft-shadow fragment stage, loaded at start-up and swapped in by `specialize`.
static LEAF_SOFT_SHADER: std::sync::OnceLock<Handle<bevy::shader::Shader>> =
    std::sync::OnceLock::new();

/// The tree lighting's fragment stage, loaded at start-up and swapped in by `specialize`.
static LEAF_VOLUME_SHADER: std::sync::OnceLock<Handle<bevy::shader::Shader>> =
    std::sync::OnceLock::new();

const LEAF_SHADER: &str = "embedded://bevy_foliage/pruning/leaf.wgsl";
const LEAF_PREPASS_SHADER: &str = "embedded://bevy_foliage/pruning/leaf_prepass.wgsl";

impl MaterialExtension for LeafExtension {
    fn vertex_shader() -> ShaderRef {
        ShaderRef::Path(LEAF_SHADER.into())
    }
    fn prepass_vertex_shader() -> ShaderRef {
        ShaderRef::Path(LEAF_PREPASS_SHADER.into())
    }
    fn deferred_vertex_shader() -> ShaderRef {
        ShaderRef::Path(LEAF_PREPASS_SHADER.into())
    }

    fn specialize(
        _pipeline: &bevy::pbr::MaterialExtensionPipeline,
        descriptor: &mut bevy::render::render_resource::RenderPipelineDescriptor,
        _layout: &bevy::mesh::MeshVertexBufferLayoutRef,
        key: bevy::pbr::MaterialExtensionKey<Self>,
    ) -> Result<(), bevy::render::render_resource::SpecializedMeshPipelineError> {
        let prepass = descriptor
            .vertex
            .shader_defs
            .iter()
            .any(|d| *d == ShaderDefVal::from("PREPASS_PIPELINE"));
        if key.bind_group_data.tree_lighting && !prepass {
            // The main pass lit as a volume: the vertex stage computes each leaf's light
            // (`TreeLitVertexOutput`), the fragment stage shows it under the sun's shadow from
            // outside the crown. Screen-space soft shadows do not apply in this mode.
            if let (Some(fragment), Some(volume)) =
                (descriptor.fragment.as_mut(), LEAF_VOLUME_SHADER.get())
            {
                fragment.shader = volume.clone();
                fragment.shader_defs.push("TREE_LIGHTING".into());
                descriptor.vertex.shader_defs.push("TREE_LIGHTING".into());
            }
            return Ok(());
        }
        // Only the main pass: the prepass and shadow pipelines keep Bevy's prepass shader.
        crate::soft_receiver::use_soft_fragment(
            descriptor,
            key.bind_group_data.soft_shadows,
            LEAF_SOFT_SHADER.get(),
        );
        Ok(())
    }
}

/// A leaf material from a `StandardMaterial`; leaves are two-sided. For alpha-masked leaf
/// textures use [`leaf_material_textured`] so faded leaves keep the right area.
pub fn leaf_material(base: StandardMaterial) -> LeafMaterial {
    leaf_material_textured(base, 1.0)
}

/// A leaf material whose texture is opaque over `opaque_fraction` of its area (measure it with
/// [`opaque_fraction`]): sub-pixel leaves, drawn solid,
/// shrink to that area so distant crowns keep their density.
pub fn leaf_material_textured(base: StandardMaterial, opaque_fraction: f32) -> LeafMaterial {
    let opaque_fraction = if opaque_fraction.is_finite() && opaque_fraction > 0.0 {
        opaque_fraction.min(1.0)
    } else {
        warn!("leaf opaque fraction {opaque_fraction} must be in (0, 1]: using 1");
        1.0
    };
    LeafMaterial {
        base: StandardMaterial {
            double_sided: true,
            cull_mode: None,
            ..base
        },
        extension: LeafExtension {
            params: LeafParams {
                opaque_fraction,
                ..default()
            },
            ..default()
        },
    }
}

/// The fraction of `image`'s texels whose alpha reaches `cutoff` (the opaque area of an
/// alpha-masked leaf texture), or `None` if the format is not 8-bit RGBA or the data is missing.
/// Pass it to [`leaf_material_textured`].
pub fn opaque_fraction(image: &Image, cutoff: f32) -> Option<f32> {
    let format = image.texture_descriptor.format;
    if !matches!(
        format,
        TextureFormat::Rgba8Unorm | TextureFormat::Rgba8UnormSrgb
    ) {
        return None;
    }
    let data = image.data.as_ref()?;
    let size = image.texture_descriptor.size;
    // Level 0 comes first in the data.
    let texels = (size.width * size.height) as usize;
    if data.len() < texels * 4 || texels == 0 {
        return None;
    }
    let threshold = (cutoff.clamp(0.0, 1.0) * 255.0).round() as u8;
    let opaque = data[..texels * 4]
        .chunks_exact(4)
        .filter(|t| t[3] >= threshold)
        .count();
    Some(opaque as f32 / texels as f32)
}

/// Keeps the soft-shadow and the tree-lighting leaf fragment stages loaded.
#[derive(Resource)]
#[allow(dead_code)]
struct LeafSoftShader(Handle<bevy::shader::Shader>, Handle<bevy::shader::Shader>);

/// Registers the leaf material and its shaders.
pub(crate) fn build(app: &mut App) {
    load_shader_library!(app, "leaf_pulling.wgsl");
    load_shader_library!(app, "tree_lighting.wgsl");
    embedded_asset!(app, "leaf.wgsl");
    embedded_asset!(app, "leaf_prepass.wgsl");
    embedded_asset!(app, "leaf_soft_fragment.wgsl");
    let soft: Handle<bevy::shader::Shader> =
        bevy::asset::load_embedded_asset!(app, "leaf_soft_fragment.wgsl");
    let _ = LEAF_SOFT_SHADER.set(soft.clone());
    embedded_asset!(app, "leaf_volume_fragment.wgsl");
    let volume: Handle<bevy::shader::Shader> =
        bevy::asset::load_embedded_asset!(app, "leaf_volume_fragment.wgsl");
    let _ = LEAF_VOLUME_SHADER.set(volume.clone());
    app.insert_resource(LeafSoftShader(soft, volume))
        .add_plugins(MaterialPlugin::<LeafMaterial>::default());
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy::asset::RenderAssetUsages;
    use bevy::render::render_resource::{Extent3d, TextureDimension};

    #[test]
    fn opaque_fraction_counts_texels_over_the_cutoff() {
        let mut data = vec![255u8; 4 * 4 * 4];
        for (i, t) in data.chunks_exact_mut(4).enumerate() {
            t[3] = if i < 6 { 255 } else { 10 };
        }
        let image = Image::new(
            Extent3d {
                width: 4,
                height: 4,
                depth_or_array_layers: 1,
            },
            TextureDimension::D2,
            data,
            TextureFormat::Rgba8UnormSrgb,
            RenderAssetUsages::all(),
        );
        assert_eq!(opaque_fraction(&image, 0.5), Some(6.0 / 16.0));
        let float = Image::new_fill(
            Extent3d::default(),
            TextureDimension::D2,
            &[0; 16],
            TextureFormat::Rgba32Float,
            RenderAssetUsages::all(),
        );
        assert_eq!(opaque_fraction(&float, 0.5), None);
    }
}
