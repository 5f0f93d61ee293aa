//! Accuracy on the sensor catalogue: for each sensor, the noise-free SI_Tun+T row of Table 1
//! (a same-illuminant table trained under tungsten without noise, then T, on the noise-free
//! Natural-100 chart under tungsten) against its matching linear map, and the table's largest
//! kernel norm. Each row is computed by the same steps as that row of [`run_paper_table`]
//! (its training spec, its linear map and correction, its capture), without the rest of the
//! table.
//!
//! [`run_paper_table`]: crate::eval::run_paper_table

use std::sync::atomic::AtomicBool;

use serde::{Deserialize, Serialize};

use super::paper_table::{PaperOptions, linear_counterpart, short, table_spec};
use super::{ChartSetup, EvalError, Method, evaluate_capture, simulate_chart};
use crate::camera::{Camera, SensorDesign};
use crate::l3::L3Table;
use crate::l3::correct::IlluminantRegistry;
use crate::l3::learn::train_table;
use crate::l3::table::TableKind;
use crate::spectral::{IsetData, WavelengthGrid};

/// The acquisition light of the sweep.
pub const SWEEP_LIGHT: &str = "Tungsten";

/// How far above its matching linear map a row may be and still count as matching it.
pub const LINEAR_MARGIN: f64 = 0.2;

/// The largest kernel norm a well-conditioned table is expected to keep.
pub const NORM_BOUND: f64 = 100.0;

/// Options of a sweep: the training size and seed of every table, and the chart.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SweepOptions {
    pub scenes: usize,
    pub scene_size: usize,
    /// The training seed and the chart's.
    pub seed: u64,
    /// Side of each chart patch in pixels.
    pub patch_px: usize,
}

impl Default for SweepOptions {
    /// Table 1's CI size (`tests/table1`, `l3 eval --paper-table`'s defaults): 48 scenes of
    /// 96 px, seed 7.
    fn default() -> Self {
        let p = PaperOptions::default();
        Self {
            scenes: p.scenes,
            scene_size: p.scene_size,
            seed: ChartSetup::default().seed,
            patch_px: ChartSetup::default().patch_px,
        }
    }
}

impl SweepOptions {
    /// The noise-free Table 1 run under tungsten these options stand for.
    fn paper_options(&self) -> PaperOptions {
        PaperOptions {
            acquisitions: vec![SWEEP_LIGHT.into()],
            scenes: self.scenes,
            scene_size: self.scene_size,
            seed: self.seed,
            chart: ChartSetup {
                seed: self.seed,
                noise: false,
                patch_px: self.patch_px,
                ..ChartSetup::default()
            },
            // the sweep reads colour only: no spatial metrics
            spatial_px: 0,
            ..PaperOptions::default()
        }
    }
}

/// One sensor's row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SweepRow {
    pub sensor: String,
    /// The CFA, as a design file writes it (`RG/GB`).
    pub cfa: String,
    /// SI_Tun+T: mean patch-mean ΔE2000.
    pub l3_mean: f64,
    pub l3_p90: f64,
    /// Its matching linear map (+T) on the same frame.
    pub linear_mean: f64,
    /// `l3_mean − linear_mean`: negative where the table beats its linear map.
    pub delta: f64,
    /// The largest kernel norm of the table's classes, and that class's luminance level
    /// (0: the darkest).
    pub max_kernel_norm: f64,
    pub max_norm_level: usize,
    pub training_seconds: f64,
}

/// A sweep over several sensors.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CatalogueSweep {
    pub options: SweepOptions,
    /// Sorted by sensor name.
    pub rows: Vec<SweepRow>,
    /// Wall-clock time of the whole sweep.
    pub seconds: f64,
}

/// The sweep's summary figures.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepSummary {
    pub sensors: usize,
    /// Rows within [`LINEAR_MARGIN`] of their linear map or better, and those better.
    pub within: usize,
    pub better: usize,
    /// The largest delta and its sensor.
    pub worst_delta: (f64, String),
    /// The largest kernel norm and its sensor.
    pub max_norm: (f64, String),
    /// Rows whose largest kernel norm is within [`NORM_BOUND`].
    pub norm_within: usize,
}

