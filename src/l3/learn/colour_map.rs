//! Colour maps: the linear channel → XYZ maps that fix how every unsaturated
//! kernel renders a uniform patch.
//!
//! A kernel applied to a uniform patch returns `Σ_c s_c · v_c`, where `s_c`
//! is the sum of its weights over the patch pixels of channel `c`. Those
//! channel sums are the kernel's colour; its spatial weights only decide how
//! noise and edges are handled. The trainer therefore fixes the channel sums
//! of each level's kernels to a colour map fitted on *spectral* data (channel
//! responses and XYZ of reflectances) and lets the patches decide only the
//! spatial weights.
//!
//! Why not learn the colour from the patches: on real filters the colour
//! lives in small differences between large channel signals (ISET's RGBW
//! needs `X ≈ 8.9 W − 5.5 R − 5.2 G − 8.6 B`). In training patches those
//! differences are swamped by spatial variation (edges, blur, flare), so a
//! least-squares fit over patches — with or without noise — shrinks them and
//! renders colour with a bias: on ISET's RGBW under tungsten, 4.9 ΔE2000
//! against 3.2 for the global linear map in the same renderer, noise-free.
//!
//! The map of a level is the best linear map for a *patch* of that level:
//! - every reflectance is scaled to the level's luminance statistic (the mean
//!   over channels of the channel responses), as a patch of that level is;
//! - the error is weighted perceptually: each sample's XYZ error goes
//!   through the Jacobian of CIELAB at its true colour (relative to the
//!   white of its illuminant) and CIEDE2000's local metric there
//!   ([`delta_e_weights`](crate::l3::correct::delta_e_weights)), so the fit minimises a first-order ΔE00², the
//!   measure the evaluation reports, rather than an XYZ error that bright
//!   colours dominate. A same-illuminant table's output is judged after its
//!   light's correction T, so its samples carry T
//!   ([`ColourSamples::judged_through`]) and the error is weighted where it
//!   is judged, at `T·xyz` relative to `T·white`, pulled back through T
//!   (noise-free on ISET's RGBW under tungsten, SI_Tun+T 2.58 → 2.47 against
//!   its matching linear map's 2.52). Its target is what T must receive to
//!   give the true D65 colour, `T⁻¹·xyz_D65`, not XYZ under the light
//!   (`l3::correct::ColourTarget`): the map then also absorbs T's own error
//!   where the channels tell apart what T confuses (rgbw-paper SI_Tun+T
//!   1.48 → 0.87). The samples are the natural reflectances
//!   (`scene::natural_reflectances`, no Munsell chips): on ISET's RGBW under
//!   tungsten a cross table's one-capture error went from 3.55 (ΔE76 on the
//!   training reflectances) to 2.86, where either change alone made it
//!   worse (3.56 with ΔE00, 3.81 with the natural set;
//!   `docs/research/colour-map-loss.md`);
//! - the loss is every light's *mean* error, not the sum of squares
//!   ([`ColourLoss::MeanDeltaE`]): the evaluation reports a mean ΔE2000, and
//!   a squared loss lets a few surfaces no linear map can render (saturated
//!   reds, deep blues) pull every other colour off. Each sample's error is
//!   its expected first-order ΔE00 with the level's noise, `sqrt(bias² +
//!   noise²)`, and the fit minimises `Σ_light (Σ_sample ΔE)²` by iteratively
//!   reweighted least squares (a sample weighs its light's total error over
//!   its own). Squaring each light's sum keeps an ensemble serving every
//!   light: a plain sum of ΔE over an ensemble's samples gave up the light
//!   that is hardest to fit (ISET's RGBW three-light table under fluorescent,
//!   noise-free, 8.87 → 11.02; with the per-light square 8.71). Over 16
//!   captures under tungsten it moved the cross table (I_Tun) 2.80 → 2.77 on
//!   ISET's RGBW (per-pixel 4.46 → 4.21, with [`CROSS_AVERAGING_PX`]
//!   re-chosen), 2.29 → 2.20 on rgbw-ar0132at and 1.90 → 1.77 on the Nikon
//!   D5100; SI_Tun+T 3.08 → 3.02, 2.49 → 2.43 and 2.06 → 2.00. Which
//!   loss a table uses is the trainer's choice (`TrainingSpec::colour_loss`:
//!   the mean for one light, the squared loss for an ensemble);
//! - the sensor's noise enters as a ridge: the expected error of the map on
//!   a channel mean over `averaging_px` pixels per channel
//!   (`tr(J M Σ Mᵀ Jᵀ)`, `Σ` the noise variance of such a mean at the level),
//!   so dark levels trade a little colour accuracy for much less noise and
//!   bright levels converge to the noise-free map.
//!
//! The plain least-squares map ([`least_squares_map`]) is the reference a
//! table is compared with: a table whose every class holds it is a valid L3
//! table, and the evaluation prints it beside every L3 row.

