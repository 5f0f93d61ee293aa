//! The exit code of a failed command, from the kind of its error: the one place the CLI's
//! errors (and the core's typed errors inside them) are mapped to codes.
//!
//! docs/cli.md: 0 success; 1 an error (a file, a table, the service could not start); 2 bad
//! arguments or configuration. Each core error variant has a [`Fault`]:
//!
//! - [`Fault::Usage`]: bad whoever gave it: an unknown name (illuminant, scene, sensor), a
//!   malformed spec, a parameter out of range, an invalid sensor design, a missing ISET data
//!   folder. Exit code 2.
//! - [`Fault::Invalid`]: a value the core refused (a light it cannot correct, a frame it
//!   cannot render, corners that miss the chart). Exit code 2 when a flag gave the value (the
//!   command wraps such errors in [`CliError::Argument`] where it hands the flag's value over),
//!   else 1: the value came from a file.
//! - [`Fault::Failure`]: a file that cannot be read or written, a table, a fit that does not
//!   solve, a canceled run, the service. Exit code 1, even when a flag named the file.

use super::CliError;
use crate::baseline::BaselineError;
use crate::bench::BenchError;
use crate::camera::CameraError;
use crate::colour::ColourError;
use crate::eval::{EvalError, SfrError};
use crate::io::IoError;
use crate::l3::classify::ClassifyError;
use crate::l3::correct::CorrectError;
use crate::l3::learn::LearnError;
use crate::l3::params::ParamsError;
use crate::l3::render::RenderError;
use crate::l3::table::TableError;
use crate::pipeline::PipelineError;
use crate::scene::SceneError;
use crate::spectral::SpectralError;

/// What kind of mistake or failure an error reports (see the module's documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// A bad argument or configuration, whoever gave it.
    Usage,
    /// A value refused: the argument's fault when a flag gave it, else the file's.
    Invalid,
    /// A file, a table, a fit, the service.
    Failure,
}

impl CliError {
    /// The kind of this error.
    pub fn fault(&self) -> Fault {
        use CliError::*;
        match self {
            Usage(_) => Fault::Usage,
            Argument(e) => match e.fault() {
                Fault::Failure => Fault::Failure,
                Fault::Usage | Fault::Invalid => Fault::Usage,
            },
            NoTable(_) | EarlierPhase { .. } | File { .. } | Json(_) | Service(_) => Fault::Failure,
            Pipeline(e) => e.fault(),
            Camera(e) => e.fault(),
            Scene(e) => e.fault(),
            Spectral(e) => e.fault(),
            Table(e) => e.fault(),
            Correct(e) => e.fault(),
            Render(e) => e.fault(),
            Baseline(e) => e.fault(),
            Params(e) => e.fault(),
            Classify(e) => e.fault(),
            Io(e) => e.fault(),
            Eval(e) => e.fault(),
            Sfr(e) => e.fault(),
            Learn(e) => e.fault(),
            Bench(e) => e.fault(),
        }
    }

    /// The process's exit code for this error: 2 for a bad argument or configuration, else 1.
    pub fn exit_code(&self) -> u8 {
        match self.fault() {
            Fault::Usage => 2,
            Fault::Invalid | Fault::Failure => 1,
        }
    }
}

/// The [`Fault`] of a core error, variant by variant (the matches are exhaustive, so a new
/// variant must be classified here).
trait FaultOf {
    fn fault(&self) -> Fault;
}

impl FaultOf for SpectralError {
    fn fault(&self) -> Fault {
        use SpectralError::*;
        match self {
            UnknownIlluminant(..)
            | InvalidIlluminantSpec(..)
            | IsetDataMissing(_)
            | NoSuchTable { .. }
            | Csv { .. }
            | NoSuchColumn { .. }
            | InvalidSamples(_) => Fault::Usage,
            Io { .. } | InvalidGrid(_) | LengthMismatch { .. } | GridMismatch(..) => Fault::Failure,
        }
    }
}

impl FaultOf for ColourError {
    fn fault(&self) -> Fault {
        use ColourError::*;
        match self {
            Spectral(e) => e.fault(),
            ZeroLuminance(_) | CctOutOfRange { .. } | TemperatureOutOfRange(..) => Fault::Invalid,
            NonFinite(_) => Fault::Failure,
        }
    }
}

