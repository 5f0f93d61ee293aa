//! DNG raw files: a reader for Bayer and RGBW CFA images and a writer for simulated mosaics.
//!
//! Our own reader, because no crate does the job: rawler maps CFA colour codes 0–5 and
//! panics on 6 (white), rawloader takes only codes 0–2, and the `tiff` crate reads tags but
//! refuses to decode CFA (32803) photometric data and has no lossless JPEG. This one walks
//! the IFDs itself (bounded, never panicking: [`ifd`]), decodes uncompressed and lossless
//! JPEG (compression 7, [`ljpeg`]) strips or tiles of 8–16 bits, in IFD0 or in a SubIFD with
//! NewSubFileType 0, and applies LinearizationTable, ActiveArea, BlackLevel (scalar, per
//! CFA position with BlackLevelRepeatDim, and BlackLevelDeltaH/V), DefaultCrop and the
//! opcodes it supports ([`opcodes`]: FixBadPixelsConstant, GainMap; others are reported in
//! [`DngInfo::skipped_opcodes`]). The result
//! is what the `.raw` + JSON sidecar path gives for the same mosaic: a [`RawFrame`] and a
//! [`RawMeta`] with the CFA (`"RG/WB"`), one black level and the white level, so a DNG renders
//! exactly as its raw twin does.
//!
//! Files as common writers make them (PiDNG writes no CFAPlaneColor unless asked, and some
//! tags twice) are read where their intent is unambiguous: `docs/dng.md`, "Leniencies", lists
//! each reading; contradictions and every size, offset and count check stay errors.
//!
//! The writer uses the `tiff` crate's encoder: one uncompressed 16-bit strip with the CFA,
//! levels, AsShotNeutral and CalibrationIlluminant1 tags.

mod chunks;
mod ifd;
mod ljpeg;
mod opcodes;
mod read;

use std::io::Cursor;
use std::path::Path;

use tiff::encoder::{Rational, SRational, TiffEncoder};
use tiff::tags::Tag;

use super::atomic::write_bytes_atomic;
use super::error::{IoError, IoResult};
use super::limits::Limits;
use super::raw::{RawFrame, RawMeta, check_len};

pub use read::{is_cfa_tiff_without_dng_version, is_dng};

/// The letter of a DNG CFA colour code this crate takes: 0 R, 1 G, 2 B, 6 W.
fn cfa_letter(code: u64) -> Option<char> {
    match code {
        0 => Some('R'),
        1 => Some('G'),
        2 => Some('B'),
        6 => Some('W'),
        _ => None,
    }
}

/// The DNG colour code of a CFA letter (the inverse of [`cfa_letter`]).
fn cfa_code(letter: char) -> Option<u8> {
    match letter {
        'R' => Some(0),
        'G' => Some(1),
        'B' => Some(2),
        'W' => Some(6),
        _ => None,
    }
}

/// " (cyan)" etc. for the DNG colour codes this crate refuses.
fn code_name(code: u64) -> &'static str {
    match code {
        3 => " (cyan)",
        4 => " (magenta)",
        5 => " (yellow)",
        _ => "",
    }
}

