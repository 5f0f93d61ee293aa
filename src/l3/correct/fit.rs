//! The small fitting primitives a colour map and a camera-aware correction share: the
//! sensor's noise ([`NoiseModel`], and [`LevelNoise`] on a level's channel means), the
//! first-order ΔE00 weights of an XYZ error ([`delta_e_weights`]) and the mean-ΔE loss's
//! reweighted least squares ([`mean_loss_fit`]). The trainer fits its colour maps with
//! them, and the render path fits the camera-aware C with them, so they live here, beside
//! the correction, rather than with the trainer.

use crate::camera::SensorDesign;
use crate::colour::{ciede2000_metric, xyz_to_lab};

/// Sensor noise at a signal level, for the noise-variance ridge.
#[derive(Clone, Copy, Debug)]
pub struct NoiseModel {
    pub conversion_gain_v: f64,
    pub read_noise_v: f64,
    pub dsnu_v: f64,
    pub prnu_fraction: f64,
}

impl NoiseModel {
    /// Variance in volts² of a pixel at mean signal `v` volts.
    pub fn variance(&self, v: f64) -> f64 {
        self.conversion_gain_v * v
            + (self.prnu_fraction * v).powi(2)
            + self.dsnu_v.powi(2)
            + self.read_noise_v.powi(2)
    }
}

/// The noise model of `design`'s sensor: what the colour maps and the
/// camera-aware corrections trade colour against.
pub fn noise_model(design: &SensorDesign) -> NoiseModel {
    NoiseModel {
        conversion_gain_v: design.conversion_gain_v(),
        read_noise_v: design.read_noise_v(),
        dsnu_v: design.dsnu_v(),
        prnu_fraction: design.prnu_fraction(),
    }
}

/// The noise a level's colour map is fitted for: the sensor's noise on a
/// channel mean over `averaging_px` pixels per channel, at the level's
/// luminance statistic `level_v` volts (of a `swing_v` swing).
#[derive(Clone, Copy, Debug)]
pub struct LevelNoise {
    pub model: NoiseModel,
    pub level_v: f64,
    pub swing_v: f64,
    pub averaging_px: f64,
}

impl LevelNoise {
    /// Per channel, the noise variance of a patch of this level whose
    /// noise-free channel responses are proportional to `channels`, in
    /// `channels`' units (the sample is scaled so that its mean channel
    /// response is the level; zero noise for a sample with no signal).
    pub fn channel_variance(&self, channels: &[f64]) -> Vec<f64> {
        let lum = channels.iter().sum::<f64>() / channels.len().max(1) as f64;
        if !(lum > 0.0 && self.level_v > 0.0) {
            return vec![0.0; channels.len()];
        }
        let s = self.level_v / lum;
        channels
            .iter()
            .map(|v| {
                self.model.variance((v * s).clamp(0.0, self.swing_v)) / self.averaging_px / (s * s)
            })
            .collect()
    }
}

/// `∂(L*, a*, b*)/∂(X, Y, Z)` at `xyz` for reference white `white`.
fn lab_jacobian(xyz: [f64; 3], white: [f64; 3]) -> [[f64; 3]; 3] {
    // d f(t)/dt of the CIELAB function, kept finite at t → 0
    let df = |t: f64| {
        if t > 216.0 / 24389.0 {
            t.powf(-2.0 / 3.0) / 3.0
        } else {
            24389.0 / 27.0 / 116.0
        }
    };
    let d = [0, 1, 2].map(|k| df(xyz[k] / white[k]) / white[k]);
    [
        [0.0, 116.0 * d[1], 0.0],
        [500.0 * d[0], -500.0 * d[1], 0.0],
        [0.0, 200.0 * d[1], -200.0 * d[2]],
    ]
}

/// The weights `W = Jᵀ Q J` that make an XYZ error `e` at `xyz` (relative to
/// `white`) cost `eᵀ W e`, its first-order ΔE00²: `J` is the CIELAB Jacobian,
/// `Q` CIEDE2000's local metric in CIELAB ([`ciede2000_metric`]).
pub fn delta_e_weights(xyz: [f64; 3], white: [f64; 3]) -> [[f64; 3]; 3] {
    let j = lab_jacobian(xyz, white);
    let q = ciede2000_metric(xyz_to_lab(xyz, white));
    [0, 1, 2].map(|k| {
        [0, 1, 2].map(|l| {
            (0..3)
                .map(|p| (0..3).map(|r| j[p][k] * q[p][r] * j[r][l]).sum::<f64>())
                .sum()
        })
    })
}

/// Minimises `Σ_light (Σ_i e_i)²` over `n` samples, `e_i` sample i's
/// smoothed error (`sqrt(square_error + s²)`, `s` `MEAN_LOSS_SMOOTHING`),
/// by iteratively reweighted least squares: `solve(weights)` solves the
/// problem whose loss is `Σ_i weights[i] · square_error_i`, and
/// `square_error(x, i)` is sample i's squared error under solution `x`. The
/// gradient of the loss weighs a sample by its light's total error over its
/// own, so each round solves with those weights; the first round is the
/// plain squared loss.
pub fn mean_loss_fit<T, E>(
    n: usize,
    light: impl Fn(usize) -> usize,
    solve: impl Fn(&[f64]) -> Result<T, E>,
    square_error: impl Fn(&T, usize) -> f64,
) -> Result<T, E> {
    let n_lights = (0..n).map(|i| light(i) + 1).max().unwrap_or(1);
    let mut weights = vec![1.0; n];
    let mut x = solve(&weights)?;
    for _ in 0..MEAN_LOSS_ITERATIONS {
        let errors: Vec<f64> = (0..n)
            .map(|i| {
                (square_error(&x, i).max(0.0) + MEAN_LOSS_SMOOTHING * MEAN_LOSS_SMOOTHING).sqrt()
            })
            .collect();
        let mut light_total = vec![0.0; n_lights];
        for (i, e) in errors.iter().enumerate() {
            light_total[light(i)] += e;
        }
        for (i, (w, e)) in weights.iter_mut().zip(&errors).enumerate() {
            *w = light_total[light(i)] / e;
        }
        x = solve(&weights)?;
    }
    Ok(x)
}

/// Reweighting rounds of the mean-ΔE loss ([`ColourLoss::MeanDeltaE`](crate::l3::params::ColourLoss::MeanDeltaE)).
const MEAN_LOSS_ITERATIONS: usize = 12;
/// The error (ΔE00) below which the mean-ΔE loss turns quadratic, so that a
/// sample fitted exactly does not take all the weight.
pub const MEAN_LOSS_SMOOTHING: f64 = 0.25;

/// For tests of a mean-ΔE fit: the per-sample errors of the mean-loss fit
/// have the lower mean (by 0.05 or more), those of the squared-loss fit the
/// lower sum of squares.
#[cfg(test)]
pub(crate) fn assert_mean_loss_trade(mean_fit: &[f64], squared_fit: &[f64]) {
    let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
    let sq = |e: &[f64]| e.iter().map(|v| v * v).sum::<f64>();
    assert!(
        mean(mean_fit) < mean(squared_fit) - 0.05,
        "mean {} against {}",
        mean(mean_fit),
        mean(squared_fit)
    );
    assert!(
        sq(squared_fit) < sq(mean_fit),
        "squares {} against {}",
        sq(squared_fit),
        sq(mean_fit)
    );
}
