//! Evaluation: CIEDE2000 colour error of a rendered chart against the
//! chart's ideal XYZ under D65 (docs/design.md §7), as a stable JSON report.

mod budget;
mod captured_floor;
mod catalogue_sweep;
pub mod colorchecker;
mod colour_classes;
mod edge;
mod edge_panel;
mod figure;
mod illuminant_estimation;
mod noise_split;
pub(crate) mod paper_table;
mod report;
mod scielab;
mod sfr;
mod spatial;
mod texture;
mod workflow;

pub use budget::{ErrorBudget, error_budget};
pub use captured_floor::{CapturedFloor, captured_floor};
pub use catalogue_sweep::{
    CatalogueSweep, LINEAR_MARGIN, NORM_BOUND, SWEEP_LIGHT, SweepOptions, SweepRow, SweepSummary,
    catalogue_sweep, sweep_row,
};
pub use colorchecker::{
    COLORCHECKER_SCHEMA, ColorCheckerOptions, ColorCheckerReport, evaluate_colorchecker,
};
pub use colour_classes::{
    ColourClassRow, ColourClassStudy, colour_class_markdown, colour_class_study,
};
pub use edge::{
    BAND_PX, EdgeCapture, EdgeScore, FLAT_FAR_PX, FLAT_NEAR_PX, ROI_MARGIN, false_colour,
    simulate_edge,
};
pub use edge_panel::{CROP_SIDE, EdgeCrop, EdgeCurve, EdgePanel, acquisition_isp};
pub use figure::{colorchecker_svg, report_svg};
pub use illuminant_estimation::{
    EstimateResult, EstimationRow, STUDY_LIGHTS, estimation_markdown, illuminant_estimation_study,
};
pub use noise_split::{
    MAX_CAPTURES, MIN_CAPTURES, MethodOnChart, NoiseSplit, averaged_patch_means, noise_split,
};
pub use paper_table::{
    BaselineComparison, BaselineFamily, ExposurePoint, PAPER_TABLE1, PaperOptions, PaperRow,
    PaperTable, Spatial, StorageComparison, paper_summary, run_paper_table,
};
pub use report::{
    ChartTruth, DeltaEReport, ErrorStats, PatchResult, PixelStats, REPORT_SCHEMA, evaluate_chart,
    interior, patch_means, summarize, white_patch_index,
};
pub use scielab::{
    Border, ChannelFilter, DeltaEFormula, FilterSet, Scielab, ScielabOptions, ViewingCondition,
    XYZ_TO_OPP, channel_filters, scielab,
};
pub use sfr::{EdgeOrientation, Sfr, SfrError, slanted_edge_sfr};
pub use spatial::{SPATIAL_SIZE, SpatialCaptures, SpatialScore, simulate_spatial, spatial_score};
pub use texture::{MIN_TEXTURE_SIZE, TEXTURE_LAYOUT_SEED, TextureCapture, simulate_texture};
pub use workflow::{
    ChannelSet, ChartCapture, ChartSetup, ColourFit, EvalChart, LightLevel, Method,
    REFERENCE_LUMINANCE, capture_scene, chart_scene, evaluate_capture, evaluate_method,
    fit_baseline_matrix, fit_colour_matrix, frame_chart_capture, ideal_d65_patch_means,
    linear_table, matching_linear_map, method_correction, render_method, simulate_chart,
};

/// Errors of the evaluation layer.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("invalid evaluation input: {0}")]
    Invalid(String),
    /// A render with no signal where a measure needs one (the light side of the edge chart
    /// under a light with almost no blue, say): that measure is left out of a report.
    #[error("no signal to measure: {0}")]
    NoSignal(String),
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
    Spectral(#[from] crate::spectral::SpectralError),
    #[error(transparent)]
    Colour(#[from] crate::colour::ColourError),
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    #[error(transparent)]
    Learn(#[from] crate::l3::learn::LearnError),
    #[error(transparent)]
    Sfr(#[from] SfrError),
}
