//! The DNG reader: finds the full-resolution CFA image, decodes its strips or tiles, applies
//! the linearization table, black levels and crops.

use super::chunks::{check_chunks, decode_chunks, layout};
use super::ifd::{Ifd, Tiff, dng_err, required, tag_name};
use super::opcodes::{Lists, MAX_LIST_BYTES, Placement, fix_bad_pixels};
use super::{DngCamera, DngImage, DngInfo, cfa_letter};
use crate::io::IoResult;
use crate::io::limits::Limits;
use crate::io::raw::RawFrame;

/// Largest CFA or black-level repeat side accepted.
const MAX_REPEAT: u64 = 16;
/// Most IFDs visited looking for the raw image.
const MAX_IFDS: usize = 64;

const TAG_NEW_SUBFILE_TYPE: u16 = 254;
const TAG_WIDTH: u16 = 256;
const TAG_HEIGHT: u16 = 257;
const TAG_BITS: u16 = 258;
const TAG_COMPRESSION: u16 = 259;
const TAG_PHOTOMETRIC: u16 = 262;
const TAG_MAKE: u16 = 271;
const TAG_MODEL: u16 = 272;
const TAG_SAMPLES_PER_PIXEL: u16 = 277;
const TAG_SUB_IFDS: u16 = 330;
const TAG_SAMPLE_FORMAT: u16 = 339;
const TAG_CFA_REPEAT: u16 = 33421;
const TAG_CFA_PATTERN: u16 = 33422;
pub(super) const TAG_DNG_VERSION: u16 = 50706;
const TAG_CAMERA_MODEL: u16 = 50708;
const TAG_CFA_PLANE_COLOR: u16 = 50710;
const TAG_CFA_LAYOUT: u16 = 50711;
const TAG_LINEARIZATION: u16 = 50712;
const TAG_BLACK_REPEAT: u16 = 50713;
const TAG_BLACK: u16 = 50714;
const TAG_BLACK_DELTA_H: u16 = 50715;
const TAG_BLACK_DELTA_V: u16 = 50716;
const TAG_WHITE: u16 = 50717;
const TAG_CROP_ORIGIN: u16 = 50719;
const TAG_CROP_SIZE: u16 = 50720;
const TAG_COLOR_MATRIX: [u16; 2] = [50721, 50722];
const TAG_AS_SHOT_NEUTRAL: u16 = 50728;
const TAG_AS_SHOT_WHITE_XY: u16 = 50729;
const TAG_CALIBRATION_ILLUMINANT: [u16; 2] = [50778, 50779];
const TAG_ACTIVE_AREA: u16 = 50829;
const TAG_OPCODE_LISTS: [u16; 3] = [51008, 51009, 51022];

const PHOTOMETRIC_CFA: u64 = 32803;
const PHOTOMETRIC_LINEAR_RAW: u64 = 34892;

/// Whether `bytes` is a TIFF whose first IFD has a DNGVersion tag.
pub fn is_dng(bytes: &[u8]) -> bool {
    Tiff::parse(bytes).is_ok_and(|t| t.ifd_has(t.first_ifd_offset(), TAG_DNG_VERSION))
}

/// Whether `bytes` is a TIFF whose first IFD holds a CFA image (a CFAPattern, or the CFA
/// photometric interpretation) but no DNGVersion: a raw mosaic the DNG reader would take,
/// written without the tag that makes it a DNG.
pub fn is_cfa_tiff_without_dng_version(bytes: &[u8]) -> bool {
    Tiff::parse(bytes).is_ok_and(|t| {
        let first = t.first_ifd_offset();
        let cfa = t.ifd_has(first, TAG_CFA_PATTERN)
            || t.ifd(first)
                .ok()
                .and_then(|ifd| t.uint(&ifd, TAG_PHOTOMETRIC).ok().flatten())
                == Some(PHOTOMETRIC_CFA);
        cfa && !t.ifd_has(first, TAG_DNG_VERSION)
    })
}

