//! The ground and the wind as the grass shaders read them: a field's height map (an image a game
//! gives, read once on the CPU) sampled at its cell corners into a [`GroundGrid`] and uploaded as
//! an `R32Float` texture of those samples; the [`WindMap`] as an `Rg32Float` texture; and the
//! uniforms both stages take (`grass_functions.wgsl`'s `GroundWind`).

use super::ground::{GrassWind, GroundGrid, WindMap};
use super::quadtree::CellGrid;
use bevy::asset::RenderAssetUsages;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, ShaderType, TextureDimension, TextureFormat};

/// Why a height map cannot be read.
#[derive(Clone, Debug, PartialEq)]
pub enum HeightMapError {
    /// Not a 32-bit float format (the heights are metres, not normalised values).
    Format(String),
    /// No CPU-side data, or less of it than the size says.
    Data(String),
    /// A height is NaN or infinite.
    NotFinite {
        /// Its texel index.
        index: usize,
    },
}

impl std::fmt::Display for HeightMapError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Format(format) => write!(
                f,
                "a height map must be R32Float, Rg32Float or Rgba32Float (metres), not {format}"
            ),
            Self::Data(why) => write!(f, "{why}"),
            Self::NotFinite { index } => write!(f, "height texel {index} is not finite"),
        }
    }
}

impl std::error::Error for HeightMapError {}

/// A height map read from an image: heights (m) at texel centres over a rectangle, bilinear
/// between them and clamped at the edges.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightMap {
    width: u32,
    height: u32,
    values: Vec<f32>,
    min: Vec2,
    size: Vec2,
}

impl HeightMap {
    /// The first channel of `image` (32-bit float), row 0 at `min.y` (the −z edge), over
    /// `[min, min + size]`.
    pub fn from_image(image: &Image, min: Vec2, size: Vec2) -> Result<Self, HeightMapError> {
        let format = image.texture_descriptor.format;
        let channels = match format {
            TextureFormat::R32Float => 1,
            TextureFormat::Rg32Float => 2,
            TextureFormat::Rgba32Float => 4,
            other => return Err(HeightMapError::Format(format!("{other:?}"))),
        };
        let extent = image.texture_descriptor.size;
        let Some(data) = image.data.as_ref() else {
            return Err(HeightMapError::Data(
                "a height map without CPU-side data (it must keep MAIN_WORLD usage)".into(),
            ));
        };
        let (width, height) = (extent.width, extent.height);
        let texels = (width * height) as usize;
        if texels == 0 || data.len() < texels * channels * 4 {
            return Err(HeightMapError::Data(format!(
                "a {width}×{height} height map with {} bytes",
                data.len()
            )));
        }
        let values: Vec<f32> = (0..texels)
            .map(|i| {
                let at = i * channels * 4;
                f32::from_le_bytes([data[at], data[at + 1], data[at + 2], data[at + 3]])
            })
            .collect();
        if let Some(index) = values.iter().position(|v| !v.is_finite()) {
            return Err(HeightMapError::NotFinite { index });
        }
        Ok(Self {
            width,
            height,
            values,
            min,
            size,
        })
    }

    /// The height at world `xz`.
    pub fn height_at(&self, xz: Vec2) -> f32 {
        let dims = Vec2::new(self.width as f32, self.height as f32);
        let t = ((xz - self.min) / self.size * dims - 0.5).clamp(Vec2::ZERO, dims - 1.0);
        let base = t.floor();
        let f = t - base;
        let (i, j) = (base.x as u32, base.y as u32);
        let at = |di: u32, dj: u32| {
            let (x, y) = ((i + di).min(self.width - 1), (j + dj).min(self.height - 1));
            self.values[(y * self.width + x) as usize]
        };
        let top = at(0, 0) + (at(1, 0) - at(0, 0)) * f.x;
        let bottom = at(0, 1) + (at(1, 1) - at(0, 1)) * f.x;
        top + (bottom - top) * f.y
    }
}

