//! The paper's Table 1: I_Tun, SI_Tun+T, SI_D65+T, SI_Ens+T and the
//! conventional baseline on the Natural-100 chart, under tungsten and again
//! under fluorescent, beside the published figures; and the SI tables again
//! with the camera-aware correction C in place of T (`+C` rows, see
//! `crate::l3::correct::camera_correction`).

use std::collections::BTreeMap;
use std::sync::atomic::AtomicBool;

use serde::{Deserialize, Serialize};

use super::noise_split::check_captures;
use super::workflow::{
    ChannelSet, ChartCapture, ChartSetup, ColourFit, LightLevel, Method, evaluate_capture,
    fit_colour_matrix, linear_table, matching_linear_map, simulate_chart,
};
use super::{DeltaEReport, EvalError, summarize};
use crate::camera::{Camera, SensorDesign};
use crate::l3::L3Table;
use crate::l3::correct::{
    IlluminantEntry, IlluminantRegistry, LevelMap, camera_corrected, noise_model,
};
use crate::l3::learn::{TrainingSpec, train_table};
use crate::l3::table::TableKind;
use crate::spectral::{IsetData, WavelengthGrid};

/// The paper's Table 1 (tungsten acquisition): mean, std, p90 of ΔE2000.
pub const PAPER_TABLE1: [(&str, f64, f64, f64); 4] = [
    ("I_Tun", 2.5, 1.8, 4.9),
    ("SI_Tun+T", 2.5, 2.0, 5.4),
    ("SI_D65+T", 4.0, 3.0, 8.3),
    ("SI_Ens+T", 2.9, 2.2, 6.0),
];

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
            ..TrainingSpec::default()
        }
    } else {
        TrainingSpec::default()
    }
}

/// Options of a Table 1 run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PaperOptions {
    /// Acquisition illuminants, each a row block (tungsten first).
    pub acquisitions: Vec<String>,
    /// Training scenes and their size for every table.
    pub scenes: usize,
    pub scene_size: usize,
    pub seed: u64,
    pub chart: ChartSetup,
    /// Exposure factors (relative to the chart's) at which every row is also
    /// evaluated; the smallest is the low-light column.
    #[serde(default = "default_exposures")]
    pub exposures: Vec<f64>,
    /// Chroma classes of every table (1: none; see `src/l3/classify/chroma.rs`).
    #[serde(default = "one")]
    pub chroma_classes: usize,
    /// Noisy captures of the chart every row is evaluated on at full
    /// exposure: 1 (the table as the paper gives it, one capture), or
    /// [`super::MIN_CAPTURES`]..=[`super::MAX_CAPTURES`], which adds each row's mean over
    /// the captures (chart seeds `chart.seed`, `chart.seed + 1`, …) and its
    /// matching linear map's ([`CaptureSpread`]).
    #[serde(default = "one")]
    pub captures: usize,
}

fn one() -> usize {
    1
}

fn default_exposures() -> Vec<f64> {
    LightLevel::SWEEP[1..].to_vec()
}

impl Default for PaperOptions {
    fn default() -> Self {
        Self {
            acquisitions: vec!["Tungsten".into(), "Fluorescent".into()],
            scenes: 48,
            scene_size: 96,
            seed: 1,
            chart: ChartSetup::default(),
            exposures: default_exposures(),
            chroma_classes: 1,
            captures: 1,
        }
    }
}

/// A row's error at a lower exposure.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ExposurePoint {
    /// Exposure time relative to auto-exposure.
    pub factor: f64,
    /// Patch-mean ΔE2000.
    pub mean: f64,
    /// Mean per-pixel ΔE2000 over patch interiors.
    pub pixel_mean: f64,
}

/// One row of the table.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PaperRow {
    pub acquisition: String,
    pub method: String,
    pub mean: f64,
    pub std: f64,
    pub median: f64,
    pub p90: f64,
    pub max: f64,
    pub pixel_mean: f64,
    /// L3 rows: mean ΔE of the matching linear map (a table whose every class
    /// holds the least-squares map fitted on the same reflectances,
    /// illuminants and target), evaluated on the same frame.
    #[serde(default)]
    pub linear_mean: Option<f64>,
    /// The same row at the lower exposures of [`PaperOptions::exposures`].
    #[serde(default)]
    pub exposures: Vec<ExposurePoint>,
    /// L3 rows: the conventional baseline they are judged against.
    #[serde(default)]
    pub baseline: Option<BaselineFamily>,
    /// The paper's (mean, std, p90) for this row, tungsten only.
    pub paper: Option<[f64; 3]>,
    pub training_seconds: Option<f64>,
    /// With [`PaperOptions::captures`] > 1: the row over every capture.
    #[serde(default)]
    pub captures: Option<CaptureSpread>,
}