use nalgebra::{DMatrix, DVector};

use super::LearnError;
use super::spec::TrainingSpec;
use crate::baseline::ColourMatrix;
use crate::camera::{Camera, SensorDesign};
use crate::l3::classify::ChromaClasses;
use crate::l3::correct::{ColourSamples, LevelNoise, Mat3, NoiseModel, mean_loss_fit};
use crate::l3::params::{ColourLoss, ColourMapFit};
use crate::spectral::Spectrum;

/// The plain least-squares linear map `XYZ = M · channels` over `samples`:
/// the noise-free reference an L3 table is compared with.
pub fn least_squares_map(samples: &ColourSamples) -> Result<ColourMatrix, LearnError> {
    samples.check()?;
    Ok(ColourMatrix::fit(&samples.channels, &samples.xyz)?)
}

/// One colour map per level (`levels` in volts, the patch luminance
/// statistic), for a sensor with `noise` and `swing` volts.
pub fn level_maps(
    samples: &ColourSamples,
    levels: &[f64],
    noise: &NoiseModel,
    swing: f64,
    fit: &ColourMapFit,
) -> Result<Vec<ColourMatrix>, LearnError> {
    fit.validate()?;
    let nc = samples.check()?;
    levels
        .iter()
        .map(|&level| level_map(samples, nc, level, noise, swing, fit, None))
        .collect()
}

/// One colour map per band (level × chroma classes + class, see
/// [`chroma`](crate::l3::classify::chroma)): each level's map fitted on each chroma class's
/// samples, with a ridge (`PRIOR_WEIGHT`) toward `pooled`, the level's map over every
/// sample ([`level_maps`] on the same samples). A class's surfaces span a narrow cone of channel space, so on its
/// own a class map is free in the directions across the cone and takes large,
/// noisy weights there; the ridge leaves those directions to the pooled map.
/// Measured on cross tables under tungsten (8 classes asked, 16 captures, one
/// capture's patch-mean ΔE00 and the largest kernel norm), by weight:
/// rgbw-ar0132at 0: 1.97 / 139.5, 1e-5: 1.96 / 33.1, 1e-4: 2.00 / 24.4,
/// 1e-3: 2.10 / 21.8; rgbw-iset 0: 2.13 / 46.3, 1e-5: 2.14 / 22.5,
/// 1e-4: 2.23 / 20.9, 1e-3: 2.33 / 20.6. The weights across the cone do real
/// work up to a point, so the ridge is kept light.
pub fn band_maps(
    samples: &ColourSamples,
    classes: &ChromaClasses,
    pooled: &[ColourMatrix],
    levels: &[f64],
    noise: &NoiseModel,
    swing: f64,
    fit: &ColourMapFit,
) -> Result<Vec<ColourMatrix>, LearnError> {
    fit.validate()?;
    samples.check()?;
    if pooled.len() != levels.len() {
        return Err(LearnError::InvalidParams(format!(
            "{} pooled maps for {} levels",
            pooled.len(),
            levels.len()
        )));
    }
    let per_class = (0..classes.len().max(1))
        .map(|k| {
            let sub = samples.subset(&samples.in_chroma_class(classes, k));
            let nc = sub.check()?;
            levels
                .iter()
                .zip(pooled)
                .map(|(&level, prior)| level_map(&sub, nc, level, noise, swing, fit, Some(prior)))
                .collect::<Result<Vec<_>, LearnError>>()
        })
        .collect::<Result<Vec<_>, LearnError>>()?;
    let kc = per_class.len();
    Ok((0..levels.len() * kc)
        .map(|b| per_class[b % kc][b / kc].clone())
        .collect())
}