/// The raw image's IFD: IFD0 or one of its SubIFDs (two levels deep) with NewSubFileType 0
/// and CFA photometric interpretation.
fn find_raw(t: &Tiff<'_>, ifd0: &Ifd) -> IoResult<Ifd> {
    let mut queue = vec![(ifd0.clone(), 0u8)];
    let mut seen = vec![ifd0.offset];
    let mut linear_raw = false;
    let mut i = 0;
    while let Some((ifd, depth)) = queue.get(i).cloned() {
        i += 1;
        let kind = t.uint(&ifd, TAG_NEW_SUBFILE_TYPE)?.unwrap_or(0);
        let photometric = t.uint(&ifd, TAG_PHOTOMETRIC)?;
        if kind == 0 {
            match photometric {
                Some(PHOTOMETRIC_CFA) => return Ok(ifd),
                Some(PHOTOMETRIC_LINEAR_RAW) => linear_raw = true,
                _ => {}
            }
        }
        if depth < 2 {
            for off in t.uints(&ifd, TAG_SUB_IFDS, MAX_IFDS)?.unwrap_or_default() {
                let off = u32::try_from(off).unwrap_or(u32::MAX);
                if seen.contains(&off) || seen.len() >= MAX_IFDS {
                    continue;
                }
                seen.push(off);
                queue.push((t.ifd(off)?, depth + 1));
            }
        }
    }
    Err(dng_err(if linear_raw {
        "the DNG holds LinearRaw (demosaicked) data; a CFA mosaic is expected".to_string()
    } else {
        "no full-resolution CFA image (NewSubFileType 0, PhotometricInterpretation 32803) in IFD0 or its SubIFDs".to_string()
    }))
}

/// A crop coordinate or size rounded to the nearest integer, as the DNG SDK rounds
/// DefaultCropOrigin and DefaultCropSize rationals.
fn to_usize(v: f64) -> usize {
    if v.is_finite() && v > 0.0 {
        v.round().min(usize::MAX as f64) as usize
    } else {
        0
    }
}

/// Decodes a DNG's full-resolution CFA image; see [`super::decode_dng`].
pub(super) fn decode(bytes: &[u8], limits: &Limits) -> IoResult<DngImage> {
    let t = Tiff::parse(bytes)?;
    let ifd0 = t.first_ifd()?;
    let dng_version = version(&t, &ifd0)?;
    let raw = find_raw(&t, &ifd0)?;
    let s = stored(&t, &raw, limits)?;
    let (w, h) = (s.width, s.height);
    let cfa = cfa_pattern(&t, &raw)?;

    // --- decode
    let lay = layout(&t, &raw, w, h, limits)?;
    check_chunks(&t, &lay, s.compression, s.bits, w, h)?;
    let ops = opcode_lists(&t, &raw)?;
    let mut img = crate::buffers::zeroed::<u16>(w * h);
    decode_chunks(&t, &lay, s.compression, s.bits, w, h, &mut img)?;

    // --- OpcodeList1, linearization, areas, levels, OpcodeList2
    let area = active_area(&t, &raw, w, h)?;
    for &constant in &ops.bad_pixel_constants {
        fix_bad_pixels(&mut img, w, constant, |r, c| cfa.colour_at(r, c, &area));
    }
    let lin = linearization(&t, &raw)?;
    let crop = default_crop(&t, &raw, &area)?;
    limits.check(crop.width, crop.height)?;
    let levels = levels(&t, &raw, s.bits, &area)?;
    let mut data = crop_and_level(img, w, lin.as_deref(), &area, &crop, &levels);
    if levels.black_level >= levels.white_level {
        return Err(dng_err(format!(
            "black level {} is not below the white level {}",
            levels.black_level, levels.white_level
        )));
    }
    let placement = Placement {
        x: crop.x,
        y: crop.y,
        area_width: area.width,
        area_height: area.height,
        black: levels.black_level,
        white: levels.white_level,
    };
    for map in &ops.gain_maps {
        map.apply(&mut data, crop.width, &placement);
    }

    let cam = camera_metadata(&t, &ifd0, &cfa)?;
    let frame = RawFrame {
        width: crop.width,
        height: crop.height,
        data,
    };
    Ok(DngImage {
        frame,
        cfa: cfa.seen_from(crop.x, crop.y),
        black_level: levels.black_level,
        white_level: levels.white_level,
        info: DngInfo {
            version: dng_version,
            bits_per_sample: s.bits as u8,
            compression: s.compression as u16,
            plane_colors: cfa.plane_colors,
            black_levels: levels.blacks,
            as_shot_neutral: cam.as_shot_neutral,
            as_shot_white_xy: cam.as_shot_white_xy,
            calibration_illuminants: cam.calibration_illuminants,
            color_matrices: cam.color_matrices,
            unique_camera_model: cam.unique_camera_model,
            make: cam.make,
            model: cam.model,
            skipped_opcodes: ops.skipped,
        },
    })
}

