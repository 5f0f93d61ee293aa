//! A luma/chroma denoiser for demosaicked camera channels (volts), with the strength taken
//! from the sensor's noise model at the frame's exposure ([`NoiseProfile`]).
//!
//! - **Luma** `L` (the mean of the channels) gets a self-guided filter (He, Sun and Tang,
//!   *Guided image filtering*, 2010/2013) of radius `luma_radius` with
//!   `ε = luma_strength · σ²_L(local mean)`: windows whose variance is at the noise's level are
//!   smoothed, windows with edges or texture well above it are kept.
//! - **Chroma** `C_k = ch_k − β_k·L` (β_k the channel's share of the frame, so a grey has no
//!   chroma) gets a guided filter of the larger `chroma_radius`, guided by the denoised luma,
//!   with `ε = chroma_strength · σ²_L`: chroma is flattened within luma-flat regions and
//!   follows luma's edges. Each channel is rebuilt as `β_k·L' + C_k'`.
//!
//! The noise variance of a pixel at `v` volts is `floor + shot·u + prnu²·u²` with
//! `u = v − offset` ([`crate::camera::Camera::analytic_noise`]'s terms); at a tenth of the
//! exposure the signal is ten times lower, its relative noise higher, so the filter works
//! relatively harder with no change of parameters. The guided filter is written here (box
//! filters with running sums, O(1) per pixel whatever the radius) because no maintained crate
//! offers it on f32 planes with a per-window ε; it is a few dozen lines.

use rayon::prelude::*;

use super::BaselineError;
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
            luma_strength: 1.0,
            chroma_radius: 6,
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
    let planes = Planes { width, height };
    let luma: Vec<f32> = channels
        .par_chunks(nc)
        .map(|px| px.iter().sum::<f32>() / nc as f32)
        .collect();
    let total_l: f64 = luma.par_iter().map(|&v| v as f64).sum();
    let beta: Vec<f32> = (0..nc)
        .map(|k| {
            let s: f64 = channels
                .par_iter()
                .skip(k)
                .step_by(nc)
                .map(|&v| v as f64)
                .sum();
            if total_l > 0.0 && s.is_finite() {
                (s / total_l) as f32
            } else {
                1.0
            }
        })
        .collect();
    // the variance of L's noise at luma m: the channels' variances at β_k·m over nc²
    let luma_var = |m: f32| -> f32 {
        let m = m as f64;
        let v: f64 = beta.iter().map(|&b| profile.variance(b as f64 * m)).sum();
        (v / (nc * nc) as f64) as f32
    };
    let luma_d = planes.guided(
        &luma,
        &luma,
        params.luma_radius,
        |m| params.luma_strength * luma_var(m),
        None,
    );
    let guide = planes.guide_stats(&luma_d, params.chroma_radius);
    let mut out = vec![0f32; n * nc];
    for (k, &b) in beta.iter().enumerate() {
        let chroma: Vec<f32> = channels
            .par_iter()
            .skip(k)
            .step_by(nc)
            .zip(luma.par_iter())
            .map(|(&c, &l)| c - b * l)
            .collect();
        let chroma_d = planes.guided(
            &luma_d,
            &chroma,
            params.chroma_radius,
            |m| params.chroma_strength * luma_var(m),
            Some(&guide),
        );
        out.par_chunks_mut(nc)
            .zip(chroma_d.par_iter().zip(luma_d.par_iter()))
            .for_each(|(px, (&c, &l))| px[k] = b * l + c);
    }
    Ok(out)
}

/// A guide's local means and variances at one radius.
struct GuideStats {
    mean: Vec<f32>,
    var: Vec<f32>,
}

/// Box filters and the guided filter on `width × height` planes.
struct Planes {
    width: usize,
    height: usize,
}

