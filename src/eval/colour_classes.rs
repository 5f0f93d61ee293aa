//! What colour classes would buy: the chart's patch-mean ΔE2000 of a
//! cross-illuminant table's colour, predicted from the sensor's filters and
//! noise model without training a table, for a colour map per luminance
//! level (what the trainer fits today, one chroma class) and for a colour
//! map per luminance level *and* chroma class ([`ChromaClasses`]).
//!
//! Why a prediction is enough: a kernel's weights on a uniform patch sum to
//! its level's colour map, so a patch mean rendered by a table is, to first
//! order, that map applied to the patch's channel means, and its noise is
//! the channel means' noise through the map. The study therefore
//! - fits the maps exactly as the trainer fits a cross table's
//!   (`l3::correct::colour_samples` on the natural reflectances, the
//!   trainer's levels, [`CROSS_AVERAGING_PX`], the mean-ΔE loss), once per
//!   chroma class on the class's surfaces;
//! - takes each chart patch's channel means as its surface's ideal
//!   responses, scaled to the volts of a noise-free simulated capture of
//!   the chart (so the exposure, and any `--exposure`, is the simulator's),
//!   and the truth as the surfaces' XYZ under D65 (neither side has the
//!   lens's flare);
//! - draws `captures` noisy captures of those means from the sensor's noise
//!   model (the variance of a mean over the patch interior's pixels of
//!   each channel), classifies each patch's pixels by the chroma of a
//!   5×5-patch mean (drawn with that smaller average's noise, 16 draws per
//!   patch, their estimates averaged as the patch mean averages its
//!   pixels), applies the level's map of each class, and scores the chart
//!   as the evaluation does (both sides normalised by the white patch, grey
//!   strip excluded).
//!
//! With one class it predicts the trained I_Tun within 0.04 on four
//! sensors (`docs/research/chroma-classes.md`). Flare, demosaicking and the kernels' spatial weights
//! are not modelled: the prediction is for the colour maps.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use super::EvalError;
use super::budget::per_patch;
use super::captured_floor::interior_channel_means;
use super::report::{scored_patches, white_patch_index};
use super::workflow::{ChartSetup, acquisition_and_d65, simulate_chart};
use crate::baseline::ColourMatrix;
use crate::camera::Camera;
use crate::colour::{Cmfs, Xyz};
use crate::l3::L3Params;
use crate::l3::classify::{ChromaClasses, MIN_SURFACES_PER_CHANNEL};
use crate::l3::correct::{ColourTarget, NoiseModel, colour_samples, noise_model};
use crate::l3::learn::{band_maps, level_maps};
use crate::l3::params::{CROSS_AVERAGING_PX, ColourLoss, ColourMapFit};
use crate::spectral::{IsetData, Spectrum};

/// Draws of a patch's classification noise (the patch mean averages pixels
/// whose 5×5 neighbourhoods fall in different classes).
const CLASS_DRAWS: usize = 16;

/// The side of the neighbourhood whose chroma classifies a pixel.
const CLASS_PATCH: usize = 5;

/// One row of the study: a number of chroma classes and the chart's error.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ColourClassRow {
    /// The classes asked for.
    pub classes_asked: usize,
    /// The classes kept (fewer when a class held too few surfaces).
    pub classes: usize,
    /// One noisy capture's mean patch-mean ΔE2000, averaged over the captures.
    pub one_capture: f64,
    /// Its standard deviation over the captures.
    pub one_capture_std: f64,
    /// The same maps on the noise-free chart.
    pub noise_free: f64,
}

/// The study of one sensor under one acquisition light.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ColourClassStudy {
    pub acquisition: String,
    pub captures: usize,
    pub seed: u64,
    pub exposure_factor: f64,
    /// Pixels per channel the colour maps are fitted for.
    pub averaging_px: f64,
    pub rows: Vec<ColourClassRow>,
}