/// OpcodeList1, 2 and 3 of the raw image.
fn opcode_lists(t: &Tiff<'_>, raw: &Ifd) -> IoResult<Lists> {
    let [l1, l2, l3] = TAG_OPCODE_LISTS;
    Lists::new(
        t.bytes(raw, l1, MAX_LIST_BYTES)?,
        t.bytes(raw, l2, MAX_LIST_BYTES)?,
        t.bytes(raw, l3, MAX_LIST_BYTES)?,
    )
}

/// DNGVersion of IFD0, which a DNG must have.
fn version(t: &Tiff<'_>, ifd0: &Ifd) -> IoResult<[u8; 4]> {
    let version = t
        .uints(ifd0, TAG_DNG_VERSION, 4)?
        .ok_or_else(|| dng_err("not a DNG: IFD0 has no DNGVersion (50706) tag"))?;
    let mut dng_version = [0u8; 4];
    for (d, v) in dng_version.iter_mut().zip(&version) {
        *d = *v as u8;
    }
    Ok(dng_version)
}

/// How the raw image's samples are stored.
struct Stored {
    width: usize,
    height: usize,
    bits: u32,
    compression: u64,
}

/// The stored image's size (checked against `limits`), sample layout and compression, of
/// the kinds this reader decodes.
fn stored(t: &Tiff<'_>, raw: &Ifd, limits: &Limits) -> IoResult<Stored> {
    let w = required(t, raw, TAG_WIDTH)?;
    let h = required(t, raw, TAG_HEIGHT)?;
    let (w, h) = (
        usize::try_from(w).unwrap_or(usize::MAX),
        usize::try_from(h).unwrap_or(usize::MAX),
    );
    limits.check(w, h)?;
    let spp = t.uint(raw, TAG_SAMPLES_PER_PIXEL)?.unwrap_or(1);
    if spp != 1 {
        return Err(dng_err(format!(
            "the CFA image has {spp} samples per pixel; 1 is expected"
        )));
    }
    let bits = t.uint(raw, TAG_BITS)?.unwrap_or(1);
    if !(8..=16).contains(&bits) {
        return Err(dng_err(format!(
            "{bits} bits per sample; 8 to 16 are supported"
        )));
    }
    let bits = bits as u32;
    let format = t.uint(raw, TAG_SAMPLE_FORMAT)?.unwrap_or(1);
    if format != 1 {
        return Err(dng_err(format!(
            "sample format {format} (floating point or signed); unsigned integers are supported"
        )));
    }
    let compression = t.uint(raw, TAG_COMPRESSION)?.unwrap_or(1);
    if compression != 1 && compression != 7 {
        let what = match compression {
            8 => " (deflate)",
            34892 => " (lossy JPEG)",
            52546 => " (JPEG XL)",
            _ => "",
        };
        return Err(dng_err(format!(
            "compression {compression}{what}; uncompressed (1) and lossless JPEG (7) are supported"
        )));
    }
    Ok(Stored {
        width: w,
        height: h,
        bits,
        compression,
    })
}

/// The CFA: its repeat pattern as letters from the stored image's origin, and CFAPlaneColor.
struct CfaPattern {
    rows: usize,
    cols: usize,
    pattern: Vec<char>,
    plane_colors: String,
    /// Where `plane_colors` comes from (for messages).
    planes_from: &'static str,
}

