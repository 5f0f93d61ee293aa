//! The self-guided filter (He, Sun and Tang, *Guided image filtering*, 2010/2013) with a
//! per-pixel ε, streamed down a band of rows of a plane: the denoiser's one filter
//! ([`super::denoise`]), and the L3 renderer's chroma stage's ([`crate::l3::render::chroma`]).
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

/// One self-guided filter of radius `r` down planes of a given height, with its rings and
/// accumulators (reused from band to band, and resized to each band's width).
pub(crate) struct SelfGuided {
    h: usize,
    /// The radius asked for, and the one used on the current width (cut to the plane's
    /// sides: a larger one is the whole plane's).
    radius: usize,
    r: usize,
    w: usize,
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
    /// A filter of radius `r` for planes `height` rows high.
    pub(crate) fn new(height: usize, r: usize) -> Self {
        Self {
            h: height,
            radius: r,
            r: 0,
            w: 0,
            ring: 0,
            inv_nx: Vec::new(),
            input: Vec::new(),
            a: Vec::new(),
            b: Vec::new(),
            col: Default::default(),
            prefix: Default::default(),
            mean: Vec::new(),
            mean_sq: Vec::new(),
            eps: Vec::new(),
            out: Vec::new(),
        }
    }

    /// Size the buffers for planes `w` wide.
    fn set_width(&mut self, w: usize) {
        if w == self.w && !self.inv_nx.is_empty() {
            return;
        }
        let (h, r) = (self.h, self.radius.min(w.max(self.h)));
        let ring = (2 * r + 2).min(h).max(1);
        (self.w, self.r, self.ring) = (w, r, ring);
        self.inv_nx = (0..w)
            .map(|x| 1.0 / ((x + r + 1).min(w) - x.saturating_sub(r)) as f64)
            .collect();
        for v in [&mut self.input, &mut self.a, &mut self.b] {
            v.resize(ring * w, 0.0);
        }
        for v in self
            .col
            .iter_mut()
            .chain([&mut self.mean, &mut self.mean_sq])
        {
            v.resize(w, 0.0);
        }
        for v in &mut self.prefix {
            v.resize(w + 1, 0.0);
        }
        self.eps.resize(w, 0.0);
        self.out.resize(w, 0.0);
    }

    /// Filter the rows `rows` of the `width`-wide plane whose row `t` `input(t, row)` writes,
    /// with `eps(s, m, e)` writing row `s`'s ε into `e` from its window means `m` of the
    /// input; `emit(y, out)` receives each output row, in order (see [`run_side_by_side`]).
    #[cfg(test)]
    pub(super) fn run(
        &mut self,
        width: usize,
        rows: Range<usize>,
        mut input: impl FnMut(usize, &mut [f32]),
        mut eps: impl FnMut(usize, &[f64], &mut [f32]),
        mut emit: impl FnMut(usize, &[f32]),
    ) {
        run_side_by_side(
            std::slice::from_mut(self),
            width,
            rows,
            |_, t, row| input(t, row),
            |_, s, m, e| eps(s, m, e),
            |_, y, row| emit(y, row),
        );
    }

    #[inline(always)]
    fn row_of(&self, t: usize) -> Range<usize> {
        let at = (t % self.ring) * self.w;
        at..at + self.w
    }

    /// Input row `take` into its ring slot and the `I`, `I²` accumulators; row `drop` out
    /// of them (it has left the window).
    #[inline(always)]
    fn slide_input(
        &mut self,
        take: Option<usize>,
        drop: Option<usize>,
        input: &mut impl FnMut(usize, &mut [f32]),
    ) {
        let (new, old) = (take.map(|t| self.row_of(t)), drop.map(|t| self.row_of(t)));
        if let (Some(t), Some(at)) = (take, &new) {
            input(t, &mut self.input[at.clone()]);
        }
        let [ci, cii, ..] = &mut self.col;
        let cols = ci.iter_mut().zip(cii.iter_mut());
        let row = |at: Range<usize>| &self.input[at];
        match (new, old) {
            (Some(new), Some(old)) => {
                for ((i, ii), (&n, &o)) in cols.zip(row(new).iter().zip(row(old))) {
                    let (n, o) = (n as f64, o as f64);
                    *i += n - o;
                    *ii += n * n - o * o;
                }
            }
            (Some(new), None) => {
                for ((i, ii), &n) in cols.zip(row(new)) {
                    let n = n as f64;
                    *i += n;
                    *ii += n * n;
                }
            }
            (None, Some(old)) => {
                for ((i, ii), &o) in cols.zip(row(old)) {
                    let o = o as f64;
                    *i -= o;
                    *ii -= o * o;
                }
            }
            (None, None) => {}
        }
    }

