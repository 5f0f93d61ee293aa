//! The kernels in the layouts the row kernels read.

use super::LANES;

/// Whether patch size `p` uses the packed AVX-512 kernel layout (the three
/// outputs' weights of a patch row fit one 16-lane register: patch 3 and 5).
pub(super) const fn packed(p: usize) -> bool {
    p > 0 && 3 * p < 16
}

/// Values per class in the packed layout: `p` weight rows and the bias row, 16 lanes each.
pub(super) const fn packed_stride(p: usize) -> usize {
    16 * (p + 1)
}

/// The lane of weight `dx` of output `o` in a packed row (and of output o's
/// bias, dx = 0, in the bias row).
pub(super) const fn packed_lane(p: usize, o: usize, dx: usize) -> usize {
    o * p + dx
}

/// One kernel set in both layouts.
#[derive(Clone, Debug)]
pub(super) struct KernelSet {
    /// The table's layout: class × 3 × n_features.
    pub(super) flat: Vec<f32>,
    /// Values per class in `rows`.
    pub(super) stride: usize,
    /// Per class: 3 outputs × `size` patch rows × [`LANES`] weights, then 4 biases.
    pub(super) rows: Vec<f32>,
    /// Values per class in `paired`.
    pub(super) pstride: usize,
    /// Per class, for the AVX-512 kernels: patch 3 and 5 ([`packed`]): `size` rows
    /// of 16 weights holding all three outputs ([`packed_lane`]) and the bias row;
    /// patch 7: `size` rows of [X row | Y row] weights (8 lanes each), the
    /// [X bias | Y bias] row, `size` rows of Z weights, the Z bias row.
    pub(super) paired: Vec<f32>,
    /// Where the classes start in `paired` (its first 64-byte boundary, so
    /// 16-lane loads of a class never straddle cache lines).
    pub(super) paired_at: usize,
}

impl KernelSet {
    /// The classes of the AVX-512 layout, from a 64-byte boundary.
    pub(super) fn paired(&self) -> &[f32] {
        &self.paired[self.paired_at..]
    }
}

impl KernelSet {
    /// Both SIMD layouts of the classes without saturated channels (sat case 0,
    /// the only ones the fast path applies; the others are read from `flat`).
    pub(super) fn new(flat: Vec<f32>, size: usize, n_sat: usize) -> Self {
        let nf = size * size + 1;
        let stride = 3 * size * LANES + 4;
        let pack = packed(size);
        let pstride = if pack {
            packed_stride(size)
        } else {
            24 * (size + 1)
        };
        let n_classes = flat.len() / (3 * nf);
        let mut rows = vec![0f32; n_classes * stride];
        // 16 spare values to start on a 64-byte boundary
        let mut paired = vec![0f32; n_classes * pstride + 16];
        let paired_at = paired.as_ptr().align_offset(64).min(16);
        let unsaturated = |class: &usize| (class / 2).is_multiple_of(n_sat.max(1));
        for class in (0..n_classes).filter(unsaturated) {
            let src = &flat[class * 3 * nf..(class + 1) * 3 * nf];
            let dst = &mut rows[class * stride..(class + 1) * stride];
            let at = paired_at + class * pstride;
            let pair = &mut paired[at..at + pstride];
            // [X | Y] rows, then Z rows
            let z0 = 16 * (size + 1);
            for i in 0..3 {
                for dy in 0..size {
                    for dx in 0..size {
                        let w = src[i * nf + dy * size + dx];
                        dst[(i * size + dy) * LANES + dx] = w;
                        let at = if pack {
                            16 * dy + packed_lane(size, i, dx)
                        } else if i < 2 {
                            16 * dy + 8 * i + dx
                        } else {
                            z0 + 8 * dy + dx
                        };
                        pair[at] = w;
                    }
                }
                let bias = src[i * nf + nf - 1];
                dst[3 * size * LANES + i] = bias;
                let at = if pack {
                    16 * size + packed_lane(size, i, 0)
                } else if i < 2 {
                    16 * size + 8 * i
                } else {
                    z0 + 8 * size
                };
                pair[at] = bias;
            }
        }
        Self {
            flat,
            stride,
            rows,
            pstride,
            paired,
            paired_at,
        }
    }
}