/// A row's patch-mean ΔE2000 over several noisy captures of the chart
/// (the first is the capture the rest of the row is measured on). One
/// capture's patch means keep noise (a 16 × 16 interior), so its mean moves
/// from capture to capture by about a tenth of a ΔE on the real sensors:
/// as much as the bounds rows are judged by.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CaptureSpread {
    /// The mean patch-mean ΔE of each capture.
    pub per_capture: Vec<f64>,
    /// Their mean and standard deviation.
    pub mean: f64,
    pub std: f64,
    /// L3 rows: the matching linear map's mean over the same captures.
    #[serde(default)]
    pub linear_mean: Option<f64>,
}

impl CaptureSpread {
    fn new(per_capture: Vec<f64>, linear: Option<&[f64]>) -> Self {
        let stats = summarize(&per_capture);
        Self {
            mean: stats.mean,
            std: stats.std,
            linear_mean: linear.map(|l| summarize(l).mean),
            per_capture,
        }
    }
}

/// Which conventional baseline an L3 row is compared with: like with like.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BaselineFamily {
    /// The white-balanced matrix fitted under the acquisition light
    /// (`Baseline_<acq>` and `Baseline_<acq> all`): for cross tables and for
    /// SI tables trained under the acquisition light alone, and for SI
    /// tables followed by the camera-aware correction C (like this matrix,
    /// fitted for this light and this camera).
    AcquisitionFit,
    /// The matrix fitted under D65, then T (`Baseline+T` and `Baseline+T
    /// all`): for SI tables trained under D65, which like this matrix serve
    /// every light through T.
    D65FitThenT,
    /// The matrix fitted on an ensemble's lights together, then T
    /// (`Baseline_Ens+T`, `Baseline_Ens3+T` and their `all`): for SI tables
    /// trained on that ensemble (`SI_Ens+T`, `SI_Ens3+T`), a conventional
    /// pipeline calibrated on the same lights and serving every light
    /// through T. (Until these rows existed the ensembles were judged
    /// against the D65 fit; the markdown still shows that difference.)
    EnsembleFitThenT,
}

/// One L3 row against its baseline (of the RGB and all-channel variants,
/// the sensor's better one by patch-mean ΔE at full exposure).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BaselineComparison {
    pub acquisition: String,
    pub method: String,
    pub baseline: String,
    /// L3 patch-mean ΔE minus the baseline's, full exposure.
    pub mean_difference: f64,
    /// The same over every capture ([`PaperOptions::captures`] > 1).
    #[serde(default)]
    pub capture_mean_difference: Option<f64>,
    /// (exposure factor, L3 per-pixel ΔE / baseline per-pixel ΔE), full
    /// exposure first.
    pub pixel_ratios: Vec<(f64, f64)>,
}

/// Storage of one SI table plus N matrices against N cross-illuminant tables.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StorageComparison {
    pub illuminants: usize,
    pub table_bytes: usize,
    pub matrix_bytes: usize,
    pub si_plus_matrices_bytes: usize,
    pub cross_tables_bytes: usize,
}

/// The whole result.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PaperTable {
    pub sensor: String,
    pub chart: String,
    pub rows: Vec<PaperRow>,
    pub storage: StorageComparison,
    pub reports: Vec<DeltaEReport>,
    pub options: PaperOptions,
    /// Every L3 row against its baseline.
    #[serde(default)]
    pub comparisons: Vec<BaselineComparison>,
}

impl PaperTable {
    /// The row of `method` under `acquisition`.
    pub fn row(&self, acquisition: &str, method: &str) -> Option<&PaperRow> {
        self.rows
            .iter()
            .find(|r| r.acquisition.eq_ignore_ascii_case(acquisition) && r.method == method)
    }

    /// Whether this sensor's baseline is the all-channel variant: the one,
    /// of RGB and all channels, whose baseline rows (every acquisition and
    /// both fits, in pairs present in both variants) have the lower mean
    /// patch-mean ΔE at full exposure. One variant per sensor, as the
    /// acceptance asks ("on each sensor, use the one with the lower
    /// patch-mean ΔE"); a choice per light flips on differences of 0.01.
    pub fn all_channel_baseline(&self) -> bool {
        let (mut rgb, mut all, mut n) = (0.0, 0.0, 0usize);
        for r in self
            .rows
            .iter()
            .filter(|r| r.method.starts_with("Baseline"))
        {
            if r.method.ends_with(" all") {
                continue;
            }
            if let Some(a) = self.row(&r.acquisition, &format!("{} all", r.method)) {
                rgb += r.mean;
                all += a.mean;
                n += 1;
            }
        }
        n > 0 && all < rgb
    }

    /// The baseline row an L3 row is judged against: its family's row in
    /// the sensor's variant ([`Self::all_channel_baseline`]), or the other
    /// variant when that one is missing.
    pub fn baseline_for(&self, row: &PaperRow) -> Option<&PaperRow> {
        let stem = match row.baseline? {
            BaselineFamily::AcquisitionFit => format!("Baseline_{}", short(&row.acquisition)),
            BaselineFamily::D65FitThenT => "Baseline+T".to_string(),
            // `SI_Ens+T` against `Baseline_Ens+T`
            BaselineFamily::EnsembleFitThenT => row.method.replacen("SI_", "Baseline_", 1),
        };
        self.baseline_row(&row.acquisition, &stem)
    }

