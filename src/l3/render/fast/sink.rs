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

/// The sRGB table in every form the 8-bit sink uses.
pub(super) struct Srgb8Tables {
    lut: SrgbLut,
    /// The table widened to u32 for gathers.
    wide: Vec<u32>,
    /// The table as arithmetic, where that reproduces every entry.
    #[cfg(target_arch = "x86_64")]
    poly: Option<avx512::SrgbPoly>,
}

impl Srgb8Tables {
    /// The default table in every form, built (and the polynomial checked
    /// against all its entries) once per process.
    pub(super) fn shared() -> &'static Self {
        static TABLES: std::sync::OnceLock<Srgb8Tables> = std::sync::OnceLock::new();
        TABLES.get_or_init(|| {
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

/// Interleaved 8-bit sRGB from linear sRGB times `gain` (white = 1 / gain):
/// the frame's white level is applied here, so the kernels fused with the
/// XYZ → sRGB matrix serve every frame.
pub(super) struct Srgb8Sink {
    tables: &'static Srgb8Tables,
    /// Linear value → table index: the gain times the table's scale.
    times: f32,
}

impl Srgb8Sink {
    pub(super) fn new(gain: f32) -> Self {
        let tables = Srgb8Tables::shared();
        Self {
            tables,
            times: gain * tables.lut.scale(),
        }
    }
}

impl Sink<u8> for Srgb8Sink {
    #[inline(always)]
    unsafe fn finish_row_wide(&self, row: &mut [u8], lin: &[Vec<f32>; 3], n: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            let planes = [&lin[0][..], &lin[1][..], &lin[2][..]];
            let t = self.tables;
            let (wide, scale, poly) = (&t.wide, t.lut.scale(), t.poly.as_ref());
            // SAFETY: the caller guarantees the CPU features; the kernel checks lengths.
            if unsafe { avx512::srgb8_row(planes, n, wide, scale, self.times, poly, row) } {
                return;
            }
        }
        self.finish_row(row, lin, n)
    }

    #[inline(always)]
    fn finish_row(&self, row: &mut [u8], lin: &[Vec<f32>; 3], n: usize) {
        const CHUNK: usize = 64;
        let (lut, times) = (&self.tables.lut, self.times);
        let mut idx = [[0u32; CHUNK]; 3];
        let mut start = 0;
        while start < n {
            let m = CHUNK.min(n - start);
            // table indices, vectorised per plane
            for (ix, plane) in idx.iter_mut().zip(lin) {
                for (o, &v) in ix[..m].iter_mut().zip(&plane[start..start + m]) {
                    *o = lut.index_times(v, times);
                }
            }
            for (k, o) in row[3 * start..3 * (start + m)]
                .chunks_exact_mut(3)
                .enumerate()
            {
                o[0] = lut.at(idx[0][k]);
                o[1] = lut.at(idx[1][k]);
                o[2] = lut.at(idx[2][k]);
            }
            start += m;
        }
    }
}
