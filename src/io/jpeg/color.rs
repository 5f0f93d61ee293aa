//! Colour conversion (sRGB → JFIF YCbCr) and chroma downsampling, one MCU row at a time.
//!
//! Samples are `f32`, level-shifted for the DCT (Y − 128; Cb and Cr centred on 0) and never
//! rounded to 8 bits in between. Chroma is converted at full resolution and then averaged over
//! each 2 × 2 (4:2:0) or 2 × 1 (4:2:2) block, libjpeg's way (see the [module](super) doc for
//! why not the first pixel of each block). The loops run over contiguous rows of one plane,
//! so the compiler vectorises them.

/// One MCU row's planes, padded to whole MCUs by repeating the last column and the last row.
pub(super) struct McuRow {
    /// Luma's sampling factors (chroma's are 1 × 1).
    h: usize,
    v: usize,
    width: usize,
    /// Luma: `8 v` rows of `y_stride` samples.
    pub y: Vec<f32>,
    pub y_stride: usize,
    /// Chroma: 8 rows of `c_stride` samples each.
    pub cb: Vec<f32>,
    pub cr: Vec<f32>,
    pub c_stride: usize,
    /// Full-resolution chroma of the (up to two) rows one chroma row averages.
    full_cb: [Vec<f32>; 2],
    full_cr: [Vec<f32>; 2],
}

impl McuRow {
    pub fn new(width: usize, h: usize, v: usize) -> Self {
        let mcus = width.div_ceil(8 * h);
        let y_stride = mcus * 8 * h;
        let c_stride = mcus * 8;
        McuRow {
            h,
            v,
            width,
            y: vec![0.0; y_stride * 8 * v],
            y_stride,
            cb: vec![0.0; c_stride * 8],
            cr: vec![0.0; c_stride * 8],
            c_stride,
            full_cb: [vec![0.0; y_stride], vec![0.0; y_stride]],
            full_cr: [vec![0.0; y_stride], vec![0.0; y_stride]],
        }
    }

    /// Whole MCUs across.
    pub fn mcus(&self) -> usize {
        self.c_stride / 8
    }

    /// Fills the planes from the rows `first..` of `rgb` (interleaved 8-bit, `self.width`
    /// pixels a row), repeating its last row below its end.
    #[inline(always)]
    pub fn fill(&mut self, rgb: &[u8], first: usize) {
        let row_bytes = self.width * 3;
        let last = rgb.len() / row_bytes - 1;
        for cy in 0..8 {
            for k in 0..self.v {
                let ly = cy * self.v + k;
                let src = (first + ly).min(last) * row_bytes;
                convert_row(
                    &rgb[src..src + row_bytes],
                    &mut self.y[ly * self.y_stride..][..self.y_stride],
                    &mut self.full_cb[k],
                    &mut self.full_cr[k],
                );
            }
            let out = cy * self.c_stride..(cy + 1) * self.c_stride;
            downsample(&self.full_cb, self.h, self.v, &mut self.cb[out.clone()]);
            downsample(&self.full_cr, self.h, self.v, &mut self.cr[out]);
        }
    }
}

/// One row to Y, Cb and Cr (JFIF: BT.601 full range), the last pixel repeated to the end of
/// each output.
#[inline(always)]
fn convert_row(rgb: &[u8], y: &mut [f32], cb: &mut [f32], cr: &mut [f32]) {
    let n = rgb.len() / 3;
    for (((px, y), cb), cr) in rgb.chunks_exact(3).zip(&mut *y).zip(&mut *cb).zip(&mut *cr) {
        let (r, g, b) = (f32::from(px[0]), f32::from(px[1]), f32::from(px[2]));
        *y = 0.299 * r + 0.587 * g + 0.114 * b - 128.0;
        *cb = -0.168_736 * r - 0.331_264 * g + 0.5 * b;
        *cr = 0.5 * r - 0.418_688 * g - 0.081_312 * b;
    }
    for plane in [y, cb, cr] {
        let edge = plane[n - 1];
        plane[n..].fill(edge);
    }
}

/// Averages `h × v` blocks of the full-resolution rows into `out`.
#[inline(always)]
fn downsample(full: &[Vec<f32>; 2], h: usize, v: usize, out: &mut [f32]) {
    let n = out.len();
    match (h, v) {
        (2, 2) => {
            let (a, b) = (&full[0][..2 * n], &full[1][..2 * n]);
            for ((o, a), b) in out.iter_mut().zip(a.chunks_exact(2)).zip(b.chunks_exact(2)) {
                *o = 0.25 * ((a[0] + a[1]) + (b[0] + b[1]));
            }
        }
        (2, _) => {
            for (o, a) in out.iter_mut().zip(full[0][..2 * n].chunks_exact(2)) {
                *o = 0.5 * (a[0] + a[1]);
            }
        }
        _ => out.copy_from_slice(&full[0][..n]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey_has_no_chroma_and_edges_repeat() {
        // 3 × 2 pixels: a grey ramp; 4:2:0 pads to one 16 × 16 MCU
        let rgb = [
            10, 10, 10, 20, 20, 20, 30, 30, 30, 40, 40, 40, 50, 50, 50, 60, 60, 60,
        ];
        let mut m = McuRow::new(3, 2, 2);
        m.fill(&rgb, 0);
        assert_eq!(m.y_stride, 16);
        let y = |r: usize, c: usize| m.y[r * m.y_stride + c] + 128.0;
        assert!((y(0, 0) - 10.0).abs() < 1e-3);
        assert!((y(0, 15) - 30.0).abs() < 1e-3, "last column repeated");
        assert!((y(15, 1) - 50.0).abs() < 1e-3, "last row repeated");
        assert!(m.cb.iter().chain(&m.cr).all(|c| c.abs() < 1e-3));
    }

    #[test]
    fn chroma_is_the_mean_of_its_block() {
        // pure red and pure blue side by side: 4:2:2 averages them
        let rgb = [255, 0, 0, 0, 0, 255];
        let mut m = McuRow::new(2, 2, 1);
        m.fill(&rgb, 0);
        let cb = (-0.168_736 * 255.0 + 0.5 * 255.0) / 2.0;
        assert!((m.cb[0] - cb).abs() < 1e-3, "{} vs {cb}", m.cb[0]);
    }
}