impl FaultOf for CameraError {
    fn fault(&self) -> Fault {
        use CameraError::*;
        match self {
            Spectral(e) => e.fault(),
            InvalidDesign(_) | InvalidCfa(_) | Toml { .. } | Json(_) | InvalidArgument(_) => {
                Fault::Usage
            }
            Io { .. } | GridMismatch { .. } => Fault::Failure,
        }
    }
}

impl FaultOf for SceneError {
    fn fault(&self) -> Fault {
        match self {
            SceneError::Spectral(e) => e.fault(),
            SceneError::Invalid(_) => Fault::Usage,
            SceneError::Image { .. } => Fault::Failure,
        }
    }
}

impl FaultOf for TableError {
    /// A table that cannot be read, used or written: the table's failure.
    fn fault(&self) -> Fault {
        use TableError::*;
        match self {
            BadFile { .. } | Unusable(_) | Write(_) | NoSensor | Classify(_) => Fault::Failure,
        }
    }
}

impl FaultOf for CorrectError {
    fn fault(&self) -> Fault {
        use CorrectError::*;
        match self {
            InvalidInput(_) | Neutral(_) => Fault::Invalid,
            InvalidParams(_) | Samples(_) | Fit(_) => Fault::Failure,
            Table(e) => e.fault(),
            Camera(e) => e.fault(),
            Spectral(e) => e.fault(),
        }
    }
}

impl FaultOf for RenderError {
    fn fault(&self) -> Fault {
        use RenderError::*;
        match self {
            InvalidInput(_) => Fault::Invalid,
            Prepare(e) => e.fault(),
            Table(_) | RenderCanceled | KernelMismatch { .. } | OutputBuffer { .. } => {
                Fault::Failure
            }
        }
    }
}

impl FaultOf for BaselineError {
    fn fault(&self) -> Fault {
        match self {
            BaselineError::InvalidParams(_) => Fault::Usage,
            BaselineError::InvalidInput(_) => Fault::Invalid,
            BaselineError::Singular(_) => Fault::Failure,
        }
    }
}

impl FaultOf for ParamsError {
    fn fault(&self) -> Fault {
        match self {
            ParamsError::Invalid(_) => Fault::Usage,
            ParamsError::Classify(e) => e.fault(),
        }
    }
}

impl FaultOf for ClassifyError {
    fn fault(&self) -> Fault {
        match self {
            ClassifyError::InvalidParams(_) => Fault::Usage,
            ClassifyError::InvalidInput(_) => Fault::Invalid,
        }
    }
}

impl FaultOf for IoError {
    /// A file that cannot be opened, read or written, or an encoder's failure: a failure; a
    /// file whose contents are not a frame: invalid.
    fn fault(&self) -> Fault {
        if self.is_input() {
            Fault::Invalid
        } else {
            Fault::Failure
        }
    }
}

impl FaultOf for EvalError {
    /// `Invalid` covers the evaluation's own failures as well as values a flag gave: the
    /// command marks the latter where it parses them ([`CliError::Argument`]).
    fn fault(&self) -> Fault {
        use EvalError::*;
        match self {
            Invalid(_) | NoSignal(_) => Fault::Invalid,
            Table(e) => e.fault(),
            Correct(e) => e.fault(),
            Render(e) => e.fault(),
            Baseline(e) => e.fault(),
            Params(e) => e.fault(),
            Classify(e) => e.fault(),
            Spectral(e) => e.fault(),
            Colour(e) => e.fault(),
            Scene(e) => e.fault(),
            Learn(e) => e.fault(),
            Sfr(e) => e.fault(),
        }
    }
}

impl FaultOf for SfrError {
    /// An image that holds no measurable edge.
    fn fault(&self) -> Fault {
        match self {
            SfrError::TooSmall { .. } | SfrError::NotFinite | SfrError::NoEdge(_) => Fault::Invalid,
        }
    }
}

