//! Evaluating a rendering method on a simulated chart: simulate the chart
//! under the acquisition illuminant, render with the method, compare with
//! the chart's ideal XYZ under D65.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::{ChartTruth, DeltaEReport, EvalError, evaluate_chart};
use crate::baseline::{ColourMatrix, Isp, NoiseProfile, render_baseline};
use crate::camera::{Camera, Exposure, NoiseSwitches, simulate};
use crate::l3::L3Table;
use crate::l3::correct::{
    ColourSamples, ColourTarget, IlluminantEntry, colour_samples, same_illuminant_corrections,
};
use crate::l3::render::{ChromaMode, Mosaic};
use crate::l3::table::TableKind;
use crate::scene::{Scene, SceneOptions, macbeth, natural100_chart};
use crate::spectral::{Extrapolation, IlluminantSpec, IsetData, Spectrum, cie_illuminant};

/// A rendering method under evaluation.
pub enum Method<'a> {
    /// An L3 table; SI tables are followed by the correction T (fused).
    Table(&'a L3Table),
    /// Bilinear demosaic + colour matrix (then T).
    Baseline(&'a ColourMatrix),
    /// The strong conventional ISP (its colour matrix then T). With a noise profile, its
    /// denoiser is given the camera's profile at each capture's exposure.
    Isp(&'a Isp),
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
    /// The exposure time relative to auto-exposure (1 = auto; 0.1 = a tenth
    /// of the light, ten times the relative shot and read noise).
    #[serde(default = "one")]
    pub exposure_factor: f64,
    /// The chart: Natural-100 (the paper's) or the Macbeth ColorChecker.
    #[serde(default)]
    pub chart: EvalChart,
    /// Whether L3 renders run the chroma stage ([`ChromaMode`]; `auto` by default).
    #[serde(default)]
    pub chroma_denoise: ChromaMode,
}

/// The chart an evaluation simulates (or reads from a frame).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EvalChart {
    /// Natural-100 and its grey strip (the paper's §3.3).
    #[default]
    Natural100,
    /// ISET's Macbeth ColorChecker, 6 × 4 patches edge to edge (`l3 simulate --scene
    /// macbeth`'s chart); its bottom row (white … black) is the grey category.
    Macbeth,
}

impl std::str::FromStr for EvalChart {
    type Err = EvalError;
    fn from_str(s: &str) -> Result<Self, EvalError> {
        match s.to_ascii_lowercase().replace('-', "").as_str() {
            "natural100" => Ok(EvalChart::Natural100),
            "macbeth" => Ok(EvalChart::Macbeth),
            _ => Err(EvalError::Invalid(format!(
                "chart '{s}': expected natural100 or macbeth"
            ))),
        }
    }
}

impl EvalChart {
    /// Its name in reports.
    pub fn name(self) -> &'static str {
        match self {
            EvalChart::Natural100 => "Natural-100",
            EvalChart::Macbeth => "Macbeth",
        }
    }
}

fn one() -> f64 {
    1.0
}

impl Default for ChartSetup {
    fn default() -> Self {
        Self {
            patch_px: 24,
            mean_luminance: REFERENCE_LUMINANCE,
            exposure_fraction: 0.95,
            seed: 7,
            noise: true,
            exposure_factor: 1.0,
            chart: EvalChart::Natural100,
            chroma_denoise: ChromaMode::Auto,
        }
    }
}

/// The chart luminance (cd/m²) at which auto-exposure reaches the camera's
/// longest exposure time: dimmer charts get that time and less signal.
pub const REFERENCE_LUMINANCE: f64 = 100.0;

/// How much light the evaluation chart gives the sensor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightLevel {
    /// Exposure time relative to auto-exposure, in (0, 1].
    ExposureFactor(f64),
    /// Mean chart luminance in cd/m². Up to [`REFERENCE_LUMINANCE`] the
    /// camera holds its longest exposure (the auto-exposure time at the
    /// reference luminance), so the signal falls with the luminance; above
    /// it, auto-exposure shortens the time and the frame looks as at the
    /// reference.
    SceneLuminance(f64),
}

impl LightLevel {
    /// The exposure factors of the low-light sweep.
    pub const SWEEP: [f64; 4] = [1.0, 0.5, 0.25, 0.1];