    /// An ensemble row's D65-fit + T baseline, which judged the ensembles
    /// before [`BaselineFamily::EnsembleFitThenT`]: shown beside its own.
    pub fn d65_baseline_for(&self, row: &PaperRow) -> Option<&PaperRow> {
        (row.baseline? == BaselineFamily::EnsembleFitThenT)
            .then(|| self.baseline_row(&row.acquisition, "Baseline+T"))?
    }

    /// The baseline `stem` under `acquisition` in the sensor's variant, or
    /// the other variant when that one is missing.
    fn baseline_row(&self, acquisition: &str, stem: &str) -> Option<&PaperRow> {
        let all = format!("{stem} all");
        let (first, second) = if self.all_channel_baseline() {
            (all.as_str(), stem)
        } else {
            (stem, all.as_str())
        };
        self.row(acquisition, first)
            .or_else(|| self.row(acquisition, second))
    }

    fn compare_with_baselines(&self) -> Vec<BaselineComparison> {
        self.rows
            .iter()
            .filter_map(|r| {
                let b = self.baseline_for(r)?;
                let ratio = |l: f64, b: f64| if b > 0.0 { l / b } else { f64::NAN };
                let mut pixel_ratios = vec![(1.0, ratio(r.pixel_mean, b.pixel_mean))];
                for p in &r.exposures {
                    if let Some(q) = b.exposures.iter().find(|q| q.factor == p.factor) {
                        pixel_ratios.push((p.factor, ratio(p.pixel_mean, q.pixel_mean)));
                    }
                }
                Some(BaselineComparison {
                    acquisition: r.acquisition.clone(),
                    method: r.method.clone(),
                    baseline: b.method.clone(),
                    mean_difference: r.mean - b.mean,
                    capture_mean_difference: r
                        .captures
                        .as_ref()
                        .zip(b.captures.as_ref())
                        .map(|(r, b)| r.mean - b.mean),
                    pixel_ratios,
                })
            })
            .collect()
    }

    /// The lowest exposure factor evaluated (the low-light column).
    fn low_light(row: &PaperRow) -> Option<&ExposurePoint> {
        row.exposures
            .iter()
            .min_by(|a, b| a.factor.total_cmp(&b.factor))
    }

    /// The captures a run was evaluated on: 1, or [`PaperOptions::captures`].
    pub fn n_captures(&self) -> usize {
        self.rows
            .iter()
            .filter_map(|r| r.captures.as_ref())
            .map(|c| c.per_capture.len())
            .max()
            .unwrap_or(1)
    }

    /// With several captures: every row's mean over them beside its first
    /// capture and, for L3 rows, the matching linear map's; else nothing.
    fn captures_markdown(&self) -> String {
        let n = self.n_captures();
        if n < 2 {
            return String::new();
        }
        let seed = self.options.chart.seed;
        let mut s = format!(
            "\nOver {n} noisy captures of the chart (seeds {seed}–{}): each row's mean patch-mean ΔE2000 and its spread from capture to capture.\n\n\
             | acquisition | method | first capture | mean over {n} (std) | matching linear map over {n} | L3 − linear |\n|---|---|---|---|---|---|\n",
            seed.wrapping_add(n as u64 - 1)
        );
        for r in &self.rows {
            let Some(c) = &r.captures else { continue };
            let (lin, gap) = match c.linear_mean {
                Some(l) => (format!("{l:.2}"), format!("{:+.2}", c.mean - l)),
                None => ("—".into(), "—".into()),
            };
            s.push_str(&format!(
                "| {} | {} | {:.2} | {:.2} ({:.2}) | {lin} | {gap} |\n",
                r.acquisition, r.method, r.mean, c.mean, c.std
            ));
        }
        s
    }

