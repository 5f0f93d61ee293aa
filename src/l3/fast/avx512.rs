//! AVX-512 kernels of the fast renderer, for 2×2 CFAs (RGBW, Bayer) and up
//! to 32 luminance levels:
//!
//! - [`classify_row`] classifies 16 pixels per step: phase sums → means and
//!   luminance (one multiply per phase where every phase holds its own
//!   channel, as on RGBW; a 4 × 4 map per CFA position, blended between the
//!   row's even and odd lanes, where two phases share one, as Bayer's greens
//!   do), the contrast, the level by a branch-free binary search over the
//!   level edges held in registers, the chroma class where the table has
//!   them (its scores in the reference's order, with the reference's margin
//!   to the runner-up), the contrast threshold by a register permute (a
//!   gather with chroma classes), and the mask of pixels the reference code
//!   must classify;
//! - [`apply_row_packed`] (patch 3 and 5) applies the kernels of 8 pixels at a
//!   time, all three outputs sharing one 16-lane FMA per patch row (the input
//!   row spread to their lanes by one permute), and sums the lanes of the 8
//!   pixels with a tree of two-source permutes so results leave as whole
//!   vectors; [`apply_row`] (patch 7) does the same with X and Y sharing one
//!   FMA and Z in 8 lanes;
//! - [`srgb8_row`] encodes three planes of linear sRGB (the table computed by a
//!   polynomial checked against every entry, else gathers) and interleaves the
//!   bytes with one permute.
//!
//! Every function checks the lengths of what it reads and writes before its
//! unchecked loads; the callers run them only when the CPU has the features.

#![allow(unsafe_op_in_unsafe_fn)]

use std::arch::x86_64::*;

use super::kernels::{packed, packed_lane, packed_stride};
use super::{CONTRAST_MARGIN, LUMINANCE_MARGIN, NO_CLASS};

/// Lanes per classification step.
pub(super) const WIDE: usize = 16;
/// The most luminance levels the register tables hold.
pub(super) const MAX_LEVELS: usize = 32;

