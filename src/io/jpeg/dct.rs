//! The forward DCT and quantisation of one 8 × 8 block.
//!
//! The transform is the AAN (Arai–Agui–Nakajima) factorisation of libjpeg's `jfdctflt.c`, in
//! `f32`, with its output scale folded into the quantisation's reciprocals. Each pass works on
//! the block's eight rows as vectors of eight lanes, so it computes eight one-dimensional
//! DCTs at once (a vertical pass), and the compiler turns every lane-wise operation into SIMD
//! instructions of whatever width the target has; a transpose makes the second pass the
//! horizontal one. The result is left transposed (row = horizontal frequency): the entropy
//! coder's zig-zag table reads it that way ([`TRANSPOSED`]).

use super::tables::NATURAL;

type V = [f32; 8];

/// Eight `f32` lanes, as the column DCT needs them: the portable arrays here, AVX2 registers
/// in [`super::dct_avx2`]. One [`dct_columns`] serves both, so the two give the same bits.
pub(super) trait Lanes: Copy {
    fn add(self, b: Self) -> Self;
    fn sub(self, b: Self) -> Self;
    fn scale(self, k: f32) -> Self;
}

impl Lanes for V {
    #[inline(always)]
    fn add(mut self, b: V) -> V {
        for (x, y) in self.iter_mut().zip(b) {
            *x += y;
        }
        self
    }

    #[inline(always)]
    fn sub(mut self, b: V) -> V {
        for (x, y) in self.iter_mut().zip(b) {
            *x -= y;
        }
        self
    }

    #[inline(always)]
    fn scale(mut self, k: f32) -> V {
        for x in &mut self {
            *x *= k;
        }
        self
    }
}

/// Eight DCTs down the columns of `d` (each lane a column), unscaled (AAN).
#[inline(always)]
pub(super) fn dct_columns<L: Lanes>(d: &mut [L; 8]) {
    let tmp0 = d[0].add(d[7]);
    let tmp7 = d[0].sub(d[7]);
    let tmp1 = d[1].add(d[6]);
    let tmp6 = d[1].sub(d[6]);
    let tmp2 = d[2].add(d[5]);
    let tmp5 = d[2].sub(d[5]);
    let tmp3 = d[3].add(d[4]);
    let tmp4 = d[3].sub(d[4]);

    let tmp10 = tmp0.add(tmp3);
    let tmp13 = tmp0.sub(tmp3);
    let tmp11 = tmp1.add(tmp2);
    let tmp12 = tmp1.sub(tmp2);
    d[0] = tmp10.add(tmp11);
    d[4] = tmp10.sub(tmp11);
    let z1 = tmp12.add(tmp13).scale(std::f32::consts::FRAC_1_SQRT_2);
    d[2] = tmp13.add(z1);
    d[6] = tmp13.sub(z1);

    let tmp10 = tmp4.add(tmp5);
    let tmp11 = tmp5.add(tmp6);
    let tmp12 = tmp6.add(tmp7);
    let z5 = tmp10.sub(tmp12).scale(0.382_683_43);
    let z2 = tmp10.scale(0.541_196_1).add(z5);
    let z4 = tmp12.scale(1.306_563).add(z5);
    let z3 = tmp11.scale(std::f32::consts::FRAC_1_SQRT_2);
    let z11 = tmp7.add(z3);
    let z13 = tmp7.sub(z3);
    d[5] = z13.add(z2);
    d[3] = z13.sub(z2);
    d[1] = z11.add(z4);
    d[7] = z11.sub(z4);
}

#[inline(always)]
fn transpose(d: &[V; 8]) -> [V; 8] {
    let mut t = [[0.0; 8]; 8];
    for (r, row) in d.iter().enumerate() {
        for (c, &x) in row.iter().enumerate() {
            t[c][r] = x;
        }
    }
    t
}

/// `TRANSPOSED[k]`: where the `k`-th coefficient in zig-zag order is in [`fdct_quantise`]'s
/// output.
pub(super) const TRANSPOSED: [usize; 64] = {
    let mut t = [0; 64];
    let mut k = 0;
    while k < 64 {
        t[k] = (NATURAL[k] % 8) * 8 + NATURAL[k] / 8;
        k += 1;
    }
    t
};

