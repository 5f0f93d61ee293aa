//! The output formats and their one encoder. The service maps `Accept` (and `tiff=`) onto an
//! [`OutputFormat`] by its media type, `l3 render` maps the output file's extension (and
//! `--tiff`); both renderers' pixels are encoded by [`encode`], with the PNG compression and
//! JPEG options of [`Encoding`].

use std::str::FromStr;

use crate::io::{
    IoError, JpegOptions, PngCompression, encode_jpeg_rgb8, encode_png_rgb8, encode_ppm_rgb8,
    encode_tiff_f32_rgb, encode_tiff_rgb16, ppm_header,
};
use crate::l3::render::{Frame, xyz_to_srgb8, xyz_to_srgb16};

/// What a TIFF output holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TiffKind {
    /// Float XYZ (scene-referred).
    #[default]
    Xyz,
    /// 16-bit sRGB.
    Srgb16,
}

/// A TIFF kind that is neither `xyz` nor `srgb16`; shown as `'<name>': expected …` for the
/// caller to prefix with its option's name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{0}': expected xyz or srgb16")]
pub struct UnknownTiffKind(pub String);

impl FromStr for TiffKind {
    type Err = UnknownTiffKind;

    /// `xyz` or `srgb16`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "xyz" => Ok(TiffKind::Xyz),
            "srgb16" => Ok(TiffKind::Srgb16),
            other => Err(UnknownTiffKind(other.to_string())),
        }
    }
}

/// The encoded output formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    /// 8-bit sRGB PNG.
    Png,
    /// 8-bit sRGB JPEG with an sRGB ICC profile.
    Jpeg,
    /// 8-bit sRGB binary PPM (a header and the pixels).
    Ppm,
    /// A TIFF: float XYZ or 16-bit sRGB.
    Tiff(TiffKind),
    /// Interleaved little-endian f32 XYZ, no header.
    F32,
}

impl OutputFormat {
    /// One format per media type, PNG (the default) first.
    pub const BY_MEDIA_TYPE: [OutputFormat; 5] = [
        OutputFormat::Png,
        OutputFormat::Jpeg,
        OutputFormat::Ppm,
        OutputFormat::Tiff(TiffKind::Xyz),
        OutputFormat::F32,
    ];

    /// The media type of the encoded output.
    pub fn media_type(self) -> &'static str {
        match self {
            OutputFormat::Png => "image/png",
            OutputFormat::Jpeg => "image/jpeg",
            OutputFormat::Ppm => "image/x-portable-pixmap",
            OutputFormat::Tiff(_) => "image/tiff",
            OutputFormat::F32 => "application/octet-stream",
        }
    }

    /// The format of a media type (lower case, no parameters); a TIFF holds float XYZ.
    pub fn from_media_type(media: &str) -> Option<Self> {
        Self::BY_MEDIA_TYPE
            .into_iter()
            .find(|f| f.media_type() == media)
    }

    /// The format of a file extension (any case): `png`, `jpg`/`jpeg`, `ppm`, `tif`/`tiff`
    /// (float XYZ), `raw`/`bin`/`f32`.
    pub fn from_extension(ext: &str) -> Option<Self> {
        match ext.to_ascii_lowercase().as_str() {
            "png" => Some(OutputFormat::Png),
            "jpg" | "jpeg" => Some(OutputFormat::Jpeg),
            "ppm" => Some(OutputFormat::Ppm),
            "tif" | "tiff" => Some(OutputFormat::Tiff(TiffKind::Xyz)),
            "raw" | "bin" | "f32" => Some(OutputFormat::F32),
            _ => None,
        }
    }

    /// A TIFF of `kind`; any other format unchanged.
    pub fn with_tiff(self, kind: TiffKind) -> Self {
        match self {
            OutputFormat::Tiff(_) => OutputFormat::Tiff(kind),
            other => other,
        }
    }

    /// Whether the output is display-referred (needs a white level).
    pub fn needs_white(self) -> bool {
        !matches!(self, OutputFormat::Tiff(TiffKind::Xyz) | OutputFormat::F32)
    }

    /// Whether the output is 8-bit sRGB, which the fast renderer writes straight from its
    /// kernels.
    pub fn is_srgb8(self) -> bool {
        matches!(
            self,
            OutputFormat::Png | OutputFormat::Jpeg | OutputFormat::Ppm
        )
    }
}

/// What a renderer produced, before encoding.
pub enum Pixels {
    /// 8-bit sRGB (for PNG, JPEG and PPM only).
    Srgb8(Frame),
    /// Interleaved XYZ.
    Xyz(Vec<f32>),
}

/// Rendered pixels with their size and white.
pub struct Image {
    pub pixels: Pixels,
    pub width: usize,
    pub height: usize,
    /// The Y mapped to white (ignored by scene-referred outputs).
    pub white_y: f64,
}

