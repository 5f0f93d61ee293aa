//! The self-guided filter (He, Sun and Tang, *Guided image filtering*, 2010/2013) with a
//! per-pixel ε, streamed down a band of rows of a plane: the denoiser's one filter
//! ([`super::denoise`]).
//!
//! For a plane `I` and radius `r`, with every window the `(2r+1)²` square clamped to the plane:
//! `m`, `q` the window means of `I` and `I²`, `cov = q − m²`,
//! `a = cov / (max(cov, 0) + ε)`, `b = m − a·m`; the output is `A·I + B`, `A` and `B` the
//! window means of `a` and `b` at the same radius.
//!
//! **Structure.** Every box filter is separable and done in two passes per row. Down the
//! columns, a row of f64 accumulators holds each column's sum over the window's rows: moving to
//! the next row adds the row entering the window and subtracts the one leaving it (whole rows at
//! a time, so it vectorises across the columns). Along the row, the window's sum is the
//! difference of two prefix sums of that accumulator row, clamped at the row's ends; the
//! count (clamped window width × height) divides it. So the filter costs the same per pixel
//! whatever the radius. It is fused: each input row is produced once (by the caller, e.g. the
//! luma of the demosaicked channels) into a ring of `2r+2` rows, from which it is added to the
//! `I` and `I²` accumulators, subtracted again, and read for the output; each `a`, `b` row is
//! computed as soon as its window's input is in, goes into its own ring and accumulators, and
//! each output row as soon as its `a`, `b` window is complete. A band of rows therefore reads
//! its input once, and its working set is a few dozen rows: it stays in cache. The caller
//! processes bands in parallel (one band per task); a band reads `2r` rows beyond its ends,
//! so its result is the whole plane's, to rounding.
//!
//! The accumulators and the a/b arithmetic are f64: the variance `q − m²` cancels to 1e-5 of
//! `m²` at low noise, where f32 would keep one or two digits; the rings and the output are
//! f32.
//!
//! Why hand-written: no maintained crate offers the guided filter on f32 planes with a
//! per-window ε, let alone streamed by rows; it is under two hundred lines.

use std::ops::Range;

/// One self-guided filter of radius `r` on a `width × height` plane, with its rings and
/// accumulators (reused from band to band).
pub(super) struct SelfGuided {
    w: usize,
    h: usize,
    r: usize,
    /// Ring length in rows: `2r+2` (the rows alive at once), at most the plane's height.
    ring: usize,
    /// `1 / (clamped window width)` at each column.
    inv_nx: Vec<f64>,
    input: Vec<f32>,
    a: Vec<f32>,
    b: Vec<f32>,
    /// Column sums over the window's rows of `I`, `I²` (for the next a/b row) and of `a`, `b`
    /// (for the next output row).
    col: [Vec<f64>; 4],
    /// Prefix sums of two accumulator rows (`w + 1` each).
    prefix: [Vec<f64>; 2],
    /// The window means of `I` and `I²` of the current row.
    mean: Vec<f64>,
    mean_sq: Vec<f64>,
    eps: Vec<f32>,
    out: Vec<f32>,
}

impl SelfGuided {
    /// A filter of radius `r` for `width × height` planes (a radius beyond the plane's sides
    /// is the whole plane's, and is cut to it).
    pub(super) fn new(width: usize, height: usize, r: usize) -> Self {
        let (w, h) = (width, height);
        let r = r.min(w.max(h));
        let ring = (2 * r + 2).min(h).max(1);
        let inv_nx = (0..w)
            .map(|x| 1.0 / ((x + r + 1).min(w) - x.saturating_sub(r)) as f64)
            .collect();
        let zf = |n: usize| vec![0f32; n];
        let zd = |n: usize| vec![0f64; n];
        Self {
            w,
            h,
            r,
            ring,
            inv_nx,
            input: zf(ring * w),
            a: zf(ring * w),
            b: zf(ring * w),
            col: [zd(w), zd(w), zd(w), zd(w)],
            prefix: [zd(w + 1), zd(w + 1)],
            mean: zd(w),
            mean_sq: zd(w),
            eps: zf(w),
            out: zf(w),
        }
    }

