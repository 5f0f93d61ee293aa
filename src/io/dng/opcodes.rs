//! DNG opcode lists (OpcodeList1, 2 and 3, DNG 1.3+): parsed bounded and never panicking.
//! The reader applies FixBadPixelsConstant of OpcodeList1 (to the stored image) and GainMap
//! of OpcodeList2 (to the linearised, black-subtracted CFA data); every other opcode is
//! skipped and reported by name (OpcodeList3 works on the demosaicked image, which l3 does
//! not make: its lens corrections are always skipped).
//!
//! A list is big-endian whatever the file's byte order: a u32 count, then per opcode its ID,
//! the DNG version it needs, flags (bit 0: optional) and the byte count of its parameters,
//! each a u32, then the parameters.

use super::ifd::dng_err;
use crate::io::IoResult;

/// Largest opcode list read (bytes); a phone's four gain maps take a few kilobytes.
pub(super) const MAX_LIST_BYTES: usize = 64 << 20;
/// Most opcodes in one list.
const MAX_OPCODES: u32 = 4096;
/// Most gain map points (rows × columns × planes).
const MAX_MAP_POINTS: u64 = 1 << 22;

const ID_FIX_BAD_PIXELS_CONSTANT: u32 = 4;
const ID_GAIN_MAP: u32 = 9;
const FLAG_OPTIONAL: u32 = 1;

/// The name of an opcode ID (DNG 1.6), for reports.
pub(super) fn opcode_name(id: u32) -> String {
    let name = match id {
        1 => "WarpRectilinear",
        2 => "WarpFisheye",
        3 => "FixVignetteRadial",
        4 => "FixBadPixelsConstant",
        5 => "FixBadPixelsList",
        6 => "TrimBounds",
        7 => "MapTable",
        8 => "MapPolynomial",
        9 => "GainMap",
        10 => "DeltaPerRow",
        11 => "DeltaPerColumn",
        12 => "ScalePerRow",
        13 => "ScalePerColumn",
        14 => "WarpRectilinear2",
        _ => return format!("opcode {id}"),
    };
    name.to_string()
}

/// One opcode of a list.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Opcode {
    pub id: u32,
    pub flags: u32,
    pub op: Op,
}

impl Opcode {
    /// How a skipped opcode is reported: `"WarpRectilinear (OpcodeList3, optional)"`.
    pub fn report(&self, list: u8) -> String {
        let optional = if self.flags & FLAG_OPTIONAL != 0 {
            ", optional"
        } else {
            ""
        };
        format!("{} (OpcodeList{list}{optional})", opcode_name(self.id))
    }
}

/// What the reader does with an opcode.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Op {
    FixBadPixelsConstant {
        constant: u32,
    },
    GainMap(GainMap),
    /// Any other opcode: its parameters are not read.
    Other,
}

/// A GainMap opcode's area and map.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct GainMap {
    pub top: u32,
    pub left: u32,
    pub bottom: u32,
    pub right: u32,
    pub plane: u32,
    pub planes: u32,
    pub row_pitch: u32,
    pub col_pitch: u32,
    pub points_v: usize,
    pub points_h: usize,
    pub spacing_v: f64,
    pub spacing_h: f64,
    pub origin_v: f64,
    pub origin_h: f64,
    pub map_planes: usize,
    /// `points_v × points_h × map_planes` gains, row by row, planes innermost.
    pub gains: Vec<f32>,
}

/// A big-endian reader over an opcode's bytes.
struct Be<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Be<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.b.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(s)
    }
    fn u32(&mut self) -> Option<u32> {
        let s = self.take(4)?;
        Some(u32::from_be_bytes([
            *s.first()?,
            *s.get(1)?,
            *s.get(2)?,
            *s.get(3)?,
        ]))
    }
    fn f32(&mut self) -> Option<f32> {
        self.u32().map(f32::from_bits)
    }
    fn f64(&mut self) -> Option<f64> {
        let hi = u64::from(self.u32()?);
        let lo = u64::from(self.u32()?);
        Some(f64::from_bits((hi << 32) | lo))
    }
}

