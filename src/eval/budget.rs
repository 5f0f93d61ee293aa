//! The error budget of a sensor on a chart (docs/design.md §7): what T alone
//! costs, and the best any linear map from the sensor's channels can do.
//! Noise-free and without optics: these are floors, not simulations.

use serde::{Deserialize, Serialize};

use super::workflow::{
    ChannelSet, ChartSetup, ColourFit, acquisition_and_d65, chart_scene, fit_colour_matrix,
};
use super::{ErrorStats, EvalError, summarize};
use crate::baseline::ColourMatrix;
use crate::camera::Camera;
use crate::colour::{Cmfs, D65_WHITE_XYZ, Xyz, ciede2000, mat3_mul_vec, xyz_to_lab};
use crate::l3::correct::IlluminantEntry;
use crate::spectral::IsetData;

/// ΔE2000 statistics of the error budget's rows.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ErrorBudget {
    /// Ideal XYZ under the acquisition illuminant, then T.
    pub t_only: ErrorStats,
    /// The best linear map from channel responses to XYZ under D65, fitted
    /// on the chart itself: no linear pipeline on this sensor beats it.
    pub linear_floor: ErrorStats,
    /// A linear map fitted on the training reflectances under the
    /// acquisition illuminant (same-illuminant), then T: the noise-free
    /// linear analogue of SI_X + T.
    pub linear_si_then_t: ErrorStats,
    /// A linear map fitted on the training reflectances from channels under
    /// the acquisition illuminant to XYZ under D65: the noise-free linear
    /// analogue of a cross-illuminant table (I_X).
    #[serde(default)]
    pub linear_cross: Option<ErrorStats>,
    /// Per patch (chart order, grey strip included): ΔE of T alone, the
    /// linear floor, linear SI + T and linear cross.
    pub per_patch: Vec<Vec<f64>>,
}

/// ΔE2000 of each patch, both sides normalised by their `white` patch's Y
/// and compared in CIELAB with the D65 white (as the evaluation scores).
pub(super) fn per_patch(est: &[Xyz], truth: &[Xyz], white: usize) -> Vec<f64> {
    let (ye, yt) = (est[white][1], truth[white][1]);
    est.iter()
        .zip(truth)
        .map(|(e, t)| {
            ciede2000(
                xyz_to_lab(t.map(|x| x / yt), D65_WHITE_XYZ),
                xyz_to_lab(e.map(|x| x / ye), D65_WHITE_XYZ),
            )
        })
        .collect()
}

fn de_stats(de: &[f64], include: &[bool]) -> ErrorStats {
    let v: Vec<f64> = de
        .iter()
        .zip(include)
        .filter(|(_, i)| **i)
        .map(|(d, _)| *d)
        .collect();
    summarize(&v)
}

/// Compute the budget for `camera` on the evaluation chart under `acquisition`.
pub fn error_budget(
    camera: &Camera,
    acquisition: &str,
    correction: &IlluminantEntry,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<ErrorBudget, EvalError> {
    let (scene, _) = chart_scene(camera, acquisition, iset, setup)?;
    let grid = *camera.grid();
    let cmfs = Cmfs::cie1931(&grid);
    let (acq, d65) = acquisition_and_d65(camera, acquisition, iset)?;
    let patches = &scene.patches;
    let include: Vec<bool> = patches.iter().map(|p| p.category != "grey").collect();
    let white = (0..patches.len())
        .filter(|&i| !include[i])
        .max_by(|&a, &b| {
            let ya = patches[a].reflectance.values().iter().sum::<f64>();
            let yb = patches[b].reflectance.values().iter().sum::<f64>();
            ya.total_cmp(&yb)
        })
        .unwrap_or(0);
    let truth: Vec<Xyz> = patches
        .iter()
        .map(|p| cmfs.reflectance_xyz(&p.reflectance, &d65))
        .collect::<Result<_, _>>()?;
    let under_acq: Vec<Xyz> = patches
        .iter()
        .map(|p| cmfs.reflectance_xyz(&p.reflectance, &acq))
        .collect::<Result<_, _>>()?;
    let t_only: Vec<Xyz> = under_acq
        .iter()
        .map(|x| mat3_mul_vec(&correction.t, *x))
        .collect();
    let chans: Vec<Vec<f64>> = patches
        .iter()
        .map(|p| {
            camera
                .reflectance_response(&p.reflectance, &acq)
                .map(|r| r.0)
                .map_err(|e| EvalError::Invalid(e.to_string()))
        })
        .collect::<Result<_, _>>()?;
    let floor_m = ColourMatrix::fit(&chans, &truth)?;
    let apply = |m: &ColourMatrix, c: &[f64]| -> Xyz {
        [0, 1, 2].map(|k| c.iter().enumerate().map(|(j, v)| m.m[j][k] * v).sum())
    };
    let floor: Vec<Xyz> = chans.iter().map(|c| apply(&floor_m, c)).collect();
    let acq_list = [acquisition.to_string()];
    let si_fit = ColourFit {
        illuminants: &acq_list,
        kind: crate::l3::table::TableKind::SameIlluminant,
        channels: ChannelSet::All,
        preserve_white: false,
        // the paper's SI map: XYZ under the light, then T (T's cost shows)
        through_correction: false,
    };
    let si_m = fit_colour_matrix(camera, &si_fit, iset)?.then(&correction.t);
    let si: Vec<Xyz> = chans.iter().map(|c| apply(&si_m, c)).collect();
    let cross_fit = ColourFit {
        kind: crate::l3::table::TableKind::CrossIlluminant,
        ..si_fit
    };
    let cross_m = fit_colour_matrix(camera, &cross_fit, iset)?;
    let cross: Vec<Xyz> = chans.iter().map(|c| apply(&cross_m, c)).collect();
    let rows = [
        per_patch(&t_only, &truth, white),
        per_patch(&floor, &truth, white),
        per_patch(&si, &truth, white),
        per_patch(&cross, &truth, white),
    ];
    Ok(ErrorBudget {
        t_only: de_stats(&rows[0], &include),
        linear_floor: de_stats(&rows[1], &include),
        linear_si_then_t: de_stats(&rows[2], &include),
        linear_cross: Some(de_stats(&rows[3], &include)),
        per_patch: (0..rows[0].len())
            .map(|i| rows.iter().map(|r| r[i]).collect())
            .collect(),
    })
}