/// The multipliers that quantise the unscaled AAN output by the row-major table `q`, in the
/// transposed layout of [`fdct_quantise`].
pub(super) fn reciprocals(q: &[u8; 64]) -> [f32; 64] {
    let aan = |k: usize| {
        if k == 0 {
            1.0
        } else {
            (k as f64 * std::f64::consts::PI / 16.0).cos() * std::f64::consts::SQRT_2
        }
    };
    std::array::from_fn(|i| {
        let (u, v) = (i / 8, i % 8); // horizontal, vertical frequency
        (1.0 / (f64::from(q[v * 8 + u]) * aan(u) * aan(v) * 8.0)) as f32
    })
}

/// Adding this to an `f32` of magnitude below 2²² leaves the nearest integer in the low bits
/// of the mantissa (ties to even), which a vector unit does without a rounding instruction.
pub(super) const ROUNDER: f32 = 12_582_912.0; // 1.5 × 2²³

/// A quantised block, transposed (see the module doc).
pub(super) struct Quantised {
    pub coef: [i32; 64],
    /// Byte `r`, bit `l`: whether `coef[8 r + l]` is nonzero.
    pub rows: u64,
}

/// The quantised DCT of the 8 × 8 block at `at` of a plane whose rows are `stride` apart.
#[inline(always)]
pub(super) fn fdct_quantise(
    plane: &[f32],
    stride: usize,
    at: usize,
    recip: &[f32; 64],
) -> Quantised {
    let mut d = [[0.0; 8]; 8];
    for (r, row) in d.iter_mut().enumerate() {
        row.copy_from_slice(&plane[at + r * stride..][..8]);
    }
    dct_columns(&mut d);
    let mut d = transpose(&d);
    dct_columns(&mut d);
    let mut out = [0i32; 64];
    for (i, (o, r)) in out
        .chunks_exact_mut(8)
        .zip(recip.chunks_exact(8))
        .enumerate()
    {
        for l in 0..8 {
            let t = d[i][l] * r[l] + ROUNDER;
            o[l] = t.to_bits() as i32 - ROUNDER.to_bits() as i32;
        }
    }
    let mut rows = 0;
    for (i, &c) in out.iter().enumerate() {
        rows |= u64::from(c != 0) << i;
    }
    Quantised { coef: out, rows }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The DCT of T.81 A.3.3, straight from its definition.
    fn reference(block: &[f32; 64]) -> [f64; 64] {
        let c = |k: usize| {
            if k == 0 {
                std::f64::consts::FRAC_1_SQRT_2
            } else {
                1.0
            }
        };
        std::array::from_fn(|i| {
            let (v, u) = (i / 8, i % 8);
            let mut s = 0.0;
            for y in 0..8 {
                for x in 0..8 {
                    s += f64::from(block[y * 8 + x])
                        * (((2 * x + 1) * u) as f64 * std::f64::consts::PI / 16.0).cos()
                        * (((2 * y + 1) * v) as f64 * std::f64::consts::PI / 16.0).cos();
                }
            }
            0.25 * c(u) * c(v) * s
        })
    }

    #[test]
    fn matches_the_definition_to_rounding() {
        let mut seed = 7u32;
        let block: [f32; 64] = std::array::from_fn(|_| {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 24) as f32 - 128.0
        });
        let want = reference(&block);
        let got = fdct_quantise(&block, 8, 0, &reciprocals(&[1; 64])).coef;
        for (n, w) in want.iter().enumerate() {
            let g = got[(n % 8) * 8 + n / 8];
            assert!(
                (f64::from(g) - w).abs() <= 0.51,
                "coefficient {n}: {g} vs {w}"
            );
        }
        // a flat block is all DC
        let flat = fdct_quantise(&[-128.0; 64], 8, 0, &reciprocals(&[1; 64]));
        assert_eq!(flat.coef[0], -1024);
        assert!(flat.coef[1..].iter().all(|&c| c == 0));
        assert_eq!(flat.rows, 1);
    }
}
