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

/// A procedural meadow's density over `size` metres (x, z) centred on `centre`, as
/// `resolution²` texels: patches of thicker and thinner grass from a few octaves of smooth
/// value noise (seeded), cleared to nothing inside each `(centre, radius)` of `clearings` with a
/// soft metre-wide edge — e.g. around rocks, trunks and buildings.
pub fn meadow(
    resolution: u32,
    centre: [f32; 2],
    size: [f32; 2],
    clearings: &[([f32; 2], f32)],
    seed: u64,
) -> Result<DensityMap, DensityMapError> {
    let n = resolution.max(1);
    let lattice = |x: i64, z: i64, octave: u64| {
        let mut h = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (z as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
            ^ seed
                .wrapping_add(octave)
                .wrapping_mul(0x1656_67B1_9E37_79F9);
        h ^= h >> 31;
        h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h ^= h >> 29;
        (h >> 40) as f32 / (1u64 << 24) as f32
    };
    let noise = |x: f32, z: f32, octave: u64| {
        let (x0, z0) = (x.floor(), z.floor());
        let (fx, fz) = (x - x0, z - z0);
        let (sx, sz) = (fx * fx * (3.0 - 2.0 * fx), fz * fz * (3.0 - 2.0 * fz));
        let (x0, z0) = (x0 as i64, z0 as i64);
        let a =
            lattice(x0, z0, octave) + (lattice(x0 + 1, z0, octave) - lattice(x0, z0, octave)) * sx;
        let b = lattice(x0, z0 + 1, octave)
            + (lattice(x0 + 1, z0 + 1, octave) - lattice(x0, z0 + 1, octave)) * sx;
        a + (b - a) * sz
    };
    let min = [centre[0] - size[0] / 2.0, centre[1] - size[1] / 2.0];
    let mut values = Vec::with_capacity((n * n) as usize);
    for j in 0..n {
        for i in 0..n {
            let x = min[0] + (i as f32 + 0.5) / n as f32 * size[0];
            let z = min[1] + (j as f32 + 0.5) / n as f32 * size[1];
            // Patches about 12 m and 4 m across.
            let v = 0.65 * noise(x / 12.0, z / 12.0, 0) + 0.35 * noise(x / 4.0, z / 4.0, 1);
            let mut d = (0.35 + 1.1 * (v - 0.3)).clamp(0.0, 1.0);
            for &(c, r) in clearings {
                let dist = ((x - c[0]).powi(2) + (z - c[1]).powi(2)).sqrt();
                d *= ((dist - r) / 1.0).clamp(0.0, 1.0);
            }
            values.push(d);
        }
    }
    DensityMap::new(n, n, values, min, size)
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

    #[test]
    fn a_meadow_varies_and_is_cleared_where_asked() {
        let map = meadow(64, [0.0, 0.0], [40.0, 40.0], &[([5.0, 5.0], 3.0)], 7).unwrap();
        assert_eq!(map.density_at(5.0, 5.0), 0.0);
        assert_eq!(map.density_at(6.5, 5.0), 0.0);
        let values = map.values();
        let mean = values.iter().sum::<f32>() / values.len() as f32;
        let spread = values.iter().fold(0.0f32, |m, v| m.max((v - mean).abs()));
        assert!(mean > 0.3 && mean < 0.9, "{mean}");
        assert!(spread > 0.2, "{spread}");
        assert_ne!(map, meadow(64, [0.0, 0.0], [40.0, 40.0], &[], 8).unwrap());
    }
}
