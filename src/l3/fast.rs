//! The fast renderer (DESIGN.md §9). Same classes and kernels as
//! [`render_reference`](super::render_reference), organised for speed:
//!
//! - the frame is cut into bands of rows (one rayon task each) and column tiles
//!   small enough for the core's cache; each tile copies its rows plus a halo
//!   into an f32 buffer, converting u16 DN on the way (vectorised f64
//!   arithmetic, bit-identical to `RawFrame::to_volts`; no float copy of the frame);
//! - on 2×2 CFAs the per-channel patch sums come from separable sums of the
//!   four CFA phases, and the contrast from one vectorised pass per row;
//! - a pixel whose patch holds no saturated value (most of them) is a plain
//!   affine map of its patch rows: the kernels are laid out one 8-lane vector
//!   per patch row and output, applied with FMA where the CPU has it;
//! - on CPUs with AVX-512 (F, VL, BW, DQ, VBMI) and a 2×2 CFA (RGBW, or
//!   Bayer, whose two green phases make one channel), classification, kernels
//!   and the sRGB encoding run 16 pixels at a time in [`avx512`]; elsewhere
//!   the AVX2 + FMA or portable loops do;
//! - the 3×3 output matrix (illuminant correction, XYZ → linear sRGB and the
//!   white level) is fused into the kernels, so sRGB leaves through a lookup
//!   table without an XYZ image;
//! - work a tile does not need is skipped: saturation handling where no value
//!   reaches the threshold, the contrast measure where no level's flat and
//!   texture kernels differ, and everything outside the requested region.
//!
//! Pixels with a saturated value in their patch, pixels whose luminance or
//! contrast lies within a rounding margin of a class boundary, and CFAs other
//! than 2×2 take the reference classification, so both renderers put every
//! pixel in the same class; outputs then differ by float rounding only.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

#[cfg(target_arch = "x86_64")]
mod avx512;
mod frames;

pub use frames::Frame;

use super::classify::{PatchGeometry, sat_case_index};
use super::render::error::RenderError;
use super::render::output::{WhiteLevel, white_from_samples, white_sample_points};
use super::render::reference::{RenderStats, dot, fuse_matrix};
use super::table::L3Table;
use crate::colour::{SrgbLut, XYZ_TO_LINEAR_SRGB};

/// Rows per rayon task.
const BAND_ROWS: usize = 32;
/// Output columns per tile (the tile buffers stay in L2).
const TILE_COLS: usize = 512;
/// Lanes per kernel row in the SIMD layout.
const LANES: usize = 8;
/// Luminance (V) within this of a level boundary is classified by the reference code.
const LUMINANCE_MARGIN: f32 = 2e-5;
/// Contrast (V) within this of a class threshold is classified by the reference code.
const CONTRAST_MARGIN: f32 = 1e-5;
/// A chroma class whose margin over the runner-up ([`PatchGeometry::chroma_of`]'s
/// score gap) is under this fraction of the pixel's score scale, `Σ_ch max_k |a_k,ch| ·
/// mean_ch`, is classified by the reference code. The means are sums of at most 25
/// non-negative values (a 9×9 patch's largest phase), scaled: each path's rounding is
/// under 24 · 2⁻²⁴ ≈ 1.4e-6 of the mean, so the two paths' scores differ by ≲4e-6 of
/// the scale (with the scores' own rounding), a fifth of the margin. The margin is
/// relative because the error is: an absolute one (1e-4 V) sent dark pixels near a
/// class boundary to the reference code.
const CHROMA_MARGIN: f32 = 2e-5;
/// The smallest chroma margin (V): pixels this close to black are classified by the
/// reference code.
const CHROMA_MARGIN_FLOOR: f32 = 1e-9;

/// A mosaic to render: volts or integer DN, row-major.
#[derive(Clone, Copy, Debug)]
pub enum Mosaic<'a> {
    /// Volts. Non-finite values are an error; values outside [0, swing] are clamped and counted.
    Volts(&'a [f32]),
    /// Integer DN: volts = (dn − black) / (white − black) × swing, clamped to [0, swing].
    Dn {
        data: &'a [u16],
        black: u16,
        white: u16,
    },
}

/// A rectangle of the frame (output pixels).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    pub x: usize,
    pub y: usize,
    pub width: usize,
    pub height: usize,
}

/// Switches for the optimisations, all on by default (turned off to measure them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FastOptions {
    /// Skip the saturation tests in tiles where no value reaches the threshold.
    pub skip_unsaturated_tiles: bool,
    /// Skip the contrast measure for classes whose flat and texture kernels are equal.
    pub skip_equal_contrast_kernels: bool,
    /// Use AVX2 + FMA when the CPU has them.
    pub simd: bool,
    /// Use AVX-512 when the CPU has it (and `simd` is on).
    pub avx512: bool,
}

impl Default for FastOptions {
    fn default() -> Self {
        Self {
            skip_unsaturated_tiles: true,
            skip_equal_contrast_kernels: true,
            simd: true,
            avx512: true,
        }
    }
}

/// Whether patch size `p` uses the packed AVX-512 kernel layout (the three
/// outputs' weights of a patch row fit one 16-lane register: patch 3 and 5).
const fn packed(p: usize) -> bool {
    p > 0 && 3 * p < 16
}

/// Values per class in the packed layout: `p` weight rows and the bias row, 16 lanes each.
const fn packed_stride(p: usize) -> usize {
    16 * (p + 1)
}

/// The lane of weight `dx` of output `o` in a packed row (and of output o's
/// bias, dx = 0, in the bias row).
const fn packed_lane(p: usize, o: usize, dx: usize) -> usize {
    o * p + dx
}

/// One kernel set in both layouts.
#[derive(Clone, Debug)]
struct KernelSet {
    /// The table's layout: class × 3 × n_features.
    flat: Vec<f32>,
    /// Values per class in `rows`.
    stride: usize,
    /// Per class: 3 outputs × `size` patch rows × [`LANES`] weights, then 4 biases.
    rows: Vec<f32>,
    /// Values per class in `paired`.
    pstride: usize,
    /// Per class, for the AVX-512 kernels: patch 3 and 5 ([`packed`]): `size` rows
    /// of 16 weights holding all three outputs ([`packed_lane`]) and the bias row;
    /// patch 7: `size` rows of [X row | Y row] weights (8 lanes each), the
    /// [X bias | Y bias] row, `size` rows of Z weights, the Z bias row.
    paired: Vec<f32>,
    /// Where the classes start in `paired` (its first 64-byte boundary, so
    /// 16-lane loads of a class never straddle cache lines).
    paired_at: usize,
}

impl KernelSet {
    /// The classes of the AVX-512 layout, from a 64-byte boundary.
    fn paired(&self) -> &[f32] {
        &self.paired[self.paired_at..]
    }
}

/// A table prepared for fast rendering with one set of (possibly T-fused) XYZ kernels.
#[derive(Clone, Debug)]
pub struct FastRenderer {
    geo: PatchGeometry,
    n_features: usize,
    /// Classification bands: levels × chroma classes.
    n_bands: usize,
    /// Chroma classes per level (1: no chroma split).
    n_chroma: usize,
    /// Per CFA position, the channel of each phase (2×2 CFAs), so the phase
    /// means give the channel means the chroma class is read from.
    phase_channels: [[u8; 4]; 4],
    /// Per channel, the largest chroma score weight in magnitude (see [`CHROMA_MARGIN`]).
    chroma_scale: Vec<f32>,
    sat_cases: Vec<u32>,
    contrast_thresholds: Vec<f32>,
    /// Per group: do the flat and texture kernels differ?
    contrast_matters: Vec<bool>,
    /// The thresholds, +∞ where flat and texture kernels are equal.
    thresholds_where_they_matter: Vec<f32>,
    /// +∞ for every group (no contrast classes).
    no_thresholds: Vec<f32>,
    sat_classes: bool,
    contrast_classes: bool,
    swing: f32,
    /// The swing as the table holds it (DN conversion is done in f64 as `RawFrame::to_volts` does).
    swing_f64: f64,
    xyz: KernelSet,
    /// Per CFA position, the 4×4 map from phase sums to per-phase channel means,
    /// and the luminance weights of the phase sums (2×2 CFAs only).
    phases: Option<Vec<PhaseMap>>,
    /// Set when every CFA phase holds its own channel at every position (RGBW).
    uniform_phases: Option<UniformPhases>,
    level_lut: LevelLut,
    simd_available: bool,
    avx512_available: bool,
    pub options: FastOptions,
}

