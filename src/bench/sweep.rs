//! The configurations of the sweep, running them, and the result records.

use std::hint::black_box;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::render::{
    RENDERER, prepare, render_baseline_srgb8, render_baseline_xyz, render_srgb8, render_xyz,
};
use super::skips::{EncoderResult, SkipInputs, SkipResult, run_skips};
use super::{BenchError, pareto_front};
use crate::baseline::ColourMatrix;
use crate::camera::{Camera, NoiseSwitches, SensorDesign, mosaic};
use crate::eval::{
    ChannelSet, ChartCapture, ChartSetup, ColourFit, LightLevel, fit_colour_matrix, simulate_chart,
};
use crate::l3::L3Table;
use crate::l3::correct::{IlluminantEntry, IlluminantRegistry};
use crate::l3::learn::{TrainingSpec, train_table};
use crate::l3::table::TableKind;
use crate::scene::{DeadLeavesParams, SceneOptions, dead_leaves, training_reflectances};
use crate::spectral::{IlluminantSpec, IsetData, WavelengthGrid};

/// Which tables an L3 configuration trains.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TableChoice {
    /// One same-illuminant table on D65 + every acquisition illuminant, then T.
    SiEnsemble,
    /// One cross-illuminant table (→ D65) per acquisition illuminant.
    CrossPerIlluminant,
}

/// One L3 configuration of the sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct L3Config {
    pub name: String,
    pub patch_size: usize,
    pub levels: usize,
    pub contrast_classes: bool,
    pub saturation_classes: bool,
    pub tables: TableChoice,
    /// Chroma classes per level (`TrainingSpec::chroma_classes`; 1: no split).
    #[serde(default = "one")]
    pub chroma_classes: usize,
}

fn one() -> usize {
    1
}

impl L3Config {
    /// The default: patch 5, 20 levels, contrast and saturation classes, SI ensemble + T.
    pub fn default_config() -> Self {
        Self {
            name: "default (5×5, 20 lv, SI+T)".into(),
            patch_size: 5,
            levels: 20,
            contrast_classes: true,
            saturation_classes: true,
            tables: TableChoice::SiEnsemble,
            chroma_classes: 1,
        }
    }

    fn with(name: &str, f: impl FnOnce(&mut Self)) -> Self {
        let mut c = Self::default_config();
        c.name = name.into();
        f(&mut c);
        c
    }
}

/// The full sweep: the default and one change at a time from it.
pub fn default_sweep() -> Vec<L3Config> {
    vec![
        L3Config::default_config(),
        L3Config::with("patch 3", |c| c.patch_size = 3),
        L3Config::with("patch 7", |c| c.patch_size = 7),
        L3Config::with("10 levels", |c| c.levels = 10),
        L3Config::with("40 levels", |c| c.levels = 40),
        L3Config::with("no contrast classes", |c| c.contrast_classes = false),
        L3Config::with("no saturation classes", |c| c.saturation_classes = false),
        L3Config::with("I tables", |c| c.tables = TableChoice::CrossPerIlluminant),
        L3Config::with("4 chroma classes", |c| c.chroma_classes = 4),
        L3Config::with("8 chroma classes", |c| c.chroma_classes = 8),
    ]
}

/// The configurations of the sensor sweep: the default and the I tables,
/// each with one and with 8 chroma classes.
fn sensor_sweep_configs() -> Vec<L3Config> {
    vec![
        L3Config::default_config(),
        L3Config::with("I tables", |c| c.tables = TableChoice::CrossPerIlluminant),
        L3Config::with("8 chroma classes", |c| c.chroma_classes = 8),
        L3Config::with("I tables, 8 chroma classes", |c| {
            c.tables = TableChoice::CrossPerIlluminant;
            c.chroma_classes = 8;
        }),
    ]
}

/// Options of a benchmark run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BenchOptions {
    pub configs: Vec<L3Config>,
    /// Training scenes per table, and their side in pixels.
    pub scenes: usize,
    pub scene_size: usize,
    /// Timed runs per throughput figure (after one untimed warm-up run).
    pub runs: usize,
    pub seed: u64,
    /// The throughput frame (a simulated tile repeated to this size).
    pub frame_width: usize,
    pub frame_height: usize,
    pub tile_width: usize,
    pub tile_height: usize,
    /// Acquisition illuminants of the colour evaluation (tungsten first; the
    /// throughput frame is simulated under the first).
    pub acquisitions: Vec<String>,
    pub chart: ChartSetup,
    /// Exposure factor of the low-light column (relative to auto-exposure).
    #[serde(default = "default_low_light")]
    pub low_light_factor: f64,
    /// Measure the skips and encoders on the default table.
    #[serde(default = "yes")]
    pub skips: bool,
}