/// Parses OpcodeList`list` from its bytes.
pub(super) fn parse_list(bytes: &[u8], list: u8) -> IoResult<Vec<Opcode>> {
    let bad = |what: String| dng_err(format!("OpcodeList{list}: {what}"));
    let mut r = Be { b: bytes, at: 0 };
    let n = r.u32().ok_or_else(|| bad("no opcode count".into()))?;
    if n > MAX_OPCODES {
        return Err(bad(format!("{n} opcodes; at most {MAX_OPCODES} are read")));
    }
    let mut ops = Vec::with_capacity(n as usize);
    for i in 0..n {
        let head = (r.u32(), r.u32(), r.u32(), r.u32());
        let (Some(id), Some(_version), Some(flags), Some(len)) = head else {
            return Err(bad(format!("opcode {i} of {n} ends early")));
        };
        let params = r.take(len as usize).ok_or_else(|| {
            bad(format!(
                "the parameters of opcode {i} ({}, {len} bytes) run past the list's end",
                opcode_name(id)
            ))
        })?;
        let op = match id {
            ID_GAIN_MAP => Op::GainMap(gain_map(params).map_err(|e| bad(format!("GainMap: {e}")))?),
            ID_FIX_BAD_PIXELS_CONSTANT => {
                let mut p = Be { b: params, at: 0 };
                let constant = p.u32().filter(|_| params.len() == 8).ok_or_else(|| {
                    bad("FixBadPixelsConstant needs 8 bytes of parameters".into())
                })?;
                Op::FixBadPixelsConstant { constant }
            }
            _ => Op::Other,
        };
        ops.push(Opcode { id, flags, op });
    }
    Ok(ops)
}

/// A GainMap's parameters, checked: the map's sizes agree with its byte count, its spacing
/// is positive and its gains finite.
fn gain_map(params: &[u8]) -> Result<GainMap, String> {
    let mut p = Be { b: params, at: 0 };
    let short = || "its parameters end early".to_string();
    let mut area = [0u32; 10];
    for a in &mut area {
        *a = p.u32().ok_or_else(short)?;
    }
    let [
        top,
        left,
        bottom,
        right,
        plane,
        planes,
        row_pitch,
        col_pitch,
        pv,
        ph,
    ] = area;
    let mut real = [0f64; 4];
    for x in &mut real {
        *x = p.f64().ok_or_else(short)?;
    }
    let [mut spacing_v, mut spacing_h, mut origin_v, mut origin_h] = real;
    let map_planes = p.u32().ok_or_else(short)?;
    let n = u64::from(pv) * u64::from(ph) * u64::from(map_planes);
    if n == 0 || n > MAX_MAP_POINTS {
        return Err(format!(
            "a map of {pv} × {ph} points and {map_planes} planes; 1 to {MAX_MAP_POINTS} values are read"
        ));
    }
    if (params.len() as u64).checked_sub(76) != Some(4 * n) {
        return Err(format!(
            "{} bytes of parameters; a map of {pv} × {ph} × {map_planes} needs {}",
            params.len(),
            76 + 4 * n
        ));
    }
    // one point along a side: the spec's reading is a constant along it
    if pv == 1 {
        (spacing_v, origin_v) = (1.0, 0.0);
    }
    if ph == 1 {
        (spacing_h, origin_h) = (1.0, 0.0);
    }
    let finite = [spacing_v, spacing_h, origin_v, origin_h]
        .iter()
        .all(|x| x.is_finite());
    if !(finite && spacing_v > 0.0 && spacing_h > 0.0) {
        return Err(format!(
            "spacing {spacing_v} × {spacing_h} and origin {origin_v}, {origin_h}; positive finite spacings and finite origins are expected"
        ));
    }
    if row_pitch == 0 || col_pitch == 0 {
        return Err("a row or column pitch of 0".into());
    }
    let mut gains = Vec::with_capacity(n as usize);
    for _ in 0..n {
        let g = p.f32().ok_or_else(short)?;
        if !g.is_finite() {
            return Err(format!("a gain of {g}"));
        }
        gains.push(g);
    }
    Ok(GainMap {
        top,
        left,
        bottom,
        right,
        plane,
        planes,
        row_pitch,
        col_pitch,
        points_v: pv as usize,
        points_h: ph as usize,
        spacing_v,
        spacing_h,
        origin_v,
        origin_h,
        map_planes: map_planes as usize,
        gains,
    })
}

