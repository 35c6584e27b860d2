//! The blade material: Bevy's `StandardMaterial` extended with the grass fragment stages of
//! `grass_blade.wgsl` (the density test and the geometry opacity of eq. 4.6 in every pass, the
//! colour ramp and ambient occlusion in the main pass), and the density map as an `R32Float`
//! texture the shaders read texel by texel (`grass_functions.wgsl`, whose CPU references are
//! [`super::transition`] and [`super::density`]).

use super::density::DensityMap;
use super::field::{GrassSettings, GrassSpecies};
use super::ground_map::GroundWindUniform;
use super::lighting::{BLADE_PERCEPTUAL_ROUGHNESS, BLADE_REFLECTANCE, ShadowMask};
use super::transition::TransitionDistances;
use bevy::asset::{RenderAssetUsages, embedded_asset};
use bevy::pbr::{ExtendedMaterial, MaterialExtension, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::render_resource::{
    AsBindGroup, Extent3d, ShaderType, TextureDimension, TextureFormat,
};
use bevy::shader::ShaderRef;
use bevy::shader::load_shader_library;

/// The blade material.
pub type GrassBladeMaterial = ExtendedMaterial<StandardMaterial, GrassBladeExtension>;

/// Uniforms of the blade stages (see `grass_blade.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, ShaderType, Reflect)]
pub struct GrassBladeParams {
    /// xyz: the eye the transitions are measured from.
    pub eye: Vec4,
    /// (min_geom, max_geom, min_btf, max_btf).
    pub distances: Vec4,
    /// (ω_max, ω₀, max_silhouettes, silhouette ε).
    pub window: Vec4,
    /// The density map's rectangle (min.x, min.z, size.x, size.z).
    pub density_rect: Vec4,
    /// rgb: root colour (linear); w: ambient occlusion at the root.
    pub root_color: Vec4,
    /// rgb: tip colour (linear).
    pub tip_color: Vec4,
    /// The ground under the field and the wind over it.
    pub ground_wind: GroundWindUniform,
    /// The blade shadow mask's (slab height, cylinder radius, 0, 0); radius 0: no mask.
    pub mask_shape: Vec4,
}

impl GrassBladeParams {
    /// The parameters of `species` under `settings`, the density map covering `density_rect`,
    /// seen from `eye`.
    pub fn new(
        settings: &GrassSettings,
        species: &GrassSpecies,
        density_rect: Vec4,
        eye: Vec3,
        ground_wind: GroundWindUniform,
    ) -> Self {
        let (distances, window) = transition_uniforms(&settings.transitions);
        let c = |c: LinearRgba| Vec4::new(c.red, c.green, c.blue, 1.0);
        Self {
            eye: eye.extend(1.0),
            distances,
            window,
            density_rect,
            root_color: c(species.root_color).truncate().extend(species.root_ao),
            tip_color: c(species.tip_color),
            ground_wind,
            mask_shape: Vec4::ZERO,
        }
    }
}

/// The transition distances and window as the grass shaders take them:
/// `(min_geom, max_geom, min_btf, max_btf)` and `(ω_max, ω₀, max_silhouettes, silhouette ε)`.
pub fn transition_uniforms(t: &TransitionDistances) -> (Vec4, Vec4) {
    (
        Vec4::new(t.min_geom, t.max_geom, t.min_btf, t.max_btf),
        Vec4::new(
            t.omega_max,
            t.omega_0,
            t.max_silhouettes,
            t.silhouette_epsilon,
        ),
    )
}

/// The grass part of [`GrassBladeMaterial`].
#[derive(Asset, AsBindGroup, Reflect, Debug, Clone, Default)]
#[bind_group_data(GrassBladeKey)]
pub struct GrassBladeExtension {
    /// Transition distances, eye, colours.
    #[uniform(100)]
    pub params: GrassBladeParams,
    /// The density map (`R32Float`, see [`density_image`]).
    #[texture(101, sample_type = "float", filterable = false)]
    pub density: Handle<Image>,
    /// The ground's samples (`R32Float`, [`ground_image`](super::ground_map::ground_image) or
    /// [`flat_ground_image`](super::ground_map::flat_ground_image)).
    #[texture(103, sample_type = "float", filterable = false)]
    pub ground: Handle<Image>,
    /// The wind map (`Rg32Float`, [`GrassWindMap`](super::ground_map::GrassWindMap)).
    #[texture(104, sample_type = "float", filterable = false)]
    pub wind: Handle<Image>,
    /// The blade shadow mask (`R32Float` visibility, [`shadow_mask_image`]).
    #[texture(105, sample_type = "float", filterable = false)]
    pub shadow_mask: Handle<Image>,
    /// The terrain's ambient occlusion over the field (`R32Float`, as [`density_image`] makes).
    #[texture(106, sample_type = "float", filterable = false)]
    pub terrain_occlusion: Handle<Image>,
    /// A screen-space soft-shadow visibility texture (`bevy_soft_shadows`'
    /// `SsssTextures::visibility`) to use as the sun's shadow term. With one, the main pass's
    /// fragment stage is `grass_blade_soft.wgsl`, which imports
    /// `bevy_soft_shadows::receiver_functions` (so that plugin must be added); `bevy_nature`'s
    /// glue sets it while a light has soft shadows.
    #[texture(102, sample_type = "float", filterable = false)]
    pub soft_visibility: Option<Handle<Image>>,
}

/// What the blade pipeline is specialised on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct GrassBladeKey {
    /// The blades receive screen-space soft shadows.
    pub soft_shadows: bool,
}