impl FaultOf for LearnError {
    fn fault(&self) -> Fault {
        use LearnError::*;
        match self {
            Invalid(_) | InvalidParams(_) => Fault::Usage,
            InvalidInput(_) => Fault::Invalid,
            Canceled | PartialSums(_) | Solve(_) => Fault::Failure,
            Table(e) => e.fault(),
            Params(e) => e.fault(),
            Classify(e) => e.fault(),
            Correct(e) => e.fault(),
            Baseline(e) => e.fault(),
            Camera(e) => e.fault(),
            Scene(e) => e.fault(),
            Spectral(e) => e.fault(),
        }
    }
}

impl FaultOf for BenchError {
    fn fault(&self) -> Fault {
        use BenchError::*;
        match self {
            Invalid(_) => Fault::Usage,
            Plot(_) | ThreadPool { .. } => Fault::Failure,
            Table(e) => e.fault(),
            Correct(e) => e.fault(),
            Render(e) => e.fault(),
            Baseline(e) => e.fault(),
            Params(e) => e.fault(),
            Classify(e) => e.fault(),
            Eval(e) => e.fault(),
            Learn(e) => e.fault(),
            Camera(e) => e.fault(),
            Scene(e) => e.fault(),
            Spectral(e) => e.fault(),
        }
    }
}

impl FaultOf for PipelineError {
    /// Options that do not fit (a region, a preview, the reference renderer asked for a
    /// crop) and a frame whose CFA is not the table's are usage errors; a frame's levels or
    /// size that do not hold, or a light it does not give, are the file's.
    fn fault(&self) -> Fault {
        use PipelineError::*;
        match self {
            Options(_) | WholeFrameOnly | CfaMismatch { .. } | GivenLevels { .. } => Fault::Usage,
            Levels { .. } | SizeMismatch { .. } | CfaShiftTooSmall { .. } | FrameLight(_) => {
                Fault::Invalid
            }
            UntrainedCamera { .. } => Fault::Failure,
            Decode(e) | Encode(e) => e.fault(),
            Correction(e) => e.fault(),
            Kernels(e) | Render(e) => e.fault(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bad names, specs, parameters and designs exit 2 whoever gave them; files, tables and
    /// the service exit 1.
    #[test]
    fn kinds_map_to_their_codes() {
        let usage = [
            CliError::from(SpectralError::UnknownIlluminant("x".into(), "D65".into())),
            SpectralError::IsetDataMissing("/x".into()).into(),
            CameraError::InvalidDesign("'x': fill_factor".into()).into(),
            CameraError::InvalidCfa("'RG/G'".into()).into(),
            SceneError::Invalid("unknown scene 'foo'".into()).into(),
            LearnError::Invalid("levels 0".into()).into(),
            EvalError::Learn(LearnError::Invalid("scenes 0".into())).into(),
            PipelineError::Options("region".into()).into(),
            PipelineError::GivenLevels { black: 0, white: 0 }.into(),
        ];
        for e in usage {
            assert_eq!(e.fault(), Fault::Usage, "{e}");
            assert_eq!(e.exit_code(), 2);
        }
        let failure = [
            CliError::from(TableError::BadFile {
                path: "t".into(),
                msg: "no such file".into(),
            }),
            CliError::NoTable("no table".into()),
            IoError::Png("truncated".into()).into(),
            EvalError::Invalid("the chart has no patches".into()).into(),
            RenderError::InvalidInput("white level 'abc'".into()).into(),
            CliError::from(PipelineError::Levels {
                black: 10,
                white: 5,
            }),
        ];
        for e in failure {
            assert_ne!(e.fault(), Fault::Usage, "{e}");
            assert_eq!(e.exit_code(), 1);
        }
    }

    /// A value refused when a flag gave it is a usage error; a file a flag named that cannot
    /// be read stays a failure.
    #[test]
    fn an_argument_makes_a_refused_value_a_usage_error_but_not_a_missing_file() {
        let refused = CliError::argument(RenderError::InvalidInput("white level 'abc'".into()));
        assert_eq!(refused.fault(), Fault::Usage);
        assert_eq!(refused.to_string(), "invalid input: white level 'abc'");
        let missing = CliError::argument(SpectralError::Io {
            path: "light.csv".into(),
            source: std::io::Error::from(std::io::ErrorKind::NotFound),
        });
        assert_eq!(missing.fault(), Fault::Failure);
        assert_eq!(missing.exit_code(), 1);
    }
}