fn default_low_light() -> f64 {
    0.1
}

fn yes() -> bool {
    true
}

impl BenchOptions {
    /// The full sweep on a 12 MP (4000×3000) frame, 5 runs, 48 scenes.
    pub fn full() -> Self {
        Self {
            configs: default_sweep(),
            scenes: 48,
            scene_size: 96,
            runs: 5,
            seed: 1,
            frame_width: 4000,
            frame_height: 3000,
            tile_width: 1000,
            tile_height: 750,
            acquisitions: vec!["Tungsten".into(), "Fluorescent".into()],
            chart: ChartSetup::default(),
            low_light_factor: default_low_light(),
            skips: true,
        }
    }

    /// A tiny run for tests: 2 configurations, 6 scenes, a 0.6 MP frame, 2 runs.
    pub fn quick() -> Self {
        let mut o = Self::full();
        o.configs = vec![
            L3Config::default_config(),
            L3Config::with("patch 3", |c| c.patch_size = 3),
        ];
        o.scenes = 6;
        o.scene_size = 48;
        o.runs = 2;
        o.frame_width = 768;
        o.frame_height = 768;
        o.tile_width = 256;
        o.tile_height = 256;
        o
    }

    pub fn validate(&self) -> Result<(), BenchError> {
        let bad = |m: String| Err(BenchError::Invalid(m));
        if self.runs == 0 || self.runs > 1000 {
            return bad(format!("runs {} (1 to 1000)", self.runs));
        }
        if self.frame_width < 16 || self.frame_height < 16 {
            return bad(format!(
                "frame {}×{} (at least 16×16)",
                self.frame_width, self.frame_height
            ));
        }
        if self.frame_width.saturating_mul(self.frame_height) > 100_000_000 {
            return bad("frame larger than 100 Mpix".into());
        }
        if self.tile_width < 16 || self.tile_height < 16 {
            return bad(format!(
                "tile {}×{} (at least 16×16)",
                self.tile_width, self.tile_height
            ));
        }
        if self.acquisitions.is_empty() {
            return bad("no acquisition illuminant".into());
        }
        if !(self.low_light_factor > 0.0 && self.low_light_factor <= 1.0) {
            return bad(format!(
                "low-light exposure factor {} (0 to 1)",
                self.low_light_factor
            ));
        }
        let mut names: Vec<&str> = self.configs.iter().map(|c| c.name.as_str()).collect();
        names.sort_unstable();
        if names.windows(2).any(|w| w[0] == w[1]) {
            return bad("configuration names must be unique".into());
        }
        Ok(())
    }
}

/// The conventional pipelines of the benchmark: bilinear demosaic of every
/// CFA channel and a least-squares colour matrix.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BaselineChoice {
    /// R, G, B → XYZ fitted under the acquisition light, white-balanced.
    AcquisitionRgb,
    /// Every channel → XYZ fitted under the acquisition light, white-balanced.
    AcquisitionAll,
    /// R, G, B → XYZ fitted under D65, then T.
    D65RgbThenT,
}

impl BaselineChoice {
    pub const ALL: [BaselineChoice; 3] = [
        BaselineChoice::AcquisitionRgb,
        BaselineChoice::AcquisitionAll,
        BaselineChoice::D65RgbThenT,
    ];

