//! A luma/chroma denoiser for demosaicked camera channels (volts), with the strength taken
//! from the sensor's noise model at the frame's exposure ([`NoiseProfile`]).
//!
//! - **Luma** `L` (the mean of the channels) gets a self-guided filter (He, Sun and Tang,
//!   *Guided image filtering*, 2010/2013) of radius `luma_radius` with
//!   `ε = luma_strength · σ²_L(local mean)`: windows whose variance is at the noise's level are
//!   smoothed, windows with edges or texture well above it are kept.
//! - **Chroma** `C_k = ch_k − β_k·L` (β_k the channel's share of the frame, so a grey has no
//!   chroma) gets a self-guided filter of the larger `chroma_radius` with
//!   `ε = chroma_strength · σ²(β_k·L')`, the channel's noise at the denoised luma's level:
//!   chroma steps well above the noise are kept (isoluminant ones too), chroma noise is
//!   flattened. Each channel is rebuilt as `β_k·L' + C_k'`. (Guided by the luma instead,
//!   the chroma bled across the chart's isoluminant patch edges: S-CIELAB 2.86 against 2.77
//!   undenoised on the D5100 at full exposure.)
//!
//! The noise variance of a pixel at `v` volts is `floor + shot·u + prnu²·u²` with
//! `u = v − offset` ([`crate::camera::Camera::analytic_noise`]'s terms); at a tenth of the
//! exposure the signal is ten times lower, its relative noise higher, so the filter works
//! relatively harder with no change of parameters.
//!
//! **Structure.** The frame is cut into strips of rows (one rayon task each, no nested
//! parallelism) and each strip into tiles of columns; on a tile the luma is made once, its
//! filter run, then the `nc` chroma filters run side by side (each source row read once for
//! all channels) and the channels rebuilt. Each filter reads its tile widened by twice its
//! radius, so the result is the whole frame's to float rounding (the tests compare it with
//! the filters' definition). The guided filter itself, streamed down rows with fused box
//! filters, is `guided.rs`'s, hand-written because no maintained crate offers it on
//! f32 planes with a per-window ε.

use std::ops::Range;

use rayon::prelude::*;

use super::BaselineError;
use super::guided::{SelfGuided, run_side_by_side};
use crate::camera::{Camera, SensorDesign};

/// The variance of a pixel's noise as a function of its signal, from the sensor's noise
/// model at one exposure: `σ²(v) = floor + shot·u + prnu²·u²`, `u = max(v − offset, 0)`.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseProfile {
    /// Variance independent of the signal (read noise² + DSNU² + ADC quantisation), V².
    pub floor_v2: f64,
    /// Shot noise slope: conversion gain × analog gain, V (variance per volt of signal).
    pub shot_v: f64,
    /// PRNU as a fraction.
    pub prnu: f64,
    /// The analog offset, V.
    pub offset_v: f64,
    /// The mean dark signal over the exposure, V (its shot noise is in `shot_v · u`).
    pub dark_v: f64,
}

impl NoiseProfile {
    /// The profile of `camera` at an exposure of `exposure_s` seconds (dark current; a
    /// non-finite or negative time counts as 0).
    pub fn new(camera: &Camera, exposure_s: f64) -> Self {
        Self::from_design(camera.design(), exposure_s)
    }

    /// [`Self::new`] from a sensor design.
    pub fn from_design(d: &SensorDesign, exposure_s: f64) -> Self {
        let t = if exposure_s.is_finite() && exposure_s > 0.0 {
            exposure_s
        } else {
            0.0
        };
        let lsb2 = d
            .adc_bits
            .map(|b| (d.voltage_swing_v / ((1u64 << b.min(62)) - 1) as f64).powi(2) / 12.0)
            .unwrap_or(0.0);
        Self {
            floor_v2: d.read_noise_v().powi(2) + d.dsnu_v().powi(2) + lsb2,
            shot_v: d.conversion_gain_v() * d.analog_gain,
            prnu: d.prnu_fraction(),
            offset_v: d.offset_v,
            dark_v: d.dark_voltage_v_per_s * d.analog_gain * t,
        }
    }

    /// Noise variance (V²) of a pixel whose mean is `v` volts.
    #[inline]
    pub fn variance(&self, v: f64) -> f64 {
        let u = (v - self.offset_v).max(0.0);
        let photo = (u - self.dark_v).max(0.0);
        self.floor_v2 + self.shot_v * u + (self.prnu * photo).powi(2)
    }

