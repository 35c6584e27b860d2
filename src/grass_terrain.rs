//! Grass on a terrain built from an elevation pyramid: the height map a [`GrassField`] takes
//! (its `ground`), read from the same pyramid the clipmap terrain is displaced by, so the blades
//! stand on the ground the terrain draws.
//!
//! ```no_run
//! # use bevy::prelude::*;
//! # use bevy_nature::foliage::grass::GrassField;
//! # use bevy_nature::terrain_clip::dem::{DiskHeightSource, HeightQuery};
//! # fn setup(mut commands: Commands, mut images: ResMut<Assets<Image>>) {
//! let mut query = HeightQuery::new(DiskHeightSource::open("terrain/heights").unwrap(), 16);
//! // A 64 m meadow centred at (300, 450), its entity on the ground's plane at y = 12.
//! let origin = Vec3::new(300.0, 12.0, 450.0);
//! let size = Vec2::splat(64.0);
//! match bevy_nature::grass_terrain::grass_ground_from_terrain(&mut query, origin, size, UVec2::splat(129)) {
//!     Ok(ground) => {
//!         commands.spawn((
//!             GrassField { size, ground: Some(images.add(ground)), ..default() },
//!             Transform::from_translation(origin),
//!         ));
//!     }
//!     Err(e) => error!("no grass ground: {e}"),
//! }
//! # }
//! ```

use bevy::prelude::*;
use bevy_foliage::grass::height_map_image;
use bevy_terrain_clip::dem::HeightQuery;
use bevy_terrain_clip::source::TileError;

/// Why a field's ground could not be read from the terrain.
#[derive(Debug)]
pub enum TerrainGroundError {
    /// A tile of the pyramid could not be read or decoded.
    Tile(TileError),
    /// A texel of the field's height map lies outside the pyramid's data (or where its finest
    /// level has no tile): the field must lie over the terrain.
    OutsideData {
        /// World x of the texel centre (m).
        x: f64,
        /// World z of the texel centre (m).
        z: f64,
    },
    /// The height map would have no texels, or the field no area.
    Empty,
}

impl std::fmt::Display for TerrainGroundError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Tile(e) => write!(f, "grass ground: the terrain's heights: {e}"),
            Self::OutsideData { x, z } => write!(
                f,
                "grass ground: ({x:.1}, {z:.1}) is outside the terrain's height data; place the \
                 field over the terrain"
            ),
            Self::Empty => write!(f, "grass ground: the field or its height map is empty"),
        }
    }
}

impl std::error::Error for TerrainGroundError {}

impl From<TileError> for TerrainGroundError {
    fn from(e: TileError) -> Self {
        Self::Tile(e)
    }
}

/// The height map for a [`GrassField`] of `size` metres whose entity stands at world `origin`
/// (its centre; `origin.y` the field's plane): `texels` a side, each texel the terrain's height
/// at its centre less `origin.y` (as [`height_map_image`] lays it out). The field samples the
/// map at its cell corners, so about one texel per cell corner is enough (a 0.5 m cell: `size /
/// 0.5 + 1` a side); the height query reads the pyramid's finest level, bilinearly.
///
/// [`GrassField`]: bevy_foliage::grass::GrassField
pub fn grass_ground_from_terrain(
    query: &mut HeightQuery,
    origin: Vec3,
    size: Vec2,
    texels: UVec2,
) -> Result<Image, TerrainGroundError> {
    if texels.x == 0 || texels.y == 0 || !(size.x > 0.0 && size.y > 0.0) {
        return Err(TerrainGroundError::Empty);
    }
    let mut heights = Vec::with_capacity((texels.x * texels.y) as usize);
    for j in 0..texels.y {
        for i in 0..texels.x {
            let uv = (Vec2::new(i as f32, j as f32) + 0.5) / texels.as_vec2();
            let local = (uv - 0.5) * size;
            let (x, z) = (
                origin.x as f64 + local.x as f64,
                origin.z as f64 + local.y as f64,
            );
            let h = query
                .height_at(x, z)?
                .ok_or(TerrainGroundError::OutsideData { x, z })?;
            heights.push(h - origin.y);
        }
    }
    // The same texel centres again, each mapped back to its index.
    let index = |p: Vec2| {
        let t = (p / size + 0.5) * texels.as_vec2() - 0.5;
        let (i, j) = (
            (t.x.round() as u32).min(texels.x - 1),
            (t.y.round() as u32).min(texels.y - 1),
        );
        (j * texels.x + i) as usize
    };
    Ok(height_map_image(size, texels, |p| heights[index(p)]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy_terrain_clip::builder::{BuildSettings, build_height_pyramid};
    use bevy_terrain_clip::dem::{DiskHeightSource, HeightScale};

    /// Over a tilted plane's pyramid, the field's map holds the plane less the field's height at
    /// every texel centre; a field reaching past the data is a clear error.
    #[test]
    fn the_field_reads_the_terrain_s_heights_at_its_texel_centres() {
        let dir = std::env::temp_dir().join(format!("grass_terrain_{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        let (origin, mpt) = ([1000.0f64, 5000.0f64], 1.0f64);
        let plane = |x: f64, z: f64| 100.0 + 0.3 * (x - origin[0]) - 0.2 * (z - origin[1]);
        let scale = HeightScale::covering(0.0, 200.0);
        let settings = BuildSettings {
            tile_size: 32,
            origin_m: origin,
            metres_per_texel: mpt,
            heights: scale,
            ..Default::default()
        };
        build_height_pyramid(&dir, [96, 80], &settings, plane).unwrap();
        let mut query = HeightQuery::new(DiskHeightSource::open(&dir).unwrap(), 8);
        let field = Vec3::new(1040.0, 95.0, 5030.0);
        let size = Vec2::new(40.0, 30.0);
        let texels = UVec2::new(21, 16);
        let image = grass_ground_from_terrain(&mut query, field, size, texels).unwrap();
        let bytes = image.data.as_ref().expect("the texels");
        let texel = |k: usize| f32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap());
        let mut worst = 0.0f64;
        for j in 0..texels.y {
            for i in 0..texels.x {
                let uv = (Vec2::new(i as f32, j as f32) + 0.5) / texels.as_vec2();
                let local = (uv - 0.5) * size;
                let want = plane(
                    field.x as f64 + local.x as f64,
                    field.z as f64 + local.y as f64,
                ) - field.y as f64;
                let got = texel((j * texels.x + i) as usize) as f64;
                worst = worst.max((got - want).abs());
            }
        }
        assert!(worst <= scale.scale_m + 1e-3, "worst {worst} m");
        // Half of it hanging off the data's east edge (x > 1096 m; the pyramid's padding
        // beyond is not data).
        let Err(off) = grass_ground_from_terrain(&mut query, field + Vec3::X * 60.0, size, texels)
        else {
            panic!("a field off the terrain read heights");
        };
        assert!(
            matches!(off, TerrainGroundError::OutsideData { x, .. } if x > 1096.0),
            "{off}"
        );
        assert!(
            off.to_string()
                .contains("outside the terrain's height data")
        );
        assert!(matches!(
            grass_ground_from_terrain(&mut query, field, size, UVec2::new(0, 4)),
            Err(TerrainGroundError::Empty)
        ));
        std::fs::remove_dir_all(&dir).ok();
    }
}