impl From<&GrassBladeExtension> for GrassBladeKey {
    fn from(material: &GrassBladeExtension) -> Self {
        Self {
            soft_shadows: material.soft_visibility.is_some(),
        }
    }
}

const BLADE_SHADER: &str = "embedded://bevy_foliage/grass/grass_blade.wgsl";
const BLADE_VERTEX_SHADER: &str = "embedded://bevy_foliage/grass/grass_blade_vertex.wgsl";

/// The soft-shadow main-pass stage, loaded at start-up and swapped in by `specialize`.
static BLADE_SOFT_SHADER: std::sync::OnceLock<Handle<bevy::shader::Shader>> =
    std::sync::OnceLock::new();

impl MaterialExtension for GrassBladeExtension {
    fn vertex_shader() -> ShaderRef {
        ShaderRef::Path(BLADE_VERTEX_SHADER.into())
    }
    fn prepass_vertex_shader() -> ShaderRef {
        ShaderRef::Path(BLADE_VERTEX_SHADER.into())
    }
    fn deferred_vertex_shader() -> ShaderRef {
        ShaderRef::Path(BLADE_VERTEX_SHADER.into())
    }
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Path(BLADE_SHADER.into())
    }
    fn prepass_fragment_shader() -> ShaderRef {
        ShaderRef::Path(BLADE_SHADER.into())
    }
    fn specialize(
        _pipeline: &bevy::pbr::MaterialExtensionPipeline,
        descriptor: &mut bevy::render::render_resource::RenderPipelineDescriptor,
        _layout: &bevy::mesh::MeshVertexBufferLayoutRef,
        key: bevy::pbr::MaterialExtensionKey<Self>,
    ) -> Result<(), bevy::render::render_resource::SpecializedMeshPipelineError> {
        // The main pass's vertex stage hands the fragment stage the terrain's occlusion at the
        // blade and the point's height above the ground (`BladeVertexOutput`), and the fragment
        // reads the density once for the blade test and the shadow mask: four texel reads a
        // fragment instead of twenty. The prepass and shadow pipelines keep their own.
        let prepass = descriptor
            .vertex
            .shader_defs
            .iter()
            .any(|d| *d == bevy::shader::ShaderDefVal::from("PREPASS_PIPELINE"));
        if !prepass {
            descriptor.vertex.shader_defs.push("BLADE_TERMS".into());
            if let Some(fragment) = descriptor.fragment.as_mut() {
                fragment.shader_defs.push("BLADE_TERMS".into());
            }
        }
        // Only the main pass: the prepass and shadow pipelines keep the blade test of
        // `grass_blade.wgsl`.
        crate::soft_receiver::use_soft_fragment(
            descriptor,
            key.bind_group_data.soft_shadows,
            BLADE_SOFT_SHADER.get(),
        );
        Ok(())
    }
}

/// A blade material for `species`: two-sided, alpha-masked (so the prepass and shadow passes run
/// the blade test too), with the species' transmission.
pub fn blade_material(
    species: &GrassSpecies,
    extension: GrassBladeExtension,
) -> GrassBladeMaterial {
    GrassBladeMaterial {
        base: StandardMaterial {
            base_color: Color::WHITE,
            perceptual_roughness: BLADE_PERCEPTUAL_ROUGHNESS,
            reflectance: BLADE_REFLECTANCE,
            diffuse_transmission: species.transmission,
            double_sided: true,
            cull_mode: None,
            alpha_mode: AlphaMode::Mask(0.5),
            ..default()
        },
        extension,
    }
}