    /// The row name.
    pub fn name(self) -> &'static str {
        match self {
            BaselineChoice::AcquisitionRgb => "baseline (bilinear + RGB matrix per light)",
            BaselineChoice::AcquisitionAll => "baseline (bilinear + all-channel matrix per light)",
            BaselineChoice::D65RgbThenT => "baseline (bilinear + 3×3 D65 + T)",
        }
    }

    fn label(self, acquisition: &str) -> String {
        match self {
            BaselineChoice::AcquisitionRgb => format!("Baseline_{acquisition}"),
            BaselineChoice::AcquisitionAll => format!("Baseline_{acquisition} all"),
            BaselineChoice::D65RgbThenT => "Baseline+T".into(),
        }
    }

    /// The matrix for `acquisition`, T folded in where the choice uses it.
    fn matrix(
        self,
        camera: &Camera,
        acquisition: &str,
        correction: &IlluminantEntry,
        iset: Option<&IsetData>,
    ) -> Result<ColourMatrix, BenchError> {
        let acq = [acquisition.to_string()];
        let d65 = ["D65".to_string()];
        let (ills, kind, channels) = match self {
            BaselineChoice::AcquisitionRgb => (&acq, TableKind::CrossIlluminant, ChannelSet::Rgb),
            BaselineChoice::AcquisitionAll => (&acq, TableKind::CrossIlluminant, ChannelSet::All),
            BaselineChoice::D65RgbThenT => (&d65, TableKind::SameIlluminant, ChannelSet::Rgb),
        };
        let fit = ColourFit {
            illuminants: ills,
            kind,
            channels,
            preserve_white: kind == TableKind::CrossIlluminant,
            through_correction: false,
        };
        let m = fit_colour_matrix(camera, &fit, iset)?;
        Ok(match kind {
            TableKind::SameIlluminant => m.then(&correction.t),
            TableKind::CrossIlluminant => m,
        })
    }
}

/// What a result row measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConfigKind {
    L3,
    /// Bilinear demosaic + 3×3 colour matrix + T.
    Baseline,
    /// A plain copy of the frame (speed reference; no colour).
    Copy,
}

/// Median wall time of repeated runs at a thread count.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Throughput {
    pub threads: usize,
    pub runs: usize,
    pub median_ms: f64,
    pub ms_per_mpix: f64,
    pub mpix_per_s: f64,
    pub samples_ms: Vec<f64>,
}

impl Throughput {
    fn from_samples(samples_ms: Vec<f64>, threads: usize, mpix: f64) -> Self {
        // A run faster than the clock's resolution still counts as 1 ns.
        let median_ms = median(&samples_ms).max(1e-6);
        Self {
            threads,
            runs: samples_ms.len(),
            median_ms,
            ms_per_mpix: median_ms / mpix,
            mpix_per_s: mpix / (median_ms / 1e3),
            samples_ms,
        }
    }
}

/// Colour error of one configuration on the chart under one illuminant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColourResult {
    pub illuminant: String,
    /// What rendered it (e.g. the I table of this illuminant).
    pub method: String,
    pub mean: f64,
    pub std: f64,
    pub median: f64,
    pub p90: f64,
    pub max: f64,
    /// Mean per-pixel ΔE2000 over patch interiors (noise included).
    pub pixel_mean: f64,
    /// The same at [`BenchOptions::low_light_factor`] of the exposure.
    #[serde(default)]
    pub low_light_pixel_mean: Option<f64>,
}

/// One row of the benchmark.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConfigResult {
    pub name: String,
    pub kind: ConfigKind,
    /// The L3 configuration (None for the baseline and the copy).
    pub config: Option<L3Config>,
    /// Wall time to train every table of the configuration (fit the matrix
    /// for the baseline), seconds; None for the copy.
    pub training_seconds: Option<f64>,
    /// One entry per acquisition illuminant (empty for the copy).
    pub colour: Vec<ColourResult>,
    pub one_thread: Throughput,
    pub all_threads: Throughput,
    /// All-threads time relative to the plain copy's.
    pub time_vs_copy: f64,
}

impl ConfigResult {
    /// The colour result under `illuminant` (case-insensitive).
    pub fn colour_under(&self, illuminant: &str) -> Option<&ColourResult> {
        self.colour
            .iter()
            .find(|c| c.illuminant.eq_ignore_ascii_case(illuminant))
    }
}

/// The throughput frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameInfo {
    pub width: usize,
    pub height: usize,
    pub megapixels: f64,
    pub source: String,
}

/// The whole result (`bench.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BenchReport {
    /// Always [`super::BENCH_SCHEMA`].
    pub schema: String,
    /// Which L3 renderer produced every figure.
    pub renderer: String,
    pub sensor: String,
    pub chart: String,
    pub acquisitions: Vec<String>,
    pub frame: FrameInfo,
    /// Threads of the "all threads" figures.
    pub threads: usize,
    pub configs: Vec<ConfigResult>,
    /// Names on the Pareto front of (ms/Mpix all threads, mean ΔE) per
    /// acquisition illuminant, fastest first.
    pub pareto: Vec<ParetoFront>,
    pub total_seconds: f64,
    pub options: BenchOptions,
    /// The skips of DESIGN.md §9 with and without, on the default table.
    #[serde(default)]
    pub skips: Vec<SkipResult>,
    /// Encodings of the rendered frame.
    #[serde(default)]
    pub encoders: Vec<EncoderResult>,
}

