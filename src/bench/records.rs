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
    /// The skips of docs/design.md §9 with and without, on the default table.
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

/// The benchmark's sensor sweep: the default configuration on each sensor.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SensorSweep {
    /// Always [`super::BENCH_SCHEMA`].
    pub schema: String,
    pub reports: Vec<BenchReport>,
    pub total_seconds: f64,
}