/// The two map indices around `f` (a position in map points) and the weight of the second,
/// clamped to the map's first and last points.
fn around(f: f64, n: usize) -> (usize, usize, f64) {
    let last = n.saturating_sub(1);
    if f.is_nan() || f <= 0.0 {
        (0, 0, 0.0)
    } else if f >= last as f64 {
        (last, last, 0.0)
    } else {
        let i = f.floor() as usize;
        (i, (i + 1).min(last), f - i as f64)
    }
}

/// Where a frame sits in the image an opcode's coordinates refer to (the active area), and
/// its levels.
pub(super) struct Placement {
    /// The frame's origin in the active area, and the active area's size.
    pub x: usize,
    pub y: usize,
    pub area_width: usize,
    pub area_height: usize,
    pub black: u16,
    pub white: u16,
}

impl GainMap {
    /// The gain at pixel (`r`, `c`) of an `h` × `w` image: the map is laid over the image in
    /// relative coordinates (a pixel's centre at ((c + ½) / w, (r + ½) / h)), interpolated
    /// bilinearly and clamped to the map's edges.
    fn gain(&self, r: usize, c: usize, h: usize, w: usize, plane: usize) -> f64 {
        let fv = ((r as f64 + 0.5) / h.max(1) as f64 - self.origin_v) / self.spacing_v;
        let fh = ((c as f64 + 0.5) / w.max(1) as f64 - self.origin_h) / self.spacing_h;
        let (v0, v1, tv) = around(fv, self.points_v);
        let (h0, h1, th) = around(fh, self.points_h);
        let at = |v: usize, hh: usize| {
            let i = (v * self.points_h + hh) * self.map_planes + plane;
            f64::from(self.gains.get(i).copied().unwrap_or(1.0))
        };
        let top = at(v0, h0) * (1.0 - th) + at(v0, h1) * th;
        let bottom = at(v1, h0) * (1.0 - th) + at(v1, h1) * th;
        top * (1.0 - tv) + bottom * tv
    }

    /// Applies the map to `data`, a `width`-wide frame placed at `at` in the active area, one
    /// CFA plane: only a map whose planes include plane 0 touches it. Each pixel of the area
    /// (every `row_pitch`-th row and `col_pitch`-th column from its top-left) is scaled above
    /// the black level and clipped at the white level.
    pub fn apply(&self, data: &mut [u16], width: usize, at: &Placement) {
        if self.plane != 0 || self.planes == 0 {
            return;
        }
        let map_plane = 0;
        let (aw, ah) = (at.area_width, at.area_height);
        let height = data.len() / width.max(1);
        let range = (f64::from(at.white) - f64::from(at.black)).max(0.0);
        let (rows, cols) = (
            (self.top as usize..(self.bottom as usize).min(ah))
                .step_by(self.row_pitch.max(1) as usize),
            (self.left as usize..(self.right as usize).min(aw))
                .step_by(self.col_pitch.max(1) as usize),
        );
        for r in rows {
            let Some(fr) = r.checked_sub(at.y).filter(|&fr| fr < height) else {
                continue;
            };
            for c in cols.clone() {
                let Some(fc) = c.checked_sub(at.x).filter(|&fc| fc < width) else {
                    continue;
                };
                if let Some(v) = data.get_mut(fr * width + fc) {
                    let x = (f64::from(*v) - f64::from(at.black)).max(0.0);
                    let g = self.gain(r, c, ah, aw, map_plane);
                    let y = (x * g).clamp(0.0, range) + f64::from(at.black);
                    *v = y.round().clamp(0.0, 65535.0) as u16;
                }
            }
        }
    }
}

