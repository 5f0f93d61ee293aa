//! The spectral data a table's colour maps are fitted on: noise-free channel
//! responses and target XYZ of the natural reflectances (`scene::natural_reflectances`) under the training
//! illuminants (DESIGN.md §5, `super::super::l3::colour_map`). The same
//! samples give the evaluation's matching linear map and the conventional
//! baseline's colour matrix, so every comparison is fitted on one set.

use crate::camera::{Camera, SensorDesign};
use crate::l3::{
    ColourLoss, ColourSamples, IlluminantEntry, LevelMap, MIN_SURFACES_PER_CHANNEL, NoiseModel,
    TableKind, camera_correction,
};
use crate::spectral::{Extrapolation, IsetData, Spectrum, cie_illuminant};

use super::TrainError;

/// Colour samples of `reflectances` under each of `illuminants` (on the
/// camera's grid). The target is XYZ under the same illuminant for
/// same-illuminant tables and under `d65` for cross-illuminant ones (scaled
/// so a perfect white keeps its luminance, as the simulation relights a
/// scene at the same mean luminance). Each illuminant's samples are
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
    kind: TableKind,
    d65: &Spectrum,
    reflectances: &[Spectrum],
) -> Result<ColourSamples, TrainError> {
    let grid = *camera.grid();
    let white = Spectrum::constant(grid, 1.0);
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
        let target_white = match kind {
            TableKind::SameIlluminant => wx,
            TableKind::CrossIlluminant => wd.map(|v| v * relight),
        };
        for r in reflectances {
            let (c, x) = camera.reflectance_response(r, ill)?;
            let x = match kind {
                TableKind::SameIlluminant => x,
                TableKind::CrossIlluminant => {
                    camera.reflectance_response(r, d65)?.1.map(|v| v * relight)
                }
            };
            out.channels.push(c.iter().map(|v| v / norm).collect());
            out.xyz.push(x.map(|v| v / norm));
            out.white.push(target_white.map(|v| v / norm));
            out.light.push(light);
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
        TableKind::CrossIlluminant,
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