/// The non-dominated configurations under one illuminant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParetoFront {
    pub illuminant: String,
    pub names: Vec<String>,
}

impl BenchReport {
    /// The row named `name`.
    pub fn config(&self, name: &str) -> Option<&ConfigResult> {
        self.configs.iter().find(|c| c.name == name)
    }

    /// The plain-copy row.
    pub fn copy(&self) -> Option<&ConfigResult> {
        self.configs.iter().find(|c| c.kind == ConfigKind::Copy)
    }
}

/// Median of a sample (mean of the middle two for an even count); NaN if empty.
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        (s[n / 2 - 1] + s[n / 2]) / 2.0
    }
}

/// The chart simulated once under one acquisition illuminant, at full
/// exposure and at the low-light exposure.
struct ChartCase {
    name: String,
    correction: IlluminantEntry,
    full: ChartCapture,
    low: ChartCapture,
}

impl ChartCase {
    fn new(
        camera: &Camera,
        acquisition: &str,
        registry: &mut IlluminantRegistry,
        iset: Option<&IsetData>,
        opts: &BenchOptions,
    ) -> Result<Self, BenchError> {
        // the camera's neutral under the light, which balanced chroma classes need
        let correction =
            crate::l3::correct::with_neutral(camera, &registry.resolve(acquisition, iset)?)?;
        let full = simulate_chart(camera, acquisition, iset, &opts.chart)?;
        let low_setup = LightLevel::ExposureFactor(opts.low_light_factor).apply(&opts.chart)?;
        let low = simulate_chart(camera, acquisition, iset, &low_setup)?;
        Ok(Self {
            name: full.acquisition.clone(),
            correction,
            full,
            low,
        })
    }

    /// Render both captures with `render(volts, width, height)` and score them.
    fn evaluate(
        &self,
        method: &str,
        render: impl Fn(&[f32], usize, usize) -> Result<Vec<f32>, BenchError>,
    ) -> Result<ColourResult, BenchError> {
        let score = |cap: &ChartCapture| -> Result<crate::eval::DeltaEReport, BenchError> {
            let xyz = render(&cap.volts, cap.width, cap.height)?;
            Ok(cap.score(&xyz, method, serde_json::Value::Null)?)
        };
        let rep = score(&self.full)?;
        let low = score(&self.low)?;
        Ok(ColourResult {
            illuminant: self.name.clone(),
            method: method.to_string(),
            mean: rep.summary.mean,
            std: rep.summary.std,
            median: rep.summary.median,
            p90: rep.summary.p90,
            max: rep.summary.max,
            pixel_mean: rep.per_pixel.mean,
            low_light_pixel_mean: Some(low.per_pixel.mean),
        })
    }
}

/// A simulated natural frame: a dead-leaves scene of the training
/// reflectances under `illuminant`, through the camera with full noise,
/// tiled to `width × height`.
fn throughput_frame(
    camera: &Camera,
    illuminant: &str,
    iset: Option<&IsetData>,
    opts: &BenchOptions,
) -> Result<(Vec<f32>, FrameInfo), BenchError> {
    let grid = *camera.grid();
    let named = IlluminantSpec::parse(illuminant)?.resolve(iset)?;
    let so = SceneOptions::from_samples(grid, &named.spd, named.name.clone())?;
    let refl: Vec<_> = training_reflectances(&grid, iset)?
        .into_iter()
        .map(|(_, s)| s)
        .collect();
    let params = DeadLeavesParams::new(opts.tile_height, opts.tile_width, opts.seed);
    let scene = dead_leaves(&so, &refl, &params)?;
    let optical = camera.optical_image(&scene)?;
    let rates = camera.channel_rates(&optical)?;
    let mean = mosaic(&rates, camera.cfa())?;
    let t = camera.auto_exposure(&rates, camera.cfa(), 0.95)?;
    let tile = camera.capture(&mean, t, &NoiseSwitches::all(), opts.seed)?;
    let (th, src_w) = tile.dim();
    let tile = tile.into_raw_vec_and_offset().0;
    let (w, h) = (opts.frame_width, opts.frame_height);
    // repeat whole CFA periods so the mosaic stays consistent across seams
    let (pr, pc) = (camera.cfa().rows.max(1), camera.cfa().cols.max(1));
    let (th, tw) = (th / pr * pr, src_w / pc * pc);
    if th == 0 || tw == 0 {
        return Err(BenchError::Invalid("throughput tile is empty".into()));
    }
    let frame: Vec<f32> = (0..w * h)
        .map(|i| tile[((i / w) % th) * src_w + (i % w) % tw])
        .collect();
    let info = FrameInfo {
        width: w,
        height: h,
        megapixels: (w * h) as f64 / 1e6,
        source: format!(
            "dead-leaves scene of the training reflectances under {}, {}×{} simulated with full noise, tiled",
            named.name, tw, th
        ),
    };
    Ok((frame, info))
}

