//! The spectral data a table's colour maps are fitted on: noise-free channel
//! responses and target XYZ of the natural reflectances (`scene::natural_reflectances`) under the training
//! illuminants (DESIGN.md §5, `super::super::l3::colour_map`). The same
//! samples give the evaluation's matching linear map and the conventional
//! baseline's colour matrix, so every comparison is fitted on one set.

use crate::camera::{Camera, SensorDesign};
use crate::colour::mat3_mul_vec;
use crate::l3::{
    ColourLoss, ColourSamples, IlluminantEntry, IlluminantRegistry, LevelMap,
    MIN_SURFACES_PER_CHANNEL, Mat3, NoiseModel, TableKind, camera_correction,
};
use crate::spectral::{Extrapolation, IsetData, Spectrum, WavelengthGrid, cie_illuminant};

use super::TrainError;

/// What a table's colour samples aim at.
#[derive(Clone, Copy, Debug)]
pub enum ColourTarget<'a> {
    /// XYZ under D65, as a cross-illuminant table renders it.
    D65,
    /// XYZ under the sample's own light, as the paper's same-illuminant table
    /// renders it, with each sample's error weighed after its light's
    /// correction T (one per illuminant, in order; empty: as it is). The
    /// maps a same-illuminant table renders a light it was not trained under
    /// with ([`crate::l3::L3Params::transfer_maps`]).
    UnderLight(&'a [Mat3]),
    /// A same-illuminant table judged after its light's correction T (one
    /// per illuminant, in order): the target is `T⁻¹ · xyz_D65`, the XYZ
    /// under the light that T takes to the true D65 colour, and every
    /// sample's error is weighed after T ([`ColourSamples::judged_through`]).
    /// The paper fits the table to XYZ under the light and lets T's own
    /// error stand; aiming through T lets the table's colour maps absorb it
    /// wherever the sensor's channels tell apart what T confuses (see the
    /// README, "Same-illuminant tables aimed through T").
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
) -> Result<Vec<Mat3>, TrainError> {
    if kind == TableKind::CrossIlluminant {
        return Ok(Vec::new());
    }
    let registry = IlluminantRegistry::new(grid, reflectances.to_vec())?;
    illuminants
        .iter()
        .map(|spd| Ok(registry.correction_for(spd)?))
        .collect()
}

/// `T⁻¹`, refused when T is singular or not finite.
pub fn inverse_correction(t: &Mat3) -> Result<Mat3, TrainError> {
    let m = nalgebra::Matrix3::from_fn(|r, c| t[r][c]);
    let inv = m
        .try_inverse()
        .filter(|i| i.iter().all(|v| v.is_finite()))
        .ok_or_else(|| TrainError::Invalid("a light's correction T is singular".into()))?;
    Ok([0, 1, 2].map(|r| [0, 1, 2].map(|c| inv[(r, c)])))
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
) -> Result<ColourSamples, TrainError> {
    let grid = *camera.grid();
    let white = Spectrum::constant(grid, 1.0);
    let (corrections, aimed) = match target {
        ColourTarget::D65 => (&[][..], false),
        ColourTarget::UnderLight(ts) => (ts, false),
        ColourTarget::ThroughCorrection(ts) => (ts, true),
    };
    if (aimed || !corrections.is_empty()) && corrections.len() != illuminants.len() {
        return Err(TrainError::Invalid(format!(
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
            return Err(TrainError::Invalid(
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

/// `entry` with its T replaced by the camera-aware correction C of a
/// same-illuminant table whose colour maps are `maps` (one per band, the
/// brightest level last, each with the noise it was fitted for:
/// [`crate::l3::L3Table::level_colour_maps`]; or one map every level shares),
/// fitted on the natural reflectances under the entry's light (see
/// `crate::l3::camera_correction`). `t` is the brightest level's C; with
/// several maps every level also gets its own
/// ([`IlluminantEntry::level_corrections`]). An entry with no spectrum (a
/// correction given as a matrix) is refused.
pub fn camera_corrected(
    camera: &Camera,
    maps: &[LevelMap],
    entry: &IlluminantEntry,
    iset: Option<&IsetData>,
) -> Result<IlluminantEntry, TrainError> {
    let spd = entry.spd.as_ref().ok_or_else(|| {
        TrainError::Invalid(format!(
            "illuminant '{}' has no spectrum to fit a camera-aware correction on",
            entry.name
        ))
    })?;
    let grid = *camera.grid();
    let refl: Vec<Spectrum> = crate::scene::natural_reflectances(&grid, iset)
        .map_err(|e| TrainError::Invalid(e.to_string()))?
        .into_iter()
        .map(|(_, s)| s)
        .collect();
    let d65 = cie_illuminant("D65")
        .ok_or_else(|| TrainError::Invalid("D65 missing from the built-in data".into()))?
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
        TrainError::Invalid("a camera-aware correction needs a colour map".into())
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
) -> Result<IlluminantEntry, TrainError> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::l3::ColourMatrix;
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
        let one = [crate::l3::IDENTITY];
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