    /// Noise σ (V) of a pixel whose mean is `v` volts.
    pub fn sigma(&self, v: f64) -> f64 {
        self.variance(v).sqrt()
    }
}

/// The denoiser's parameters (module doc). Radii in pixels; strengths multiply the noise
/// variance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DenoiseParams {
    pub luma_radius: usize,
    pub luma_strength: f32,
    pub chroma_radius: usize,
    pub chroma_strength: f32,
}

impl Default for DenoiseParams {
    /// The parameters that measured best on the simulated charts (docs/accuracy.md).
    fn default() -> Self {
        Self {
            luma_radius: 2,
            luma_strength: 2.0,
            chroma_radius: 4,
            chroma_strength: 4.0,
        }
    }
}

/// Denoise an interleaved `width × height × nc` image of camera channels in volts (see the
/// module doc); same layout out.
pub fn denoise(
    channels: &[f32],
    width: usize,
    height: usize,
    nc: usize,
    profile: &NoiseProfile,
    params: &DenoiseParams,
) -> Result<Vec<f32>, BaselineError> {
    let n = width * height;
    if nc == 0 || n == 0 || channels.len() != n * nc {
        return Err(BaselineError::InvalidInput(format!(
            "{} values for a {width}×{height} image of {nc} channels",
            channels.len()
        )));
    }
    let frame = Frame {
        channels,
        width,
        height,
        nc,
        beta: channel_shares(channels, nc),
        profile,
        params,
    };
    let row = width * nc;
    let mut out = vec![0f32; n * nc];
    out.par_chunks_mut(STRIP * row).enumerate().for_each_init(
        || Scratch::new(height, nc, params),
        |scratch, (strip, o)| {
            let y0 = strip * STRIP;
            frame.strip(scratch, y0..y0 + o.len() / row, o);
        },
    );
    Ok(out)
}

/// Rows per parallel task: each task's filters start from its first rows' windows (a few rows
/// of extra work, see [`Frame::tile`]), so strips are tall enough to make that small and
/// short enough to share out among the threads.
const STRIP: usize = 128;
/// Columns per tile within a strip: the tile's rows stay in cache from one filter to the
/// next. The filters reach beyond the tile's sides as they do beyond the strip's ends.
const TILE: usize = 512;

/// A frame being denoised: its channels, their shares of the luma, the noise model.
struct Frame<'a> {
    channels: &'a [f32],
    width: usize,
    height: usize,
    nc: usize,
    beta: Vec<f32>,
    profile: &'a NoiseProfile,
    params: &'a DenoiseParams,
}

/// A task's filters and row buffers, reused from tile to tile.
struct Scratch {
    luma: SelfGuided,
    /// One per channel.
    chroma: Vec<SelfGuided>,
    /// The tile's luma and denoised luma.
    luma_in: Rows,
    luma_d: Rows,
    /// The luma noise's variance along a row.
    var: Vec<f64>,
}

/// A block of a plane: its rows from `start`, `width` values each.
#[derive(Default)]
struct Rows {
    start: usize,
    width: usize,
    v: Vec<f32>,
}

impl Rows {
    fn set(&mut self, rows: &Range<usize>, width: usize) {
        self.start = rows.start;
        self.width = width;
        self.v.resize(rows.len() * width, 0.0);
    }

    fn row(&self, y: usize) -> &[f32] {
        let at = (y - self.start) * self.width;
        &self.v[at..at + self.width]
    }

    fn row_mut(&mut self, y: usize) -> &mut [f32] {
        let at = (y - self.start) * self.width;
        &mut self.v[at..at + self.width]
    }
}

impl Scratch {
    fn new(height: usize, nc: usize, params: &DenoiseParams) -> Self {
        Self {
            luma: SelfGuided::new(height, params.luma_radius),
            chroma: (0..nc)
                .map(|_| SelfGuided::new(height, params.chroma_radius))
                .collect(),
            luma_in: Rows::default(),
            luma_d: Rows::default(),
            var: Vec::new(),
        }
    }
}

/// `r` widened by `by` on both sides, within `0..end`.
fn widen(r: &Range<usize>, by: usize, end: usize) -> Range<usize> {
    r.start.saturating_sub(by)..r.end.saturating_add(by).min(end)
}

