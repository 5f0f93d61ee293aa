//! The sRGB encoder: three planes of linear sRGB to interleaved 8-bit codes.

#![allow(unsafe_op_in_unsafe_fn)]

use std::arch::x86_64::*;

use super::WIDE;

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
pub(in super::super) struct SrgbPoly {
    exps: [f32; 16],
    inv: f32,
    linear: f32,
    gain: f32,
    offset: f32,
}

impl SrgbPoly {
    /// The encoder, if it reproduces every entry of `table` (the 4096-entry
    /// sRGB table, `code(i) = round(255 · srgb(i / 4095))`), checked exhaustively.
    pub(in super::super) fn for_table(table: &[u8]) -> Option<Self> {
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
    /// Linear value → table index.
    times: __m512,
    /// The last index.
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
    unsafe fn new(scale: f32, times: f32, table: &[u32], poly: Option<&SrgbPoly>) -> Self {
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
            times: _mm512_set1_ps(times),
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
        // v · times + 0.5 rounded twice (no FMA), as SrgbLut::index_times
        let x = _mm512_add_ps(_mm512_mul_ps(v, self.times), self.half);
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

/// Encode `n` pixels of three linear sRGB planes to interleaved 8-bit sRGB
/// through `table` (the sRGB table widened to u32, indexed by `round(v · times)`
/// clamped to `0..=scale`, as [`SrgbLut::index_times`](super::super::SrgbLut::index_times);
/// `times = scale` puts white at 1).
///
/// Returns `false` (and writes nothing) if a slice is too short, the table does not
/// match `scale`, or `times` is not finite.
///
/// # Safety
/// The CPU must have AVX-512 F, VL, BW, DQ and VBMI.
#[target_feature(enable = "avx512f,avx512vl,avx512bw,avx512dq,avx512vbmi")]
pub(in super::super) unsafe fn srgb8_row(
    planes: [&[f32]; 3],
    n: usize,
    table: &[u32],
    scale: f32,
    times: f32,
    poly: Option<&SrgbPoly>,
    out: &mut [u8],
) -> bool {
    let padded = n.div_ceil(WIDE) * WIDE;
    if out.len() < 3 * n
        || planes.iter().any(|p| p.len() < padded)
        || !(scale >= 1.0 && (scale as usize) < table.len())
        || !times.is_finite()
    {
        return false;
    }
    let enc = Encoder::new(scale, times, table, poly);
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
    use super::super::super::SrgbLut;
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

    #[test]
    fn the_vector_encoder_equals_the_table() {
        if !super::super::super::dispatch::avx512_available() {
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
            assert!(unsafe { srgb8_row(planes, n, &wide, lut.scale(), lut.scale(), p, &mut out) });
            assert_eq!(out, want, "polynomial {}", p.is_some());
        }
        // a white level as a gain: the codes of `v · gain` through the same index
        // arithmetic as the scalar sink's, for gains that push values past white,
        // keep them below, and one that is not finite (refused, nothing written)
        for gain in [0.37f32, 1.0, 2.5] {
            let times = gain * lut.scale();
            let want: Vec<u8> = plane[..n]
                .iter()
                .flat_map(|&v| [lut.at(lut.index_times(v, times)); 3])
                .collect();
            for p in [poly.as_ref(), None] {
                let mut out = vec![0u8; 3 * n];
                let planes = [&plane[..], &plane[..], &plane[..]];
                // SAFETY: as above
                assert!(unsafe { srgb8_row(planes, n, &wide, lut.scale(), times, p, &mut out) });
                assert_eq!(out, want, "gain {gain}, polynomial {}", p.is_some());
            }
        }
        let mut out = vec![9u8; 3 * n];
        let planes = [&plane[..], &plane[..], &plane[..]];
        // SAFETY: as above
        let refused =
            unsafe { srgb8_row(planes, n, &wide, lut.scale(), f32::INFINITY, None, &mut out) };
        assert!(!refused && out.iter().all(|&b| b == 9));
    }
}