/// What a DNG says besides the pixels.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DngInfo {
    /// DNGVersion, e.g. `[1, 4, 0, 0]`.
    pub version: [u8; 4],
    /// Bits per stored sample (8–16).
    pub bits_per_sample: u8,
    /// 1 (uncompressed) or 7 (lossless JPEG).
    pub compression: u16,
    /// CFAPlaneColor as letters, e.g. `"RGBW"`: the order of AsShotNeutral and the colour
    /// matrices' rows. Without the tag: the colours CFAPattern uses, in the order R, G, B, W
    /// (what [`encode_dng`] writes; `"RGB"` for a Bayer pattern, the DNG default).
    pub plane_colors: String,
    /// BlackLevel as stored, one per BlackLevelRepeatDim position.
    pub black_levels: Vec<f64>,
    /// AsShotNeutral: the camera's response to white under the scene light, one value per
    /// plane (in `plane_colors` order), usually with a maximum of 1.
    pub as_shot_neutral: Option<Vec<f64>>,
    /// AsShotWhiteXY: the scene light's white as a CIE 1931 chromaticity (x, y); the DNG
    /// alternative to AsShotNeutral.
    pub as_shot_white_xy: Option<[f64; 2]>,
    /// CalibrationIlluminant1/2 as EXIF LightSource codes.
    pub calibration_illuminants: [Option<u16>; 2],
    /// ColorMatrix1/2 (XYZ → camera), row-major, `planes × 3` values.
    pub color_matrices: [Option<Vec<f64>>; 2],
    /// UniqueCameraModel, Make and Model (IFD0), trimmed of NULs and spaces; `None` when
    /// absent or empty.
    pub unique_camera_model: Option<String>,
    /// Make (271) and Model (272) of IFD0, trimmed of NULs and spaces.
    pub make: Option<String>,
    pub model: Option<String>,
    /// The opcodes of OpcodeList1, 2 and 3 the reader did not apply (it applies
    /// FixBadPixelsConstant in OpcodeList1 and GainMap in OpcodeList2), e.g.
    /// `"WarpRectilinear (OpcodeList3, optional)"`.
    pub skipped_opcodes: Vec<String>,
}

/// What a DNG says of its camera: UniqueCameraModel, Make and Model of IFD0 (each trimmed of
/// NULs and spaces; an empty one is absent).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DngCamera {
    pub unique_camera_model: Option<String>,
    pub make: Option<String>,
    pub model: Option<String>,
}

/// The camera a DNG names, from IFD0's tags alone: no pixel is read or decoded, so a render
/// can choose its table before it decodes the frame.
pub fn read_camera(bytes: &[u8]) -> IoResult<DngCamera> {
    read::camera(bytes)
}

impl DngInfo {
    /// The camera the DNG names.
    pub fn camera(&self) -> DngCamera {
        DngCamera {
            unique_camera_model: self.unique_camera_model.clone(),
            make: self.make.clone(),
            model: self.model.clone(),
        }
    }

    /// The light AsShotWhiteXY names, as an illuminant spec (`xy:x,y`), when the file has no
    /// AsShotNeutral (which then says the light instead).
    pub fn white_xy_light(&self) -> Option<String> {
        if self.as_shot_neutral.is_some() {
            return None;
        }
        self.as_shot_white_xy
            .map(|[x, y]| format!("xy:{x:.6},{y:.6}"))
    }

    /// AsShotNeutral as (channel letter, value) pairs.
    pub fn neutral(&self) -> Option<Vec<(String, f64)>> {
        self.as_shot_neutral.as_ref().map(|n| {
            self.plane_colors
                .chars()
                .zip(n)
                .map(|(c, &v)| (c.to_string(), v))
                .collect()
        })
    }
}

/// A decoded DNG: the mosaic cropped to ActiveArea and DefaultCrop, linearised, with one
/// black level (per-position blacks are folded in, see [`decode_dng`]).
#[derive(Debug, Clone, PartialEq)]
pub struct DngImage {
    pub frame: RawFrame,
    /// The CFA from the crop's top-left pixel, rows separated by '/', e.g. `"RG/WB"`.
    pub cfa: String,
    pub black_level: u16,
    pub white_level: u16,
    pub info: DngInfo,
}

impl DngImage {
    /// The sidecar metadata the same mosaic would have as `.raw`: size, CFA, levels and the
    /// camera model as `sensor`. A DNG does not record the sensor's voltage swing; the given
    /// one is used (readers scale DN to the table's own swing anyway).
    pub fn raw_meta(&self, voltage_swing: f64) -> RawMeta {
        let mut m = RawMeta::new(
            self.frame.width,
            self.frame.height,
            self.cfa.clone(),
            self.black_level,
            self.white_level,
            voltage_swing,
        );
        m.sensor = self.info.unique_camera_model.clone();
        m
    }
}

