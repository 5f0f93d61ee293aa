//! Mosaic input in any supported format, detected from the bytes: PNG, TIFF, DNG, PGM, and
//! `.raw` files with a sidecar.

use std::path::Path;

use super::atomic::read_capped;
use super::dng::{DngInfo, decode_dng, is_dng};
use super::error::{IoError, IoResult};
use super::limits::Limits;
use super::pgm::decode_pgm;
use super::png_format::{PNG_MAGIC, decode_png_mosaic};
use super::raw::{RawFrame, RawMeta, read_raw, read_sidecar};
use super::tiff_format::{TiffPixels, decode_tiff_mosaic};

/// A decoded single-channel mosaic: integer DN, or float values (e.g. volts).
#[derive(Debug, Clone, PartialEq)]
pub enum DecodedMosaic {
    /// Integer samples (8-bit input is widened, not rescaled).
    U16(RawFrame),
    /// 32-bit float samples, all finite, row-major.
    F32 {
        width: usize,
        height: usize,
        data: Vec<f32>,
    },
}

impl DecodedMosaic {
    /// (width, height).
    pub fn dims(&self) -> (usize, usize) {
        match self {
            DecodedMosaic::U16(f) => (f.width, f.height),
            DecodedMosaic::F32 { width, height, .. } => (*width, *height),
        }
    }
}

/// A supported mosaic container.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MosaicFormat {
    Png,
    Tiff,
    Pgm,
    /// A DNG raw file (a TIFF with a DNGVersion tag) holding a CFA image.
    Dng,
    /// Headerless little-endian u16 with a JSON sidecar.
    Raw,
}

/// What the decoder found besides the pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SourceInfo {
    pub format: MosaicFormat,
    /// Bits per stored sample: 8 or 16 (integers), 32 (float).
    pub bits_per_sample: u8,
    /// The largest value the container can hold: 255 or 65535 for 8/16-bit PNG and TIFF, the
    /// maxval of a PGM; `None` for float data, `.raw` (whose sidecar has the white level) and
    /// DNG (whose tags have it).
    pub max_value: Option<u16>,
}

/// The container format from the leading magic bytes (and, for TIFF, a DNGVersion tag in the
/// first IFD), if it is a supported one.
pub fn detect_format(bytes: &[u8]) -> Option<MosaicFormat> {
    if bytes.starts_with(PNG_MAGIC) {
        Some(MosaicFormat::Png)
    } else if is_dng(bytes) {
        Some(MosaicFormat::Dng)
    } else if bytes.starts_with(b"II*\0")
        || bytes.starts_with(b"MM\0*")
        || bytes.starts_with(b"II+\0")
        || bytes.starts_with(b"MM\0+")
    {
        Some(MosaicFormat::Tiff)
    } else if bytes.len() >= 2 && bytes[0] == b'P' && matches!(bytes[1], b'1'..=b'7') {
        Some(MosaicFormat::Pgm)
    } else {
        None
    }
}

/// Names well-known formats we do not take, else shows the first bytes.
fn unknown_format(bytes: &[u8]) -> IoError {
    let detail = if bytes.is_empty() {
        "the input is empty".to_string()
    } else if bytes.starts_with(b"\xff\xd8\xff") {
        "JPEG is lossy and not accepted for raw mosaics".to_string()
    } else if bytes.starts_with(b"GIF8") {
        "GIF is not accepted".to_string()
    } else if bytes.starts_with(b"BM") {
        "BMP is not accepted".to_string()
    } else if bytes.len() >= 12 && &bytes[4..8] == b"ftyp" {
        "HEIF/AVIF is not accepted".to_string()
    } else if bytes.starts_with(b"RIFF") {
        "RIFF/WebP is not accepted".to_string()
    } else {
        let head: Vec<String> = bytes.iter().take(8).map(|b| format!("{b:02x}")).collect();
        format!("first bytes {}", head.join(" "))
    };
    IoError::UnknownFormat { detail }
}

/// Decodes a mosaic from PNG (8/16-bit grayscale), TIFF (8/16-bit grayscale or 32-bit float
/// single channel), DNG (a CFA image, see [`decode_dng`](super::decode_dng)) or PGM (P5/P2),
/// detected from the magic bytes. Sizes are checked against `limits` before pixel memory is
/// allocated; float input must be finite. A DNG's levels and CFA come with
/// [`decode_mosaic_with_meta`].
pub fn decode_mosaic(bytes: &[u8], limits: &Limits) -> IoResult<DecodedMosaic> {
    decode_mosaic_with_info(bytes, limits).map(|(m, _)| m)
}

/// [`decode_mosaic`], also returning what was found (format, bit depth, maximum value).
pub fn decode_mosaic_with_info(
    bytes: &[u8],
    limits: &Limits,
) -> IoResult<(DecodedMosaic, SourceInfo)> {
    decode_mosaic_with_meta(bytes, limits).map(|l| (l.mosaic, l.info))
}