/// The chart as the study sees it.
struct Chart {
    /// Per patch, the noise-free channel means in volts.
    volts: Vec<Vec<f64>>,
    /// Per patch and channel, the interior pixels averaged.
    counts: Vec<Vec<usize>>,
    /// Per channel, the pixels of a [`CLASS_PATCH`]² neighbourhood (mean over CFA positions).
    class_counts: Vec<f64>,
    truth: Vec<Xyz>,
    white: usize,
    scored: Vec<bool>,
}

/// Per channel, how many pixels of an `s × s` neighbourhood it has, averaged
/// over the CFA positions.
fn neighbourhood_counts(camera: &Camera, s: usize) -> Vec<f64> {
    let cfa = camera.cfa();
    let mut n = vec![0.0; camera.n_channels()];
    let positions = cfa.rows * cfa.cols;
    for pos in 0..positions {
        let (pr, pc) = (pos / cfa.cols, pos % cfa.cols);
        for dy in 0..s {
            for dx in 0..s {
                if let Some(v) = n.get_mut(cfa.channel_at(pr + dy, pc + dx)) {
                    *v += 1.0 / positions as f64;
                }
            }
        }
    }
    n
}

fn chart(
    camera: &Camera,
    acquisition: &str,
    acq: &Spectrum,
    d65: &Spectrum,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<Chart, EvalError> {
    let noise_free = ChartSetup {
        noise: false,
        ..setup.clone()
    };
    let cap = simulate_chart(camera, acquisition, iset, &noise_free)?;
    let captured = interior_channel_means(camera, &cap);
    let ideal: Vec<Vec<f64>> = cap
        .scene
        .patches
        .iter()
        .map(|p| {
            camera
                .reflectance_response(&p.reflectance, acq)
                .map(|r| r.0)
        })
        .collect::<Result<_, _>>()
        .map_err(|e| EvalError::Invalid(e.to_string()))?;
    // the truth of the surfaces themselves: the capture's own truth carries
    // the lens's flare, which the ideal responses do not
    let cmfs = Cmfs::cie1931(camera.grid());
    let truth: Vec<Xyz> = cap
        .scene
        .patches
        .iter()
        .map(|p| cmfs.reflectance_xyz(&p.reflectance, d65))
        .collect::<Result<_, _>>()?;
    let sum_captured: f64 = captured.iter().flat_map(|(m, _)| m).sum();
    let sum_ideal: f64 = ideal.iter().flatten().sum();
    if !(sum_captured > 0.0 && sum_ideal > 0.0) {
        return Err(EvalError::Invalid(
            "the sensor records no signal from the chart".into(),
        ));
    }
    let scale = sum_captured / sum_ideal;
    Ok(Chart {
        volts: ideal
            .iter()
            .map(|r| r.iter().map(|v| v * scale).collect())
            .collect(),
        counts: captured.into_iter().map(|(_, n)| n).collect(),
        class_counts: neighbourhood_counts(camera, CLASS_PATCH),
        white: white_patch_index(&cap.scene.patches, &truth),
        scored: scored_patches(&cap.scene.patches),
        truth,
    })
}

fn apply(m: &ColourMatrix, c: &[f64]) -> Xyz {
    [0, 1, 2].map(|k| c.iter().zip(&m.m).map(|(v, w)| w[k] * v).sum())
}

/// The nearest level to a luminance statistic (the renderer's rule).
fn level_of(levels: &[f64], lum: f64) -> usize {
    let edges: Vec<f64> = levels.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
    edges.partition_point(|&e| e < lum)
}

/// The study's rows for each count in `class_counts`, on `captures` noisy
/// captures drawn from `setup.seed`.
pub fn colour_class_study(
    camera: &Camera,
    acquisition: &str,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
    class_counts: &[usize],
    captures: usize,
) -> Result<ColourClassStudy, EvalError> {
    if captures == 0 || class_counts.is_empty() || class_counts.contains(&0) {
        return Err(EvalError::Invalid(
            "the colour-class study needs at least one capture and class counts of 1 or more"
                .into(),
        ));
    }
    let grid = *camera.grid();
    let (acq, d65) = acquisition_and_d65(camera, acquisition, iset)?;
    let refl: Vec<Spectrum> = crate::scene::natural_reflectances(&grid, iset)?
        .into_iter()
        .map(|(_, s)| s)
        .collect();
    let samples = colour_samples(
        camera,
        std::slice::from_ref(&acq),
        ColourTarget::D65,
        &d65,
        &refl,
    )?;
    let design = camera.design();
    let noise = noise_model(design);
    let swing = design.voltage_swing_v;
    let levels = L3Params::levels_for(L3Params::default().levels.len(), swing)?;
    let fit = ColourMapFit {
        averaging_px: Some(CROSS_AVERAGING_PX),
        perceptual: true,
        loss: ColourLoss::MeanDeltaE,
    };
    let chart = chart(camera, acquisition, &acq, &d65, iset, setup)?;
    let nc = camera.n_channels();
    let rows = class_counts
        .iter()
        .map(|&k| {
            let classes = ChromaClasses::fit_balanced(
                &samples.channels,
                &samples.light,
                &samples.neutral,
                k,
                MIN_SURFACES_PER_CHANNEL * nc,
                setup.seed,
            )?;
            let pooled = level_maps(&samples, &levels, &noise, swing, &fit)?;
            let maps = band_maps(&samples, &classes, &pooled, &levels, &noise, swing, &fit)?;
            let model = Model {
                chart: &chart,
                classes: &classes,
                maps: &maps,
                levels: &levels,
                noise: &noise,
            };
            let mut rng = ChaCha8Rng::seed_from_u64(setup.seed);
            let means: Vec<f64> = (0..captures)
                .map(|_| model.capture_mean(Some(&mut rng)))
                .collect::<Result<_, _>>()?;
            let one = means.iter().sum::<f64>() / captures as f64;
            let var = means.iter().map(|m| (m - one).powi(2)).sum::<f64>() / captures as f64;
            Ok(ColourClassRow {
                classes_asked: k,
                classes: classes.len(),
                one_capture: one,
                one_capture_std: var.sqrt(),
                noise_free: model.capture_mean(None)?,
            })
        })
        .collect::<Result<Vec<_>, EvalError>>()?;
    Ok(ColourClassStudy {
        acquisition: acquisition.to_string(),
        captures,
        seed: setup.seed,
        exposure_factor: setup.exposure_factor,
        averaging_px: CROSS_AVERAGING_PX,
        rows,
    })
}

/// One class count's maps on the chart.
struct Model<'a> {
    chart: &'a Chart,
    classes: &'a ChromaClasses,
    /// One per band (level × classes + class).
    maps: &'a [ColourMatrix],
    levels: &'a [f64],
    noise: &'a NoiseModel,
}

