//! Bands, tiles and the instruction set: the render split over threads.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::kernels::KernelSet;
use super::scratch::{SCRATCH, Scratch};
use super::sink::Sink;
use super::source::Source;
use super::tile::Tile;
use super::{FastRenderer, L3Error, Region, RenderStats};

/// Rows per rayon task.
const BAND_ROWS: usize = 32;
/// Output columns per tile (the tile buffers stay in L2).
const TILE_COLS: usize = 512;

impl FastRenderer {
    /// Render the region band by band into `out` (`chans` values per pixel); bands not yet
    /// started when `cancel` is set are skipped and the render fails.
    pub(super) fn run<T: Send, S: Sink<T>>(
        &self,
        src: &Source<'_>,
        reg: Region,
        set: &KernelSet,
        out: &mut [T],
        sink: &S,
        cancel: &AtomicBool,
    ) -> Result<RenderStats, L3Error> {
        let chans = 3;
        let row_len = reg.width * chans;
        let simd = if self.uses_avx512() {
            Isa::Avx512
        } else if self.uses_simd() {
            Isa::Avx2
        } else {
            Isa::Portable
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
                    Ok(mut scratch) => {
                        self.band(src, reg, set, b, band, row_len, simd, sink, &mut scratch)
                    }
                    Err(_) => self.band(
                        src,
                        reg,
                        set,
                        b,
                        band,
                        row_len,
                        simd,
                        sink,
                        &mut Scratch::default(),
                    ),
                })
            })
            .reduce(RenderStats::default, |mut a, b| {
                a += b;
                a
            });
        if cancel.load(Ordering::Relaxed) {
            return Err(L3Error::RenderCanceled);
        }
        Ok(stats)
    }

    /// Render band `b` (rows `reg.y + b·BAND_ROWS …`) tile by tile.
    #[allow(clippy::too_many_arguments)]
    fn band<T, S: Sink<T>>(
        &self,
        src: &Source<'_>,
        reg: Region,
        set: &KernelSet,
        b: usize,
        band: &mut [T],
        row_len: usize,
        simd: Isa,
        sink: &S,
        scratch: &mut Scratch,
    ) -> RenderStats {
        let chans = 3;
        {
            {
                let y0 = reg.y + b * BAND_ROWS;
                let rows = band.len() / row_len;
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
                    st += match simd {
                        // SAFETY: `Avx512` is only chosen when the CPU reports AVX-512 F, VL,
                        // BW, VBMI, AVX2 and FMA; `Avx2` when it reports AVX2 and FMA.
                        Isa::Avx512 => unsafe {
                            self.tile_avx512(
                                src,
                                set,
                                tile,
                                scratch,
                                band,
                                row_len,
                                chans * x,
                                sink,
                            )
                        },
                        Isa::Avx2 => unsafe {
                            self.tile_avx2(src, set, tile, scratch, band, row_len, chans * x, sink)
                        },
                        Isa::Portable => self.tile::<false, false, 0, T, S>(
                            src,
                            set,
                            tile,
                            scratch,
                            band,
                            row_len,
                            chans * x,
                            sink,
                        ),
                    };
                    x += tw;
                }
                st
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn tile_avx2<T, S: Sink<T>>(
        &self,
        src: &Source<'_>,
        set: &KernelSet,
        tile: Tile,
        scratch: &mut Scratch,
        band: &mut [T],
        row_len: usize,
        offset: usize,
        sink: &S,
    ) -> RenderStats {
        self.tile_sized::<false, T, S>(src, set, tile, scratch, band, row_len, offset, sink)
    }

    /// [`tile`](Self::tile) with the patch size as a constant where it is a common
    /// one, so loops unroll (inlined into the `target_feature` functions).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn tile_sized<const WIDE: bool, T, S: Sink<T>>(
        &self,
        src: &Source<'_>,
        set: &KernelSet,
        tile: Tile,
        sc: &mut Scratch,
        band: &mut [T],
        row_len: usize,
        offset: usize,
        sink: &S,
    ) -> RenderStats {
        match self.geo.size {
            3 => self.tile::<true, WIDE, 3, T, S>(src, set, tile, sc, band, row_len, offset, sink),
            5 => self.tile::<true, WIDE, 5, T, S>(src, set, tile, sc, band, row_len, offset, sink),
            7 => self.tile::<true, WIDE, 7, T, S>(src, set, tile, sc, band, row_len, offset, sink),
            _ => self.tile::<true, false, 0, T, S>(src, set, tile, sc, band, row_len, offset, sink),
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,avx512f,avx512vl,avx512bw,avx512dq,avx512vbmi")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn tile_avx512<T, S: Sink<T>>(
        &self,
        src: &Source<'_>,
        set: &KernelSet,
        tile: Tile,
        scratch: &mut Scratch,
        band: &mut [T],
        row_len: usize,
        offset: usize,
        sink: &S,
    ) -> RenderStats {
        self.tile_sized::<true, T, S>(src, set, tile, scratch, band, row_len, offset, sink)
    }

    #[cfg(not(target_arch = "x86_64"))]
    #[allow(clippy::too_many_arguments)]
    unsafe fn tile_avx512<T, S: Sink<T>>(
        &self,
        src: &Source<'_>,
        set: &KernelSet,
        tile: Tile,
        scratch: &mut Scratch,
        band: &mut [T],
        row_len: usize,
        offset: usize,
        sink: &S,
    ) -> RenderStats {
        self.tile::<false, false, 0, T, S>(src, set, tile, scratch, band, row_len, offset, sink)
    }

    #[cfg(not(target_arch = "x86_64"))]
    #[allow(clippy::too_many_arguments)]
    unsafe fn tile_avx2<T, S: Sink<T>>(
        &self,
        src: &Source<'_>,
        set: &KernelSet,
        tile: Tile,
        scratch: &mut Scratch,
        band: &mut [T],
        row_len: usize,
        offset: usize,
        sink: &S,
    ) -> RenderStats {
        self.tile::<false, false, 0, T, S>(src, set, tile, scratch, band, row_len, offset, sink)
    }
}

/// The instruction set a render runs with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Isa {
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