    /// Apply to a chart setup, or say why the level is out of range.
    pub fn apply(self, setup: &ChartSetup) -> Result<ChartSetup, EvalError> {
        let mut s = setup.clone();
        match self {
            LightLevel::ExposureFactor(f) => {
                if !(f.is_finite() && f > 0.0 && f <= 1.0) {
                    return Err(EvalError::Invalid(format!(
                        "exposure factor {f}: expected a value in (0, 1] (relative to auto-exposure)"
                    )));
                }
                s.exposure_factor = f;
            }
            LightLevel::SceneLuminance(l) => {
                if !(l.is_finite() && (0.01..=1e5).contains(&l)) {
                    return Err(EvalError::Invalid(format!(
                        "scene luminance {l} cd/m²: expected 0.01 to 100000"
                    )));
                }
                s.mean_luminance = l;
                s.exposure_factor = (l / REFERENCE_LUMINANCE).min(1.0);
            }
        }
        Ok(s)
    }
}

/// The acquisition light's and D65's spectra on `camera`'s grid.
pub(super) fn acquisition_and_d65(
    camera: &Camera,
    acquisition: &str,
    iset: Option<&IsetData>,
) -> Result<(Spectrum, Spectrum), EvalError> {
    let grid = *camera.grid();
    let acq = IlluminantSpec::parse(acquisition)?
        .resolve(iset)?
        .spd
        .resample(&grid, Extrapolation::Zero);
    let d65 = cie_illuminant("D65")
        .ok_or_else(|| EvalError::Invalid("D65 missing from the built-in data".into()))?
        .resample(&grid, Extrapolation::Zero);
    Ok((acq, d65))
}

/// The evaluation chart (`setup.chart`: Natural-100 or the Macbeth chart) under an
/// acquisition illuminant.
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
    let data = IsetData::or_built_in(iset);
    let scene = match setup.chart {
        EvalChart::Natural100 => natural100_chart(data, &opts, setup.patch_px)?,
        EvalChart::Macbeth => macbeth(data, &opts, setup.patch_px)?,
    };
    Ok((scene, named.name))
}

/// The chart simulated once under one acquisition illuminant, with its truth.
#[derive(Clone, Debug)]
pub struct ChartCapture {
    pub scene: Scene,
    /// The acquisition illuminant's resolved name.
    pub acquisition: String,
    /// The raw mosaic in volts, row-major `width × height`.
    pub volts: Vec<f32>,
    pub width: usize,
    pub height: usize,
    pub exposure_s: f64,
    /// Per patch: the ideal (noise-free) XYZ of the same optical image relit
    /// by D65, averaged over the patch interior — what a perfect camera
    /// behind this lens would record. The lens's flare is not the
    /// pipeline's error.
    pub ideal_d65: Vec<crate::colour::Xyz>,
    /// The ideal image itself (interleaved XYZ, `width × height × 3`, the units of
    /// `ideal_d65`), when asked for ([`ChartCapture::with_ideal_image`]): scoring then adds
    /// the render's S-CIELAB against it.
    pub ideal_image: Option<Vec<f32>>,
}

impl ChartCapture {
    /// This capture with its ideal image, so that [`ChartCapture::score`] adds S-CIELAB.
    pub fn with_ideal_image(mut self, camera: &Camera) -> Result<Self, EvalError> {
        self.ideal_image = Some(ideal_d65_image(camera, &self.scene)?);
        Ok(self)
    }

    /// S-CIELAB of a rendered XYZ image against the ideal image, both normalised by their
    /// white patch as the chart evaluation normalises them; `None` without the ideal image or
    /// when its size is not the render's.
    fn s_cielab_mean(&self, xyz: &[f32]) -> Result<Option<f64>, EvalError> {
        let Some(ideal) = self.ideal_image.as_ref().filter(|i| i.len() == xyz.len()) else {
            return Ok(None);
        };
        let patches = &self.scene.patches;
        let wi = super::white_patch_index(patches, &self.ideal_d65);
        let y_true = self.ideal_d65.get(wi).map_or(0.0, |v| v[1]);
        let y_est = super::patch_means(&patches[wi..=wi], xyz, self.width)[0][1];
        if !(y_true > 0.0 && y_est > 0.0) {
            return Ok(None);
        }
        let a: Vec<f64> = ideal.iter().map(|&v| f64::from(v) / y_true).collect();
        let b: Vec<f64> = xyz.iter().map(|&v| f64::from(v) / y_est).collect();
        let opts = super::ScielabOptions::default();
        let s = super::scielab(&a, &b, self.width, self.height, &opts, false)?;
        Ok(Some(s.stats.mean))
    }

