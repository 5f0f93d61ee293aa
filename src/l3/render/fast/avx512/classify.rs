//! The classification of 16 pixels at a time.

#![allow(unsafe_op_in_unsafe_fn)]

use std::arch::x86_64::*;

use super::super::{CONTRAST_MARGIN, LUMINANCE_MARGIN, NO_CLASS};
use super::WIDE;

/// The most luminance levels the register tables hold.
pub(in super::super) const MAX_LEVELS: usize = 32;

/// What classification needs beyond the row data, prepared once per tile.
pub(in super::super) struct ClassParams {
    /// Per CFA position (2 · row parity + column parity), the phase map:
    /// `mean[p] = Σ_q to_mean[p][q] · sum[q]` and `luminance = Σ_q lum[q] ·
    /// sum[q]`, phases relative to the centre (0: the centre's, 1: same row
    /// other column, 2: other row same column, 3: both other).
    pub to_mean: [[[f32; 4]; 4]; 4],
    pub lum: [[f32; 4]; 4],
    /// Every position has the same diagonal map (each phase its own
    /// channel): the means are one multiply per phase.
    pub diagonal: bool,
    /// Per phase, its values in the patch.
    pub count: [f32; 4],
    pub inv_area: f32,
    /// Level edges padded with +∞ to 32: `edges[l]` is the top of level l.
    pub edges: [f32; MAX_LEVELS],
    /// The bottom of each level: −∞, then the edges.
    pub below: [f32; MAX_LEVELS],
    /// Per CFA position, the contrast threshold of each level (sat case 0), padded with +∞.
    pub thresholds: [[f32; MAX_LEVELS]; 4],
    pub n_levels: u32,
    /// Chroma classes per level (1: none); with more, [`Self::chroma`].
    pub n_chroma: u32,
    pub chroma: Option<ChromaParams>,
    pub n_sat: u32,
    pub use_contrast: bool,
    /// Classes in the kernel layout, and values per class.
    pub n_classes: u32,
    pub kstride: u32,
}

/// What the chroma classification needs ([`FastRenderer::chroma_row`](super::super::FastRenderer::chroma_row)'s
/// scores, 16 pixels at a time).
pub(in super::super) struct ChromaParams {
    /// Per chroma class, its score weight per channel (0 past the sensor's channels).
    pub coef: Vec<[f32; 4]>,
    /// Per channel, the largest score weight in magnitude (the margin's scale).
    pub scale: [f32; 4],
    /// Per CFA position, the channel of each phase.
    pub phase_channels: [[u8; 4]; 4],
    pub n_channels: usize,
    /// Per CFA position and band (level × classes + class), the contrast
    /// threshold of saturation case 0.
    pub thresholds: Vec<f32>,
    /// [`CHROMA_MARGIN`](super::super::CHROMA_MARGIN) and
    /// [`CHROMA_MARGIN_FLOOR`](super::super::CHROMA_MARGIN_FLOOR).
    pub margin: f32,
    pub floor: f32,
}

/// Per-row counts from [`classify_row`].
#[derive(Default, Clone, Copy)]
pub(in super::super) struct RowCounts {
    pub texture: u64,
    pub exact: u64,
}

#[inline(always)]
fn tail_mask(i: usize, n: usize) -> u16 {
    if i + WIDE <= n {
        u16::MAX
    } else {
        ((1u32 << (n - i)) - 1) as u16
    }
}

/// One output row as the classification reads it.
#[derive(Clone, Copy)]
pub(in super::super) struct ClassifyRow<'a> {
    /// `P` rows of `tw_pad` horizontal sums over the even / odd column offsets
    /// of the patch, starting at the patch's top row.
    pub he: &'a [f32],
    pub ho: &'a [f32],
    pub tw_pad: usize,
    /// The tile buffer from the patch's top row, rows `stride` apart.
    pub buf: &'a [f32],
    pub stride: usize,
    /// Per pixel, whether its patch holds a saturated value (when the tile can).
    pub sat: Option<&'a [bool]>,
    /// Pixels in the row.
    pub tw: usize,
    /// The parities of the row and of the tile's first column.
    pub rpar: usize,
    pub cpar: usize,
}

