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
//! relatively harder with no change of parameters. The guided filter is written here (box
//! filters with running sums, O(1) per pixel whatever the radius) because no maintained crate
//! offers it on f32 planes with a per-window ε; it is a few dozen lines.

use std::ops::Range;

use rayon::prelude::*;

use super::BaselineError;
use super::guided::SelfGuided;
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
    out.par_chunks_mut(STRIP * row)
        .enumerate()
        .for_each_init(
            || Scratch::new(width, height, params),
            |scratch, (strip, o)| {
                let y0 = strip * STRIP;
                frame.strip(scratch, y0..y0 + o.len() / row, o);
            },
        );
    Ok(out)
}

/// Rows per parallel task: the strip's filters start from the strip's first rows' windows (a
/// few rows of extra work, see [`Frame::strip`]), so strips are tall enough to make that small
/// and short enough to share out among the threads.
const STRIP: usize = 64;

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

/// A task's filters and its strip's denoised luma, reused from strip to strip.
struct Scratch {
    luma: SelfGuided,
    chroma: SelfGuided,
    luma_d: Vec<f32>,
}

impl Scratch {
    fn new(width: usize, height: usize, params: &DenoiseParams) -> Self {
        Self {
            luma: SelfGuided::new(width, height, params.luma_radius),
            chroma: SelfGuided::new(width, height, params.chroma_radius),
            luma_d: Vec::new(),
        }
    }
}

impl Frame<'_> {
    /// The pixels of row `t`, interleaved.
    fn row(&self, t: usize) -> &[f32] {
        let n = self.width * self.nc;
        &self.channels[t * n..(t + 1) * n]
    }

    /// The luma `L` (the mean of a pixel's channels) of row `t`.
    fn luma(&self, t: usize, out: &mut [f32]) {
        let nc = self.nc;
        for (o, px) in out.iter_mut().zip(self.row(t).chunks_exact(nc)) {
            *o = px.iter().sum::<f32>() / nc as f32;
        }
    }

    /// Channel `k`'s chroma `C_k = ch_k − β_k·L` of row `t`.
    fn chroma(&self, k: usize, t: usize, out: &mut [f32]) {
        let (nc, b) = (self.nc, self.beta[k]);
        for (o, px) in out.iter_mut().zip(self.row(t).chunks_exact(nc)) {
            *o = px[k] - b * (px.iter().sum::<f32>() / nc as f32);
        }
    }

    /// The variance of L's noise at luma `m`: the channels' variances at β_k·m over nc².
    fn luma_var(&self, m: f64) -> f32 {
        let v: f64 = self
            .beta
            .iter()
            .map(|&b| self.profile.variance(b as f64 * m))
            .sum();
        (v / (self.nc * self.nc) as f64) as f32
    }

    /// Denoise the rows `ys` into `out` (their interleaved pixels): the luma filter on the
    /// rows the chroma filters' ε reads (`ys` widened by the chroma radius), then each
    /// channel's chroma filter, rebuilt on the denoised luma.
    fn strip(&self, scratch: &mut Scratch, ys: Range<usize>, out: &mut [f32]) {
        let (w, nc, prm) = (self.width, self.nc, self.params);
        let Scratch {
            luma,
            chroma,
            luma_d,
        } = scratch;
        let ld_lo = ys.start.saturating_sub(prm.chroma_radius);
        let ld_hi = (ys.end + prm.chroma_radius).min(self.height);
        luma_d.resize((ld_hi - ld_lo) * w, 0.0);
        luma.run(
            ld_lo..ld_hi,
            |t, row| self.luma(t, row),
            |_, m, e| {
                for (e, &m) in e.iter_mut().zip(m) {
                    *e = prm.luma_strength * self.luma_var(m);
                }
            },
            |y, row| luma_d[(y - ld_lo) * w..(y - ld_lo + 1) * w].copy_from_slice(row),
        );
        let ld = |y: usize| &luma_d[(y - ld_lo) * w..(y - ld_lo + 1) * w];
        for (k, &b) in self.beta.iter().enumerate() {
            // self-guided: chroma edges above the channel's noise are kept (isoluminant
            // edges too, which a luma guide cannot see), the rest is flattened
            chroma.run(
                ys.clone(),
                |t, row| self.chroma(k, t, row),
                |s, _, e| {
                    for (e, &l) in e.iter_mut().zip(ld(s)) {
                        *e = prm.chroma_strength * self.profile.variance((b * l) as f64) as f32;
                    }
                },
                |y, c| {
                    let o = &mut out[(y - ys.start) * w * nc..(y - ys.start + 1) * w * nc];
                    for ((px, &c), &l) in o.chunks_exact_mut(nc).zip(c).zip(ld(y)) {
                        px[k] = b * l + c;
                    }
                },
            );
        }
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