    /// Take row `t` of `a` and `b` out of their accumulators.
    #[inline(always)]
    fn drop_coefficients(&mut self, t: usize) {
        let at = self.row_of(t);
        let [.., ca, cb] = &mut self.col;
        let (a, b) = (&self.a[at.clone()], &self.b[at]);
        for ((ca, cb), (&a, &b)) in ca.iter_mut().zip(cb.iter_mut()).zip(a.iter().zip(b)) {
            *ca -= a as f64;
            *cb -= b as f64;
        }
    }

    /// Row `s` of `a` and `b` into their rings and accumulators, row `leaving` out of the
    /// accumulators.
    #[inline(always)]
    fn coefficients(
        &mut self,
        s: usize,
        leaving: Option<usize>,
        eps: &mut impl FnMut(usize, &[f64], &mut [f32]),
    ) {
        let (h, r) = (self.h, self.r);
        let k = 1.0 / ((s + r + 1).min(h) - s.saturating_sub(r)) as f64;
        let [ci, cii, ..] = &self.col;
        let [p0, p1] = &mut self.prefix;
        prefix_sums(ci, p0);
        prefix_sums(cii, p1);
        window_means(p0, r, &self.inv_nx, k, &mut self.mean);
        window_means(p1, r, &self.inv_nx, k, &mut self.mean_sq);
        eps(s, &self.mean, &mut self.eps);
        let (at, old) = (self.row_of(s), leaving.map(|t| self.row_of(t)));
        let stats = self.mean.iter().zip(&self.mean_sq).zip(&self.eps);
        let new = self.a[at.clone()]
            .iter_mut()
            .zip(self.b[at.clone()].iter_mut())
            .zip(stats);
        for ((a, b), ((&m, &q), &e)) in new {
            let cov = q - m * m;
            let ai = cov / (cov.max(0.0) + e.max(f32::MIN_POSITIVE) as f64);
            *a = ai as f32;
            *b = (m - ai * m) as f32;
        }
        let [.., ca, cb] = &mut self.col;
        let cols = ca.iter_mut().zip(cb.iter_mut());
        let (a_new, b_new) = (&self.a[at.clone()], &self.b[at]);
        match old {
            // (row s's ring slot is not row `leaving`'s: they are 2r + 1 apart)
            Some(old) => {
                let (a_old, b_old) = (&self.a[old.clone()], &self.b[old]);
                let ab = a_new.iter().zip(b_new).zip(a_old.iter().zip(b_old));
                for ((ca, cb), ((&a, &b), (&ao, &bo))) in cols.zip(ab) {
                    *ca += a as f64 - ao as f64;
                    *cb += b as f64 - bo as f64;
                }
            }
            None => {
                for ((ca, cb), (&a, &b)) in cols.zip(a_new.iter().zip(b_new)) {
                    *ca += a as f64;
                    *cb += b as f64;
                }
            }
        }
    }

    /// Output row `y` from the `a`, `b` accumulators (holding its window's rows).
    #[inline(always)]
    fn output(&mut self, y: usize, emit: &mut impl FnMut(usize, &[f32])) {
        let (h, r, w) = (self.h, self.r, self.w);
        let k = 1.0 / ((y + r + 1).min(h) - y.saturating_sub(r)) as f64;
        let at = self.row_of(y);
        let [.., ca, cb] = &self.col;
        let [pa, pb] = &mut self.prefix;
        prefix_sums(ca, pa);
        prefix_sums(cb, pb);
        let i = &self.input[at];
        let (pa, pb) = (&*pa, &*pb);
        let clamped = |x: usize| {
            let (lo, hi) = (x.saturating_sub(r), (x + r + 1).min(w));
            let a = pa[hi] - pa[lo];
            let b = pb[hi] - pb[lo];
            ((a * i[x] as f64 + b) * (self.inv_nx[x] * k)) as f32
        };
        let (lo, hi) = interior(w, r);
        for (x, o) in self.out[..lo].iter_mut().enumerate() {
            *o = clamped(x);
        }
        if hi > lo {
            let kk = k / (2 * r + 1) as f64;
            let sums = (pa[lo + r + 1..hi + r + 1].iter().zip(&pa[lo - r..hi - r]))
                .zip(pb[lo + r + 1..hi + r + 1].iter().zip(&pb[lo - r..hi - r]));
            for ((o, &i), ((a1, a0), (b1, b0))) in
                self.out[lo..hi].iter_mut().zip(&i[lo..hi]).zip(sums)
            {
                *o = (((a1 - a0) * i as f64 + (b1 - b0)) * kk) as f32;
            }
        }
        for x in hi..w {
            self.out[x] = clamped(x);
        }
        emit(y, &self.out);
    }
}