    /// Score a rendered XYZ image of this capture.
    pub fn score(
        &self,
        xyz: &[f32],
        method_name: &str,
        context: serde_json::Value,
    ) -> Result<DeltaEReport, EvalError> {
        let truth = ChartTruth {
            name: &self.scene.name,
            patches: &self.scene.patches,
            ideal_d65: &self.ideal_d65,
        };
        let mut report = evaluate_chart(
            &truth,
            xyz,
            self.width,
            self.height,
            &self.acquisition,
            method_name,
            context,
        )?;
        report.s_cielab_mean = self.s_cielab_mean(xyz)?;
        Ok(report)
    }
}

/// Simulate the evaluation chart under `acquisition` as `setup` says (noise,
/// seed, exposure factor).
pub fn simulate_chart(
    camera: &Camera,
    acquisition: &str,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<ChartCapture, EvalError> {
    let (scene, acq_name) = chart_scene(camera, acquisition, iset, setup)?;
    let cap = capture_scene(camera, &scene, setup)?;
    let (height, width) = cap.volts.dim();
    let ideal_d65 = ideal_d65_patch_means(camera, &scene)?;
    Ok(ChartCapture {
        scene,
        acquisition: acq_name,
        volts: cap.volts.into_raw_vec_and_offset().0,
        width,
        height,
        exposure_s: cap.exposure_s,
        ideal_d65,
        ideal_image: None,
    })
}

/// `scene` captured as `setup` says (noise, seed, exposure).
pub fn capture_scene(
    camera: &Camera,
    scene: &Scene,
    setup: &ChartSetup,
) -> Result<crate::camera::Capture, EvalError> {
    let noise = if setup.noise {
        NoiseSwitches::all()
    } else {
        NoiseSwitches::none()
    };
    simulate(
        camera,
        scene,
        Exposure::Scaled {
            target_fraction: setup.exposure_fraction,
            factor: setup.exposure_factor,
        },
        &noise,
        setup.seed,
    )
    .map_err(|e| EvalError::Invalid(e.to_string()))
}

/// Per patch of `scene`: the noise-free XYZ of its optical image relit by D65, averaged over
/// the patch interior: the truth the chart evaluation scores against (in the optical image's
/// units; the evaluation normalises by the white patch).
pub fn ideal_d65_patch_means(
    camera: &Camera,
    scene: &Scene,
) -> Result<Vec<crate::colour::Xyz>, EvalError> {
    Ok(super::report::patch_means(
        &scene.patches,
        &ideal_d65_image(camera, scene)?,
        scene.cols(),
    ))
}

/// The noise-free XYZ image of `scene`'s optical image relit by D65 (interleaved, `cols ×
/// rows × 3`), whose patch means [`ideal_d65_patch_means`] takes.
pub fn ideal_d65_image(camera: &Camera, scene: &Scene) -> Result<Vec<f32>, EvalError> {
    let invalid = |e: crate::camera::CameraError| EvalError::Invalid(e.to_string());
    let d65 = cie_illuminant("D65")
        .ok_or_else(|| EvalError::Invalid("D65 missing".into()))?
        .resample(camera.grid(), Extrapolation::Zero);
    let optical = camera.optical_image(scene).map_err(invalid)?;
    let ideal_img = camera.xyz_rates(&optical, &d65).map_err(invalid)?;
    Ok(ideal_img
        .as_slice()
        .map(<[f32]>::to_vec)
        .unwrap_or_default())
}

/// A captured frame of the evaluation chart (e.g. `l3 simulate --scene natural100`'s mosaic,
/// read from its `.raw` or DNG) in volts, with the truth of the chart `setup` lays out. The
/// frame must have the chart's size; a Macbeth chart's patch size is taken from the frame
/// (6 × 4 patches edge to edge). `acquisition` only labels the report.
pub fn frame_chart_capture(
    camera: &Camera,
    volts: Vec<f32>,
    width: usize,
    height: usize,
    acquisition: &str,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<ChartCapture, EvalError> {
    let mut setup = setup.clone();
    if setup.chart == EvalChart::Macbeth && width.is_multiple_of(6) && height * 6 == width * 4 {
        setup.patch_px = width / 6;
    }
    let (scene, _) = chart_scene(camera, "D65", iset, &setup)?;
    if (scene.cols(), scene.rows()) != (width, height) || volts.len() != width * height {
        return Err(EvalError::Invalid(format!(
            "the frame is {width}×{height} but the {} chart with {} px patches is {}×{} (simulate it with `l3 simulate --scene {}`)",
            setup.chart.name(),
            setup.patch_px,
            scene.cols(),
            scene.rows(),
            serde_json::to_value(setup.chart)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default()
        )));
    }
    let ideal_d65 = ideal_d65_patch_means(camera, &scene)?;
    Ok(ChartCapture {
        scene,
        acquisition: acquisition.to_string(),
        volts,
        width,
        height,
        exposure_s: f64::NAN,
        ideal_d65,
        ideal_image: None,
    })
}

/// Render a mosaic (`width × height`) with `method`, correcting with `correction` (ignored
/// for cross-illuminant tables, whose output is already under D65); a table's render runs
/// the chroma stage as `chroma` says. XYZ out.
pub fn render_method(
    method: &Method,
    correction: &IlluminantEntry,
    volts: &[f32],
    (width, height): (usize, usize),
    cfa: &crate::camera::Cfa,
    chroma: ChromaMode,
) -> Result<Vec<f32>, EvalError> {
    Ok(match method {
        Method::Table(t) => {
            let never = std::sync::atomic::AtomicBool::new(false);
            crate::pipeline::RenderPipeline::new(t, correction)?
                .render_xyz(Mosaic::Volts(volts), width, height, None, chroma, &never)?
                .0
        }
        Method::Baseline(m) => render_baseline(volts, width, height, cfa, &m.then(&correction.t))?,
        Method::Isp(isp) => isp
            .with_matrix(isp.matrix().then(&correction.t))
            .render(volts, width, height, cfa)?,
    })
}

/// The correction `method` renders an evaluation capture with: `correction`, except that a
/// table whose chroma classes balance by the light gets `camera`'s neutral under the
/// correction's light, as a renderer told that light would.
pub fn method_correction<'c>(
    camera: &Camera,
    method: &Method,
    correction: &'c IlluminantEntry,
) -> Result<std::borrow::Cow<'c, IlluminantEntry>, EvalError> {
    Ok(match method {
        Method::Table(t) if t.chroma_balances() && correction.neutral.is_none() => {
            std::borrow::Cow::Owned(crate::l3::correct::with_neutral(camera, correction)?)
        }
        _ => std::borrow::Cow::Borrowed(correction),
    })
}

