//! The row steps of a tile: phase sums, contrast, classification, kernels.

#[cfg(target_arch = "x86_64")]
use super::avx2::row_dot_avx2;
use super::kernels::KernelSet;
use super::scratch::{ChromaScratch, RowScratch, resize};
use super::{
    FastRenderer, LANES, LUMINANCE_MARGIN, NO_CLASS, PatchGeometry, RenderStats, dot,
    sat_case_index,
};

/// One output row of a tile: the padded input rows under it (from the patch's
/// top row), their stride, its width and where it starts in the frame.
pub(super) struct TileRow<'a> {
    pub(super) rows: &'a [f32],
    pub(super) stride: usize,
    pub(super) tw: usize,
    pub(super) r: usize,
    pub(super) c0: usize,
}

impl FastRenderer {
    /// The reference path's pixels of a tile row (class [`NO_CLASS`] in
    /// `rs.class`), rendered by [`Self::exact_pixel`] into `rs.lin`. They are
    /// few and far between, so each 16-pixel chunk is tested whole first (one
    /// vector compare) rather than pixel by pixel.
    pub(super) fn exact_pixels(
        &self,
        set: &KernelSet,
        row: &TileRow<'_>,
        rs: &mut RowScratch,
        st: &mut RenderStats,
    ) {
        let RowScratch {
            class,
            lin: [l0, l1, l2],
            patch,
            feat,
            ..
        } = rs;
        let tw = row.tw.min(class.len());
        for (k, chunk) in class[..tw].chunks(16).enumerate() {
            if !chunk.iter().fold(false, |a, &c| a | (c == NO_CLASS)) {
                continue;
            }
            for (j, _) in chunk.iter().enumerate().filter(|(_, c)| **c == NO_CLASS) {
                let i = k * 16 + j;
                let v = self.exact_pixel(set, row, i, (&mut patch[..], &mut feat[..]), st);
                l0[i] = v[0];
                l1[i] = v[1];
                l2[i] = v[2];
            }
        }
    }

    /// The reference classification of a gathered patch: (class, sat case, fell back, texture).
    #[inline]
    pub(super) fn classify_exact(
        &self,
        patch: &[f32],
        r: usize,
        c: usize,
    ) -> (usize, usize, bool, bool) {
        let pos = self.geo.position(r, c);
        let s = self.geo.stats(patch, pos);
        let band = self.geo.band_of(s.luminance, &s.channel_means);
        let (sat, fell_back) = if self.sat_classes && s.sat_mask != 0 {
            sat_case_index(&self.sat_cases, s.sat_mask, &s.channel_means)
        } else {
            (0, false)
        };
        let group = self.group(pos, band, sat);
        let texture = self.contrast_classes && s.contrast > self.contrast_thresholds[group];
        (group * 2 + texture as usize, sat, fell_back, texture)
    }

    #[inline(always)]
    pub(super) fn group(&self, pos: usize, band: usize, sat: usize) -> usize {
        (pos * self.n_bands + band) * self.sat_cases.len() + sat
    }

