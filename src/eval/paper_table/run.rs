//! A Table 1 run: train the tables, fit the baseline matrices, simulate the chart under
//! each acquisition light and evaluate every row.

use std::sync::atomic::AtomicBool;

use super::baselines::short;
use super::rows::{
    BaselineFamily, CaptureSpread, ExposurePoint, PAPER_TABLE1, PaperOptions, PaperRow, PaperTable,
    Spatial, StorageComparison,
};
use crate::baseline::{ColourMatrix, Isp, NoiseProfile};
use crate::camera::{Camera, SensorDesign};
use crate::eval::noise_split::check_captures;
use crate::eval::{
    ChannelSet, ChartCapture, ChartSetup, ColourFit, DeltaEReport, EvalError, LightLevel, Method,
    SpatialCaptures, evaluate_capture, fit_colour_matrix, linear_table, matching_linear_map,
    simulate_chart, simulate_spatial,
};
use crate::l3::L3Table;
use crate::l3::correct::{IDENTITY, IlluminantEntry, IlluminantRegistry, LevelMap};
use crate::l3::correct::{camera_corrected, noise_model};
use crate::l3::learn::{TrainingSpec, train_table};
use crate::l3::table::TableKind;
use crate::spectral::{IsetData, WavelengthGrid};

/// The training spec's noise settings for a Table 1 run: a noise-free run
/// (`ChartSetup::noise` off) trains noise-free too — noise-free patches and
/// the noise-free colour map at every level — so that it shows the
/// trainer's colour error alone. Tables trained for noise trade colour for
/// noise at every level, and on a noise-free chart that trade shows as
/// bias: on ISET's RGBW under tungsten, I_Tun 2.62 against 2.04 trained
/// noise-free, with its matching linear map at 2.17.
fn base_training_spec(noise_free: bool) -> TrainingSpec {
    if noise_free {
        TrainingSpec {
            noise: false,
            colour_averaging_px: Some(0.0),
            texture_colour_averaging_px: None,
            ..TrainingSpec::default()
        }
    } else {
        TrainingSpec::default()
    }
}

/// The training spec of a run's table of `kind` on the lights `ills`.
pub(crate) fn table_spec(opts: &PaperOptions, kind: TableKind, ills: &[&str]) -> TrainingSpec {
    TrainingSpec {
        kind,
        illuminants: ills.iter().map(|s| s.to_string()).collect(),
        seed: opts.seed,
        scenes: opts.scenes,
        scene_size: opts.scene_size,
        chroma_classes: opts.chroma_classes,
        ..base_training_spec(!opts.chart.noise)
    }
}

/// An L3 row's matching linear map under the light `acq` (a table whose every class holds
/// the map) and the correction it is evaluated with: the row's own `corr`, or with
/// `camera_aware` the map's own C, as the table gets its own.
pub(crate) fn linear_counterpart(
    camera: &Camera,
    t: &L3Table,
    acq: &str,
    corr: &IlluminantEntry,
    camera_aware: bool,
    iset: Option<&IsetData>,
) -> Result<(L3Table, IlluminantEntry), EvalError> {
    let map = matching_linear_map(camera, t, acq, iset)?;
    let lin_corr = if camera_aware {
        camera_corrected(
            camera,
            &[LevelMap {
                map: map.clone(),
                noise: None,
                chroma: None,
            }],
            corr,
            iset,
        )?
    } else {
        corr.clone()
    };
    Ok((linear_table(t, &map)?, lin_corr))
}