/// FixBadPixelsConstant: every pixel of the `w`-wide stored image `img` equal to `constant`
/// becomes the mean of its nearest pixels of the same CFA colour (`colour(r, c)`) within two
/// pixels that are not bad themselves; one without such neighbours is left as it is.
pub(super) fn fix_bad_pixels(
    img: &mut [u16],
    w: usize,
    constant: u32,
    colour: impl Fn(usize, usize) -> char,
) {
    let Ok(bad) = u16::try_from(constant) else {
        return;
    };
    let h = img.len() / w.max(1);
    let fixes: Vec<(usize, u16)> = img
        .iter()
        .enumerate()
        .filter(|&(_, &v)| v == bad)
        .filter_map(|(i, _)| {
            let (r, c) = (i / w, i % w);
            let me = colour(r, c);
            let mut best = (usize::MAX, 0u64, 0u64); // (distance², sum, count)
            for nr in r.saturating_sub(2)..(r + 3).min(h) {
                for nc in c.saturating_sub(2)..(c + 3).min(w) {
                    let v = img.get(nr * w + nc).copied().unwrap_or(bad);
                    if (nr, nc) == (r, c) || v == bad || colour(nr, nc) != me {
                        continue;
                    }
                    let d = nr.abs_diff(r).pow(2) + nc.abs_diff(c).pow(2);
                    if d < best.0 {
                        best = (d, 0, 0);
                    }
                    if d == best.0 {
                        best.1 += u64::from(v);
                        best.2 += 1;
                    }
                }
            }
            (best.2 > 0).then(|| (i, ((best.1 + best.2 / 2) / best.2) as u16))
        })
        .collect();
    for (i, v) in fixes {
        if let Some(p) = img.get_mut(i) {
            *p = v;
        }
    }
}

/// The opcode lists of a raw image: what the reader applies, and what it skips.
#[derive(Debug, Default)]
pub(super) struct Lists {
    /// OpcodeList1's FixBadPixelsConstant constants, in order.
    pub bad_pixel_constants: Vec<u32>,
    /// OpcodeList2's gain maps, in order.
    pub gain_maps: Vec<GainMap>,
    /// Every other opcode, as [`Opcode::report`] names it.
    pub skipped: Vec<String>,
}

impl Lists {
    /// Sorts the opcodes of OpcodeList1, 2 and 3 (`None`: no such list). OpcodeList3 works on
    /// the demosaicked image: every opcode in it is skipped, and a list that cannot be read
    /// is reported rather than refused.
    pub fn new(
        list1: Option<&[u8]>,
        list2: Option<&[u8]>,
        list3: Option<&[u8]>,
    ) -> IoResult<Lists> {
        let mut lists = Lists::default();
        for op in parse_list(list1.unwrap_or(&[0; 4]), 1)? {
            match op.op {
                Op::FixBadPixelsConstant { constant } => lists.bad_pixel_constants.push(constant),
                _ => lists.skipped.push(op.report(1)),
            }
        }
        for op in parse_list(list2.unwrap_or(&[0; 4]), 2)? {
            match op.op {
                Op::GainMap(map) => lists.gain_maps.push(map),
                _ => lists.skipped.push(op.report(2)),
            }
        }
        match list3.map(|b| parse_list(b, 3)) {
            None => {}
            Some(Ok(ops)) => lists.skipped.extend(ops.iter().map(|op| op.report(3))),
            Some(Err(e)) => lists.skipped.push(format!(
                "OpcodeList3 (unreadable: {})",
                ascii(&e.to_string())
            )),
        }
        Ok(lists)
    }
}

/// `s` with every character outside printable ASCII as '?' (reports go into HTTP headers).
fn ascii(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_graphic() || c == ' ' {
                c
            } else {
                '?'
            }
        })
        .collect()
}