    /// The chroma class of every pixel of a tile row (`tw` columns, row parity
    /// `rpar`, first column's parity `cpar`) from its phase means, as
    /// [`PatchGeometry::chroma_of`] computes it, a class (all pixels) at a time
    /// so that the loops vectorise: with AVX2 when the tile runs with it
    /// (`SIMD`), kept out of line so that one-class tables do not carry it.
    #[inline(never)]
    pub(super) fn chroma_row<const SIMD: bool>(
        &self,
        means: &[Vec<f32>; 4],
        parity: (usize, usize),
        tw: usize,
        cs: &mut ChromaScratch,
    ) {
        #[cfg(target_arch = "x86_64")]
        if SIMD {
            // SAFETY: the tile runs with `SIMD` only where AVX2 and FMA were detected
            unsafe { self.chroma_row_avx2(means, parity, tw, cs) };
            return;
        }
        self.chroma_row_body(means, parity, tw, cs);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn chroma_row_avx2(
        &self,
        means: &[Vec<f32>; 4],
        parity: (usize, usize),
        tw: usize,
        cs: &mut ChromaScratch,
    ) {
        self.chroma_row_body(means, parity, tw, cs);
    }

    /// [`Self::chroma_row`]'s loops; separate multiplies and adds (no fused
    /// ones), so every instruction set gives the reference's scores.
    #[inline(always)]
    fn chroma_row_body(
        &self,
        means: &[Vec<f32>; 4],
        (rpar, cpar): (usize, usize),
        tw: usize,
        cs: &mut ChromaScratch,
    ) {
        let nc = self.geo.n_channels();
        cs.means.resize_with(nc, Vec::new);
        for v in cs.means.iter_mut() {
            resize(v, tw);
        }
        for par in 0..2 {
            // pixels of this column parity sit at CFA position `pos`
            let pos = rpar * 2 + (cpar + par) % 2;
            for (p, &ch) in self.phase_channels[pos].iter().enumerate() {
                let (dst, src) = (&mut cs.means[ch as usize][..tw], &means[p][..tw]);
                for i in (par..tw).step_by(2) {
                    dst[i] = src[i].max(0.0);
                }
            }
        }
        for v in [&mut cs.score, &mut cs.scale, &mut cs.s1, &mut cs.s2] {
            resize(v, tw);
        }
        let scale = &mut cs.scale[..tw];
        scale.fill(0.0);
        for (m, &w) in cs.means.iter().zip(&self.chroma_scale) {
            for (s, &v) in scale.iter_mut().zip(&m[..tw]) {
                *s += w * v;
            }
        }
        cs.s1[..tw].fill(f32::INFINITY);
        cs.s2[..tw].fill(f32::INFINITY);
        cs.best.clear();
        cs.best.resize(tw, 0);
        for (k, a) in self.geo.chroma_coefficients().iter().enumerate() {
            let score = &mut cs.score[..tw];
            score.fill(0.0);
            for (ch, m) in cs.means.iter().enumerate() {
                let w = a[ch];
                for (s, &v) in score.iter_mut().zip(&m[..tw]) {
                    *s += w * v;
                }
            }
            let (s1, s2, best) = (&mut cs.s1[..tw], &mut cs.s2[..tw], &mut cs.best[..tw]);
            for i in 0..tw {
                let v = score[i];
                let lower = v < s1[i];
                s2[i] = s2[i].min(s1[i].max(v));
                best[i] = if lower { k as u32 } else { best[i] };
                s1[i] = s1[i].min(v);
            }
        }
    }

    /// The reference path for the pixel at column `i` of a tile row: gather its
    /// patch from the row's buffer into `patch`, classify it with the reference
    /// code and apply the table's layout of `set` (`feat`: its features).
    #[inline(always)]
    pub(super) fn exact_pixel(
        &self,
        set: &KernelSet,
        row: &TileRow<'_>,
        i: usize,
        (patch, feat): (&mut [f32], &mut [f32]),
        st: &mut RenderStats,
    ) -> [f32; 4] {
        let s = self.geo.size;
        let nf = self.n_features;
        let (r, c) = (row.r, row.c0 + i);
        for dy in 0..s {
            let o = dy * row.stride + i;
            patch[dy * s..dy * s + s].copy_from_slice(&row.rows[o..o + s]);
        }
        let (class, sat, fell_back, texture) = self.classify_exact(patch, r, c);
        st.exact_path += 1;
        st.saturated += (sat != 0) as u64;
        st.fallback += fell_back as u64;
        st.texture += texture as u64;
        let pos = self.geo.position(r, c);
        self.geo.features(patch, pos, self.sat_cases[sat], feat);
        let k = &set.flat[class * 3 * nf..(class + 1) * 3 * nf];
        [
            dot(&k[..nf], feat),
            dot(&k[nf..2 * nf], feat),
            dot(&k[2 * nf..], feat),
            0.0,
        ]
    }
}

/// The largest value of a row of clamped (finite) volts, 16 lanes at a time.
#[inline(always)]
pub(super) fn row_peak(row: &[f32]) -> f32 {
    let mut m = [0f32; 16];
    let chunks = row.chunks_exact(16);
    let rest = chunks.remainder();
    for c in chunks {
        for l in 0..16 {
            m[l] = if c[l] > m[l] { c[l] } else { m[l] };
        }
    }
    let tail = rest.iter().fold(0f32, |a, &v| if v > a { v } else { a });
    m.iter().fold(tail, |a, &v| if v > a { v } else { a })
}

/// Horizontal sums of one buffer row over the patch's even (`he`) and odd
/// (`ho`) column offsets from the centre, 16 columns at a time, in one pass.
#[inline(always)]
pub(super) fn phase_sums_row<const P: usize>(row: &[f32], he: &mut [f32], ho: &mut [f32]) {
    const W: usize = 16;
    let rad = P / 2;
    for (c, (e16, o16)) in he
        .chunks_exact_mut(W)
        .zip(ho.chunks_exact_mut(W))
        .enumerate()
    {
        let x0 = c * W;
        let (mut e, mut o) = ([0f32; W], [0f32; W]);
        for d in 0..P {
            // a short row (never expected) sums zeros
            let v: &[f32; W] = row
                .get(x0 + d..x0 + d + W)
                .and_then(|r| r.try_into().ok())
                .unwrap_or(&[0.0; W]);
            let acc = if (d + rad).is_multiple_of(2) {
                &mut e
            } else {
                &mut o
            };
            for l in 0..W {
                acc[l] += v[l];
            }
        }
        e16.copy_from_slice(&e);
        o16.copy_from_slice(&o);
    }
}

/// `dst[i] += src[i]`.
#[inline(always)]
pub(super) fn add_into(dst: &mut [f32], src: &[f32]) {
    for (o, &v) in dst.iter_mut().zip(src) {
        *o += v;
    }
}

/// Mean absolute deviation of each patch value from its phase's mean, for a
/// row of pixels; `rows` starts at the patch's top row, `means[p]` are the
/// per-pixel means of phase p. Accumulates 8 pixels at a time in registers.
#[inline(always)]
pub(super) fn contrast_row(
    rows: &[f32],
    stride: usize,
    s: usize,
    rad: usize,
    means: &[Vec<f32>; 4],
    inv_area: f32,
    out: &mut [f32],
) {
    let n = out.len();
    // one bounds check for everything the loop below reads; NaN (never expected)
    // sends the pixels to the reference path
    if s == 0 || rows.len() < (s - 1) * stride + n + s - 1 || means.iter().any(|m| m.len() < n) {
        out.fill(f32::NAN);
        return;
    }
    for (ci, o) in out.chunks_exact_mut(LANES).enumerate() {
        let i0 = ci * LANES;
        let mut acc = [0f32; LANES];
        for dy in 0..s {
            let pr = (dy + rad) % 2;
            let row = &rows[dy * stride + i0..dy * stride + i0 + s - 1 + LANES];
            let ma: &[f32; LANES] = means[pr * 2 + rad % 2][i0..i0 + LANES]
                .try_into()
                .unwrap_or(&[0.0; LANES]);
            let mb: &[f32; LANES] = means[pr * 2 + (1 + rad) % 2][i0..i0 + LANES]
                .try_into()
                .unwrap_or(&[0.0; LANES]);
            // even and odd column offsets: one phase mean each
            for (start, m) in [(0, ma), (1, mb)] {
                for dx in (start..s).step_by(2) {
                    let v: &[f32; LANES] = row[dx..dx + LANES].try_into().unwrap_or(&[0.0; LANES]);
                    for l in 0..LANES {
                        acc[l] += (v[l] - m[l]).abs();
                    }
                }
            }
        }
        for l in 0..LANES {
            o[l] = acc[l] * inv_area;
        }
    }
}

/// Luminance → level without a search: a table over [0, swing] whose bins
/// lie wholly inside one level, farther than the margin from its edges;
/// other bins (and values outside the table) go to the reference path.
#[derive(Clone, Debug)]
pub(super) struct LevelLut {
    pub(super) scale: f32,
    pub(super) bins: Vec<u16>,
}

impl LevelLut {
    const BINS: usize = 8192;
    const AMBIGUOUS: u16 = u16::MAX;