/// Train the tables and evaluate every row. `progress(message)` reports each step.
pub fn run_paper_table(
    design: &SensorDesign,
    iset: Option<&IsetData>,
    opts: &PaperOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<PaperTable, EvalError> {
    check_options(opts)?;
    let grid = WavelengthGrid::default();
    let camera = Camera::new(design, grid, iset).map_err(|e| EvalError::Invalid(e.to_string()))?;
    let mut registry = IlluminantRegistry::with_defaults(grid, iset)?;
    let run = Run {
        design,
        iset,
        opts,
        progress,
        camera,
        cancel: AtomicBool::new(false),
    };
    let shared = run.shared()?;
    let mut out = Rows::default();
    for acq in &opts.acquisitions {
        run.acquisition_rows(&shared, acq, &mut registry, &mut out)?;
    }
    // N = the registry's illuminants: one cross table each, against one SI
    // table plus one 3×3 matrix (9 f64) each.
    let n = registry.len().max(1);
    let table_bytes = shared.si_ens.kernel_bytes();
    let matrix_bytes = 9 * 8;
    let cross_bytes = out.cross_bytes / opts.acquisitions.len().max(1) * n;
    let mut table = PaperTable {
        sensor: design.name.clone(),
        chart: out.chart_name,
        rows: out.rows,
        storage: StorageComparison {
            illuminants: n,
            table_bytes,
            matrix_bytes,
            si_plus_matrices_bytes: table_bytes + n * matrix_bytes,
            cross_tables_bytes: cross_bytes,
        },
        reports: out.reports,
        options: opts.clone(),
        comparisons: Vec::new(),
    };
    table.comparisons = table.compare_with_baselines();
    Ok(table)
}

/// Refuse a run over several captures without noise or with a count out of range.
fn check_options(opts: &PaperOptions) -> Result<(), EvalError> {
    if opts.captures != 1 {
        check_captures(opts.captures, "a Table 1 over several captures")?;
        if !opts.chart.noise {
            return Err(EvalError::Invalid(
                "a Table 1 over several captures needs noise: every noise-free capture is the same"
                    .into(),
            ));
        }
    }
    Ok(())
}

/// What every step of a run works with.
struct Run<'a> {
    design: &'a SensorDesign,
    iset: Option<&'a IsetData>,
    opts: &'a PaperOptions,
    progress: &'a (dyn Fn(&str) + Sync),
    camera: Camera,
    cancel: AtomicBool,
}

/// The tables and matrices every acquisition light's rows share.
struct Shared {
    si_d65: L3Table,
    si_ens: L3Table,
    /// The SI table on D65 and every acquisition light, with more than one light.
    si_all: Option<L3Table>,
    /// How many lights `si_all` is trained on.
    n_all: usize,
    d65_rgb: ColourMatrix,
    d65_all: ColourMatrix,
    /// The strong ISP with the D65 matrices (RGB, all channels), denoising by the camera's
    /// noise model.
    isp_d65: [Isp; 2],
    /// Each ensemble's name and its RGB and all-channel matrices.
    ensemble_fits: Vec<(String, ColourMatrix, ColourMatrix)>,
}

/// The rows found so far.
#[derive(Default)]
struct Rows {
    rows: Vec<PaperRow>,
    reports: Vec<DeltaEReport>,
    chart_name: String,
    cross_bytes: usize,
}

/// One acquisition light: its corrections and its captures of the chart.
struct Acquisition<'a> {
    name: &'a str,
    tag: String,
    corr: IlluminantEntry,
    /// The acquisition-fit baselines are white-balanced cross maps: no T.
    identity: IlluminantEntry,
    /// The names of the acquisition-fit baselines and ISP rows (rendered without T).
    acq_names: [String; 4],
    cap: ChartCapture,
    /// The further captures of a run over several (chart seeds after the first).
    extra: Vec<ChartCapture>,
    lower: Vec<LowerCapture>,
    /// The slanted edge and the texture at full exposure and at each lower one (none with
    /// `spatial_px` 0), shared by every row.
    spatial: Option<SpatialCaptures>,
    lower_spatial: Vec<Option<SpatialCaptures>>,
}

/// The chart at a lower exposure: the exposure factor, the capture and its set-up.
type LowerCapture = (f64, ChartCapture, ChartSetup);

/// A row to evaluate: its name, what renders it and its training time.
type MethodRow<'t> = (String, Method<'t>, Option<f64>);

