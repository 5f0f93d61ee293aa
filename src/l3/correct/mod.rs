//! Illuminant correction: what takes a same-illuminant table's output under the light a
//! frame was taken under to XYZ under D65 (docs/design.md §6).
//!
//! - the paper's T, fitted on surface reflectances independently of the camera, and the
//!   registry of named lights ([`IlluminantRegistry`], `correction.rs`);
//! - the camera-aware C, fitted on what the table and its sensor actually produce under
//!   the light ([`camera_correction`], [`camera_corrected`]), and the spectral samples and
//!   fitting primitives it shares with the trainer's colour maps ([`ColourSamples`],
//!   `fit.rs`);
//! - the light of a frame that names none, from its metadata or its own statistics
//!   (`illuminant_estimate.rs`);
//! - the kernels a same-illuminant table renders a light it was not trained under with
//!   (`transfer.rs`).
//!
//! Everything the render path needs to correct a table's output is here, so that the
//! render path never depends on the trainer.

mod camera_correction;
mod correction;
mod fit;
mod illuminant_estimate;
mod samples;
mod transfer;

pub use camera_correction::{LevelMap, camera_corrected, camera_correction, with_neutral};
pub use correction::{
    CorrectionSource, IDENTITY, IlluminantEntry, IlluminantRegistry, MAX_MATRIX_ENTRY, Mat3,
    correction_matrix, default_reflectances, xy_spec_cct,
};
pub use fit::{LevelNoise, NoiseModel, delta_e_weights, mean_loss_fit, noise_model};
pub use illuminant_estimate::{
    BRIGHT_FRACTION, CLIP_FRACTION, FrameMetadata, IlluminantEstimate, IlluminantSource, MIN_TILES,
    NeutralStatistic, frame_neutral,
};
pub use samples::{
    ColourSamples, ColourTarget, colour_samples, inverse_correction, same_illuminant_corrections,
};

#[cfg(test)]
pub(crate) use fit::{MEAN_LOSS_SMOOTHING, assert_mean_loss_trade};

/// Errors of an illuminant correction: a light, matrix or neutral that cannot be used, a
/// correction that cannot be fitted, and what the table or the camera it is fitted through
/// cannot give.
#[derive(Debug, thiserror::Error)]
pub enum CorrectError {
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// A frame's neutral (e.g. a DNG's AsShotNeutral) that matches no light.
    #[error("the frame's neutral: {0}")]
    Neutral(String),
    /// Colour samples, or a camera-aware correction, that the lights, the corrections or
    /// the camera given cannot make. (Worded as the training spec's errors: these checks
    /// were the trainer's before the render path shared them.)
    #[error("invalid training spec: {0}")]
    Samples(String),
    /// A camera-aware correction whose fit is singular or out of bounds.
    #[error("table is not usable: {0}")]
    Fit(String),
    #[error(transparent)]
    Table(#[from] crate::l3::table::TableError),
    #[error(transparent)]
    Camera(#[from] crate::camera::CameraError),
    #[error(transparent)]
    Spectral(#[from] crate::spectral::SpectralError),
}