impl Frame<'_> {
    /// The pixels of row `t` at columns `xs`, interleaved (`nc` channels).
    fn pixels(&self, t: usize, xs: &Range<usize>, nc: usize) -> &[f32] {
        let at = (t * self.width) * nc;
        &self.channels[at + xs.start * nc..at + xs.end * nc]
    }

    /// `e = strength · σ²_L(m)`, with σ²_L(m) the variance of L's noise at luma `m`: the
    /// channels' variances at β_k·m over nc² (summed in `var`).
    fn luma_eps(&self, m: &[f64], var: &mut Vec<f64>, e: &mut [f32]) {
        var.clear();
        var.resize(m.len(), 0.0);
        for &b in &self.beta {
            for (v, &m) in var.iter_mut().zip(m) {
                *v += self.profile.variance(b as f64 * m);
            }
        }
        let k = 1.0 / (self.nc * self.nc) as f64;
        for (e, &v) in e.iter_mut().zip(var.iter()) {
            *e = self.params.luma_strength * (v * k) as f32;
        }
    }

    /// Denoise the rows `ys` into `out` (their interleaved pixels), tile by tile; with the
    /// common channel counts a constant, so that the (de)interleaving loops vectorise.
    fn strip(&self, scratch: &mut Scratch, ys: Range<usize>, out: &mut [f32]) {
        for x0 in (0..self.width).step_by(TILE) {
            let xs = x0..(x0 + TILE).min(self.width);
            match self.nc {
                3 => self.tile::<3>(scratch, &ys, xs, out),
                4 => self.tile::<4>(scratch, &ys, xs, out),
                _ => self.tile::<0>(scratch, &ys, xs, out),
            }
        }
    }

    /// Denoise the block `ys × xs` into `out` (the strip `ys`): the luma filter on the block
    /// the chroma filters' ε reads (widened by the chroma radius), then each channel's
    /// chroma filter, rebuilt on the denoised luma. Each filter works on its block widened
    /// by twice its radius, so that the block's result is the whole frame's.
    fn tile<const NC: usize>(
        &self,
        scratch: &mut Scratch,
        ys: &Range<usize>,
        xs: Range<usize>,
        out: &mut [f32],
    ) {
        let nc = if NC == 0 { self.nc } else { NC };
        let (w, h, prm) = (self.width, self.height, self.params);
        let (lr, cr) = (prm.luma_radius, prm.chroma_radius);
        let Scratch {
            luma,
            chroma,
            luma_in,
            luma_d,
            var,
        } = scratch;
        // columns: the chroma filters' block, the luma's (which holds it)
        let cxs = widen(&xs, 2 * cr, w);
        let lxs = widen(&cxs, 2 * lr, w);
        let (cw, lw) = (cxs.len(), lxs.len());
        // rows: the denoised luma's, and the luma both filters read
        let ld_rows = widen(ys, cr, h);
        let (a, b) = (widen(&ld_rows, 2 * lr, h), widen(ys, 2 * cr, h));
        let in_rows = a.start.min(b.start)..a.end.max(b.end);
        luma_in.set(&in_rows, lw);
        for t in in_rows {
            let px = self.pixels(t, &lxs, nc).chunks_exact(nc);
            for (o, px) in luma_in.row_mut(t).iter_mut().zip(px) {
                *o = px.iter().sum::<f32>() / nc as f32;
            }
        }
        luma_d.set(&ld_rows, lw);
        run_side_by_side(
            std::slice::from_mut(luma),
            lw,
            ld_rows,
            |_, t, row| row.copy_from_slice(luma_in.row(t)),
            |_, _, m, e| self.luma_eps(m, var, e),
            |_, y, row| luma_d.row_mut(y).copy_from_slice(row),
        );
        let (luma_in, luma_d, beta) = (&*luma_in, &*luma_d, &self.beta);
        // the chroma block's and the tile's columns in the luma block, the tile's in the
        // chroma block
        let (c_in_l, x_in_l, x_in_c) = (
            cxs.start - lxs.start..cxs.end - lxs.start,
            xs.start - lxs.start..xs.end - lxs.start,
            xs.start - cxs.start..xs.end - cxs.start,
        );
        let row_len = w * nc;
        // self-guided: chroma edges above the channel's noise are kept (isoluminant edges
        // too, which a luma guide cannot see), the rest is flattened
        run_side_by_side(
            chroma,
            cw,
            ys.clone(),
            |k, t, row| {
                let (px, b) = (self.pixels(t, &cxs, nc).chunks_exact(nc), beta[k]);
                let l = &luma_in.row(t)[c_in_l.clone()];
                for ((o, px), &l) in row.iter_mut().zip(px).zip(l) {
                    *o = px[k] - b * l;
                }
            },
            |k, s, _, e| {
                let b = beta[k];
                for (e, &l) in e.iter_mut().zip(&luma_d.row(s)[c_in_l.clone()]) {
                    *e = prm.chroma_strength * self.profile.variance((b * l) as f64) as f32;
                }
            },
            |k, y, c| {
                let at = (y - ys.start) * row_len;
                let o = &mut out[at + xs.start * nc..at + xs.end * nc];
                let (l, b) = (&luma_d.row(y)[x_in_l.clone()], beta[k]);
                for ((px, &c), &l) in o.chunks_exact_mut(nc).zip(&c[x_in_c.clone()]).zip(l) {
                    px[k] = b * l + c;
                }
            },
        );
    }
}

