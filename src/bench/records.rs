//! The result records of a benchmark run (`bench.json`).

use serde::{Deserialize, Serialize};

use super::skips::{EncoderResult, SkipResult};
use super::stats::median;
use super::sweep::{BenchOptions, L3Config};

/// What a result row measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConfigKind {
    L3,
    /// Bilinear demosaic + 3×3 colour matrix + T.
    Baseline,
    /// The strong conventional ISP ([`crate::baseline::Isp`]): Malvar or gradient-corrected
    /// demosaic, a denoiser driven by the sensor's noise model, a colour matrix (+ T).
    Isp,
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
    pub(super) fn from_samples(samples_ms: Vec<f64>, threads: usize, mpix: f64) -> Self {
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
    /// S-CIELAB of the whole chart render against its ideal image, at full exposure and at
    /// the low-light exposure.
    #[serde(default)]
    pub s_cielab_mean: Option<f64>,
    #[serde(default)]
    pub low_light_s_cielab_mean: Option<f64>,
    /// Sharpness, false colour and texture S-CIELAB at full exposure
    /// ([`crate::eval::SpatialScore`]) and at the low-light exposure.
    #[serde(default)]
    pub spatial: crate::eval::SpatialScore,
    #[serde(default)]
    pub low_light_spatial: crate::eval::SpatialScore,
}

/// One row of the benchmark.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConfigResult {
    pub name: String,
    pub kind: ConfigKind,
    /// The L3 configuration (None for the conventional pipelines and the copy).
    pub config: Option<L3Config>,
    /// Wall time to train every table of the configuration (fit the matrices
    /// for the conventional pipelines), seconds; None for the copy.
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
    /// The skips of docs/design.md §9 with and without, on the default table.
    #[serde(default)]
    pub skips: Vec<SkipResult>,
    /// Encodings of the rendered frame.
    #[serde(default)]
    pub encoders: Vec<EncoderResult>,
}

/// The non-dominated configurations under one illuminant, by run time against one metric.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParetoFront {
    pub illuminant: String,
    /// The metric ([`FrontMetric`]); absent in reports written before there were several:
    /// mean ΔE2000.
    #[serde(default)]
    pub metric: FrontMetric,
    pub names: Vec<String>,
}

/// What a Pareto front weighs run time against: a configuration that wins on ΔE by blurring
/// shows on the other two.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrontMetric {
    /// Mean patch-mean ΔE2000 (lower is better).
    #[default]
    DeltaE,
    /// S-CIELAB of the chart render (lower is better).
    SCielab,
    /// MTF50 of the slanted edge (higher is better).
    Mtf50,
}

impl FrontMetric {
    pub const ALL: [FrontMetric; 3] = [
        FrontMetric::DeltaE,
        FrontMetric::SCielab,
        FrontMetric::Mtf50,
    ];

    /// The metric of a colour result, as a value to minimise (MTF50 negated), when measured.
    pub fn cost(self, c: &ColourResult) -> Option<f64> {
        match self {
            FrontMetric::DeltaE => Some(c.mean),
            FrontMetric::SCielab => c.s_cielab_mean,
            FrontMetric::Mtf50 => c.spatial.mtf50.map(|m| -m),
        }
        .filter(|v| v.is_finite())
    }

    /// The metric as plotted (MTF50 as measured).
    pub fn value(self, c: &ColourResult) -> Option<f64> {
        self.cost(c)
            .map(|v| if self == FrontMetric::Mtf50 { -v } else { v })
    }

    /// The axis title.
    pub fn label(self) -> &'static str {
        match self {
            FrontMetric::DeltaE => "mean ΔE2000, Natural-100 chart",
            FrontMetric::SCielab => "S-CIELAB mean, Natural-100 chart",
            FrontMetric::Mtf50 => "MTF50 of the slanted edge, cycles/pixel (higher is sharper)",
        }
    }

    /// Its name in file names and tables: `delta_e`, `s_cielab`, `mtf50`.
    pub fn name(self) -> &'static str {
        match self {
            FrontMetric::DeltaE => "delta_e",
            FrontMetric::SCielab => "s_cielab",
            FrontMetric::Mtf50 => "mtf50",
        }
    }
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

/// The benchmark's sensor sweep: the default configuration on each sensor.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SensorSweep {
    /// Always [`super::BENCH_SCHEMA`].
    pub schema: String,
    pub reports: Vec<BenchReport>,
    pub total_seconds: f64,
}