/// [`decode_mosaic`], with what the bytes say about the mosaic: for a DNG, the sidecar fields
/// (size, CFA, black and white levels, camera model as `sensor`, a voltage swing of 1 V, which
/// a DNG does not record) and the DNG's own metadata; `None` for the other formats.
pub fn decode_mosaic_with_meta(bytes: &[u8], limits: &Limits) -> IoResult<LoadedMosaic> {
    if detect_format(bytes) == Some(MosaicFormat::Dng) {
        let d = decode_dng(bytes, limits)?;
        let meta = d.raw_meta(1.0);
        return Ok(LoadedMosaic {
            info: SourceInfo {
                format: MosaicFormat::Dng,
                bits_per_sample: d.info.bits_per_sample,
                max_value: None,
            },
            mosaic: DecodedMosaic::U16(d.frame),
            meta: Some(meta),
            dng: Some(d.info),
        });
    }
    let (mosaic, info) = match detect_format(bytes) {
        Some(MosaicFormat::Png) => {
            let (frame, bits) = decode_png_mosaic(bytes, limits)?;
            let info = SourceInfo {
                format: MosaicFormat::Png,
                bits_per_sample: bits,
                max_value: Some(if bits == 16 { u16::MAX } else { 255 }),
            };
            Ok((DecodedMosaic::U16(frame), info))
        }
        Some(MosaicFormat::Tiff) => {
            let (width, height, px) = decode_tiff_mosaic(bytes, limits)?;
            let (mosaic, bits, max_value) = match px {
                TiffPixels::U8(v) => (
                    DecodedMosaic::U16(RawFrame {
                        width,
                        height,
                        data: v.into_iter().map(u16::from).collect(),
                    }),
                    8,
                    Some(255),
                ),
                TiffPixels::U16(data) => (
                    DecodedMosaic::U16(RawFrame {
                        width,
                        height,
                        data,
                    }),
                    16,
                    Some(u16::MAX),
                ),
                TiffPixels::F32(data) => (
                    DecodedMosaic::F32 {
                        width,
                        height,
                        data,
                    },
                    32,
                    None,
                ),
            };
            let info = SourceInfo {
                format: MosaicFormat::Tiff,
                bits_per_sample: bits,
                max_value,
            };
            Ok((mosaic, info))
        }
        Some(MosaicFormat::Pgm) => {
            let pgm = decode_pgm(bytes, limits)?;
            let info = SourceInfo {
                format: MosaicFormat::Pgm,
                bits_per_sample: if pgm.maxval > 255 { 16 } else { 8 },
                max_value: Some(pgm.maxval),
            };
            Ok((DecodedMosaic::U16(pgm.frame), info))
        }
        Some(MosaicFormat::Raw) | Some(MosaicFormat::Dng) | None => Err(unknown_format(bytes)),
    }?;
    Ok(LoadedMosaic {
        mosaic,
        info,
        meta: None,
        dng: None,
    })
}

/// A mosaic read from a file, with its sidecar metadata when there is one.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedMosaic {
    pub mosaic: DecodedMosaic,
    pub info: SourceInfo,
    /// The JSON sidecar: required for `.raw`; for a DNG, the sidecar fields its tags give
    /// (see [`decode_mosaic_with_meta`]); for other formats read when the file with the same
    /// stem and extension `.json` exists (its size must match the image).
    pub meta: Option<RawMeta>,
    /// A DNG's metadata (AsShotNeutral, calibration illuminants, colour matrices…).
    pub dng: Option<DngInfo>,
}

/// Reads a mosaic file: `.raw` (with its required sidecar, see [`read_raw`]) or any format
/// [`decode_mosaic`] takes (by magic bytes, whatever the extension). The file size is checked
/// against `limits` before reading. A DNG carries its own metadata: no sidecar is read for it.
pub fn read_mosaic(path: &Path, limits: &Limits) -> IoResult<LoadedMosaic> {
    let is_raw = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("raw"));
    if is_raw {
        let (frame, meta) = read_raw(path, limits)?;
        return Ok(LoadedMosaic {
            mosaic: DecodedMosaic::U16(frame),
            info: SourceInfo {
                format: MosaicFormat::Raw,
                bits_per_sample: 16,
                max_value: None,
            },
            meta: Some(meta),
            dng: None,
        });
    }
    let bytes = read_capped(path, limits.max_file_bytes(4))?;
    let loaded = decode_mosaic_with_meta(&bytes, limits).map_err(|e| match e {
        IoError::UnknownFormat { detail } => IoError::UnknownFormat {
            detail: format!(
                "{}: {detail}; a .raw file needs the .raw extension",
                path.display()
            ),
        },
        other => other,
    })?;
    if loaded.dng.is_some() {
        return Ok(loaded);
    }
    let LoadedMosaic { mosaic, info, .. } = loaded;
    let json = path.with_extension("json");
    let meta = if json.is_file() && json != path {
        let meta = read_sidecar(&json)?;
        if (meta.width, meta.height) != mosaic.dims() {
            let (w, h) = mosaic.dims();
            return Err(IoError::Sidecar {
                path: json,
                msg: format!(
                    "says {}×{} but {} is {w}×{h}",
                    meta.width,
                    meta.height,
                    path.display()
                ),
            });
        }
        Some(meta)
    } else {
        None
    };
    Ok(LoadedMosaic {
        mosaic,
        info,
        meta,
        dng: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detection() {
        assert_eq!(
            detect_format(b"\x89PNG\r\n\x1a\nxx"),
            Some(MosaicFormat::Png)
        );
        assert_eq!(detect_format(b"II*\0"), Some(MosaicFormat::Tiff));
        assert_eq!(detect_format(b"MM\0*"), Some(MosaicFormat::Tiff));
        assert_eq!(detect_format(b"P5"), Some(MosaicFormat::Pgm));
        assert_eq!(detect_format(b"P9"), None);
        assert_eq!(detect_format(b""), None);
    }

    #[test]
    fn unknown_formats_are_named() {
        let l = Limits::default();
        let e = decode_mosaic(b"\xff\xd8\xff\xe0junk", &l)
            .unwrap_err()
            .to_string();
        assert!(e.contains("JPEG"), "{e}");
        let e = decode_mosaic(&[1, 2, 3], &l).unwrap_err().to_string();
        assert!(e.contains("first bytes 01 02 03"), "{e}");
        let e = decode_mosaic(&[], &l).unwrap_err().to_string();
        assert!(e.contains("empty"), "{e}");
    }
}