/// What classification needs beyond the row data, prepared once per tile.
pub(super) struct ClassParams {
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

/// What the chroma classification needs ([`super::FastRenderer::chroma_row`]'s
/// scores, 16 pixels at a time).
pub(super) struct ChromaParams {
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
    /// [`super::CHROMA_MARGIN`] and [`super::CHROMA_MARGIN_FLOOR`].
    pub margin: f32,
    pub floor: f32,
}

/// Per-row counts from [`classify_row`].
#[derive(Default, Clone, Copy)]
pub(super) struct RowCounts {
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

/// Classify pixels `0..tw` of one output row.
///
/// - `he`, `ho`: `P` rows of `tw_pad` horizontal sums over the even / odd column
///   offsets of the patch, starting at the patch's top row;
/// - `buf`: the tile buffer from the patch's top row, rows `stride` apart;
/// - `sat`: per pixel, whether its patch holds a saturated value (when the tile can);
/// - `class`: receives [`NO_CLASS`] where the reference code must decide, 0
///   elsewhere; `rpar`/`cpar` are the parities of the row and
///   of the tile's first column;
/// - `offsets`: receives where each pixel's kernels start in the AVX-512 layout
///   (class 0's for the reference path's pixels), for [`apply_row`].
///
/// Returns `None` (and writes nothing) if a slice is too short.
///
/// # Safety
/// The CPU must have AVX-512 F, VL, BW and DQ, AVX2 and FMA.
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx2,fma")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn classify_row<const P: usize>(
    he: &[f32],
    ho: &[f32],
    tw_pad: usize,
    buf: &[f32],
    stride: usize,
    sat: Option<&[bool]>,
    tw: usize,
    rpar: usize,
    cpar: usize,
    prm: &ClassParams,
    class: &mut [u32],
    offsets: &mut [u32],
) -> Option<RowCounts> {
    let rad = P / 2;
    if P == 0
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
        || (prm.n_chroma > 1) != prm.chroma.is_some()
    {
        return None;
    }
    let (hp, op, bp) = (he.as_ptr(), ho.as_ptr(), buf.as_ptr());
    // positions of even and odd lanes in this row
    let pos_even = rpar * 2 + cpar;
    let pos_odd = rpar * 2 + (1 - cpar);
    let odd_lanes: __mmask16 = 0xAAAA;
    // the phase maps of this row's even and odd lanes, one register per coefficient
    let lanes = |even: f32, odd: f32| {
        _mm512_mask_blend_ps(odd_lanes, _mm512_set1_ps(even), _mm512_set1_ps(odd))
    };
    let (mut to_mean, mut lw) = ([[_mm512_setzero_ps(); 4]; 4], [_mm512_setzero_ps(); 4]);
    for p in 0..4 {
        lw[p] = lanes(prm.lum[pos_even][p], prm.lum[pos_odd][p]);
        for q in 0..4 {
            to_mean[p][q] = lanes(prm.to_mean[pos_even][p][q], prm.to_mean[pos_odd][p][q]);
        }
    }
    let inv_area = _mm512_set1_ps(prm.inv_area);
    let e0 = _mm512_loadu_ps(prm.edges.as_ptr());
    let e1 = _mm512_loadu_ps(prm.edges.as_ptr().add(16));
    let b0 = _mm512_loadu_ps(prm.below.as_ptr());
    let b1 = _mm512_loadu_ps(prm.below.as_ptr().add(16));
    let t_even = &prm.thresholds[pos_even];
    let t_odd = &prm.thresholds[pos_odd];
    let (te0, te1) = (
        _mm512_loadu_ps(t_even.as_ptr()),
        _mm512_loadu_ps(t_even.as_ptr().add(16)),
    );
    let (to0, to1) = (
        _mm512_loadu_ps(t_odd.as_ptr()),
        _mm512_loadu_ps(t_odd.as_ptr().add(16)),
    );
    let pos = _mm512_mask_blend_epi32(
        odd_lanes,
        _mm512_set1_epi32(pos_even as i32),
        _mm512_set1_epi32(pos_odd as i32),
    );
    // kernel offsets: class = ((pos · levels + level) · n_sat + 0) · 2 + texture
    let per_level = 2 * prm.n_sat * prm.kstride;
    let n_bands = prm.n_levels * prm.n_chroma;
    let base = _mm512_mullo_epi32(pos, _mm512_set1_epi32((n_bands * per_level) as i32));
    // chroma: per channel, the phase that holds it for the even and the odd lanes
    // (the last such phase, as the AVX2 path writes them)
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
    let per_level = _mm512_set1_epi32(per_level as i32);
    let per_texture = _mm512_set1_epi32(prm.kstride as i32);
    let last = _mm512_set1_epi32(((prm.n_classes - 1) * prm.kstride) as i32);
    let mut count = [_mm512_setzero_ps(); 4];
    for (c, &n) in count.iter_mut().zip(&prm.count) {
        *c = _mm512_set1_ps(n);
    }
    let two = _mm512_set1_ps(2.0);
    let one = _mm512_set1_ps(1.0);
    let margin = _mm512_set1_ps(LUMINANCE_MARGIN);
    let cmargin = _mm512_set1_ps(CONTRAST_MARGIN);
    let abs_mask = _mm512_set1_epi32(0x7fff_ffff);
    let no_class = _mm512_set1_epi32(NO_CLASS as i32);
    // per-lane counts of texture and reference-path pixels, summed after the row
    let (mut n_texture, mut n_exact) = (_mm512_setzero_si512(), _mm512_setzero_si512());
    let one_i = _mm512_set1_epi32(1);
    let mut i = 0;
    while i < tw {
        // phase sums over the patch rows
        let mut s = [_mm512_setzero_ps(); 4];
        for dy in 0..P {
            let e = _mm512_loadu_ps(hp.add(dy * tw_pad + i));
            let o = _mm512_loadu_ps(op.add(dy * tw_pad + i));
            let base = 2 * ((dy + rad) % 2);
            s[base] = _mm512_add_ps(s[base], e);
            s[base + 1] = _mm512_add_ps(s[base + 1], o);
        }
        let mut m = [_mm512_setzero_ps(); 4];
        if prm.diagonal {
            for k in 0..4 {
                m[k] = _mm512_mul_ps(s[k], to_mean[k][k]);
            }
        } else {
            // the same order of operations as the AVX2 path's
            // `t[0]·q[0] + t[1]·q[1] + t[2]·q[2] + t[3]·q[3]`
            for k in 0..4 {
                let t = &to_mean[k];
                let a = _mm512_add_ps(_mm512_mul_ps(t[0], s[0]), _mm512_mul_ps(t[1], s[1]));
                let a = _mm512_add_ps(a, _mm512_mul_ps(t[2], s[2]));
                m[k] = _mm512_add_ps(a, _mm512_mul_ps(t[3], s[3]));
            }
        }
        let lum = _mm512_add_ps(
            _mm512_add_ps(_mm512_mul_ps(s[0], lw[0]), _mm512_mul_ps(s[1], lw[1])),
            _mm512_add_ps(_mm512_mul_ps(s[2], lw[2]), _mm512_mul_ps(s[3], lw[3])),
        );
        // level: the number of edges below the luminance (a binary search over the
        // edges held in two registers), exact only if no edge lies within the margin
        let mut lo = _mm512_setzero_si512();
        for step in [16, 8, 4, 2, 1] {
            let probe = _mm512_add_epi32(lo, _mm512_set1_epi32(step - 1));
            let e = _mm512_permutex2var_ps(e0, probe, e1);
            let k = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(e, lum);
            lo = _mm512_mask_add_epi32(lo, k, lo, _mm512_set1_epi32(step));
        }
        let top = _mm512_permutex2var_ps(e0, lo, e1);
        let bottom = _mm512_permutex2var_ps(b0, lo, b1);
        // (NaN luminance fails both tests)
        let mut exact = _mm512_cmp_ps_mask::<_CMP_NGT_UQ>(_mm512_sub_ps(lum, bottom), margin)
            | _mm512_cmp_ps_mask::<_CMP_NGE_UQ>(_mm512_sub_ps(top, lum), margin);
        // the band: the level, or the level's chroma class
        let band = match &prm.chroma {
            None => lo,
            Some(c) => {
                let (best, sure) = chroma_classes(c, &m, &chroma_phase, odd_lanes);
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
            // Σ |v − m_k| = Σ (2 · max(v, m_k) − v − m_k) = 2 · Σ max(v, m_k) − Σ_k (S_k + n_k · m_k):
            // two operations per value instead of three. One accumulator per patch row,
            // so the adds do not wait on each other.
            let mut acc = [_mm512_setzero_ps(); P];
            for (dy, a) in acc.iter_mut().enumerate() {
                let pr = (dy + rad) % 2;
                let row = bp.add(dy * stride + i);
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
            let mut rest = _mm512_add_ps(_mm512_add_ps(s[0], s[1]), _mm512_add_ps(s[2], s[3]));
            for k in 0..4 {
                rest = _mm512_fmadd_ps(count[k], m[k], rest);
            }
            let cv = _mm512_mul_ps(_mm512_fmsub_ps(sum, two, rest), inv_area);
            let t = match &prm.chroma {
                None => _mm512_mask_blend_ps(
                    odd_lanes,
                    _mm512_permutex2var_ps(te0, lo, te1),
                    _mm512_permutex2var_ps(to0, lo, to1),
                ),
                // (checked: 4 × bands thresholds; the band is clamped below the bands)
                Some(c) => _mm512_i32gather_ps::<4>(
                    _mm512_add_epi32(
                        _mm512_mullo_epi32(pos, _mm512_set1_epi32(n_bands as i32)),
                        band,
                    ),
                    c.thresholds.as_ptr(),
                ),
            };
            let gap = _mm512_castsi512_ps(_mm512_and_si512(
                _mm512_castps_si512(_mm512_sub_ps(cv, t)),
                abs_mask,
            ));
            // near the threshold (or NaN): the reference decides
            exact |= _mm512_cmp_ps_mask::<_CMP_NGE_UQ>(gap, cmargin);
            texture = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(cv, t);
        }
        if let Some(sat) = sat {
            let b = _mm_loadu_si128(sat.as_ptr().add(i).cast());
            exact |= _mm_cmpneq_epi8_mask(b, _mm_setzero_si128());
        }
        let valid = tail_mask(i, tw);
        exact &= valid;
        // where each pixel's kernels start (class 0's for the reference path's pixels)
        let off = _mm512_add_epi32(base, _mm512_mullo_epi32(band, per_level));
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

/// The chroma class of 16 pixels from their phase means `m`, as
/// [`PatchGeometry::chroma_of`](crate::l3::PatchGeometry::chroma_of) scores it
/// (separate multiplies and adds, in its order), and the lanes whose class is
/// sure: the runner-up's score is at least the margin above the best's.
/// `phase[ch]` is the phase holding channel `ch` for the even and odd lanes.
#[inline(always)]
unsafe fn chroma_classes(
    c: &ChromaParams,
    m: &[__m512; 4],
    phase: &[(usize, usize); 4],
    odd_lanes: __mmask16,
) -> (__m512i, __mmask16) {
    let zero = _mm512_setzero_ps();
    let mut cm = [zero; 4];
    for (ch, v) in cm.iter_mut().enumerate().take(c.n_channels) {
        let (pe, po) = phase[ch];
        *v = _mm512_max_ps(_mm512_mask_blend_ps(odd_lanes, m[pe & 3], m[po & 3]), zero);
    }
    let mut scale = zero;
    for (v, &w) in cm.iter().zip(&c.scale).take(c.n_channels) {
        scale = _mm512_add_ps(scale, _mm512_mul_ps(_mm512_set1_ps(w), *v));
    }
    let inf = _mm512_set1_ps(f32::INFINITY);
    let (mut s1, mut s2, mut best) = (inf, inf, _mm512_setzero_si512());
    for (k, a) in c.coef.iter().enumerate() {
        let mut score = zero;
        for (v, &w) in cm.iter().zip(a).take(c.n_channels) {
            score = _mm512_add_ps(score, _mm512_mul_ps(_mm512_set1_ps(w), *v));
        }
        let lower = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(score, s1);
        s2 = _mm512_min_ps(s2, _mm512_max_ps(s1, score));
        best = _mm512_mask_mov_epi32(best, lower, _mm512_set1_epi32(k as i32));
        s1 = _mm512_min_ps(s1, score);
    }
    let margin = _mm512_add_ps(
        _mm512_mul_ps(_mm512_set1_ps(c.margin), scale),
        _mm512_set1_ps(c.floor),
    );
    // (NaN fails)
    let sure = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(_mm512_sub_ps(s2, s1), margin);
    (best, sure)
}

/// Whether the kernel step's arguments are long enough for `n` pixels (a
/// multiple of 8) of patch size `p` with classes of at least `min_kstride`
/// values, and every offset leaves a whole class inside `kernels`.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn kernel_args_ok(
    min_kstride: usize,
    p: usize,
    buf: &[f32],
    stride: usize,
    offsets: &[u32],
    n: usize,
    kernels: &[f32],
    kstride: usize,
    planes: &[&mut [f32]; 3],
) -> bool {
    let padded = n.div_ceil(WIDE) * WIDE;
    if p == 0
        || kstride < min_kstride
        || kernels.len() < kstride
        || offsets.len() < padded
        || buf.len() < (p - 1) * stride + n + 8
        || planes.iter().any(|pl| pl.len() < n)
    {
        return false;
    }
    let top = _mm512_set1_epi32((kernels.len() - kstride).min(i32::MAX as usize) as i32);
    let mut past: __mmask16 = 0;
    for chunk in offsets[..padded].chunks_exact(WIDE) {
        past |= _mm512_cmpgt_epu32_mask(_mm512_loadu_si512(chunk.as_ptr().cast()), top);
    }
    past == 0
}

/// The kernel step for patch size `P`: [`apply_row_packed`] for patch 3 and 5,
/// [`apply_row`] otherwise (same arguments).
///
/// # Safety
/// The CPU must have AVX-512 F, VL and DQ, AVX2 and FMA.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2,fma")]
pub(super) unsafe fn apply_kernels<const P: usize>(
    buf: &[f32],
    stride: usize,
    offsets: &[u32],
    tw: usize,
    kernels: &[f32],
    kstride: usize,
    planes: [&mut [f32]; 3],
) -> bool {
    let step = if packed(P) {
        apply_row_packed::<P>
    } else {
        apply_row::<P>
    };
    step(buf, stride, offsets, tw, kernels, kstride, planes)
}

/// Apply the kernels of pixels `0..tw` (rounded up to 8) of one output row into
/// the three output planes, with each pixel's kernels at `offsets` (from
/// [`classify_row`]) in `kernels`, which holds per class, `kstride` values apart:
/// `P` rows of 16 weights (X row | Y row, 8 lanes each), the biases (X at lane
/// 0, Y at lane 8), `P` rows of 8 Z weights, and the Z bias at lane 0. Pixels
/// for the reference path get class 0's values (the caller overwrites them).
///
/// Returns `false` (and writes nothing) if a slice is too short.
///
/// # Safety
/// The CPU must have AVX-512 F, VL and DQ, AVX2 and FMA.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn apply_row<const P: usize>(
    buf: &[f32],
    stride: usize,
    offsets: &[u32],
    tw: usize,
    kernels: &[f32],
    kstride: usize,
    planes: [&mut [f32]; 3],
) -> bool {
    let n = tw.div_ceil(8) * 8;
    if P == 0
        || !kernel_args_ok(
            24 * (P + 1),
            P,
            buf,
            stride,
            offsets,
            n,
            kernels,
            kstride,
            &planes,
        )
    {
        return false;
    }
    let (bp, kp) = (buf.as_ptr(), kernels.as_ptr());
    let [px, py, pz] = planes;
    let mut i0 = 0;
    while i0 < n {
        let mut xy = [_mm512_setzero_ps(); 8];
        let mut z = [_mm256_setzero_ps(); 8];
        for p in 0..8 {
            let k = kp.add(*offsets.get_unchecked(i0 + p) as usize);
            let b = bp.add(i0 + p);
            let mut axy = _mm512_loadu_ps(k.add(16 * P));
            let mut az = _mm256_loadu_ps(k.add(16 * (P + 1) + 8 * P));
            for dy in 0..P {
                let row = _mm256_loadu_ps(b.add(dy * stride));
                let both = _mm512_broadcast_f32x8(row);
                axy = _mm512_fmadd_ps(both, _mm512_loadu_ps(k.add(16 * dy)), axy);
                az = _mm256_fmadd_ps(row, _mm256_loadu_ps(k.add(16 * (P + 1) + 8 * dy)), az);
            }
            xy[p] = axy;
            z[p] = az;
        }
        let (x8, y8) = reduce_xy(&xy);
        _mm256_storeu_ps(px.as_mut_ptr().add(i0), x8);
        _mm256_storeu_ps(py.as_mut_ptr().add(i0), y8);
        _mm256_storeu_ps(pz.as_mut_ptr().add(i0), reduce8(&z));
        i0 += 8;
    }
    true
}

/// Lanes of the zero-weight pad of a packed row (it sums to 0).
const PAD: i32 = (WIDE - 1) as i32;

/// The permute indices of [`apply_row_packed`] for patch size `p`.
struct PackedIdx {
    /// Per pixel q of 8: lane `o·p + dx` takes input lane `q + dx`.
    spread: [[i32; WIDE]; 8],
    /// Two pixels → per pixel and output two partial sums (lane `6·b + 2·o + h`),
    /// as the sum of three two-source permutes (each half of an output's lanes
    /// has at most three).
    pair: [[i32; WIDE]; 3],
    /// Two pairs → per output o and pixel q of the four, one sum (lane `4·o + q`).
    quad: [[i32; WIDE]; 2],
    /// Two quads → [X 0..8 | Y 0..8] and [Z 0..8 | Z 0..8].
    xy: [i32; WIDE],
    z: [i32; WIDE],
}

impl PackedIdx {
    const fn new(p: usize) -> Self {
        let half = p.div_ceil(2);
        let mut t = Self {
            spread: [[0; WIDE]; 8],
            pair: [[PAD; WIDE]; 3],
            quad: [[PAD; WIDE]; 2],
            xy: [0; WIDE],
            z: [0; WIDE],
        };
        let mut k = 0;
        while k < WIDE {
            let mut q = 0;
            while q < 8 {
                t.spread[q][k] = (q + k % if p > 0 { p } else { 1 }) as i32;
                q += 1;
            }
            if k < 12 {
                // pair lanes: pixel b, output o, half h; element j of the half
                let (b, o, h) = (k / 6, (k % 6) / 2, k % 2);
                let mut j = 0;
                while j < 3 {
                    let dx = h * half + j;
                    let inside = dx < p && (h == 1 || j < half);
                    if inside {
                        t.pair[j][k] = (packed_lane(p, o, dx) + 16 * b) as i32;
                    }
                    j += 1;
                }
                // quad lanes: output o, pixel q of four (pair q / 2, pixel q % 2)
                let (o, q) = (k / 4, k % 4);
                t.quad[0][k] = ((q % 2) * 6 + o * 2 + 16 * (q / 2)) as i32;
                t.quad[1][k] = ((q % 2) * 6 + o * 2 + 1 + 16 * (q / 2)) as i32;
            }
            // quad lane 4·o + q of the first (pixels 0..4) or second (4..8) quad
            let (o, q) = (k / 8, k % 8);
            t.xy[k] = (o * 4 + q % 4 + 16 * (q / 4)) as i32;
            t.z[k] = (8 + q % 4 + 16 * (q / 4)) as i32;
            k += 1;
        }
        t
    }
}

#[inline(always)]
unsafe fn index(lanes: &[i32; WIDE]) -> __m512i {
    _mm512_loadu_si512(lanes.as_ptr().cast())
}

/// [`apply_row`] for the packed layout (patch 3 or 5, see [`packed`]): per
/// class, `P` rows of 16 weights holding all three outputs (output o's weight
/// `dx` at lane `o·P + dx`, see [`packed_lane`]), then the bias row (output
/// o's bias at lane `o·P`). Each patch row costs one permute (the input row
/// spread to the three outputs' lanes) and one FMA; the reduction sums the
/// lanes of 8 pixels with 18 permutes.
///
/// Returns `false` (and writes nothing) if a slice is too short.
///
/// # Safety
/// The CPU must have AVX-512 F, VL and DQ, AVX2 and FMA.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn apply_row_packed<const P: usize>(
    buf: &[f32],
    stride: usize,
    offsets: &[u32],
    tw: usize,
    kernels: &[f32],
    kstride: usize,
    planes: [&mut [f32]; 3],
) -> bool {
    let n = tw.div_ceil(8) * 8;
    if !packed(P)
        || !kernel_args_ok(
            packed_stride(P),
            P,
            buf,
            stride,
            offsets,
            n,
            kernels,
            kstride,
            &planes,
        )
    {
        return false;
    }
    let idx = const { PackedIdx::new(P) };
    let mut spread = [_mm512_setzero_si512(); 8];
    for (v, lanes) in spread.iter_mut().zip(&idx.spread) {
        *v = index(lanes);
    }
    let pair = [
        index(&idx.pair[0]),
        index(&idx.pair[1]),
        index(&idx.pair[2]),
    ];
    let quad = [index(&idx.quad[0]), index(&idx.quad[1])];
    let (ixy, iz) = (index(&idx.xy), index(&idx.z));
    let (bp, kp) = (buf.as_ptr(), kernels.as_ptr());
    let [px, py, pz] = planes;
    let mut i0 = 0;
    while i0 < n {
        let b = bp.add(i0);
        let mut rows = [_mm512_setzero_ps(); P];
        for (dy, row) in rows.iter_mut().enumerate() {
            *row = _mm512_loadu_ps(b.add(dy * stride));
        }
        let mut acc = [_mm512_setzero_ps(); 8];
        for (q, a) in acc.iter_mut().enumerate() {
            let k = kp.add(*offsets.get_unchecked(i0 + q) as usize);
            let mut s = _mm512_loadu_ps(k.add(WIDE * P));
            for (dy, row) in rows.iter().enumerate() {
                let v = _mm512_permutexvar_ps(spread[q], *row);
                s = _mm512_fmadd_ps(v, _mm512_loadu_ps(k.add(WIDE * dy)), s);
            }
            *a = s;
        }
        let mut pairs = [_mm512_setzero_ps(); 4];
        for (q, v) in pairs.iter_mut().enumerate() {
            let (a, b) = (acc[2 * q], acc[2 * q + 1]);
            *v = _mm512_add_ps(
                _mm512_add_ps(
                    _mm512_permutex2var_ps(a, pair[0], b),
                    _mm512_permutex2var_ps(a, pair[1], b),
                ),
                _mm512_permutex2var_ps(a, pair[2], b),
            );
        }
        let mut quads = [_mm512_setzero_ps(); 2];
        for (q, v) in quads.iter_mut().enumerate() {
            let (a, b) = (pairs[2 * q], pairs[2 * q + 1]);
            *v = _mm512_add_ps(
                _mm512_permutex2var_ps(a, quad[0], b),
                _mm512_permutex2var_ps(a, quad[1], b),
            );
        }
        let xy = _mm512_permutex2var_ps(quads[0], ixy, quads[1]);
        let z = _mm512_permutex2var_ps(quads[0], iz, quads[1]);
        _mm256_storeu_ps(px.as_mut_ptr().add(i0), _mm512_castps512_ps256(xy));
        _mm256_storeu_ps(py.as_mut_ptr().add(i0), _mm512_extractf32x8_ps::<1>(xy));
        _mm256_storeu_ps(pz.as_mut_ptr().add(i0), _mm512_castps512_ps256(z));
        i0 += 8;
    }
    true
}

/// `[a0+a1, a2+a3, b0+b1, b2+b3]` in each 128-bit lane.
#[inline(always)]
unsafe fn hadd512(a: __m512, b: __m512) -> __m512 {
    let even = _mm512_shuffle_ps::<0b10_00_10_00>(a, b);
    let odd = _mm512_shuffle_ps::<0b11_01_11_01>(a, b);
    _mm512_add_ps(even, odd)
}

/// Eight [X row | Y row] accumulators → (X sums, Y sums) of the eight pixels.
#[inline(always)]
unsafe fn reduce_xy(v: &[__m512; 8]) -> (__m256, __m256) {
    // per 128-bit lane L of pixel p: after two steps, lane L of u holds the sums of
    // lane L of pixels 0..4, of w those of pixels 4..8 (lanes 0, 1: X; 2, 3: Y)
    let u = hadd512(hadd512(v[0], v[1]), hadd512(v[2], v[3]));
    let w = hadd512(hadd512(v[4], v[5]), hadd512(v[6], v[7]));
    // [u0, u2, w0, w2] + [u1, u3, w1, w3] = [X 0..4, Y 0..4, X 4..8, Y 4..8]
    let a = _mm512_shuffle_f32x4::<0b10_00_10_00>(u, w);
    let b = _mm512_shuffle_f32x4::<0b11_01_11_01>(u, w);
    let s = _mm512_add_ps(a, b);
    // → [X 0..4, X 4..8, Y 0..4, Y 4..8]
    let s = _mm512_shuffle_f32x4::<0b11_01_10_00>(s, s);
    (_mm512_castps512_ps256(s), _mm512_extractf32x8_ps::<1>(s))
}

/// Eight 8-lane accumulators → their eight sums.
#[inline(always)]
unsafe fn reduce8(v: &[__m256; 8]) -> __m256 {
    let q0 = _mm256_hadd_ps(_mm256_hadd_ps(v[0], v[1]), _mm256_hadd_ps(v[2], v[3]));
    let q1 = _mm256_hadd_ps(_mm256_hadd_ps(v[4], v[5]), _mm256_hadd_ps(v[6], v[7]));
    let lo = _mm256_permute2f128_ps::<0x20>(q0, q1);
    let hi = _mm256_permute2f128_ps::<0x31>(q0, q1);
    _mm256_add_ps(lo, hi)
}

/// `m^(5/12)` for `m` in [1, 2), as a polynomial in `m − 1.5` (degree 5,
/// least squares on Chebyshev nodes; error 1.6e-6, within which every entry
/// of the 4096-entry table still rounds the same way: checked exhaustively by
/// [`SrgbPoly::for_table`]).
const POW_5_12: [f32; POLY_TERMS] = [
    1.184_052_2,
    0.328_906_27,
    -0.063_860_23,
    0.022_423_48,
    -0.010_654_743,
    0.005_237_355_4,
];
/// Coefficients of [`POW_5_12`].
const POLY_TERMS: usize = 6;
/// Entries of the table the polynomial encoder replaces.
const POLY_ENTRIES: u32 = 4096;
/// The last index of that table on the sRGB curve's linear segment (i / 4095 ≤ 0.003 130 8).
const POLY_LINEAR_LAST: i32 = 12;

/// The sRGB table as arithmetic: `2^(−5k/12)` for k = 0..16, and the scales.
#[derive(Clone, Copy, Debug)]
pub(super) struct SrgbPoly {
    exps: [f32; 16],
    inv: f32,
    linear: f32,
    gain: f32,
    offset: f32,
}

impl SrgbPoly {
    /// The encoder, if it reproduces every entry of `table` (the 4096-entry
    /// sRGB table, `code(i) = round(255 · srgb(i / 4095))`), checked exhaustively.
    pub(super) fn for_table(table: &[u8]) -> Option<Self> {
        let last = f64::from(POLY_ENTRIES - 1);
        let poly = Self {
            exps: std::array::from_fn(|k| (-(5.0 * k as f64) / 12.0).exp2() as f32),
            inv: (1.0 / last) as f32,
            linear: (255.0 * 12.92 / last) as f32,
            gain: (255.0 * 1.055) as f32,
            offset: (255.0 * 0.055) as f32,
        };
        let same = table.len() == POLY_ENTRIES as usize
            && (0..POLY_ENTRIES).all(|i| poly.code(i) == table[i as usize]);
        same.then_some(poly)
    }

    /// The code of table index `i`, by the same operations as the vector kernel.
    fn code(&self, i: u32) -> u8 {
        let fi = i as f32;
        let g = if i as i32 <= POLY_LINEAR_LAST {
            fi * self.linear
        } else {
            let x = fi * self.inv;
            let bits = x.to_bits();
            let e = ((bits >> 23) & 0xff) as i32 - 127;
            let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
            let t = m - 1.5;
            let mut acc = POW_5_12[POLY_TERMS - 1];
            for &c in POW_5_12[..POLY_TERMS - 1].iter().rev() {
                acc = acc.mul_add(t, c);
            }
            let q = self.exps[(-e).clamp(0, 15) as usize] * acc;
            q.mul_add(self.gain, -self.offset)
        };
        g.round_ties_even().clamp(0.0, 255.0) as u8
    }
}

/// The byte order that interleaves three 16-byte planes (R at 0, G at 16, B at 32).
const INTERLEAVE: [u8; 64] = {
    let mut t = [0u8; 64];
    let mut j = 0;
    while j < 48 {
        t[j] = ((j % 3) * 16 + j / 3) as u8;
        j += 1;
    }
    t
};

/// The constants of [`srgb8_row`]'s encoder, in registers.
struct Encoder {
    scale: __m512,
    half: __m512,
    zero: __m512,
    table: *const i32,
    /// The polynomial encoder, if the table matched it.
    poly: bool,
    exps: __m512,
    inv: __m512,
    linear: __m512,
    gain: __m512,
    offset: __m512,
    coef: [__m512; POLY_TERMS],
    mid: __m512,
    last_linear: __m512i,
}

impl Encoder {
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx512vbmi")]
    #[inline]
    unsafe fn new(scale: f32, table: &[u32], poly: Option<&SrgbPoly>) -> Self {
        // the polynomial encoder's constants (unused without it)
        let pc = poly.copied().unwrap_or(SrgbPoly {
            exps: [0.0; 16],
            inv: 0.0,
            linear: 0.0,
            gain: 0.0,
            offset: 0.0,
        });
        let mut coef = [_mm512_setzero_ps(); POLY_TERMS];
        for (v, &c) in coef.iter_mut().zip(&POW_5_12) {
            *v = _mm512_set1_ps(c);
        }
        Self {
            scale: _mm512_set1_ps(scale),
            half: _mm512_set1_ps(0.5),
            zero: _mm512_setzero_ps(),
            table: table.as_ptr().cast(),
            poly: poly.is_some(),
            exps: _mm512_loadu_ps(pc.exps.as_ptr()),
            inv: _mm512_set1_ps(pc.inv),
            linear: _mm512_set1_ps(pc.linear),
            gain: _mm512_set1_ps(pc.gain),
            offset: _mm512_set1_ps(pc.offset),
            coef,
            mid: _mm512_set1_ps(1.5),
            last_linear: _mm512_set1_epi32(POLY_LINEAR_LAST),
        }
    }

    /// The sRGB codes of 16 linear values (the table has `scale + 1` entries).
    #[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx512vbmi")]
    #[inline]
    unsafe fn codes(&self, v: __m512) -> __m128i {
        // max/min return the second operand for NaN: NaN → 0, as SrgbLut::index;
        // v · scale + 0.5 rounded twice (no FMA), as SrgbLut::index
        let x = _mm512_add_ps(_mm512_mul_ps(v, self.scale), self.half);
        let x = _mm512_min_ps(_mm512_max_ps(x, self.zero), self.scale);
        let idx = _mm512_cvttps_epi32(x);
        if !self.poly {
            return _mm512_cvtepi32_epi8(_mm512_i32gather_epi32::<4>(idx, self.table));
        }
        // the table entry computed: 255 · (1.055 · x^(5/12) − 0.055), x = 2^e · m
        let fi = _mm512_cvtepi32_ps(idx);
        let x = _mm512_mul_ps(fi, self.inv);
        let e = _mm512_getexp_ps(x);
        let m = _mm512_getmant_ps::<_MM_MANT_NORM_1_2, _MM_MANT_SIGN_SRC>(x);
        let t = _mm512_sub_ps(m, self.mid);
        let mut acc = self.coef[POLY_TERMS - 1];
        for c in self.coef[..POLY_TERMS - 1].iter().rev() {
            acc = _mm512_fmadd_ps(acc, t, *c);
        }
        let k = _mm512_cvtps_epi32(_mm512_sub_ps(self.zero, e));
        let q = _mm512_mul_ps(_mm512_permutexvar_ps(k, self.exps), acc);
        let g = _mm512_fmsub_ps(q, self.gain, self.offset);
        let small = _mm512_cmple_epi32_mask(idx, self.last_linear);
        let g = _mm512_mask_blend_ps(small, g, _mm512_mul_ps(fi, self.linear));
        _mm512_cvtusepi32_epi8(_mm512_cvtps_epi32(g))
    }
}

/// Encode `n` pixels of three linear sRGB planes (white = 1) to interleaved
/// 8-bit sRGB through `table` (the sRGB table widened to u32, indexed by
/// `round(v · scale)` clamped to `0..=scale`, as [`SrgbLut::index`](crate::colour::SrgbLut::index)).
///
/// Returns `false` (and writes nothing) if a slice is too short or the table does not match `scale`.
///
/// # Safety
/// The CPU must have AVX-512 F, VL, BW, DQ and VBMI.
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx512vbmi")]
pub(super) unsafe fn srgb8_row(
    planes: [&[f32]; 3],
    n: usize,
    table: &[u32],
    scale: f32,
    poly: Option<&SrgbPoly>,
    out: &mut [u8],
) -> bool {
    let padded = n.div_ceil(WIDE) * WIDE;
    if out.len() < 3 * n
        || planes.iter().any(|p| p.len() < padded)
        || !(scale >= 1.0 && (scale as usize) < table.len())
    {
        return false;
    }
    let enc = Encoder::new(scale, table, poly);
    let perm = _mm512_loadu_si512(INTERLEAVE.as_ptr().cast());
    let mut i = 0;
    while i < n {
        let mut codes = [_mm_setzero_si128(); 3];
        for (c, p) in codes.iter_mut().zip(planes) {
            *c = enc.codes(_mm512_loadu_ps(p.as_ptr().add(i)));
        }
        let rgb = _mm512_inserti32x4::<2>(
            _mm512_inserti32x4::<1>(_mm512_castsi128_si512(codes[0]), codes[1]),
            codes[2],
        );
        let bytes = _mm512_permutexvar_epi8(perm, rgb);
        let m = (n - i).min(WIDE);
        let mask: __mmask64 = (1u64 << (3 * m)) - 1;
        _mm512_mask_storeu_epi8(out.as_mut_ptr().add(3 * i).cast(), mask, bytes);
        i += WIDE;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::super::SrgbLut;
    use super::*;

    #[test]
    fn the_polynomial_reproduces_every_entry_of_the_srgb_table() {
        let lut = SrgbLut::new();
        assert!(SrgbPoly::for_table(lut.entries()).is_some());
        // and refuses a table it does not reproduce
        let mut other = lut.entries().to_vec();
        other[2000] = other[2000].wrapping_add(1);
        assert!(SrgbPoly::for_table(&other).is_none());
        assert!(SrgbPoly::for_table(SrgbLut::with_entries(1024).entries()).is_none());
    }

    /// `apply_row_packed::<P>` on random data equals the dot products done
    /// one pixel at a time, for every pixel phase within the 8-pixel groups
    /// and a row length that is not a multiple of 8; bad offsets are refused.
    fn packed_kernels_match_scalar<const P: usize>() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(P as u64);
        let (tw, stride, n_classes): (usize, usize, usize) = (37, 64, 9);
        let kstride = packed_stride(P);
        // class weights w[c][o][dy][dx] and biases b[c][o]
        let w: Vec<f32> = (0..n_classes * 3 * P * P)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let b: Vec<f32> = (0..n_classes * 3)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let mut kernels = vec![0f32; n_classes * kstride];
        for c in 0..n_classes {
            for o in 0..3 {
                for dy in 0..P {
                    for dx in 0..P {
                        kernels[c * kstride + WIDE * dy + packed_lane(P, o, dx)] =
                            w[((c * 3 + o) * P + dy) * P + dx];
                    }
                }
                kernels[c * kstride + WIDE * P + packed_lane(P, o, 0)] = b[c * 3 + o];
            }
        }
        let buf: Vec<f32> = (0..P * stride + 64)
            .map(|_| rng.random_range(0.0..1.8))
            .collect();
        let n = tw.div_ceil(WIDE) * WIDE;
        let classes: Vec<usize> = (0..n).map(|_| rng.random_range(0..n_classes)).collect();
        let mut offsets: Vec<u32> = classes.iter().map(|&c| (c * kstride) as u32).collect();
        let mut planes = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
        if !super::super::dispatch::avx512_available() {
            return;
        }
        let run = |offsets: &[u32], planes: &mut [Vec<f32>; 3]| {
            let [x, y, z] = planes;
            // SAFETY: the CPU has the features (checked above)
            unsafe {
                apply_row_packed::<P>(&buf, stride, offsets, tw, &kernels, kstride, [x, y, z])
            }
        };
        assert!(run(&offsets, &mut planes));
        for (i, &c) in classes.iter().enumerate().take(tw) {
            for (o, plane) in planes.iter().enumerate() {
                let mut want = f64::from(b[c * 3 + o]);
                for dy in 0..P {
                    for dx in 0..P {
                        want += f64::from(w[((c * 3 + o) * P + dy) * P + dx])
                            * f64::from(buf[dy * stride + i + dx]);
                    }
                }
                let got = f64::from(plane[i]);
                assert!(
                    (got - want).abs() < 1e-5,
                    "P {P} pixel {i} output {o}: {got} vs {want}"
                );
            }
        }
        // an offset past the last class: refused, nothing written
        offsets[5] = (n_classes * kstride) as u32;
        let mut fresh = [vec![7f32; n], vec![7f32; n], vec![7f32; n]];
        assert!(!run(&offsets, &mut fresh));
        assert!(fresh.iter().flatten().all(|&v| v == 7.0));
    }

    #[test]
    fn packed_kernels_match_scalar_dot_products() {
        packed_kernels_match_scalar::<3>();
        packed_kernels_match_scalar::<5>();
    }

    #[test]
    fn the_vector_encoder_equals_the_table() {
        if !super::super::dispatch::avx512_available() {
            return;
        }
        let lut = SrgbLut::new();
        let wide: Vec<u32> = lut.entries().iter().map(|&v| u32::from(v)).collect();
        let poly = SrgbPoly::for_table(lut.entries());
        // every table index, plus values outside [0, 1] and NaN
        let n: usize = 4096 + 4;
        let mut plane: Vec<f32> = (0..4096).map(|i| i as f32 / 4095.0).collect();
        plane.extend([-1.0, 7.0, f32::NAN, f32::INFINITY]);
        plane.resize(n.div_ceil(WIDE) * WIDE, 0.0);
        let want: Vec<u8> = plane[..n]
            .iter()
            .flat_map(|&v| [lut.encode(v); 3])
            .collect();
        for p in [poly.as_ref(), None] {
            let mut out = vec![0u8; 3 * n];
            let planes = [&plane[..], &plane[..], &plane[..]];
            // SAFETY: the CPU has the features (checked above)
            assert!(unsafe { srgb8_row(planes, n, &wide, lut.scale(), p, &mut out) });
            assert_eq!(out, want, "polynomial {}", p.is_some());
        }
    }
}
