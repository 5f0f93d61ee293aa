//! The captured floor: how low a linear map from a patch's channel means to
//! XYZ can bring the chart's patch-mean ΔE2000 on the *simulated capture*
//! (lens flare, noise), when it is fitted on the chart itself.
//!
//! The error budget's linear floor ([`super::error_budget`]) is fitted on
//! ideal channel responses, noise-free and without optics. A method that
//! renders a patch's mean as a linear function of its channel means — a
//! linear colour pipeline, and to first order every L3 class — meets two
//! more things on a capture: the lens's flare mixes neighbouring patches
//! into each interior, where each CFA channel's pixels sample it at their
//! own positions, and one capture's interior means carry noise that the map
//! amplifies. This study fits a 3 × channels map directly on what the
//! method sees:
//!
//! - the patch channel means (per CFA channel, over each patch interior) of
//!   `n` noisy captures, against the truth the evaluation scores with;
//! - minimising the mean ΔE2000 itself (grey strip excluded, both sides
//!   normalised by their white patch, as [`super::evaluate_chart`] does),
//!   by Nelder–Mead from a least-squares start (the `argmin` crate);
//! - scored on `n` *fresh* captures (new noise, the same reflectances: the
//!   map has seen the answers), and 2-fold cross-validated over the patches
//!   (fitted on every other patch, scored on the rest of the fresh
//!   captures): the honest figure for a map that has not seen the test
//!   surfaces.
//!
//! The channel means are per CFA channel, so they carry the mosaic's
//! sampling of the flare's gradient, which a method that estimates every
//! channel at every pixel (bilinear demosaicking, an L3 kernel) partly
//! cancels. Neither figure is therefore a bound on every method (a
//! non-linear one, or one with centred channel estimates, may do better):
//! the fitted-on-the-chart figure is what a linear map of the raw channel
//! means reaches on one capture, given the answer key.

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;
use serde::{Deserialize, Serialize};

use super::budget::per_patch;
use super::report::{scored_patches, white_patch_index};
use super::workflow::{ChartCapture, ChartSetup, simulate_chart};
use super::{EvalError, interior};
use crate::camera::Camera;
use crate::colour::Xyz;
use crate::spectral::IsetData;

/// The captured floor of a sensor under one acquisition light; see the
/// module doc.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CapturedFloor {
    /// Noisy captures the map is fitted on (seeds `seed…seed + n − 1`); as
    /// many fresh ones (the next seeds) score it.
    pub captures: usize,
    /// The fitted map: one `[X, Y, Z]` weight triple per channel.
    pub map: Vec<[f64; 3]>,
    /// Mean patch-mean ΔE2000 over the captures it was fitted on.
    pub fitted: f64,
    /// The same map on the fresh captures (mean of their means).
    pub fresh: f64,
    /// The same map on the chart captured without noise.
    pub noise_free: f64,
    /// 2-fold cross-validation over the patches, on the fresh captures:
    /// the mean of the two folds (each fold fitted on the other patches).
    pub cross_validated: f64,
    /// The two folds' held-out means (even-, then odd-numbered patches).
    pub folds: [f64; 2],
}

/// A capture as the study needs it: per patch, the interior mean of each
/// CFA channel and the truth; the white patch and the patches scored.
struct PatchData {
    channels: Vec<Vec<f64>>,
    truth: Vec<Xyz>,
    white: usize,
    scored: Vec<bool>,
}

impl PatchData {
    fn new(camera: &Camera, cap: &ChartCapture) -> Self {
        let channels = interior_channel_means(camera, cap)
            .into_iter()
            .map(|(means, _)| means)
            .collect();
        Self {
            channels,
            truth: cap.ideal_d65.clone(),
            white: white_patch_index(&cap.scene.patches, &cap.ideal_d65),
            scored: scored_patches(&cap.scene.patches),
        }
    }

    /// Mean ΔE2000 of `map` (channel-major, `3 × nc` values) over the
    /// scored patches `keep` accepts (by index).
    fn mean_delta_e(&self, map: &[f64], keep: &dyn Fn(usize) -> bool) -> f64 {
        let est: Vec<Xyz> = self.channels.iter().map(|c| apply(map, c)).collect();
        let de = per_patch(&est, &self.truth, self.white);
        let (sum, n) = de
            .iter()
            .enumerate()
            .filter(|&(i, _)| self.scored[i] && keep(i))
            .fold((0.0, 0usize), |(s, n), (_, d)| (s + d, n + 1));
        if n == 0 { f64::NAN } else { sum / n as f64 }
    }
}

