//! The AVX2 + FMA row kernel.

use super::LANES;

#[cfg(target_arch = "x86_64")]
#[inline(always)]
/// # Safety
/// The CPU must have AVX2 and FMA (callers run inside `tile_avx2`).
pub(super) unsafe fn row_dot_avx2(
    buf: &[f32],
    stride: usize,
    i: usize,
    s: usize,
    k: &[f32],
) -> [f32; 4] {
    use std::arch::x86_64::*;
    let mut out = [0f32; 4];
    let need_buf = (s - 1) * stride + i + LANES;
    let need_k = 3 * s * LANES + 4;
    if s == 0 || buf.len() < need_buf || k.len() < need_k {
        return out;
    }
    // SAFETY: the features are present (see above), and the checks above keep
    // every 8-lane load inside `buf` (rows 0..s at column i) and `k`.
    unsafe {
        let b = buf.as_ptr().add(i);
        let kp = k.as_ptr();
        let mut a0 = _mm256_setzero_ps();
        let mut a1 = _mm256_setzero_ps();
        let mut a2 = _mm256_setzero_ps();
        for dy in 0..s {
            let pv = _mm256_loadu_ps(b.add(dy * stride));
            a0 = _mm256_fmadd_ps(pv, _mm256_loadu_ps(kp.add(dy * LANES)), a0);
            a1 = _mm256_fmadd_ps(pv, _mm256_loadu_ps(kp.add((s + dy) * LANES)), a1);
            a2 = _mm256_fmadd_ps(pv, _mm256_loadu_ps(kp.add((2 * s + dy) * LANES)), a2);
        }
        // [x y z z] from three 8-lane sums
        let t01 = _mm256_hadd_ps(a0, a1);
        let t22 = _mm256_hadd_ps(a2, a2);
        let t = _mm256_hadd_ps(t01, t22);
        let sum = _mm_add_ps(_mm256_castps256_ps128(t), _mm256_extractf128_ps(t, 1));
        let bias = _mm_loadu_ps(kp.add(3 * s * LANES));
        _mm_storeu_ps(out.as_mut_ptr(), _mm_add_ps(sum, bias));
    }
    out
}
