//! The L3 method: classify each sensor pixel by CFA position, response
//! level, saturation case and local contrast, and apply the class's learned
//! affine kernel to its patch (DESIGN.md §2, §5).

mod baseline;
mod camera_correction;
mod chroma;
mod classify;
mod colour_map;
mod correction;
mod fast;
mod illuminant_estimate;
mod normal_eq;
mod output;
mod params;
mod partial_format;
mod render;
mod shards;
mod table;
mod trainer;
mod transfer;

pub use baseline::{ColourMatrix, bilinear_demosaic, render_baseline};
pub use camera_correction::{LevelMap, camera_correction};
pub use chroma::{ChromaClasses, MAX_CHROMA_CLASSES, MIN_SURFACES_PER_CHANNEL, chromaticity};
pub use classify::{MAX_CHANNELS, PatchGeometry, PatchStats, mirror, sat_case_index};
pub use colour_map::{
    CROSS_AVERAGING_PX, ColourLoss, ColourMapFit, ColourSamples, LevelNoise,
    UNDER_LIGHT_AVERAGING_PX, band_maps, least_squares_map, level_maps,
};
pub use correction::{
    CorrectionSource, IDENTITY, IlluminantEntry, IlluminantRegistry, MAX_MATRIX_ENTRY, Mat3,
    correction_matrix, default_reflectances, xy_spec_cct,
};
pub use fast::{FastOptions, FastRenderer, Frame, Mosaic, Region};
pub use illuminant_estimate::{
    BRIGHT_FRACTION, CLIP_FRACTION, FrameMetadata, IlluminantEstimate, IlluminantSource, MIN_TILES,
    NeutralStatistic, frame_neutral,
};
pub use normal_eq::{ChannelSumConstraint, ClassSolution, Gram, RidgeChoice, solve, solve_with};
pub use output::{
    WHITE_GRID, WhiteLevel, white_from_samples, white_sample_points, white_y, xyz_to_srgb8,
    xyz_to_srgb16,
};
pub use params::{DEFAULT_LEVELS_1V8, L3Params};
pub use partial_format::PARTIAL_FORMAT_VERSION;
pub use render::{
    RenderStats, fuse_entry, fuse_kernels, render_reference, render_reference_under,
    resolve_sat_case,
};
pub use shards::{
    ClassSums, Classes, GramPartial, Node, ShardSpec, SurveyPartial, SurveyShape, cover,
    merge_partials, merge_surveys, plan_shards,
};
pub use table::{ClassReport, L3Table, TABLE_FORMAT_VERSION, TableKind, TableMeta};
pub use trainer::{
    Learned, NoiseModel, TrainControl, TrainSetup, TrainingFrame, accumulate_batches,
    classes_from_survey, learn, package, solve_learned, survey_batches,
};

/// Errors of the L3 core.
#[derive(Debug, thiserror::Error)]
pub enum L3Error {
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    #[error("invalid input: {0}")]
    InvalidInput(String),
    #[error("table file {path}: {msg}")]
    BadTable { path: String, msg: String },
    #[error("table is not usable: {0}")]
    Table(String),
    #[error("cannot save the table: {0}")]
    Write(#[source] Box<crate::io::IoError>),
    #[error("training was canceled")]
    Canceled,
    /// Partial sums of a sharded training run that cannot be read or merged.
    #[error("partial sums: {0}")]
    PartialSums(String),
    #[error("the render was canceled")]
    RenderCanceled,
    /// A kernel set whose length is not the table's (the caller's fault, never the input's).
    #[error("a kernel set of {got} weights does not match the table's {expected}")]
    KernelMismatch { got: usize, expected: usize },
    /// An output buffer of the wrong size (the caller's fault, never the input's).
    #[error("the output buffer holds {got} bytes; the {width}×{height} region needs {need}")]
    OutputBuffer {
        got: usize,
        need: usize,
        width: usize,
        height: usize,
    },
    /// The table carries no sensor description, so no neutral can be matched through it.
    #[error("the table has no sensor description to match the frame's neutral with")]
    NoSensor,
    /// A frame's neutral (e.g. a DNG's AsShotNeutral) that matches no light.
    #[error("the frame's neutral: {0}")]
    Neutral(String),
    #[error(transparent)]
    Spectral(#[from] crate::spectral::SpectralError),
}
#[cfg(test)]
mod tests;
