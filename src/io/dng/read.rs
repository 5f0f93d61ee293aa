//! The DNG reader: finds the full-resolution CFA image, decodes its strips or tiles, applies
//! the linearization table, black levels and crops.

use super::ifd::{Ifd, Tiff, dng_err, tag_name};
use super::ljpeg;
use super::{DngImage, DngInfo, cfa_letter};
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
const TAG_STRIP_OFFSETS: u16 = 273;
const TAG_SAMPLES_PER_PIXEL: u16 = 277;
const TAG_ROWS_PER_STRIP: u16 = 278;
const TAG_STRIP_BYTES: u16 = 279;
const TAG_TILE_WIDTH: u16 = 322;
const TAG_TILE_LENGTH: u16 = 323;
const TAG_TILE_OFFSETS: u16 = 324;
const TAG_TILE_BYTES: u16 = 325;
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
const TAG_CALIBRATION_ILLUMINANT: [u16; 2] = [50778, 50779];
const TAG_ACTIVE_AREA: u16 = 50829;

const PHOTOMETRIC_CFA: u64 = 32803;
const PHOTOMETRIC_LINEAR_RAW: u64 = 34892;

/// Whether `bytes` is a TIFF whose first IFD has a DNGVersion tag.
pub fn is_dng(bytes: &[u8]) -> bool {
    Tiff::parse(bytes).is_ok_and(|t| t.ifd_has(t.first_ifd_offset(), TAG_DNG_VERSION))
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

fn required(t: &Tiff<'_>, ifd: &Ifd, tag: u16) -> IoResult<u64> {
    t.uint(ifd, tag)?
        .ok_or_else(|| dng_err(format!("the raw image has no {}", tag_name(tag))))
}

/// How the raw image is cut into chunks (strips are tiles as wide as the image).
struct Layout {
    tile_w: usize,
    tile_h: usize,
    across: usize,
    offsets: Vec<u64>,
    counts: Vec<u64>,
}

fn layout(t: &Tiff<'_>, ifd: &Ifd, w: usize, h: usize, limits: &Limits) -> IoResult<Layout> {
    let tiled = ifd.has(TAG_TILE_OFFSETS);
    let (tile_w, tile_h, off_tag, count_tag) = if tiled {
        let tw = required(t, ifd, TAG_TILE_WIDTH)?;
        let th = required(t, ifd, TAG_TILE_LENGTH)?;
        (tw, th, TAG_TILE_OFFSETS, TAG_TILE_BYTES)
    } else {
        let rps = t.uint(ifd, TAG_ROWS_PER_STRIP)?.unwrap_or(h as u64);
        (
            w as u64,
            rps.min(h as u64),
            TAG_STRIP_OFFSETS,
            TAG_STRIP_BYTES,
        )
    };
    let what = if tiled { "tile" } else { "strip" };
    let (tile_w, tile_h) = (
        usize::try_from(tile_w).unwrap_or(usize::MAX),
        usize::try_from(tile_h).unwrap_or(usize::MAX),
    );
    limits
        .check(tile_w, tile_h)
        .map_err(|e| dng_err(format!("a {what} of {tile_w}×{tile_h} pixels: {e}")))?;
    let across = w.div_ceil(tile_w);
    let down = h.div_ceil(tile_h);
    let n = across * down;
    // (read whatever count the file holds, to name a mismatch clearly)
    let offsets = t
        .uints(ifd, off_tag, usize::MAX)?
        .ok_or_else(|| dng_err(format!("the raw image has no {}", tag_name(off_tag))))?;
    let counts = t
        .uints(ifd, count_tag, usize::MAX)?
        .ok_or_else(|| dng_err(format!("the raw image has no {}", tag_name(count_tag))))?;
    if offsets.len() != n || counts.len() != n {
        return Err(dng_err(format!(
            "a {w}×{h} image in {tile_w}×{tile_h} {what}s needs {n} {what}s; {} lists {} and {} lists {}",
            tag_name(off_tag),
            offsets.len(),
            tag_name(count_tag),
            counts.len()
        )));
    }
    Ok(Layout {
        tile_w,
        tile_h,
        across,
        offsets,
        counts,
    })
}

/// Checks, before the image is allocated, that the chunks' data can hold the image: every
/// chunk lies inside the file, their bytes add up to no more than the file (chunks do not
/// share data), and lossless JPEG chunks have at least one bit per sample.
fn check_chunks(
    t: &Tiff<'_>,
    lay: &Layout,
    compression: u64,
    bits: u32,
    w: usize,
    h: usize,
) -> IoResult<()> {
    let mut bytes = 0u64;
    let mut samples = 0u64;
    for (k, (&off, &count)) in lay.offsets.iter().zip(&lay.counts).enumerate() {
        let (x0, y0) = ((k % lay.across) * lay.tile_w, (k / lay.across) * lay.tile_h);
        let vis_w = lay.tile_w.min(w.saturating_sub(x0)) as u64;
        let vis_h = lay.tile_h.min(h.saturating_sub(y0)) as u64;
        let len = if compression == 1 {
            (lay.tile_w as u64 * u64::from(bits)).div_ceil(8) * vis_h
        } else {
            count
        };
        if t.slice(off, len).is_none() {
            return Err(dng_err(format!(
                "chunk {k} needs {len} bytes at offset {off} but the file has {}",
                t.len()
            )));
        }
        bytes = bytes.saturating_add(len);
        samples = samples.saturating_add(vis_w * vis_h);
    }
    if bytes > t.len() as u64 {
        return Err(dng_err(format!(
            "the {} chunks need {bytes} bytes, more than the file's {}",
            lay.offsets.len(),
            t.len()
        )));
    }
    if compression != 1 && samples > bytes.saturating_mul(8) {
        return Err(dng_err(format!(
            "{samples} samples cannot fit in {bytes} bytes of lossless JPEG data"
        )));
    }
    Ok(())
}

/// Decodes every chunk into the `w × h` image.
fn decode_chunks(
    t: &Tiff<'_>,
    lay: &Layout,
    compression: u64,
    bits: u32,
    w: usize,
    h: usize,
    out: &mut [u16],
) -> IoResult<()> {
    let chunk_samples = lay.tile_w * lay.tile_h;
    for (k, (&off, &count)) in lay.offsets.iter().zip(&lay.counts).enumerate() {
        let (x0, y0) = ((k % lay.across) * lay.tile_w, (k / lay.across) * lay.tile_h);
        let vis_w = lay.tile_w.min(w.saturating_sub(x0));
        let vis_h = lay.tile_h.min(h.saturating_sub(y0));
        let put = |out: &mut [u16], r: usize, c: usize, v: u16| {
            if let Some(o) = out.get_mut((y0 + r) * w + x0 + c) {
                *o = v;
            }
        };
        if compression == 1 {
            let row_bytes = (lay.tile_w as u64 * u64::from(bits)).div_ceil(8);
            let need = row_bytes * vis_h as u64;
            let data = t.slice(off, need).ok_or_else(|| {
                dng_err(format!(
                    "chunk {k} needs {need} bytes at offset {off} but the file has {}",
                    t.len()
                ))
            })?;
            for (r, row) in data.chunks(row_bytes as usize).enumerate().take(vis_h) {
                match bits {
                    8 => {
                        for (c, &b) in row.iter().take(vis_w).enumerate() {
                            put(out, r, c, u16::from(b));
                        }
                    }
                    16 => {
                        for (c, p) in row.chunks_exact(2).take(vis_w).enumerate() {
                            let a = [
                                p.first().copied().unwrap_or(0),
                                p.get(1).copied().unwrap_or(0),
                            ];
                            let v = if t.big_endian() {
                                u16::from_be_bytes(a)
                            } else {
                                u16::from_le_bytes(a)
                            };
                            put(out, r, c, v);
                        }
                    }
                    _ => {
                        // packed samples, most significant bit first, rows byte-aligned
                        let mut acc = 0u32;
                        let mut n = 0u32;
                        let mut bytes = row.iter();
                        for c in 0..vis_w {
                            while n < bits {
                                acc = (acc << 8) | u32::from(bytes.next().copied().unwrap_or(0));
                                n += 8;
                            }
                            n -= bits;
                            put(out, r, c, ((acc >> n) & ((1 << bits) - 1)) as u16);
                        }
                    }
                }
            }
        } else {
            let data = t.slice(off, count).ok_or_else(|| {
                dng_err(format!(
                    "chunk {k}: {count} bytes at offset {off} lie beyond the end of the file ({} bytes)",
                    t.len()
                ))
            })?;
            let j = ljpeg::decode(data, chunk_samples)?;
            let need = (vis_h.saturating_sub(1)) * lay.tile_w + vis_w;
            if j.samples.len() < need {
                return Err(dng_err(format!(
                    "chunk {k}: its lossless JPEG holds {} samples ({}×{}×{}); the {}×{} chunk needs {need}",
                    j.samples.len(),
                    j.width,
                    j.height,
                    j.components,
                    lay.tile_w,
                    lay.tile_h
                )));
            }
            for r in 0..vis_h {
                let row = j
                    .samples
                    .get(r * lay.tile_w..r * lay.tile_w + vis_w)
                    .unwrap_or(&[]);
                for (c, &v) in row.iter().enumerate() {
                    put(out, r, c, v);
                }
            }
        }
    }
    Ok(())
}

fn to_usize(v: f64) -> usize {
    if v.is_finite() && v > 0.0 {
        v.floor().min(usize::MAX as f64) as usize
    } else {
        0
    }
}

/// Decodes a DNG's full-resolution CFA image; see [`super::decode_dng`].
pub(super) fn decode(bytes: &[u8], limits: &Limits) -> IoResult<DngImage> {
    let t = Tiff::parse(bytes)?;
    let ifd0 = t.first_ifd()?;
    let version = t
        .uints(&ifd0, TAG_DNG_VERSION, 4)?
        .ok_or_else(|| dng_err("not a DNG: IFD0 has no DNGVersion (50706) tag"))?;
    let mut dng_version = [0u8; 4];
    for (d, v) in dng_version.iter_mut().zip(&version) {
        *d = *v as u8;
    }
    let raw = find_raw(&t, &ifd0)?;

    // --- the stored image
    let w = required(&t, &raw, TAG_WIDTH)?;
    let h = required(&t, &raw, TAG_HEIGHT)?;
    let (w, h) = (
        usize::try_from(w).unwrap_or(usize::MAX),
        usize::try_from(h).unwrap_or(usize::MAX),
    );
    limits.check(w, h)?;
    let spp = t.uint(&raw, TAG_SAMPLES_PER_PIXEL)?.unwrap_or(1);
    if spp != 1 {
        return Err(dng_err(format!(
            "the CFA image has {spp} samples per pixel; 1 is expected"
        )));
    }
    let bits = t.uint(&raw, TAG_BITS)?.unwrap_or(1);
    if !(8..=16).contains(&bits) {
        return Err(dng_err(format!(
            "{bits} bits per sample; 8 to 16 are supported"
        )));
    }
    let bits = bits as u32;
    let format = t.uint(&raw, TAG_SAMPLE_FORMAT)?.unwrap_or(1);
    if format != 1 {
        return Err(dng_err(format!(
            "sample format {format} (floating point or signed); unsigned integers are supported"
        )));
    }
    let compression = t.uint(&raw, TAG_COMPRESSION)?.unwrap_or(1);
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

    // --- the CFA
    let layout_tag = t.uint(&raw, TAG_CFA_LAYOUT)?.unwrap_or(1);
    if layout_tag != 1 {
        return Err(dng_err(format!(
            "CFALayout {layout_tag}; only the rectangular layout (1) is supported"
        )));
    }
    let dims = t
        .uints(&raw, TAG_CFA_REPEAT, 2)?
        .ok_or_else(|| dng_err("the raw image has no CFARepeatPatternDim (33421)"))?;
    let [rows, cols] = dims[..] else {
        return Err(dng_err("CFARepeatPatternDim (33421) needs 2 values"));
    };
    if !(1..=MAX_REPEAT).contains(&rows) || !(1..=MAX_REPEAT).contains(&cols) {
        return Err(dng_err(format!(
            "CFARepeatPatternDim is {rows}×{cols}; each side must be 1–{MAX_REPEAT}"
        )));
    }
    let (rows, cols) = (rows as usize, cols as usize);
    let codes = t
        .uints(&raw, TAG_CFA_PATTERN, rows * cols)?
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
    let planes = t
        .uints(&raw, TAG_CFA_PLANE_COLOR, 16)?
        .unwrap_or_else(|| vec![0, 1, 2]);
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
    if let Some(&l) = pattern.iter().find(|l| !plane_colors.contains(**l)) {
        return Err(dng_err(format!(
            "CFAPattern uses {l}, which CFAPlaneColor ({plane_colors}) does not list"
        )));
    }

    // --- decode
    let lay = layout(&t, &raw, w, h, limits)?;
    check_chunks(&t, &lay, compression, bits, w, h)?;
    let mut img = crate::buffers::zeroed::<u16>(w * h);
    decode_chunks(&t, &lay, compression, bits, w, h, &mut img)?;

    // --- linearization, areas, levels
    let lin = t.uints(&raw, TAG_LINEARIZATION, 1 << 16)?.map(|v| {
        v.into_iter()
            .map(|x| x.min(65535) as u16)
            .collect::<Vec<u16>>()
    });
    if lin.as_ref().is_some_and(|l| l.is_empty()) {
        return Err(dng_err("LinearizationTable (50712) is empty"));
    }
    let (top, left, bottom, right) = match t.uints(&raw, TAG_ACTIVE_AREA, 4)? {
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
    let (aw, ah) = (right - left, bottom - top);
    let crop = |tag: u16| -> IoResult<Option<(usize, usize)>> {
        Ok(match t.reals(&raw, tag, 2)? {
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
    limits.check(cw, ch)?;

    let (br, bc) = match t.uints(&raw, TAG_BLACK_REPEAT, 2)? {
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
    let blacks = match t.reals(&raw, TAG_BLACK, (MAX_REPEAT * MAX_REPEAT) as usize)? {
        None => vec![0.0; br * bc],
        Some(v) if v.len() == br * bc => v,
        Some(v) if v.len() == 1 => vec![v.first().copied().unwrap_or(0.0); br * bc],
        Some(v) => {
            return Err(dng_err(format!(
                "BlackLevel has {} values; BlackLevelRepeatDim {br}×{bc} needs {}",
                v.len(),
                br * bc
            )));
        }
    };
    let delta = |tag: u16, n: usize| -> IoResult<Vec<f64>> {
        match t.reals(&raw, tag, n)? {
            None => Ok(vec![0.0; n]),
            Some(v) if v.len() == n => Ok(v),
            Some(v) => Err(dng_err(format!(
                "{} has {} values; the active area needs {n}",
                tag_name(tag),
                v.len()
            ))),
        }
    };
    let delta_h = delta(TAG_BLACK_DELTA_H, aw)?;
    let delta_v = delta(TAG_BLACK_DELTA_V, ah)?;
    let white = match t.reals(&raw, TAG_WHITE, 1)? {
        None => f64::from((1u32 << bits) - 1),
        Some(v) => v.first().copied().unwrap_or(0.0),
    };
    if !(white > 0.0 && white <= 65535.0) {
        return Err(dng_err(format!(
            "WhiteLevel {white}; 1 to 65535 is expected for integer data"
        )));
    }
    let white_level = white.round() as u16;
    // the black of each output pixel, relative to the active area's origin
    let black_at = |r: usize, c: usize| -> f64 {
        blacks.get((r % br) * bc + c % bc).copied().unwrap_or(0.0)
            + delta_v.get(r).copied().unwrap_or(0.0)
            + delta_h.get(c).copied().unwrap_or(0.0)
    };
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

    let mut data = crate::buffers::zeroed::<u16>(cw * ch);
    for r in 0..ch {
        let (ar, sr) = (cy + r, top + cy + r);
        for c in 0..cw {
            let (ac, sc) = (cx + c, left + cx + c);
            let mut v = img.get(sr * w + sc).copied().unwrap_or(0);
            if let Some(l) = &lin {
                v = l.get(usize::from(v)).or(l.last()).copied().unwrap_or(v);
            }
            if !exact {
                // one black level for the frame: rescale (v − b) / (white − b) to
                // (white − black_level) so that every pixel keeps its place between its own
                // black and the white
                let b = black_at(ar, ac);
                let scale = (white - f64::from(black_level)) / (white - b).max(1e-9);
                let x = (f64::from(v) - b) * scale + f64::from(black_level);
                v = x.round().clamp(0.0, 65535.0) as u16;
            }
            if let Some(o) = data.get_mut(r * cw + c) {
                *o = v;
            }
        }
    }
    if black_level >= white_level {
        return Err(dng_err(format!(
            "black level {black_level} is not below the white level {white_level}"
        )));
    }

    // the CFA seen from the default crop's origin (the pattern starts at the active area)
    let cfa: String = (0..rows)
        .map(|r| {
            (0..cols)
                .map(|c| {
                    pattern
                        .get(((r + cy) % rows) * cols + (c + cx) % cols)
                        .copied()
                        .unwrap_or('?')
                })
                .collect::<String>()
        })
        .collect::<Vec<_>>()
        .join("/");

    // --- camera metadata (IFD0)
    let n_planes = plane_colors.len();
    let as_shot_neutral = match t.reals(&ifd0, TAG_AS_SHOT_NEUTRAL, 16)? {
        None => None,
        Some(v) if v.len() == n_planes && v.iter().all(|&x| x > 0.0) => Some(v),
        Some(v) => {
            return Err(dng_err(format!(
                "AsShotNeutral holds {v:?}; {n_planes} positive values (one per CFAPlaneColor entry, {plane_colors}) are expected"
            )));
        }
    };
    let mut calibration_illuminants = [None, None];
    let mut color_matrices = [None, None];
    for k in 0..2 {
        calibration_illuminants[k] = t
            .uint(&ifd0, TAG_CALIBRATION_ILLUMINANT[k])?
            .map(|v| v.min(u64::from(u16::MAX)) as u16);
        color_matrices[k] = match t.reals(&ifd0, TAG_COLOR_MATRIX[k], 3 * 16)? {
            None => None,
            Some(v) if v.len() == 3 * n_planes => Some(v),
            Some(v) => {
                return Err(dng_err(format!(
                    "{} has {} values; 3 × {n_planes} planes are expected",
                    tag_name(TAG_COLOR_MATRIX[k]),
                    v.len()
                )));
            }
        };
    }
    let unique_camera_model = t.ascii(&ifd0, TAG_CAMERA_MODEL, 1024)?;

    let frame = RawFrame {
        width: cw,
        height: ch,
        data,
    };
    Ok(DngImage {
        frame,
        cfa,
        black_level,
        white_level,
        info: DngInfo {
            version: dng_version,
            bits_per_sample: bits as u8,
            compression: compression as u16,
            plane_colors,
            black_levels: blacks,
            as_shot_neutral,
            calibration_illuminants,
            color_matrices,
            unique_camera_model,
        },
    })
}