/// The weight of a chroma class map's ridge toward its level's pooled map,
/// relative to the mean diagonal of the class's normal equations.
pub const PRIOR_WEIGHT: f64 = 1e-5;

/// One sample of a level's fit: its index, error weights and the noise
/// variance of its channel mean at the level.
struct LevelSample {
    index: usize,
    weights: [[f64; 3]; 3],
    variance: Vec<f64>,
}

fn level_map(
    samples: &ColourSamples,
    nc: usize,
    level: f64,
    noise: &NoiseModel,
    swing: f64,
    fit: &ColourMapFit,
    prior: Option<&ColourMatrix>,
) -> Result<ColourMatrix, LearnError> {
    let level_noise = fit.averaging_px.map(|n| LevelNoise {
        model: *noise,
        level_v: level,
        swing_v: swing,
        averaging_px: n,
    });
    // this surface as a patch at `level` is the sample × level / lum. Error
    // weights W = JᵀQJ (perceptual), or the identity: the error of a scaled
    // sample is that scale × the error at unit scale, and J scales by its
    // inverse: both cancel, so every sample has the same weight at every
    // level. The noise variance is that of a channel mean over
    // `averaging_px` pixels, in the sample's (unit-scale) units.
    let prepared: Vec<LevelSample> = samples
        .channels
        .iter()
        .enumerate()
        .filter(|(_, c)| c.iter().sum::<f64>() > 0.0)
        .map(|(index, c)| LevelSample {
            index,
            weights: samples.error_weights(index, fit.perceptual),
            variance: match &level_noise {
                Some(n) => n.channel_variance(c),
                None => vec![0.0; nc],
            },
        })
        .collect();
    if prepared.len() < nc.max(3) {
        return Err(LearnError::InvalidParams(format!(
            "a colour map needs at least {} samples with signal, got {}",
            nc.max(3),
            prepared.len()
        )));
    }
    let solve = |weights: &[f64]| solve_level(samples, nc, &prepared, weights, level, prior);
    let m = match fit.loss {
        ColourLoss::SquaredDeltaE => solve(&vec![1.0; prepared.len()])?,
        ColourLoss::MeanDeltaE => mean_loss_fit(
            prepared.len(),
            |i| samples.light.get(prepared[i].index).copied().unwrap_or(0),
            solve,
            |m, i| expected_square_error(m, nc, samples, &prepared[i]),
        )?,
    };
    Ok(ColourMatrix {
        m: (0..nc).map(|c| [m[c], m[nc + c], m[2 * nc + c]]).collect(),
        n_channels: nc,
    })
}

/// Sample `s`'s expected weighted squared error under map `m` (unknowns
/// `m[k * nc + c]`): its bias `eᵀWe` plus its noise `tr(W M Σ Mᵀ)`.
fn expected_square_error(
    m: &DVector<f64>,
    nc: usize,
    samples: &ColourSamples,
    s: &LevelSample,
) -> f64 {
    let c = &samples.channels[s.index];
    let x = samples.xyz[s.index];
    let e = [0, 1, 2].map(|k| (0..nc).map(|i| m[k * nc + i] * c[i]).sum::<f64>() - x[k]);
    let mut total = 0.0;
    for k in 0..3 {
        for l in 0..3 {
            let noise: f64 = (0..nc)
                .map(|i| m[k * nc + i] * m[l * nc + i] * s.variance[i])
                .sum();
            total += s.weights[k][l] * (e[k] * e[l] + noise);
        }
    }
    total.max(0.0)
}

