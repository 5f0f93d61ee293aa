//! Evaluating a rendering method on a simulated chart: simulate the chart
//! under the acquisition illuminant, render with the method, compare with
//! the chart's ideal XYZ under D65.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::{ChartTruth, DeltaEReport, EvalError, evaluate_chart};
use crate::camera::{Camera, Exposure, NoiseSwitches, simulate};
use crate::l3::{
    ColourMatrix, FastRenderer, IlluminantEntry, L3Table, Mosaic, TableKind, fuse_kernels,
    render_baseline,
};
use crate::scene::{Scene, SceneOptions, natural100_chart};
use crate::spectral::{Extrapolation, IlluminantSpec, IsetData, Spectrum, cie_illuminant};
use crate::training::colour_samples;

/// A rendering method under evaluation.
pub enum Method<'a> {
    /// An L3 table; SI tables are followed by the correction T (fused).
    Table(&'a L3Table),
    /// Bilinear demosaic + colour matrix (then T).
    Baseline(&'a ColourMatrix),
}

/// How the chart is simulated.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ChartSetup {
    pub patch_px: usize,
    pub mean_luminance: f64,
    /// Fraction of the swing the auto-exposure puts the brightest region at.
    pub exposure_fraction: f64,
    pub seed: u64,
    pub noise: bool,
}

impl Default for ChartSetup {
    fn default() -> Self {
        Self {
            patch_px: 24,
            mean_luminance: 100.0,
            exposure_fraction: 0.95,
            seed: 7,
            noise: true,
        }
    }
}

/// The evaluation chart under an acquisition illuminant: Natural-100.
pub fn chart_scene(
    camera: &Camera,
    acquisition: &str,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<(Scene, String), EvalError> {
    let named = IlluminantSpec::parse(acquisition)?.resolve(iset)?;
    let grid = *camera.grid();
    let opts = SceneOptions::from_samples(grid, &named.spd, named.name.clone())?
        .with_mean_luminance(setup.mean_luminance);
    let scene = natural100_chart(IsetData::or_built_in(iset), &opts, setup.patch_px)?;
    Ok((scene, named.name))
}

/// Evaluate `method` on the chart acquired under `acquisition`, correcting
/// with `correction` (ignored for cross-illuminant tables, whose output is
/// already under D65).
pub fn evaluate_method(
    camera: &Camera,
    method: &Method,
    method_name: &str,
    acquisition: &str,
    correction: &IlluminantEntry,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<DeltaEReport, EvalError> {
    let (scene, acq_name) = chart_scene(camera, acquisition, iset, setup)?;
    let noise = if setup.noise {
        NoiseSwitches::all()
    } else {
        NoiseSwitches::none()
    };
    let cap = simulate(
        camera,
        &scene,
        Exposure::Auto {
            target_fraction: setup.exposure_fraction,
        },
        &noise,
        setup.seed,
    )
    .map_err(|e| EvalError::Invalid(e.to_string()))?;
    let (h, w) = cap.volts.dim();
    let volts = cap.volts.as_slice().unwrap_or(&[]).to_vec();
    let started = std::time::Instant::now();
    let xyz = match method {
        Method::Table(t) => {
            let kernels = match t.meta.kind {
                TableKind::SameIlluminant => fuse_kernels(t, &correction.t),
                TableKind::CrossIlluminant => t.kernels.clone(),
            };
            FastRenderer::new(t, &kernels)?
                .render_xyz(Mosaic::Volts(&volts), w, h, None)?
                .0
        }
        Method::Baseline(m) => {
            let mt = m.then(&correction.t);
            render_baseline(&volts, w, h, camera.cfa(), &mt)?
        }
    };
    let render_ms = started.elapsed().as_secs_f64() * 1e3;
    // The truth: the ideal (noise-free) XYZ image of the same optical image
    // relit by D65, averaged over each patch interior — what a perfect
    // camera behind this lens would record. The lens's flare is not the
    // pipeline's error.
    let d65 = cie_illuminant("D65")
        .ok_or_else(|| EvalError::Invalid("D65 missing".into()))?
        .resample(camera.grid(), Extrapolation::Zero);
    let optical = camera
        .optical_image(&scene)
        .map_err(|e| EvalError::Invalid(e.to_string()))?;
    let ideal_img = camera
        .xyz_rates(&optical, &d65)
        .map_err(|e| EvalError::Invalid(e.to_string()))?;
    let ideal = super::report::patch_means(&scene.patches, ideal_img.as_slice().unwrap_or(&[]), w);
    let truth = ChartTruth {
        name: &scene.name,
        patches: &scene.patches,
        ideal_d65: &ideal,
    };
    let ctx = serde_json::json!({
        "exposure_s": cap.exposure_s,
        "width": w,
        "height": h,
        "render_ms": render_ms,
        "correction": correction.name,
        "setup": setup,
        "sensor": camera.design().name,
    });
    evaluate_chart(&truth, &xyz, w, h, &acq_name, method_name, ctx)
}

/// The least-squares colour matrix of the conventional baseline for
/// `illuminants`: noise-free channel responses of the training reflectances
/// → their XYZ under the same illuminant (same-illuminant, like an SI
/// table). A conventional pipeline uses a 3×3 matrix on R, G, B: when the
/// CFA has channels named R, G and B only those are used (W gets weight 0);
/// other CFAs use all their channels.
pub fn fit_baseline_matrix(
    camera: &Camera,
    illuminants: &[String],
    iset: Option<&IsetData>,
) -> Result<ColourMatrix, EvalError> {
    let fit = ColourFit {
        illuminants,
        kind: TableKind::SameIlluminant,
        channels: ChannelSet::Rgb,
        preserve_white: false,
    };
    fit_colour_matrix(camera, &fit, iset)
}

/// Which channels a colour matrix uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChannelSet {
    /// R, G and B only (a conventional 3×3), when the CFA has them; every
    /// channel otherwise.
    Rgb,
    /// Every CFA channel.
    All,
}

/// What a colour matrix is fitted on: the training reflectances under
/// `illuminants`, to XYZ under the same light (`SameIlluminant`) or under
/// D65 (`CrossIlluminant`), on `channels`. With `preserve_white` the fit is
/// constrained to map a perfect white exactly (a white-balanced camera
/// matrix, as an ISP's); otherwise it is plain least squares in XYZ.
#[derive(Clone, Debug)]
pub struct ColourFit<'a> {
    pub illuminants: &'a [String],
    pub kind: TableKind,
    pub channels: ChannelSet,
    pub preserve_white: bool,
}

