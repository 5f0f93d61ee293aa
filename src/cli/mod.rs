//! The `l3` command line: thin wrappers over the core.

mod bench;
mod colorchecker;
mod demosaic;
mod eval;
mod exit;
mod render;
mod scielab;
mod sensors;
mod serve;
mod sfr;
mod simulate;
mod train;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::camera::SensorDesign;
use crate::spectral::IsetData;

pub use exit::Fault;

/// L3 (Local, Linear, Learned) camera pipeline: simulate, train, render, evaluate.
#[derive(Parser, Debug)]
#[command(name = "l3", version, about)]
pub struct Cli {
    /// ISET spectral data folder, over the built-in spectral data (default:
    /// $L3_ISET_DIR or ../shared/data/iset when there).
    #[arg(long, global = true)]
    pub iset_dir: Option<PathBuf>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Simulate a scene through the camera: raw mosaic, ideal XYZ, sRGB preview.
    Simulate(simulate::SimulateArgs),
    /// Train an L3 table from simulated scenes.
    Train(train::TrainArgs),
    /// Render a raw mosaic with a table and an illuminant correction.
    Render(render::RenderArgs),
    /// ΔE2000 evaluation on the Natural-100 chart; `--paper-table` for Table 1;
    /// `--colorchecker` for a real ColorChecker capture.
    Eval(Box<eval::EvalArgs>),
    /// Demosaic a mosaic with the conventional pipelines' methods (bilinear, Malvar, the
    /// gradient-corrected RGBW demosaic, the ISP's denoiser) to float TIFF.
    Demosaic(demosaic::DemosaicArgs),
    /// Run time against colour error for a sweep of configurations (JSON, markdown, SVG plot).
    Bench(bench::BenchArgs),
    /// Sharpness: the ISO 12233 slanted-edge SFR of an edge in an image (JSON).
    Sfr(sfr::SfrArgs),
    /// The sensor catalogue: name, CFA, source, and the newest table trained for each in the
    /// data directory.
    Sensors(sensors::SensorsArgs),
    /// Run the HTTP render service (config/default.toml, --config FILE, L3_* variables).
    Serve(serve::ServeArgs),
}

