//! Camera-aware illuminant correction: the 3×3 matrix C that takes a
//! same-illuminant table's output under an acquisition light to XYZ under
//! D65, fitted on what this table and its sensor actually produce.
//!
//! The paper's correction T ([`correction_matrix`](super::correction_matrix)) maps the *true*
//! XYZ under the acquisition light to XYZ under D65. It assumes the table
//! renders the light's XYZ exactly. A table trained under D65 does not: under
//! another light the sensor's channels move in ways its colour map was never
//! fitted for, and on real filters the error is large (ISET's RGBW under ISET's
//! fluorescent lamp: 15.3 ΔE2000 with T). C instead fits, by least squares
//! over the natural reflectances (`scene::natural_reflectances`),
//!
//! `C · (M · channels_X(r)) ≈ XYZ_D65(r)` (errors weighted by a first-order
//! ΔE00, as the colour maps are),
//!
//! where `M` is the table's own colour map. The fit needs the table's sensor
//! and the light's spectrum; T needs neither.
//!
//! **One C per level.** A table's darker levels have colour maps shrunk for
//! its own light's noise (the trainer's colour maps). Under another light that
//! shrinkage is a colour cast which differs from level to level, and one C
//! fitted on the brightest level's map cannot undo it: rgbw-ar0132at's D65
//! table under the fluorescent lamp gave 2.48 ΔE2000 (8 captures), 9.26 at a
//! tenth of the exposure, dark patches shifted green (a* −5). So C is fitted
//! for every level on that level's map ([`L3Table::level_colour_maps`]) with
//! the noise that map was fitted for (the expected ΔE00² of the level's noise
//! after `C · M` joins the objective, so a dark level's C keeps its map's
//! noise trade instead of undoing it): 1.79 and 2.94 there. The registry
//! still holds one T (and the spectrum) per light; the per-level C (20 × 9
//! numbers per light) is derived from the table and fused into each class's
//! kernel, so rendering costs the same.
//!
//! **The mean ΔE.** [`camera_corrected`] fits C for the light's
//! mean first-order ΔE00 ([`ColourLoss::MeanDeltaE`], the colour maps'
//! reweighted least squares, [`mean_loss_fit`]) rather than its squared
//! sum, whatever loss the table's maps used: C is fitted under one light, so
//! the ensemble concern that keeps their maps squared does not arise. In the
//! six-sensor Table 1 every `+C` row moved by −0.01 to −0.13 (Canon
//! 1.66 → 1.56 under tungsten, Nikon 1.91 → 1.78, rgbw-ar0132at SI_Ens3 2.31
//! → 2.18, rgbw-iset SI_D65 under the lamp 2.00 → 1.94).

use nalgebra::{SMatrix, SVector};

use super::CorrectError;
use super::correction::{IlluminantEntry, MAX_MATRIX_ENTRY, Mat3};
use super::fit::{LevelNoise, NoiseModel, delta_e_weights, mean_loss_fit};
use super::samples::{ColourSamples, ColourTarget, colour_samples};
use crate::baseline::ColourMatrix;
use crate::camera::Camera;
use crate::l3::classify::{ChromaClasses, MIN_SURFACES_PER_CHANNEL};
use crate::l3::params::ColourLoss;
use crate::l3::table::{L3Table, TableError};
use crate::spectral::{Extrapolation, IsetData, Spectrum, cie_illuminant};

impl L3Table {
    /// Every band's colour map (every level's, darkest first, split by
    /// chroma class where the table has them: see [`Self::colour_map_at`]),
    /// with the noise it was fitted for on a sensor with `noise` (none for a
    /// table whose maps were fitted noise-free) and its chroma class.
    pub fn level_colour_maps(&self, noise: &NoiseModel) -> Result<Vec<LevelMap>, TableError> {
        let averaging = self.meta.params.colour_map.and_then(|fit| fit.averaging_px);
        let kc = self.n_chroma();
        let chroma = self.meta.params.chroma.as_ref().filter(|c| c.len() > 1);
        (0..self.n_bands())
            .map(|band| {
                let level_v = self.meta.params.levels[band / kc];
                Ok(LevelMap {
                    map: self.colour_map_at(band)?,
                    noise: averaging.map(|averaging_px| LevelNoise {
                        model: *noise,
                        level_v,
                        swing_v: self.meta.voltage_swing,
                        averaging_px,
                    }),
                    chroma: chroma.map(|c| (c.clone(), band % kc)),
                })
            })
            .collect()
    }