/// Decodes a DNG's full-resolution CFA image (IFD0, or the first SubIFD with NewSubFileType
/// 0): uncompressed or lossless JPEG, strips or tiles, 8–16 bits per sample; CFA colours R,
/// G, B and W. The mosaic is linearised (LinearizationTable), cropped to ActiveArea then
/// DefaultCrop, and its CFA string is the pattern seen from the crop's origin.
///
/// When every pixel has the same whole-numbered black level the values are kept as stored;
/// otherwise (BlackLevel per CFA position, fractional, or with BlackLevelDeltaH/V) each pixel
/// is rescaled from its own black to the lowest one, floored to an integer:
/// `round((v − b) · (white − b₀) / (white − b)) + b₀`, so that one black level describes the
/// frame. Sizes are checked against `limits` before any pixel memory is allocated.
pub fn decode_dng(bytes: &[u8], limits: &Limits) -> IoResult<DngImage> {
    read::decode(bytes, limits)
}

/// What a written DNG records besides the mosaic and its sidecar fields.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DngWriteInfo {
    /// UniqueCameraModel (the sensor's name); `meta.sensor` when `None`.
    pub camera_model: Option<String>,
    /// The camera's response to white under the scene light, per channel letter (any order,
    /// any scale: written normalised to a maximum of 1, in CFAPlaneColor order).
    pub as_shot_neutral: Option<Vec<(String, f64)>>,
    /// CalibrationIlluminant1, an EXIF LightSource code (see [`exif_light_source`]).
    pub calibration_illuminant: Option<u16>,
    /// ColorMatrix1: per channel letter (any order), the row mapping XYZ to that channel's
    /// response under the scene light; written in CFAPlaneColor order.
    pub color_matrix: Option<Vec<(String, [f64; 3])>>,
}

/// The EXIF LightSource code of a standard illuminant name, for CalibrationIlluminant:
/// A 17, D50 23, D55 20, D65 21, D75 22, measured Tungsten 3 (incandescent), measured
/// Fluorescent 2, F2 14 (cool white fluorescent); `None` for anything else.
pub fn exif_light_source(name: &str) -> Option<u16> {
    Some(match name.trim().to_ascii_uppercase().as_str() {
        "A" => 17,
        "D50" => 23,
        "D55" => 20,
        "D65" => 21,
        "D75" => 22,
        "TUNGSTEN" => 3,
        "FLUORESCENT" => 2,
        "F2" => 14,
        _ => return None,
    })
}

fn encode_err(e: tiff::TiffError) -> IoError {
    IoError::Encode {
        format: "DNG",
        msg: e.to_string(),
    }
}

/// CFAPlaneColor order: R, G, B, then W, of the colours the CFA uses.
const PLANE_ORDER: [char; 4] = ['R', 'G', 'B', 'W'];

/// The colour planes of a CFA that uses the colours for which `uses` holds: R, G, B, then W.
/// The writer's CFAPlaneColor, and the reader's when a file has none.
fn plane_order(uses: impl Fn(char) -> bool) -> Vec<char> {
    PLANE_ORDER.into_iter().filter(|&p| uses(p)).collect()
}