/// One sensor's row: train its SI table under tungsten without noise and evaluate it and
/// its matching linear map, both then T, on the noise-free chart.
pub fn sweep_row(
    design: &SensorDesign,
    iset: Option<&IsetData>,
    opts: &SweepOptions,
    cancel: &AtomicBool,
) -> Result<SweepRow, EvalError> {
    let popts = opts.paper_options();
    let grid = WavelengthGrid::default();
    let camera = Camera::new(design, grid, iset).map_err(|e| EvalError::Invalid(e.to_string()))?;
    let corr = IlluminantRegistry::with_defaults(grid, iset)?.resolve(SWEEP_LIGHT, iset)?;
    let spec = table_spec(&popts, TableKind::SameIlluminant, &[SWEEP_LIGHT]);
    let table = train_table(design, &spec, iset, &|_, _| {}, cancel)?;
    let chart = &popts.chart;
    let cap = simulate_chart(&camera, SWEEP_LIGHT, iset, chart)?;
    let name = format!("SI_{}+T", short(SWEEP_LIGHT));
    let rep = evaluate_capture(&camera, &cap, &Method::Table(&table), &name, &corr, chart)?;
    let (lt, lin_corr) = linear_counterpart(&camera, &table, SWEEP_LIGHT, &corr, false, iset)?;
    let lin_name = format!("linear {name}");
    let lin = evaluate_capture(
        &camera,
        &cap,
        &Method::Table(&lt),
        &lin_name,
        &lin_corr,
        chart,
    )?;
    let (max_kernel_norm, max_norm_level) = largest_norm(&table);
    Ok(SweepRow {
        sensor: design.name.clone(),
        cfa: design.cfa.to_string(),
        l3_mean: rep.summary.mean,
        l3_p90: rep.summary.p90,
        linear_mean: lin.summary.mean,
        delta: rep.summary.mean - lin.summary.mean,
        max_kernel_norm,
        max_norm_level,
        training_seconds: table.meta.training_seconds,
    })
}

/// The largest kernel norm of a table's classes and its class's level.
fn largest_norm(table: &L3Table) -> (f64, usize) {
    table
        .reports
        .iter()
        .enumerate()
        .fold((0.0, 0), |(best, level), (i, r)| {
            if r.kernel_norm > best {
                (r.kernel_norm, table.class_level(i))
            } else {
                (best, level)
            }
        })
}