/// Per patch of a capture: the mean of each CFA channel over the patch
/// interior, in volts, and how many pixels of each channel it averages.
pub(super) fn interior_channel_means(
    camera: &Camera,
    cap: &ChartCapture,
) -> Vec<(Vec<f64>, Vec<usize>)> {
    let cfa = camera.cfa();
    let nc = camera.n_channels();
    cap.scene
        .patches
        .iter()
        .map(|p| {
            let (r0, c0, h, w) = interior(p);
            let mut sum = vec![0f64; nc];
            let mut n = vec![0usize; nc];
            for r in r0..r0 + h {
                for c in c0..c0 + w {
                    let k = cfa.channel_at(r, c);
                    if let (Some(s), Some(v)) = (sum.get_mut(k), cap.volts.get(r * cap.width + c)) {
                        *s += f64::from(*v);
                        n[k] += 1;
                    }
                }
            }
            let means = sum
                .iter()
                .zip(&n)
                .map(|(s, &k)| if k > 0 { s / k as f64 } else { 0.0 })
                .collect();
            (means, n)
        })
        .collect()
}

fn apply(map: &[f64], c: &[f64]) -> Xyz {
    [0, 1, 2].map(|k| c.iter().enumerate().map(|(j, v)| map[3 * j + k] * v).sum())
}

/// Mean over captures of the mean ΔE2000 on the patches `keep` accepts.
fn mean_over(data: &[PatchData], map: &[f64], keep: &dyn Fn(usize) -> bool) -> f64 {
    data.iter().map(|d| d.mean_delta_e(map, keep)).sum::<f64>() / data.len().max(1) as f64
}

struct Objective<'a> {
    data: &'a [PatchData],
    keep: &'a dyn Fn(usize) -> bool,
}

impl CostFunction for Objective<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, map: &Self::Param) -> Result<f64, argmin::core::Error> {
        let v = mean_over(self.data, map, self.keep);
        // a map that sends the white patch to no signal scores NaN: worst
        Ok(if v.is_finite() { v } else { f64::MAX })
    }
}

/// The least-squares start: every patch's channels and truth normalised by
/// its capture's white, errors weighted by 1/Y so dark patches count.
fn least_squares_start(
    data: &[PatchData],
    keep: &dyn Fn(usize) -> bool,
) -> Result<Vec<f64>, EvalError> {
    let nc = data
        .first()
        .map_or(0, |d| d.channels.first().map_or(0, Vec::len));
    let mut a = nalgebra::DMatrix::<f64>::zeros(nc, nc);
    let mut b = nalgebra::DMatrix::<f64>::zeros(nc, 3);
    for d in data {
        let cw = d.channels[d.white].iter().sum::<f64>() / nc.max(1) as f64;
        let yw = d.truth[d.white][1];
        if !(cw > 0.0 && yw > 0.0) {
            continue;
        }
        for (i, (c, t)) in d.channels.iter().zip(&d.truth).enumerate() {
            if !keep(i) {
                continue;
            }
            let w = 1.0 / (t[1] / yw).max(0.01);
            for p in 0..nc {
                for q in 0..nc {
                    a[(p, q)] += w * c[p] * c[q] / (cw * cw);
                }
                for k in 0..3 {
                    b[(p, k)] += w * c[p] / cw * t[k] / yw;
                }
            }
        }
    }
    let floor = (0..nc).map(|i| a[(i, i)]).fold(0.0, f64::max) * 1e-12;
    for i in 0..nc {
        a[(i, i)] += floor.max(f64::MIN_POSITIVE);
    }
    let x = a
        .cholesky()
        .map(|ch| ch.solve(&b))
        .ok_or_else(|| EvalError::Invalid("the chart's channel means are singular".into()))?;
    Ok((0..nc)
        .flat_map(|p| [x[(p, 0)], x[(p, 1)], x[(p, 2)]])
        .collect())
}

/// Fit the map minimising the mean ΔE2000 over `data` on the patches
/// `keep` accepts: Nelder–Mead from the least-squares start, restarted
/// around the best point until a round gains less than 0.001 ΔE.
fn fit(data: &[PatchData], keep: &dyn Fn(usize) -> bool) -> Result<Vec<f64>, EvalError> {
    let mut best = least_squares_start(data, keep)?;
    let objective = Objective { data, keep };
    let mut best_cost = objective.cost(&best).unwrap_or(f64::MAX);
    for _ in 0..8 {
        let simplex: Vec<Vec<f64>> = std::iter::once(best.clone())
            .chain((0..best.len()).map(|i| {
                let mut p = best.clone();
                p[i] += if p[i].abs() > 1e-9 { 0.05 * p[i] } else { 1e-3 };
                p
            }))
            .collect();
        let solver = NelderMead::new(simplex)
            .with_sd_tolerance(1e-10)
            .map_err(|e| EvalError::Invalid(format!("Nelder–Mead: {e}")))?;
        let res = Executor::new(Objective { data, keep }, solver)
            .configure(|s| s.max_iters(3000))
            .run()
            .map_err(|e| EvalError::Invalid(format!("Nelder–Mead: {e}")))?;
        let state = res.state();
        let (Some(p), cost) = (state.get_best_param(), state.get_best_cost()) else {
            break;
        };
        let gain = best_cost - cost;
        if cost < best_cost {
            best = p.clone();
            best_cost = cost;
        }
        if gain < 1e-3 {
            break;
        }
    }
    Ok(best)
}