impl Model<'_> {
    /// The mean ΔE2000 of one capture (`rng`: its noise; `None`: noise-free).
    fn capture_mean(&self, mut rng: Option<&mut ChaCha8Rng>) -> Result<f64, EvalError> {
        let normal =
            Normal::new(0.0, 1.0).map_err(|e| EvalError::Invalid(format!("normal: {e}")))?;
        let c = self.chart;
        let mut draw = |v: f64, n: f64| match rng.as_deref_mut() {
            Some(r) => v + normal.sample(r) * (self.noise.variance(v.max(0.0)) / n.max(1.0)).sqrt(),
            None => v,
        };
        let est: Vec<Xyz> = c
            .volts
            .iter()
            .zip(&c.counts)
            .map(|(v, counts)| {
                let mean: Vec<f64> = v
                    .iter()
                    .zip(counts)
                    .map(|(&x, &n)| draw(x, n as f64))
                    .collect();
                let level = level_of(self.levels, v.iter().sum::<f64>() / v.len().max(1) as f64);
                let draws = if c.class_counts.is_empty() {
                    1
                } else {
                    CLASS_DRAWS
                };
                let mut sum = [0.0; 3];
                for _ in 0..draws {
                    let local: Vec<f64> = v
                        .iter()
                        .zip(&c.class_counts)
                        .map(|(&x, &n)| draw(x, n))
                        .collect();
                    let class = self.classes.classify(&local);
                    let e = apply(&self.maps[level * self.classes.len() + class], &mean);
                    for k in 0..3 {
                        sum[k] += e[k] / draws as f64;
                    }
                }
                sum
            })
            .collect();
        let de = per_patch(&est, &c.truth, c.white);
        let scored: Vec<f64> = de
            .iter()
            .zip(&c.scored)
            .filter(|(_, s)| **s)
            .map(|(d, _)| *d)
            .collect();
        Ok(scored.iter().sum::<f64>() / scored.len().max(1) as f64)
    }
}