/// Evaluate `method` on the chart acquired under `acquisition`, correcting
/// with `correction` (ignored for cross-illuminant tables).
pub fn evaluate_method(
    camera: &Camera,
    method: &Method,
    method_name: &str,
    acquisition: &str,
    correction: &IlluminantEntry,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<DeltaEReport, EvalError> {
    let cap = simulate_chart(camera, acquisition, iset, setup)?;
    evaluate_capture(camera, &cap, method, method_name, correction, setup)
}

/// Evaluate `method` on an already simulated chart, with the correction
/// [`method_correction`] gives it.
pub fn evaluate_capture(
    camera: &Camera,
    cap: &ChartCapture,
    method: &Method,
    method_name: &str,
    correction: &IlluminantEntry,
    setup: &ChartSetup,
) -> Result<DeltaEReport, EvalError> {
    let correction = &method_correction(camera, method, correction)?;
    let (at_exposure, isp_method);
    let method = match method {
        Method::Isp(isp) if isp.noise().is_some() => {
            at_exposure = isp.with_noise(Some(NoiseProfile::new(camera, cap.exposure_s)));
            isp_method = Method::Isp(&at_exposure);
            &isp_method
        }
        _ => method,
    };
    let started = std::time::Instant::now();
    let xyz = render_method(
        method,
        correction,
        &cap.volts,
        (cap.width, cap.height),
        camera.cfa(),
        setup.chroma_denoise,
    )?;
    let render_ms = started.elapsed().as_secs_f64() * 1e3;
    let ctx = serde_json::json!({
        "exposure_s": cap.exposure_s,
        "width": cap.width,
        "height": cap.height,
        "render_ms": render_ms,
        "correction": correction.name,
        "setup": setup,
        "sensor": camera.design().name,
    });
    cap.score(&xyz, method_name, ctx)
}

/// The least-squares colour matrix of the conventional baseline for
/// `illuminants`: noise-free channel responses of the natural reflectances
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
        through_correction: false,
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

/// What a colour matrix is fitted on: the natural reflectances under
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
    /// A same-illuminant fit aimed through each light's T
    /// ([`ColourTarget::ThroughCorrection`], as a same-illuminant table's
    /// colour maps are) rather than at XYZ under the light (the paper's
    /// target, [`ColourTarget::UnderLight`]).
    pub through_correction: bool,
}