    /// A markdown rendering beside the paper's figures.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "Natural-100 chart ({}), sensor `{}`, CIEDE2000 of patch means\n\n",
            self.chart, self.sensor
        );
        let low = self
            .rows
            .first()
            .and_then(Self::low_light)
            .map(|p| format!("per-pixel at {}×", p.factor))
            .unwrap_or_else(|| "low light".into());
        s.push_str(&format!("| acquisition | method | mean ΔE (std) | median | p90 | max | per-pixel mean | {low} | matching linear map | paper mean (std) / p90 |\n"));
        s.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
        for r in &self.rows {
            let paper = r
                .paper
                .map(|p| format!("{:.1} ({:.1}) / {:.1}", p[0], p[1], p[2]))
                .unwrap_or_else(|| "—".into());
            let linear = r
                .linear_mean
                .map(|v| format!("{v:.2}"))
                .unwrap_or_else(|| "—".into());
            let low = Self::low_light(r)
                .map(|p| format!("{:.2}", p.pixel_mean))
                .unwrap_or_else(|| "—".into());
            s.push_str(&format!(
                "| {} | {} | {:.2} ({:.2}) | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} |\n",
                r.acquisition,
                r.method,
                r.mean,
                r.std,
                r.median,
                r.p90,
                r.max,
                r.pixel_mean,
                low,
                linear,
                paper
            ));
        }
        s.push_str(&self.captures_markdown());
        if !self.comparisons.is_empty() {
            s.push_str("\nEach L3 row against its conventional baseline (of RGB and all channels, the one with the lower mean patch-mean ΔE over this sensor's baseline rows at full exposure): patch-mean difference, and per-pixel ΔE as a ratio L3 / baseline at each exposure factor.\n\n");
            let several = self.n_captures() > 1;
            s.push_str(if several {
                "| acquisition | method | baseline | Δ patch mean | Δ over the captures | per-pixel L3/baseline |\n|---|---|---|---|---|---|\n"
            } else {
                "| acquisition | method | baseline | Δ patch mean | per-pixel L3/baseline |\n|---|---|---|---|---|\n"
            });
            for c in &self.comparisons {
                let ratios: Vec<String> = c
                    .pixel_ratios
                    .iter()
                    .map(|(f, r)| format!("{f}×: {r:.2}"))
                    .collect();
                let over = match (several, c.capture_mean_difference) {
                    (false, _) => String::new(),
                    (true, Some(d)) => format!(" {d:+.2} |"),
                    (true, None) => " — |".into(),
                };
                s.push_str(&format!(
                    "| {} | {} | {} | {:+.2} |{over} {} |\n",
                    c.acquisition,
                    c.method,
                    c.baseline,
                    c.mean_difference,
                    ratios.join(", ")
                ));
            }
        }
        let st = &self.storage;
        s.push_str(&format!(
            "\nStorage for {} illuminants: one SI table + {} matrices = {} bytes; {} cross-illuminant tables = {} bytes ({:.1}× more).\n",
            st.illuminants,
            st.illuminants,
            st.si_plus_matrices_bytes,
            st.illuminants,
            st.cross_tables_bytes,
            st.cross_tables_bytes as f64 / st.si_plus_matrices_bytes.max(1) as f64
        ));
        s
    }
}

/// One markdown table over several sensors' Table 1 runs: every L3 row with
/// its matching linear map and its baseline, so that a regression on any
/// sensor shows in one place.
pub fn paper_summary(tables: &[PaperTable]) -> String {
    let n = tables.iter().map(PaperTable::n_captures).max().unwrap_or(1);
    let (more, more_rule) = if n > 1 {
        (
            format!(
                " mean over {n} captures (std) | matching linear map over {n} | Δ over {n} vs baseline |"
            ),
            "---|---|---|",
        )
    } else {
        (String::new(), "")
    };
    let mut s = format!(
        "Table 1 on every sensor (patch-mean ΔE2000; per-pixel ΔE at full and lowest exposure)\n\n\
         | sensor | acquisition | method | mean | matching linear map | per-pixel | low light per-pixel | baseline | Δ mean vs baseline | low light L3/baseline |{more}\n\
         |---|---|---|---|---|---|---|---|---|---|{more_rule}\n",
    );
    let f2 = |v: Option<f64>| v.map(|v| format!("{v:.2}")).unwrap_or_else(|| "—".into());
    for t in tables {
        for r in t.rows.iter().filter(|r| r.linear_mean.is_some()) {
            let b = t.baseline_for(r);
            let low = PaperTable::low_light(r);
            let low_b = b.and_then(PaperTable::low_light);
            let over = match (&r.captures, n > 1) {
                (Some(c), true) => format!(
                    " {:.2} ({:.2}) | {} | {} |",
                    c.mean,
                    c.std,
                    f2(c.linear_mean),
                    b.and_then(|b| b.captures.as_ref())
                        .map(|bc| format!("{:+.2}", c.mean - bc.mean))
                        .unwrap_or_else(|| "—".into())
                ),
                (None, true) => " — | — | — |".into(),
                _ => String::new(),
            };
            s.push_str(&format!(
                "| {} | {} | {} | {:.2} | {} | {:.2} | {} | {} | {} | {} |{over}\n",
                t.sensor,
                r.acquisition,
                r.method,
                r.mean,
                f2(r.linear_mean),
                r.pixel_mean,
                f2(low.map(|p| p.pixel_mean)),
                b.map(|b| {
                    let d65 = t
                        .d65_baseline_for(r)
                        .map(|d| format!(" (D65 fit: {:.2}, {:+.2})", d.mean, r.mean - d.mean))
                        .unwrap_or_default();
                    format!("{} {:.2}{d65}", b.method, b.mean)
                })
                .unwrap_or_else(|| "—".into()),
                b.map(|b| format!("{:+.2}", r.mean - b.mean))
                    .unwrap_or_else(|| "—".into()),
                f2(low
                    .zip(low_b)
                    .map(|(l, b)| l.pixel_mean / b.pixel_mean.max(1e-12))),
            ));
        }
    }
    s
}