/// Whether [`classify_row`]'s slices and parameters fit each other: every read and write
/// in bounds.
fn args_ok<const P: usize>(
    row: &ClassifyRow<'_>,
    prm: &ClassParams,
    class: &[u32],
    offsets: &[u32],
) -> bool {
    let (tw_pad, stride) = (row.tw_pad, row.stride);
    let (he, ho, buf, sat, tw) = (row.he, row.ho, row.buf, row.sat, row.tw);
    !(P == 0
        || tw > tw_pad
        || !tw_pad.is_multiple_of(WIDE)
        || he.len() < P * tw_pad
        || ho.len() < P * tw_pad
        || buf.len() < (P - 1) * stride + tw_pad + P - 1
        || class.len() < tw_pad
        || offsets.len() < tw_pad
        || prm.n_classes == 0
        || sat.is_some_and(|s| s.len() < tw_pad)
        || prm.n_levels as usize > MAX_LEVELS
        || prm.n_chroma == 0
        || prm.chroma.as_ref().is_some_and(|c| {
            c.coef.len() != prm.n_chroma as usize
                || c.n_channels > 4
                || c.phase_channels
                    .iter()
                    .flatten()
                    .any(|&ch| ch as usize >= c.n_channels)
                || c.thresholds.len() < 4 * (prm.n_levels * prm.n_chroma) as usize
        })
        || (prm.n_chroma > 1) != prm.chroma.is_some())
}

/// A row's per-lane constants for [`classify_row`]: its even and odd lanes sit at two
/// CFA positions, so every per-position parameter is a blend of the two.
struct RowLanes {
    /// The phase maps of the row's even and odd lanes, one register per coefficient.
    to_mean: [[__m512; 4]; 4],
    lum: [__m512; 4],
    /// The level edges and bottoms ([`ClassParams::edges`], [`ClassParams::below`]), each
    /// in two registers.
    edges: (__m512, __m512),
    below: (__m512, __m512),
    /// The contrast thresholds of the even and the odd lanes' positions, two registers each.
    thr_even: (__m512, __m512),
    thr_odd: (__m512, __m512),
    /// Each lane's CFA position.
    pos: __m512i,
    /// Where each lane's position's kernels start, and the step per band.
    base: __m512i,
    per_level: __m512i,
    /// Per channel, the phase that holds it for the even and the odd lanes (the last
    /// such phase, as the AVX2 path writes them).
    chroma_phase: [(usize, usize); 4],
    /// Per phase, its values in the patch.
    count: [__m512; 4],
}

/// The odd lanes of a 16-lane register.
const ODD_LANES: __mmask16 = 0xAAAA;

/// `even` in the even lanes, `odd` in the odd ones. (Functions, not closures, here and
/// below: a closure does not inherit its caller's target features.)
#[inline(always)]
unsafe fn lanes(even: f32, odd: f32) -> __m512 {
    _mm512_mask_blend_ps(ODD_LANES, _mm512_set1_ps(even), _mm512_set1_ps(odd))
}

/// A 32-entry table in two registers.
#[inline(always)]
unsafe fn pair(v: &[f32; MAX_LEVELS]) -> (__m512, __m512) {
    (
        _mm512_loadu_ps(v.as_ptr()),
        _mm512_loadu_ps(v.as_ptr().add(16)),
    )
}