    /// The linear channel → XYZ map this table applies to a uniform,
    /// unsaturated patch of band `level` (a level, or a level's chroma class:
    /// [`Self::n_bands`]): the channel sums of the band's flat, unsaturated
    /// kernels, averaged over CFA positions. The trainer fixes these sums to
    /// the band's colour map.
    pub fn colour_map_at(&self, level: usize) -> Result<ColourMatrix, TableError> {
        let geo = self.geometry()?;
        let nf = self.n_features();
        let nch = geo.n_channels();
        if level >= self.n_bands() {
            return Err(TableError::Unusable(format!(
                "the table has no band {level}"
            )));
        }
        let np = self.n_positions();
        let mut m = vec![[0.0f64; 3]; nch];
        for pos in 0..np {
            let kernel = self.kernel(self.class_index(pos, level, 0, false));
            for (k, out) in kernel.chunks_exact(nf).take(3).enumerate() {
                for (&c, &w) in geo.channels_of(pos).iter().zip(out) {
                    let c = c as usize;
                    if c < nch {
                        m[c][k] += f64::from(w) / np as f64;
                    }
                }
            }
        }
        Ok(ColourMatrix { m, n_channels: nch })
    }
}

/// A colour map a camera-aware correction is fitted on, with the noise it
/// was fitted for (none: noise-free).
#[derive(Clone, Debug)]
pub struct LevelMap {
    pub map: ColourMatrix,
    pub noise: Option<LevelNoise>,
    /// The chroma classes of the table and this map's class: the map is
    /// fitted, and its correction too, on the surfaces of that class only.
    pub chroma: Option<(ChromaClasses, usize)>,
}

/// C = argmin Σ ΔE00²(C · map(channels), xyz), to first order, over `samples`: channel
/// responses under the acquisition light and their target XYZ under D65,
/// relit to the same luminance (the cross-illuminant samples of the training
/// set). `J` is the CIELAB Jacobian at the target colour relative to the
/// sample's white, taken through CIEDE2000's local metric (the norm is
/// `eᵀ Jᵀ Q J e`, see `delta_e_weights`), so the fit minimises a first-order
/// ΔE00, as the trainer's colour maps do; a plain XYZ fit lets bright
/// surfaces decide and costs the dark ones.
///
/// With `noise` (a level's map and the noise it was fitted for), the fit
/// also counts the expected ΔE00² of that noise after `C · map`
/// (`tr(W C M Σ Mᵀ Cᵀ)`, `Σ` the channel-mean variance at the level under
/// this light), so a dark level's C keeps the noise trade its map made
/// instead of undoing it.
pub fn camera_correction(
    map: &ColourMatrix,
    samples: &ColourSamples,
    noise: Option<&LevelNoise>,
    loss: ColourLoss,
) -> Result<Mat3, CorrectError> {
    if samples.n_channels() != map.n_channels || map.m.len() != map.n_channels {
        return Err(CorrectError::InvalidParams(format!(
            "a {}-channel colour map for {}-channel samples",
            map.n_channels,
            samples.n_channels()
        )));
    }
    if samples.len() < 3
        || samples.xyz.len() != samples.len()
        || samples.white.len() != samples.len()
    {
        return Err(CorrectError::InvalidParams(
            "a camera-aware correction needs at least 3 consistent samples".into(),
        ));
    }
    let prepared: Vec<CorrectionSample> = samples
        .channels
        .iter()
        .zip(&samples.xyz)
        .zip(&samples.white)
        .map(|((c, x), w)| CorrectionSample::new(map, c, *x, *w, noise))
        .collect();
    let solve = |weights: &[f64]| solve_correction(&prepared, weights);
    let c = match loss {
        ColourLoss::SquaredDeltaE => solve(&vec![1.0; prepared.len()])?,
        ColourLoss::MeanDeltaE => mean_loss_fit(
            prepared.len(),
            |i| samples.light.get(i).copied().unwrap_or(0),
            solve,
            |c, i| prepared[i].expected_square_error(c),
        )?,
    };
    if c.iter()
        .flatten()
        .any(|v| !v.is_finite() || v.abs() > MAX_MATRIX_ENTRY)
    {
        return Err(CorrectError::Fit(format!(
            "the camera-aware correction is not finite or out of bounds: {c:?}"
        )));
    }
    Ok(c)
}