impl Run<'_> {
    fn train(&self, kind: TableKind, ills: &[&str]) -> Result<L3Table, EvalError> {
        (self.progress)(&format!("training {kind} table on {}", ills.join("+")));
        let spec = table_spec(self.opts, kind, ills);
        train_table(self.design, &spec, self.iset, &|_, _| {}, &self.cancel)
            .map_err(|e| EvalError::Invalid(e.to_string()))
    }

    fn fit_matrix(
        &self,
        ills: &[String],
        kind: TableKind,
        channels: ChannelSet,
    ) -> Result<ColourMatrix, EvalError> {
        let fit = ColourFit {
            illuminants: ills,
            kind,
            channels,
            preserve_white: kind == TableKind::CrossIlluminant,
            through_correction: false,
        };
        fit_colour_matrix(&self.camera, &fit, self.iset)
    }

    /// The strong ISP with `m`, denoising by the camera's noise model (at each capture's
    /// exposure: [`evaluate_capture`] sets it).
    fn isp(&self, m: &ColourMatrix) -> Isp {
        let noise = self
            .opts
            .chart
            .noise
            .then(|| NoiseProfile::new(&self.camera, 0.0));
        Isp::new(m.clone(), noise)
    }

    /// Train the SI tables of D65 and the ensembles, and fit the D65 and ensemble matrices.
    fn shared(&self) -> Result<Shared, EvalError> {
        let si_d65 = self.train(TableKind::SameIlluminant, &["D65"])?;
        let si_ens = self.train(TableKind::SameIlluminant, &["D65", "Tungsten"])?;
        let all_ens: Vec<&str> = std::iter::once("D65")
            .chain(self.opts.acquisitions.iter().map(|s| s.as_str()))
            .collect();
        let si_all = if self.opts.acquisitions.len() > 1 {
            Some(self.train(TableKind::SameIlluminant, &all_ens)?)
        } else {
            None
        };
        (self.progress)("fitting the baseline colour matrices");
        let d65_list = ["D65".to_string()];
        let d65_rgb = self.fit_matrix(&d65_list, TableKind::SameIlluminant, ChannelSet::Rgb)?;
        let d65_all = self.fit_matrix(&d65_list, TableKind::SameIlluminant, ChannelSet::All)?;
        // each ensemble's own conventional matrices (RGB, all channels), fitted
        // on its lights together as its table was, then T
        let mut ensemble_fits = Vec::new();
        for (name, t) in std::iter::once(("Ens".to_string(), &si_ens)).chain(
            si_all
                .as_ref()
                .map(|t| (format!("Ens{}", all_ens.len()), t)),
        ) {
            let lights = &t.meta.train_illuminants;
            ensemble_fits.push((
                name,
                self.fit_matrix(lights, TableKind::SameIlluminant, ChannelSet::Rgb)?,
                self.fit_matrix(lights, TableKind::SameIlluminant, ChannelSet::All)?,
            ));
        }
        let isp_d65 = [self.isp(&d65_rgb), self.isp(&d65_all)];
        Ok(Shared {
            si_d65,
            si_ens,
            si_all,
            n_all: all_ens.len(),
            d65_rgb,
            d65_all,
            isp_d65,
            ensemble_fits,
        })
    }

    /// Train the acquisition light's own tables and evaluate every row under it.
    fn acquisition_rows(
        &self,
        shared: &Shared,
        acq: &str,
        registry: &mut IlluminantRegistry,
        out: &mut Rows,
    ) -> Result<(), EvalError> {
        let tag = short(acq);
        let cross = self.train(TableKind::CrossIlluminant, &[acq])?;
        let si_acq = self.train(TableKind::SameIlluminant, &[acq])?;
        out.cross_bytes += cross.kernel_bytes();
        let corr = registry.resolve(acq, self.iset)?;
        let mut methods = table_methods(shared, &tag, &cross, &si_acq);
        let acq_list = [acq.to_string()];
        let acq_rgb = self.fit_matrix(&acq_list, TableKind::CrossIlluminant, ChannelSet::Rgb)?;
        let acq_all = self.fit_matrix(&acq_list, TableKind::CrossIlluminant, ChannelSet::All)?;
        let identity = IlluminantEntry {
            t: IDENTITY,
            ..corr.clone()
        };
        baseline_methods(&mut methods, shared, &tag, &acq_rgb, &acq_all);
        let isp_acq = [self.isp(&acq_rgb), self.isp(&acq_all)];
        isp_methods(&mut methods, shared, &tag, &isp_acq);
        let acq_names = [
            format!("Baseline_{tag}"),
            format!("Baseline_{tag} all"),
            format!("ISP_{tag}"),
            format!("ISP_{tag} all"),
        ];
        let (cap, extra, lower) = self.captures(acq)?;
        let spatial = self.spatial_captures(acq, &self.opts.chart)?;
        let lower_spatial = lower
            .iter()
            .map(|(_, _, setup)| self.spatial_captures(acq, setup))
            .collect::<Result<Vec<_>, EvalError>>()?;
        let a = Acquisition {
            name: acq,
            tag,
            corr,
            identity,
            acq_names,
            cap,
            extra,
            lower,
            spatial,
            lower_spatial,
        };
        for (name, method, secs) in methods {
            (self.progress)(&format!("evaluating {name} under {acq}"));
            let (row, rep) = self.evaluate_row(&a, name, method, secs)?;
            out.chart_name = rep.chart.clone();
            out.rows.push(row);
            out.reports.push(rep);
        }
        Ok(())
    }

    /// The chart under `acq`: the first capture, the further captures of a run over several,
    /// and one capture at each lower exposure.
    fn captures(
        &self,
        acq: &str,
    ) -> Result<(ChartCapture, Vec<ChartCapture>, Vec<LowerCapture>), EvalError> {
        let (camera, iset, opts) = (&self.camera, self.iset, self.opts);
        let cap = self.chart_with_ideal(acq, &opts.chart)?;
        // the further captures of a run over several (chart seeds after the first)
        let extra = (1..opts.captures as u64)
            .map(|k| {
                let setup = ChartSetup {
                    seed: opts.chart.seed.wrapping_add(k),
                    ..opts.chart.clone()
                };
                simulate_chart(camera, acq, iset, &setup)
            })
            .collect::<Result<Vec<_>, EvalError>>()?;
        let lower = opts
            .exposures
            .iter()
            .map(|&f| {
                let setup = LightLevel::ExposureFactor(f).apply(&opts.chart)?;
                Ok((f, self.chart_with_ideal(acq, &setup)?, setup))
            })
            .collect::<Result<Vec<_>, EvalError>>()?;
        Ok((cap, extra, lower))
    }

    /// The chart under `acq` with `setup`, with its ideal image (for the S-CIELAB) unless the
    /// run leaves the spatial metrics out.
    fn chart_with_ideal(&self, acq: &str, setup: &ChartSetup) -> Result<ChartCapture, EvalError> {
        let cap = simulate_chart(&self.camera, acq, self.iset, setup)?;
        if self.opts.spatial_px == 0 {
            return Ok(cap);
        }
        cap.with_ideal_image(&self.camera)
    }

    /// The slanted edge and the texture under `acq` with `setup` (none with `spatial_px` 0).
    fn spatial_captures(
        &self,
        acq: &str,
        setup: &ChartSetup,
    ) -> Result<Option<SpatialCaptures>, EvalError> {
        match self.opts.spatial_px {
            0 => Ok(None),
            px => simulate_spatial(&self.camera, acq, self.iset, setup, px).map(Some),
        }
    }

    /// A row's spatial figures on `spatial` with its chart report's S-CIELAB.
    fn spatial_row(
        &self,
        rep: &DeltaEReport,
        spatial: Option<&SpatialCaptures>,
        method: &Method,
        correction: &IlluminantEntry,
    ) -> Result<Spatial, EvalError> {
        let score = spatial
            .map(|s| s.score(&self.camera, method, correction))
            .transpose()?;
        Ok(Spatial::new(rep.s_cielab_mean, score.as_ref()))
    }

    /// One row: the method on the first capture, over the further captures, its matching
    /// linear map (L3 rows) and at the lower exposures.
    fn evaluate_row(
        &self,
        a: &Acquisition,
        name: String,
        method: Method,
        secs: Option<f64>,
    ) -> Result<(PaperRow, DeltaEReport), EvalError> {
        let is_acq_baseline = a.acq_names.contains(&name);
        let camera_aware = name.ends_with("+C");
        let own: IlluminantEntry = match method {
            Method::Table(t) if camera_aware => camera_corrected(
                &self.camera,
                &t.level_colour_maps(&noise_model(self.design))?,
                &a.corr,
                self.iset,
            )?,
            _ if is_acq_baseline => a.identity.clone(),
            _ => a.corr.clone(),
        };
        let c = &own;
        let chart = &self.opts.chart;
        let rep = evaluate_capture(&self.camera, &a.cap, &method, &name, c, chart)?;
        let row_means = self.means_over(rep.summary.mean, a, &method, &name, c)?;
        let (linear_mean, linear_means, baseline) = match method {
            Method::Table(t) => {
                let (mean, means, family) = self.linear_row(a, t, &name, camera_aware)?;
                (Some(mean), Some(means), Some(family))
            }
            Method::Baseline(_) | Method::Isp(_) => (None, None, None),
        };
        let exposures = a
            .lower
            .iter()
            .zip(&a.lower_spatial)
            .map(|((f, lc, ls), lsp)| {
                let r = evaluate_capture(&self.camera, lc, &method, &name, c, ls)?;
                Ok(ExposurePoint {
                    factor: *f,
                    mean: r.summary.mean,
                    pixel_mean: r.per_pixel.mean,
                    spatial: self.spatial_row(&r, lsp.as_ref(), &method, c)?,
                })
            })
            .collect::<Result<Vec<_>, EvalError>>()?;
        let spatial = self.spatial_row(&rep, a.spatial.as_ref(), &method, c)?;
        let is_tungsten = a.tag == "Tun";
        let row = PaperRow {
            acquisition: rep.acquisition_illuminant.clone(),
            method: name.clone(),
            mean: rep.summary.mean,
            std: rep.summary.std,
            median: rep.summary.median,
            p90: rep.summary.p90,
            max: rep.summary.max,
            pixel_mean: rep.per_pixel.mean,
            linear_mean,
            exposures,
            baseline,
            paper: if is_tungsten {
                paper_figures(&name)
            } else {
                None
            },
            training_seconds: secs,
            captures: (self.opts.captures > 1)
                .then(|| CaptureSpread::new(row_means, linear_means.as_deref())),
            spatial,
        };
        Ok((row, rep))
    }

    /// An L3 row's matching linear map: its mean on the first capture and on every capture,
    /// and the baseline family the row is judged against.
    fn linear_row(
        &self,
        a: &Acquisition,
        t: &L3Table,
        name: &str,
        camera_aware: bool,
    ) -> Result<(f64, Vec<f64>, BaselineFamily), EvalError> {
        let (camera, acq) = (&self.camera, a.name);
        // the linear map gets its own C, as the table does
        let (lt, lin_corr) = linear_counterpart(camera, t, acq, &a.corr, camera_aware, self.iset)?;
        let (lin_method, lin_name) = (Method::Table(&lt), format!("linear {name}"));
        let lin = evaluate_capture(
            camera,
            &a.cap,
            &lin_method,
            &lin_name,
            &lin_corr,
            &self.opts.chart,
        )?;
        let lin_means = self.means_over(lin.summary.mean, a, &lin_method, &lin_name, &lin_corr)?;
        // like with like: a table for this light alone against
        // the matrix for this light; one table for several
        // lights (then T) against one matrix (then T)
        let only_acq = matches!(t.meta.train_illuminants.as_slice(),
            [i] if i.eq_ignore_ascii_case(acq));
        let family = if only_acq || camera_aware || t.meta.kind == TableKind::CrossIlluminant {
            BaselineFamily::AcquisitionFit
        } else if t.meta.train_illuminants.len() > 1 {
            BaselineFamily::EnsembleFitThenT
        } else {
            BaselineFamily::D65FitThenT
        };
        Ok((lin.summary.mean, lin_means, family))
    }

    /// `first` (a method's mean patch-mean ΔE on the first capture), then its
    /// mean on each of the further captures.
    fn means_over(
        &self,
        first: f64,
        a: &Acquisition,
        method: &Method,
        name: &str,
        correction: &IlluminantEntry,
    ) -> Result<Vec<f64>, EvalError> {
        let (camera, setup) = (&self.camera, &self.opts.chart);
        std::iter::once(Ok(first))
            .chain(a.extra.iter().map(|cap| {
                evaluate_capture(camera, cap, method, name, correction, setup)
                    .map(|r| r.summary.mean)
            }))
            .collect()
    }
}

