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
    let beta = channel_shares(channels, nc);
    // strips of rows with a halo as wide as the filters reach (each guided filter reaches
    // twice its radius; the chroma's ε reads the denoised luma): the same result as the
    // whole frame at once, with every plane small enough to stay in cache
    const STRIP: usize = 64;
    let halo = 2 * (params.luma_radius + params.chroma_radius);
    let row = width * nc;
    let mut out = vec![0f32; n * nc];
    out.par_chunks_mut(STRIP * row)
        .enumerate()
        .for_each(|(strip, o)| {
            let y0 = strip * STRIP;
            let y1 = (y0 + STRIP).min(height);
            let (e0, e1) = (y0.saturating_sub(halo), (y1 + halo).min(height));
            let planes = Planes {
                width,
                height: e1 - e0,
            };
            let d = planes.denoise(&channels[e0 * row..e1 * row], nc, &beta, profile, params);
            o.copy_from_slice(&d[(y0 - e0) * row..(y1 - e0) * row]);
        });
    Ok(out)
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
    /// The module doc's denoiser on these planes (interleaved `nc` channels), with the
    /// channels' shares `beta` of the luma.
    fn denoise(
        &self,
        channels: &[f32],
        nc: usize,
        beta: &[f32],
        profile: &NoiseProfile,
        params: &DenoiseParams,
    ) -> Vec<f32> {
        let luma: Vec<f32> = channels
            .chunks_exact(nc)
            .map(|px| px.iter().sum::<f32>() / nc as f32)
            .collect();
        // the variance of L's noise at luma m: the channels' variances at β_k·m over nc²
        let luma_var = |m: f32| -> f32 {
            let m = m as f64;
            let v: f64 = beta.iter().map(|&b| profile.variance(b as f64 * m)).sum();
            (v / (nc * nc) as f64) as f32
        };
        let luma_d = self.guided(&luma, &luma, params.luma_radius, |_, m| {
            params.luma_strength * luma_var(m)
        });
        let mut out = vec![0f32; channels.len()];
        for (k, &b) in beta.iter().enumerate() {
            let chroma: Vec<f32> = channels
                .iter()
                .skip(k)
                .step_by(nc)
                .zip(&luma)
                .map(|(&c, &l)| c - b * l)
                .collect();
            // self-guided: chroma edges above the channel's noise are kept (isoluminant
            // edges too, which a luma guide cannot see), the rest is flattened
            let chroma_d = self.guided(&chroma, &chroma, params.chroma_radius, |i, _| {
                params.chroma_strength * profile.variance((b * luma_d[i]) as f64) as f32
            });
            for ((px, &c), &l) in out.chunks_exact_mut(nc).zip(&chroma_d).zip(&luma_d) {
                px[k] = b * l + c;
            }
        }
        out
    }

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

    /// The guided filter of `input` by `guide` at radius `r`, ε a function of the pixel's
    /// index and the guide's window mean.
    fn guided(
        &self,
        guide: &[f32],
        input: &[f32],
        r: usize,
        eps: impl Fn(usize, f32) -> f32 + Sync,
    ) -> Vec<f32> {
        let g = self.guide_stats(guide, r);
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
                let e = eps(i, mi).max(f32::MIN_POSITIVE);
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

    /// The mean over the `(2r+1)²` window clamped to the plane, by running sums.
    fn box_mean(&self, src: &[f32], r: usize) -> Vec<f32> {
        let (w, h) = (self.width, self.height);
        let mut tmp = vec![0f32; w * h];
        tmp.par_chunks_mut(w)
            .zip(src.par_chunks(w))
            .for_each(|(o, s)| {
                let mut acc: f64 = s[..(r + 1).min(w)].iter().map(|&v| v as f64).sum();
                let full = 1.0 / (2 * r + 1) as f64;
                for x in 0..w {
                    let inv = if x >= r && x + r < w {
                        full
                    } else {
                        1.0 / ((x + r).min(w - 1) - x.saturating_sub(r) + 1) as f64
                    };
                    o[x] = (acc * inv) as f32;
                    if x + r + 1 < w {
                        acc += s[x + r + 1] as f64;
                    }
                    if x >= r {
                        acc -= s[x - r] as f64;
                    }
                }
            });
        // f32 sums, started afresh every band of rows, so rounding cannot build up
        const BAND: usize = 32;
        let mut out = vec![0f32; w * h];
        out.par_chunks_mut(w * BAND)
            .enumerate()
            .for_each(|(band, o)| {
                let y0 = band * BAND;
                let mut acc = vec![0f32; w];
                for y in y0.saturating_sub(r)..=(y0 + r).min(h - 1) {
                    for (a, &v) in acc.iter_mut().zip(&tmp[y * w..(y + 1) * w]) {
                        *a += v;
                    }
                }
                for (i, orow) in o.chunks_exact_mut(w).enumerate() {
                    let y = y0 + i;
                    let inv = 1.0 / ((y + r).min(h - 1) - y.saturating_sub(r) + 1) as f32;
                    for (ov, a) in orow.iter_mut().zip(&acc) {
                        *ov = a * inv;
                    }
                    if y + r + 1 < h {
                        let add = &tmp[(y + r + 1) * w..(y + r + 2) * w];
                        for (a, &v) in acc.iter_mut().zip(add) {
                            *a += v;
                        }
                    }
                    if y >= r {
                        let sub = &tmp[(y - r) * w..(y - r + 1) * w];
                        for (a, &v) in acc.iter_mut().zip(sub) {
                            *a -= v;
                        }
                    }
                }
            });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_give_the_whole_frames_result() {
        let (w, h, nc) = (37, 150, 3);
        let v: Vec<f32> = (0..w * h * nc)
            .map(|i| {
                let step = if (i / nc) % w > 18 { 0.3 } else { 0.0 };
                0.2 + 0.1 * ((i * 7919 % 97) as f32 / 97.0) + step
            })
            .collect();
        let p = NoiseProfile::from_design(&SensorDesign::paper_default(), 0.01);
        let prm = DenoiseParams::default();
        let strips = denoise(&v, w, h, nc, &p, &prm).unwrap();
        let beta = channel_shares(&v, nc);
        let whole = Planes {
            width: w,
            height: h,
        }
        .denoise(&v, nc, &beta, &p, &prm);
        let worst = strips
            .iter()
            .zip(&whole)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(worst < 1e-5, "{worst}");
        assert!(strips.iter().zip(&v).any(|(a, b)| (a - b).abs() > 1e-3));
    }
}
