//! Running the benchmark: the chart under each light, the throughput frame, every
//! configuration's tables, colour error and throughput, the conventional pipelines (the
//! bilinear baselines and the strong ISP) and the skips.

use std::hint::black_box;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use super::BenchError;
use super::plot::pareto_front;
use super::records::{
    BenchReport, ColourResult, ConfigKind, ConfigResult, FrameInfo, FrontMetric, ParetoFront,
    SensorSweep, Throughput,
};
use super::render::{
    RENDERER, prepare, render_baseline_srgb8, render_baseline_xyz, render_isp_srgb8, render_srgb8,
    render_xyz,
};
use super::report::BENCH_SCHEMA;
use super::skips::{EncoderResult, SkipInputs, SkipResult, run_skips};
use super::stats::time_runs;
use super::sweep::{BaselineChoice, BenchOptions, L3Config, TableChoice, sensor_sweep_configs};
use crate::baseline::{ColourMatrix, Isp, NoiseProfile};
use crate::camera::{Camera, NoiseSwitches, SensorDesign, mosaic};
use crate::eval::{
    ChartCapture, ChartSetup, DeltaEReport, EvalError, LightLevel, Method, SPATIAL_SIZE,
    SpatialCaptures, SpatialScore, evaluate_capture, simulate_chart, simulate_spatial,
};
use crate::l3::L3Table;
use crate::l3::correct::{IDENTITY, with_neutral};
use crate::l3::correct::{IlluminantEntry, IlluminantRegistry};
use crate::l3::learn::{TrainingSpec, train_table};
use crate::l3::table::TableKind;
use crate::scene::{DeadLeavesParams, SceneOptions, dead_leaves, training_reflectances};
use crate::spectral::{IlluminantSpec, IsetData, WavelengthGrid};