    /// Filter the rows `rows` of the plane whose row `t` `input(t, row)` writes, with
    /// `eps(s, m, e)` writing row `s`'s ε into `e` from its window means `m` of the input;
    /// `emit(y, out)` receives each output row, in order. `input` is called once per row in
    /// `rows` widened by `2r` (clamped to the plane), `eps` once per row widened by `r`.
    pub(super) fn run(
        &mut self,
        rows: Range<usize>,
        mut input: impl FnMut(usize, &mut [f32]),
        mut eps: impl FnMut(usize, &[f64], &mut [f32]),
        mut emit: impl FnMut(usize, &[f32]),
    ) {
        let (h, r) = (self.h, self.r);
        let rows = rows.start..rows.end.min(h);
        if rows.is_empty() || self.w == 0 {
            return;
        }
        // a/b rows s_lo..s_hi feed the output rows; the I accumulators start on s_lo's window
        let (s_lo, s_hi) = (rows.start.saturating_sub(r), (rows.end + r).min(h));
        for c in &mut self.col {
            c.fill(0.0);
        }
        for t in s_lo.saturating_sub(r)..(s_lo + r + 1).min(h) {
            self.take_input(t, &mut input);
        }
        let mut y = rows.start;
        for s in s_lo..s_hi {
            if s > s_lo {
                if s + r < h {
                    self.take_input(s + r, &mut input);
                }
                if s > r {
                    self.drop_input(s - r - 1);
                }
            }
            self.coefficients(s, &mut eps);
            while y < rows.end && y + r <= s {
                self.output(y, s_lo, &mut emit);
                y += 1;
            }
        }
        // the plane's last rows: their windows end at its bottom
        while y < rows.end {
            self.output(y, s_lo, &mut emit);
            y += 1;
        }
    }

    fn row_of(&self, t: usize) -> Range<usize> {
        let at = (t % self.ring) * self.w;
        at..at + self.w
    }

    /// Input row `t` into its ring slot and the `I`, `I²` accumulators.
    fn take_input(&mut self, t: usize, input: &mut impl FnMut(usize, &mut [f32])) {
        let at = self.row_of(t);
        input(t, &mut self.input[at.clone()]);
        let [ci, cii, ..] = &mut self.col;
        for ((i, ii), &v) in ci.iter_mut().zip(cii.iter_mut()).zip(&self.input[at]) {
            let v = v as f64;
            *i += v;
            *ii += v * v;
        }
    }

    /// Take input row `t` out of the `I`, `I²` accumulators: it has left the window.
    fn drop_input(&mut self, t: usize) {
        let at = self.row_of(t);
        let [ci, cii, ..] = &mut self.col;
        for ((i, ii), &v) in ci.iter_mut().zip(cii.iter_mut()).zip(&self.input[at]) {
            let v = v as f64;
            *i -= v;
            *ii -= v * v;
        }
    }

    /// Take row `t` of `a` and `b` out of their accumulators.
    fn drop_coefficients(&mut self, t: usize) {
        let at = self.row_of(t);
        let [.., ca, cb] = &mut self.col;
        let (a, b) = (&self.a[at.clone()], &self.b[at]);
        for ((ca, cb), (&a, &b)) in ca.iter_mut().zip(cb.iter_mut()).zip(a.iter().zip(b)) {
            *ca -= a as f64;
            *cb -= b as f64;
        }
    }

    /// The window sums along the row of accumulators `which`, `which + 1` into the prefix
    /// buffers' first `w` entries, scaled to means for a window of `ny` rows.
    fn row_means(&mut self, which: usize, ny: usize, out: [&mut [f64]; 2]) {
        let (w, r) = (self.w, self.r);
        let [p0, p1] = &mut self.prefix;
        let (c0, c1) = (&self.col[which], &self.col[which + 1]);
        let (mut s0, mut s1) = (0f64, 0f64);
        p0[0] = 0.0;
        p1[0] = 0.0;
        for x in 0..w {
            s0 += c0[x];
            s1 += c1[x];
            p0[x + 1] = s0;
            p1[x + 1] = s1;
        }
        let k = 1.0 / ny as f64;
        for (o, p) in out.into_iter().zip([&*p0, &*p1]) {
            window_sums(p, r, o);
            for (o, &inv) in o.iter_mut().zip(&self.inv_nx) {
                *o *= inv * k;
            }
        }
    }