impl CfaPattern {
    /// The colour of stored pixel (`r`, `c`): the pattern repeats from the active area's
    /// origin.
    fn colour_at(&self, r: usize, c: usize, area: &ActiveArea) -> char {
        let (rows, cols) = (self.rows.max(1), self.cols.max(1));
        // (r − top) mod rows, without going below zero
        let rr = (r + rows * area.top - area.top) % rows;
        let cc = (c + cols * area.left - area.left) % cols;
        self.pattern.get(rr * cols + cc).copied().unwrap_or('?')
    }

    /// The CFA seen from pixel (`x`, `y`), rows separated by '/'.
    fn seen_from(&self, x: usize, y: usize) -> String {
        let (rows, cols) = (self.rows, self.cols);
        (0..rows)
            .map(|r| {
                (0..cols)
                    .map(|c| {
                        self.pattern
                            .get(((r + y) % rows) * cols + (c + x) % cols)
                            .copied()
                            .unwrap_or('?')
                    })
                    .collect::<String>()
            })
            .collect::<Vec<_>>()
            .join("/")
    }
}

/// CFALayout, CFARepeatPatternDim, CFAPattern and CFAPlaneColor, checked.
fn cfa_pattern(t: &Tiff<'_>, raw: &Ifd) -> IoResult<CfaPattern> {
    let layout_tag = t.uint(raw, TAG_CFA_LAYOUT)?.unwrap_or(1);
    if layout_tag != 1 {
        return Err(dng_err(format!(
            "CFALayout {layout_tag}; only the rectangular layout (1) is supported"
        )));
    }
    let (rows, cols) = cfa_dims(t, raw)?;
    let codes = t
        .uints(raw, TAG_CFA_PATTERN, rows * cols)?
        .ok_or_else(|| dng_err("the raw image has no CFAPattern (33422)"))?;
    if codes.len() != rows * cols {
        return Err(dng_err(format!(
            "CFAPattern has {} values; a {rows}×{cols} pattern needs {}",
            codes.len(),
            rows * cols
        )));
    }
    let mut pattern = Vec::with_capacity(codes.len());
    for (i, &code) in codes.iter().enumerate() {
        pattern.push(cfa_letter(code).ok_or_else(|| {
            dng_err(format!(
                "CFAPattern colour code {code}{} at row {}, column {} is not supported; R (0), G (1), B (2) and W (6) are",
                super::code_name(code),
                i / cols,
                i % cols
            ))
        })?);
    }
    let (plane_colors, planes_from) = plane_colors(t, raw, &pattern)?;
    if let Some(&l) = pattern.iter().find(|l| !plane_colors.contains(**l)) {
        return Err(dng_err(format!(
            "CFAPattern uses {l}, which CFAPlaneColor ({plane_colors}) does not list"
        )));
    }
    let (rows, cols, pattern) = smallest_repeat(rows, cols, pattern);
    Ok(CfaPattern {
        rows,
        cols,
        pattern,
        plane_colors,
        planes_from,
    })
}

/// The smallest tile that repeats to `pattern` (`rows` × `cols`, row-major): a Bayer pattern
/// written as a 4 × 4 repeat is the 2 × 2 one, so that it matches a table's CFA as it is.
fn smallest_repeat(rows: usize, cols: usize, pattern: Vec<char>) -> (usize, usize, Vec<char>) {
    let at = |r: usize, c: usize| pattern.get(r * cols + c);
    let repeats =
        |pr: usize, pc: usize| (0..rows).all(|r| (0..cols).all(|c| at(r, c) == at(r % pr, c % pc)));
    let pr = (1..=rows)
        .find(|&p| rows.is_multiple_of(p) && repeats(p, cols))
        .unwrap_or(rows);
    let pc = (1..=cols)
        .find(|&p| cols.is_multiple_of(p) && repeats(pr, p))
        .unwrap_or(cols);
    let tile = (0..pr)
        .flat_map(|r| (0..pc).filter_map(move |c| at(r, c).copied()))
        .collect();
    (pr, pc, tile)
}