/// The blade shadow mask as the shaders read it (`R32Float` visibility, row 0 at the top).
pub fn shadow_mask_image(mask: &ShadowMask) -> Image {
    let bytes: Vec<u8> = mask.texels.iter().flat_map(|v| v.to_le_bytes()).collect();
    Image::new(
        Extent3d {
            width: mask.width,
            height: mask.height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        bytes,
        TextureFormat::R32Float,
        RenderAssetUsages::RENDER_WORLD,
    )
}

/// `map` as the `R32Float` texture the shaders read.
pub fn density_image(map: &DensityMap) -> Image {
    let (width, height) = map.dimensions();
    let bytes: Vec<u8> = map.values().iter().flat_map(|v| v.to_le_bytes()).collect();
    Image::new(
        Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        bytes,
        TextureFormat::R32Float,
        RenderAssetUsages::RENDER_WORLD,
    )
}

/// `map` as an image a [`GrassField`](super::GrassField) can take as its density map (`R32Float`,
/// kept on the CPU too, where the field reads it).
pub fn density_map_image(map: &DensityMap) -> Image {
    let mut image = density_image(map);
    image.asset_usage = RenderAssetUsages::all();
    image
}

/// The density map in `image`'s first channel over the rectangle `[min, min + size]`, or why it
/// cannot be read (a compressed or unsupported format, missing data, a size that does not match
/// the data).
pub fn density_map_from_image(
    image: &Image,
    min: [f32; 2],
    size: [f32; 2],
) -> Result<DensityMap, super::density::DensityMapError> {
    use super::density::DensityMapError;
    let format = image.texture_descriptor.format;
    let (channels, bits) = match format {
        TextureFormat::R8Unorm => (1, 8),
        TextureFormat::Rg8Unorm => (2, 8),
        TextureFormat::Rgba8Unorm | TextureFormat::Rgba8UnormSrgb => (4, 8),
        TextureFormat::R16Unorm => (1, 16),
        TextureFormat::Rg16Unorm => (2, 16),
        TextureFormat::Rgba16Unorm => (4, 16),
        TextureFormat::R32Float => (1, 32),
        TextureFormat::Rg32Float => (2, 32),
        TextureFormat::Rgba32Float => (4, 32),
        other => return Err(DensityMapError::Format(format!("{other:?}"))),
    };
    let Some(data) = image.data.as_ref() else {
        return Err(DensityMapError::Format(
            "an image without CPU-side data (it must keep MAIN_WORLD usage)".into(),
        ));
    };
    let extent = image.texture_descriptor.size;
    if extent.depth_or_array_layers != 1 {
        return Err(DensityMapError::Format(format!(
            "a {}-layer image",
            extent.depth_or_array_layers
        )));
    }
    // Mip level 0 only.
    let level0 = (extent.width * extent.height * channels * bits / 8) as usize;
    let bytes = if data.len() >= level0 {
        &data[..level0]
    } else {
        &data[..]
    };
    DensityMap::from_pixels(
        extent.width,
        extent.height,
        bytes,
        channels,
        bits,
        min,
        size,
    )
}

/// Registers the blade material and the shaders.
pub(crate) fn build(app: &mut App) {
    load_shader_library!(app, "grass_functions.wgsl");
    load_shader_library!(app, "grass_blade_functions.wgsl");
    load_shader_library!(app, "grass_blade_light.wgsl");
    embedded_asset!(app, "grass_blade.wgsl");
    embedded_asset!(app, "grass_blade_vertex.wgsl");
    embedded_asset!(app, "grass_blade_soft.wgsl");
    let soft: Handle<bevy::shader::Shader> =
        bevy::asset::load_embedded_asset!(app, "grass_blade_soft.wgsl");
    let _ = BLADE_SOFT_SHADER.set(soft.clone());
    app.insert_resource(GrassBladeSoftShader(soft))
        .add_plugins(MaterialPlugin::<GrassBladeMaterial>::default());
}

/// Keeps the soft-shadow blade stage loaded.
#[derive(Resource)]
struct GrassBladeSoftShader(#[allow(dead_code)] Handle<bevy::shader::Shader>);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn density_images_are_read_or_refused_with_the_reason() {
        let grey = Image::new(
            Extent3d {
                width: 2,
                height: 1,
                depth_or_array_layers: 1,
            },
            TextureDimension::D2,
            vec![0, 0, 0, 255, 255, 255, 255, 255],
            TextureFormat::Rgba8UnormSrgb,
            RenderAssetUsages::MAIN_WORLD,
        );
        let map = density_map_from_image(&grey, [0.0, 0.0], [2.0, 1.0]).unwrap();
        assert_eq!(map.values(), &[0.0, 1.0]);
        let gpu = density_image(&map);
        assert_eq!(gpu.texture_descriptor.format, TextureFormat::R32Float);
        assert_eq!(gpu.data.as_ref().unwrap().len(), 8);

        let mut bc = grey.clone();
        bc.texture_descriptor.format = TextureFormat::Bc1RgbaUnorm;
        let e = density_map_from_image(&bc, [0.0, 0.0], [2.0, 1.0]).unwrap_err();
        assert!(e.to_string().contains("Bc1RgbaUnorm"), "{e}");
        let mut short = grey.clone();
        short.data = Some(vec![0; 4]);
        assert!(density_map_from_image(&short, [0.0, 0.0], [2.0, 1.0]).is_err());
    }
}