/// One sample of a correction's fit: the map's output `y`, the target
/// `x`, the error weights at the target and the map's output noise
/// covariance `M Σ Mᵀ` for this sample.
struct CorrectionSample {
    y: [f64; 3],
    x: [f64; 3],
    weights: [[f64; 3]; 3],
    out_cov: [[f64; 3]; 3],
}

impl CorrectionSample {
    fn new(
        map: &ColourMatrix,
        channels: &[f64],
        x: [f64; 3],
        white: [f64; 3],
        noise: Option<&LevelNoise>,
    ) -> Self {
        let y = [0, 1, 2].map(|k| channels.iter().zip(&map.m).map(|(v, col)| v * col[k]).sum());
        let var = noise.map(|n| n.channel_variance(channels));
        let out_cov = [0, 1, 2].map(|p| {
            [0, 1, 2].map(|l| match &var {
                Some(v) => v
                    .iter()
                    .zip(&map.m)
                    .map(|(s2, col)| s2 * col[p] * col[l])
                    .sum(),
                None => 0.0,
            })
        });
        Self {
            y,
            x,
            weights: delta_e_weights(x, white),
            out_cov,
        }
    }

    /// The expected first-order ΔE00² of this sample under `c`: its bias
    /// `eᵀWe` plus its noise `tr(W C M Σ Mᵀ Cᵀ)`.
    fn expected_square_error(&self, c: &Mat3) -> f64 {
        let e = [0, 1, 2].map(|i| (0..3).map(|p| c[i][p] * self.y[p]).sum::<f64>() - self.x[i]);
        let mut total = 0.0;
        for i in 0..3 {
            for k in 0..3 {
                let noise: f64 = (0..3)
                    .map(|p| {
                        (0..3)
                            .map(|l| c[i][p] * self.out_cov[p][l] * c[k][l])
                            .sum::<f64>()
                    })
                    .sum();
                total += self.weights[i][k] * (e[i] * e[k] + noise);
            }
        }
        total
    }
}

/// The weighted normal equations of C (unknowns `C[i][j]` at `3i + j`),
/// solved.
fn solve_correction(
    prepared: &[CorrectionSample],
    sample_weight: &[f64],
) -> Result<Mat3, CorrectError> {
    let mut a = SMatrix::<f64, 9, 9>::zeros();
    let mut b = SVector::<f64, 9>::zeros();
    for (s, &sw) in prepared.iter().zip(sample_weight) {
        for i in 0..3 {
            for k in 0..3 {
                let w = sw * s.weights[i][k];
                for p in 0..3 {
                    for l in 0..3 {
                        a[(3 * i + p, 3 * k + l)] += w * (s.y[p] * s.y[l] + s.out_cov[p][l]);
                    }
                    b[3 * i + p] += w * s.x[k] * s.y[p];
                }
            }
        }
    }
    let floor = (0..9).map(|i| a[(i, i)]).fold(0.0, f64::max) * 1e-12;
    for i in 0..9 {
        a[(i, i)] += floor.max(f64::MIN_POSITIVE);
    }
    let sol = a
        .cholesky()
        .map(|ch| ch.solve(&b))
        .ok_or_else(|| CorrectError::Fit("the camera-aware correction is singular".into()))?;
    Ok([0, 1, 2].map(|i| [0, 1, 2].map(|p| sol[3 * i + p])))
}