/// Time `f` `runs` times after one warm-up run, in milliseconds.
fn time_runs<T>(
    runs: usize,
    mut f: impl FnMut() -> Result<T, BenchError>,
) -> Result<Vec<f64>, BenchError> {
    black_box(f()?);
    let mut out = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t = Instant::now();
        let v = f()?;
        out.push(t.elapsed().as_secs_f64() * 1e3);
        black_box(v);
    }
    Ok(out)
}

/// Throughput with one thread (a private one-thread pool) and with every
/// thread of the global pool.
fn measure<T: Send>(
    single: &rayon::ThreadPool,
    runs: usize,
    mpix: f64,
    f: impl Fn() -> Result<T, BenchError> + Sync,
) -> Result<(Throughput, Throughput), BenchError> {
    let one = single.install(|| time_runs(runs, &f))?;
    let all = time_runs(runs, &f)?;
    Ok((
        Throughput::from_samples(one, 1, mpix),
        Throughput::from_samples(all, rayon::current_num_threads(), mpix),
    ))
}

fn training_spec(
    c: &L3Config,
    kind: TableKind,
    ills: Vec<String>,
    o: &BenchOptions,
) -> TrainingSpec {
    TrainingSpec {
        kind,
        illuminants: ills,
        patch_size: c.patch_size,
        levels: c.levels,
        seed: o.seed,
        scenes: o.scenes,
        scene_size: o.scene_size,
        contrast_classes: c.contrast_classes,
        saturation_classes: c.saturation_classes,
        chroma_classes: c.chroma_classes,
        ..TrainingSpec::default()
    }
}

