//! The render split over threads: bands of rows (one rayon task each), tiles
//! of columns, and the instruction set each tile runs with (portable, AVX2 +
//! FMA, or AVX-512), with the patch size as a constant where it is a common one.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::kernels::KernelSet;
use super::scratch::{SCRATCH, Scratch};
use super::sink::Sink;
use super::source::Source;
use super::tile::{Tile, TileCtx};
use super::{FastRenderer, Region, RenderError, RenderStats};

/// Rows per rayon task.
const BAND_ROWS: usize = 32;
/// Output columns per tile (the tile buffers stay in L2).
const TILE_COLS: usize = 512;

impl FastRenderer {
    /// Render the region band by band into `out` (3 values per pixel); bands not yet
    /// started when `cancel` is set are skipped and the render fails.
    pub(super) fn run<T: Send, S: Sink<T>>(
        &self,
        src: &Source<'_>,
        reg: Region,
        set: &KernelSet,
        out: &mut [T],
        sink: &S,
        cancel: &AtomicBool,
    ) -> Result<RenderStats, RenderError> {
        let chans = 3;
        let row_len = reg.width * chans;
        let isa = if self.uses_avx512() {
            Isa::Avx512
        } else if self.uses_simd() {
            Isa::Avx2
        } else {
            Isa::Portable
        };
        let ctx = TileCtx {
            fr: self,
            src,
            set,
            sink,
            reg,
            row_len,
        };
        let stats = out
            .par_chunks_mut(BAND_ROWS * row_len)
            .enumerate()
            .map(|(b, band)| {
                if cancel.load(Ordering::Relaxed) {
                    return RenderStats::default();
                }
                // the thread's buffers, reused across bands and renders
                SCRATCH.with(|cell| match cell.try_borrow_mut() {
                    Ok(mut scratch) => ctx.band(isa, b, band, &mut scratch),
                    Err(_) => ctx.band(isa, b, band, &mut Scratch::default()),
                })
            })
            .reduce(RenderStats::default, |mut a, b| {
                a += b;
                a
            });
        if cancel.load(Ordering::Relaxed) {
            return Err(RenderError::RenderCanceled);
        }
        Ok(stats)
    }
}

impl<S> TileCtx<'_, S> {
    /// Render band `b` (rows `reg.y + b·BAND_ROWS …`) tile by tile with `isa`.
    fn band<T>(&self, isa: Isa, b: usize, band: &mut [T], scratch: &mut Scratch) -> RenderStats
    where
        S: Sink<T>,
    {
        let reg = self.reg;
        let y0 = reg.y + b * BAND_ROWS;
        let rows = band.len() / self.row_len;
        let mut st = RenderStats::default();
        let mut x = 0;
        while x < reg.width {
            let tw = TILE_COLS.min(reg.width - x);
            let tile = Tile {
                r0: y0,
                c0: reg.x + x,
                rows,
                cols: tw,
            };
            st += match isa {
                // SAFETY: `Avx512` is only chosen when the CPU reports AVX-512 F, VL,
                // BW, VBMI, AVX2 and FMA; `Avx2` when it reports AVX2 and FMA.
                Isa::Avx512 => unsafe { self.tile_avx512(tile, scratch, band) },
                Isa::Avx2 => unsafe { self.tile_avx2(tile, scratch, band) },
                Isa::Portable => self.tile::<false, false, 0, T>(tile, scratch, band),
            };
            x += tw;
        }
        st
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn tile_avx2<T>(&self, tile: Tile, sc: &mut Scratch, band: &mut [T]) -> RenderStats
    where
        S: Sink<T>,
    {
        self.tile_sized::<false, T>(tile, sc, band)
    }

    /// [`tile`](Self::tile) with the patch size as a constant where it is a common
    /// one, so loops unroll (inlined into the `target_feature` functions).
    #[inline(always)]
    fn tile_sized<const WIDE: bool, T>(
        &self,
        tile: Tile,
        sc: &mut Scratch,
        band: &mut [T],
    ) -> RenderStats
    where
        S: Sink<T>,
    {
        match self.fr.geo.size {
            3 => self.tile::<true, WIDE, 3, T>(tile, sc, band),
            5 => self.tile::<true, WIDE, 5, T>(tile, sc, band),
            7 => self.tile::<true, WIDE, 7, T>(tile, sc, band),
            _ => self.tile::<true, false, 0, T>(tile, sc, band),
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,avx512f,avx512vl,avx512bw,avx512dq,avx512vbmi")]
    unsafe fn tile_avx512<T>(&self, tile: Tile, sc: &mut Scratch, band: &mut [T]) -> RenderStats
    where
        S: Sink<T>,
    {
        self.tile_sized::<true, T>(tile, sc, band)
    }

    #[cfg(not(target_arch = "x86_64"))]
    unsafe fn tile_avx512<T>(&self, tile: Tile, sc: &mut Scratch, band: &mut [T]) -> RenderStats
    where
        S: Sink<T>,
    {
        self.tile::<false, false, 0, T>(tile, sc, band)
    }

    #[cfg(not(target_arch = "x86_64"))]
    unsafe fn tile_avx2<T>(&self, tile: Tile, sc: &mut Scratch, band: &mut [T]) -> RenderStats
    where
        S: Sink<T>,
    {
        self.tile::<false, false, 0, T>(tile, sc, band)
    }
}

/// The instruction set a render runs with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Isa {
    Portable,
    Avx2,
    Avx512,
}

pub(super) fn avx512_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        simd_available()
            && std::is_x86_feature_detected!("avx512f")
            && std::is_x86_feature_detected!("avx512vl")
            && std::is_x86_feature_detected!("avx512bw")
            && std::is_x86_feature_detected!("avx512dq")
            && std::is_x86_feature_detected!("avx512vbmi")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

pub(super) fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