/// `entry` with its T replaced by the camera-aware correction C of a
/// same-illuminant table whose colour maps are `maps` (one per band, the
/// brightest level last, each with the noise it was fitted for:
/// [`L3Table::level_colour_maps`]; or one map every level shares),
/// fitted on the natural reflectances under the entry's light (see
/// [`camera_correction`]). `t` is the brightest level's C; with
/// several maps every level also gets its own
/// ([`IlluminantEntry::level_corrections`]). An entry with no spectrum (a
/// correction given as a matrix) is refused.
pub fn camera_corrected(
    camera: &Camera,
    maps: &[LevelMap],
    entry: &IlluminantEntry,
    iset: Option<&IsetData>,
) -> Result<IlluminantEntry, CorrectError> {
    let spd = entry.spd.as_ref().ok_or_else(|| {
        CorrectError::Samples(format!(
            "illuminant '{}' has no spectrum to fit a camera-aware correction on",
            entry.name
        ))
    })?;
    let grid = *camera.grid();
    let refl: Vec<Spectrum> = crate::scene::natural_reflectances(&grid, iset)
        .map_err(|e| CorrectError::Samples(e.to_string()))?
        .into_iter()
        .map(|(_, s)| s)
        .collect();
    let d65 = cie_illuminant("D65")
        .ok_or_else(|| CorrectError::Samples("D65 missing from the built-in data".into()))?
        .resample(&grid, Extrapolation::Zero);
    let samples = colour_samples(
        camera,
        std::slice::from_ref(spd),
        ColourTarget::D65,
        &d65,
        &refl,
    )?;
    let corrections = maps
        .iter()
        .map(|m| {
            // a chroma class's map is corrected on the surfaces the class
            // holds under this light (all of them if too few stay in it)
            let class_samples = m.chroma.as_ref().and_then(|(classes, k)| {
                let idx = samples.in_chroma_class(classes, *k);
                (idx.len() >= MIN_SURFACES_PER_CHANNEL * samples.n_channels())
                    .then(|| samples.subset(&idx))
            });
            let fit_on = class_samples.as_ref().unwrap_or(&samples);
            camera_correction(&m.map, fit_on, m.noise.as_ref(), ColourLoss::MeanDeltaE)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let t = *corrections.last().ok_or_else(|| {
        CorrectError::Samples("a camera-aware correction needs a colour map".into())
    })?;
    with_neutral(
        camera,
        &IlluminantEntry {
            t,
            level_corrections: if corrections.len() > 1 {
                corrections
            } else {
                Vec::new()
            },
            ..entry.clone()
        },
    )
}

/// `entry` with `camera`'s neutral under its light (the channel responses to
/// a white surface, [`IlluminantEntry::neutral`]), which a table's chroma
/// classes balance by; unchanged for an entry with no spectrum.
pub fn with_neutral(
    camera: &Camera,
    entry: &IlluminantEntry,
) -> Result<IlluminantEntry, CorrectError> {
    let neutral = match &entry.spd {
        Some(spd) => {
            let white = Spectrum::constant(*camera.grid(), 1.0);
            Some(camera.reflectance_response(&white, spd)?.0.to_vec())
        }
        None => entry.neutral.clone(),
    };
    Ok(IlluminantEntry {
        neutral,
        ..entry.clone()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4-channel sensor's exact channel → XYZ map, and a correction.
    const TRUTH: [[f64; 3]; 4] = [
        [0.6, 0.3, 0.0],
        [0.3, 0.6, 0.1],
        [0.05, 0.1, 0.9],
        [0.2, 0.2, 0.2],
    ];
    const T: Mat3 = [[1.1, 0.1, -0.05], [0.02, 0.97, 0.01], [-0.03, 0.05, 1.4]];

    /// The map of `truth` as a colour map.
    fn exact_map(truth: &[[f64; 3]]) -> ColourMatrix {
        ColourMatrix {
            m: truth.to_vec(),
            n_channels: truth.len(),
        }
    }

    fn samples_from(truth: &[[f64; 3]], t: &Mat3) -> ColourSamples {
        let mut s = ColourSamples::default();
        for i in 0..30 {
            let c: Vec<f64> = (0..truth.len())
                .map(|k| 0.05 + ((i * 7 + k * 11) % 13) as f64 / 13.0)
                .collect();
            let x = [0, 1, 2].map(|q| (0..c.len()).map(|k| truth[k][q] * c[k]).sum::<f64>());
            let y = [0, 1, 2].map(|r| (0..3).map(|q| t[r][q] * x[q]).sum::<f64>());
            s.channels.push(c);
            s.xyz.push(y);
            s.white.push([0.95, 1.0, 1.09]);
        }
        s
    }

    #[test]
    fn recovers_the_correction_after_an_exact_map() {
        let (truth, t) = (TRUTH, T);
        let map = exact_map(&truth);
        for loss in [ColourLoss::SquaredDeltaE, ColourLoss::MeanDeltaE] {
            let c = camera_correction(&map, &samples_from(&truth, &t), None, loss).unwrap();
            for i in 0..3 {
                for j in 0..3 {
                    assert!((c[i][j] - t[i][j]).abs() < 1e-7, "{loss:?} {c:?}");
                }
            }
        }
    }

    #[test]
    fn the_mean_loss_lowers_the_corrections_mean_error() {
        let (truth, t) = (TRUTH, T);
        let map = exact_map(&truth);
        let mut s = samples_from(&truth, &t);
        // surfaces no 3×3 renders: Z pushed up by 60 %
        for i in [2, 9, 17] {
            s.xyz[i][2] *= 1.6;
        }
        let errors = |c: &Mat3| -> Vec<f64> {
            (0..s.len())
                .map(|i| {
                    CorrectionSample::new(&map, &s.channels[i], s.xyz[i], s.white[i], None)
                        .expected_square_error(c)
                        .sqrt()
                })
                .collect()
        };
        let mean = camera_correction(&map, &s, None, ColourLoss::MeanDeltaE).unwrap();
        let squared = camera_correction(&map, &s, None, ColourLoss::SquaredDeltaE).unwrap();
        let (em, es) = (errors(&mean), errors(&squared));
        crate::l3::correct::assert_mean_loss_trade(&em, &es);
        // the outliers pull the mean-loss C less far from T
        let dist = |c: &Mat3| {
            (0..3)
                .flat_map(|i| (0..3).map(move |j| (i, j)))
                .map(|(i, j)| (c[i][j] - t[i][j]).abs())
                .fold(0.0, f64::max)
        };
        assert!(dist(&mean) < dist(&squared) / 2.0, "{mean:?} {squared:?}");
    }

    #[test]
    fn a_level_map_biased_in_output_space_gets_the_bias_undone() {
        // a darker level's map that renders every colour through a shrink A
        // (desaturated, dimmed): its C is T·A⁻¹, so the level renders as the
        // brightest one does
        let (truth, t) = (TRUTH, T);
        let a = nalgebra::Matrix3::new(0.8, 0.1, 0.05, 0.1, 0.85, 0.05, 0.05, 0.1, 0.75);
        let shrunk: Vec<[f64; 3]> = truth
            .iter()
            .map(|r| {
                let v = a * nalgebra::Vector3::new(r[0], r[1], r[2]);
                [v[0], v[1], v[2]]
            })
            .collect();
        let map = exact_map(&shrunk);
        let c = camera_correction(
            &map,
            &samples_from(&truth, &t),
            None,
            ColourLoss::SquaredDeltaE,
        )
        .unwrap();
        let a_inv = a.try_inverse().unwrap();
        let want = nalgebra::Matrix3::from_fn(|i, j| t[i][j]) * a_inv;
        for i in 0..3 {
            for j in 0..3 {
                assert!(
                    (c[i][j] - want[(i, j)]).abs() < 1e-7,
                    "{c:?} against {want}"
                );
            }
        }
    }

    #[test]
    fn the_noise_term_keeps_a_dark_levels_noise_trade() {
        let (truth, t) = (TRUTH, T);
        let map = exact_map(&truth);
        let s = samples_from(&truth, &t);
        let at = |level_v: f64| LevelNoise {
            model: NoiseModel {
                conversion_gain_v: 1e-4,
                read_noise_v: 1e-3,
                dsnu_v: 5e-4,
                prnu_fraction: 0.005,
            },
            level_v,
            swing_v: 1.8,
            averaging_px: 16.0,
        };
        let clean = camera_correction(&map, &s, None, ColourLoss::SquaredDeltaE).unwrap();
        let bright =
            camera_correction(&map, &s, Some(&at(1.5)), ColourLoss::SquaredDeltaE).unwrap();
        let dark =
            camera_correction(&map, &s, Some(&at(0.002)), ColourLoss::SquaredDeltaE).unwrap();
        // bright: the noise is negligible and C is the noise-free fit
        for i in 0..3 {
            for j in 0..3 {
                assert!((bright[i][j] - clean[i][j]).abs() < 5e-3, "{bright:?}");
            }
        }
        // dark: C trades colour for noise, as the level's map did: it passes
        // less noise than the noise-free C, and its expected ΔE00² (colour
        // error plus noise, computed here independently) is the lower
        let noise = at(0.002);
        let cost = |c: &Mat3| {
            let (mut colour, mut noisy) = (0.0, 0.0);
            for ((ch, x), w) in s.channels.iter().zip(&s.xyz).zip(&s.white) {
                let wm = delta_e_weights(*x, *w);
                let y: [f64; 3] =
                    [0, 1, 2].map(|k| ch.iter().zip(&map.m).map(|(v, col)| v * col[k]).sum());
                let e: [f64; 3] =
                    [0, 1, 2].map(|i| (0..3).map(|p| c[i][p] * y[p]).sum::<f64>() - x[i]);
                colour += (0..3)
                    .map(|i| (0..3).map(|k| e[i] * wm[i][k] * e[k]).sum::<f64>())
                    .sum::<f64>();
                // noise of C·M on each channel, weighted
                for (var, col) in noise.channel_variance(ch).iter().zip(&map.m) {
                    let g: [f64; 3] =
                        [0, 1, 2].map(|i| (0..3).map(|p| c[i][p] * col[p]).sum::<f64>());
                    noisy += var
                        * (0..3)
                            .map(|i| (0..3).map(|k| g[i] * wm[i][k] * g[k]).sum::<f64>())
                            .sum::<f64>();
                }
            }
            (colour, noisy)
        };
        let (dc, dn) = cost(&dark);
        let (cc, cn) = cost(&clean);
        assert!(dn < cn, "noise {dn} against {cn}");
        assert!(dc + dn < cc + cn, "total {} against {}", dc + dn, cc + cn);
        assert!(dark.iter().flatten().all(|v| v.is_finite()));
    }

    #[test]
    fn a_map_for_other_channels_is_refused() {
        let truth = [[0.6, 0.3, 0.0], [0.3, 0.6, 0.1], [0.05, 0.1, 0.9]];
        let s = samples_from(&truth, &crate::l3::correct::IDENTITY);
        let map = ColourMatrix {
            m: vec![[1.0, 0.0, 0.0]; 4],
            n_channels: 4,
        };
        assert!(camera_correction(&map, &s, None, ColourLoss::SquaredDeltaE).is_err());
    }
}