/// A height map image for a field of `size` metres centred on its entity: `texels` a side,
/// `height(x, z)` (m above the field's plane, in the field's frame: (0, 0) is its centre) at each
/// texel centre. What [`GrassField::ground`](super::GrassField::ground) takes — from a
/// procedural ground, or from a terrain's height query.
pub fn height_map_image(size: Vec2, texels: UVec2, height: impl Fn(Vec2) -> f32) -> Image {
    let texels = texels.max(UVec2::ONE);
    let mut bytes = Vec::with_capacity((texels.x * texels.y * 4) as usize);
    for j in 0..texels.y {
        for i in 0..texels.x {
            let uv = (Vec2::new(i as f32, j as f32) + 0.5) / texels.as_vec2();
            let h = height((uv - 0.5) * size);
            bytes.extend_from_slice(&h.to_le_bytes());
        }
    }
    Image::new(
        Extent3d {
            width: texels.x,
            height: texels.y,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        bytes,
        TextureFormat::R32Float,
        RenderAssetUsages::all(),
    )
}

/// The ground's samples as the shaders read them (`R32Float`, `samples²`).
pub fn ground_image(ground: &GroundGrid) -> Image {
    let bytes: Vec<u8> = ground
        .heights()
        .iter()
        .flat_map(|h| h.to_le_bytes())
        .collect();
    Image::new(
        Extent3d {
            width: ground.samples,
            height: ground.samples,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        bytes,
        TextureFormat::R32Float,
        RenderAssetUsages::RENDER_WORLD,
    )
}

/// Flat ground: 2 × 2 samples of 0.
pub fn flat_ground_image() -> Image {
    Image::new(
        Extent3d {
            width: 2,
            height: 2,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        vec![0; 16],
        TextureFormat::R32Float,
        RenderAssetUsages::RENDER_WORLD,
    )
}

/// `map` as the `Rg32Float` texture the shaders read.
pub fn wind_image(map: &WindMap) -> Image {
    let bytes: Vec<u8> = map
        .texels
        .iter()
        .flat_map(|t| [t.x.to_le_bytes(), t.y.to_le_bytes()])
        .flatten()
        .collect();
    Image::new(
        Extent3d {
            width: map.width,
            height: map.height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        bytes,
        TextureFormat::Rg32Float,
        RenderAssetUsages::RENDER_WORLD,
    )
}

/// The wind map the grass shaders read, and its CPU copy. The plugin fills it with
/// [`WindMap::gusts`]; a game may put another map here (both fields: the image the shaders
/// read, `Rg32Float`, and the map it was made from, for the cell bounds).
#[derive(Resource, Clone, Debug)]
pub struct GrassWindMap {
    /// The map.
    pub map: WindMap,
    /// [`wind_image`] of it.
    pub image: Handle<Image>,
}

/// The ground and wind uniforms of both grass stages (`GroundWind` in `grass_functions.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, ShaderType, Reflect)]
pub struct GroundWindUniform {
    /// (origin x, origin z, sample spacing, cell side).
    pub ground: Vec4,
    /// (unit direction x, z, strength, speed).
    pub wind: Vec4,
    /// (map scale, volume height, time, the field's plane y).
    pub wind_shape: Vec4,
}

impl GroundWindUniform {
    /// The uniforms of a field on `grid` over `ground` (`None`: flat) above the plane
    /// `y = plane_y`, with grass `volume_height` tall in `wind` at `time`.
    pub fn new(
        grid: &CellGrid,
        ground: Option<&GroundGrid>,
        plane_y: f32,
        wind: &GrassWind,
        volume_height: f32,
        time: f32,
    ) -> Self {
        let (origin, spacing) = match ground {
            Some(g) => (g.origin, g.spacing),
            None => (grid.origin, grid.cell),
        };
        let dir = wind.direction.normalize_or(Vec2::X);
        Self {
            ground: Vec4::new(origin.x, origin.y, spacing, grid.cell),
            wind: Vec4::new(dir.x, dir.y, wind.strength, wind.speed),
            wind_shape: Vec4::new(wind.scale, volume_height, time, plane_y),
        }
    }

    /// How far (m) the wind can push a grass top sideways: the strength times the longest vector
    /// the map holds.
    pub fn reach(wind: &GrassWind, map: &WindMap) -> f32 {
        let longest = map.texels.iter().map(|t| t.length()).fold(0.0, f32::max);
        wind.strength * longest
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn height_maps_are_read_in_metres_or_refused() {
        let image = height_map_image(Vec2::new(4.0, 2.0), UVec2::new(4, 2), |p| p.x + 10.0 * p.y);
        let map =
            HeightMap::from_image(&image, Vec2::new(-2.0, -1.0), Vec2::new(4.0, 2.0)).unwrap();
        // At texel centres the function; between them bilinear; clamped beyond.
        assert!((map.height_at(Vec2::new(-1.5, -0.5)) - (-1.5 - 5.0)).abs() < 1e-5);
        assert!((map.height_at(Vec2::new(0.0, 0.0)) - 0.0).abs() < 1e-5);
        assert!((map.height_at(Vec2::new(-9.0, -9.0)) - (-1.5 - 5.0)).abs() < 1e-5);
        let mut bad = image.clone();
        bad.texture_descriptor.format = TextureFormat::R8Unorm;
        assert!(matches!(
            HeightMap::from_image(&bad, Vec2::ZERO, Vec2::ONE),
            Err(HeightMapError::Format(_))
        ));
        let mut short = image.clone();
        short.data = Some(vec![0; 12]);
        assert!(matches!(
            HeightMap::from_image(&short, Vec2::ZERO, Vec2::ONE),
            Err(HeightMapError::Data(_))
        ));
        let mut nan = image;
        nan.data.as_mut().unwrap()[4..8].copy_from_slice(&f32::NAN.to_le_bytes());
        assert_eq!(
            HeightMap::from_image(&nan, Vec2::ZERO, Vec2::ONE),
            Err(HeightMapError::NotFinite { index: 1 })
        );
    }
}