/// CFARepeatPatternDim as (rows, columns). Without it, a CFAPattern of 4 values is 2×2 (as
/// dcraw and LibRaw read it); any other count is ambiguous.
fn cfa_dims(t: &Tiff<'_>, raw: &Ifd) -> IoResult<(usize, usize)> {
    let Some(dims) = t.uints(raw, TAG_CFA_REPEAT, 2)? else {
        return match raw.count(TAG_CFA_PATTERN) {
            Some(4) => Ok((2, 2)),
            Some(n) => Err(dng_err(format!(
                "the raw image has no CFARepeatPatternDim (33421) and its CFAPattern has {n} values; only 4 (a 2×2 pattern) need none"
            ))),
            None => Err(dng_err("the raw image has no CFARepeatPatternDim (33421)")),
        };
    };
    let [rows, cols] = dims[..] else {
        return Err(dng_err("CFARepeatPatternDim (33421) needs 2 values"));
    };
    if !(1..=MAX_REPEAT).contains(&rows) || !(1..=MAX_REPEAT).contains(&cols) {
        return Err(dng_err(format!(
            "CFARepeatPatternDim is {rows}×{cols}; each side must be 1–{MAX_REPEAT}"
        )));
    }
    Ok((rows as usize, cols as usize))
}

/// Where the colour planes come from, for messages.
const PLANES_FROM_TAG: &str = "CFAPlaneColor";
const PLANES_FROM_PATTERN: &str =
    "the colours CFAPattern uses, R, G, B then W, as the file has no CFAPlaneColor";

/// CFAPlaneColor as letters, each listed once, and where they come from. Without the tag, the
/// colours `pattern` uses in the order R, G, B, W: what [`super::encode_dng`] writes, and for
/// a Bayer pattern the DNG default R, G, B.
fn plane_colors(t: &Tiff<'_>, raw: &Ifd, pattern: &[char]) -> IoResult<(String, &'static str)> {
    let Some(planes) = t.uints(raw, TAG_CFA_PLANE_COLOR, 16)? else {
        let planes = super::plane_order(|p| pattern.contains(&p));
        return Ok((planes.into_iter().collect(), PLANES_FROM_PATTERN));
    };
    let mut plane_colors = String::new();
    for &code in &planes {
        let l = cfa_letter(code).ok_or_else(|| {
            dng_err(format!(
                "CFAPlaneColor lists colour code {code}{}; R (0), G (1), B (2) and W (6) are supported",
                super::code_name(code)
            ))
        })?;
        if plane_colors.contains(l) {
            return Err(dng_err(format!("CFAPlaneColor lists {l} twice")));
        }
        plane_colors.push(l);
    }
    Ok((plane_colors, PLANES_FROM_TAG))
}

/// LinearizationTable, when there is one (it may not be empty).
fn linearization(t: &Tiff<'_>, raw: &Ifd) -> IoResult<Option<Vec<u16>>> {
    let lin = t.uints(raw, TAG_LINEARIZATION, 1 << 16)?.map(|v| {
        v.into_iter()
            .map(|x| x.min(65535) as u16)
            .collect::<Vec<u16>>()
    });
    if lin.as_ref().is_some_and(|l| l.is_empty()) {
        return Err(dng_err("LinearizationTable (50712) is empty"));
    }
    Ok(lin)
}

/// ActiveArea in the stored image (the whole image by default).
struct ActiveArea {
    top: usize,
    left: usize,
    width: usize,
    height: usize,
}

fn active_area(t: &Tiff<'_>, raw: &Ifd, w: usize, h: usize) -> IoResult<ActiveArea> {
    let (top, left, bottom, right) = match t.uints(raw, TAG_ACTIVE_AREA, 4)? {
        None => (0, 0, h, w),
        Some(v) => match v[..] {
            [a, b, c, d] => {
                let u = |x: u64| usize::try_from(x).unwrap_or(usize::MAX);
                (u(a), u(b), u(c), u(d))
            }
            _ => return Err(dng_err("ActiveArea (50829) needs 4 values")),
        },
    };
    if !(top < bottom && left < right && bottom <= h && right <= w) {
        return Err(dng_err(format!(
            "ActiveArea (top {top}, left {left}, bottom {bottom}, right {right}) is not inside the {w}×{h} image"
        )));
    }
    Ok(ActiveArea {
        top,
        left,
        width: right - left,
        height: bottom - top,
    })
}