/// Fit and score the captured floor for `camera` under `acquisition`,
/// `captures` noisy captures (2–64) from `setup.seed` on; see the module doc.
pub fn captured_floor(
    camera: &Camera,
    acquisition: &str,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
    captures: usize,
) -> Result<CapturedFloor, EvalError> {
    super::noise_split::check_captures(captures, "the captured floor")?;
    let capture = |k: usize, noise: bool| -> Result<PatchData, EvalError> {
        let s = ChartSetup {
            seed: setup.seed.wrapping_add(k as u64),
            noise,
            ..setup.clone()
        };
        let data = PatchData::new(camera, &simulate_chart(camera, acquisition, iset, &s)?);
        if data.channels.len() <= data.white || data.truth.len() != data.channels.len() {
            return Err(EvalError::Invalid("the chart has no patches".into()));
        }
        Ok(data)
    };
    let fitted_on = (0..captures)
        .map(|k| capture(k, true))
        .collect::<Result<Vec<_>, _>>()?;
    let fresh = (captures..2 * captures)
        .map(|k| capture(k, true))
        .collect::<Result<Vec<_>, _>>()?;
    let noise_free = capture(0, false)?;
    let all = |_: usize| true;
    let map = fit(&fitted_on, &all)?;
    let mut folds = [0.0; 2];
    for (f, out) in folds.iter_mut().enumerate() {
        let train = move |i: usize| i % 2 != f;
        let test = move |i: usize| i % 2 == f;
        let m = fit(&fitted_on, &train)?;
        *out = mean_over(&fresh, &m, &test);
    }
    let result = CapturedFloor {
        captures,
        fitted: mean_over(&fitted_on, &map, &all),
        fresh: mean_over(&fresh, &map, &all),
        noise_free: noise_free.mean_delta_e(&map, &all),
        cross_validated: 0.5 * (folds[0] + folds[1]),
        folds,
        map: map.chunks(3).map(|c| [c[0], c[1], c[2]]).collect(),
    };
    let figures = [
        result.fitted,
        result.fresh,
        result.noise_free,
        result.cross_validated,
    ];
    if figures.iter().any(|v| !v.is_finite()) {
        return Err(EvalError::Invalid(
            "the captured floor is not finite (no signal in the white patch?)".into(),
        ));
    }
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Patches whose truth is an exact linear function of their channels.
    fn exact(map: &[f64], n: usize, white: usize) -> PatchData {
        let channels: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                vec![
                    0.2 + 0.7 * t,
                    0.9 - 0.6 * t,
                    0.3 + 0.5 * (7.0 * t).sin().abs(),
                ]
            })
            .collect();
        let truth = channels.iter().map(|c| apply(map, c)).collect();
        PatchData {
            channels,
            truth,
            white,
            scored: (0..n).map(|i| i != white).collect(),
        }
    }

    const MAP: [f64; 9] = [0.4, 0.2, 0.02, 0.35, 0.7, 0.1, 0.15, 0.1, 0.9];

    /// [`exact`] with patch 0 the white: every channel at its brightest.
    fn exact_with_white() -> PatchData {
        let mut d = exact(&MAP, 40, 0);
        d.channels[0] = vec![1.0, 1.0, 1.0];
        d.truth[0] = apply(&MAP, &d.channels[0]);
        d
    }

    #[test]
    fn an_exact_linear_chart_is_fitted_to_no_error() {
        let m = MAP;
        let d = exact_with_white();
        let all = |_: usize| true;
        let fitted = fit(std::slice::from_ref(&d), &all).unwrap();
        assert!(mean_over(std::slice::from_ref(&d), &fitted, &all) < 1e-3);
        // the scale is free (both sides are normalised by their white)
        let scaled: Vec<f64> = m.iter().map(|v| 3.0 * v).collect();
        assert!(d.mean_delta_e(&scaled, &all) < 1e-9);
    }

    #[test]
    fn a_wrong_map_scores_worse_than_the_fit() {
        let m = MAP;
        let d = exact_with_white();
        let wrong = [0.4, 0.2, 0.02, 0.35, 0.7, 0.1, 0.15, 0.1, 0.6];
        let all = |_: usize| true;
        assert!(d.mean_delta_e(&wrong, &all) > 1.0);
        let odd = |i: usize| i % 2 == 1;
        assert!(d.mean_delta_e(&m, &odd) < 1e-9);
    }

    #[test]
    fn too_few_or_too_many_captures_are_refused() {
        let camera = Camera::new(
            &crate::camera::SensorDesign::paper_default(),
            crate::spectral::WavelengthGrid::default(),
            None,
        )
        .unwrap();
        for n in [0, 1, 65] {
            let e = captured_floor(&camera, "Tungsten", None, &ChartSetup::default(), n);
            assert!(matches!(e, Err(EvalError::Invalid(_))), "{n}");
        }
    }
}