/// Run the benchmark. `progress(message)` reports each step.
pub fn run_bench(
    design: &SensorDesign,
    iset: Option<&IsetData>,
    opts: &BenchOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<BenchReport, BenchError> {
    opts.validate()?;
    let started = Instant::now();
    let grid = WavelengthGrid::default();
    let camera = Camera::new(design, grid, iset)?;
    let mut registry = IlluminantRegistry::with_defaults(grid, iset)?;
    let acqs = &opts.acquisitions;
    progress(&format!("simulating the chart under {}", acqs.join(", ")));
    let cases = acqs
        .iter()
        .map(|a| ChartCase::new(&camera, a, &mut registry, iset, opts))
        .collect::<Result<Vec<_>, _>>()?;
    progress(&format!(
        "simulating the {}×{} throughput frame under {}",
        opts.frame_width, opts.frame_height, acqs[0]
    ));
    let (frame, frame_info) = throughput_frame(&camera, &acqs[0], iset, opts)?;
    let (w, h) = (frame_info.width, frame_info.height);
    let mpix = frame_info.megapixels;
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| BenchError::ThreadPool {
            threads: 1,
            msg: e.to_string(),
        })?;
    let cancel = AtomicBool::new(false);
    let mut rows = Vec::new();
    // the table the skips are measured on: the default configuration's (else the first SI one)
    let mut skip_table: Option<(bool, L3Table)> = None;

    // the plain copy first: the reference every row is compared with
    progress("timing a plain copy of the frame");
    let mut buf = vec![0f32; frame.len()];
    let copy_one = {
        let samples = single.install(|| {
            time_runs(opts.runs, || {
                buf.copy_from_slice(black_box(&frame));
                Ok(black_box(buf[buf.len() / 2]))
            })
        })?;
        Throughput::from_samples(samples, 1, mpix)
    };
    // a copy is one memcpy: the "all threads" figure is the same single copy
    let copy_all = {
        let samples = time_runs(opts.runs, || {
            buf.copy_from_slice(black_box(&frame));
            Ok(black_box(buf[buf.len() / 2]))
        })?;
        Throughput::from_samples(samples, rayon::current_num_threads(), mpix)
    };
    drop(buf);
    let copy_ms = copy_all.median_ms;
    rows.push(ConfigResult {
        name: "plain copy".into(),
        kind: ConfigKind::Copy,
        config: None,
        training_seconds: None,
        colour: Vec::new(),
        one_thread: copy_one,
        all_threads: copy_all,
        time_vs_copy: 1.0,
    });

    for c in &opts.configs {
        let t0 = Instant::now();
        // per case: the table it renders with, and its label
        let mut per_case: Vec<(usize, String)> = Vec::new();
        let mut tables: Vec<L3Table> = Vec::new();
        match c.tables {
            TableChoice::SiEnsemble => {
                let ills: Vec<String> = std::iter::once("D65".to_string())
                    .chain(acqs.iter().cloned())
                    .collect();
                progress(&format!(
                    "[{}] training SI table on {}",
                    c.name,
                    ills.join("+")
                ));
                let spec = training_spec(c, TableKind::SameIlluminant, ills.clone(), opts);
                tables.push(train_table(design, &spec, iset, &|_, _| {}, &cancel)?);
                let is_default = c.name == L3Config::default_config().name;
                if skip_table.as_ref().is_none_or(|(d, _)| !d && is_default) {
                    skip_table = Some((is_default, tables[0].clone()));
                }
                for _ in &cases {
                    per_case.push((0, format!("SI_{}+T", ills.join("+"))));
                }
            }
            TableChoice::CrossPerIlluminant => {
                for (i, case) in cases.iter().enumerate() {
                    progress(&format!("[{}] training I table for {}", c.name, case.name));
                    let spec =
                        training_spec(c, TableKind::CrossIlluminant, vec![acqs[i].clone()], opts);
                    tables.push(train_table(design, &spec, iset, &|_, _| {}, &cancel)?);
                    per_case.push((i, format!("I_{}", case.name)));
                }
            }
        }
        let training_seconds = t0.elapsed().as_secs_f64();
        let mut colour = Vec::new();
        for (case, (ti, label)) in cases.iter().zip(&per_case) {
            progress(&format!("[{}] ΔE under {}", c.name, case.name));
            let renderer = prepare(&tables[*ti], &case.correction)?;
            colour.push(case.evaluate(label, |v, w, h| Ok(render_xyz(&renderer, v, w, h)?))?);
        }
        progress(&format!(
            "[{}] timing {} runs on {:.1} Mpix",
            c.name, opts.runs, mpix
        ));
        let (ti, _) = &per_case[0];
        let renderer = prepare(&tables[*ti], &cases[0].correction)?;
        let (one, all) = measure(&single, opts.runs, mpix, || {
            Ok(render_srgb8(&renderer, &frame, w, h)?)
        })?;
        rows.push(ConfigResult {
            name: c.name.clone(),
            kind: ConfigKind::L3,
            config: Some(c.clone()),
            training_seconds: Some(training_seconds),
            colour,
            time_vs_copy: all.median_ms / copy_ms,
            one_thread: one,
            all_threads: all,
        });
    }

    for b in BaselineChoice::ALL {
        progress(&format!("[baseline] fitting {}", b.name()));
        let t0 = Instant::now();
        // one matrix per case, T folded in where the choice uses T
        let matrices = cases
            .iter()
            .map(|case| b.matrix(&camera, &case.name, &case.correction, iset))
            .collect::<Result<Vec<_>, BenchError>>()?;
        let training_seconds = t0.elapsed().as_secs_f64();
        let cfa = camera.cfa();
        let mut colour = Vec::new();
        for (case, m) in cases.iter().zip(&matrices) {
            colour.push(case.evaluate(&b.label(&case.name), |v, w, h| {
                Ok(render_baseline_xyz(v, w, h, cfa, m)?)
            })?);
        }
        progress(&format!("[baseline] timing {} runs", opts.runs));
        let m0 = &matrices[0];
        let (one, all) = measure(&single, opts.runs, mpix, || {
            Ok(render_baseline_srgb8(&frame, w, h, cfa, m0)?)
        })?;
        rows.push(ConfigResult {
            name: b.name().into(),
            kind: ConfigKind::Baseline,
            config: None,
            training_seconds: Some(training_seconds),
            colour,
            time_vs_copy: all.median_ms / copy_ms,
            one_thread: one,
            all_threads: all,
        });
    }

    let pareto = cases
        .iter()
        .map(|case| {
            let pts: Vec<(usize, (f64, f64))> = rows
                .iter()
                .enumerate()
                .filter_map(|(i, r)| {
                    r.colour_under(&case.name)
                        .map(|c| (i, (r.all_threads.ms_per_mpix, c.mean)))
                })
                .collect();
            let xy: Vec<(f64, f64)> = pts.iter().map(|p| p.1).collect();
            ParetoFront {
                illuminant: case.name.clone(),
                names: pareto_front(&xy)
                    .into_iter()
                    .map(|k| rows[pts[k].0].name.clone())
                    .collect(),
            }
        })
        .collect();
    let (skips, encoders) = match skip_table.as_ref().filter(|_| opts.skips) {
        Some((_, table)) => run_skips(
            &SkipInputs {
                table,
                t: cases[0].correction.t,
                frame: &frame,
                width: w,
                height: h,
                runs: opts.runs,
            },
            progress,
        )?,
        None => (Vec::new(), Vec::new()),
    };
    Ok(BenchReport {
        skips,
        encoders,
        schema: super::BENCH_SCHEMA.into(),
        renderer: RENDERER.into(),
        sensor: design.name.clone(),
        chart: cases[0].full.scene.name.clone(),
        acquisitions: cases.iter().map(|c| c.name.clone()).collect(),
        frame: frame_info,
        threads: rayon::current_num_threads(),
        configs: rows,
        pareto,
        total_seconds: started.elapsed().as_secs_f64(),
        options: opts.clone(),
    })
}

