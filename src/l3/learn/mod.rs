//! Training an L3 table from the camera simulation (docs/design.md §5).
//!
//! A [`TrainingRun`] (`run.rs`) is prepared from a [`TrainingSpec`] (`spec.rs`): the camera,
//! the training scenes (`scenes.rs`) and lights, the L3 parameters and the per-level colour
//! maps that fix every kernel's colour (`colour_map.rs`, fitted on the spectral samples of
//! [`crate::l3::correct`]; a same-illuminant table's maps for foreign lights are chosen on
//! held-out lights, `transfer_fit.rs`). It trains in one call or in shards (batch ranges)
//! whose partial sums (`shards.rs`, their bytes in `partial_format.rs`) can be computed on
//! other machines and merged into the same table bytes.
//!
//! The learner itself works on frames: it surveys the frames' classes, accumulates every
//! class's normal equations (`trainer.rs`, `normal_eq.rs`), then fills and solves every
//! class (`solve.rs`).

mod colour_map;
mod normal_eq;
mod partial_format;
mod run;
mod scenes;
mod setup;
mod shards;
mod solve;
mod spec;
mod trainer;
mod transfer_fit;

pub use colour_map::{band_maps, least_squares_map, level_maps};
pub use normal_eq::{ChannelSumConstraint, ClassSolution, Gram, solve, solve_with};
pub use partial_format::PARTIAL_FORMAT_VERSION;
pub use run::{TrainingRun, train_table};
pub use scenes::{TrainingScenes, mix};
pub use setup::{ClassMaps, Learned, TrainControl, TrainSetup, TrainingFrame};
pub use shards::{
    ClassSums, Classes, GramPartial, Node, ShardSpec, SurveyPartial, SurveyShape, cover,
    merge_partials, merge_surveys, plan_shards,
};
pub use solve::{package, solve_learned};
pub use spec::{
    DEFAULT_CHROMA_CLASSES, DEFAULT_TEXTURE_AVERAGING_PX, TrainingSpec, new_spec_defaults,
};
pub use trainer::{accumulate_batches, classes_from_survey, learn, survey_batches};
pub use transfer_fit::{
    HELD_OUT_LIGHTS, HeldOutLight, TransferCandidate, TransferChoice, TransferFit,
    choose_transfer_fit, held_out_error, held_out_lights,
};

use crate::baseline::BaselineError;
use crate::camera::CameraError;
use crate::l3::classify::ClassifyError;
use crate::l3::correct::CorrectError;
use crate::l3::params::ParamsError;
use crate::l3::table::TableError;
use crate::scene::SceneError;
use crate::spectral::SpectralError;

/// Errors of training: a spec or parameters that cannot be trained, partial sums that
/// cannot be merged, a class that cannot be solved, a run canceled, and the errors of what
/// a run is made from (the camera, the scenes, the colour samples, the table it packages).
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    #[error("invalid training spec: {0}")]
    Invalid(String),
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    #[error("invalid input: {0}")]
    InvalidInput(String),
    #[error("training was canceled")]
    Canceled,
    /// Partial sums of a sharded training run that cannot be read or merged.
    #[error("partial sums: {0}")]
    PartialSums(String),
    /// A class, or a colour map, whose equations cannot be solved.
    #[error("table is not usable: {0}")]
    Solve(String),
    #[error(transparent)]
    Table(#[from] TableError),
    #[error(transparent)]
    Params(#[from] ParamsError),
    #[error(transparent)]
    Classify(#[from] ClassifyError),
    #[error(transparent)]
    Correct(#[from] CorrectError),
    #[error(transparent)]
    Baseline(#[from] BaselineError),
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Spectral(#[from] SpectralError),
}