impl RowLanes {
    /// The constants of a row of parity `rpar` whose first column has parity `cpar`.
    #[inline(always)]
    unsafe fn new(prm: &ClassParams, rpar: usize, cpar: usize) -> Self {
        // positions of even and odd lanes in this row
        let pos_even = rpar * 2 + cpar;
        let pos_odd = rpar * 2 + (1 - cpar);
        let (mut to_mean, mut lum) = ([[_mm512_setzero_ps(); 4]; 4], [_mm512_setzero_ps(); 4]);
        for p in 0..4 {
            lum[p] = lanes(prm.lum[pos_even][p], prm.lum[pos_odd][p]);
            for q in 0..4 {
                to_mean[p][q] = lanes(prm.to_mean[pos_even][p][q], prm.to_mean[pos_odd][p][q]);
            }
        }
        let pos = _mm512_mask_blend_epi32(
            ODD_LANES,
            _mm512_set1_epi32(pos_even as i32),
            _mm512_set1_epi32(pos_odd as i32),
        );
        // kernel offsets: class = ((pos · levels + level) · n_sat + 0) · 2 + texture
        let per_level = 2 * prm.n_sat * prm.kstride;
        let n_bands = prm.n_levels * prm.n_chroma;
        let mut chroma_phase = [(0usize, 0usize); 4];
        if let Some(c) = &prm.chroma {
            for (p, (&ce, &co)) in c.phase_channels[pos_even]
                .iter()
                .zip(&c.phase_channels[pos_odd])
                .enumerate()
            {
                chroma_phase[ce as usize].0 = p;
                chroma_phase[co as usize].1 = p;
            }
        }
        let mut count = [_mm512_setzero_ps(); 4];
        for (c, &n) in count.iter_mut().zip(&prm.count) {
            *c = _mm512_set1_ps(n);
        }
        Self {
            to_mean,
            lum,
            edges: pair(&prm.edges),
            below: pair(&prm.below),
            thr_even: pair(&prm.thresholds[pos_even]),
            thr_odd: pair(&prm.thresholds[pos_odd]),
            pos,
            base: _mm512_mullo_epi32(pos, _mm512_set1_epi32((n_bands * per_level) as i32)),
            per_level: _mm512_set1_epi32(per_level as i32),
            chroma_phase,
            count,
        }
    }

    /// The phase sums `s`, phase means `m` and luminance of 16 pixels from their patches'
    /// `P` rows of horizontal sums (`he`, `ho`, rows `tw_pad` apart, from the pixels').
    #[inline(always)]
    unsafe fn means<const P: usize>(
        &self,
        he: *const f32,
        ho: *const f32,
        tw_pad: usize,
        diagonal: bool,
    ) -> ([__m512; 4], [__m512; 4], __m512) {
        let rad = P / 2;
        let mut s = [_mm512_setzero_ps(); 4];
        for dy in 0..P {
            let e = _mm512_loadu_ps(he.add(dy * tw_pad));
            let o = _mm512_loadu_ps(ho.add(dy * tw_pad));
            let base = 2 * ((dy + rad) % 2);
            s[base] = _mm512_add_ps(s[base], e);
            s[base + 1] = _mm512_add_ps(s[base + 1], o);
        }
        let mut m = [_mm512_setzero_ps(); 4];
        if diagonal {
            for k in 0..4 {
                m[k] = _mm512_mul_ps(s[k], self.to_mean[k][k]);
            }
        } else {
            // the same order of operations as the AVX2 path's
            // `t[0]·q[0] + t[1]·q[1] + t[2]·q[2] + t[3]·q[3]`
            for k in 0..4 {
                let t = &self.to_mean[k];
                let a = _mm512_add_ps(_mm512_mul_ps(t[0], s[0]), _mm512_mul_ps(t[1], s[1]));
                let a = _mm512_add_ps(a, _mm512_mul_ps(t[2], s[2]));
                m[k] = _mm512_add_ps(a, _mm512_mul_ps(t[3], s[3]));
            }
        }
        let lw = &self.lum;
        let lum = _mm512_add_ps(
            _mm512_add_ps(_mm512_mul_ps(s[0], lw[0]), _mm512_mul_ps(s[1], lw[1])),
            _mm512_add_ps(_mm512_mul_ps(s[2], lw[2]), _mm512_mul_ps(s[3], lw[3])),
        );
        (s, m, lum)
    }

