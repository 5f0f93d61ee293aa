//! The errors of a render request, by what went wrong.

use std::fmt;

use crate::io::IoError;
use crate::l3::correct::CorrectError;
use crate::l3::render::RenderError;

/// Where an input's CFA comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CfaOrigin {
    /// The request declared it.
    Declared,
    /// A DNG's CFAPattern.
    Dng,
    /// A `.raw` (or image) file's JSON sidecar.
    Sidecar,
    /// The sensor design a caller gives (`l3 eval --sensor`).
    Sensor,
}

impl fmt::Display for CfaOrigin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CfaOrigin::Declared => "the declared",
            CfaOrigin::Dng => "the DNG's",
            CfaOrigin::Sidecar => "the sidecar's",
            CfaOrigin::Sensor => "the sensor's",
        })
    }
}

/// Errors of the pipeline, by kind: options that do not fit, an input that does not decode
/// or does not fit the table, a light that cannot be taken from the frame, kernels that cannot
/// be prepared, a failed (or canceled) render, a failed encoding.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// A region, preview or correction that is malformed or does not fit the frame.
    #[error("{0}")]
    Options(String),
    /// A region or preview asked of the reference renderer, which renders whole frames.
    #[error("a region or a preview needs the fast renderer")]
    WholeFrameOnly,
    /// The input's CFA is not the table's.
    #[error("{origin} CFA '{input}' does not match the table's CFA '{table}'")]
    CfaMismatch {
        origin: CfaOrigin,
        input: String,
        table: String,
    },
    /// A DNG whose CFA is the table's seen from another pixel, in a frame too small to leave
    /// out the rows or columns that would move it onto the table's.
    #[error(
        "the DNG's CFA '{input}' is the table's '{table}' seen from another pixel, but its {}×{} frame is too small to leave out its first {left_out}",
        size.0, size.1
    )]
    CfaShiftTooSmall {
        input: String,
        table: String,
        size: (usize, usize),
        left_out: String,
    },
    /// Black and white levels that leave no range, the file's or the file's with the
    /// request's.
    #[error("white level {white} must exceed black level {black}")]
    Levels { black: u16, white: u16 },
    /// Black and white levels the request gives (or the request's with the defaults, 0 and
    /// 65535) that leave no range, whatever the file holds.
    #[error("white level {white} must exceed black level {black}")]
    GivenLevels { black: u16, white: u16 },
    /// A decoded image whose size is not the declared one.
    #[error("the image is {}×{} but {}×{} was declared", image.0, image.1, show(declared.0), show(declared.1))]
    SizeMismatch {
        image: (usize, usize),
        declared: (Option<usize>, Option<usize>),
    },
    /// The input does not decode (or its samples do not convert to volts).
    #[error(transparent)]
    Decode(IoError),
    /// The frame's metadata or pixels give no light.
    #[error("the light cannot be taken from the frame: {0}")]
    FrameLight(#[source] CorrectError),
    /// The camera-aware correction could not be fitted for the table's sensor.
    #[error("camera-aware correction: {0}")]
    Correction(#[from] CorrectError),
    /// The table's kernels cannot be prepared under the light.
    #[error("{0}")]
    Kernels(#[source] RenderError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Encode(IoError),
    /// The file's camera is a catalogue sensor for which no good table is stored.
    #[error("the file's camera ({camera}) is the catalogue sensor {}, and no table trained for it is stored", sensors.join(" or "))]
    UntrainedCamera {
        /// The catalogue's maker and model.
        camera: String,
        /// Its catalogue sensors, best first.
        sensors: Vec<String>,
    },
}

/// A declared dimension, `?` when not declared.
pub(crate) fn show(v: Option<usize>) -> String {
    v.map_or("?".into(), |v| v.to_string())
}