/// The colour samples of the natural reflectances (the set every colour
/// map and matrix is fitted on, [`crate::scene::natural_reflectances`])
/// under `illuminants` (see
/// [`crate::l3::correct::colour_samples`]), with the white's own samples
/// (`whites`: the perfect white under each light, same normalisation).
fn training_samples(
    camera: &Camera,
    fit: &ColourFit,
    iset: Option<&IsetData>,
) -> Result<(ColourSamples, ColourSamples), EvalError> {
    let illuminants = fit.illuminants;
    let grid = *camera.grid();
    let refl: Vec<Spectrum> = crate::scene::natural_reflectances(&grid, iset)?
        .into_iter()
        .map(|(_, s)| s)
        .collect();
    let spds = illuminants
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
    let err = |e: crate::l3::correct::CorrectError| EvalError::Invalid(e.to_string());
    let corrections = if fit.through_correction {
        same_illuminant_corrections(fit.kind, grid, &refl, &spds).map_err(err)?
    } else {
        Vec::new()
    };
    let target = match fit.kind {
        TableKind::CrossIlluminant => ColourTarget::D65,
        TableKind::SameIlluminant if fit.through_correction => {
            ColourTarget::ThroughCorrection(&corrections)
        }
        TableKind::SameIlluminant => ColourTarget::UnderLight(&[]),
    };
    let samples = |r: &[Spectrum]| colour_samples(camera, &spds, target, &d65, r).map_err(err);
    Ok((samples(&refl)?, samples(&[Spectrum::constant(grid, 1.0)])?))
}

/// [`fit_baseline_matrix`]'s general form: see [`ColourFit`].
pub fn fit_colour_matrix(
    camera: &Camera,
    fit: &ColourFit,
    iset: Option<&IsetData>,
) -> Result<ColourMatrix, EvalError> {
    let (samples, whites) = training_samples(camera, fit, iset)?;
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
        let (wc, wx) = whites
            .channels
            .first()
            .zip(whites.xyz.first())
            .ok_or_else(|| EvalError::Invalid("a colour fit needs an illuminant".into()))?;
        fit_preserving(&chans, &samples.xyz, &pick(wc), *wx)?
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

/// The matching linear map of `table` under the light named `acquisition`:
/// the plain least-squares channel → XYZ map fitted on the same (natural)
/// reflectances, illuminants and target as the table renders that light
/// with, on every channel. A same-illuminant table aims its colour maps
/// through T under the lights it was trained on, and keeps maps aimed at XYZ
/// under the light for every other ([`L3Table::transfers_to`]); so does its
/// matching map.
pub fn matching_linear_map(
    camera: &Camera,
    table: &L3Table,
    acquisition: &str,
    iset: Option<&IsetData>,
) -> Result<ColourMatrix, EvalError> {
    let fit = ColourFit {
        illuminants: &table.meta.train_illuminants,
        kind: table.meta.kind,
        channels: ChannelSet::All,
        preserve_white: false,
        through_correction: !table.transfers_to(acquisition),
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
    // one map in every class: nothing for another light to move its kernels to
    out.meta.params.transfer_maps = None;
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
        for l in 0..table.n_bands() {
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

#[cfg(test)]
mod tests;