/// DefaultCropOrigin and DefaultCropSize, in the active area (all of it by default).
struct Crop {
    x: usize,
    y: usize,
    width: usize,
    height: usize,
}

fn default_crop(t: &Tiff<'_>, raw: &Ifd, area: &ActiveArea) -> IoResult<Crop> {
    let (aw, ah) = (area.width, area.height);
    let crop = |tag: u16| -> IoResult<Option<(usize, usize)>> {
        Ok(match t.reals(raw, tag, 2)? {
            None => None,
            Some(v) => match v[..] {
                [x, y] if x >= 0.0 && y >= 0.0 => Some((to_usize(x), to_usize(y))),
                _ => {
                    return Err(dng_err(format!(
                        "{} needs 2 non-negative values",
                        tag_name(tag)
                    )));
                }
            },
        })
    };
    let (cx, cy) = crop(TAG_CROP_ORIGIN)?.unwrap_or((0, 0));
    let (cw, ch) = crop(TAG_CROP_SIZE)?.unwrap_or((aw.saturating_sub(cx), ah.saturating_sub(cy)));
    if cw == 0 || ch == 0 || cx.saturating_add(cw) > aw || cy.saturating_add(ch) > ah {
        return Err(dng_err(format!(
            "the default crop ({cw}×{ch} at {cx},{cy}) is not inside the {aw}×{ah} active area"
        )));
    }
    Ok(Crop {
        x: cx,
        y: cy,
        width: cw,
        height: ch,
    })
}

/// The black and white levels, and the one black level the frame gets.
struct Levels {
    /// BlackLevel, `br × bc` values.
    blacks: Vec<f64>,
    br: usize,
    bc: usize,
    /// BlackLevelDeltaH (per active-area column) and BlackLevelDeltaV (per row).
    delta_h: Vec<f64>,
    delta_v: Vec<f64>,
    white: f64,
    white_level: u16,
    /// The lowest black, floored: the frame's one black level.
    black_level: u16,
    /// Whether every pixel has `black_level` as its black (the values are kept as stored).
    exact: bool,
}

impl Levels {
    /// The black of an output pixel, relative to the active area's origin.
    fn black_at(&self, r: usize, c: usize) -> f64 {
        self.blacks
            .get((r % self.br) * self.bc + c % self.bc)
            .copied()
            .unwrap_or(0.0)
            + self.delta_v.get(r).copied().unwrap_or(0.0)
            + self.delta_h.get(c).copied().unwrap_or(0.0)
    }
}

