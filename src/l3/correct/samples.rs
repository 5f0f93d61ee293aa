//! The spectral data a table's colour maps and its camera-aware corrections are fitted on
//! ([`ColourSamples`]): noise-free channel responses and target XYZ of the natural
//! reflectances (`scene::natural_reflectances`) under the training illuminants
//! (docs/design.md §5, `src/l3/learn/colour_map.rs`), and the per-light corrections T a same-illuminant table
//! is judged through. The same samples give the evaluation's matching linear map and the
//! conventional baseline's colour matrix, so every comparison is fitted on one set.

use super::CorrectError;
use super::correction::{IDENTITY, IlluminantRegistry, Mat3};
use super::fit::delta_e_weights;
use crate::camera::Camera;
use crate::colour::mat3_mul_vec;
use crate::l3::classify::ChromaClasses;
use crate::l3::table::TableKind;
use crate::spectral::{Spectrum, WavelengthGrid};

/// What a table's colour samples aim at.
#[derive(Clone, Copy, Debug)]
pub enum ColourTarget<'a> {
    /// XYZ under D65, as a cross-illuminant table renders it.
    D65,
    /// XYZ under the sample's own light, as the paper's same-illuminant table
    /// renders it, with each sample's error weighed after its light's
    /// correction T (one per illuminant, in order; empty: as it is). The
    /// maps a same-illuminant table renders a light it was not trained under
    /// with ([`L3Params::transfer_maps`](crate::l3::params::L3Params::transfer_maps)).
    UnderLight(&'a [Mat3]),
    /// A same-illuminant table judged after its light's correction T (one
    /// per illuminant, in order): the target is `T⁻¹ · xyz_D65`, the XYZ
    /// under the light that T takes to the true D65 colour, and every
    /// sample's error is weighed after T ([`ColourSamples::judged_through`]).
    /// The paper fits the table to XYZ under the light and lets T's own
    /// error stand; aiming through T lets the table's colour maps absorb it
    /// wherever the sensor's channels tell apart what T confuses
    /// (`docs/research/aim-through-t.md`).
    ThroughCorrection(&'a [Mat3]),
}

/// Per illuminant, the correction T to D65 that a same-illuminant table's
/// output goes through, fitted on `reflectances` as the registry fits it
/// (the service's and the evaluation's T); empty for a cross table.
pub fn same_illuminant_corrections(
    kind: TableKind,
    grid: WavelengthGrid,
    reflectances: &[Spectrum],
    illuminants: &[Spectrum],
) -> Result<Vec<Mat3>, CorrectError> {
    if kind == TableKind::CrossIlluminant {
        return Ok(Vec::new());
    }
    let registry = IlluminantRegistry::new(grid, reflectances.to_vec())?;
    illuminants
        .iter()
        .map(|spd| registry.correction_for(spd))
        .collect()
}

/// `T⁻¹`, refused when T is singular or not finite.
pub fn inverse_correction(t: &Mat3) -> Result<Mat3, CorrectError> {
    let m = nalgebra::Matrix3::from_fn(|r, c| t[r][c]);
    let inv = m
        .try_inverse()
        .filter(|i| i.iter().all(|v| v.is_finite()))
        .ok_or_else(|| CorrectError::Samples("a light's correction T is singular".into()))?;
    Ok([0, 1, 2].map(|r| [0, 1, 2].map(|c| inv[(r, c)])))
}

/// Noise-free channel responses and XYZ of a set of surfaces, the data every
/// colour map is fitted on. All three lists have one entry per sample; each
/// sample carries the XYZ of the white of its illuminant (same units) for the
/// perceptual weights. Units are arbitrary but common to channels and XYZ.
#[derive(Clone, Debug, Default)]
pub struct ColourSamples {
    pub channels: Vec<Vec<f64>>,
    pub xyz: Vec<[f64; 3]>,
    pub white: Vec<[f64; 3]>,
    /// Per sample, the 3×3 matrix the table's output goes through before it
    /// is judged: a same-illuminant table's correction T to D65. Empty when
    /// the output is judged as it is (a cross table's D65 XYZ).
    pub judged_through: Vec<Mat3>,
    /// Per sample, the index of the illuminant it is lit by (empty: one
    /// light), so that a loss can weigh every light of an ensemble alike.
    pub light: Vec<usize>,
    /// Per illuminant (by [`Self::light`]'s index), the sensor's channel
    /// responses to white under it: what chroma classes balance by
    /// ([`chroma`](crate::l3::classify::chroma)). Empty: the classes' reference light.
    pub neutral: Vec<Vec<f64>>,
}

impl ColourSamples {
    pub fn len(&self) -> usize {
        self.channels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.channels.is_empty()
    }

    /// The samples at `indices`, in that order (every per-sample column kept).
    pub fn subset(&self, indices: &[usize]) -> Self {
        let pick = |v: &[Mat3]| -> Vec<Mat3> {
            if v.is_empty() {
                Vec::new()
            } else {
                indices.iter().map(|&i| v[i]).collect()
            }
        };
        Self {
            channels: indices.iter().map(|&i| self.channels[i].clone()).collect(),
            xyz: indices.iter().map(|&i| self.xyz[i]).collect(),
            white: indices.iter().map(|&i| self.white[i]).collect(),
            judged_through: pick(&self.judged_through),
            light: if self.light.is_empty() {
                Vec::new()
            } else {
                indices.iter().map(|&i| self.light[i]).collect()
            },
            neutral: self.neutral.clone(),
        }
    }

    /// The neutral of sample `i`'s light, when known.
    pub fn neutral_of(&self, i: usize) -> Option<&[f64]> {
        let light = self.light.get(i).copied().unwrap_or(0);
        self.neutral.get(light).map(Vec::as_slice)
    }

    /// The indices of the samples `classes` puts in chroma class `k`, each
    /// balanced by its light's neutral.
    pub fn in_chroma_class(&self, classes: &ChromaClasses, k: usize) -> Vec<usize> {
        (0..self.len())
            .filter(|&i| classes.classify_under(&self.channels[i], self.neutral_of(i)) == k)
            .collect()
    }

    /// Channels per sample (0 when empty).
    pub fn n_channels(&self) -> usize {
        self.channels.first().map(Vec::len).unwrap_or(0)
    }

    /// The weights `W` that make an XYZ error `e` of sample `i` cost
    /// `eᵀ W e` where it is judged: with `perceptual`, its first-order ΔE00²
    /// after [`Self::judged_through`] (`Tᵀ (JᵀQJ at T·xyz, white T·white) T`),
    /// otherwise its squared error relative to the judged white's luminance.
    pub fn error_weights(&self, i: usize, perceptual: bool) -> [[f64; 3]; 3] {
        let t = self.judged_through.get(i).copied().unwrap_or(IDENTITY);
        let apply = |v: [f64; 3]| mat3_mul_vec(&t, v);
        let white = apply(self.white[i]);
        let w = if perceptual {
            delta_e_weights(apply(self.xyz[i]), white)
        } else {
            let y = white[1].max(f64::MIN_POSITIVE);
            [0, 1, 2].map(|k| [0, 1, 2].map(|l| if k == l { 1.0 / (y * y) } else { 0.0 }))
        };
        // Tᵀ W T
        [0, 1, 2].map(|a| {
            [0, 1, 2].map(|b| {
                (0..3)
                    .map(|p| (0..3).map(|q| t[p][a] * w[p][q] * t[q][b]).sum::<f64>())
                    .sum()
            })
        })
    }

    /// The channel count, once the samples are consistent and finite: what every fit on
    /// them checks first.
    pub fn check(&self) -> Result<usize, CorrectError> {
        let nc = self.n_channels();
        let n = self.len();
        if n < nc.max(3) || nc == 0 {
            return Err(CorrectError::InvalidParams(format!(
                "a colour map needs at least {} samples, got {n}",
                nc.max(3)
            )));
        }
        if self.xyz.len() != n
            || self.white.len() != n
            || !(self.judged_through.is_empty() || self.judged_through.len() == n)
            || !(self.light.is_empty() || self.light.len() == n)
        {
            return Err(CorrectError::InvalidParams(
                "colour samples: channel, XYZ, white, correction and light lists differ in length"
                    .into(),
            ));
        }
        if self.channels.iter().any(|c| c.len() != nc) {
            return Err(CorrectError::InvalidParams(
                "colour samples differ in channel count".into(),
            ));
        }
        let finite = self.channels.iter().flatten().all(|v| v.is_finite())
            && self.xyz.iter().flatten().all(|v| v.is_finite())
            && self
                .judged_through
                .iter()
                .flatten()
                .flatten()
                .all(|v| v.is_finite())
            && self
                .white
                .iter()
                .flatten()
                .all(|v| v.is_finite() && *v > 0.0);
        if !finite {
            return Err(CorrectError::InvalidParams(
                "colour samples must be finite, with a positive white".into(),
            ));
        }
        Ok(nc)
    }
}

/// Colour samples of `reflectances` under each of `illuminants` (on the
/// camera's grid), aimed at `target`. D65 targets are scaled so a perfect
/// white keeps its luminance, as the simulation relights a scene at the same
/// mean luminance. Each illuminant's samples are
/// normalised so a perfect white has Y = 1 under it, so an ensemble's plain
/// least-squares map (the matching linear map, the baseline) weighs every
/// illuminant's errors relative to that illuminant's white, as ΔE does and as
/// the colour maps' weights do. (Normalising the white's mean *channel*
/// response instead weighted each light by the square of its white's Y per
/// unit of channel signal: on ISET's RGBW the three-light ensemble's
/// matching map then favoured fluorescent, 7.37 ΔE2000 under it against 8.67
/// now, and lost tungsten, 4.71 against 3.64, noise-free.) Single-illuminant
/// fits do not depend on this scale.
pub fn colour_samples(
    camera: &Camera,
    illuminants: &[Spectrum],
    target: ColourTarget,
    d65: &Spectrum,
    reflectances: &[Spectrum],
) -> Result<ColourSamples, CorrectError> {
    let grid = *camera.grid();
    let white = Spectrum::constant(grid, 1.0);
    let (corrections, aimed) = match target {
        ColourTarget::D65 => (&[][..], false),
        ColourTarget::UnderLight(ts) => (ts, false),
        ColourTarget::ThroughCorrection(ts) => (ts, true),
    };
    if (aimed || !corrections.is_empty()) && corrections.len() != illuminants.len() {
        return Err(CorrectError::Samples(format!(
            "{} corrections for {} illuminants",
            corrections.len(),
            illuminants.len()
        )));
    }
    let inverses: Vec<Mat3> = if aimed {
        corrections
            .iter()
            .map(inverse_correction)
            .collect::<Result<_, _>>()?
    } else {
        Vec::new()
    };
    let mut out = ColourSamples::default();
    for (light, ill) in illuminants.iter().enumerate() {
        let (wc, wx) = camera.reflectance_response(&white, ill)?;
        let (_, wd) = camera.reflectance_response(&white, d65)?;
        let norm = wx[1];
        if !(wc.iter().any(|&v| v > 0.0) && norm.is_finite() && norm > 0.0 && wd[1] > 0.0) {
            return Err(CorrectError::Samples(
                "the sensor does not respond to a white surface under a training illuminant".into(),
            ));
        }
        let relight = wx[1] / wd[1];
        // the target XYZ of a surface whose XYZ is `x` under this light and
        // `d` under D65
        let aim = |x: [f64; 3], d: [f64; 3]| -> [f64; 3] {
            let d = d.map(|v| v * relight);
            match target {
                ColourTarget::D65 => d,
                ColourTarget::UnderLight(_) => x,
                ColourTarget::ThroughCorrection(_) => mat3_mul_vec(&inverses[light], d),
            }
        };
        let target_white = aim(wx, wd);
        for r in reflectances {
            let (c, x) = camera.reflectance_response(r, ill)?;
            let d = match target {
                ColourTarget::UnderLight(_) => x,
                _ => camera.reflectance_response(r, d65)?.1,
            };
            out.channels.push(c.iter().map(|v| v / norm).collect());
            out.xyz.push(aim(x, d).map(|v| v / norm));
            out.white.push(target_white.map(|v| v / norm));
            out.light.push(light);
            if let Some(t) = corrections.get(light) {
                out.judged_through.push(*t);
            }
        }
        out.neutral.push(wc.to_vec());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::baseline::ColourMatrix;
    use crate::spectral::{Extrapolation, cie_illuminant};
    use crate::test_support::paper_camera;

    fn setup() -> (Camera, Vec<Spectrum>, Spectrum, Spectrum) {
        let camera = paper_camera();
        let grid = *camera.grid();
        let refl: Vec<Spectrum> = crate::scene::natural_reflectances(&grid, None)
            .unwrap()
            .into_iter()
            .map(|(_, s)| s)
            .collect();
        let d65 = cie_illuminant("D65")
            .unwrap()
            .resample(&grid, Extrapolation::Zero);
        let a = cie_illuminant("A")
            .unwrap()
            .resample(&grid, Extrapolation::Zero);
        (camera, refl, d65, a)
    }

    #[test]
    fn aiming_through_t_makes_the_samples_t_maps_to_the_d65_truth() {
        let (camera, refl, d65, a) = setup();
        let grid = *camera.grid();
        let lights = [a.clone()];
        let ts =
            same_illuminant_corrections(TableKind::SameIlluminant, grid, &refl, &lights).unwrap();
        assert_eq!(ts.len(), 1);
        assert!(
            same_illuminant_corrections(TableKind::CrossIlluminant, grid, &refl, &lights)
                .unwrap()
                .is_empty()
        );
        let through = colour_samples(
            &camera,
            &lights,
            ColourTarget::ThroughCorrection(&ts),
            &d65,
            &refl,
        )
        .unwrap();
        let cross = colour_samples(&camera, &lights, ColourTarget::D65, &d65, &refl).unwrap();
        let same =
            colour_samples(&camera, &lights, ColourTarget::UnderLight(&ts), &d65, &refl).unwrap();
        let as_is =
            colour_samples(&camera, &lights, ColourTarget::UnderLight(&[]), &d65, &refl).unwrap();
        assert_eq!(through.judged_through, same.judged_through);
        assert_eq!(through.judged_through.len(), refl.len());
        assert!(cross.judged_through.is_empty() && as_is.judged_through.is_empty());
        assert_eq!(same.xyz, as_is.xyz);
        for i in 0..refl.len() {
            // the same channels; T takes the target to the D65 truth
            assert_eq!(through.channels[i], same.channels[i]);
            let judged = mat3_mul_vec(&ts[0], through.xyz[i]);
            for k in 0..3 {
                assert!((judged[k] - cross.xyz[i][k]).abs() < 1e-9, "{i} {k}");
            }
        }
        // the paper's target is not what T reaches: T's own error shows
        let t_error: f64 = (0..refl.len())
            .map(|i| {
                let j = mat3_mul_vec(&ts[0], same.xyz[i]);
                (0..3)
                    .map(|k| (j[k] - cross.xyz[i][k]).powi(2))
                    .sum::<f64>()
            })
            .sum();
        assert!(t_error > 1e-6, "{t_error}");
        // least squares commutes with T: the plain map aimed through T, then
        // T, is the cross-illuminant map
        let m = ColourMatrix::fit(&through.channels, &through.xyz)
            .unwrap()
            .then(&ts[0]);
        let c = ColourMatrix::fit(&cross.channels, &cross.xyz).unwrap();
        for (mc, cc) in m.m.iter().zip(&c.m) {
            for k in 0..3 {
                assert!(
                    (mc[k] - cc[k]).abs() < 1e-6 * (1.0 + cc[k].abs()),
                    "{mc:?} {cc:?}"
                );
            }
        }
    }

    #[test]
    fn aiming_through_t_refuses_a_singular_or_missing_correction() {
        let (camera, refl, d65, a) = setup();
        let lights = [a, d65.clone()];
        let one = [IDENTITY];
        assert!(
            colour_samples(
                &camera,
                &lights,
                ColourTarget::ThroughCorrection(&one),
                &d65,
                &refl
            )
            .is_err()
        );
        let singular = [[[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]; 2];
        assert!(
            colour_samples(
                &camera,
                &lights,
                ColourTarget::ThroughCorrection(&singular),
                &d65,
                &refl
            )
            .is_err()
        );
        assert!(inverse_correction(&[[f64::NAN; 3]; 3]).is_err());
    }
}
