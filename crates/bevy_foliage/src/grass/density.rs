//! Density maps (Boulanger 2008, thesis §4.2.4): the local density `ld ∈ [0, 1]` of one grass
//! species over a rectangle of ground, bilinearly interpolated between texel centres. A blade of
//! the base patch is drawn where its density threshold `dth ≤ ld`, so the map sets how many of
//! the patch's blades grow there while the ones that do stay uniformly spread.

/// Why a density map cannot be made.
#[derive(Clone, Debug, PartialEq)]
pub enum DensityMapError {
    /// Width or height is zero.
    Empty,
    /// `values.len()` is not `width × height`.
    WrongSize {
        /// Texels given.
        len: usize,
        /// Width × height.
        expected: usize,
    },
    /// A value is NaN or infinite.
    NotFinite {
        /// Its texel index.
        index: usize,
    },
    /// The image's pixel format has no grey or first channel to read densities from.
    Format(String),
    /// The ground rectangle is empty or not finite.
    Extent,
}

impl std::fmt::Display for DensityMapError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Empty => write!(f, "a density map needs at least one texel"),
            Self::WrongSize { len, expected } => write!(
                f,
                "a density map of {expected} texels was given {len} values"
            ),
            Self::NotFinite { index } => write!(f, "density texel {index} is not finite"),
            Self::Format(format) => write!(
                f,
                "a density map is read from the first channel of an 8- or 16-bit or float image, \
                 not {format}"
            ),
            Self::Extent => write!(f, "a density map must cover a finite, non-empty rectangle"),
        }
    }
}

impl std::error::Error for DensityMapError {}

/// One species' local density over the ground rectangle `[min, min + size]` (x, z in metres).
#[derive(Clone, Debug, PartialEq)]
pub struct DensityMap {
    width: u32,
    height: u32,
    values: Vec<f32>,
    /// World (x, z) of the map's corner (texel (0, 0)'s outer corner).
    pub min: [f32; 2],
    /// World size (x, z) the map covers.
    pub size: [f32; 2],
}

impl DensityMap {
    /// A map of `width × height` densities (row-major, row 0 at `min.z`), each clamped to
    /// `[0, 1]`, covering `[min, min + size]`.
    pub fn new(
        width: u32,
        height: u32,
        values: Vec<f32>,
        min: [f32; 2],
        size: [f32; 2],
    ) -> Result<Self, DensityMapError> {
        if width == 0 || height == 0 {
            return Err(DensityMapError::Empty);
        }
        let expected = width as usize * height as usize;
        if values.len() != expected {
            return Err(DensityMapError::WrongSize {
                len: values.len(),
                expected,
            });
        }
        if let Some(index) = values.iter().position(|v| !v.is_finite()) {
            return Err(DensityMapError::NotFinite { index });
        }
        if !(min.iter().chain(&size).all(|v| v.is_finite()) && size[0] > 0.0 && size[1] > 0.0) {
            return Err(DensityMapError::Extent);
        }
        Ok(Self {
            width,
            height,
            values: values.into_iter().map(|v| v.clamp(0.0, 1.0)).collect(),
            min,
            size,
        })
    }

    /// The same density everywhere over the rectangle.
    pub fn uniform(density: f32, min: [f32; 2], size: [f32; 2]) -> Result<Self, DensityMapError> {
        Self::new(1, 1, vec![density], min, size)
    }

    /// A map from a grey image's bytes: `channels` interleaved channels of `bits` 8 or 16 (little
    /// endian) or 32 (float) per texel, the first one read as the density (0 … max → 0 … 1).
    pub fn from_pixels(
        width: u32,
        height: u32,
        bytes: &[u8],
        channels: u32,
        bits: u32,
        min: [f32; 2],
        size: [f32; 2],
    ) -> Result<Self, DensityMapError> {
        let stride = match (channels, bits) {
            (1..=4, 8 | 16 | 32) => (channels * bits / 8) as usize,
            _ => {
                return Err(DensityMapError::Format(format!(
                    "{channels} channels of {bits} bits"
                )));
            }
        };
        let expected = width as usize * height as usize;
        if bytes.len() != expected * stride {
            return Err(DensityMapError::WrongSize {
                len: bytes.len() / stride.max(1),
                expected,
            });
        }
        let values = bytes
            .chunks_exact(stride)
            .map(|p| match bits {
                8 => p[0] as f32 / 255.0,
                16 => u16::from_le_bytes([p[0], p[1]]) as f32 / 65535.0,
                _ => f32::from_le_bytes([p[0], p[1], p[2], p[3]]),
            })
            .collect();
        Self::new(width, height, values, min, size)
    }