/// The sweep over `designs`, one sensor after the other: each training is parallel inside,
/// and two sensors at a time on two cores took longer (83 s against 73 s for two sensors)
/// for no gain. `progress(message)` reports each finished sensor.
pub fn catalogue_sweep(
    designs: &[SensorDesign],
    iset: Option<&IsetData>,
    opts: &SweepOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<CatalogueSweep, EvalError> {
    let started = std::time::Instant::now();
    let cancel = AtomicBool::new(false);
    let n = designs.len();
    let one = |(i, d): (usize, &SensorDesign)| {
        let row = sweep_row(d, iset, opts, &cancel)
            .map_err(|e| EvalError::Invalid(format!("sensor {}: {e}", d.name)))?;
        let k = i + 1;
        progress(&format!(
            "[{k}/{n}] {}: SI_Tun+T {:.2}, linear map {:.2} ({:+.2}), max kernel norm {:.1}, trained in {:.1} s",
            row.sensor,
            row.l3_mean,
            row.linear_mean,
            row.delta,
            row.max_kernel_norm,
            row.training_seconds
        ));
        Ok(row)
    };
    let mut rows = designs
        .iter()
        .enumerate()
        .map(one)
        .collect::<Result<Vec<_>, EvalError>>()?;
    rows.sort_by(|a, b| a.sensor.cmp(&b.sensor));
    Ok(CatalogueSweep {
        options: opts.clone(),
        rows,
        seconds: started.elapsed().as_secs_f64(),
    })
}

impl CatalogueSweep {
    /// The summary figures; `None` for an empty sweep.
    pub fn summary(&self) -> Option<SweepSummary> {
        let worst = self
            .rows
            .iter()
            .max_by(|a, b| a.delta.total_cmp(&b.delta))?;
        let norm = self
            .rows
            .iter()
            .max_by(|a, b| a.max_kernel_norm.total_cmp(&b.max_kernel_norm))?;
        Some(SweepSummary {
            sensors: self.rows.len(),
            within: self
                .rows
                .iter()
                .filter(|r| r.delta <= LINEAR_MARGIN)
                .count(),
            better: self.rows.iter().filter(|r| r.delta < 0.0).count(),
            worst_delta: (worst.delta, worst.sensor.clone()),
            max_norm: (norm.max_kernel_norm, norm.sensor.clone()),
            norm_within: self
                .rows
                .iter()
                .filter(|r| r.max_kernel_norm <= NORM_BOUND)
                .count(),
        })
    }

    /// The rows as a markdown table, sorted by sensor name, and a line of summary.
    pub fn markdown(&self) -> String {
        let o = &self.options;
        let mut md = format!(
            "Noise-free SI_Tun+T (a same-illuminant table trained under tungsten without noise, \
             then T) against its matching linear map (+T), mean patch-mean ΔE2000 on the \
             noise-free Natural-100 chart under tungsten; {} scenes of {} px, seed {}, \
             {}-px patches.\n\n\
             | sensor | CFA | SI_Tun+T | p90 | linear map | delta | max kernel norm (level) | training s |\n\
             |---|---|---|---|---|---|---|---|\n",
            o.scenes, o.scene_size, o.seed, o.patch_px
        );
        for r in &self.rows {
            let mark = |miss: bool| if miss { " **miss**" } else { "" };
            md.push_str(&format!(
                "| {} | `{}` | {:.2} | {:.2} | {:.2} | {:+.2}{} | {:.1} ({}){} | {:.1} |\n",
                r.sensor,
                r.cfa,
                r.l3_mean,
                r.l3_p90,
                r.linear_mean,
                r.delta,
                mark(r.delta > LINEAR_MARGIN),
                r.max_kernel_norm,
                r.max_norm_level,
                mark(r.max_kernel_norm > NORM_BOUND),
                r.training_seconds
            ));
        }
        if let Some(s) = self.summary() {
            md.push_str(&format!(
                "\n{} of {} sensors within {LINEAR_MARGIN} of their linear map or better ({} better); \
                 worst delta {:+.2} ({}); {} of {} with every kernel norm ≤ {NORM_BOUND}, the largest \
                 {:.1} ({}). {:.0} s in all.\n",
                s.within,
                s.sensors,
                s.better,
                s.worst_delta.0,
                s.worst_delta.1,
                s.norm_within,
                s.sensors,
                s.max_norm.0,
                s.max_norm.1,
                self.seconds
            ));
        }
        md
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(sensor: &str, delta: f64, norm: f64) -> SweepRow {
        SweepRow {
            sensor: sensor.into(),
            cfa: "RG/GB".into(),
            l3_mean: 1.5 + delta,
            l3_p90: 3.0,
            linear_mean: 1.5,
            delta,
            max_kernel_norm: norm,
            max_norm_level: 3,
            training_seconds: 10.0,
        }
    }

    #[test]
    fn summary_counts_the_bounds_and_names_the_worst() {
        let sweep = CatalogueSweep {
            options: SweepOptions::default(),
            rows: vec![
                row("a", -0.3, 12.0),
                row("b", 0.2, 150.0),
                row("c", 0.25, 40.0),
            ],
            seconds: 30.0,
        };
        let s = sweep.summary().unwrap();
        assert_eq!((s.sensors, s.within, s.better, s.norm_within), (3, 2, 1, 2));
        assert_eq!(s.worst_delta, (0.25, "c".to_string()));
        assert_eq!(s.max_norm, (150.0, "b".to_string()));
        let md = sweep.markdown();
        assert!(md.contains("| c | `RG/GB` | 1.75 | 3.00 | 1.50 | +0.25 **miss** |"));
        assert!(md.contains("| 150.0 (3) **miss** |"), "{md}");
        assert!(md.contains("2 of 3 sensors within 0.2"), "{md}");
        assert!(md.contains("the largest 150.0 (b)"), "{md}");
        let empty = CatalogueSweep {
            rows: vec![],
            ..sweep
        };
        assert!(empty.summary().is_none());
    }

    #[test]
    fn options_are_the_noise_free_tungsten_table() {
        let p = SweepOptions::default().paper_options();
        assert!(!p.chart.noise);
        assert_eq!(p.acquisitions, vec![SWEEP_LIGHT.to_string()]);
        assert_eq!(
            (p.scenes, p.scene_size, p.seed, p.chart.seed),
            (48, 96, 7, 7)
        );
        let spec = table_spec(&p, TableKind::SameIlluminant, &[SWEEP_LIGHT]);
        assert!(!spec.noise);
    }
}