/// The L3 rows under one light: its I table, the SI tables then T, and the SI tables but
/// the light's own then C (the camera-aware correction in place of T).
fn table_methods<'t>(
    shared: &'t Shared,
    tag: &str,
    cross: &'t L3Table,
    si_acq: &'t L3Table,
) -> Vec<MethodRow<'t>> {
    let mut si_rows: Vec<(String, &L3Table)> = vec![
        (format!("SI_{tag}"), si_acq),
        ("SI_D65".into(), &shared.si_d65),
        ("SI_Ens".into(), &shared.si_ens),
    ];
    if let Some(t) = &shared.si_all {
        si_rows.push((format!("SI_Ens{}", shared.n_all), t));
    }
    let mut methods: Vec<MethodRow> = vec![(
        format!("I_{tag}"),
        Method::Table(cross),
        Some(cross.meta.training_seconds),
    )];
    for (name, t) in &si_rows {
        methods.push((
            format!("{name}+T"),
            Method::Table(t),
            Some(t.meta.training_seconds),
        ));
    }
    // the same SI tables with the camera-aware correction C in place of T
    for (name, t) in si_rows.iter().skip(1) {
        methods.push((
            format!("{name}+C"),
            Method::Table(t),
            Some(t.meta.training_seconds),
        ));
    }
    methods
}

