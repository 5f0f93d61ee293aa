//! The input: the mosaic as clamped volts, the frame and region checks.

use rayon::prelude::*;

use super::{FastRenderer, Mosaic, PatchGeometry, Region, RenderError, mirror};

/// The frame being rendered, with its conversion to clamped volts.
pub(super) struct Source<'a> {
    pub(super) mosaic: Mosaic<'a>,
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) swing: f32,
    /// DN → volts: `((dn − black) · scale).clamp(0, swing)` in f64, as `RawFrame::to_volts`.
    pub(super) dn: DnScale,
}

/// DN → volts: `((dn − black) · scale).clamp(0, swing)` in f64, then f32, the arithmetic of
/// `RawFrame::to_volts`, so that every path that reads a DN frame (the renderers, the light's
/// estimate) sees the volts a decoded frame holds, to the last bit.
#[derive(Clone, Copy, Debug, Default)]
pub struct DnScale {
    black: f64,
    scale: f64,
    swing: f64,
}

impl DnScale {
    /// The conversion for `black` and `white` levels and a `swing` in volts; `None` unless
    /// white exceeds black.
    pub fn new(black: u16, white: u16, swing: f64) -> Option<DnScale> {
        (white > black).then(|| {
            let b = f64::from(black);
            DnScale {
                black: b,
                scale: swing / (f64::from(white) - b),
                swing,
            }
        })
    }

    /// The volts of `d`.
    #[inline(always)]
    pub fn volts(&self, d: u16) -> f32 {
        ((f64::from(d) - self.black) * self.scale).clamp(0.0, self.swing) as f32
    }
}

impl Source<'_> {
    /// Clamped volts of frame row `r`, columns `c0..c0 + out.len()` (all inside the frame).
    #[inline(always)]
    pub(super) fn row_into(&self, r: usize, c0: usize, out: &mut [f32]) {
        let start = r * self.width + c0;
        let end = start + out.len();
        match self.mosaic {
            Mosaic::Volts(v) => {
                for (o, &x) in out.iter_mut().zip(&v[start..end]) {
                    *o = x.clamp(0.0, self.swing);
                }
            }
            Mosaic::Dn { data, .. } => {
                for (o, &d) in out.iter_mut().zip(&data[start..end]) {
                    *o = self.dn.volts(d);
                }
            }
        }
    }

    /// Ask the CPU to bring frame rows `rows`, columns `c0..c1` (clamped to the
    /// frame) into its caches: a hint, so that scattered reads (the white sample
    /// grid) wait on memory together rather than one after another.
    #[inline]
    pub(super) fn prefetch(&self, rows: std::ops::Range<usize>, c0: usize, c1: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
            let (base, elem) = match self.mosaic {
                Mosaic::Volts(v) => (v.as_ptr().cast::<u8>(), 4),
                Mosaic::Dn { data, .. } => (data.as_ptr().cast::<u8>(), 2),
            };
            let c1 = c1.min(self.width);
            for r in rows.start..rows.end.min(self.height) {
                let (a, b) = ((r * self.width + c0) * elem, (r * self.width + c1) * elem);
                let mut at = a & !63;
                while at < b {
                    // SAFETY: a prefetch never faults; the address lies inside the frame
                    // (wrapping_add only avoids asserting so).
                    unsafe { _mm_prefetch::<_MM_HINT_T0>(base.wrapping_add(at).cast()) };
                    at += 64;
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (rows, c0, c1);
    }

    #[inline]
    pub(super) fn at(&self, r: usize, c: usize) -> f32 {
        let i = r * self.width + c;
        match self.mosaic {
            Mosaic::Volts(v) => v[i].clamp(0.0, self.swing),
            Mosaic::Dn { data, .. } => self.dn.volts(data[i]),
        }
    }
}

impl FastRenderer {
    /// Check the frame and build its converter; f32 input is scanned once for
    /// non-finite values and counted for clamping, as the reference does.
    pub(super) fn source<'a>(
        &self,
        mosaic: Mosaic<'a>,
        width: usize,
        height: usize,
    ) -> Result<(Source<'a>, u64), RenderError> {
        if width == 0 || height == 0 {
            return Err(RenderError::InvalidInput(format!(
                "frame is {width}×{height}"
            )));
        }
        let n = width.checked_mul(height).ok_or_else(|| {
            RenderError::InvalidInput(format!("frame {width}×{height} is too large"))
        })?;
        let swing = self.swing;
        let (len, dn, clamped) = match mosaic {
            Mosaic::Volts(v) => {
                // one vectorised pass counts both; the first bad value is looked up only if there is one
                let (bad, clamped) = v
                    .par_chunks(1 << 16)
                    .map(|ch| {
                        ch.iter().fold((0u64, 0u64), |(b, c), &x| {
                            let finite = x.abs() < f32::INFINITY;
                            (
                                b + u64::from(!finite),
                                c + u64::from(!(0.0..=swing).contains(&x)),
                            )
                        })
                    })
                    .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
                if bad > 0 {
                    let i = v.par_iter().position_first(|x| !x.is_finite()).unwrap_or(0);
                    return Err(RenderError::InvalidInput(format!(
                        "input value at row {}, column {} is not finite",
                        i / width,
                        i % width
                    )));
                }
                (v.len(), DnScale::default(), clamped)
            }
            Mosaic::Dn { data, black, white } => {
                let dn = DnScale::new(black, white, self.swing_f64).ok_or_else(|| {
                    RenderError::InvalidInput(format!(
                        "white level {white} must exceed black level {black}"
                    ))
                })?;
                (data.len(), dn, 0)
            }
        };
        if len != n {
            return Err(RenderError::InvalidInput(format!(
                "{len} values for a {width}×{height} frame ({n} expected)"
            )));
        }
        Ok((
            Source {
                mosaic,
                width,
                height,
                swing,
                dn,
            },
            clamped,
        ))
    }
}

/// Copy the patch around frame pixel (r, c) with mirrored borders.
pub(super) fn gather_frame(
    geo: &PatchGeometry,
    src: &Source<'_>,
    r: usize,
    c: usize,
    out: &mut [f32],
) {
    let s = geo.size;
    let rad = geo.radius;
    if r >= rad && c >= rad && r + rad < src.height && c + rad < src.width {
        for (dy, row) in out.chunks_exact_mut(s).take(s).enumerate() {
            src.row_into(r + dy - rad, c - rad, row);
        }
        return;
    }
    let rad = rad as isize;
    for dy in 0..s {
        let rr = mirror(r as isize + dy as isize - rad, src.height);
        for dx in 0..s {
            let cc = mirror(c as isize + dx as isize - rad, src.width);
            out[dy * s + dx] = src.at(rr, cc);
        }
    }
}

pub(super) fn check_region(
    region: Option<Region>,
    width: usize,
    height: usize,
) -> Result<Region, RenderError> {
    let reg = region.unwrap_or(Region {
        x: 0,
        y: 0,
        width,
        height,
    });
    let inside = reg.width > 0
        && reg.height > 0
        && reg.x.checked_add(reg.width).is_some_and(|e| e <= width)
        && reg.y.checked_add(reg.height).is_some_and(|e| e <= height);
    if !inside {
        return Err(RenderError::InvalidInput(format!(
            "region {},{} {}×{} is empty or not inside the {width}×{height} frame",
            reg.x, reg.y, reg.width, reg.height
        )));
    }
    Ok(reg)
}
