//! [`super::dct::fdct_quantise`] in AVX2 intrinsics: the same column DCT ([`super::dct::dct_columns`]
//! over AVX2 lanes), and the same operations in the same order on
//! the same lanes, so the same results, bit for bit (a test checks). The compiler does not
//! vectorise the portable version across its transpose, and this is about half of its time.

use std::arch::x86_64::*;

use super::dct::{Lanes, Quantised, ROUNDER, dct_columns};

// The lane operations of the column DCT in AVX2. They are inlined into this file's
// `#[target_feature(enable = "avx2")]` functions, the only ones that build `__m256` values, and
// those run only where AVX2 was detected.
impl Lanes for __m256 {
    #[inline(always)]
    fn add(self, b: Self) -> Self {
        // SAFETY: called only from AVX2 functions on a CPU with AVX2 (see above)
        unsafe { _mm256_add_ps(self, b) }
    }

    #[inline(always)]
    fn sub(self, b: Self) -> Self {
        // SAFETY: as `add`
        unsafe { _mm256_sub_ps(self, b) }
    }

    #[inline(always)]
    fn scale(self, k: f32) -> Self {
        // SAFETY: as `add`
        unsafe { _mm256_mul_ps(self, _mm256_set1_ps(k)) }
    }
}

#[target_feature(enable = "avx2")]
#[inline]
fn transpose(r: &[__m256; 8]) -> [__m256; 8] {
    let t0 = _mm256_unpacklo_ps(r[0], r[1]);
    let t1 = _mm256_unpackhi_ps(r[0], r[1]);
    let t2 = _mm256_unpacklo_ps(r[2], r[3]);
    let t3 = _mm256_unpackhi_ps(r[2], r[3]);
    let t4 = _mm256_unpacklo_ps(r[4], r[5]);
    let t5 = _mm256_unpackhi_ps(r[4], r[5]);
    let t6 = _mm256_unpacklo_ps(r[6], r[7]);
    let t7 = _mm256_unpackhi_ps(r[6], r[7]);
    let s0 = _mm256_shuffle_ps::<0x44>(t0, t2);
    let s1 = _mm256_shuffle_ps::<0xee>(t0, t2);
    let s2 = _mm256_shuffle_ps::<0x44>(t1, t3);
    let s3 = _mm256_shuffle_ps::<0xee>(t1, t3);
    let s4 = _mm256_shuffle_ps::<0x44>(t4, t6);
    let s5 = _mm256_shuffle_ps::<0xee>(t4, t6);
    let s6 = _mm256_shuffle_ps::<0x44>(t5, t7);
    let s7 = _mm256_shuffle_ps::<0xee>(t5, t7);
    [
        _mm256_permute2f128_ps::<0x20>(s0, s4),
        _mm256_permute2f128_ps::<0x20>(s1, s5),
        _mm256_permute2f128_ps::<0x20>(s2, s6),
        _mm256_permute2f128_ps::<0x20>(s3, s7),
        _mm256_permute2f128_ps::<0x31>(s0, s4),
        _mm256_permute2f128_ps::<0x31>(s1, s5),
        _mm256_permute2f128_ps::<0x31>(s2, s6),
        _mm256_permute2f128_ps::<0x31>(s3, s7),
    ]
}

/// As [`super::dct::fdct_quantise`].
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn fdct_quantise(
    plane: &[f32],
    stride: usize,
    at: usize,
    recip: &[f32; 64],
) -> Quantised {
    let row = |r: usize| -> &[f32; 8] {
        plane[at + r * stride..][..8]
            .try_into()
            .unwrap_or(&[0.0; 8])
    };
    // SAFETY: each pointer is to eight f32 of a borrowed array (loads are unaligned).
    let mut d: [__m256; 8] = std::array::from_fn(|r| unsafe { _mm256_loadu_ps(row(r).as_ptr()) });
    dct_columns(&mut d);
    let mut d = transpose(&d);
    dct_columns(&mut d);
    let mut out = [0i32; 64];
    let rounder = _mm256_set1_ps(ROUNDER);
    let bias = _mm256_set1_epi32(ROUNDER.to_bits() as i32);
    let mut rows = 0u64;
    for (i, v) in d.iter().enumerate() {
        // SAFETY: 8 f32 of `recip` and 8 i32 of `out` from `8 i` (i < 8); unaligned.
        unsafe {
            let r = _mm256_loadu_ps(recip.as_ptr().add(8 * i));
            let t = _mm256_add_ps(_mm256_mul_ps(*v, r), rounder);
            let q = _mm256_sub_epi32(_mm256_castps_si256(t), bias);
            _mm256_storeu_si256(out.as_mut_ptr().add(8 * i).cast(), q);
            let zero = _mm256_cmpeq_epi32(q, _mm256_setzero_si256());
            let zero = _mm256_movemask_ps(_mm256_castsi256_ps(zero)) as u64;
            rows |= (!zero & 0xff) << (8 * i);
        }
    }
    Quantised { coef: out, rows }
}