/// Run `filters` (all of one radius, for planes of one height) side by side over the rows
/// `rows` of `width`-wide planes: filter `k`'s plane has row `t` written by
/// `input(k, t, row)`, its ε at row `s` by `eps(k, s, m, e)` from the window means `m` of its
/// input, and `emit(k, y, out)` receives its output rows in order. `input` is called once
/// per row in `rows` widened by `2r` (clamped to the plane), `eps` once per row widened by
/// `r`. Side by side, the filters take their rows at the same time, so that inputs made from
/// the same source rows (a pixel's channels) read them once. Runs with AVX2 where the CPU
/// has it (the same arithmetic, more of it per instruction).
pub(crate) fn run_side_by_side(
    filters: &mut [SelfGuided],
    width: usize,
    rows: Range<usize>,
    input: impl FnMut(usize, usize, &mut [f32]),
    eps: impl FnMut(usize, usize, &[f64], &mut [f32]),
    emit: impl FnMut(usize, usize, &[f32]),
) {
    for f in filters.iter_mut() {
        f.set_width(width);
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU reports AVX2.
        return unsafe { run_avx2(filters, rows, input, eps, emit) };
    }
    run_rows(filters, rows, input, eps, emit)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn run_avx2(
    filters: &mut [SelfGuided],
    rows: Range<usize>,
    input: impl FnMut(usize, usize, &mut [f32]),
    eps: impl FnMut(usize, usize, &[f64], &mut [f32]),
    emit: impl FnMut(usize, usize, &[f32]),
) {
    run_rows(filters, rows, input, eps, emit)
}

/// [`run_side_by_side`]'s body (inlined into each instruction set's function).
#[inline(always)]
fn run_rows(
    filters: &mut [SelfGuided],
    rows: Range<usize>,
    mut input: impl FnMut(usize, usize, &mut [f32]),
    mut eps: impl FnMut(usize, usize, &[f64], &mut [f32]),
    mut emit: impl FnMut(usize, usize, &[f32]),
) {
    let Some(first) = filters.first() else {
        return;
    };
    let (h, r) = (first.h, first.r);
    debug_assert!(filters.iter().all(|f| (f.h, f.r, f.w) == (h, r, first.w)));
    let rows = rows.start..rows.end.min(h);
    if rows.is_empty() || first.w == 0 {
        return;
    }
    // a/b rows s_lo..s_hi feed the output rows; the I accumulators start on s_lo's window
    let (s_lo, s_hi) = (rows.start.saturating_sub(r), (rows.end + r).min(h));
    for (k, f) in filters.iter_mut().enumerate() {
        for c in &mut f.col {
            c.fill(0.0);
        }
        for t in s_lo.saturating_sub(r)..(s_lo + r + 1).min(h) {
            f.slide_input(Some(t), None, &mut |t, row| input(k, t, row));
        }
    }
    let mut y = rows.start;
    for s in s_lo..s_hi {
        // the a/b row leaving the next output row's window (if this band added it)
        let leaving = s.checked_sub(2 * r + 1).filter(|&t| t >= s_lo);
        let out = y < rows.end && y + r <= s;
        for (k, f) in filters.iter_mut().enumerate() {
            if s > s_lo {
                let take = (s + r < h).then_some(s + r);
                f.slide_input(take, s.checked_sub(r + 1), &mut |t, row| input(k, t, row));
            }
            f.coefficients(s, leaving, &mut |s, m, e| eps(k, s, m, e));
            if out {
                f.output(y, &mut |y, row| emit(k, y, row));
            }
        }
        y += out as usize;
    }
    // the plane's last rows: their windows end at its bottom
    while y < rows.end {
        for (k, f) in filters.iter_mut().enumerate() {
            if y > s_lo + r {
                f.drop_coefficients(y - r - 1);
            }
            f.output(y, &mut |y, row| emit(k, y, row));
        }
        y += 1;
    }
}

/// The columns `lo..hi` whose windows of radius `r` lie inside a row of `w`.
#[inline(always)]
fn interior(w: usize, r: usize) -> (usize, usize) {
    let lo = r.min(w);
    (lo, w.saturating_sub(r + 1).max(lo))
}

/// The prefix sums `p[0] = 0`, `p[x + 1] = p[x] + c[x]`, in four runs side by side (each
/// from 0, then shifted by the runs before it), so that the additions need not wait on each
/// other.
#[inline(always)]
fn prefix_sums(c: &[f64], p: &mut [f64]) {
    let w = c.len();
    let n = w / 4;
    p[0] = 0.0;
    let (p0, rest) = p[1..].split_at_mut(n);
    let (p1, rest) = rest.split_at_mut(n);
    let (p2, p3) = rest.split_at_mut(n);
    let (c0, c1, c2, c3) = (&c[..n], &c[n..2 * n], &c[2 * n..3 * n], &c[3 * n..]);
    let mut s = [0f64; 4];
    for i in 0..n {
        s[0] += c0[i];
        p0[i] = s[0];
        s[1] += c1[i];
        p1[i] = s[1];
        s[2] += c2[i];
        p2[i] = s[2];
        s[3] += c3[i];
        p3[i] = s[3];
    }
    for (p, &c) in p3[n..].iter_mut().zip(&c3[n..]) {
        s[3] += c;
        *p = s[3];
    }
    let mut base = 0.0;
    for (run, total) in [p1, p2, p3].into_iter().zip(s) {
        base += total;
        for v in run {
            *v += base;
        }
    }
}

/// `out[x] = (p[min(x + r + 1, w)] − p[max(x − r, 0)]) · inv_nx[x] · k` for prefix sums `p`
/// (`w + 1` long): the means over windows of radius `r` clamped to the row (`inv_nx` the
/// windows' inverse widths, `k` the inverse height); the interior in one vectorisable run.
#[inline(always)]
fn window_means(p: &[f64], r: usize, inv_nx: &[f64], k: f64, out: &mut [f64]) {
    let w = out.len();
    let clamped = |x: usize| (p[(x + r + 1).min(w)] - p[x.saturating_sub(r)]) * (inv_nx[x] * k);
    let (lo, hi) = interior(w, r);
    for (x, o) in out[..lo].iter_mut().enumerate() {
        *o = clamped(x);
    }
    if hi > lo {
        let kk = k / (2 * r + 1) as f64;
        let inner = out[lo..hi]
            .iter_mut()
            .zip(&p[lo + r + 1..hi + r + 1])
            .zip(&p[lo - r..hi - r]);
        for ((o, &a), &b) in inner {
            *o = (a - b) * kk;
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
        let mut g = SelfGuided::new(h, r);
        g.run(
            w,
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
                0.1 + 0.05 * u + step + 0.5 * (i / w).is_multiple_of(5) as u8 as f32 * u
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
                    assert!(
                        g.is_nan(),
                        "{w}×{h} r {r}: row {y} outside {rows:?} written"
                    );
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
        let mut g = SelfGuided::new(h, 3);
        let mut got = vec![0f32; w * h];
        for band in [20..41, 0..7, 7..20] {
            g.run(
                w,
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
    fn prefix_sums_and_window_means_clamp_at_both_ends() {
        let v: Vec<f64> = (0..11).map(|i| (1u32 << i) as f64).collect();
        for w in [0, 1, 3, 4, 5, 11] {
            let mut p = vec![f64::NAN; w + 1];
            prefix_sums(&v[..w], &mut p);
            assert_eq!(
                p,
                (0..=w)
                    .map(|x| ((1u32 << x) - 1) as f64)
                    .collect::<Vec<_>>()
            );
        }
        let mut p = vec![0.0; 6];
        prefix_sums(&v[..5], &mut p);
        let mut out = [0.0; 5];
        for (r, k, want) in [
            (
                1,
                1.0,
                [3.0 / 2.0, 7.0 / 3.0, 14.0 / 3.0, 28.0 / 3.0, 24.0 / 2.0],
            ),
            (7, 0.5, [3.1; 5]),
            (0, 1.0, [1.0, 2.0, 4.0, 8.0, 16.0]),
        ] {
            let mut g = SelfGuided::new(1, r);
            g.set_width(5);
            let inv_nx = g.inv_nx;
            window_means(&p, r, &inv_nx, k, &mut out);
            for (o, w) in out.iter().zip(want) {
                assert!((o - w).abs() < 1e-12, "r {r}: {out:?}");
            }
        }
    }
}