/// BlackLevelRepeatDim, BlackLevel, BlackLevelDeltaH/V and WhiteLevel, checked.
fn levels(t: &Tiff<'_>, raw: &Ifd, bits: u32, area: &ActiveArea) -> IoResult<Levels> {
    let (br, bc) = match t.uints(raw, TAG_BLACK_REPEAT, 2)? {
        None => (1, 1),
        Some(v) => match v[..] {
            [r, c] if (1..=MAX_REPEAT).contains(&r) && (1..=MAX_REPEAT).contains(&c) => {
                (r as usize, c as usize)
            }
            _ => {
                return Err(dng_err(format!(
                    "BlackLevelRepeatDim must be 2 values of 1–{MAX_REPEAT}"
                )));
            }
        },
    };
    let blacks = match t.reals(raw, TAG_BLACK, (MAX_REPEAT * MAX_REPEAT) as usize)? {
        None => vec![0.0; br * bc],
        Some(v) if v.len() == br * bc => v,
        Some(v) if v.len() == 1 => vec![v.first().copied().unwrap_or(0.0); br * bc],
        // one black written once per CFA position without BlackLevelRepeatDim (or more
        // times than it says): every pixel has that black
        Some(v) if !v.is_empty() && v.windows(2).all(|p| p.first() == p.last()) => {
            vec![v.first().copied().unwrap_or(0.0); br * bc]
        }
        Some(v) => {
            return Err(dng_err(format!(
                "BlackLevel has {} values; BlackLevelRepeatDim {br}×{bc} needs {}",
                v.len(),
                br * bc
            )));
        }
    };
    let delta = |tag: u16, n: usize| -> IoResult<Vec<f64>> {
        match t.reals(raw, tag, n)? {
            None => Ok(vec![0.0; n]),
            Some(v) if v.len() == n => Ok(v),
            Some(v) => Err(dng_err(format!(
                "{} has {} values; the active area needs {n}",
                tag_name(tag),
                v.len()
            ))),
        }
    };
    let delta_h = delta(TAG_BLACK_DELTA_H, area.width)?;
    let delta_v = delta(TAG_BLACK_DELTA_V, area.height)?;
    let white = match t.reals(raw, TAG_WHITE, 1)? {
        None => f64::from((1u32 << bits) - 1),
        Some(v) => v.first().copied().unwrap_or(0.0),
    };
    if !(white > 0.0 && white <= 65535.0) {
        return Err(dng_err(format!(
            "WhiteLevel {white}; 1 to 65535 is expected for integer data"
        )));
    }
    let white_level = white.round() as u16;
    // one black level for the frame: the lowest; pixels are rescaled to it unless every
    // pixel has the same, whole-numbered black
    let lowest = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    let min_black = lowest(&blacks) + lowest(&delta_v) + lowest(&delta_h);
    let first_black = blacks.first().copied().unwrap_or(0.0);
    let uniform = blacks.iter().all(|&b| b == first_black)
        && delta_v.iter().chain(&delta_h).all(|&d| d == 0.0);
    if !(min_black >= 0.0 && min_black < white) {
        return Err(dng_err(format!(
            "the black level {min_black} is not between 0 and the white level {white}"
        )));
    }
    let black_level = min_black.floor() as u16;
    let exact = uniform && first_black == f64::from(black_level);
    Ok(Levels {
        blacks,
        br,
        bc,
        delta_h,
        delta_v,
        white,
        white_level,
        black_level,
        exact,
    })
}

/// The default crop of the `w`-wide stored image, linearised and, unless every pixel has the
/// frame's black level, rescaled to it.
fn crop_and_level(
    mut img: Vec<u16>,
    w: usize,
    lin: Option<&[u16]>,
    area: &ActiveArea,
    crop: &Crop,
    levels: &Levels,
) -> Vec<u16> {
    let (cx, cy, cw, ch) = (crop.x, crop.y, crop.width, crop.height);
    let (top, left) = (area.top, area.left);
    let (white, black_level) = (levels.white, levels.black_level);
    // In place: crop row r moves from (top + cy + r, left + cx) of the w-wide image to r × cw,
    // never past where it is read from, and rows are moved in order, so every sample is read
    // before anything is written over it.
    // (the crop lies inside the stored image; rows that would not are zeros)
    let mut kept = 0;
    for r in 0..ch {
        let (ar, sr) = (cy + r, top + cy + r);
        let from = sr * w + left + cx;
        if from + cw > img.len() {
            break;
        }
        img.copy_within(from..from + cw, r * cw);
        kept = r + 1;
        let Some(row) = img.get_mut(r * cw..(r + 1) * cw) else {
            break;
        };
        if let Some(l) = lin {
            for v in row.iter_mut() {
                *v = l.get(usize::from(*v)).or(l.last()).copied().unwrap_or(*v);
            }
        }
        if !levels.exact {
            for (c, v) in row.iter_mut().enumerate() {
                // one black level for the frame: rescale (v − b) / (white − b) to
                // (white − black_level) so that every pixel keeps its place between its own
                // black and the white
                let b = levels.black_at(ar, cx + c);
                let scale = (white - f64::from(black_level)) / (white - b).max(1e-9);
                let x = (f64::from(*v) - b) * scale + f64::from(black_level);
                *v = x.round().clamp(0.0, 65535.0) as u16;
            }
        }
    }
    img.truncate(kept * cw);
    img.resize(cw * ch, 0);
    img
}