    /// The luminance level of 16 pixels: the number of level edges below `lum`, by a
    /// binary search over the two registers; and the lanes with an edge within the
    /// margin (or a NaN luminance), which the reference decides.
    #[inline(always)]
    unsafe fn level(&self, lum: __m512) -> (__m512i, __mmask16) {
        let (e0, e1) = self.edges;
        let mut lo = _mm512_setzero_si512();
        for step in [16, 8, 4, 2, 1] {
            let probe = _mm512_add_epi32(lo, _mm512_set1_epi32(step - 1));
            let e = _mm512_permutex2var_ps(e0, probe, e1);
            let k = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(e, lum);
            lo = _mm512_mask_add_epi32(lo, k, lo, _mm512_set1_epi32(step));
        }
        let top = _mm512_permutex2var_ps(e0, lo, e1);
        let bottom = _mm512_permutex2var_ps(self.below.0, lo, self.below.1);
        let margin = _mm512_set1_ps(LUMINANCE_MARGIN);
        // (NaN luminance fails both tests)
        let near = _mm512_cmp_ps_mask::<_CMP_NGT_UQ>(_mm512_sub_ps(lum, bottom), margin)
            | _mm512_cmp_ps_mask::<_CMP_NGE_UQ>(_mm512_sub_ps(top, lum), margin);
        (lo, near)
    }

    /// The contrast of 16 pixels (the mean absolute deviation from their phases' means
    /// over the patch) against the threshold of their class (`lo`: level; `band`: the
    /// level's chroma class when the table has them): the texture lanes, and those
    /// near the threshold (or NaN), which the reference decides.
    #[inline(always)]
    unsafe fn texture<const P: usize>(
        &self,
        prm: &ClassParams,
        patch: *const f32,
        stride: usize,
        (s, m): (&[__m512; 4], &[__m512; 4]),
        (lo, band): (__m512i, __m512i),
    ) -> (__mmask16, __mmask16) {
        // Σ |v − m_k| = Σ (2 · max(v, m_k) − v − m_k) = 2 · Σ max(v, m_k) − Σ_k (S_k + n_k · m_k):
        // two operations per value instead of three.
        let sum = sum_of_max::<P>(patch, stride, m);
        let mut rest = _mm512_add_ps(_mm512_add_ps(s[0], s[1]), _mm512_add_ps(s[2], s[3]));
        for k in 0..4 {
            rest = _mm512_fmadd_ps(self.count[k], m[k], rest);
        }
        let cv = _mm512_mul_ps(
            _mm512_fmsub_ps(sum, _mm512_set1_ps(2.0), rest),
            _mm512_set1_ps(prm.inv_area),
        );
        let t = match &prm.chroma {
            None => _mm512_mask_blend_ps(
                ODD_LANES,
                _mm512_permutex2var_ps(self.thr_even.0, lo, self.thr_even.1),
                _mm512_permutex2var_ps(self.thr_odd.0, lo, self.thr_odd.1),
            ),
            // (checked: 4 × bands thresholds; the band is clamped below the bands)
            Some(c) => _mm512_i32gather_ps::<4>(
                _mm512_add_epi32(
                    _mm512_mullo_epi32(
                        self.pos,
                        _mm512_set1_epi32((prm.n_levels * prm.n_chroma) as i32),
                    ),
                    band,
                ),
                c.thresholds.as_ptr(),
            ),
        };
        let gap = _mm512_castsi512_ps(_mm512_and_si512(
            _mm512_castps_si512(_mm512_sub_ps(cv, t)),
            _mm512_set1_epi32(0x7fff_ffff),
        ));
        (
            _mm512_cmp_ps_mask::<_CMP_GT_OQ>(cv, t),
            _mm512_cmp_ps_mask::<_CMP_NGE_UQ>(gap, _mm512_set1_ps(CONTRAST_MARGIN)),
        )
    }
}