/// The weighted normal equations of a level's map, solved: unknowns
/// `m[k * nc + c]`, the weight of channel c for output k.
fn solve_level(
    samples: &ColourSamples,
    nc: usize,
    prepared: &[LevelSample],
    sample_weight: &[f64],
    level: f64,
    prior: Option<&ColourMatrix>,
) -> Result<DVector<f64>, LearnError> {
    let nn = 3 * nc;
    let mut a = DMatrix::<f64>::zeros(nn, nn);
    let mut b = DVector::<f64>::zeros(nn);
    for (s, &sw) in prepared.iter().zip(sample_weight) {
        let c = &samples.channels[s.index];
        let x = samples.xyz[s.index];
        for k in 0..3 {
            for l in 0..3 {
                let wkl = sw * s.weights[k][l];
                if wkl == 0.0 {
                    continue;
                }
                for i in 0..nc {
                    let row = k * nc + i;
                    for j in 0..nc {
                        a[(row, l * nc + j)] += wkl * c[i] * c[j];
                    }
                    a[(row, l * nc + i)] += wkl * s.variance[i];
                    b[row] += wkl * x[l] * c[i];
                }
            }
        }
    }
    if let Some(p) = prior {
        // a ridge toward the prior map, relative to the data's scale: the
        // directions the samples do not pin down keep the prior's weights
        let lambda = PRIOR_WEIGHT * (0..nn).map(|i| a[(i, i)]).sum::<f64>() / nn as f64;
        for k in 0..3 {
            for i in 0..nc {
                a[(k * nc + i, k * nc + i)] += lambda;
                b[k * nc + i] += lambda * p.m[i][k];
            }
        }
    }
    // a relative floor keeps channels that never respond solvable
    let floor = (0..nn).map(|i| a[(i, i)]).fold(0.0, f64::max) * 1e-12;
    for i in 0..nn {
        a[(i, i)] += floor.max(f64::MIN_POSITIVE);
    }
    let m = a.cholesky().map(|ch| ch.solve(&b)).ok_or_else(|| {
        LearnError::Solve(format!("the colour map at level {level} V is singular"))
    })?;
    if m.iter().any(|v| !v.is_finite()) {
        return Err(LearnError::Solve(format!(
            "the colour map at level {level} V is not finite"
        )));
    }
    Ok(m)
}

