//! The entropy-coded scan of a run of rows: MCU by MCU, colour conversion, DCT, quantisation
//! and Huffman coding.

use super::color::McuRow;
use super::dct::{fdct_quantise, reciprocals};
use super::entropy::{BitWriter, Codes};
use super::tables::{CHROMA_AC, CHROMA_DC, LUMA_AC, LUMA_DC};

/// What every strip of one image shares.
pub(super) struct Plan {
    /// Luma's sampling factors, horizontal and vertical.
    h: usize,
    v: usize,
    /// Luma's and chroma's quantisation multipliers.
    recip: [[f32; 64]; 2],
    codes: [Codes; 2],
}

impl Plan {
    pub fn new(factors: (u8, u8), quant: [&[u8; 64]; 2]) -> Self {
        Plan {
            h: usize::from(factors.0),
            v: usize::from(factors.1),
            recip: quant.map(reciprocals),
            codes: [
                Codes::new(&LUMA_DC, &LUMA_AC),
                Codes::new(&CHROMA_DC, &CHROMA_AC),
            ],
        }
    }

    /// Image rows per MCU row.
    pub fn mcu_rows(&self) -> usize {
        8 * self.v
    }

    /// MCUs across an image `width` pixels wide.
    pub fn mcus_across(&self, width: usize) -> usize {
        width.div_ceil(8 * self.h)
    }

    /// The scan data (byte-stuffed, the last byte padded) of the rows `rgb` (interleaved
    /// 8-bit, `width` pixels a row), coded as if they were a whole image or one restart
    /// interval: the DC predictions start at zero.
    pub fn encode_rows(&self, rgb: &[u8], width: usize) -> Vec<u8> {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2")
            && std::is_x86_feature_detected!("bmi1")
            && std::is_x86_feature_detected!("lzcnt")
        {
            // SAFETY: the CPU has just reported the features the function is compiled for.
            return unsafe { self.encode_rows_avx2(rgb, width) };
        }
        self.encode_rows_with::<false>(rgb, width)
    }

    /// [`Self::encode_rows`] compiled for AVX2 (wider vectors for the colour conversion and
    /// the DCT; `tzcnt`/`lzcnt` for the coder). The arithmetic is the same, so the bytes are.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,bmi1,lzcnt")]
    unsafe fn encode_rows_avx2(&self, rgb: &[u8], width: usize) -> Vec<u8> {
        self.encode_rows_with::<true>(rgb, width)
    }

    /// [`Self::encode_rows`], with the AVX2 DCT when `AVX2` (only ever inlined into a
    /// function compiled for AVX2) and the portable one otherwise.
    #[inline(always)]
    pub(super) fn encode_rows_with<const AVX2: bool>(&self, rgb: &[u8], width: usize) -> Vec<u8> {
        let dct = |plane: &[f32], stride: usize, at: usize, recip: &[f32; 64]| {
            #[cfg(target_arch = "x86_64")]
            if AVX2 {
                // SAFETY: `AVX2` is true only in `encode_rows_avx2`, which runs only on a CPU
                // that has reported AVX2.
                return unsafe { super::dct_avx2::fdct_quantise(plane, stride, at, recip) };
            }
            fdct_quantise(plane, stride, at, recip)
        };
        let rows = rgb.len() / (width * 3);
        let mut m = McuRow::new(width, self.h, self.v);
        let mut out = BitWriter::new(rgb.len() / 10 + 1024);
        let mut pred = [0i32; 3];
        let [luma, chroma] = &self.codes;
        for first in (0..rows).step_by(self.mcu_rows()) {
            m.fill(rgb, first);
            for mx in 0..m.mcus() {
                for by in 0..self.v {
                    for bx in 0..self.h {
                        let at = by * 8 * m.y_stride + (mx * self.h + bx) * 8;
                        let c = dct(&m.y, m.y_stride, at, &self.recip[0]);
                        out.block(&c, &mut pred[0], luma);
                    }
                }
                let c = dct(&m.cb, m.c_stride, mx * 8, &self.recip[1]);
                out.block(&c, &mut pred[1], chroma);
                let c = dct(&m.cr, m.c_stride, mx * 8, &self.recip[1]);
                out.block(&c, &mut pred[2], chroma);
            }
        }
        out.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::jpeg::tables::quant_table;

    /// The dispatched coder (AVX2 where the CPU has it) writes the portable one's bytes.
    #[test]
    fn every_instruction_set_writes_the_same_bytes() {
        let (w, h) = (53, 37);
        let mut s = 5u32;
        let rgb: Vec<u8> = (0..w * h * 3)
            .map(|i| {
                s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                ((s >> 27) as usize + i % 200) as u8
            })
            .collect();
        for (q, factors) in [(90, (2, 2)), (100, (2, 1)), (50, (1, 1))] {
            let quant = [quant_table(q, false), quant_table(q, true)];
            let plan = Plan::new(factors, [&quant[0], &quant[1]]);
            assert_eq!(
                plan.encode_rows(&rgb, w),
                plan.encode_rows_with::<false>(&rgb, w)
            );
        }
    }
}