/// Classify pixels `0..tw` of one output row.
///
/// - `class`: receives [`NO_CLASS`] where the reference code must decide, 0
///   elsewhere;
/// - `offsets`: receives where each pixel's kernels start in the AVX-512 layout
///   (class 0's for the reference path's pixels), for the kernel step
///   ([`apply_kernels`](super::apply_kernels)).
///
/// Returns `None` (and writes nothing) if a slice is too short.
///
/// # Safety
/// The CPU must have AVX-512 F, VL, BW and DQ, AVX2 and FMA.
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx2,fma")]
pub(in super::super) unsafe fn classify_row<const P: usize>(
    row: &ClassifyRow<'_>,
    prm: &ClassParams,
    class: &mut [u32],
    offsets: &mut [u32],
) -> Option<RowCounts> {
    if !args_ok::<P>(row, prm, class, offsets) {
        return None;
    }
    let ClassifyRow {
        he,
        ho,
        tw_pad,
        buf,
        stride,
        sat,
        tw,
        rpar,
        cpar,
    } = *row;
    let l = RowLanes::new(prm, rpar, cpar);
    let n_bands = prm.n_levels * prm.n_chroma;
    let per_texture = _mm512_set1_epi32(prm.kstride as i32);
    let last = _mm512_set1_epi32(((prm.n_classes - 1) * prm.kstride) as i32);
    let no_class = _mm512_set1_epi32(NO_CLASS as i32);
    // per-lane counts of texture and reference-path pixels, summed after the row
    let (mut n_texture, mut n_exact) = (_mm512_setzero_si512(), _mm512_setzero_si512());
    let one_i = _mm512_set1_epi32(1);
    let mut i = 0;
    while i < tw {
        let (s, m, lum) =
            l.means::<P>(he.as_ptr().add(i), ho.as_ptr().add(i), tw_pad, prm.diagonal);
        let (lo, mut exact) = l.level(lum);
        // the band: the level, or the level's chroma class
        let band = match &prm.chroma {
            None => lo,
            Some(c) => {
                let (best, sure) = match c.n_channels {
                    4 => chroma_classes::<4>(c, &m, &l.chroma_phase, ODD_LANES),
                    3 => chroma_classes::<3>(c, &m, &l.chroma_phase, ODD_LANES),
                    2 => chroma_classes::<2>(c, &m, &l.chroma_phase, ODD_LANES),
                    _ => chroma_classes::<1>(c, &m, &l.chroma_phase, ODD_LANES),
                };
                exact |= !sure;
                let band = _mm512_add_epi32(
                    _mm512_mullo_epi32(lo, _mm512_set1_epi32(prm.n_chroma as i32)),
                    best,
                );
                _mm512_min_epu32(band, _mm512_set1_epi32(n_bands as i32 - 1))
            }
        };
        let mut texture: __mmask16 = 0;
        if prm.use_contrast {
            let (t, near) = l.texture::<P>(prm, buf.as_ptr().add(i), stride, (&s, &m), (lo, band));
            texture = t;
            exact |= near;
        }
        if let Some(sat) = sat {
            let b = _mm_loadu_si128(sat.as_ptr().add(i).cast());
            exact |= _mm_cmpneq_epi8_mask(b, _mm_setzero_si128());
        }
        let valid = tail_mask(i, tw);
        exact &= valid;
        // where each pixel's kernels start (class 0's for the reference path's pixels)
        let off = _mm512_add_epi32(l.base, _mm512_mullo_epi32(band, l.per_level));
        let off = _mm512_mask_add_epi32(off, texture, off, per_texture);
        let off = _mm512_maskz_mov_epi32(!exact, _mm512_min_epu32(off, last));
        _mm512_storeu_si512(offsets.as_mut_ptr().add(i).cast(), off);
        let c = _mm512_maskz_mov_epi32(exact, no_class);
        _mm512_storeu_si512(class.as_mut_ptr().add(i).cast(), c);
        n_texture = _mm512_mask_add_epi32(n_texture, texture & !exact & valid, n_texture, one_i);
        n_exact = _mm512_mask_add_epi32(n_exact, exact, n_exact, one_i);
        i += WIDE;
    }
    Some(RowCounts {
        texture: u64::from(_mm512_reduce_add_epi32(n_texture) as u32),
        exact: u64::from(_mm512_reduce_add_epi32(n_exact) as u32),
    })
}