    /// Row `s` of `a` and `b` into their rings and accumulators.
    fn coefficients(&mut self, s: usize, eps: &mut impl FnMut(usize, &[f64], &mut [f32])) {
        let ny = (s + self.r + 1).min(self.h) - s.saturating_sub(self.r);
        let (mut mean, mut mean_sq) = (
            std::mem::take(&mut self.mean),
            std::mem::take(&mut self.mean_sq),
        );
        self.row_means(0, ny, [&mut mean, &mut mean_sq]);
        eps(s, &mean, &mut self.eps);
        let at = self.row_of(s);
        let (a, b) = (&mut self.a[at.clone()], &mut self.b[at]);
        let [.., ca, cb] = &mut self.col;
        for (((a, b), (ca, cb)), ((&m, &q), &e)) in a
            .iter_mut()
            .zip(b.iter_mut())
            .zip(ca.iter_mut().zip(cb.iter_mut()))
            .zip(mean.iter().zip(&mean_sq).zip(&self.eps))
        {
            let cov = q - m * m;
            let ai = cov / (cov.max(0.0) + e.max(f32::MIN_POSITIVE) as f64);
            let bi = m - ai * m;
            *a = ai as f32;
            *b = bi as f32;
            *ca += *a as f64;
            *cb += *b as f64;
        }
        (self.mean, self.mean_sq) = (mean, mean_sq);
    }

    /// Output row `y`: its `a`, `b` window is in the accumulators once row `y − r − 1` (if
    /// this band added it) is taken out.
    fn output(&mut self, y: usize, s_lo: usize, emit: &mut impl FnMut(usize, &[f32])) {
        let r = self.r;
        if y > s_lo + r {
            self.drop_coefficients(y - r - 1);
        }
        let ny = (y + r + 1).min(self.h) - y.saturating_sub(r);
        let (mut ma, mut mb) = (
            std::mem::take(&mut self.mean),
            std::mem::take(&mut self.mean_sq),
        );
        self.row_means(2, ny, [&mut ma, &mut mb]);
        let at = self.row_of(y);
        for ((o, &i), (&a, &b)) in self
            .out
            .iter_mut()
            .zip(&self.input[at])
            .zip(ma.iter().zip(&mb))
        {
            *o = (a * i as f64 + b) as f32;
        }
        (self.mean, self.mean_sq) = (ma, mb);
        emit(y, &self.out);
    }
}