/// An uncompressed 16-bit DNG (version 1.4) of `frame`: CFAPattern, CFARepeatPatternDim and
/// CFAPlaneColor from `meta.cfa` (one-letter channels R, G, B, W), BlackLevel and WhiteLevel
/// from `meta`, and what `info` gives.
pub fn encode_dng(frame: &RawFrame, meta: &RawMeta, info: &DngWriteInfo) -> IoResult<Vec<u8>> {
    let (w, h) = (frame.width, frame.height);
    check_len("frame data", frame.data.len(), w, h, 1, "values")?;
    if (meta.width, meta.height) != (w, h) {
        return Err(IoError::InvalidMeta(format!(
            "metadata says {}×{} but the frame is {w}×{h}",
            meta.width, meta.height
        )));
    }
    meta.validate()?;
    let rows = meta.cfa_cells()?;
    let mut pattern = Vec::new();
    for row in &rows {
        for name in row {
            let mut letters = name.chars();
            let code = match (letters.next(), letters.next()) {
                (Some(l), None) => cfa_code(l),
                _ => None,
            };
            pattern.push(code.ok_or_else(|| {
                IoError::InvalidMeta(format!(
                    "cfa {:?}: a DNG CFA holds R, G, B and W; '{name}' has no DNG colour code",
                    meta.cfa
                ))
            })?);
        }
    }
    let planes = plane_order(|p| meta.cfa.contains(p));
    let plane_codes: Vec<u8> = planes.iter().filter_map(|&p| cfa_code(p)).collect();
    let bytes = u32::try_from(w as u64 * h as u64 * 2).map_err(|_| IoError::Encode {
        format: "DNG",
        msg: format!("a {w}×{h} frame does not fit a classic TIFF strip"),
    })?;
    let tags = DngTags {
        cfa_rows: rows.len(),
        pattern,
        plane_codes,
        strip_bytes: bytes,
        neutral: as_shot_neutral(info, &planes)?,
        color_matrix: color_matrix(info, &planes)?,
        model: camera_model(info, meta),
    };
    write_tiff(frame, meta, info, &tags)
}

/// The tags of a written DNG worked out from the metadata.
struct DngTags {
    /// CFA pattern rows, and the pattern's colour codes row by row.
    cfa_rows: usize,
    pattern: Vec<u8>,
    /// CFAPlaneColor.
    plane_codes: Vec<u8>,
    /// The one strip's size.
    strip_bytes: u32,
    neutral: Option<Vec<Rational>>,
    color_matrix: Option<Vec<SRational>>,
    model: String,
}

/// AsShotNeutral in CFAPlaneColor order, normalised to a maximum of 1.
fn as_shot_neutral(info: &DngWriteInfo, planes: &[char]) -> IoResult<Option<Vec<Rational>>> {
    let Some(n) = &info.as_shot_neutral else {
        return Ok(None);
    };
    let mut v = Vec::with_capacity(planes.len());
    for p in planes {
        let x = n
            .iter()
            .find(|(name, _)| name.len() == 1 && name.starts_with(*p))
            .map(|(_, x)| *x)
            .ok_or_else(|| IoError::InvalidMeta(format!("AsShotNeutral has no value for {p}")))?;
        v.push(x);
    }
    let max = v.iter().copied().fold(0.0, f64::max);
    if !(max.is_finite() && max > 0.0) || v.iter().any(|x| x.is_nan() || *x <= 0.0) {
        return Err(IoError::InvalidMeta(format!(
            "AsShotNeutral {v:?}: positive finite values are expected"
        )));
    }
    Ok(Some(
        v.iter()
            .map(|x| Rational {
                n: (x / max * 1e6).round().max(1.0) as u32,
                d: 1_000_000,
            })
            .collect::<Vec<_>>(),
    ))
}

/// ColorMatrix1, rows in CFAPlaneColor order.
fn color_matrix(info: &DngWriteInfo, planes: &[char]) -> IoResult<Option<Vec<SRational>>> {
    let Some(m) = &info.color_matrix else {
        return Ok(None);
    };
    let mut v = Vec::with_capacity(3 * planes.len());
    for p in planes {
        let row = m
            .iter()
            .find(|(name, _)| name.len() == 1 && name.starts_with(*p))
            .map(|(_, r)| *r)
            .ok_or_else(|| IoError::InvalidMeta(format!("ColorMatrix1 has no row for {p}")))?;
        for x in row {
            if !(x.is_finite() && x.abs() < 1e4) {
                return Err(IoError::InvalidMeta(format!(
                    "ColorMatrix1 row {p} holds {x}; finite values below 1e4 are expected"
                )));
            }
            v.push(SRational {
                n: (x * 1e4).round() as i32,
                d: 10_000,
            });
        }
    }
    Ok(Some(v))
}