/// `Σ max(v, m_k)` over the `P × P` patches of 16 pixels whose patches' top-left values
/// start at `top` (rows `stride` apart), `m_k` the mean of the value's phase `k`.
#[inline(always)]
unsafe fn sum_of_max<const P: usize>(top: *const f32, stride: usize, m: &[__m512; 4]) -> __m512 {
    let rad = P / 2;
    let one = _mm512_set1_ps(1.0);
    // one accumulator per patch row, so the adds do not wait on each other
    let mut acc = [_mm512_setzero_ps(); P];
    for (dy, a) in acc.iter_mut().enumerate() {
        let pr = (dy + rad) % 2;
        let row = top.add(dy * stride);
        for dx in 0..P {
            let v = _mm512_loadu_ps(row.add(dx));
            // (the max takes an adder; the accumulation an FMA unit, which is
            // otherwise idle here)
            *a = _mm512_fmadd_ps(_mm512_max_ps(v, m[2 * pr + (dx + rad) % 2]), one, *a);
        }
    }
    let mut sum = acc[0];
    for a in &acc[1..] {
        sum = _mm512_add_ps(sum, *a);
    }
    sum
}

/// The chroma class of 16 pixels from their phase means `m`, scored as
/// [`PatchGeometry::chroma_of`](super::super::PatchGeometry::chroma_of) scores it
/// over `NCH` channels, and the lanes whose class is sure: the runner-up's score is
/// at least the margin above the best's. The scores are fused multiply-adds, so
/// they round differently from the reference's separate multiplies and adds, by
/// less than the reference's own rounding: the margin
/// ([`CHROMA_MARGIN`](super::super::CHROMA_MARGIN)) covers both. `phase[ch]` is
/// the phase holding channel `ch` for the even and odd lanes.
#[inline(always)]
unsafe fn chroma_classes<const NCH: usize>(
    c: &ChromaParams,
    m: &[__m512; 4],
    phase: &[(usize, usize); 4],
    odd_lanes: __mmask16,
) -> (__m512i, __mmask16) {
    let zero = _mm512_setzero_ps();
    let mut cm = [zero; NCH];
    for (ch, v) in cm.iter_mut().enumerate() {
        let (pe, po) = phase[ch];
        *v = _mm512_max_ps(_mm512_mask_blend_ps(odd_lanes, m[pe & 3], m[po & 3]), zero);
    }
    let scale = score(&c.scale, &cm);
    let inf = _mm512_set1_ps(f32::INFINITY);
    let (mut s1, mut s2, mut best) = (inf, inf, _mm512_setzero_si512());
    for (k, a) in c.coef.iter().enumerate() {
        let score = score(a, &cm);
        let lower = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(score, s1);
        s2 = _mm512_min_ps(s2, _mm512_max_ps(s1, score));
        best = _mm512_mask_mov_epi32(best, lower, _mm512_set1_epi32(k as i32));
        s1 = _mm512_min_ps(s1, score);
    }
    let margin = _mm512_fmadd_ps(_mm512_set1_ps(c.margin), scale, _mm512_set1_ps(c.floor));
    // (NaN fails)
    let sure = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(_mm512_sub_ps(s2, s1), margin);
    (best, sure)
}

/// `Σ_ch w[ch] · cm[ch]`, unrolled over the `NCH` channels (a function, not a
/// closure: closures do not inherit the caller's target features).
#[inline(always)]
unsafe fn score<const NCH: usize>(w: &[f32; 4], cm: &[__m512; NCH]) -> __m512 {
    let mut s = _mm512_mul_ps(_mm512_set1_ps(w[0]), cm[0]);
    // (an index loop: iterator adapters such as `skip` are not always inlined here)
    #[allow(clippy::needless_range_loop)]
    for ch in 1..NCH.min(4) {
        s = _mm512_fmadd_ps(_mm512_set1_ps(w[ch]), cm[ch], s);
    }
    s
}