/// The camera metadata of IFD0.
struct CameraMetadata {
    as_shot_neutral: Option<Vec<f64>>,
    as_shot_white_xy: Option<[f64; 2]>,
    calibration_illuminants: [Option<u16>; 2],
    color_matrices: [Option<Vec<f64>>; 2],
    unique_camera_model: Option<String>,
    make: Option<String>,
    model: Option<String>,
}

/// The camera's names in IFD0 (UniqueCameraModel, Make, Model), each trimmed of NULs and
/// spaces; an empty one is absent.
fn camera_names(t: &Tiff<'_>, ifd0: &Ifd) -> IoResult<DngCamera> {
    let name = |tag| -> IoResult<Option<String>> {
        Ok(t.ascii(ifd0, tag, MAX_NAME)?.filter(|s| !s.is_empty()))
    };
    Ok(DngCamera {
        unique_camera_model: name(TAG_CAMERA_MODEL)?,
        make: name(TAG_MAKE)?,
        model: name(TAG_MODEL)?,
    })
}

/// What a DNG says of its camera, from IFD0's tags alone (no pixel is read); see
/// [`super::read_camera`].
pub(super) fn camera(bytes: &[u8]) -> IoResult<DngCamera> {
    let t = Tiff::parse(bytes)?;
    let ifd0 = t.first_ifd()?;
    version(&t, &ifd0)?;
    camera_names(&t, &ifd0)
}

/// Longest camera name read (UniqueCameraModel, Make, Model).
const MAX_NAME: usize = 1024;

/// AsShotNeutral, CalibrationIlluminant1/2, ColorMatrix1/2 (one value, or row, per colour
/// plane of `cfa`), UniqueCameraModel, Make and Model.
fn camera_metadata(t: &Tiff<'_>, ifd0: &Ifd, cfa: &CfaPattern) -> IoResult<CameraMetadata> {
    let (plane_colors, planes_from) = (&cfa.plane_colors, cfa.planes_from);
    let n_planes = plane_colors.len();
    let as_shot_neutral = match t.reals(ifd0, TAG_AS_SHOT_NEUTRAL, 16)? {
        None => None,
        Some(v) if v.len() == n_planes && v.iter().all(|&x| x > 0.0) => Some(v),
        Some(v) => {
            return Err(dng_err(format!(
                "AsShotNeutral holds {v:?}; {n_planes} positive values (one per colour plane, {plane_colors}: {planes_from}) are expected"
            )));
        }
    };
    let as_shot_white_xy = match t.reals(ifd0, TAG_AS_SHOT_WHITE_XY, 2)?.as_deref() {
        None => None,
        Some(&[x, y]) if x > 0.0 && y > 0.0 => Some([x, y]),
        Some(v) => {
            return Err(dng_err(format!(
                "AsShotWhiteXY holds {v:?}; two positive values (a chromaticity x, y) are expected"
            )));
        }
    };
    let mut calibration_illuminants = [None, None];
    let mut color_matrices = [None, None];
    for k in 0..2 {
        calibration_illuminants[k] = t
            .uint(ifd0, TAG_CALIBRATION_ILLUMINANT[k])?
            .map(|v| v.min(u64::from(u16::MAX)) as u16);
        color_matrices[k] = match t.reals(ifd0, TAG_COLOR_MATRIX[k], 3 * 16)? {
            None => None,
            Some(v) if v.len() == 3 * n_planes => Some(v),
            Some(v) => {
                return Err(dng_err(format!(
                    "{} has {} values; 3 × {n_planes} colour planes ({plane_colors}: {planes_from}) are expected",
                    tag_name(TAG_COLOR_MATRIX[k]),
                    v.len()
                )));
            }
        };
    }
    let names = camera_names(t, ifd0)?;
    Ok(CameraMetadata {
        as_shot_neutral,
        as_shot_white_xy,
        calibration_illuminants,
        color_matrices,
        unique_camera_model: names.unique_camera_model,
        make: names.make,
        model: names.model,
    })
}