/// [`fit_baseline_matrix`]'s general form: see [`ColourFit`].
pub fn fit_colour_matrix(
    camera: &Camera,
    fit: &ColourFit,
    iset: Option<&IsetData>,
) -> Result<ColourMatrix, EvalError> {
    let grid = *camera.grid();
    let refl: Vec<Spectrum> = crate::scene::training_reflectances(&grid, iset)?
        .into_iter()
        .map(|(_, s)| s)
        .collect();
    let spds = fit
        .illuminants
        .iter()
        .map(|spec| {
            Ok(IlluminantSpec::parse(spec)?
                .resolve(iset)?
                .spd
                .resample(&grid, Extrapolation::Zero))
        })
        .collect::<Result<Vec<_>, EvalError>>()?;
    let d65 = cie_illuminant("D65")
        .ok_or_else(|| EvalError::Invalid("D65 missing".into()))?
        .resample(&grid, Extrapolation::Zero);
    let samples = colour_samples(camera, &spds, fit.kind, &d65, &refl)
        .map_err(|e| EvalError::Invalid(e.to_string()))?;
    let cfa = camera.cfa();
    let rgb: Option<Vec<usize>> = ["R", "G", "B"]
        .iter()
        .map(|n| cfa.channel_index(n))
        .collect();
    let used: Vec<usize> = match (fit.channels, rgb) {
        (ChannelSet::Rgb, Some(v)) => v,
        _ => (0..cfa.n_channels()).collect(),
    };
    let pick = |c: &[f64]| used.iter().map(|&i| c[i]).collect::<Vec<f64>>();
    let chans: Vec<Vec<f64>> = samples.channels.iter().map(|c| pick(c)).collect();
    let mut sub = if fit.preserve_white {
        // the white under the first illuminant: its channels and target XYZ
        let white = Spectrum::constant(grid, 1.0);
        let w = colour_samples(camera, &spds[..1], fit.kind, &d65, &[white])
            .map_err(|e| EvalError::Invalid(e.to_string()))?;
        fit_preserving(&chans, &samples.xyz, &pick(&w.channels[0]), w.xyz[0])?
    } else {
        ColourMatrix::fit(&chans, &samples.xyz)?
    };
    let mut m = vec![[0.0; 3]; cfa.n_channels()];
    for (k, &i) in used.iter().enumerate() {
        m[i] = std::mem::take(&mut sub.m[k]);
    }
    Ok(ColourMatrix {
        m,
        n_channels: cfa.n_channels(),
    })
}