/// The conventional baselines: the D65 fit then T, each ensemble's fit then T, and the
/// light's own white-balanced fit; RGB and all channels each.
fn baseline_methods<'t>(
    methods: &mut Vec<MethodRow<'t>>,
    shared: &'t Shared,
    tag: &str,
    acq_rgb: &'t ColourMatrix,
    acq_all: &'t ColourMatrix,
) {
    methods.push(("Baseline+T".into(), Method::Baseline(&shared.d65_rgb), None));
    methods.push((
        "Baseline+T all".into(),
        Method::Baseline(&shared.d65_all),
        None,
    ));
    for (name, rgb, all) in &shared.ensemble_fits {
        methods.push((format!("Baseline_{name}+T"), Method::Baseline(rgb), None));
        methods.push((
            format!("Baseline_{name}+T all"),
            Method::Baseline(all),
            None,
        ));
    }
    methods.push((format!("Baseline_{tag}"), Method::Baseline(acq_rgb), None));
    methods.push((
        format!("Baseline_{tag} all"),
        Method::Baseline(acq_all),
        None,
    ));
}

/// The strong ISP's rows: the D65 fit then T (`ISP_D65+T`) and the light's own
/// white-balanced fit (`ISP_<light>`, no T); RGB and all channels each, as the baselines.
fn isp_methods<'t>(
    methods: &mut Vec<MethodRow<'t>>,
    shared: &'t Shared,
    tag: &str,
    acq: &'t [Isp; 2],
) {
    for (suffix, d65, own) in [
        ("", &shared.isp_d65[0], &acq[0]),
        (" all", &shared.isp_d65[1], &acq[1]),
    ] {
        methods.push((format!("ISP_D65+T{suffix}"), Method::Isp(d65), None));
        methods.push((format!("ISP_{tag}{suffix}"), Method::Isp(own), None));
    }
}

/// The paper's (mean, std, p90) for a row, tungsten only.
fn paper_figures(method: &str) -> Option<[f64; 3]> {
    PAPER_TABLE1
        .iter()
        .find(|(m, ..)| *m == method)
        .map(|(_, a, b, c)| [*a, *b, *c])
}