/// UniqueCameraModel: an ASCII tag, other characters become '?'.
fn camera_model(info: &DngWriteInfo, meta: &RawMeta) -> String {
    info.camera_model
        .clone()
        .or_else(|| meta.sensor.clone())
        .unwrap_or_else(|| "l3 simulated sensor".to_string())
        .chars()
        .map(|c| {
            if c.is_ascii() && !c.is_ascii_control() {
                c
            } else {
                '?'
            }
        })
        .collect()
}

/// The TIFF: one directory, the frame as one strip, and the tags.
fn write_tiff(
    frame: &RawFrame,
    meta: &RawMeta,
    info: &DngWriteInfo,
    tags: &DngTags,
) -> IoResult<Vec<u8>> {
    let (w, h) = (frame.width, frame.height);
    let mut out = Cursor::new(Vec::with_capacity(tags.strip_bytes as usize + 4096));
    {
        let mut enc = TiffEncoder::new(&mut out).map_err(encode_err)?;
        let mut dir = enc.image_directory().map_err(encode_err)?;
        let t = Tag::from_u16_exhaustive;
        let data_at = dir.write_data(&frame.data[..]).map_err(encode_err)?;
        let offset = u32::try_from(data_at).map_err(|_| IoError::Encode {
            format: "DNG",
            msg: "the strip lies beyond 4 GiB".into(),
        })?;
        let put = |r: tiff::TiffResult<()>| r.map_err(encode_err);
        put(dir.write_tag(t(254), 0u32))?;
        put(dir.write_tag(t(256), w as u32))?;
        put(dir.write_tag(t(257), h as u32))?;
        put(dir.write_tag(t(258), 16u16))?;
        put(dir.write_tag(t(259), 1u16))?;
        put(dir.write_tag(t(262), 32803u16))?;
        put(dir.write_tag(t(273), offset))?;
        put(dir.write_tag(t(277), 1u16))?;
        put(dir.write_tag(t(278), h as u32))?;
        put(dir.write_tag(t(279), tags.strip_bytes))?;
        put(dir.write_tag(t(284), 1u16))?;
        put(dir.write_tag(t(305), "l3"))?;
        put(dir.write_tag(
            t(33421),
            &[
                tags.cfa_rows as u16,
                tags.pattern.len() as u16 / tags.cfa_rows.max(1) as u16,
            ][..],
        ))?;
        put(dir.write_tag(t(33422), &tags.pattern[..]))?;
        put(dir.write_tag(t(50706), &[1u8, 4, 0, 0][..]))?;
        put(dir.write_tag(t(50707), &[1u8, 1, 0, 0][..]))?;
        put(dir.write_tag(t(50708), tags.model.as_str()))?;
        put(dir.write_tag(t(50710), &tags.plane_codes[..]))?;
        put(dir.write_tag(t(50711), 1u16))?;
        put(dir.write_tag(t(50714), meta.black_level))?;
        put(dir.write_tag(t(50717), u32::from(meta.white_level)))?;
        if let Some(n) = &tags.neutral {
            put(dir.write_tag(t(50728), &n[..]))?;
        }
        if let Some(m) = &tags.color_matrix {
            put(dir.write_tag(t(50721), &m[..]))?;
        }
        if let Some(code) = info.calibration_illuminant {
            put(dir.write_tag(t(50778), code))?;
        }
        dir.finish().map_err(encode_err)?;
    }
    Ok(out.into_inner())
}

/// [`encode_dng`] written atomically to `path`.
pub fn write_dng(
    path: &Path,
    frame: &RawFrame,
    meta: &RawMeta,
    info: &DngWriteInfo,
) -> IoResult<()> {
    write_bytes_atomic(path, &encode_dng(frame, meta, info)?)
}

#[cfg(test)]
mod tests;
