//! `l3 bench`: render throughput against colour error for a sweep of L3
//! configurations, the conventional pipelines (bilinear baselines and the strong ISP) and a
//! plain copy, measured in one run on the same frames (issue 5). Pure core: no HTTP, no SQL.

mod labels;
mod plot;
mod records;
mod render;
mod report;
mod run;
mod skips;
mod stats;
mod sweep;

pub use plot::{PlotError, pareto_front, svg_plot, svg_plot_metric};
pub use records::{
    BenchReport, ColourResult, ConfigKind, ConfigResult, FrameInfo, FrontMetric, ParetoFront,
    SensorSweep, Throughput,
};
pub use render::{
    BENCH_WHITE_Y, RENDERER, render_baseline_srgb8, render_baseline_xyz, render_isp_srgb8,
    render_srgb8, render_xyz,
};
pub use report::{BENCH_SCHEMA, markdown_table, sensor_sweep_markdown};
pub use run::{run_bench, run_sensor_sweep};
pub use skips::{EncoderResult, SkipInputs, SkipResult, run_skips};
pub use stats::median;
pub use sweep::{BaselineChoice, BenchOptions, L3Config, TableChoice, default_sweep};

/// Errors of a benchmark run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("invalid benchmark input: {0}")]
    Invalid(String),
    #[error(transparent)]
    Table(#[from] crate::l3::table::TableError),
    #[error(transparent)]
    Correct(#[from] crate::l3::correct::CorrectError),
    #[error(transparent)]
    Render(#[from] crate::l3::render::RenderError),
    #[error(transparent)]
    Baseline(#[from] crate::baseline::BaselineError),
    #[error(transparent)]
    Params(#[from] crate::l3::params::ParamsError),
    #[error(transparent)]
    Classify(#[from] crate::l3::classify::ClassifyError),
    #[error(transparent)]
    Eval(#[from] crate::eval::EvalError),
    #[error(transparent)]
    Learn(#[from] crate::l3::learn::LearnError),
    #[error(transparent)]
    Camera(#[from] crate::camera::CameraError),
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    #[error(transparent)]
    Spectral(#[from] crate::spectral::SpectralError),
    #[error("cannot draw the plot: {0}")]
    Plot(#[from] PlotError),
    #[error("cannot build a {threads}-thread pool: {msg}")]
    ThreadPool { threads: usize, msg: String },
}
