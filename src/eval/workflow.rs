//! Evaluating a rendering method on a simulated chart: simulate the chart
//! under the acquisition illuminant, render with the method, compare with
//! the chart's ideal XYZ under D65.

use serde::{Deserialize, Serialize};

use super::{ChartTruth, DeltaEReport, EvalError, evaluate_chart};
use crate::camera::{Camera, Exposure, NoiseSwitches, simulate};
use crate::colour::Cmfs;
use crate::l3::{
    ColourMatrix, FastRenderer, IlluminantEntry, L3Table, Mosaic, TableKind, fuse_kernels,
    render_baseline,
};
use crate::scene::{Scene, SceneOptions, natural100_or_ces_chart};
use crate::spectral::{Extrapolation, IlluminantSpec, IsetData, cie_illuminant};

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

/// The evaluation chart under an acquisition illuminant: Natural-100 when the
/// ISET data is present, else the CES chart.
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
    let scene = natural100_or_ces_chart(iset, &opts, setup.patch_px)?;
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
    fit_colour_matrix(camera, illuminants, iset, true)
}

/// [`fit_baseline_matrix`], or with every channel when `rgb_only` is false.
pub fn fit_colour_matrix(
    camera: &Camera,
    illuminants: &[String],
    iset: Option<&IsetData>,
    rgb_only: bool,
) -> Result<ColourMatrix, EvalError> {
    let grid = *camera.grid();
    let refl = crate::scene::training_reflectances(&grid, iset)?;
    let cfa = camera.cfa();
    let rgb: Option<Vec<usize>> = ["R", "G", "B"]
        .iter()
        .map(|n| cfa.channel_index(n))
        .collect();
    let used: Vec<usize> = match rgb {
        Some(v) if rgb_only => v,
        _ => (0..cfa.n_channels()).collect(),
    };
    let mut chans = Vec::new();
    let mut xyz = Vec::new();
    for spec in illuminants {
        let named = IlluminantSpec::parse(spec)?.resolve(iset)?;
        let ill = named.spd.resample(&grid, Extrapolation::Zero);
        for (_, r) in &refl {
            let (c, x) = reflectance_response(camera, r, &ill)?;
            chans.push(used.iter().map(|&i| c[i]).collect::<Vec<f64>>());
            xyz.push(x);
        }
    }
    let sub = ColourMatrix::fit(&chans, &xyz)?;
    let mut m = vec![[0.0; 3]; cfa.n_channels()];
    for (k, &i) in used.iter().enumerate() {
        m[i] = sub.m[k];
    }
    Ok(ColourMatrix {
        m,
        n_channels: cfa.n_channels(),
    })
}

/// Noise-free channel volts and volts-equivalent XYZ of a uniform
/// reflectance under `illuminant` (common scale: per unit irradiance and
/// exposure), from the camera's public description.
pub fn reflectance_response(
    camera: &Camera,
    reflectance: &crate::spectral::Spectrum,
    illuminant: &crate::spectral::Spectrum,
) -> Result<(Vec<f64>, [f64; 3]), EvalError> {
    const H: f64 = 6.626_070_15e-34;
    const C: f64 = 299_792_458.0;
    let d = camera.design();
    let grid = camera.grid();
    let e = reflectance.product(illuminant)?;
    let base =
        d.pixel_area_m2() * d.fill_factor * d.conversion_gain_v() * d.analog_gain * grid.step_nm;
    let chans = camera
        .responsivity()
        .iter()
        .map(|resp| {
            (0..grid.n)
                .map(|b| e.values()[b] * grid.wavelength(b) * 1e-9 / (H * C) * resp.values()[b])
                .sum::<f64>()
                * base
        })
        .collect();
    let cmfs = Cmfs::cie1931(grid);
    let xyz = cmfs
        .tristimulus(&e)?
        .map(|v| v / grid.step_nm * base * camera.xyz_scale());
    Ok((chans, xyz))
}