/// `first` (a method's mean patch-mean ΔE on the first capture), then its
/// mean on each of the further captures `extra`.
fn means_over(
    first: f64,
    extra: &[ChartCapture],
    camera: &Camera,
    method: &Method,
    name: &str,
    correction: &IlluminantEntry,
    setup: &ChartSetup,
) -> Result<Vec<f64>, EvalError> {
    std::iter::once(Ok(first))
        .chain(extra.iter().map(|cap| {
            evaluate_capture(camera, cap, method, name, correction, setup).map(|r| r.summary.mean)
        }))
        .collect()
}

fn short(name: &str) -> String {
    match name.to_ascii_lowercase().as_str() {
        "tungsten" => "Tun".into(),
        "fluorescent" => "Flu".into(),
        _ => name.to_string(),
    }
}

/// Train the tables and evaluate every row. `progress(message)` reports each step.
pub fn run_paper_table(
    design: &SensorDesign,
    iset: Option<&IsetData>,
    opts: &PaperOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<PaperTable, EvalError> {
    if opts.captures != 1 {
        check_captures(opts.captures, "a Table 1 over several captures")?;
        if !opts.chart.noise {
            return Err(EvalError::Invalid(
                "a Table 1 over several captures needs noise: every noise-free capture is the same"
                    .into(),
            ));
        }
    }
    let grid = WavelengthGrid::default();
    let camera = Camera::new(design, grid, iset).map_err(|e| EvalError::Invalid(e.to_string()))?;
    let mut registry = IlluminantRegistry::with_defaults(grid, iset)?;
    let cancel = AtomicBool::new(false);
    let train = |kind: TableKind, ills: &[&str]| -> Result<L3Table, EvalError> {
        progress(&format!("training {kind} table on {}", ills.join("+")));
        let spec = TrainingSpec {
            kind,
            illuminants: ills.iter().map(|s| s.to_string()).collect(),
            seed: opts.seed,
            scenes: opts.scenes,
            scene_size: opts.scene_size,
            chroma_classes: opts.chroma_classes,
            ..base_training_spec(!opts.chart.noise)
        };
        train_table(design, &spec, iset, &|_, _| {}, &cancel)
            .map_err(|e| EvalError::Invalid(e.to_string()))
    };
    let si_d65 = train(TableKind::SameIlluminant, &["D65"])?;
    let si_ens = train(TableKind::SameIlluminant, &["D65", "Tungsten"])?;
    let all_ens: Vec<&str> = std::iter::once("D65")
        .chain(opts.acquisitions.iter().map(|s| s.as_str()))
        .collect();
    let si_all = if opts.acquisitions.len() > 1 {
        Some(train(TableKind::SameIlluminant, &all_ens)?)
    } else {
        None
    };
    progress("fitting the baseline colour matrices");
    let d65_list = ["D65".to_string()];
    let fit_matrix = |ills: &[String], kind: TableKind, channels: ChannelSet| {
        let fit = ColourFit {
            illuminants: ills,
            kind,
            channels,
            preserve_white: kind == TableKind::CrossIlluminant,
            through_correction: false,
        };
        fit_colour_matrix(&camera, &fit, iset)
    };
    let d65_rgb = fit_matrix(&d65_list, TableKind::SameIlluminant, ChannelSet::Rgb)?;
    let d65_all = fit_matrix(&d65_list, TableKind::SameIlluminant, ChannelSet::All)?;
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
            fit_matrix(lights, TableKind::SameIlluminant, ChannelSet::Rgb)?,
            fit_matrix(lights, TableKind::SameIlluminant, ChannelSet::All)?,
        ));
    }
    let mut rows = Vec::new();
    let mut reports = Vec::new();
    let mut chart_name = String::new();
    let mut cross_bytes = 0usize;
    let paper: BTreeMap<&str, [f64; 3]> = PAPER_TABLE1
        .iter()
        .map(|(m, a, b, c)| (*m, [*a, *b, *c]))
        .collect();
    for acq in &opts.acquisitions {
        let tag = short(acq);
        let cross = train(TableKind::CrossIlluminant, &[acq])?;
        let si_acq = train(TableKind::SameIlluminant, &[acq])?;
        cross_bytes += cross.kernel_bytes();
        let corr = registry.resolve(acq, iset)?;
        let mut si_rows: Vec<(String, &L3Table)> = vec![
            (format!("SI_{tag}"), &si_acq),
            ("SI_D65".into(), &si_d65),
            ("SI_Ens".into(), &si_ens),
        ];
        if let Some(t) = &si_all {
            si_rows.push((format!("SI_Ens{}", all_ens.len()), t));
        }
        let mut methods: Vec<(String, Method, Option<f64>)> = vec![(
            format!("I_{tag}"),
            Method::Table(&cross),
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
        let acq_list = [acq.to_string()];
        let acq_rgb = fit_matrix(&acq_list, TableKind::CrossIlluminant, ChannelSet::Rgb)?;
        let acq_all = fit_matrix(&acq_list, TableKind::CrossIlluminant, ChannelSet::All)?;
        // the acquisition-fit baselines are white-balanced cross maps: no T
        let identity = crate::l3::correct::IlluminantEntry {
            t: crate::l3::correct::IDENTITY,
            ..corr.clone()
        };
        methods.push(("Baseline+T".into(), Method::Baseline(&d65_rgb), None));
        methods.push(("Baseline+T all".into(), Method::Baseline(&d65_all), None));
        for (name, rgb, all) in &ensemble_fits {
            methods.push((format!("Baseline_{name}+T"), Method::Baseline(rgb), None));
            methods.push((
                format!("Baseline_{name}+T all"),
                Method::Baseline(all),
                None,
            ));
        }
        let acq_names = [format!("Baseline_{tag}"), format!("Baseline_{tag} all")];
        methods.push((format!("Baseline_{tag}"), Method::Baseline(&acq_rgb), None));
        methods.push((
            format!("Baseline_{tag} all"),
            Method::Baseline(&acq_all),
            None,
        ));
        let cap = simulate_chart(&camera, acq, iset, &opts.chart)?;
        // the further captures of a run over several (chart seeds after the first)
        let extra = (1..opts.captures as u64)
            .map(|k| {
                let setup = ChartSetup {
                    seed: opts.chart.seed.wrapping_add(k),
                    ..opts.chart.clone()
                };
                simulate_chart(&camera, acq, iset, &setup)
            })
            .collect::<Result<Vec<_>, EvalError>>()?;
        let lower = opts
            .exposures
            .iter()
            .map(|&f| {
                let setup = LightLevel::ExposureFactor(f).apply(&opts.chart)?;
                Ok((f, simulate_chart(&camera, acq, iset, &setup)?, setup))
            })
            .collect::<Result<Vec<_>, EvalError>>()?;
        for (name, method, secs) in methods {
            progress(&format!("evaluating {name} under {acq}"));
            let is_acq_baseline = acq_names.contains(&name);
            let camera_aware = name.ends_with("+C");
            let own: IlluminantEntry = match method {
                Method::Table(t) if camera_aware => camera_corrected(
                    &camera,
                    &t.level_colour_maps(&noise_model(design))?,
                    &corr,
                    iset,
                )?,
                _ if is_acq_baseline => identity.clone(),
                _ => corr.clone(),
            };
            let c = &own;
            let rep = evaluate_capture(&camera, &cap, &method, &name, c, &opts.chart)?;
            let means = |first: f64, method: &Method, name: &str, corr: &IlluminantEntry| {
                means_over(first, &extra, &camera, method, name, corr, &opts.chart)
            };
            let row_means = means(rep.summary.mean, &method, &name, c)?;
            let (linear_mean, linear_means, baseline) = match method {
                Method::Table(t) => {
                    let map = matching_linear_map(&camera, t, acq, iset)?;
                    // the linear map gets its own C, as the table does
                    let lin_corr = if camera_aware {
                        camera_corrected(
                            &camera,
                            &[LevelMap {
                                map: map.clone(),
                                noise: None,
                                chroma: None,
                            }],
                            &corr,
                            iset,
                        )?
                    } else {
                        corr.clone()
                    };
                    let lt = linear_table(t, &map)?;
                    let (lin_method, lin_name) = (Method::Table(&lt), format!("linear {name}"));
                    let lin = evaluate_capture(
                        &camera,
                        &cap,
                        &lin_method,
                        &lin_name,
                        &lin_corr,
                        &opts.chart,
                    )?;
                    let lin_means = means(lin.summary.mean, &lin_method, &lin_name, &lin_corr)?;
                    // like with like: a table for this light alone against
                    // the matrix for this light; one table for several
                    // lights (then T) against one matrix (then T)
                    let only_acq = matches!(t.meta.train_illuminants.as_slice(),
                        [i] if i.eq_ignore_ascii_case(acq));
                    let family =
                        if only_acq || camera_aware || t.meta.kind == TableKind::CrossIlluminant {
                            BaselineFamily::AcquisitionFit
                        } else if t.meta.train_illuminants.len() > 1 {
                            BaselineFamily::EnsembleFitThenT
                        } else {
                            BaselineFamily::D65FitThenT
                        };
                    (Some(lin.summary.mean), Some(lin_means), Some(family))
                }
                Method::Baseline(_) => (None, None, None),
            };
            let exposures = lower
                .iter()
                .map(|(f, lc, ls)| {
                    let r = evaluate_capture(&camera, lc, &method, &name, c, ls)?;
                    Ok(ExposurePoint {
                        factor: *f,
                        mean: r.summary.mean,
                        pixel_mean: r.per_pixel.mean,
                    })
                })
                .collect::<Result<Vec<_>, EvalError>>()?;
            chart_name = rep.chart.clone();
            let is_tungsten = tag == "Tun";
            rows.push(PaperRow {
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
                    paper.get(name.as_str()).copied()
                } else {
                    None
                },
                training_seconds: secs,
                captures: (opts.captures > 1)
                    .then(|| CaptureSpread::new(row_means, linear_means.as_deref())),
            });
            reports.push(rep);
        }
    }
    // N = the registry's illuminants: one cross table each, against one SI
    // table plus one 3×3 matrix (9 f64) each.
    let n = registry.len().max(1);
    let table_bytes = si_ens.kernel_bytes();
    let matrix_bytes = 9 * 8;
    let cross_bytes = cross_bytes / opts.acquisitions.len().max(1) * n;
    let mut table = PaperTable {
        sensor: design.name.clone(),
        chart: chart_name,
        rows,
        storage: StorageComparison {
            illuminants: n,
            table_bytes,
            matrix_bytes,
            si_plus_matrices_bytes: table_bytes + n * matrix_bytes,
            cross_tables_bytes: cross_bytes,
        },
        reports,
        options: opts.clone(),
        comparisons: Vec::new(),
    };
    table.comparisons = table.compare_with_baselines();
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(acq: &str, method: &str, mean: f64, baseline: Option<BaselineFamily>) -> PaperRow {
        PaperRow {
            acquisition: acq.into(),
            method: method.into(),
            mean,
            std: 0.0,
            median: mean,
            p90: mean,
            max: mean,
            pixel_mean: mean,
            linear_mean: baseline.map(|_| mean),
            exposures: Vec::new(),
            baseline,
            paper: None,
            training_seconds: None,
            captures: None,
        }
    }

    fn table(rows: Vec<PaperRow>) -> PaperTable {
        PaperTable {
            sensor: "s".into(),
            chart: "natural100".into(),
            rows,
            storage: StorageComparison {
                illuminants: 0,
                table_bytes: 0,
                matrix_bytes: 0,
                si_plus_matrices_bytes: 0,
                cross_tables_bytes: 0,
            },
            reports: Vec::new(),
            options: PaperOptions::default(),
            comparisons: Vec::new(),
        }
    }

    #[test]
    fn one_baseline_variant_per_sensor_by_its_mean_over_every_baseline_row() {
        use BaselineFamily::*;
        // RGB wins under tungsten by 0.01, all channels wins overall
        let t = table(vec![
            row("Tungsten", "I_Tun", 2.7, Some(AcquisitionFit)),
            row("Tungsten", "SI_D65+T", 4.0, Some(D65FitThenT)),
            row("Tungsten", "Baseline_Tun", 4.52, None),
            row("Tungsten", "Baseline_Tun all", 4.53, None),
            row("Tungsten", "Baseline+T", 9.04, None),
            row("Tungsten", "Baseline+T all", 4.55, None),
        ]);
        assert!(t.all_channel_baseline());
        let base = |m: &str| {
            let r = t.row("Tungsten", m).unwrap();
            t.baseline_for(r).unwrap().method.clone()
        };
        assert_eq!(base("I_Tun"), "Baseline_Tun all");
        assert_eq!(base("SI_D65+T"), "Baseline+T all");
        // RGB wins overall: every row uses it, and a missing variant falls
        // back to the other
        let t = table(vec![
            row("Tungsten", "I_Tun", 2.7, Some(AcquisitionFit)),
            row("Tungsten", "SI_D65+T", 4.0, Some(D65FitThenT)),
            row("Tungsten", "Baseline_Tun", 4.0, None),
            row("Tungsten", "Baseline_Tun all", 4.5, None),
            row("Tungsten", "Baseline+T all", 4.55, None),
        ]);
        assert!(!t.all_channel_baseline());
        let i = t.row("Tungsten", "I_Tun").unwrap();
        assert_eq!(t.baseline_for(i).unwrap().method, "Baseline_Tun");
        let s = t.row("Tungsten", "SI_D65+T").unwrap();
        assert_eq!(t.baseline_for(s).unwrap().method, "Baseline+T all");
    }

    #[test]
    fn an_ensemble_is_judged_against_the_matrix_fitted_on_its_lights() {
        use BaselineFamily::*;
        let t = table(vec![
            row("Fluorescent", "SI_D65+T", 1.53, Some(D65FitThenT)),
            row("Fluorescent", "SI_Ens+T", 1.61, Some(EnsembleFitThenT)),
            row("Fluorescent", "SI_Ens3+T", 1.46, Some(EnsembleFitThenT)),
            row("Fluorescent", "Baseline+T", 1.96, None),
            row("Fluorescent", "Baseline+T all", 1.48, None),
            row("Fluorescent", "Baseline_Ens+T", 1.89, None),
            row("Fluorescent", "Baseline_Ens+T all", 1.57, None),
            row("Fluorescent", "Baseline_Ens3+T", 1.57, None),
            row("Fluorescent", "Baseline_Ens3+T all", 1.52, None),
        ]);
        assert!(t.all_channel_baseline());
        let r = |m: &str| t.row("Fluorescent", m).unwrap();
        let base = |m: &str| t.baseline_for(r(m)).unwrap().method.clone();
        assert_eq!(base("SI_D65+T"), "Baseline+T all");
        assert_eq!(base("SI_Ens+T"), "Baseline_Ens+T all");
        assert_eq!(base("SI_Ens3+T"), "Baseline_Ens3+T all");
        // the D65 fit, which judged the ensembles before, is shown beside
        let d65 = |m: &str| t.d65_baseline_for(r(m)).map(|b| b.method.clone());
        assert_eq!(d65("SI_Ens+T").as_deref(), Some("Baseline+T all"));
        assert_eq!(d65("SI_D65+T"), None);
        let summary = paper_summary(std::slice::from_ref(&t));
        assert!(
            summary.contains("| Baseline_Ens+T all 1.57 (D65 fit: 1.48, +0.13) | +0.04 |"),
            "{summary}"
        );
    }

    #[test]
    fn several_captures_need_noise_and_a_count_in_range() {
        let design = SensorDesign::paper_default();
        let run = |captures: usize, noise: bool| {
            let opts = PaperOptions {
                captures,
                chart: ChartSetup {
                    noise,
                    ..ChartSetup::default()
                },
                ..PaperOptions::default()
            };
            // (refused before any table is trained)
            match run_paper_table(&design, None, &opts, &|_| {}) {
                Err(EvalError::Invalid(m)) => m,
                other => panic!(
                    "{captures} captures, noise {noise}: {:?}",
                    other.map(|_| ())
                ),
            }
        };
        assert!(run(4, false).contains("needs noise"), "{}", run(4, false));
        for n in [0, super::super::MAX_CAPTURES + 1] {
            assert!(run(n, true).contains("captures"), "{}", run(n, true));
        }
    }

    #[test]
    fn rows_over_several_captures_are_reported_beside_the_first() {
        use BaselineFamily::*;
        let with = |mut r: PaperRow, means: &[f64], linear: Option<&[f64]>| {
            r.captures = Some(CaptureSpread::new(means.to_vec(), linear));
            r
        };
        let mut t = table(vec![
            with(
                row("Tungsten", "I_Tun", 2.67, Some(AcquisitionFit)),
                &[2.67, 2.87],
                Some(&[5.0, 5.2]),
            ),
            with(
                row("Tungsten", "Baseline_Tun", 4.0, None),
                &[4.0, 4.4],
                None,
            ),
            row("Tungsten", "Baseline_Tun all", 4.5, None),
        ]);
        let spread = t.rows[0].captures.clone().unwrap();
        assert!((spread.mean - 2.77).abs() < 1e-12, "{spread:?}");
        assert!((spread.linear_mean.unwrap() - 5.1).abs() < 1e-12);
        assert_eq!(t.n_captures(), 2);
        t.comparisons = t.compare_with_baselines();
        let c = &t.comparisons[0];
        assert!((c.mean_difference - (2.67 - 4.0)).abs() < 1e-12);
        assert!((c.capture_mean_difference.unwrap() - (2.77 - 4.2)).abs() < 1e-12);
        let md = t.markdown();
        assert!(
            md.contains("Over 2 noisy captures of the chart (seeds 7–8)"),
            "{md}"
        );
        assert!(md.contains("| Tungsten | I_Tun | 2.67 | 2.77 ("), "{md}");
        assert!(md.contains("| 5.10 | -2.33 |"), "{md}");
        assert!(md.contains("| -1.33 | -1.43 |"), "{md}");
        let summary = paper_summary(std::slice::from_ref(&t));
        assert!(summary.contains("mean over 2 captures (std)"), "{summary}");
        assert!(
            summary.contains("| 2.77 (0.10) | 5.10 | -1.43 |"),
            "{summary}"
        );
        assert!(
            md.contains("| Δ patch mean | Δ over the captures |"),
            "{md}"
        );
        // one capture: the columns are not there
        let mut one = table(vec![
            row("Tungsten", "I_Tun", 2.67, Some(AcquisitionFit)),
            row("Tungsten", "Baseline_Tun", 4.0, None),
        ]);
        one.comparisons = one.compare_with_baselines();
        assert_eq!(one.n_captures(), 1);
        let md = one.markdown();
        assert!(
            !md.contains("noisy captures") && !md.contains("captures |"),
            "{md}"
        );
        assert!(md.contains("| Baseline_Tun | -1.33 | 1×"), "{md}");
        assert!(!paper_summary(&[one]).contains("captures"));
    }
}