/// The chart simulated once under one acquisition illuminant, at full
/// exposure and at the low-light exposure.
struct ChartCase {
    name: String,
    correction: IlluminantEntry,
    full: ChartCapture,
    low: ChartCapture,
    /// The slanted edge and the texture at both exposures.
    spatial_full: SpatialCaptures,
    spatial_low: SpatialCaptures,
    /// The set-ups of the full and the low-light captures.
    setups: [ChartSetup; 2],
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
        let correction = with_neutral(camera, &registry.resolve(acquisition, iset)?)?;
        let full =
            simulate_chart(camera, acquisition, iset, &opts.chart)?.with_ideal_image(camera)?;
        let low_setup = LightLevel::ExposureFactor(opts.low_light_factor).apply(&opts.chart)?;
        let low =
            simulate_chart(camera, acquisition, iset, &low_setup)?.with_ideal_image(camera)?;
        let spatial = |setup| simulate_spatial(camera, acquisition, iset, setup, SPATIAL_SIZE);
        Ok(Self {
            name: full.acquisition.clone(),
            correction,
            spatial_full: spatial(&opts.chart)?,
            spatial_low: spatial(&low_setup)?,
            setups: [opts.chart.clone(), low_setup],
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
        let in_eval = |v: &[f32], w: usize, h: usize| {
            render(v, w, h).map_err(|e| EvalError::Invalid(e.to_string()))
        };
        self.score(
            method,
            |cap, _| {
                let xyz = render(&cap.volts, cap.width, cap.height)?;
                Ok(cap.score(&xyz, method, serde_json::Value::Null)?)
            },
            |spatial| Ok(spatial.score_with(in_eval)?),
        )
    }

    /// Score `method` under `correction` as the evaluation does ([`evaluate_capture`], which
    /// has the strong ISP denoise by the noise model at each capture's exposure, and
    /// [`SpatialCaptures::score`]).
    fn evaluate_method(
        &self,
        camera: &Camera,
        name: &str,
        method: &Method,
        correction: &IlluminantEntry,
    ) -> Result<ColourResult, BenchError> {
        self.score(
            name,
            |cap, setup| {
                Ok(evaluate_capture(
                    camera, cap, method, name, correction, setup,
                )?)
            },
            |spatial| Ok(spatial.score(camera, method, correction)?),
        )
    }

    /// Score both captures with `chart(capture, its set-up)` and `spatial`.
    fn score(
        &self,
        method: &str,
        chart: impl Fn(&ChartCapture, &ChartSetup) -> Result<DeltaEReport, BenchError>,
        spatial: impl Fn(&SpatialCaptures) -> Result<SpatialScore, BenchError>,
    ) -> Result<ColourResult, BenchError> {
        let rep = chart(&self.full, &self.setups[0])?;
        let low = chart(&self.low, &self.setups[1])?;
        let low_light_spatial = spatial(&self.spatial_low)?;
        let spatial = spatial(&self.spatial_full)?;
        Ok(ColourResult {
            s_cielab_mean: rep.s_cielab_mean,
            low_light_s_cielab_mean: low.s_cielab_mean,
            spatial,
            low_light_spatial,
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
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| BenchError::ThreadPool {
            threads: 1,
            msg: e.to_string(),
        })?;
    let b = Bench {
        design,
        iset,
        opts,
        progress,
        camera,
        cases,
        w: frame_info.width,
        h: frame_info.height,
        mpix: frame_info.megapixels,
        frame,
        single,
        cancel: AtomicBool::new(false),
    };
    // the plain copy first: the reference every row is compared with
    let mut rows = vec![b.copy_row()?];
    let copy_ms = rows[0].all_threads.median_ms;
    // the table the skips are measured on: the default configuration's (else the first SI one)
    let mut skip_table: Option<(bool, L3Table)> = None;
    for c in &opts.configs {
        rows.push(b.l3_row(c, copy_ms, &mut skip_table)?);
    }
    for choice in BaselineChoice::ALL {
        rows.push(b.baseline_row(choice, copy_ms)?);
    }
    for choice in BaselineChoice::ISP {
        rows.push(b.isp_row(choice, copy_ms)?);
    }
    let pareto = pareto_fronts(&b.cases, &rows);
    let (skips, encoders) = b.skips(skip_table.as_ref().map(|(_, t)| t))?;
    Ok(BenchReport {
        skips,
        encoders,
        schema: BENCH_SCHEMA.into(),
        renderer: RENDERER.into(),
        sensor: design.name.clone(),
        chart: b.cases[0].full.scene.name.clone(),
        acquisitions: b.cases.iter().map(|c| c.name.clone()).collect(),
        frame: frame_info,
        threads: rayon::current_num_threads(),
        configs: rows,
        pareto,
        total_seconds: started.elapsed().as_secs_f64(),
        options: opts.clone(),
    })
}

/// Per chart case: the index of the table it renders with, and its label.
type CaseTable = (usize, String);

/// What every row of a run is measured with.
struct Bench<'a> {
    design: &'a SensorDesign,
    iset: Option<&'a IsetData>,
    opts: &'a BenchOptions,
    progress: &'a (dyn Fn(&str) + Sync),
    camera: Camera,
    cases: Vec<ChartCase>,
    /// The throughput frame, its size and megapixels.
    frame: Vec<f32>,
    w: usize,
    h: usize,
    mpix: f64,
    /// A private one-thread pool.
    single: rayon::ThreadPool,
    cancel: AtomicBool,
}

impl Bench<'_> {
    /// The plain copy of the frame: the reference every row is compared with.
    fn copy_row(&self) -> Result<ConfigResult, BenchError> {
        let (opts, frame, mpix) = (self.opts, &self.frame, self.mpix);
        (self.progress)("timing a plain copy of the frame");
        let mut buf = vec![0f32; frame.len()];
        let copy_one = {
            let samples = self.single.install(|| {
                time_runs(opts.runs, || {
                    buf.copy_from_slice(black_box(frame));
                    Ok(black_box(buf[buf.len() / 2]))
                })
            })?;
            Throughput::from_samples(samples, 1, mpix)
        };
        // a copy is one memcpy: the "all threads" figure is the same single copy
        let copy_all = {
            let samples = time_runs(opts.runs, || {
                buf.copy_from_slice(black_box(frame));
                Ok(black_box(buf[buf.len() / 2]))
            })?;
            Throughput::from_samples(samples, rayon::current_num_threads(), mpix)
        };
        drop(buf);
        Ok(ConfigResult {
            name: "plain copy".into(),
            kind: ConfigKind::Copy,
            config: None,
            training_seconds: None,
            colour: Vec::new(),
            one_thread: copy_one,
            all_threads: copy_all,
            time_vs_copy: 1.0,
        })
    }

    /// One L3 configuration: train its tables, score them under every light and time the
    /// first light's on the frame.
    fn l3_row(
        &self,
        c: &L3Config,
        copy_ms: f64,
        skip_table: &mut Option<(bool, L3Table)>,
    ) -> Result<ConfigResult, BenchError> {
        let t0 = Instant::now();
        let (tables, per_case) = self.train(c, skip_table)?;
        let training_seconds = t0.elapsed().as_secs_f64();
        let mut colour = Vec::new();
        for (case, (ti, label)) in self.cases.iter().zip(&per_case) {
            (self.progress)(&format!("[{}] ΔE under {}", c.name, case.name));
            let renderer = prepare(&tables[*ti], &case.correction)?;
            colour.push(case.evaluate(label, |v, w, h| Ok(render_xyz(&renderer, v, w, h)?))?);
        }
        (self.progress)(&format!(
            "[{}] timing {} runs on {:.1} Mpix",
            c.name, self.opts.runs, self.mpix
        ));
        let (ti, _) = &per_case[0];
        let renderer = prepare(&tables[*ti], &self.cases[0].correction)?;
        let (frame, w, h) = (&self.frame, self.w, self.h);
        let (one, all) = measure(&self.single, self.opts.runs, self.mpix, || {
            Ok(render_srgb8(&renderer, frame, w, h)?)
        })?;
        Ok(ConfigResult {
            name: c.name.clone(),
            kind: ConfigKind::L3,
            config: Some(c.clone()),
            training_seconds: Some(training_seconds),
            colour,
            time_vs_copy: all.median_ms / copy_ms,
            one_thread: one,
            all_threads: all,
        })
    }

    /// The tables of configuration `c` and, per case, the table it renders with and its
    /// label. The default configuration's SI table (else the first SI one) becomes the
    /// table the skips are measured on.
    fn train(
        &self,
        c: &L3Config,
        skip_table: &mut Option<(bool, L3Table)>,
    ) -> Result<(Vec<L3Table>, Vec<CaseTable>), BenchError> {
        let (design, iset, opts, acqs) =
            (self.design, self.iset, self.opts, &self.opts.acquisitions);
        let mut per_case: Vec<CaseTable> = Vec::new();
        let mut tables: Vec<L3Table> = Vec::new();
        match c.tables {
            TableChoice::SiEnsemble => {
                let ills: Vec<String> = std::iter::once("D65".to_string())
                    .chain(acqs.iter().cloned())
                    .collect();
                (self.progress)(&format!(
                    "[{}] training SI table on {}",
                    c.name,
                    ills.join("+")
                ));
                let spec = training_spec(c, TableKind::SameIlluminant, ills.clone(), opts);
                tables.push(train_table(design, &spec, iset, &|_, _| {}, &self.cancel)?);
                let is_default = c.name == L3Config::default_config().name;
                if skip_table.as_ref().is_none_or(|(d, _)| !d && is_default) {
                    *skip_table = Some((is_default, tables[0].clone()));
                }
                for _ in &self.cases {
                    per_case.push((0, format!("SI_{}+T", ills.join("+"))));
                }
            }
            TableChoice::CrossPerIlluminant => {
                for (i, case) in self.cases.iter().enumerate() {
                    (self.progress)(&format!("[{}] training I table for {}", c.name, case.name));
                    let spec =
                        training_spec(c, TableKind::CrossIlluminant, vec![acqs[i].clone()], opts);
                    tables.push(train_table(design, &spec, iset, &|_, _| {}, &self.cancel)?);
                    per_case.push((i, format!("I_{}", case.name)));
                }
            }
        }
        Ok((tables, per_case))
    }

    /// The matrix of `b` per case (T folded in where the choice uses T) and the seconds
    /// the fits took.
    fn matrices(&self, b: BaselineChoice) -> Result<(Vec<ColourMatrix>, f64), BenchError> {
        let t0 = Instant::now();
        let matrices = self
            .cases
            .iter()
            .map(|case| b.matrix(&self.camera, &case.name, &case.correction, self.iset))
            .collect::<Result<Vec<_>, BenchError>>()?;
        Ok((matrices, t0.elapsed().as_secs_f64()))
    }

    /// A conventional pipeline's row: `colour` and the throughput of `render(frame, width,
    /// height)`.
    fn conventional_row<T: Send>(
        &self,
        (name, kind): (&str, ConfigKind),
        (training_seconds, colour): (f64, Vec<ColourResult>),
        copy_ms: f64,
        render: impl Fn(&[f32], usize, usize) -> Result<T, BenchError> + Sync,
    ) -> Result<ConfigResult, BenchError> {
        (self.progress)(&format!("[{name}] timing {} runs", self.opts.runs));
        let (frame, w, h) = (&self.frame, self.w, self.h);
        let (one, all) = measure(&self.single, self.opts.runs, self.mpix, || {
            render(frame, w, h)
        })?;
        Ok(ConfigResult {
            name: name.into(),
            kind,
            config: None,
            training_seconds: Some(training_seconds),
            colour,
            time_vs_copy: all.median_ms / copy_ms,
            one_thread: one,
            all_threads: all,
        })
    }

    /// One conventional baseline: a matrix per light (T folded in where the choice uses
    /// T), scored under every light and timed with the first light's.
    fn baseline_row(&self, b: BaselineChoice, copy_ms: f64) -> Result<ConfigResult, BenchError> {
        (self.progress)(&format!("[baseline] fitting {}", b.name()));
        let (matrices, training_seconds) = self.matrices(b)?;
        let cfa = self.camera.cfa();
        let mut colour = Vec::new();
        for (case, m) in self.cases.iter().zip(&matrices) {
            colour.push(case.evaluate(&b.label(&case.name), |v, w, h| {
                Ok(render_baseline_xyz(v, w, h, cfa, m)?)
            })?);
        }
        let m0 = &matrices[0];
        self.conventional_row(
            (b.name(), ConfigKind::Baseline),
            (training_seconds, colour),
            copy_ms,
            |f, w, h| Ok(render_baseline_srgb8(f, w, h, cfa, m0)?),
        )
    }

    /// The strong ISP with the matrices of `b` (T folded in where it uses T), denoising by
    /// the camera's noise model when the chart is noisy (as `l3 eval --method isp`): scored
    /// under every light as the evaluation scores it, timed with the first light's. The
    /// timed render denoises with the profile at no exposure, as the evaluation's spatial
    /// scores do (the exposure moves only the dark signal, not the cost).
    fn isp_row(&self, b: BaselineChoice, copy_ms: f64) -> Result<ConfigResult, BenchError> {
        (self.progress)(&format!("[ISP] fitting {}", b.isp_name()));
        let (matrices, training_seconds) = self.matrices(b)?;
        let noise = self
            .opts
            .chart
            .noise
            .then(|| NoiseProfile::new(&self.camera, 0.0));
        let isps: Vec<Isp> = matrices
            .into_iter()
            .map(|m| Isp::new(m, noise.clone()))
            .collect();
        // T is in the matrix: no further correction
        let identity = IlluminantEntry::from_matrix("identity", IDENTITY);
        let mut colour = Vec::new();
        for (case, isp) in self.cases.iter().zip(&isps) {
            let label = b.isp_label(&case.name);
            (self.progress)(&format!("[ISP] {label} under {}", case.name));
            colour.push(case.evaluate_method(
                &self.camera,
                &label,
                &Method::Isp(isp),
                &identity,
            )?);
        }
        let cfa = self.camera.cfa();
        self.conventional_row(
            (b.isp_name(), ConfigKind::Isp),
            (training_seconds, colour),
            copy_ms,
            |f, w, h| Ok(render_isp_srgb8(&isps[0], f, w, h, cfa)?),
        )
    }

    /// The skips and encoders on `table`, when the options ask for them.
    fn skips(
        &self,
        table: Option<&L3Table>,
    ) -> Result<(Vec<SkipResult>, Vec<EncoderResult>), BenchError> {
        match table.filter(|_| self.opts.skips) {
            Some(table) => run_skips(
                &SkipInputs {
                    table,
                    t: self.cases[0].correction.t,
                    frame: &self.frame,
                    width: self.w,
                    height: self.h,
                    runs: self.opts.runs,
                },
                self.progress,
            ),
            None => Ok((Vec::new(), Vec::new())),
        }
    }
}

/// Per case and metric, the rows on the Pareto front of (ms/Mpix all threads, the metric).
fn pareto_fronts(cases: &[ChartCase], rows: &[ConfigResult]) -> Vec<ParetoFront> {
    let mut out = Vec::new();
    for metric in FrontMetric::ALL {
        for case in cases {
            let pts: Vec<(usize, (f64, f64))> = rows
                .iter()
                .enumerate()
                .filter_map(|(i, r)| {
                    let cost = metric.cost(r.colour_under(&case.name)?)?;
                    Some((i, (r.all_threads.ms_per_mpix, cost)))
                })
                .collect();
            if pts.is_empty() {
                continue;
            }
            let xy: Vec<(f64, f64)> = pts.iter().map(|p| p.1).collect();
            out.push(ParetoFront {
                illuminant: case.name.clone(),
                metric,
                names: pareto_front(&xy)
                    .into_iter()
                    .map(|k| rows[pts[k].0].name.clone())
                    .collect(),
            });
        }
    }
    out
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
        schema: BENCH_SCHEMA.into(),
        reports,
        total_seconds: started.elapsed().as_secs_f64(),
    })
}
