//! The slice material: `grass_slice.wgsl` over the baked slice images, uploaded as one
//! `Rgba16Float` array texture — one layer per slice and BTF row — whose mips are built on the CPU
//! by the slices' own filter ([`super::slice_mip`]: alpha-weighted colour, maximum alpha), so
//! distant grass keeps its coverage.

use super::field::{GrassSettings, GrassSpecies};
use super::ground_map::GroundWindUniform;
use super::lighting::{BLADE_PERCEPTUAL_ROUGHNESS, BLADE_REFLECTANCE};
use super::material::transition_uniforms;
use super::quadtree::CellGrid;
use super::slice_mip::MipAlpha;
use super::slices::{LAYERS, SliceTextures};
use bevy::asset::{RenderAssetUsages, embedded_asset};
use bevy::image::{ImageAddressMode, ImageFilterMode, ImageSampler, ImageSamplerDescriptor};
use bevy::pbr::{MaterialPipeline, MaterialPipelineKey, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::render_resource::{
    AsBindGroup, Extent3d, RenderPipelineDescriptor, ShaderType, SpecializedMeshPipelineError,
    TextureDimension, TextureFormat, TextureViewDescriptor, TextureViewDimension,
};
use bevy::shader::ShaderRef;
use half::f16;

/// Uniforms of [`GrassSliceMaterial`] (see `grass_slice.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, ShaderType)]
pub struct GrassSliceParams {
    /// xyz: the eye the transitions are measured from.
    pub eye: Vec4,
    /// (min_geom, max_geom, min_btf, max_btf).
    pub distances: Vec4,
    /// (ω_max, ω₀, max_silhouettes, silhouette ε).
    pub window: Vec4,
    /// The density map's rectangle (min.x, min.z, size.x, size.z).
    pub density_rect: Vec4,
    /// (origin x, origin z, cell side, ground y).
    pub grid: Vec4,
    /// (slice height, slices per axis, texels a side, transmission γ).
    pub slices: Vec4,
    /// x: the mirror seed.
    pub seed: UVec4,
    /// The ground under the field and the wind over it.
    pub ground_wind: GroundWindUniform,
    /// The blade shadow mask's (slab height, cylinder radius, 0, 0); radius 0: no mask.
    pub mask_shape: Vec4,
    /// The blades' (perceptual roughness, reflectance at normal incidence, 0, 0) in Bevy's PBR,
    /// for the slices' ambient light ([`slice_ambient`]).
    ///
    /// [`slice_ambient`]: super::lighting::slice_ambient
    pub surface: Vec4,
}

impl GrassSliceParams {
    /// The parameters of a field of `species` on `grid` at `ground_y`, with slices `textures`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        settings: &GrassSettings,
        species: &GrassSpecies,
        textures: &SliceTextures,
        grid: &CellGrid,
        ground_y: f32,
        density_rect: Vec4,
        eye: Vec3,
        ground_wind: GroundWindUniform,
    ) -> Self {
        let (distances, window) = transition_uniforms(&settings.transitions);
        let l = &textures.layout;
        Self {
            eye: eye.extend(1.0),
            distances,
            window,
            density_rect,
            grid: Vec4::new(grid.origin.x, grid.origin.y, grid.cell, ground_y),
            slices: Vec4::new(
                l.height,
                l.per_axis as f32,
                l.resolution as f32,
                species.transmission,
            ),
            seed: UVec4::new(species.patch.seed as u32, 0, 0, 0),
            ground_wind,
            mask_shape: Vec4::ZERO,
            surface: Vec4::new(
                BLADE_PERCEPTUAL_ROUGHNESS,
                0.16 * BLADE_REFLECTANCE * BLADE_REFLECTANCE,
                0.0,
                0.0,
            ),
        }
    }
}