/// Errors of the CLI: any layer's error, shown with its message. Its exit code (1, or 2 for
/// a bad argument or configuration) is [`CliError::exit_code`], by kind ([`Fault`]).
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// Bad arguments or configuration, found by the command itself.
    #[error("{0}")]
    Usage(String),
    /// An error about a value a flag gave (made at the flag, `CliError::argument`): a
    /// refused value is a usage error, whatever the layer that refused it.
    #[error(transparent)]
    Argument(Box<CliError>),
    /// No table to render with: none given, and none stored for the frame or active.
    #[error("{0}")]
    NoTable(String),
    /// A step of a sharded training run whose input, the files an earlier phase writes, is
    /// missing; `remedy` says which phase to run first.
    #[error("{path}: {source}; {remedy}")]
    EarlierPhase {
        path: String,
        remedy: String,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Pipeline(crate::pipeline::PipelineError),
    #[error(transparent)]
    Camera(#[from] crate::camera::CameraError),
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    #[error(transparent)]
    Spectral(#[from] crate::spectral::SpectralError),
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
    Io(#[from] crate::io::IoError),
    #[error(transparent)]
    Eval(#[from] crate::eval::EvalError),
    #[error(transparent)]
    Sfr(#[from] crate::eval::SfrError),
    #[error(transparent)]
    Learn(#[from] crate::l3::learn::LearnError),
    #[error(transparent)]
    Bench(#[from] crate::bench::BenchError),
    /// A report that cannot be written as JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The service could not start (its address, its database, its data directory) or
    /// stopped with an error: exit code 1, not a usage error.
    #[error("the service: {0}")]
    Service(#[from] crate::service::ServiceError),
    #[error("{path}: {source}")]
    File {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

impl CliError {
    /// `e`, about a value a flag gave: a value the core refused is then a usage error (exit
    /// code 2), while a file the flag named that cannot be read stays an error (1).
    pub(crate) fn argument(e: impl Into<CliError>) -> CliError {
        CliError::Argument(Box::new(e.into()))
    }
}

impl From<crate::pipeline::PipelineError> for CliError {
    /// The pipeline's error as the command line says it: the reference renderer asked for a
    /// region or preview names the flags, an untrained camera says how to get a table, a
    /// layer's error is shown as that layer's.
    fn from(e: crate::pipeline::PipelineError) -> Self {
        use crate::pipeline::PipelineError::*;
        match e {
            WholeFrameOnly => {
                CliError::Usage("--region and --preview need the fast renderer".into())
            }
            Decode(e) | Encode(e) => e.into(),
            Kernels(e) | Render(e) => e.into(),
            FrameLight(e) => e.into(),
            Correction(e) => e.into(),
            UntrainedCamera { ref sensors, .. } => CliError::NoTable(format!(
                "{e}; train one (`l3 train --sensor {} --out FILE`, or POST /v1/training-jobs {{\"sensor\":\"{}\"}} to a service on the data directory), or choose a table with --table FILE or --table-id ID",
                sensors.first().map_or("", String::as_str),
                sensors.first().map_or("", String::as_str),
            )),
            e @ (Options(_)
            | CfaMismatch { .. }
            | CfaShiftTooSmall { .. }
            | Levels { .. }
            | GivenLevels { .. }
            | SizeMismatch { .. }) => CliError::Pipeline(e),
        }
    }
}

/// The ISET data directory: `--iset-dir`, else a located one; `None` means
/// the built-in spectral data.
pub(crate) fn iset(dir: &Option<PathBuf>) -> Result<Option<IsetData>, CliError> {
    match dir {
        Some(d) => Ok(Some(IsetData::at(d)?)),
        None => match std::env::var_os(crate::spectral::ISET_DIR_ENV) {
            Some(d) => Ok(Some(IsetData::at(&d).map_err(|e| {
                CliError::Usage(format!("{}: {e}", crate::spectral::ISET_DIR_ENV))
            })?)),
            None => Ok(IsetData::locate()),
        },
    }
}

pub(crate) fn load_sensor(
    path: &Option<PathBuf>,
    iset: Option<&IsetData>,
) -> Result<SensorDesign, CliError> {
    match path {
        Some(p) => {
            let loaded = crate::camera::catalogue::load_named_or_file(p, iset)?;
            for note in &loaded.notes {
                eprintln!("warning: {}: {note}", p.display());
            }
            Ok(loaded.design)
        }
        None => Ok(SensorDesign::paper_default()),
    }
}

pub(crate) fn write_file(path: &std::path::Path, bytes: &[u8]) -> Result<(), CliError> {
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).map_err(|source| CliError::File {
            path: d.display().to_string(),
            source,
        })?;
    }
    std::fs::write(path, bytes).map_err(|source| CliError::File {
        path: path.display().to_string(),
        source,
    })
}

/// A command writing to a closed pipe (`l3 sensors | head -1`) ends quietly, as a Unix
/// filter does, rather than panicking in `println!`: SIGPIPE back to its default action.
/// `l3 serve` keeps Rust's default (ignored, so a closed socket is an error to handle).
fn default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called once at the start of `main`, before any thread is spawned; setting a
    // signal's disposition to SIG_DFL has no other precondition.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Run the CLI; an error is printed and turns into its exit code ([`CliError::exit_code`]: 1,
/// or 2 for bad arguments or configuration).
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    if !matches!(cli.command, Command::Serve(_)) {
        default_sigpipe();
    }
    let result = match &cli.command {
        Command::Simulate(a) => simulate::run(&cli, a),
        Command::Train(a) => train::run(&cli, a),
        Command::Render(a) => render::run(&cli, a),
        Command::Eval(a) => eval::run(&cli, a),
        Command::Bench(a) => bench::run(&cli, a),
        Command::Demosaic(a) => demosaic::run(&cli, a),
        Command::Sfr(a) => sfr::run(a),
        Command::Sensors(a) => sensors::run(&cli, a),
        Command::Serve(a) => serve::run(&cli, a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code())
        }
    }
}