impl Planes {
    /// The guide's window means and variances at radius `r`.
    fn guide_stats(&self, guide: &[f32], r: usize) -> GuideStats {
        let mean = self.box_mean(guide, r);
        let sq: Vec<f32> = guide.par_iter().map(|v| v * v).collect();
        let mean_sq = self.box_mean(&sq, r);
        let var = mean_sq
            .par_iter()
            .zip(mean.par_iter())
            .map(|(s, m)| (s - m * m).max(0.0))
            .collect();
        GuideStats { mean, var }
    }

    /// The guided filter of `input` by `guide` at radius `r`, ε a function of the guide's
    /// window mean; `stats` are the guide's at `r` when already computed.
    fn guided(
        &self,
        guide: &[f32],
        input: &[f32],
        r: usize,
        eps: impl Fn(f32) -> f32 + Sync,
        stats: Option<&GuideStats>,
    ) -> Vec<f32> {
        let own;
        let g = match stats {
            Some(s) => s,
            None => {
                own = self.guide_stats(guide, r);
                &own
            }
        };
        let mean_p = self.box_mean(input, r);
        let ip: Vec<f32> = guide
            .par_iter()
            .zip(input.par_iter())
            .map(|(a, b)| a * b)
            .collect();
        let mean_ip = self.box_mean(&ip, r);
        let (mut a, mut b) = (vec![0f32; guide.len()], vec![0f32; guide.len()]);
        a.par_iter_mut()
            .zip(b.par_iter_mut())
            .enumerate()
            .for_each(|(i, (a, b))| {
                let (mi, mp) = (g.mean[i], mean_p[i]);
                let cov = mean_ip[i] - mi * mp;
                let e = eps(mi).max(f32::MIN_POSITIVE);
                *a = cov / (g.var[i] + e);
                *b = mp - *a * mi;
            });
        let (ma, mb) = (self.box_mean(&a, r), self.box_mean(&b, r));
        guide
            .par_iter()
            .zip(ma.par_iter().zip(mb.par_iter()))
            .map(|(i, (a, b))| a * i + b)
            .collect()
    }

    /// The mean over the `(2r+1)²` window clamped to the plane, by running sums (f64).
    fn box_mean(&self, src: &[f32], r: usize) -> Vec<f32> {
        let (w, h) = (self.width, self.height);
        let mut tmp = vec![0f32; w * h];
        tmp.par_chunks_mut(w)
            .zip(src.par_chunks(w))
            .for_each(|(o, s)| {
                let mut acc: f64 = s[..(r + 1).min(w)].iter().map(|&v| v as f64).sum();
                for x in 0..w {
                    let lo = x.saturating_sub(r);
                    let hi = (x + r).min(w - 1);
                    o[x] = (acc / (hi - lo + 1) as f64) as f32;
                    if x + r + 1 < w {
                        acc += s[x + r + 1] as f64;
                    }
                    if x >= r {
                        acc -= s[x - r] as f64;
                    }
                }
            });
        const BAND: usize = 32;
        let mut out = vec![0f32; w * h];
        out.par_chunks_mut(w * BAND)
            .enumerate()
            .for_each(|(band, o)| {
                let y0 = band * BAND;
                let mut acc = vec![0f64; w];
                for y in y0.saturating_sub(r)..=(y0 + r).min(h - 1) {
                    for (a, &v) in acc.iter_mut().zip(&tmp[y * w..(y + 1) * w]) {
                        *a += v as f64;
                    }
                }
                for (i, orow) in o.chunks_exact_mut(w).enumerate() {
                    let y = y0 + i;
                    let n = ((y + r).min(h - 1) - y.saturating_sub(r) + 1) as f64;
                    for (ov, a) in orow.iter_mut().zip(&acc) {
                        *ov = (a / n) as f32;
                    }
                    if y + r + 1 < h {
                        for (a, &v) in acc.iter_mut().zip(&tmp[(y + r + 1) * w..(y + r + 2) * w]) {
                            *a += v as f64;
                        }
                    }
                    if y >= r {
                        for (a, &v) in acc.iter_mut().zip(&tmp[(y - r) * w..(y - r + 1) * w]) {
                            *a -= v as f64;
                        }
                    }
                }
            });
        out
    }
}
