//! The error type of the file-format layer.

use std::path::PathBuf;

/// Errors of the file-format layer. Every message says what was wrong with the input, in terms
/// a user who sent the file can act on.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// A file could not be opened, read, written or renamed.
    #[error("cannot {action} {path}: {source}")]
    File {
        action: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A width or height of zero.
    #[error("image is {width}×{height}; both dimensions must be at least 1")]
    ZeroDimension { width: usize, height: usize },
    /// A width or height above [`Limits::max_dim`](super::Limits::max_dim).
    #[error("image is {width}×{height}; each side may be at most {max_dim} pixels")]
    DimensionTooLarge {
        width: usize,
        height: usize,
        max_dim: usize,
    },
    /// More pixels than [`Limits::max_pixels`](super::Limits::max_pixels).
    #[error("image is {width}×{height} = {pixels} pixels; at most {max_pixels} pixels are allowed")]
    TooManyPixels {
        width: usize,
        height: usize,
        pixels: u128,
        max_pixels: usize,
    },
    /// A byte or value count that does not match the dimensions.
    #[error("{what} has {actual} {unit}; {formula} = {expected} expected")]
    Length {
        /// What was measured ("body", "file frame.raw", "data").
        what: String,
        /// "bytes" or "values".
        unit: &'static str,
        actual: usize,
        /// How the expectation was computed, e.g. "width×height×2" with numbers.
        formula: String,
        expected: u128,
    },
    /// The bytes are none of the supported formats.
    #[error(
        "unrecognised image format ({detail}); a PNG, TIFF, DNG or PGM (P5/P2) mosaic is expected"
    )]
    UnknownFormat { detail: String },
    /// A well-formed image whose pixel layout is not a single-channel mosaic (or not what a
    /// reader expects), e.g. "PNG is 8-bit RGB; a 16-bit (or 8-bit) grayscale mosaic is expected".
    #[error("{format} is {found}; {expected} is expected")]
    PixelLayout {
        format: &'static str,
        found: String,
        expected: &'static str,
    },
    /// A malformed, truncated or unsupported PNG stream.
    #[error("invalid PNG: {0}")]
    Png(String),
    /// A malformed, truncated or unsupported TIFF stream.
    #[error("invalid TIFF: {0}")]
    Tiff(String),
    /// A malformed, truncated or unsupported DNG (what it holds that is not taken is named).
    #[error("invalid DNG: {0}")]
    Dng(String),
    /// A malformed or truncated PGM stream.
    #[error("invalid PGM: {0}")]
    Pgm(String),
    /// A NaN or infinite sample in float input.
    #[error("{what}: pixel (x={x}, y={y}){channel} is {value}; only finite values are accepted")]
    NonFinite {
        what: &'static str,
        x: usize,
        y: usize,
        /// Empty for single-channel data, else e.g. " channel 2".
        channel: String,
        value: f32,
    },
    /// A raw-frame sidecar that is missing, unparsable or inconsistent.
    #[error("sidecar {path}: {msg}")]
    Sidecar { path: PathBuf, msg: String },
    /// Metadata that cannot describe a raw frame (levels, swing, CFA).
    #[error("invalid raw metadata: {0}")]
    InvalidMeta(String),
    /// An encoder failed (should not happen for valid input).
    #[error("cannot encode {format}: {msg}")]
    Encode { format: &'static str, msg: String },
}

/// Result alias of the file-format layer.
pub type IoResult<T> = Result<T, IoError>;

impl IoError {
    /// Whether the input's contents are at fault (a frame that does not decode or is not a
    /// frame), rather than the system (a file that cannot be read or written, an encoder that
    /// failed). The command line's exit code and the service's status both follow it.
    pub fn is_input(&self) -> bool {
        use IoError::*;
        match self {
            File { .. } | Encode { .. } => false,
            ZeroDimension { .. }
            | DimensionTooLarge { .. }
            | TooManyPixels { .. }
            | Length { .. }
            | UnknownFormat { .. }
            | PixelLayout { .. }
            | Png(_)
            | Tiff(_)
            | Dng(_)
            | Pgm(_)
            | NonFinite { .. }
            | Sidecar { .. }
            | InvalidMeta(_) => true,
        }
    }

    pub(crate) fn file(
        action: &'static str,
        path: &std::path::Path,
        source: std::io::Error,
    ) -> Self {
        IoError::File {
            action,
            path: path.to_path_buf(),
            source,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_that_is_no_frame_is_the_input_and_a_file_the_system() {
        assert!(
            IoError::ZeroDimension {
                width: 0,
                height: 4
            }
            .is_input()
        );
        let missing = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert!(!IoError::file("read", std::path::Path::new("x.raw"), missing).is_input());
    }
}