/// Least squares `XYZ = M · c` subject to `M · white_c = white_xyz`.
fn fit_preserving(
    chans: &[Vec<f64>],
    xyz: &[[f64; 3]],
    white_c: &[f64],
    white_xyz: [f64; 3],
) -> Result<ColourMatrix, EvalError> {
    let n = chans.len();
    let nc = white_c.len();
    if n < nc || nc == 0 {
        return Err(EvalError::Invalid(
            "too few samples for a colour matrix".into(),
        ));
    }
    let a = DMatrix::from_fn(n, nc, |i, j| chans[i][j]);
    let ata = a.transpose() * &a;
    let chol = ata
        .cholesky()
        .ok_or_else(|| EvalError::Invalid("the colour matrix fit is singular".into()))?;
    let w = DVector::from_column_slice(white_c);
    let hw = chol.solve(&w);
    let denom = w.dot(&hw);
    if !(denom > 0.0 && denom.is_finite()) {
        return Err(EvalError::Invalid(
            "the white has no channel response".into(),
        ));
    }
    let mut m = vec![[0.0; 3]; nc];
    for k in 0..3 {
        let b = DVector::from_fn(n, |i, _| xyz[i][k]);
        let m0 = chol.solve(&(a.transpose() * b));
        let mk = &m0 - &hw * ((w.dot(&m0) - white_xyz[k]) / denom);
        for c in 0..nc {
            m[c][k] = mk[c];
        }
    }
    Ok(ColourMatrix { m, n_channels: nc })
}

/// The matching linear map of `table`: the plain least-squares channel →
/// XYZ map fitted on the same training reflectances, illuminants and target
/// (same-illuminant or D65) as the table, on every channel.
pub fn matching_linear_map(
    camera: &Camera,
    table: &L3Table,
    iset: Option<&IsetData>,
) -> Result<ColourMatrix, EvalError> {
    let fit = ColourFit {
        illuminants: &table.meta.train_illuminants,
        kind: table.meta.kind,
        channels: ChannelSet::All,
        preserve_white: false,
    };
    fit_colour_matrix(camera, &fit, iset)
}

/// `table` with every class holding `map`: each kernel weighs the patch
/// pixels of channel c by `map[c] / (their count)` with no intercept, so it
/// renders the map applied to the patch's channel means. A valid L3 table
/// that any trained table should match or beat.
pub fn linear_table(table: &L3Table, map: &ColourMatrix) -> Result<L3Table, EvalError> {
    let geo = table.geometry()?;
    let nf = table.n_features();
    let nch = geo.n_channels();
    if map.m.len() != nch {
        return Err(EvalError::Invalid(format!(
            "a {}-channel map for a {nch}-channel table",
            map.m.len()
        )));
    }
    let mut out = table.clone();
    for pos in 0..table.n_positions() {
        let chans = geo.channels_of(pos);
        let mut count = vec![0f64; nch];
        for &c in chans {
            count[c as usize] += 1.0;
        }
        let mut kernel = vec![0f32; 3 * nf];
        for k in 0..3 {
            for (j, &c) in chans.iter().enumerate() {
                let c = c as usize;
                kernel[k * nf + j] = (map.m[c][k] / count[c].max(1.0)) as f32;
            }
        }
        for l in 0..table.n_levels() {
            for s in 0..table.n_sat_cases() {
                for texture in [false, true] {
                    let cl = table.class_index(pos, l, s, texture);
                    out.kernels[cl * 3 * nf..(cl + 1) * 3 * nf].copy_from_slice(&kernel);
                }
            }
        }
    }
    out.validate()?;
    Ok(out)
}