/// The study as a markdown table.
pub fn colour_class_markdown(sensor: &str, s: &ColourClassStudy) -> String {
    let mut out = format!(
        "{sensor} under {} ({} captures, seed {}, exposure {}×; colour maps for {} px per channel)\n\n\
         | chroma classes | one capture (std) | noise-free |\n|---|---|---|\n",
        s.acquisition, s.captures, s.seed, s.exposure_factor, s.averaging_px
    );
    for r in &s.rows {
        let kept = if r.classes == r.classes_asked {
            String::new()
        } else {
            format!(" (of {} asked)", r.classes_asked)
        };
        out.push_str(&format!(
            "| {}{kept} | {:.2} ({:.2}) | {:.2} |\n",
            r.classes, r.one_capture, r.one_capture_std, r.noise_free
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::paper_camera as camera;

    #[test]
    fn neighbourhood_counts_cover_the_patch() {
        let n = neighbourhood_counts(&camera(), 5);
        assert_eq!(n.len(), 4);
        assert!((n.iter().sum::<f64>() - 25.0).abs() < 1e-9);
        // a 2×2 CFA: every channel has 25/4 pixels on average
        assert!(n.iter().all(|v| (v - 6.25).abs() < 1e-9), "{n:?}");
    }

    #[test]
    fn levels_follow_the_renderers_nearest_level_rule() {
        let levels = [0.1, 0.2, 0.4];
        assert_eq!(level_of(&levels, 0.0), 0);
        assert_eq!(level_of(&levels, 0.16), 1);
        assert_eq!(level_of(&levels, 0.31), 2);
        assert_eq!(level_of(&levels, 9.0), 2);
    }

    #[test]
    fn classes_lower_the_noise_free_error_and_reproduce_from_the_seed() {
        let setup = ChartSetup::default();
        let study = colour_class_study(&camera(), "Tungsten", None, &setup, &[1, 6], 2).unwrap();
        assert_eq!(study.rows.len(), 2);
        let (one, six) = (&study.rows[0], &study.rows[1]);
        assert_eq!(one.classes, 1);
        assert!(six.classes > 1);
        for r in &study.rows {
            assert!(r.one_capture.is_finite() && r.noise_free.is_finite());
            assert!(r.one_capture > 0.0 && r.noise_free > 0.0);
        }
        assert!(
            six.noise_free < one.noise_free,
            "{} classes {:.3} against one {:.3}",
            six.classes,
            six.noise_free,
            one.noise_free
        );
        let again = colour_class_study(&camera(), "Tungsten", None, &setup, &[6], 2).unwrap();
        assert_eq!(again.rows[0].one_capture, six.one_capture);
        assert!(colour_class_study(&camera(), "Tungsten", None, &setup, &[0], 2).is_err());
        assert!(colour_class_study(&camera(), "Tungsten", None, &setup, &[1], 0).is_err());
    }
}