/// `out[x] = p[min(x + r + 1, w)] − p[max(x − r, 0)]` for prefix sums `p` (`w + 1` long): the
/// sums over windows of radius `r` clamped to the row; the interior in one vectorisable run.
fn window_sums(p: &[f64], r: usize, out: &mut [f64]) {
    let w = out.len();
    let clamped = |x: usize| p[(x + r + 1).min(w)] - p[x.saturating_sub(r)];
    let lo = r.min(w);
    let hi = w.saturating_sub(r + 1).max(lo);
    for (x, o) in out[..lo].iter_mut().enumerate() {
        *o = clamped(x);
    }
    if hi > lo {
        let inner = out[lo..hi]
            .iter_mut()
            .zip(&p[lo + r + 1..hi + r + 1])
            .zip(&p[lo - r..hi - r]);
        for ((o, &a), &b) in inner {
            *o = a - b;
        }
    }
    for (x, o) in out[hi..].iter_mut().enumerate() {
        *o = clamped(hi + x);
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// The filter from its definition: every window summed afresh, in f64.
    pub(in crate::baseline) fn reference(
        img: &[f32],
        w: usize,
        h: usize,
        r: usize,
        eps: impl Fn(usize, f64) -> f64,
    ) -> Vec<f64> {
        let boxed = |f: &dyn Fn(usize) -> f64| -> Vec<f64> {
            (0..w * h)
                .map(|i| {
                    let (y, x) = (i / w, i % w);
                    let (y0, y1) = (y.saturating_sub(r), (y + r).min(h - 1));
                    let (x0, x1) = (x.saturating_sub(r), (x + r).min(w - 1));
                    let mut s = 0.0;
                    for yy in y0..=y1 {
                        for xx in x0..=x1 {
                            s += f(yy * w + xx);
                        }
                    }
                    s / ((y1 - y0 + 1) * (x1 - x0 + 1)) as f64
                })
                .collect()
        };
        let m = boxed(&|i| img[i] as f64);
        let q = boxed(&|i| (img[i] as f64).powi(2));
        let a: Vec<f64> = (0..w * h)
            .map(|i| {
                let cov = q[i] - m[i] * m[i];
                cov / (cov.max(0.0) + eps(i, m[i]))
            })
            .collect();
        let b: Vec<f64> = (0..w * h).map(|i| m[i] - a[i] * m[i]).collect();
        let (ma, mb) = (boxed(&|i| a[i]), boxed(&|i| b[i]));
        (0..w * h).map(|i| ma[i] * img[i] as f64 + mb[i]).collect()
    }

    /// The streamed filter on rows `rows` (an ε with a term from the pixel's index, to check
    /// `eps` gets the right row, and one from the window mean).
    fn streamed(img: &[f32], w: usize, h: usize, r: usize, rows: Range<usize>) -> Vec<f32> {
        let mut out = vec![f32::NAN; w * h];
        let mut g = SelfGuided::new(w, h, r);
        g.run(
            rows,
            |t, row| row.copy_from_slice(&img[t * w..(t + 1) * w]),
            |s, m, e| {
                for (x, (e, &m)) in e.iter_mut().zip(m).enumerate() {
                    *e = eps_of(s * w + x, m) as f32;
                }
            },
            |y, row| out[y * w..(y + 1) * w].copy_from_slice(row),
        );
        out
    }

    fn eps_of(i: usize, m: f64) -> f64 {
        0.002 * m * m + 1e-4 * (1 + i % 3) as f64
    }

    /// A random image with steps: values 0.1 to about 1.3.
    fn image(w: usize, h: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..w * h)
            .map(|i| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let u = (s >> 40) as f32 / (1u64 << 24) as f32;
                let step = if (i % w) * 3 > w { 0.6 } else { 0.0 };
                0.1 + 0.05 * u + step + 0.5 * ((i / w) % 5 == 0) as u8 as f32 * u
            })
            .collect()
    }

    fn check(w: usize, h: usize, r: usize, rows: Range<usize>) {
        let img = image(w, h, (w * 31 + h * 7 + r) as u64);
        let want = reference(&img, w, h, r, eps_of);
        let got = streamed(&img, w, h, r, rows.clone());
        for y in 0..h {
            for x in 0..w {
                let (g, t) = (got[y * w + x], want[y * w + x]);
                if rows.contains(&y) {
                    let err = (g as f64 - t).abs() / t.abs();
                    assert!(err < 1e-5, "{w}×{h} r {r} at ({x}, {y}): {g} vs {t}");
                } else {
                    assert!(g.is_nan(), "{w}×{h} r {r}: row {y} outside {rows:?} written");
                }
            }
        }
    }

    #[test]
    fn matches_the_definition_at_every_radius_and_size() {
        for (w, h) in [(1, 1), (2, 3), (3, 2), (7, 1), (1, 9), (17, 11), (40, 33)] {
            for r in [0, 1, 2, 4, 9, 50] {
                check(w, h, r, 0..h);
            }
        }
    }

    #[test]
    fn a_band_of_rows_is_the_whole_planes_result() {
        let (w, h) = (29, 41);
        for r in [0, 1, 3, 8, 30] {
            for rows in [0..5, 3..4, 10..27, 35..41, 40..41, 17..100] {
                check(w, h, r, rows.start..rows.end.min(h));
            }
        }
        // the same filter object reused from band to band, out of order
        let img = image(w, h, 3);
        let want = reference(&img, w, h, 3, eps_of);
        let mut g = SelfGuided::new(w, h, 3);
        let mut got = vec![0f32; w * h];
        for band in [20..41, 0..7, 7..20] {
            g.run(
                band,
                |t, row| row.copy_from_slice(&img[t * w..(t + 1) * w]),
                |s, m, e| {
                    for (x, (e, &m)) in e.iter_mut().zip(m).enumerate() {
                        *e = eps_of(s * w + x, m) as f32;
                    }
                },
                |y, row| got[y * w..(y + 1) * w].copy_from_slice(row),
            );
        }
        for (g, t) in got.iter().zip(&want) {
            assert!((*g as f64 - t).abs() < 1e-5 * t.abs(), "{g} vs {t}");
        }
    }

    #[test]
    fn window_sums_clamp_at_both_ends() {
        let v = [1.0, 2.0, 4.0, 8.0, 16.0];
        let mut p = vec![0.0];
        for x in v {
            p.push(p.last().unwrap() + x);
        }
        let mut out = [0.0; 5];
        window_sums(&p, 1, &mut out);
        assert_eq!(out, [3.0, 7.0, 14.0, 28.0, 24.0]);
        window_sums(&p, 7, &mut out);
        assert_eq!(out, [31.0; 5]);
        window_sums(&p, 0, &mut out);
        assert_eq!(out, v);
    }
}