/// What a run's colour maps are fitted from: its camera and sensor, its spec, its lights
/// (with their corrections T to D65, for a same-illuminant table), D65 and the
/// reflectances.
pub(super) struct MapInputs<'a> {
    pub(super) camera: &'a Camera,
    pub(super) design: &'a SensorDesign,
    pub(super) spec: &'a TrainingSpec,
    /// The lights' names, as the table records them (`TableMeta::train_illuminants`).
    pub(super) names: &'a [String],
    pub(super) lights: &'a [Spectrum],
    pub(super) corrections: &'a [Mat3],
    pub(super) d65: &'a Spectrum,
    pub(super) refl: &'a [Spectrum],
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::{mat3_mul_vec, xyz_to_lab};
    use crate::l3::correct::{MEAN_LOSS_SMOOTHING, assert_mean_loss_trade, delta_e_weights};

    fn noise() -> NoiseModel {
        NoiseModel {
            conversion_gain_v: 200e-6,
            read_noise_v: 1.34e-3,
            dsnu_v: 1.41e-3,
            prnu_fraction: 0.002218,
        }
    }

    /// Samples from a known map with channels that span XYZ.
    fn exact_samples(truth: &[[f64; 3]]) -> ColourSamples {
        let mut s = ColourSamples::default();
        for i in 0..40 {
            let c: Vec<f64> = (0..truth.len())
                .map(|k| 0.05 + ((i * 7 + k * 13) % 17) as f64 / 20.0)
                .collect();
            let x = [0, 1, 2].map(|q| (0..c.len()).map(|k| truth[k][q] * c[k]).sum::<f64>());
            s.channels.push(c);
            s.xyz.push(x);
            s.white.push([0.95, 1.0, 1.09]);
        }
        s
    }

    #[test]
    fn an_exact_linear_relation_is_recovered_at_every_level_without_noise() {
        let truth = [[0.6, 0.3, 0.0], [0.3, 0.6, 0.1], [0.05, 0.1, 0.9]];
        let s = exact_samples(&truth);
        for perceptual in [false, true] {
            let fit = ColourMapFit {
                averaging_px: None,
                perceptual,
                loss: ColourLoss::default(),
            };
            let maps = level_maps(&s, &[0.01, 0.3, 1.5], &noise(), 1.8, &fit).unwrap();
            for m in maps.iter().chain([&least_squares_map(&s).unwrap()]) {
                for c in 0..3 {
                    for k in 0..3 {
                        assert!((m.m[c][k] - truth[c][k]).abs() < 1e-6, "{perceptual} {m:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn band_maps_fit_each_chroma_class_its_own_map() {
        // two families of surfaces, each under its own linear relation
        let a = [[0.6, 0.3, 0.0], [0.3, 0.6, 0.1], [0.05, 0.1, 0.9]];
        let b = [[0.9, 0.2, 0.1], [0.1, 0.8, 0.0], [0.0, 0.2, 0.7]];
        let mut s = ColourSamples::default();
        for i in 0..80 {
            let v = [
                0.05 + (i % 5) as f64 * 0.03,
                0.3 + (i % 7) as f64 * 0.05,
                0.9 - (i % 3) as f64 * 0.1,
            ];
            // the first half reddish under `a`, the second bluish under `b`
            let (c, m) = if i < 40 {
                (vec![v[2], v[1], v[0]], &a)
            } else {
                (v.to_vec(), &b)
            };
            let x = [0, 1, 2].map(|q| (0..3).map(|k| m[k][q] * c[k]).sum::<f64>());
            s.channels.push(c);
            s.xyz.push(x);
            s.white.push([0.95, 1.0, 1.09]);
        }
        let classes = ChromaClasses {
            centroids: vec![vec![0.55, 0.35, 0.1], vec![0.1, 0.35, 0.55]],
            white: None,
        };
        let picked: Vec<usize> = (0..2)
            .map(|k| s.in_chroma_class(&classes, k).len())
            .collect();
        assert_eq!(picked, vec![40, 40]);
        let fit = ColourMapFit {
            averaging_px: None,
            perceptual: false,
            loss: ColourLoss::SquaredDeltaE,
        };
        let levels = [0.05, 1.0];
        let pooled = level_maps(&s, &levels, &noise(), 1.8, &fit).unwrap();
        let maps = band_maps(&s, &classes, &pooled, &levels, &noise(), 1.8, &fit).unwrap();
        assert_eq!(maps.len(), 4);
        assert!(band_maps(&s, &classes, &pooled[..1], &levels, &noise(), 1.8, &fit).is_err());
        let error = |m: &ColourMatrix, idx: &[usize]| {
            idx.iter()
                .map(|&i| {
                    let c = &s.channels[i];
                    (0..3)
                        .map(|q| {
                            let e: f64 =
                                (0..3).map(|k| m.m[k][q] * c[k]).sum::<f64>() - s.xyz[i][q];
                            e * e
                        })
                        .sum::<f64>()
                })
                .sum::<f64>()
        };
        for k in 0..2 {
            let idx = s.in_chroma_class(&classes, k);
            for (l, pooled) in pooled.iter().enumerate() {
                // band = level × classes + class
                let own = error(&maps[l * 2 + k], &idx);
                let all = error(pooled, &idx);
                assert!(own < 0.05 * all, "class {k} level {l}: {own} against {all}");
            }
        }
        // the subset keeps every per-sample column
        let sub = s.subset(&[3, 1]);
        assert_eq!(
            sub.channels,
            vec![s.channels[3].clone(), s.channels[1].clone()]
        );
        assert!(sub.judged_through.is_empty() && sub.light.is_empty());
    }

    #[test]
    fn the_noise_term_shrinks_dark_levels_more_than_bright_ones() {
        // W ≈ R + G + B: a high-gain difference carries the colour
        let truth = [
            [-3.0, -1.0, -2.0],
            [-3.0, -0.5, -2.0],
            [5.0, 2.0, 3.5],
            [-3.0, -1.0, 0.0],
        ];
        let mut s = exact_samples(&truth);
        for c in &mut s.channels {
            c[2] = c[0] + c[1] + c[3] + 0.05 * c[2];
        }
        for (c, x) in s.channels.iter().zip(s.xyz.iter_mut()) {
            *x = [0, 1, 2].map(|q| (0..4).map(|k| truth[k][q] * c[k]).sum::<f64>());
        }
        let fit = ColourMapFit::default();
        let maps = level_maps(&s, &[0.002, 0.05, 1.5], &noise(), 1.8, &fit).unwrap();
        let norm = |m: &ColourMatrix| m.m.iter().flatten().map(|v| v * v).sum::<f64>().sqrt();
        let (dark, mid, bright) = (norm(&maps[0]), norm(&maps[1]), norm(&maps[2]));
        assert!(dark < mid && mid < bright, "{dark} {mid} {bright}");
        assert!(
            maps.iter()
                .flat_map(|m| m.m.iter().flatten())
                .all(|v| v.is_finite())
        );
    }

    #[test]
    fn error_weights_give_the_delta_e_after_the_judging_matrix() {
        let mut s = exact_samples(&[[0.6, 0.3, 0.0], [0.3, 0.6, 0.1], [0.05, 0.1, 0.9]]);
        // a tungsten-like T: more blue, less red, white-preserving in spirit
        let t = [[0.85, 0.05, 0.1], [0.02, 0.97, 0.01], [0.0, -0.05, 3.1]];
        s.judged_through = vec![t; s.len()];
        let apply = |v: [f64; 3]| mat3_mul_vec(&t, v);
        for i in [0, 7, 19] {
            let (x, w) = (s.xyz[i], s.white[i]);
            let e = [2e-4, -1.5e-4, 3e-4];
            let moved = [x[0] + e[0], x[1] + e[1], x[2] + e[2]];
            let white = apply(w);
            let exact = crate::colour::ciede2000(
                xyz_to_lab(apply(x), white),
                xyz_to_lab(apply(moved), white),
            )
            .powi(2);
            let wm = s.error_weights(i, true);
            let quad: f64 = (0..3)
                .map(|a| (0..3).map(|b| e[a] * wm[a][b] * e[b]).sum::<f64>())
                .sum();
            assert!((quad / exact - 1.0).abs() < 0.02, "{quad} {exact}");
            // without a judging matrix the weights are the plain ΔE00 ones
            let plain = ColourSamples {
                judged_through: Vec::new(),
                ..s.clone()
            };
            assert_eq!(plain.error_weights(i, true), delta_e_weights(x, w));
        }
        s.judged_through.pop();
        assert!(level_maps(&s, &[0.1], &noise(), 1.8, &ColourMapFit::default()).is_err());
    }

    #[test]
    fn bad_samples_and_settings_are_refused() {
        let s = ColourSamples::default();
        assert!(least_squares_map(&s).is_err());
        let mut s = exact_samples(&[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        let bad_fit = ColourMapFit {
            averaging_px: Some(0.0),
            perceptual: true,
            loss: ColourLoss::default(),
        };
        assert!(level_maps(&s, &[0.1], &noise(), 1.8, &bad_fit).is_err());
        s.xyz[3][1] = f64::NAN;
        assert!(level_maps(&s, &[0.1], &noise(), 1.8, &ColourMapFit::default()).is_err());
        s.xyz.pop();
        assert!(least_squares_map(&s).is_err());
    }

    /// Each sample's smoothed first-order ΔE00 under `map` (noise-free).
    fn sample_errors(map: &ColourMatrix, s: &ColourSamples) -> Vec<f64> {
        let nc = s.n_channels();
        let m = DVector::from_iterator(
            3 * nc,
            (0..3).flat_map(|k| (0..nc).map(move |c| map.m[c][k])),
        );
        (0..s.len())
            .map(|index| {
                let sample = LevelSample {
                    index,
                    weights: s.error_weights(index, true),
                    variance: vec![0.0; nc],
                };
                let e2 = expected_square_error(&m, nc, s, &sample);
                (e2 + MEAN_LOSS_SMOOTHING * MEAN_LOSS_SMOOTHING).sqrt()
            })
            .collect()
    }

    fn noise_free(loss: ColourLoss) -> ColourMapFit {
        ColourMapFit {
            averaging_px: None,
            perceptual: true,
            loss,
        }
    }

    #[test]
    fn the_mean_loss_lowers_the_mean_error_and_the_squared_loss_the_squared_one() {
        let truth = [[0.6, 0.3, 0.0], [0.3, 0.6, 0.1], [0.05, 0.1, 0.9]];
        let mut s = exact_samples(&truth);
        // a few surfaces no linear map renders: X pushed up by half
        for i in [3, 11, 29] {
            s.xyz[i][0] *= 1.5;
        }
        let fit =
            |loss| level_maps(&s, &[0.5], &noise(), 1.8, &noise_free(loss)).unwrap()[0].clone();
        let mean_map = fit(ColourLoss::MeanDeltaE);
        let squared_map = fit(ColourLoss::SquaredDeltaE);
        let (em, es) = (
            sample_errors(&mean_map, &s),
            sample_errors(&squared_map, &s),
        );
        assert_mean_loss_trade(&em, &es);
        // the outliers move the mean-loss map less
        let dist = |m: &ColourMatrix| {
            (0..3)
                .flat_map(|c| (0..3).map(move |k| (c, k)))
                .map(|(c, k)| (m.m[c][k] - truth[c][k]).abs())
                .fold(0.0, f64::max)
        };
        assert!(
            dist(&mean_map) < dist(&squared_map) / 2.0,
            "{mean_map:?} {squared_map:?}"
        );
    }

    #[test]
    fn the_mean_loss_is_stationary_in_every_lights_mean_error_squared() {
        // two lights that want different maps, with different sample counts
        let truth = [[0.6, 0.3, 0.0], [0.3, 0.6, 0.1], [0.05, 0.1, 0.9]];
        let other = [[0.7, 0.3, 0.0], [0.2, 0.6, 0.2], [0.05, 0.1, 0.8]];
        let mut s = exact_samples(&truth);
        s.light = vec![0; s.len()];
        let b = exact_samples(&other);
        for i in 0..12 {
            s.channels.push(b.channels[i].clone());
            s.xyz.push(b.xyz[i]);
            s.white.push(b.white[i]);
            s.light.push(1);
        }
        let objective = |m: &ColourMatrix| {
            let e = sample_errors(m, &s);
            let mut per_light = [0.0; 2];
            for (i, v) in e.iter().enumerate() {
                per_light[s.light[i]] += v;
            }
            per_light.iter().map(|t| t * t).sum::<f64>()
        };
        let fit =
            |loss| level_maps(&s, &[0.5], &noise(), 1.8, &noise_free(loss)).unwrap()[0].clone();
        let map = fit(ColourLoss::MeanDeltaE);
        let best = objective(&map);
        assert!(best < objective(&fit(ColourLoss::SquaredDeltaE)));
        for c in 0..3 {
            for k in 0..3 {
                for step in [-1e-3, 1e-3] {
                    let mut moved = map.clone();
                    moved.m[c][k] += step;
                    assert!(objective(&moved) > best * (1.0 - 1e-6), "{c} {k} {step}");
                }
            }
        }
        // a light list of the wrong length is refused
        s.light.pop();
        assert!(
            level_maps(
                &s,
                &[0.5],
                &noise(),
                1.8,
                &noise_free(ColourLoss::MeanDeltaE)
            )
            .is_err()
        );
    }
}
