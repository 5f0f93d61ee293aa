//! The fast renderer (docs/design.md §9). Same classes and kernels as
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
//! - the 3×3 output matrix (illuminant correction and XYZ → linear sRGB) is
//!   fused into the kernels once, when the renderer is prepared, and a frame's
//!   white level is a gain in the sRGB lookup's index, so sRGB leaves through
//!   a lookup table without an XYZ image and no frame re-fuses the kernels;
//! - work a tile does not need is skipped: saturation handling where no value
//!   reaches the threshold, the contrast measure where no level's flat and
//!   texture kernels differ, and everything outside the requested region.
//!
//! Pixels with a saturated value in their patch, pixels whose luminance or
//! contrast lies within a rounding margin of a class boundary, and CFAs other
//! than 2×2 take the reference classification, so both renderers put every
//! pixel in the same class; outputs then differ by float rounding only.

use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use rayon::prelude::*;

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
mod dispatch;
mod frames;
mod kernels;
mod phases;
mod scratch;
mod sink;
mod source;
mod stages;
mod tile;
#[cfg(target_arch = "x86_64")]
mod wide;

pub use frames::Frame;
pub use source::DnScale;

use dispatch::{avx512_available, simd_available};
use kernels::KernelSet;
use phases::{PhaseMap, UniformPhases, phase_maps, uniform_phases};
use sink::{Srgb8Sink, XyzSink};
use source::{Source, check_region, gather_frame};
use stages::LevelLut;

// Everything the fast renderer takes from outside `fast`: its files import these through `super::`.
use super::error::RenderError;
use super::output::{WhiteLevel, white_from_samples, white_sample_points};
use super::reference::{RenderStats, dot, fuse_matrix};
use crate::buffers::zeroed;
use crate::colour::{SrgbLut, XYZ_TO_LINEAR_SRGB};
use crate::l3::classify::{PatchGeometry, mirror, sat_case_index};
use crate::l3::table::L3Table;

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

/// Marks a pixel for the reference path in the per-row class array.
const NO_CLASS: u32 = u32::MAX;

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
    /// The kernels fused with XYZ → linear sRGB (white Y = 1), for every 8-bit
    /// render: a frame's white level is applied by the sink. Built by the first
    /// 8-bit render, so renderers that only give XYZ never pay for them.
    srgb: OnceLock<KernelSet>,
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
            srgb: OnceLock::new(),
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

    /// The voltage swing the renderer's mosaics are scaled to.
    pub fn voltage_swing(&self) -> f32 {
        self.swing
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
        let mut out = zeroed::<f32>(reg.width * reg.height * 3);
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
        let (src, clamped) = self.source(mosaic, width, height)?;
        let (wy, stats) = self.srgb8_into(&src, clamped, reg, white, &mut out, cancel)?;
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
        self.srgb8_into(&src, clamped, reg, white, out, &AtomicBool::new(false))
    }

    /// Render the checked region `reg` of the checked frame `src` (`clamped`
    /// values outside the swing) into `out`, which holds 3 bytes per pixel of
    /// the region. Returns the white Y used.
    fn srgb8_into(
        &self,
        src: &Source<'_>,
        clamped: u64,
        reg: Region,
        white: WhiteLevel,
        out: &mut [u8],
        cancel: &AtomicBool,
    ) -> Result<(f64, RenderStats), RenderError> {
        let wy = self.white_of(src, white);
        let sink = Srgb8Sink::new((1.0 / wy) as f32);
        let mut stats = self.run(src, reg, self.srgb_kernels(), out, &sink, cancel)?;
        stats.clamped = clamped;
        Ok((wy, stats))
    }

    /// The sRGB-fused kernels (the `srgb` field), built on first use.
    fn srgb_kernels(&self) -> &KernelSet {
        self.srgb.get_or_init(|| {
            let fused = fuse_matrix(&self.xyz.flat, &XYZ_TO_LINEAR_SRGB, self.n_features);
            KernelSet::new(fused, self.geo.size, self.sat_cases.len())
        })
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
}
