use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use super::{Cli, CliError, iset, load_sensor};
use crate::l3::TableKind;
use crate::training::{TrainingSpec, train_table};

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Sensor design TOML (default: the paper's RGBW sensor).
    #[arg(long)]
    pub sensor: Option<PathBuf>,
    /// `si` (same-illuminant) or `cross` (to D65).
    #[arg(long, default_value = "si")]
    pub kind: String,
    /// Comma-separated training illuminants (an ensemble when several).
    #[arg(long, default_value = "D65,Tungsten", value_delimiter = ',')]
    pub illuminants: Vec<String>,
    #[arg(long, default_value_t = 5)]
    pub patch: usize,
    #[arg(long, default_value_t = 20)]
    pub levels: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Training scenes (scene s lit by illuminant s mod n).
    #[arg(long, default_value_t = 48)]
    pub scenes: usize,
    /// Side of each training scene, pixels.
    #[arg(long, default_value_t = 96)]
    pub scene_size: usize,
    /// Train on noise-free patches with the analytic noise-variance ridge.
    #[arg(long)]
    pub noise_free: bool,
    /// One kernel per level regardless of contrast.
    #[arg(long)]
    pub no_contrast: bool,
    /// No saturation cases.
    #[arg(long)]
    pub no_saturation: bool,
    #[arg(long, default_value = "table.safetensors")]
    pub out: PathBuf,
}

pub fn parse_kind(s: &str) -> Result<TableKind, CliError> {
    match s.to_ascii_lowercase().as_str() {
        "si" | "same" | "same-illuminant" => Ok(TableKind::SameIlluminant),
        "cross" | "i" | "cross-illuminant" => Ok(TableKind::CrossIlluminant),
        _ => Err(CliError::Usage(format!(
            "--kind '{s}': expected si or cross"
        ))),
    }
}

pub fn run(cli: &Cli, a: &TrainArgs) -> Result<(), CliError> {
    let iset = iset(&cli.iset_dir)?;
    let design = load_sensor(&a.sensor, iset.as_ref())?;
    let spec = TrainingSpec {
        kind: parse_kind(&a.kind)?,
        illuminants: a.illuminants.iter().map(|s| s.trim().to_string()).collect(),
        patch_size: a.patch,
        levels: a.levels,
        seed: a.seed,
        scenes: a.scenes,
        scene_size: a.scene_size,
        noise: !a.noise_free,
        contrast_classes: !a.no_contrast,
        saturation_classes: !a.no_saturation,
        ..TrainingSpec::default()
    };
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {percent:>3}% {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let cancel = AtomicBool::new(false);
    let progress = |stage: &str, f: f64| {
        bar.set_position((f * 1000.0) as u64);
        bar.set_message(stage.to_string());
    };
    let table = train_table(&design, &spec, iset.as_ref(), &progress, &cancel)?;
    bar.finish_and_clear();
    table.save(&a.out)?;
    let reps = &table.reports;
    let filled = reps.iter().filter(|r| r.filled_from >= 0).count();
    let max_cond = reps.iter().map(|r| r.condition).fold(0.0, f64::max);
    let max_norm = reps.iter().map(|r| r.kernel_norm).fold(0.0, f64::max);
    println!(
        "trained {} table for {} on {} in {:.1} s: {} classes ({} positions × {} levels × {} saturation cases × 2), {} samples",
        table.meta.kind,
        design.name,
        table.meta.train_illuminants.join("+"),
        table.meta.training_seconds,
        table.n_classes(),
        table.n_positions(),
        table.n_levels(),
        table.n_sat_cases(),
        table.meta.summary["samples"]
    );
    println!(
        "saturation cases {:?}; {filled} classes filled from neighbouring levels; max condition {max_cond:.3e}; max kernel norm {max_norm:.3}",
        table.meta.sat_cases
    );
    println!(
        "wrote {} ({} bytes)",
        a.out.display(),
        std::fs::metadata(&a.out).map(|m| m.len()).unwrap_or(0)
    );
    Ok(())
}