/// The benchmark's sensor sweep: the default configuration on each sensor.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SensorSweep {
    /// Always [`super::BENCH_SCHEMA`].
    pub schema: String,
    pub reports: Vec<BenchReport>,
    pub total_seconds: f64,
}

/// Run the default L3 configuration (SI ensemble + T), the I tables and the
/// baselines on every sensor (no skips), so that a regression on any sensor
/// shows in one run.
pub fn run_sensor_sweep(
    designs: &[SensorDesign],
    iset: Option<&IsetData>,
    opts: &BenchOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<SensorSweep, BenchError> {
    if designs.is_empty() {
        return Err(BenchError::Invalid(
            "the sensor sweep needs a sensor".into(),
        ));
    }
    let started = Instant::now();
    let mut o = opts.clone();
    o.configs = sensor_sweep_configs();
    o.skips = false;
    let reports = designs
        .iter()
        .map(|d| run_bench(d, iset, &o, &|m| progress(&format!("[{}] {m}", d.name))))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(SensorSweep {
        schema: super::BENCH_SCHEMA.into(),
        reports,
        total_seconds: started.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_and_options() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
        let t = Throughput::from_samples(vec![20.0, 10.0, 30.0], 1, 2.0);
        assert_eq!(t.median_ms, 20.0);
        assert_eq!(t.ms_per_mpix, 10.0);
        assert_eq!(t.mpix_per_s, 100.0);
        assert!(BenchOptions::full().validate().is_ok());
        assert!(BenchOptions::quick().validate().is_ok());
        let mut o = BenchOptions::quick();
        o.runs = 0;
        assert!(o.validate().is_err());
        let mut o = BenchOptions::quick();
        o.configs.push(o.configs[0].clone());
        assert!(o.validate().is_err());
        let sweep = default_sweep();
        assert_eq!(sweep.len(), 10);
        // one change at a time from the default
        let d = &sweep[0];
        for c in &sweep[1..] {
            let changes = [
                c.patch_size != d.patch_size,
                c.levels != d.levels,
                c.contrast_classes != d.contrast_classes,
                c.saturation_classes != d.saturation_classes,
                c.tables != d.tables,
                c.chroma_classes != d.chroma_classes,
            ];
            assert_eq!(changes.iter().filter(|&&x| x).count(), 1, "{}", c.name);
        }
        // the sensor sweep: the default and the I tables, with and without chroma classes
        let sensors = sensor_sweep_configs();
        assert_eq!(sensors[0], *d);
        assert!(
            sensors
                .iter()
                .all(|c| c.patch_size == d.patch_size && c.levels == d.levels)
        );
        let kinds: Vec<_> = sensors
            .iter()
            .map(|c| (c.tables, c.chroma_classes))
            .collect();
        assert_eq!(kinds.len(), 4);
        assert!(kinds.contains(&(TableChoice::CrossPerIlluminant, 8)));
    }
}