/// Position-free phase weights: `mean[p] = inv[p] · sum[p]`, `luminance = Σ lum[p] · sum[p]`.
#[derive(Clone, Copy, Debug)]
struct UniformPhases {
    inv: [f32; 4],
    lum: [f32; 4],
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct PhaseMap {
    /// `mean[p] = Σ_q to_mean[p][q] · sum[q]` for phase p = 2·(row parity) + column parity.
    to_mean: [[f32; 4]; 4],
    /// `luminance = Σ_q lum[q] · sum[q]`.
    lum: [f32; 4],
}

thread_local! {
    /// Each thread's tile buffers (a band that finds them in use makes its own).
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// Reusable per-thread buffers.
#[derive(Default)]
struct Scratch {
    buf: Vec<f32>,
    he: Vec<f32>,
    ho: Vec<f32>,
    hmax: Vec<f32>,
    sums: [Vec<f32>; 4],
    means: [Vec<f32>; 4],
    lum: Vec<f32>,
    contrast: Vec<f32>,
    sat: Vec<bool>,
    class: Vec<u32>,
    /// Per pixel, where its kernels start in the AVX-512 layout.
    offsets: Vec<u32>,
    lin: [Vec<f32>; 3],
    patch: Vec<f32>,
    feat: Vec<f32>,
    chroma: ChromaScratch,
}

/// A tile row's chroma classes ([`FastRenderer::chroma_row`]).
#[derive(Default)]
struct ChromaScratch {
    /// Channel means per channel (clamped at 0), from the phase means.
    means: Vec<Vec<f32>>,
    score: Vec<f32>,
    /// Each pixel's score scale (see [`CHROMA_MARGIN`]).
    scale: Vec<f32>,
    /// The lowest and second-lowest class score, and the lowest's class.
    s1: Vec<f32>,
    s2: Vec<f32>,
    best: Vec<u32>,
}

/// How a row of linear outputs (three planes) becomes the output row.
trait Sink<T>: Sync {
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
struct XyzSink;
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
struct Srgb8Sink {
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
    fn shared() -> &'static Self {
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

/// The frame being rendered, with its conversion to clamped volts.
struct Source<'a> {
    mosaic: Mosaic<'a>,
    width: usize,
    height: usize,
    swing: f32,
    /// DN → volts: `((dn − black) · scale).clamp(0, swing)` in f64, as `RawFrame::to_volts`.
    dn: DnScale,
}

/// The f64 constants of the DN → volts conversion.
#[derive(Clone, Copy, Debug, Default)]
struct DnScale {
    black: f64,
    scale: f64,
    swing: f64,
}

impl DnScale {
    #[inline(always)]
    fn volts(&self, d: u16) -> f32 {
        ((f64::from(d) - self.black) * self.scale).clamp(0.0, self.swing) as f32
    }
}

impl Source<'_> {
    /// Clamped volts of frame row `r`, columns `c0..c0 + out.len()` (all inside the frame).
    #[inline(always)]
    fn row_into(&self, r: usize, c0: usize, out: &mut [f32]) {
        let start = r * self.width + c0;
        let end = start + out.len();
        match self.mosaic {
            Mosaic::Volts(v) => {
                for (o, &x) in out.iter_mut().zip(&v[start..end]) {
                    *o = x.clamp(0.0, self.swing);
                }
            }
            Mosaic::Dn { data, .. } => {
                for (o, &d) in out.iter_mut().zip(&data[start..end]) {
                    *o = self.dn.volts(d);
                }
            }
        }
    }

    /// Ask the CPU to bring frame rows `rows`, columns `c0..c1` (clamped to the
    /// frame) into its caches: a hint, so that scattered reads (the white sample
    /// grid) wait on memory together rather than one after another.
    #[inline]
    fn prefetch(&self, rows: std::ops::Range<usize>, c0: usize, c1: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
            let (base, elem) = match self.mosaic {
                Mosaic::Volts(v) => (v.as_ptr().cast::<u8>(), 4),
                Mosaic::Dn { data, .. } => (data.as_ptr().cast::<u8>(), 2),
            };
            let c1 = c1.min(self.width);
            for r in rows.start..rows.end.min(self.height) {
                let (a, b) = ((r * self.width + c0) * elem, (r * self.width + c1) * elem);
                let mut at = a & !63;
                while at < b {
                    // SAFETY: a prefetch never faults; the address lies inside the frame
                    // (wrapping_add only avoids asserting so).
                    unsafe { _mm_prefetch::<_MM_HINT_T0>(base.wrapping_add(at).cast()) };
                    at += 64;
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (rows, c0, c1);
    }

    #[inline]
    fn at(&self, r: usize, c: usize) -> f32 {
        let i = r * self.width + c;
        match self.mosaic {
            Mosaic::Volts(v) => v[i].clamp(0.0, self.swing),
            Mosaic::Dn { data, .. } => self.dn.volts(data[i]),
        }
    }
}

impl FastRenderer {
    /// Prepare `table` with `kernels` (its own, or fused with a correction matrix
    /// by [`fuse_kernels`](super::fuse_kernels)), its chroma classes under their
    /// reference light.
    pub fn new(table: &L3Table, kernels: &[f32]) -> Result<Self, RenderError> {
        Self::under_light(table, kernels, None)
    }

    /// [`Self::new`] with the chroma classes balanced by `light`, the neutral
    /// (channel responses to white) of the light the mosaics are taken under.
    pub fn under_light(
        table: &L3Table,
        kernels: &[f32],
        light: Option<&[f64]>,
    ) -> Result<Self, RenderError> {
        if kernels.len() != table.kernels.len() {
            return Err(RenderError::KernelMismatch {
                got: kernels.len(),
                expected: table.kernels.len(),
            });
        }
        if kernels.iter().any(|v| !v.is_finite()) {
            return Err(RenderError::Table("a kernel weight is not finite".into()));
        }
        let geo = table.geometry_under(light)?;
        let nf = table.n_features();
        let n_groups = table.n_classes() / 2;
        let contrast_matters = (0..n_groups)
            .map(|g| {
                kernels[2 * g * 3 * nf..(2 * g + 1) * 3 * nf]
                    != kernels[(2 * g + 1) * 3 * nf..(2 * g + 2) * 3 * nf]
            })
            .collect();
        let phases = phase_maps(&geo);
        let thresholds_where_they_matter = table
            .contrast_thresholds
            .iter()
            .zip(&contrast_matters)
            .map(|(&t, &m)| if m { t } else { f32::INFINITY })
            .collect();
        let no_thresholds = vec![f32::INFINITY; n_groups];
        let uniform_phases = phases.as_ref().and_then(|maps| uniform_phases(maps));
        let level_lut = LevelLut::new(&geo, table.meta.voltage_swing as f32);
        let n_sat = table.meta.sat_cases.len();
        let xyz = KernelSet::new(kernels.to_vec(), geo.size, n_sat);
        Ok(Self {
            n_features: nf,
            n_bands: table.n_bands(),
            n_chroma: geo.n_chroma(),
            phase_channels: std::array::from_fn(|pos| {
                let (pr, pc) = (pos / 2, pos % 2);
                std::array::from_fn(|p| geo.cfa.channel_at(pr + p / 2, pc + p % 2) as u8)
            }),
            chroma_scale: (0..geo.n_channels())
                .map(|ch| {
                    geo.chroma_coefficients()
                        .iter()
                        .map(|a| a[ch].abs())
                        .fold(0.0, f32::max)
                })
                .collect(),
            sat_cases: table.meta.sat_cases.clone(),
            contrast_thresholds: table.contrast_thresholds.clone(),
            contrast_matters,
            thresholds_where_they_matter,
            no_thresholds,
            sat_classes: table.meta.params.saturation_classes,
            contrast_classes: table.meta.params.contrast_classes,
            swing: table.meta.voltage_swing as f32,
            swing_f64: table.meta.voltage_swing,
            xyz,
            phases,
            uniform_phases,
            level_lut,
            simd_available: simd_available(),
            avx512_available: avx512_available(),
            geo,
            options: FastOptions::default(),
        })
    }

    /// Whether the AVX2 + FMA kernels will be used.
    pub fn uses_simd(&self) -> bool {
        self.simd_available && self.options.simd
    }

    /// Whether the AVX-512 kernels will be used (2×2 CFAs, patch 3, 5 or 7).
    /// A table with more than 32 levels is classified by the AVX2 code and
    /// its kernels applied with AVX-512.
    pub fn uses_avx512(&self) -> bool {
        self.uses_simd()
            && self.avx512_available
            && self.options.avx512
            && self.phases.is_some()
            && matches!(self.geo.size, 3 | 5 | 7)
    }

    /// Render `region` (default: the whole frame) of a `width × height` mosaic to
    /// interleaved XYZ. Equals cropping [`render_reference`](super::render_reference)'s
    /// output to the region, to float rounding.
    pub fn render_xyz(
        &self,
        mosaic: Mosaic<'_>,
        width: usize,
        height: usize,
        region: Option<Region>,
    ) -> Result<(Vec<f32>, RenderStats), RenderError> {
        self.render_xyz_until(mosaic, width, height, region, &AtomicBool::new(false))
    }

    /// [`render_xyz`](Self::render_xyz) that stops between bands of rows once `cancel` is
    /// set, with [`RenderError::RenderCanceled`].
    pub fn render_xyz_until(
        &self,
        mosaic: Mosaic<'_>,
        width: usize,
        height: usize,
        region: Option<Region>,
        cancel: &AtomicBool,
    ) -> Result<(Vec<f32>, RenderStats), RenderError> {
        let (src, clamped) = self.source(mosaic, width, height)?;
        let reg = check_region(region, width, height)?;
        let mut out = crate::buffers::zeroed::<f32>(reg.width * reg.height * 3);
        let mut stats = self.run(&src, reg, &self.xyz, &mut out, &XyzSink, cancel)?;
        stats.clamped = clamped;
        Ok((out, stats))
    }

    /// Render `region` to 8-bit sRGB, `white` Y mapping to white (Auto: the 99th
    /// percentile of Y over the frame's sample grid, as [`white_y`](super::white_y)).
    /// Returns the pixels and the white Y used. The pixels' buffer returns to a
    /// small pool when dropped and serves a later render (see [`Frame`]).
    pub fn render_srgb8(
        &self,
        mosaic: Mosaic<'_>,
        width: usize,
        height: usize,
        region: Option<Region>,
        white: WhiteLevel,
    ) -> Result<(Frame, f64, RenderStats), RenderError> {
        self.render_srgb8_until(
            mosaic,
            width,
            height,
            region,
            white,
            &AtomicBool::new(false),
        )
    }

    /// [`render_srgb8`](Self::render_srgb8) that stops between bands of rows once `cancel`
    /// is set, with [`RenderError::RenderCanceled`].
    pub fn render_srgb8_until(
        &self,
        mosaic: Mosaic<'_>,
        width: usize,
        height: usize,
        region: Option<Region>,
        white: WhiteLevel,
        cancel: &AtomicBool,
    ) -> Result<(Frame, f64, RenderStats), RenderError> {
        let reg = check_region(region, width, height)?;
        let mut out = Frame::take(reg.width * reg.height * 3);
        let (wy, stats) =
            self.srgb8_into(mosaic, width, height, region, white, &mut out, cancel)?;
        Ok((out, wy, stats))
    }

    /// [`render_srgb8`](Self::render_srgb8) into `out` (3 bytes per pixel of the
    /// region, row-major), e.g. a buffer reused from frame to frame. Returns the
    /// white Y used.
    pub fn render_srgb8_into(
        &self,
        mosaic: Mosaic<'_>,
        width: usize,
        height: usize,
        region: Option<Region>,
        white: WhiteLevel,
        out: &mut [u8],
    ) -> Result<(f64, RenderStats), RenderError> {
        self.srgb8_into(
            mosaic,
            width,
            height,
            region,
            white,
            out,
            &AtomicBool::new(false),
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn srgb8_into(
        &self,
        mosaic: Mosaic<'_>,
        width: usize,
        height: usize,
        region: Option<Region>,
        white: WhiteLevel,
        out: &mut [u8],
        cancel: &AtomicBool,
    ) -> Result<(f64, RenderStats), RenderError> {
        let reg = check_region(region, width, height)?;
        let need = reg.width * reg.height * 3;
        if out.len() != need {
            return Err(RenderError::OutputBuffer {
                got: out.len(),
                need,
                width: reg.width,
                height: reg.height,
            });
        }
        let (src, clamped) = self.source(mosaic, width, height)?;
        let wy = self.white_of(&src, white);
        let k = 1.0 / wy;
        let m = XYZ_TO_LINEAR_SRGB.map(|r| r.map(|v| v * k));
        let set = KernelSet::new(
            fuse_matrix(&self.xyz.flat, &m, self.n_features),
            self.geo.size,
            self.sat_cases.len(),
        );
        let mut stats = self.run(&src, reg, &set, out, Srgb8Sink::shared(), cancel)?;
        stats.clamped = clamped;
        Ok((wy, stats))
    }

    /// The white level of a frame: `Y(v)` as is, or the 99th percentile of the
    /// rendered Y over the sample grid of [`white_y`](super::white_y).
    pub fn white_y(
        &self,
        mosaic: Mosaic<'_>,
        width: usize,
        height: usize,
        white: WhiteLevel,
    ) -> Result<f64, RenderError> {
        let (src, _) = self.source(mosaic, width, height)?;
        Ok(self.white_of(&src, white))
    }

    fn white_of(&self, src: &Source<'_>, white: WhiteLevel) -> f64 {
        match white {
            WhiteLevel::Y(v) => v,
            WhiteLevel::Auto => {
                let points = white_sample_points(src.width, src.height);
                let ys: Vec<f32> = points
                    .par_chunks(256)
                    .flat_map_iter(|chunk| {
                        let mut patch = vec![0f32; self.n_features - 1];
                        let mut feat = vec![0f32; self.n_features];
                        let rad = self.geo.radius;
                        for &(r, c) in chunk {
                            let c0 = c.saturating_sub(rad);
                            src.prefetch(r.saturating_sub(rad)..r + rad + 1, c0, c + rad + 1);
                        }
                        chunk
                            .iter()
                            .map(|&(r, c)| {
                                gather_frame(&self.geo, src, r, c, &mut patch);
                                let (class, sat, ..) = self.classify_exact(&patch, r, c);
                                let pos = self.geo.position(r, c);
                                self.geo
                                    .features(&patch, pos, self.sat_cases[sat], &mut feat);
                                let nf = self.n_features;
                                let k = &self.xyz.flat[class * 3 * nf..(class + 1) * 3 * nf];
                                dot(&k[nf..2 * nf], &feat)
                            })
                            .collect::<Vec<_>>()
                    })
                    .collect();
                white_from_samples(ys)
            }
        }
    }

    /// The reference classification of a gathered patch: (class, sat case, fell back, texture).
    #[inline]
    fn classify_exact(&self, patch: &[f32], r: usize, c: usize) -> (usize, usize, bool, bool) {
        let pos = self.geo.position(r, c);
        let s = self.geo.stats(patch, pos);
        let band = self.geo.band_of(s.luminance, &s.channel_means);
        let (sat, fell_back) = if self.sat_classes && s.sat_mask != 0 {
            sat_case_index(&self.sat_cases, s.sat_mask, &s.channel_means)
        } else {
            (0, false)
        };
        let group = self.group(pos, band, sat);
        let texture = self.contrast_classes && s.contrast > self.contrast_thresholds[group];
        (group * 2 + texture as usize, sat, fell_back, texture)
    }

    #[inline(always)]
    fn group(&self, pos: usize, band: usize, sat: usize) -> usize {
        (pos * self.n_bands + band) * self.sat_cases.len() + sat
    }

    /// The chroma class of every pixel of a tile row (`tw` columns, row parity
    /// `rpar`, first column's parity `cpar`) from its phase means, as
    /// [`PatchGeometry::chroma_of`] computes it, a class (all pixels) at a time
    /// so that the loops vectorise: with AVX2 when the tile runs with it
    /// (`SIMD`), kept out of line so that one-class tables do not carry it.
    #[inline(never)]
    fn chroma_row<const SIMD: bool>(
        &self,
        means: &[Vec<f32>; 4],
        parity: (usize, usize),
        tw: usize,
        cs: &mut ChromaScratch,
    ) {
        #[cfg(target_arch = "x86_64")]
        if SIMD {
            // SAFETY: the tile runs with `SIMD` only where AVX2 and FMA were detected
            unsafe { self.chroma_row_avx2(means, parity, tw, cs) };
            return;
        }
        self.chroma_row_body(means, parity, tw, cs);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn chroma_row_avx2(
        &self,
        means: &[Vec<f32>; 4],
        parity: (usize, usize),
        tw: usize,
        cs: &mut ChromaScratch,
    ) {
        self.chroma_row_body(means, parity, tw, cs);
    }

    /// [`Self::chroma_row`]'s loops; separate multiplies and adds (no fused
    /// ones), so every instruction set gives the reference's scores.
    #[inline(always)]
    fn chroma_row_body(
        &self,
        means: &[Vec<f32>; 4],
        (rpar, cpar): (usize, usize),
        tw: usize,
        cs: &mut ChromaScratch,
    ) {
        let nc = self.geo.n_channels();
        cs.means.resize_with(nc, Vec::new);
        for v in cs.means.iter_mut() {
            resize(v, tw);
        }
        for par in 0..2 {
            // pixels of this column parity sit at CFA position `pos`
            let pos = rpar * 2 + (cpar + par) % 2;
            for (p, &ch) in self.phase_channels[pos].iter().enumerate() {
                let (dst, src) = (&mut cs.means[ch as usize][..tw], &means[p][..tw]);
                for i in (par..tw).step_by(2) {
                    dst[i] = src[i].max(0.0);
                }
            }
        }
        for v in [&mut cs.score, &mut cs.scale, &mut cs.s1, &mut cs.s2] {
            resize(v, tw);
        }
        let scale = &mut cs.scale[..tw];
        scale.fill(0.0);
        for (m, &w) in cs.means.iter().zip(&self.chroma_scale) {
            for (s, &v) in scale.iter_mut().zip(&m[..tw]) {
                *s += w * v;
            }
        }
        cs.s1[..tw].fill(f32::INFINITY);
        cs.s2[..tw].fill(f32::INFINITY);
        cs.best.clear();
        cs.best.resize(tw, 0);
        for (k, a) in self.geo.chroma_coefficients().iter().enumerate() {
            let score = &mut cs.score[..tw];
            score.fill(0.0);
            for (ch, m) in cs.means.iter().enumerate() {
                let w = a[ch];
                for (s, &v) in score.iter_mut().zip(&m[..tw]) {
                    *s += w * v;
                }
            }
            let (s1, s2, best) = (&mut cs.s1[..tw], &mut cs.s2[..tw], &mut cs.best[..tw]);
            for i in 0..tw {
                let v = score[i];
                let lower = v < s1[i];
                s2[i] = s2[i].min(s1[i].max(v));
                best[i] = if lower { k as u32 } else { best[i] };
                s1[i] = s1[i].min(v);
            }
        }
    }

    /// Check the frame and build its converter; f32 input is scanned once for
    /// non-finite values and counted for clamping, as the reference does.
    fn source<'a>(
        &self,
        mosaic: Mosaic<'a>,
        width: usize,
        height: usize,
    ) -> Result<(Source<'a>, u64), RenderError> {
        if width == 0 || height == 0 {
            return Err(RenderError::InvalidInput(format!(
                "frame is {width}×{height}"
            )));
        }
        let n = width.checked_mul(height).ok_or_else(|| {
            RenderError::InvalidInput(format!("frame {width}×{height} is too large"))
        })?;
        let swing = self.swing;
        let (len, dn, clamped) = match mosaic {
            Mosaic::Volts(v) => {
                // one vectorised pass counts both; the first bad value is looked up only if there is one
                let (bad, clamped) = v
                    .par_chunks(1 << 16)
                    .map(|ch| {
                        ch.iter().fold((0u64, 0u64), |(b, c), &x| {
                            let finite = x.abs() < f32::INFINITY;
                            (
                                b + u64::from(!finite),
                                c + u64::from(!(0.0..=swing).contains(&x)),
                            )
                        })
                    })
                    .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
                if bad > 0 {
                    let i = v.par_iter().position_first(|x| !x.is_finite()).unwrap_or(0);
                    return Err(RenderError::InvalidInput(format!(
                        "input value at row {}, column {} is not finite",
                        i / width,
                        i % width
                    )));
                }
                (v.len(), DnScale::default(), clamped)
            }
            Mosaic::Dn { data, black, white } => {
                if white <= black {
                    return Err(RenderError::InvalidInput(format!(
                        "white level {white} must exceed black level {black}"
                    )));
                }
                let (b, s) = (f64::from(black), self.swing_f64);
                let dn = DnScale {
                    black: b,
                    scale: s / (f64::from(white) - b),
                    swing: s,
                };
                (data.len(), dn, 0)
            }
        };
        if len != n {
            return Err(RenderError::InvalidInput(format!(
                "{len} values for a {width}×{height} frame ({n} expected)"
            )));
        }
        Ok((
            Source {
                mosaic,
                width,
                height,
                swing,
                dn,
            },
            clamped,
        ))
    }

    /// Render the region band by band into `out` (`chans` values per pixel); bands not yet
    /// started when `cancel` is set are skipped and the render fails.
    fn run<T: Send, S: Sink<T>>(
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
            return Err(RenderError::RenderCanceled);
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

    /// Render one tile: rows `r0..r0 + rows`, columns `c0..c0 + cols` of the
    /// frame, into the band's rows at `offset`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn tile<const SIMD: bool, const WIDE: bool, const P: usize, T, S: Sink<T>>(
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
        // P: the patch size known at compile time (0: not)
        let s = if P != 0 { P } else { self.geo.size };
        let rad = s / 2;
        let nf = self.n_features;
        let tw = tile.cols;
        // scratch rows are padded to whole 16-lane chunks; the buffer has 16 more
        // columns so every 8- or 16-wide read of a patch row stays inside it
        let tw8 = tw.div_ceil(2 * LANES) * 2 * LANES;
        let stride = tw8 + 2 * LANES;
        let brows = tile.rows + 2 * rad;
        let thr = self.geo.sat_threshold();
        // 1. the tile and its halo, clamped volts, mirrored at the frame's borders.
        // Columns past the halo are never weighted (zero kernel weights), so stale
        // finite values from an earlier tile may stay there: no clearing needed.
        resize(&mut sc.buf, brows * stride);
        let mut peak = 0f32;
        let first = tile.c0 as isize - rad as isize;
        let span = tw + 2 * rad;
        // the part of the span inside the frame, and its offset in the buffer row
        let lo = first.max(0) as usize;
        let hi = (first + span as isize).min(src.width as isize) as usize;
        let off = (lo as isize - first) as usize;
        for j in 0..brows {
            let r = super::mirror(tile.r0 as isize + j as isize - rad as isize, src.height);
            let row = &mut sc.buf[j * stride..j * stride + span];
            if hi > lo {
                src.row_into(r, lo, &mut row[off..off + (hi - lo)]);
            }
            for i in (0..off).chain(off + hi.saturating_sub(lo)..span) {
                row[i] = src.at(r, super::mirror(first + i as isize, src.width));
            }
            peak = peak.max(row_peak(row));
        }
        let any_sat = !self.options.skip_unsaturated_tiles || peak >= thr;
        let use_contrast = self.contrast_classes
            && (!self.options.skip_equal_contrast_kernels
                || self.contrast_matters.iter().any(|&m| m));
        let fast_classes = self.phases.is_some();
        // 2. horizontal phase sums (and maxima where saturation is possible)
        if fast_classes {
            resize(&mut sc.he, brows * tw8);
            resize(&mut sc.ho, brows * tw8);
            for j in 0..brows {
                let row = &sc.buf[j * stride..(j + 1) * stride];
                let he = &mut sc.he[j * tw8..(j + 1) * tw8];
                let ho = &mut sc.ho[j * tw8..(j + 1) * tw8];
                if P != 0 {
                    phase_sums_row::<P>(row, he, ho);
                    continue;
                }
                he.fill(0.0);
                ho.fill(0.0);
                for d in 0..s {
                    // offset d − rad: even offsets are the centre's column phase
                    let dst = if (d + rad) % 2 == 0 {
                        &mut *he
                    } else {
                        &mut *ho
                    };
                    add_into(dst, &row[d..d + tw8]);
                }
            }
        }
        if any_sat {
            resize(&mut sc.hmax, brows * tw8);
            for j in 0..brows {
                let row = &sc.buf[j * stride..(j + 1) * stride];
                let hm = &mut sc.hmax[j * tw8..(j + 1) * tw8];
                hm.copy_from_slice(&row[..tw8]);
                for d in 1..s {
                    // (values are finite: a plain comparison, which vectorises)
                    for (o, &v) in hm.iter_mut().zip(&row[d..d + tw8]) {
                        *o = if v > *o { v } else { *o };
                    }
                }
            }
        }
        for v in sc
            .sums
            .iter_mut()
            .chain(sc.means.iter_mut())
            .chain(sc.lin.iter_mut())
        {
            resize(v, tw8);
        }
        resize(&mut sc.lum, tw8);
        resize(&mut sc.contrast, tw8);
        if sc.sat.len() < tw8 {
            sc.sat.resize(tw8, false);
        }
        sc.sat[..tw8].fill(false);
        if sc.class.len() < tw8 {
            sc.class.resize(tw8, NO_CLASS);
        }
        sc.class[..tw8].fill(NO_CLASS);
        if sc.offsets.len() < tw8 {
            sc.offsets.resize(tw8, 0);
        }
        sc.patch.clear();
        sc.patch.resize(s * s, 0.0);
        sc.feat.clear();
        sc.feat.resize(nf, 0.0);
        let inv_area = 1.0 / (s * s) as f32;
        let n_sat = self.sat_cases.len();
        let thresholds = if !use_contrast {
            &self.no_thresholds
        } else if self.options.skip_equal_contrast_kernels {
            &self.thresholds_where_they_matter
        } else {
            &self.contrast_thresholds
        };
        #[cfg(target_arch = "x86_64")]
        let wide = if WIDE && fast_classes {
            self.class_params(thresholds, use_contrast, set)
        } else {
            None
        };
        let mut st = RenderStats::default();
        // where two phases share a channel (Bayer), each row parity's maps per lane
        let lane_maps = match (&self.phases, &self.uniform_phases) {
            (Some(maps), None) => {
                Some([0, 1].map(|rpar| LaneMaps::of_row(maps, rpar, tile.c0 % 2)))
            }
            _ => None,
        };
        for y in 0..tile.rows {
            let r = tile.r0 + y;
            // 3. which pixels see a saturated value
            if any_sat {
                let sat = &mut sc.sat[..tw8];
                sat.fill(false);
                for dy in 0..s {
                    let h = &sc.hmax[(y + dy) * tw8..(y + dy + 1) * tw8];
                    for (f, &v) in sat.iter_mut().zip(h) {
                        *f |= v >= thr;
                    }
                }
            }
            #[cfg(target_arch = "x86_64")]
            if let Some(prm) = &wide {
                let rows = &sc.buf[y * stride..];
                let sat = any_sat.then_some(&sc.sat[..]);
                let (he, ho) = (&sc.he[y * tw8..], &sc.ho[y * tw8..]);
                let (rpar, cpar) = (r % 2, tile.c0 % 2);
                // SAFETY: `wide` is only set in `tile_avx512`, which runs when the CPU has
                // the features; the kernels check the lengths of what they touch.
                let counts = unsafe {
                    avx512::classify_row::<P>(
                        he,
                        ho,
                        tw8,
                        rows,
                        stride,
                        sat,
                        tw,
                        rpar,
                        cpar,
                        prm,
                        &mut sc.class,
                        &mut sc.offsets,
                    )
                };
                let [l0, l1, l2] = &mut sc.lin;
                let applied = counts.is_some()
                    // SAFETY: as above
                    && unsafe {
                        avx512::apply_kernels::<P>(
                            rows,
                            stride,
                            &sc.offsets,
                            tw,
                            set.paired(),
                            set.pstride,
                            [&mut l0[..], &mut l1[..], &mut l2[..]],
                        )
                    };
                if let (true, Some(counts)) = (applied, counts) {
                    st.texture += counts.texture;
                    if counts.exact > 0 {
                        for i in 0..tw {
                            if sc.class[i] == NO_CLASS {
                                let (patch, feat) = (&mut sc.patch, &mut sc.feat);
                                let rc = (r, tile.c0 + i);
                                let v = self
                                    .exact_pixel(set, rows, stride, i, rc, patch, feat, &mut st);
                                l0[i] = v[0];
                                l1[i] = v[1];
                                l2[i] = v[2];
                            }
                        }
                    }
                    let out_row = &mut band[y * row_len + offset..(y + 1) * row_len];
                    // SAFETY: as above
                    unsafe { sink.finish_row_wide(out_row, &sc.lin, tw) };
                    st.pixels += tw as u64;
                    continue;
                }
            }
            // 4. phase sums → per-phase means and luminance, then contrast and class
            if self.phases.is_some() {
                for v in sc.sums.iter_mut() {
                    v[..tw8].fill(0.0);
                }
                for dy in 0..s {
                    let j = y + dy;
                    let e = &sc.he[j * tw8..(j + 1) * tw8];
                    let o = &sc.ho[j * tw8..(j + 1) * tw8];
                    let [s0, s1, s2, s3] = &mut sc.sums;
                    let (se, so) = if (dy + rad) % 2 == 0 {
                        (s0, s1)
                    } else {
                        (s2, s3)
                    };
                    add_into(se, e);
                    add_into(so, o);
                }
                let rpar = r % 2;
                if let Some(u) = &self.uniform_phases {
                    // every channel on its own phase: means and luminance are position-free
                    let [s0, s1, s2, s3] = &sc.sums;
                    let [m0, m1, m2, m3] = &mut sc.means;
                    let (s0, s1, s2, s3) = (&s0[..tw8], &s1[..tw8], &s2[..tw8], &s3[..tw8]);
                    let (m0, m1, m2, m3) = (
                        &mut m0[..tw8],
                        &mut m1[..tw8],
                        &mut m2[..tw8],
                        &mut m3[..tw8],
                    );
                    let lum = &mut sc.lum[..tw8];
                    for i in 0..tw8 {
                        let q = [s0[i], s1[i], s2[i], s3[i]];
                        m0[i] = q[0] * u.inv[0];
                        m1[i] = q[1] * u.inv[1];
                        m2[i] = q[2] * u.inv[2];
                        m3[i] = q[3] * u.inv[3];
                        lum[i] =
                            q[0] * u.lum[0] + q[1] * u.lum[1] + q[2] * u.lum[2] + q[3] * u.lum[3];
                    }
                } else if let Some(lanes) = &lane_maps {
                    // two phases share a channel (Bayer): each column takes its position's map
                    lanes[rpar].apply(&sc.sums, &mut sc.means, &mut sc.lum, tw8);
                }
                if use_contrast {
                    contrast_row(
                        &sc.buf[y * stride..],
                        stride,
                        s,
                        rad,
                        &sc.means,
                        inv_area,
                        &mut sc.contrast[..tw8],
                    );
                }
                // classes of the pixels the fast path can take
                let cpar = tile.c0 % 2;
                let (sat, lum) = (&sc.sat[..tw], &sc.lum[..tw]);
                let (contrast, class) = (&sc.contrast[..tw], &mut sc.class[..tw]);
                let kc = self.n_chroma;
                if kc > 1 {
                    self.chroma_row::<SIMD>(&sc.means, (rpar, cpar), tw, &mut sc.chroma);
                }
                let cs = &sc.chroma;
                let bands = self.n_bands;
                for i in 0..tw {
                    let pos = rpar * 2 + (cpar + i) % 2;
                    let band = if sat[i] {
                        None
                    } else {
                        self.level_lut.level(lum[i]).and_then(|level| {
                            if kc == 1 {
                                Some(level)
                            } else {
                                // near a chroma boundary: the reference path
                                let margin = CHROMA_MARGIN * cs.scale[i] + CHROMA_MARGIN_FLOOR;
                                (cs.s2[i] - cs.s1[i] >= margin)
                                    .then(|| level * kc + cs.best[i] as usize)
                            }
                        })
                    };
                    class[i] = match band {
                        None => NO_CLASS,
                        Some(band) => {
                            let group = (pos * bands + band) * n_sat;
                            // +∞ where the contrast does not decide the class
                            let t = thresholds.get(group).copied().unwrap_or(f32::NAN);
                            let cv = contrast[i];
                            if (cv - t).abs() >= CONTRAST_MARGIN {
                                (group * 2 + (cv > t) as usize) as u32
                            } else {
                                // near the threshold, or NaN
                                NO_CLASS
                            }
                        }
                    };
                }
            }
            // 5. apply: with the AVX-512 kernel step where the tile runs with it but its
            // classification could not take the table (chroma classes, many levels)
            #[cfg(target_arch = "x86_64")]
            if WIDE {
                let rows = &sc.buf[y * stride..];
                let (patch, feat) = (&mut sc.patch, &mut sc.feat);
                let work = WideRow {
                    rows,
                    stride,
                    tw,
                    r,
                    c0: tile.c0,
                };
                // SAFETY: `WIDE` tiles run in `tile_avx512`, where the CPU has the features
                let applied = unsafe {
                    self.apply_classes_wide::<P>(
                        set,
                        &work,
                        &sc.class,
                        &mut sc.offsets,
                        &mut sc.lin,
                        (patch, feat),
                        &mut st,
                    )
                };
                if applied {
                    let out_row = &mut band[y * row_len + offset..(y + 1) * row_len];
                    // SAFETY: `WIDE` tiles run in `tile_avx512`, where the CPU has the features
                    unsafe { sink.finish_row_wide(out_row, &sc.lin, tw) };
                    st.pixels += tw as u64;
                    continue;
                }
            }
            let out_row = &mut band[y * row_len + offset..(y + 1) * row_len];
            let rows = &sc.buf[y * stride..];
            let [l0, l1, l2] = &mut sc.lin;
            let (l0, l1, l2) = (&mut l0[..tw], &mut l1[..tw], &mut l2[..tw]);
            for i in 0..tw {
                let class = sc.class[i];
                let v = if class != NO_CLASS {
                    let class = class as usize;
                    st.texture += (class & 1) as u64;
                    let k = &set.rows[class * set.stride..(class + 1) * set.stride];
                    row_dot::<SIMD>(rows, stride, i, s, k)
                } else {
                    let c = tile.c0 + i;
                    let (patch, feat) = (&mut sc.patch, &mut sc.feat);
                    self.exact_pixel(set, rows, stride, i, (r, c), patch, feat, &mut st)
                };
                l0[i] = v[0];
                l1[i] = v[1];
                l2[i] = v[2];
            }
            sink.finish_row(out_row, &sc.lin, tw);
            st.pixels += tw as u64;
        }
        st
    }

    /// The AVX-512 kernel step over a tile row whose classes (`class`, [`NO_CLASS`]
    /// for the reference path) the portable code found: each pixel's kernels by its
    /// class's offset in the paired layout, then the reference path's pixels. Only
    /// from `WIDE` tiles. Returns `false`, having written nothing to the output, when
    /// the kernel step refuses its arguments. Out of line (one call per row), so
    /// the tiles the AVX-512 classification takes do not carry it.
    ///
    /// # Safety
    /// The CPU must have AVX-512 F, VL and DQ, AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[inline(never)]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn apply_classes_wide<const P: usize>(
        &self,
        set: &KernelSet,
        work: &WideRow<'_>,
        class: &[u32],
        offsets: &mut [u32],
        lin: &mut [Vec<f32>; 3],
        (patch, feat): (&mut Vec<f32>, &mut Vec<f32>),
        st: &mut RenderStats,
    ) -> bool {
        let tw = work.tw;
        let mut texture = 0u64;
        let padded = offsets.len().min(tw.div_ceil(16) * 16);
        for (i, o) in offsets[..padded].iter_mut().enumerate() {
            let c = class.get(i).copied().filter(|_| i < tw).unwrap_or(NO_CLASS);
            *o = if c == NO_CLASS {
                0
            } else {
                texture += u64::from(c & 1);
                // an offset past the kernels is refused by the kernel step
                u32::try_from(c as usize * set.pstride).unwrap_or(u32::MAX)
            };
        }
        let [l0, l1, l2] = lin;
        // SAFETY: the caller has the features; the kernel step checks the lengths and
        // offsets of what it touches
        let applied = unsafe {
            avx512::apply_kernels::<P>(
                work.rows,
                work.stride,
                offsets,
                tw,
                set.paired(),
                set.pstride,
                [&mut l0[..], &mut l1[..], &mut l2[..]],
            )
        };
        if !applied {
            return false;
        }
        st.texture += texture;
        for i in (0..tw).filter(|&i| class[i] == NO_CLASS) {
            let rc = (work.r, work.c0 + i);
            let v = self.exact_pixel(set, work.rows, work.stride, i, rc, patch, feat, st);
            l0[i] = v[0];
            l1[i] = v[1];
            l2[i] = v[2];
        }
        true
    }

    /// The reference path for the pixel at column `i` of a tile row (frame pixel
    /// `rc`): gather its patch from `rows`, classify it with the reference code
    /// and apply the table's layout of `set`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn exact_pixel(
        &self,
        set: &KernelSet,
        rows: &[f32],
        stride: usize,
        i: usize,
        (r, c): (usize, usize),
        patch: &mut [f32],
        feat: &mut [f32],
        st: &mut RenderStats,
    ) -> [f32; 4] {
        let s = self.geo.size;
        let nf = self.n_features;
        for dy in 0..s {
            let o = dy * stride + i;
            patch[dy * s..dy * s + s].copy_from_slice(&rows[o..o + s]);
        }
        let (class, sat, fell_back, texture) = self.classify_exact(patch, r, c);
        st.exact_path += 1;
        st.saturated += (sat != 0) as u64;
        st.fallback += fell_back as u64;
        st.texture += texture as u64;
        let pos = self.geo.position(r, c);
        self.geo.features(patch, pos, self.sat_cases[sat], feat);
        let k = &set.flat[class * 3 * nf..(class + 1) * 3 * nf];
        [
            dot(&k[..nf], feat),
            dot(&k[nf..2 * nf], feat),
            dot(&k[2 * nf..], feat),
            0.0,
        ]
    }

    /// The AVX-512 classification's view of the table for one tile: phase
    /// weights, level edges and the contrast thresholds per position and level.
    #[cfg(target_arch = "x86_64")]
    fn class_params(
        &self,
        thresholds: &[f32],
        use_contrast: bool,
        set: &KernelSet,
    ) -> Option<avx512::ClassParams> {
        let maps = self.phases.as_deref()?;
        let src = self.geo.level_edges();
        let kc = self.n_chroma.max(1);
        let n_levels = self.n_bands / kc;
        if n_levels > avx512::MAX_LEVELS || src.len() >= avx512::MAX_LEVELS {
            return None;
        }
        let mut edges = [f32::INFINITY; avx512::MAX_LEVELS];
        edges[..src.len()].copy_from_slice(src);
        let mut below = [f32::NEG_INFINITY; avx512::MAX_LEVELS];
        below[1..=src.len()].copy_from_slice(src);
        let n_sat = self.sat_cases.len();
        // NaN (never expected) sends the pixels to the reference path
        let threshold = |pos: usize, band: usize| {
            thresholds
                .get((pos * self.n_bands + band) * n_sat)
                .copied()
                .unwrap_or(f32::NAN)
        };
        let mut per_pos = [[f32::INFINITY; avx512::MAX_LEVELS]; 4];
        if kc == 1 {
            for (pos, t) in per_pos.iter_mut().enumerate() {
                for (level, v) in t.iter_mut().take(n_levels).enumerate() {
                    *v = threshold(pos, level);
                }
            }
        }
        let chroma = (kc > 1).then(|| {
            let coef = self.geo.chroma_coefficients();
            avx512::ChromaParams {
                coef: coef
                    .iter()
                    .map(|a| std::array::from_fn(|ch| a.get(ch).copied().unwrap_or(0.0)))
                    .collect(),
                scale: std::array::from_fn(|ch| self.chroma_scale.get(ch).copied().unwrap_or(0.0)),
                phase_channels: self.phase_channels,
                n_channels: self.geo.n_channels(),
                thresholds: (0..4 * self.n_bands)
                    .map(|i| threshold(i / self.n_bands, i % self.n_bands))
                    .collect(),
                margin: CHROMA_MARGIN,
                floor: CHROMA_MARGIN_FLOOR,
            }
        });
        let s = self.geo.size;
        // patch rows (columns) of the centre's parity, and of the other
        let same = (0..s).filter(|d| (d + s / 2).is_multiple_of(2)).count();
        let other = s - same;
        let count = [same * same, same * other, other * same, other * other].map(|n| n as f32);
        // one map per CFA position, each mean a mean of whole phases (a
        // uniform patch's mean is its value)
        let [m0, m1, m2, m3] = <&[PhaseMap; 4]>::try_from(maps).ok()?;
        let maps = [m0, m1, m2, m3];
        let whole = |t: &[f32; 4]| {
            (t.iter().zip(&count).map(|(w, n)| w * n).sum::<f32>() - 1.0).abs() <= 1e-6
        };
        if !maps.iter().all(|m| m.to_mean.iter().all(whole)) {
            return None;
        }
        let diagonal = maps
            .iter()
            .all(|m| (0..4).all(|p| (0..4).all(|q| p == q || m.to_mean[p][q] == 0.0)));
        Some(avx512::ClassParams {
            to_mean: maps.map(|m| m.to_mean),
            lum: maps.map(|m| m.lum),
            diagonal,
            count,
            inv_area: 1.0 / (s * s) as f32,
            edges,
            below,
            thresholds: per_pos,
            n_levels: n_levels as u32,
            n_chroma: kc as u32,
            chroma,
            n_sat: n_sat as u32,
            use_contrast,
            n_classes: u32::try_from(set.paired().len() / set.pstride).ok()?,
            kstride: u32::try_from(set.pstride).ok()?,
        })
    }
}

/// The largest value of a row of clamped (finite) volts, 16 lanes at a time.
#[inline(always)]
fn row_peak(row: &[f32]) -> f32 {
    let mut m = [0f32; 16];
    let chunks = row.chunks_exact(16);
    let rest = chunks.remainder();
    for c in chunks {
        for l in 0..16 {
            m[l] = if c[l] > m[l] { c[l] } else { m[l] };
        }
    }
    let tail = rest.iter().fold(0f32, |a, &v| if v > a { v } else { a });
    m.iter().fold(tail, |a, &v| if v > a { v } else { a })
}

/// Marks a pixel for the reference path in the per-row class array.
const NO_CLASS: u32 = u32::MAX;

/// Horizontal sums of one buffer row over the patch's even (`he`) and odd
/// (`ho`) column offsets from the centre, 16 columns at a time, in one pass.
#[inline(always)]
fn phase_sums_row<const P: usize>(row: &[f32], he: &mut [f32], ho: &mut [f32]) {
    const W: usize = 16;
    let rad = P / 2;
    for (c, (e16, o16)) in he
        .chunks_exact_mut(W)
        .zip(ho.chunks_exact_mut(W))
        .enumerate()
    {
        let x0 = c * W;
        let (mut e, mut o) = ([0f32; W], [0f32; W]);
        for d in 0..P {
            // a short row (never expected) sums zeros
            let v: &[f32; W] = row
                .get(x0 + d..x0 + d + W)
                .and_then(|r| r.try_into().ok())
                .unwrap_or(&[0.0; W]);
            let acc = if (d + rad).is_multiple_of(2) {
                &mut e
            } else {
                &mut o
            };
            for l in 0..W {
                acc[l] += v[l];
            }
        }
        e16.copy_from_slice(&e);
        o16.copy_from_slice(&o);
    }
}

/// `dst[i] += src[i]`.
#[inline(always)]
fn add_into(dst: &mut [f32], src: &[f32]) {
    for (o, &v) in dst.iter_mut().zip(src) {
        *o += v;
    }
}

/// Mean absolute deviation of each patch value from its phase's mean, for a
/// row of pixels; `rows` starts at the patch's top row, `means[p]` are the
/// per-pixel means of phase p. Accumulates 8 pixels at a time in registers.
#[inline(always)]
fn contrast_row(
    rows: &[f32],
    stride: usize,
    s: usize,
    rad: usize,
    means: &[Vec<f32>; 4],
    inv_area: f32,
    out: &mut [f32],
) {
    let n = out.len();
    // one bounds check for everything the loop below reads; NaN (never expected)
    // sends the pixels to the reference path
    if s == 0 || rows.len() < (s - 1) * stride + n + s - 1 || means.iter().any(|m| m.len() < n) {
        out.fill(f32::NAN);
        return;
    }
    for (ci, o) in out.chunks_exact_mut(LANES).enumerate() {
        let i0 = ci * LANES;
        let mut acc = [0f32; LANES];
        for dy in 0..s {
            let pr = (dy + rad) % 2;
            let row = &rows[dy * stride + i0..dy * stride + i0 + s - 1 + LANES];
            let ma: &[f32; LANES] = means[pr * 2 + rad % 2][i0..i0 + LANES]
                .try_into()
                .unwrap_or(&[0.0; LANES]);
            let mb: &[f32; LANES] = means[pr * 2 + (1 + rad) % 2][i0..i0 + LANES]
                .try_into()
                .unwrap_or(&[0.0; LANES]);
            // even and odd column offsets: one phase mean each
            for (start, m) in [(0, ma), (1, mb)] {
                for dx in (start..s).step_by(2) {
                    let v: &[f32; LANES] = row[dx..dx + LANES].try_into().unwrap_or(&[0.0; LANES]);
                    for l in 0..LANES {
                        acc[l] += (v[l] - m[l]).abs();
                    }
                }
            }
        }
        for l in 0..LANES {
            o[l] = acc[l] * inv_area;
        }
    }
}

/// Luminance → level without a search: a table over [0, swing] whose bins
/// lie wholly inside one level, farther than the margin from its edges;
/// other bins (and values outside the table) go to the reference path.
#[derive(Clone, Debug)]
struct LevelLut {
    scale: f32,
    bins: Vec<u16>,
}

impl LevelLut {
    const BINS: usize = 8192;
    const AMBIGUOUS: u16 = u16::MAX;

    fn new(geo: &PatchGeometry, swing: f32) -> Self {
        let width = swing / Self::BINS as f32;
        let edges = geo.level_edges();
        let bins = (0..Self::BINS)
            .map(|b| {
                let lo = b as f32 * width - LUMINANCE_MARGIN;
                let hi = (b + 1) as f32 * width + LUMINANCE_MARGIN;
                let (l0, l1) = (geo.level_of(lo), geo.level_of(hi));
                let clear = edges.iter().all(|&e| e < lo || e > hi);
                if l0 == l1 && clear && l0 < usize::from(Self::AMBIGUOUS) {
                    l0 as u16
                } else {
                    Self::AMBIGUOUS
                }
            })
            .collect();
        Self {
            scale: 1.0 / width,
            bins,
        }
    }

    #[inline(always)]
    fn level(&self, lum: f32) -> Option<usize> {
        // `as usize` saturates (negative and NaN give 0, which is then range-checked by value)
        let x = lum * self.scale;
        // NaN fails both comparisons
        if !(0.0..Self::BINS as f32).contains(&x) {
            return None;
        }
        // SAFETY: x is finite and in [0, BINS), so it fits a u32.
        let i = unsafe { x.to_int_unchecked::<u32>() } as usize;
        let l = *self.bins.get(i)?;
        (l != Self::AMBIGUOUS).then_some(l as usize)
    }
}

/// One tile row for the AVX-512 kernel step: the padded input rows under it,
/// their stride, its width and where it starts in the frame.
#[cfg(target_arch = "x86_64")]
struct WideRow<'a> {
    rows: &'a [f32],
    stride: usize,
    tw: usize,
    r: usize,
    c0: usize,
}

#[derive(Clone, Copy, Debug)]
struct Tile {
    r0: usize,
    c0: usize,
    rows: usize,
    cols: usize,
}

impl KernelSet {
    /// Both SIMD layouts of the classes without saturated channels (sat case 0,
    /// the only ones the fast path applies; the others are read from `flat`).
    fn new(flat: Vec<f32>, size: usize, n_sat: usize) -> Self {
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

/// Grow `v` to at least `n` values (never shrinks: tiles of different widths reuse it;
/// callers use the first `n`).
fn resize(v: &mut Vec<f32>, n: usize) {
    if v.len() < n {
        v.resize(n, 0.0);
    }
}

/// Copy the patch around frame pixel (r, c) with mirrored borders.
fn gather_frame(geo: &PatchGeometry, src: &Source<'_>, r: usize, c: usize, out: &mut [f32]) {
    let s = geo.size;
    let rad = geo.radius;
    if r >= rad && c >= rad && r + rad < src.height && c + rad < src.width {
        for (dy, row) in out.chunks_exact_mut(s).take(s).enumerate() {
            src.row_into(r + dy - rad, c - rad, row);
        }
        return;
    }
    let rad = rad as isize;
    for dy in 0..s {
        let rr = super::mirror(r as isize + dy as isize - rad, src.height);
        for dx in 0..s {
            let cc = super::mirror(c as isize + dx as isize - rad, src.width);
            out[dy * s + dx] = src.at(rr, cc);
        }
    }
}

fn check_region(
    region: Option<Region>,
    width: usize,
    height: usize,
) -> Result<Region, RenderError> {
    let reg = region.unwrap_or(Region {
        x: 0,
        y: 0,
        width,
        height,
    });
    let inside = reg.width > 0
        && reg.height > 0
        && reg.x.checked_add(reg.width).is_some_and(|e| e <= width)
        && reg.y.checked_add(reg.height).is_some_and(|e| e <= height);
    if !inside {
        return Err(RenderError::InvalidInput(format!(
            "region {},{} {}×{} is empty or not inside the {width}×{height} frame",
            reg.x, reg.y, reg.width, reg.height
        )));
    }
    Ok(reg)
}

/// For 2×2 CFAs: per centre position, how phase sums give channel means and luminance.
fn phase_maps(geo: &PatchGeometry) -> Option<Vec<PhaseMap>> {
    if geo.cfa.rows != 2 || geo.cfa.cols != 2 || geo.size > LANES {
        return None;
    }
    let s = geo.size;
    let rad = geo.radius;
    // pixels per phase: offsets −rad..=rad with the same (0) or other (1) parity
    let n_even = (0..s).filter(|d| (d + rad).is_multiple_of(2)).count();
    let count = |p: usize| -> usize { if p == 0 { n_even } else { s - n_even } };
    let n_ch = geo.n_channels();
    let mut maps = Vec::with_capacity(4);
    for pos in 0..4 {
        let (pr, pc) = (pos / 2, pos % 2);
        let chan = |p: usize| geo.cfa.channel_at(pr + p / 2, pc + p % 2);
        let mut ch_count = vec![0usize; n_ch];
        for p in 0..4 {
            ch_count[chan(p)] += count(p / 2) * count(p % 2);
        }
        if ch_count.contains(&0) {
            return None;
        }
        let mut to_mean = [[0f32; 4]; 4];
        let mut lum = [0f32; 4];
        for p in 0..4 {
            for q in 0..4 {
                if chan(p) == chan(q) {
                    to_mean[p][q] = 1.0 / ch_count[chan(p)] as f32;
                }
            }
            lum[p] = 1.0 / (n_ch * ch_count[chan(p)]) as f32;
        }
        maps.push(PhaseMap { to_mean, lum });
    }
    Some(maps)
}

/// Per lane of a chunk of [`CHUNK`] columns, the phase map of the lane's CFA
/// position: a row's maps laid out so that the means of a whole chunk are
/// element-wise products, which vectorise (a map chosen per pixel does not).
struct LaneMaps {
    to_mean: [[[f32; CHUNK]; 4]; 4],
    lum: [[f32; CHUNK]; 4],
}

/// Columns per [`LaneMaps`] chunk (the scratch rows are whole chunks long).
const CHUNK: usize = 2 * LANES;

impl LaneMaps {
    /// The maps of row parity `rpar` for a chunk whose first column has parity `cpar`.
    fn of_row(maps: &[PhaseMap], rpar: usize, cpar: usize) -> Self {
        let mut out = Self {
            to_mean: [[[0.0; CHUNK]; 4]; 4],
            lum: [[0.0; CHUNK]; 4],
        };
        for lane in 0..CHUNK {
            let Some(pm) = maps.get((rpar * 2 + (cpar + lane) % 2) % maps.len().max(1)) else {
                continue;
            };
            for p in 0..4 {
                out.lum[p][lane] = pm.lum[p];
                for q in 0..4 {
                    out.to_mean[p][q][lane] = pm.to_mean[p][q];
                }
            }
        }
        out
    }

    /// Means and luminance of the first `n` columns (a multiple of [`CHUNK`])
    /// from their phase sums, in the order of operations of a pixel at a time.
    #[inline(always)]
    fn apply(&self, sums: &[Vec<f32>; 4], means: &mut [Vec<f32>; 4], lum: &mut [f32], n: usize) {
        for base in (0..n).step_by(CHUNK) {
            let q: [[f32; CHUNK]; 4] = std::array::from_fn(|k| {
                sums[k]
                    .get(base..base + CHUNK)
                    .and_then(|v| <[f32; CHUNK]>::try_from(v).ok())
                    .unwrap_or([0.0; CHUNK])
            });
            let mut l_sum = [0f32; CHUNK];
            for k in 0..4 {
                let t = &self.to_mean[k];
                let mut m = [0f32; CHUNK];
                for l in 0..CHUNK {
                    l_sum[l] += self.lum[k][l] * q[k][l];
                    m[l] = t[0][l] * q[0][l]
                        + t[1][l] * q[1][l]
                        + t[2][l] * q[2][l]
                        + t[3][l] * q[3][l];
                }
                if let Some(out) = means[k].get_mut(base..base + CHUNK) {
                    out.copy_from_slice(&m);
                }
            }
            if let Some(out) = lum.get_mut(base..base + CHUNK) {
                out.copy_from_slice(&l_sum);
            }
        }
    }
}

/// The position-free form of the phase maps, when there is one.
fn uniform_phases(maps: &[PhaseMap]) -> Option<UniformPhases> {
    let first = maps.first()?;
    let diagonal = (0..4).all(|p| (0..4).all(|q| p == q || first.to_mean[p][q] == 0.0));
    if !diagonal || maps.iter().any(|m| m != first) {
        return None;
    }
    Some(UniformPhases {
        inv: [0, 1, 2, 3].map(|p| first.to_mean[p][p]),
        lum: first.lum,
    })
}

/// The instruction set a render runs with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Isa {
    Portable,
    Avx2,
    Avx512,
}

fn avx512_available() -> bool {
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

fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The 3 outputs (+ a spare lane) of one pixel: its patch rows (8 values read
/// from the tile buffer, weights beyond the patch are zero) against the class's row kernels.
#[inline(always)]
fn row_dot<const SIMD: bool>(
    buf: &[f32],
    stride: usize,
    i: usize,
    s: usize,
    k: &[f32],
) -> [f32; 4] {
    #[cfg(target_arch = "x86_64")]
    if SIMD {
        // SAFETY: SIMD is only true inside `tile_avx2`, which runs when the CPU has
        // AVX2 + FMA; every load is bounds-checked by the slicing below.
        return unsafe { row_dot_avx2(buf, stride, i, s, k) };
    }
    let mut acc = [0f32; 4];
    let bias = &k[3 * s * LANES..3 * s * LANES + 3];
    for (o, a) in acc.iter_mut().take(3).enumerate() {
        let mut lanes = [0f32; LANES];
        for dy in 0..s {
            let p = &buf[(dy * stride + i)..(dy * stride + i + LANES)];
            let w = &k[(o * s + dy) * LANES..(o * s + dy + 1) * LANES];
            for l in 0..LANES {
                lanes[l] += p[l] * w[l];
            }
        }
        *a = lanes.iter().sum::<f32>() + bias[o];
    }
    acc
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
/// # Safety
/// The CPU must have AVX2 and FMA (callers run inside `tile_avx2`).
unsafe fn row_dot_avx2(buf: &[f32], stride: usize, i: usize, s: usize, k: &[f32]) -> [f32; 4] {
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
