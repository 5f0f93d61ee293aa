//! Size limits that every decoder checks before it allocates pixel memory.

use super::error::{IoError, IoResult};

/// Size limits for decoded images. Decoders check the declared dimensions against these before
/// allocating any pixel buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Maximum width × height.
    pub max_pixels: usize,
    /// Maximum width and maximum height.
    pub max_dim: usize,
}

/// The default pixel limit: 150 megapixels, room for the largest catalogue camera (the
/// Fujifilm GFX 100's stored image is 11664 × 8752 = 102.1 MP) and for the 150 MP backs.
pub const DEFAULT_MAX_PIXELS: usize = 150_000_000;

impl Default for Limits {
    /// `DEFAULT_MAX_PIXELS`, at most 30000 pixels per side.
    fn default() -> Self {
        Limits {
            max_pixels: DEFAULT_MAX_PIXELS,
            max_dim: 30_000,
        }
    }
}

/// Overhead allowed on top of the pixel payload when reading a whole file into memory
/// (headers, metadata, compression inefficiency).
const FILE_OVERHEAD_BYTES: usize = 64 << 20;

impl Limits {
    /// Checks declared dimensions; returns the pixel count width × height.
    pub fn check(&self, width: usize, height: usize) -> IoResult<usize> {
        if width == 0 || height == 0 {
            return Err(IoError::ZeroDimension { width, height });
        }
        if width > self.max_dim || height > self.max_dim {
            return Err(IoError::DimensionTooLarge {
                width,
                height,
                max_dim: self.max_dim,
            });
        }
        match width.checked_mul(height) {
            Some(n) if n <= self.max_pixels => Ok(n),
            _ => Err(IoError::TooManyPixels {
                width,
                height,
                pixels: width as u128 * height as u128,
                max_pixels: self.max_pixels,
            }),
        }
    }

    /// The default limits with at most `max_pixels` pixels.
    pub fn with_max_pixels(max_pixels: usize) -> Self {
        Limits {
            max_pixels,
            ..Limits::default()
        }
    }

    /// The largest file this limit lets a reader load into memory, for images with
    /// `bytes_per_pixel` bytes of payload per pixel.
    pub fn max_file_bytes(&self, bytes_per_pixel: usize) -> u64 {
        (self.max_pixels as u64)
            .saturating_mul(bytes_per_pixel as u64)
            .saturating_add(FILE_OVERHEAD_BYTES as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_enforces_each_limit() {
        let l = Limits {
            max_pixels: 100,
            max_dim: 20,
        };
        assert_eq!(l.check(10, 10).unwrap(), 100);
        assert!(matches!(l.check(0, 5), Err(IoError::ZeroDimension { .. })));
        assert!(matches!(l.check(5, 0), Err(IoError::ZeroDimension { .. })));
        assert!(matches!(
            l.check(21, 1),
            Err(IoError::DimensionTooLarge { .. })
        ));
        assert!(matches!(
            l.check(11, 10),
            Err(IoError::TooManyPixels { .. })
        ));
        let huge = Limits {
            max_pixels: usize::MAX,
            max_dim: usize::MAX,
        };
        let e = huge.check(usize::MAX, 3).unwrap_err();
        assert!(e.to_string().contains("pixels"), "{e}");
    }

    #[test]
    fn default_is_150_mp_and_takes_the_largest_catalogue_camera() {
        let l = Limits::default();
        assert_eq!(l.check(15_000, 10_000).unwrap(), 150_000_000);
        assert!(l.check(15_001, 10_000).is_err());
        assert!(l.check(30_001, 1).is_err());
        // Fujifilm GFX 100: 11664 × 8752 stored
        assert!(l.check(11_664, 8_752).is_ok());
        assert!(Limits::with_max_pixels(1000).check(11_664, 8_752).is_err());
        assert_eq!(Limits::with_max_pixels(1000).max_dim, l.max_dim);
    }
}