/// The slice material.
#[derive(Asset, TypePath, AsBindGroup, Clone, Debug)]
#[bind_group_data(GrassSliceKey)]
pub struct GrassSliceMaterial {
    /// Transitions, grid, eye.
    #[uniform(0)]
    pub params: GrassSliceParams,
    /// The slice images ([`slice_image`]).
    #[texture(1, dimension = "2d_array")]
    #[sampler(2)]
    pub slices: Handle<Image>,
    /// The density map (`R32Float`).
    #[texture(3, sample_type = "float", filterable = false)]
    pub density: Handle<Image>,
    /// The ground's samples (`R32Float`), as the blade material's.
    #[texture(4, sample_type = "float", filterable = false)]
    pub ground: Handle<Image>,
    /// The wind map (`Rg32Float`).
    #[texture(5, sample_type = "float", filterable = false)]
    pub wind: Handle<Image>,
    /// The blade shadow mask (`R32Float`), as the blade material's.
    #[texture(6, sample_type = "float", filterable = false)]
    pub shadow_mask: Handle<Image>,
    /// A screen-space soft-shadow visibility texture (`bevy_soft_shadows`'
    /// `SsssTextures::visibility`: .r the sun's soft visibility, negative where inactive; .g the
    /// light, −1 for the directional one) to use as the sun's shadow term where it is active;
    /// `bevy_nature`'s glue sets it while a light has soft shadows.
    #[texture(7, sample_type = "float", filterable = false)]
    pub soft_visibility: Option<Handle<Image>>,
    /// The terrain's ambient occlusion (`R32Float`), as the blade material's.
    #[texture(8, sample_type = "float", filterable = false)]
    pub terrain_occlusion: Handle<Image>,
}

/// What the slice pipeline is specialised on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct GrassSliceKey {
    /// The slices receive screen-space soft shadows.
    pub soft_shadows: bool,
}

impl From<&GrassSliceMaterial> for GrassSliceKey {
    fn from(material: &GrassSliceMaterial) -> Self {
        Self {
            soft_shadows: material.soft_visibility.is_some(),
        }
    }
}

const SLICE_SHADER: &str = "embedded://bevy_foliage/grass/grass_slice.wgsl";

impl Material for GrassSliceMaterial {
    fn vertex_shader() -> ShaderRef {
        ShaderRef::Path(SLICE_SHADER.into())
    }
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Path(SLICE_SHADER.into())
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
        key: MaterialPipelineKey<Self>,
    ) -> Result<(), SpecializedMeshPipelineError> {
        // Slices are seen from both sides.
        descriptor.primitive.cull_mode = None;
        if key.bind_group_data.soft_shadows
            && let Some(fragment) = descriptor.fragment.as_mut()
        {
            fragment.shader_defs.push("SOFT_SHADOWS".into());
        }
        Ok(())
    }
}

/// The slice images as one array texture: layer `s·LAYERS + l` is slice `s`'s layer `l`, each
/// with its custom mip chain (alpha made as `alpha` says), trilinearly filtered and clamped at
/// the edges.
pub fn slice_image(textures: &SliceTextures, alpha: MipAlpha) -> Image {
    let layout = textures.layout;
    let layers = layout.slices() * LAYERS;
    let mips = textures.mips(alpha);
    let levels = mips.first().map_or(1, |chain| chain.len()) as u32;
    let mut data = Vec::new();
    // Layer-major: every mip of layer 0, then layer 1, …
    for chain in &mips {
        for level in chain {
            for t in &level.texels {
                for c in t {
                    data.extend_from_slice(&f16::from_f32(*c).to_le_bytes());
                }
            }
        }
    }
    let mut image = Image::new_uninit(
        Extent3d {
            width: layout.resolution,
            height: layout.resolution,
            depth_or_array_layers: layers,
        },
        TextureDimension::D2,
        TextureFormat::Rgba16Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.mip_level_count = levels;
    image.data = Some(data);
    image.texture_view_descriptor = Some(TextureViewDescriptor {
        dimension: Some(TextureViewDimension::D2Array),
        ..default()
    });
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

/// Registers the slice material.
pub(crate) fn build(app: &mut App) {
    embedded_asset!(app, "grass_slice.wgsl");
    app.add_plugins(MaterialPlugin::<GrassSliceMaterial>::default());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grass::slices::SliceLayout;

    #[test]
    fn the_array_holds_every_layer_with_its_mips() {
        let layout = SliceLayout {
            size: 0.5,
            height: 0.4,
            per_axis: 1,
            resolution: 4,
        };
        let textures = SliceTextures::empty(layout);
        let image = slice_image(&textures, MipAlpha::Mean);
        assert_eq!(
            image.texture_descriptor.size.depth_or_array_layers,
            3 * LAYERS
        );
        assert_eq!(image.texture_descriptor.mip_level_count, 3);
        // (16 + 4 + 1) texels of 8 bytes per layer.
        assert_eq!(
            image.data.as_ref().unwrap().len(),
            (3 * LAYERS) as usize * 21 * 8
        );
    }
}
