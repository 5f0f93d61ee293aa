//! Where a row of linear outputs goes: interleaved XYZ or 8-bit sRGB.

use super::SrgbLut;
#[cfg(target_arch = "x86_64")]
use super::avx512;

/// How a row of linear outputs (three planes) becomes the output row.
pub(super) trait Sink<T>: Sync {
    fn finish_row(&self, row: &mut [T], lin: &[Vec<f32>; 3], n: usize);

    /// As `finish_row`, with AVX-512 where the sink has a kernel for it.
    ///
    /// # Safety
    /// The CPU must have AVX-512 F, VL, BW and VBMI.
    #[inline(always)]
    unsafe fn finish_row_wide(&self, row: &mut [T], lin: &[Vec<f32>; 3], n: usize) {
        self.finish_row(row, lin, n)
    }
}

/// Interleaved f32 XYZ.
pub(super) struct XyzSink;
impl Sink<f32> for XyzSink {
    #[inline(always)]
    fn finish_row(&self, row: &mut [f32], lin: &[Vec<f32>; 3], n: usize) {
        let [a, b, c] = lin;
        for (((o, &x), &y), &z) in row
            .chunks_exact_mut(3)
            .zip(&a[..n])
            .zip(&b[..n])
            .zip(&c[..n])
        {
            o[0] = x;
            o[1] = y;
            o[2] = z;
        }
    }
}

/// Interleaved 8-bit sRGB from linear sRGB (white = 1).
pub(super) struct Srgb8Sink {
    lut: SrgbLut,
    /// The table widened to u32 for gathers.
    wide: Vec<u32>,
    /// The table as arithmetic, where that reproduces every entry.
    #[cfg(target_arch = "x86_64")]
    poly: Option<avx512::SrgbPoly>,
}

impl Srgb8Sink {
    /// The default table in every form the sinks use, built (and the polynomial
    /// checked against all its entries) once per process.
    pub(super) fn shared() -> &'static Self {
        static SINK: std::sync::OnceLock<Srgb8Sink> = std::sync::OnceLock::new();
        SINK.get_or_init(|| {
            let lut = SrgbLut::new();
            Self {
                wide: lut.entries().iter().map(|&v| u32::from(v)).collect(),
                #[cfg(target_arch = "x86_64")]
                poly: avx512::SrgbPoly::for_table(lut.entries()),
                lut,
            }
        })
    }
}

impl Sink<u8> for Srgb8Sink {
    #[inline(always)]
    unsafe fn finish_row_wide(&self, row: &mut [u8], lin: &[Vec<f32>; 3], n: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            let planes = [&lin[0][..], &lin[1][..], &lin[2][..]];
            // SAFETY: the caller guarantees the CPU features; the kernel checks lengths.
            let (wide, scale, poly) = (&self.wide, self.lut.scale(), self.poly.as_ref());
            if unsafe { avx512::srgb8_row(planes, n, wide, scale, poly, row) } {
                return;
            }
        }
        self.finish_row(row, lin, n)
    }

    #[inline(always)]
    fn finish_row(&self, row: &mut [u8], lin: &[Vec<f32>; 3], n: usize) {
        const CHUNK: usize = 64;
        let mut idx = [[0u32; CHUNK]; 3];
        let mut start = 0;
        while start < n {
            let m = CHUNK.min(n - start);
            // table indices, vectorised per plane
            for (ix, plane) in idx.iter_mut().zip(lin) {
                for (o, &v) in ix[..m].iter_mut().zip(&plane[start..start + m]) {
                    *o = self.lut.index(v);
                }
            }
            for (k, o) in row[3 * start..3 * (start + m)]
                .chunks_exact_mut(3)
                .enumerate()
            {
                o[0] = self.lut.at(idx[0][k]);
                o[1] = self.lut.at(idx[1][k]);
                o[2] = self.lut.at(idx[2][k]);
            }
            start += m;
        }
    }
}