/// Each channel's share β_k of the luma (the mean of the channels) over the whole frame.
fn channel_shares(channels: &[f32], nc: usize) -> Vec<f32> {
    let sums = channels
        .par_chunks(nc * 4096)
        .map(|c| {
            let mut s = vec![0f64; nc];
            for px in c.chunks_exact(nc) {
                for (a, &v) in s.iter_mut().zip(px) {
                    *a += v as f64;
                }
            }
            s
        })
        .reduce(
            || vec![0f64; nc],
            |a, b| a.iter().zip(&b).map(|(x, y)| x + y).collect(),
        );
    let total_l = sums.iter().sum::<f64>() / nc as f64;
    sums.iter()
        .map(|&s| {
            if total_l > 0.0 && s.is_finite() {
                (s / total_l) as f32
            } else {
                1.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::guided::tests::reference;
    use super::*;

    /// The module doc's denoiser from the guided filter's definition, in f64, on the whole
    /// frame at once.
    fn reference_denoise(v: &[f32], w: usize, h: usize, nc: usize, p: &NoiseProfile) -> Vec<f64> {
        let prm = DenoiseParams::default();
        let beta = channel_shares(v, nc);
        let luma: Vec<f32> = v
            .chunks_exact(nc)
            .map(|px| px.iter().sum::<f32>() / nc as f32)
            .collect();
        let luma_var = |m: f64| -> f64 {
            let s: f64 = beta.iter().map(|&b| p.variance(b as f64 * m)).sum();
            s / (nc * nc) as f64
        };
        let ld = reference(&luma, w, h, prm.luma_radius, |_, m| {
            prm.luma_strength as f64 * luma_var(m)
        });
        let mut out = vec![0f64; v.len()];
        for (k, &b) in beta.iter().enumerate() {
            let chroma: Vec<f32> = v
                .chunks_exact(nc)
                .zip(&luma)
                .map(|(px, &l)| px[k] - b * l)
                .collect();
            let cd = reference(&chroma, w, h, prm.chroma_radius, |i, _| {
                prm.chroma_strength as f64 * p.variance(b as f64 * ld[i])
            });
            for ((px, &c), &l) in out.chunks_exact_mut(nc).zip(&cd).zip(&ld) {
                px[k] = b as f64 * l + c;
            }
        }
        out
    }

    #[test]
    fn strips_give_the_definitions_result_on_the_whole_frame() {
        let p = NoiseProfile::from_design(&SensorDesign::paper_default(), 0.01);
        for (w, h, nc) in [(37, 150, 3), (23, 131, 4), (5, 3, 4), (1, 1, 3), (2, 70, 1)] {
            let v: Vec<f32> = (0..w * h * nc)
                .map(|i| {
                    let step = if (i / nc) % w > w / 2 { 0.3 } else { 0.0 };
                    0.2 + 0.1 * ((i * 7919 % 97) as f32 / 97.0) + step + 0.02 * (i % nc) as f32
                })
                .collect();
            let got = denoise(&v, w, h, nc, &p, &DenoiseParams::default()).unwrap();
            let want = reference_denoise(&v, w, h, nc, &p);
            for (i, (&g, &t)) in got.iter().zip(&want).enumerate() {
                let err = (g as f64 - t).abs() / t.abs();
                assert!(err < 1e-5, "{w}×{h}×{nc} at {i}: {g} vs {t}");
            }
            if w * h > 1 {
                assert!(got.iter().zip(&v).any(|(a, b)| (a - b).abs() > 1e-3));
            }
        }
    }
}
