//! The kernel step: each pixel's kernels applied to its patch rows, 8 pixels at a time.

#![allow(unsafe_op_in_unsafe_fn)]

use std::arch::x86_64::*;

use super::super::kernels::{packed, packed_lane, packed_stride};
use super::WIDE;

/// One output row as the kernel step reads it.
#[derive(Clone, Copy)]
pub(in super::super) struct KernelRow<'a> {
    /// The tile buffer from the patch's top row, rows `stride` apart.
    pub buf: &'a [f32],
    pub stride: usize,
    /// Per pixel, where its kernels start in `kernels` (from
    /// [`classify_row`](super::classify_row)), padded to whole 16-lane chunks.
    pub offsets: &'a [u32],
    /// Pixels in the row.
    pub tw: usize,
    /// The kernels, `kstride` values per class.
    pub kernels: &'a [f32],
    pub kstride: usize,
}

/// Whether the kernel step's arguments are long enough for `n` pixels (a
/// multiple of 8) of patch size `p` with classes of at least `min_kstride`
/// values, and every offset leaves a whole class inside `kernels`.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2,fma")]
unsafe fn kernel_args_ok(
    row: &KernelRow<'_>,
    min_kstride: usize,
    p: usize,
    n: usize,
    planes: &[&mut [f32]; 3],
) -> bool {
    let KernelRow {
        buf,
        stride,
        offsets,
        kernels,
        kstride,
        ..
    } = *row;
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
pub(in super::super) unsafe fn apply_kernels<const P: usize>(
    row: &KernelRow<'_>,
    planes: [&mut [f32]; 3],
) -> bool {
    let step = if packed(P) {
        apply_row_packed::<P>
    } else {
        apply_row::<P>
    };
    step(row, planes)
}

/// Apply the kernels of pixels `0..tw` (rounded up to 8) of one output row into
/// the three output planes, with each pixel's kernels at `offsets` (from
/// [`classify_row`](super::classify_row)) in `kernels`, which holds per class,
/// `kstride` values apart:
/// `P` rows of 16 weights (X row | Y row, 8 lanes each), the biases (X at lane
/// 0, Y at lane 8), `P` rows of 8 Z weights, and the Z bias at lane 0. Pixels
/// for the reference path get class 0's values (the caller overwrites them).
///
/// Returns `false` (and writes nothing) if a slice is too short.
///
/// # Safety
/// The CPU must have AVX-512 F, VL and DQ, AVX2 and FMA.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2,fma")]
unsafe fn apply_row<const P: usize>(row: &KernelRow<'_>, planes: [&mut [f32]; 3]) -> bool {
    let KernelRow {
        buf,
        stride,
        offsets,
        tw,
        kernels,
        ..
    } = *row;
    let n = tw.div_ceil(8) * 8;
    if P == 0 || !kernel_args_ok(row, 24 * (P + 1), P, n, &planes) {
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
unsafe fn apply_row_packed<const P: usize>(row: &KernelRow<'_>, planes: [&mut [f32]; 3]) -> bool {
    let KernelRow {
        buf,
        stride,
        offsets,
        tw,
        kernels,
        ..
    } = *row;
    let n = tw.div_ceil(8) * 8;
    if !packed(P) || !kernel_args_ok(row, packed_stride(P), P, n, &planes) {
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

#[cfg(test)]
mod tests {
    use super::*;

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
        if !super::super::super::dispatch::avx512_available() {
            return;
        }
        let run = |offsets: &[u32], planes: &mut [Vec<f32>; 3]| {
            let [x, y, z] = planes;
            // SAFETY: the CPU has the features (checked above)
            let row = KernelRow {
                buf: &buf,
                stride,
                offsets,
                tw,
                kernels: &kernels,
                kstride,
            };
            unsafe { apply_row_packed::<P>(&row, [x, y, z]) }
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
}