/// An encoded output: one buffer, or a PPM header followed by the rendered frame itself (so
/// a server can send the pixels from the render's buffer).
pub enum Encoded {
    Whole(Vec<u8>),
    Framed { header: Vec<u8>, frame: Frame },
}

impl Encoded {
    pub fn len(&self) -> usize {
        match self {
            Encoded::Whole(b) => b.len(),
            Encoded::Framed { header, frame } => header.len() + frame.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The output as one buffer.
    pub fn into_vec(self) -> Vec<u8> {
        match self {
            Encoded::Whole(b) => b,
            Encoded::Framed { mut header, frame } => {
                header.extend_from_slice(&frame);
                header
            }
        }
    }
}

/// How the compressed formats are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Encoding {
    pub png: PngCompression,
    pub jpeg: JpegOptions,
}

/// `image` encoded as `format` (PNG and JPEG as `how` says).
pub fn encode(format: OutputFormat, image: Image, how: Encoding) -> Result<Encoded, IoError> {
    use OutputFormat::*;
    let png = how.png;
    let Image {
        pixels,
        width: w,
        height: h,
        white_y: wy,
    } = image;
    Ok(match pixels {
        // 8-bit pixels are rendered for PNG, JPEG and PPM only
        Pixels::Srgb8(frame) if format == Ppm => Encoded::Framed {
            header: ppm_header(w, h)?,
            frame,
        },
        Pixels::Srgb8(rgb) if format == Jpeg => {
            Encoded::Whole(encode_jpeg_rgb8(w, h, &rgb, how.jpeg)?)
        }
        Pixels::Srgb8(rgb) => Encoded::Whole(encode_png_rgb8(w, h, &rgb, png)?),
        Pixels::Xyz(xyz) => Encoded::Whole(match format {
            Png => encode_png_rgb8(w, h, &xyz_to_srgb8(&xyz, wy), png)?,
            Jpeg => encode_jpeg_rgb8(w, h, &xyz_to_srgb8(&xyz, wy), how.jpeg)?,
            Ppm => encode_ppm_rgb8(w, h, &xyz_to_srgb8(&xyz, wy))?,
            Tiff(TiffKind::Srgb16) => encode_tiff_rgb16(w, h, &xyz_to_srgb16(&xyz, wy))?,
            Tiff(TiffKind::Xyz) => encode_tiff_f32_rgb(w, h, &xyz)?,
            F32 => {
                let mut b = crate::buffers::with_capacity(xyz.len() * 4);
                b.extend(xyz.iter().flat_map(|v| v.to_le_bytes()));
                b
            }
        }),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_map_onto_one_format() {
        assert_eq!(
            OutputFormat::from_media_type("image/tiff"),
            Some(OutputFormat::Tiff(TiffKind::Xyz))
        );
        assert_eq!(OutputFormat::from_media_type("image/webp"), None);
        for f in OutputFormat::BY_MEDIA_TYPE {
            assert_eq!(OutputFormat::from_media_type(f.media_type()), Some(f));
        }
        assert_eq!(
            OutputFormat::from_extension("TIF").map(|f| f.with_tiff(TiffKind::Srgb16)),
            Some(OutputFormat::Tiff(TiffKind::Srgb16))
        );
        assert_eq!(OutputFormat::from_extension("bin"), Some(OutputFormat::F32));
        assert_eq!(
            OutputFormat::from_extension("JPEG"),
            Some(OutputFormat::Jpeg)
        );
        assert_eq!(OutputFormat::from_extension("webp"), None);
        assert!(OutputFormat::Jpeg.is_srgb8() && OutputFormat::Jpeg.needs_white());
        assert_eq!(
            OutputFormat::Png.with_tiff(TiffKind::Srgb16),
            OutputFormat::Png
        );
        assert_eq!("srgb16".parse::<TiffKind>().unwrap(), TiffKind::Srgb16);
        assert_eq!(
            "XYZ".parse::<TiffKind>().unwrap_err().to_string(),
            "'XYZ': expected xyz or srgb16"
        );
        assert!(OutputFormat::Tiff(TiffKind::Srgb16).needs_white());
        assert!(!OutputFormat::Tiff(TiffKind::Xyz).needs_white());
    }

    /// The reference renderer's bytes (its own encoder until now) and the shared encoder's
    /// agree for f32.
    #[test]
    fn f32_is_little_endian_xyz() {
        let xyz = vec![0.5f32, 1.0, -2.0];
        let out = encode(
            OutputFormat::F32,
            Image {
                pixels: Pixels::Xyz(xyz.clone()),
                width: 1,
                height: 1,
                white_y: 1.0,
            },
            Encoding {
                png: PngCompression::Fast,
                jpeg: JpegOptions::default(),
            },
        )
        .unwrap()
        .into_vec();
        let want: Vec<u8> = xyz.iter().flat_map(|v| v.to_le_bytes()).collect();
        assert_eq!(out, want);
    }
}