    pub(super) fn new(geo: &PatchGeometry, swing: f32) -> Self {
        let width = swing / Self::BINS as f32;
        let edges = geo.level_edges();
        let bins = (0..Self::BINS)
            .map(|b| {
                let lo = b as f32 * width - LUMINANCE_MARGIN;
                let hi = (b + 1) as f32 * width + LUMINANCE_MARGIN;
                let (l0, l1) = (geo.level_of(lo), geo.level_of(hi));
                let clear = edges.iter().all(|&e| e < lo || e > hi);
                if l0 == l1 && clear && l0 < usize::from(Self::AMBIGUOUS) {
                    l0 as u16
                } else {
                    Self::AMBIGUOUS
                }
            })
            .collect();
        Self {
            scale: 1.0 / width,
            bins,
        }
    }

    #[inline(always)]
    pub(super) fn level(&self, lum: f32) -> Option<usize> {
        // `as usize` saturates (negative and NaN give 0, which is then range-checked by value)
        let x = lum * self.scale;
        // NaN fails both comparisons
        if !(0.0..Self::BINS as f32).contains(&x) {
            return None;
        }
        // SAFETY: x is finite and in [0, BINS), so it fits a u32.
        let i = unsafe { x.to_int_unchecked::<u32>() } as usize;
        let l = *self.bins.get(i)?;
        (l != Self::AMBIGUOUS).then_some(l as usize)
    }
}

/// The 3 outputs (+ a spare lane) of one pixel: its patch rows (8 values read
/// from the tile buffer, weights beyond the patch are zero) against the class's row kernels.
#[inline(always)]
pub(super) fn row_dot<const SIMD: bool>(
    buf: &[f32],
    stride: usize,
    i: usize,
    s: usize,
    k: &[f32],
) -> [f32; 4] {
    #[cfg(target_arch = "x86_64")]
    if SIMD {
        // SAFETY: SIMD is only true inside `tile_avx2`, which runs when the CPU has
        // AVX2 + FMA; every load is bounds-checked by the slicing below.
        return unsafe { row_dot_avx2(buf, stride, i, s, k) };
    }
    let mut acc = [0f32; 4];
    let bias = &k[3 * s * LANES..3 * s * LANES + 3];
    for (o, a) in acc.iter_mut().take(3).enumerate() {
        let mut lanes = [0f32; LANES];
        for dy in 0..s {
            let p = &buf[(dy * stride + i)..(dy * stride + i + LANES)];
            let w = &k[(o * s + dy) * LANES..(o * s + dy + 1) * LANES];
            for l in 0..LANES {
                lanes[l] += p[l] * w[l];
            }
        }
        *a = lanes.iter().sum::<f32>() + bias[o];
    }
    acc
}