    /// The densities, row-major (row 0 at `min.z`), each in `[0, 1]`.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// Texels across and down.
    pub fn dimensions(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The density of texel (x, z), clamped to the map.
    pub fn texel(&self, x: i64, z: i64) -> f32 {
        let x = x.clamp(0, self.width as i64 - 1) as usize;
        let z = z.clamp(0, self.height as i64 - 1) as usize;
        self.values[z * self.width as usize + x]
    }

    /// The local density at world (x, z): bilinear between texel centres, clamped at the edges
    /// of the map; zero outside its rectangle.
    pub fn density_at(&self, x: f32, z: f32) -> f32 {
        let u = (x - self.min[0]) / self.size[0];
        let v = (z - self.min[1]) / self.size[1];
        if !(0.0..=1.0).contains(&u) || !(0.0..=1.0).contains(&v) {
            return 0.0;
        }
        let tx = u * self.width as f32 - 0.5;
        let tz = v * self.height as f32 - 0.5;
        let (x0, z0) = (tx.floor(), tz.floor());
        let (fx, fz) = (tx - x0, tz - z0);
        let (x0, z0) = (x0 as i64, z0 as i64);
        let lerp = |a: f32, b: f32, f: f32| a + (b - a) * f;
        lerp(
            lerp(self.texel(x0, z0), self.texel(x0 + 1, z0), fx),
            lerp(self.texel(x0, z0 + 1), self.texel(x0 + 1, z0 + 1), fx),
            fz,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn density_is_bilinear_between_texel_centres_and_zero_outside() {
        // 2 × 1 texels over 4 m × 2 m: centres at x = 1 (0.2) and x = 3 (1.0).
        let map = DensityMap::new(2, 1, vec![0.2, 1.0], [0.0, 0.0], [4.0, 2.0]).unwrap();
        assert!((map.density_at(1.0, 1.0) - 0.2).abs() < 1e-6);
        assert!((map.density_at(2.0, 0.3) - 0.6).abs() < 1e-6);
        assert!(
            (map.density_at(3.5, 1.9) - 1.0).abs() < 1e-6,
            "clamped past the last centre"
        );
        assert_eq!(map.density_at(-0.1, 1.0), 0.0);
        assert_eq!(map.density_at(2.0, 2.5), 0.0);
    }

    #[test]
    fn bad_maps_are_clear_errors() {
        assert_eq!(
            DensityMap::new(2, 2, vec![0.0; 3], [0.0; 2], [1.0; 2]),
            Err(DensityMapError::WrongSize {
                len: 3,
                expected: 4
            })
        );
        assert_eq!(
            DensityMap::new(0, 2, vec![], [0.0; 2], [1.0; 2]),
            Err(DensityMapError::Empty)
        );
        assert_eq!(
            DensityMap::new(1, 2, vec![0.5, f32::NAN], [0.0; 2], [1.0; 2]),
            Err(DensityMapError::NotFinite { index: 1 })
        );
        assert_eq!(
            DensityMap::uniform(0.5, [0.0; 2], [0.0, 1.0]),
            Err(DensityMapError::Extent)
        );
        assert!(matches!(
            DensityMap::from_pixels(2, 2, &[0; 8], 1, 12, [0.0; 2], [1.0; 2]),
            Err(DensityMapError::Format(_))
        ));
        assert!(matches!(
            DensityMap::from_pixels(2, 2, &[0; 7], 2, 8, [0.0; 2], [1.0; 2]),
            Err(DensityMapError::WrongSize { .. })
        ));
        // Out-of-range densities are clamped, not refused.
        let map = DensityMap::new(1, 1, vec![3.0], [0.0; 2], [1.0; 2]).unwrap();
        assert_eq!(map.texel(0, 0), 1.0);
    }

    #[test]
    fn pixels_of_each_depth_read_as_densities() {
        let grey8 = DensityMap::from_pixels(2, 1, &[0, 255], 1, 8, [0.0; 2], [2.0, 1.0]).unwrap();
        assert_eq!((grey8.texel(0, 0), grey8.texel(1, 0)), (0.0, 1.0));
        // RGBA8: the red channel.
        let rgba =
            DensityMap::from_pixels(1, 1, &[51, 9, 9, 255], 4, 8, [0.0; 2], [1.0; 2]).unwrap();
        assert!((rgba.texel(0, 0) - 0.2).abs() < 1e-6);
        let grey16 =
            DensityMap::from_pixels(1, 1, &32768u16.to_le_bytes(), 1, 16, [0.0; 2], [1.0; 2])
                .unwrap();
        assert!((grey16.texel(0, 0) - 0.5).abs() < 1e-4);
        let float =
            DensityMap::from_pixels(1, 1, &0.25f32.to_le_bytes(), 1, 32, [0.0; 2], [1.0; 2])
                .unwrap();
        assert_eq!(float.texel(0, 0), 0.25);
    }
}
