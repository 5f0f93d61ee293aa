use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use super::{Cli, CliError, iset, load_sensor, write_file};
use crate::l3::L3Table;
use crate::l3::learn::{Classes, GramPartial, ShardSpec, SurveyPartial, TrainingRun, TrainingSpec};
use crate::l3::params::ColourLoss;
use crate::l3::table::TableKind;

/// `--colour-loss`: [`ColourLoss`] by a short name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ColourLossArg {
    /// Every light's mean ΔE00.
    Mean,
    /// The sum of squared ΔE00.
    Squared,
}

/// A step of a sharded training run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Phase {
    Survey,
    Accumulate,
    Merge,
}

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Sensor: a design TOML or a catalogue name (`l3 sensors`; default: the paper's RGBW sensor).
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
    /// Pixels per channel whose mean the colour maps are fitted for under
    /// the sensor's noise (0: the noise-free map). Default: 48 for the maps a
    /// table renders with, 128 for a same-illuminant table's maps for lights
    /// it was not trained under; given, both.
    #[arg(long)]
    pub colour_averaging_px: Option<f64>,
    /// What each level's colour map minimises: every light's mean ΔE00 or
    /// the sum of squared ΔE00. Default by illuminants: mean for one light,
    /// squared for an ensemble.
    #[arg(long, value_enum)]
    pub colour_loss: Option<ColourLossArg>,
    /// Split every level into this many chroma classes, each with its own
    /// colour maps and kernels (k-means on the training surfaces' white-balanced
    /// channel chromaticities; 1: no split). Classes with too few surfaces are dropped.
    /// A same-illuminant table also keeps each level's map over every class, which its
    /// kernels take under a light it was not trained on through T.
    #[arg(long, default_value_t = crate::l3::learn::DEFAULT_CHROMA_CLASSES)]
    pub chroma_classes: usize,
    /// Pixels per channel whose mean the texture classes' colour maps are fitted for (fewer
    /// than the flat classes' 48: smaller weights, less false colour at edges); 0: the
    /// texture classes share the flat classes' maps.
    #[arg(long, default_value_t = crate::l3::learn::DEFAULT_TEXTURE_AVERAGING_PX)]
    pub texture_colour_averaging_px: f64,
    #[arg(long, default_value = "table.safetensors")]
    pub out: PathBuf,
    /// Train in this many shards (batch ranges), one after the other, each
    /// shard's partial sums written to --shard-dir and read back for the
    /// merge: the table is the one a single run gives.
    #[arg(long, default_value_t = 1)]
    pub shards: usize,
    /// Folder of the shards' partial sums (default: the output path with
    /// `.shards` appended).
    #[arg(long)]
    pub shard_dir: Option<PathBuf>,
    /// Run one step of a sharded run and stop (as separate machines would,
    /// sharing --shard-dir): `survey` or `accumulate` for --shard K, then
    /// `merge` once every shard's file is there. Without it every step runs.
    #[arg(long, requires = "shards")]
    pub phase: Option<Phase>,
    /// The shard (1 to --shards) of --phase survey or accumulate.
    #[arg(long)]
    pub shard: Option<usize>,
    /// Zero the creation time and training duration in the table, so that
    /// equal training gives equal file bytes.
    #[arg(long)]
    pub reproducible: bool,
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
    let spec = training_spec(a)?;
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
    let run = TrainingRun::new(&design, &spec, iset.as_ref())?;
    let mut table = if a.shards > 1 || a.shard_dir.is_some() || a.phase.is_some() {
        bar.finish_and_clear();
        match run_sharded(a, &run, &cancel)? {
            Some(table) => table,
            // one step of a sharded run: its partial is written
            None => return Ok(()),
        }
    } else {
        run.train(&progress, &cancel)?
    };
    bar.finish_and_clear();
    let seconds = table.meta.training_seconds;
    if a.reproducible {
        table.meta.created_unix_s = 0;
        table.meta.training_seconds = 0.0;
    }
    table.save(&a.out)?;
    print_summary(&table, &design.name, seconds, a);
    Ok(())
}

/// The training spec the arguments describe.
fn training_spec(a: &TrainArgs) -> Result<TrainingSpec, CliError> {
    Ok(TrainingSpec {
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
        colour_averaging_px: a.colour_averaging_px,
        colour_loss: a.colour_loss.map(|l| match l {
            ColourLossArg::Mean => ColourLoss::MeanDeltaE,
            ColourLossArg::Squared => ColourLoss::SquaredDeltaE,
        }),
        chroma_classes: a.chroma_classes,
        texture_colour_averaging_px: Some(a.texture_colour_averaging_px).filter(|&px| px != 0.0),
        ..TrainingSpec::default()
    })
}

/// A sharded run: every step (the table), or the one step `--phase` names (`None` once its
/// partial is written, or the table after the merge).
fn run_sharded(
    a: &TrainArgs,
    run: &TrainingRun,
    cancel: &AtomicBool,
) -> Result<Option<L3Table>, CliError> {
    let dir = a.shard_dir.clone().unwrap_or_else(|| {
        let mut p = a.out.clone().into_os_string();
        p.push(".shards");
        PathBuf::from(p)
    });
    let step = |shard: Option<usize>| -> Result<usize, CliError> {
        match shard {
            Some(k) if (1..=a.shards).contains(&k) => Ok(k - 1),
            _ => Err(CliError::Usage(format!(
                "--phase survey or accumulate needs --shard 1 to {}",
                a.shards
            ))),
        }
    };
    let sharded = Sharded {
        run,
        plan: run.plan(a.shards)?,
        dir,
        cancel,
    };
    Ok(match a.phase {
        None => Some(sharded.all()?),
        Some(Phase::Survey) => {
            sharded.survey(step(a.shard)?)?;
            None
        }
        Some(Phase::Accumulate) => {
            let classes = sharded.classes()?;
            sharded.accumulate(step(a.shard)?, &classes)?;
            None
        }
        Some(Phase::Merge) => Some(sharded.merge(sharded.classes()?)?),
    })
}

/// What was trained, and where it was written.
fn print_summary(table: &L3Table, sensor: &str, seconds: f64, a: &TrainArgs) {
    let reps = &table.reports;
    let filled = reps.iter().filter(|r| r.filled_from >= 0).count();
    let max_cond = reps.iter().map(|r| r.condition).fold(0.0, f64::max);
    let max_norm = reps.iter().map(|r| r.kernel_norm).fold(0.0, f64::max);
    println!(
        "trained {} table for {} on {} in {:.1} s: {} classes ({} positions × {} levels × {} chroma classes × {} saturation cases × 2), {} samples",
        table.meta.kind,
        sensor,
        table.meta.train_illuminants.join("+"),
        seconds,
        table.n_classes(),
        table.n_positions(),
        table.n_levels(),
        table.n_chroma(),
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
}

/// The steps of a sharded run, each partial written to `dir` and read back
/// from there, as separate machines would; each prints its time.
struct Sharded<'a> {
    run: &'a TrainingRun,
    plan: Vec<ShardSpec>,
    dir: PathBuf,
    cancel: &'a AtomicBool,
}

fn quiet(_: &str, _: f64) {}

impl Sharded<'_> {
    fn path(&self, stage: &str, k: usize) -> PathBuf {
        self.dir
            .join(format!("{stage}-{}-of-{}.l3p", k + 1, self.plan.len()))
    }

    /// The partial of `stage` (`survey` or `sums`) for shard `k` (0-based), as the phase that
    /// writes it left it; when it is not there, an error naming that phase.
    fn read_partial(&self, stage: &str, k: usize) -> Result<Vec<u8>, CliError> {
        let path = self.path(stage, k);
        std::fs::read(&path).map_err(|source| {
            let path = path.display().to_string();
            if source.kind() != std::io::ErrorKind::NotFound {
                return CliError::File { path, source };
            }
            let (phase, what) = match stage {
                "survey" => ("survey", "surveys"),
                _ => ("accumulate", "partial sums"),
            };
            CliError::EarlierPhase {
                path,
                remedy: format!(
                    "the shards' {what} are written by `--phase {phase}`: run `l3 train --phase \
                     {phase} --shard K` for every K from 1 to {} first (with the same --shards, \
                     --shard-dir and training flags)",
                    self.plan.len()
                ),
                source,
            }
        })
    }

    fn shard(&self, k: usize) -> Result<&ShardSpec, CliError> {
        self.plan
            .get(k)
            .ok_or_else(|| CliError::Usage(format!("no shard {}", k + 1)))
    }

    /// Survey shard `k` (0-based).
    fn survey(&self, k: usize) -> Result<(), CliError> {
        let t = Instant::now();
        let shard = self.shard(k)?;
        let bytes = self
            .run
            .survey_shard(shard, &quiet, self.cancel)?
            .to_bytes()?;
        write_file(&self.path("survey", k), &bytes)?;
        println!(
            "survey shard {}/{} (batches {}..{}): {:.2} s, {} bytes",
            k + 1,
            self.plan.len(),
            shard.start,
            shard.end,
            t.elapsed().as_secs_f64(),
            bytes.len()
        );
        Ok(())
    }

    /// The run's classes from every survey shard's file.
    fn classes(&self) -> Result<Classes, CliError> {
        let t = Instant::now();
        let surveys = (0..self.plan.len())
            .map(|k| Ok(SurveyPartial::from_bytes(&self.read_partial("survey", k)?)?))
            .collect::<Result<Vec<_>, CliError>>()?;
        let classes = self.run.classes(&surveys)?;
        println!("survey merge: {:.3} s", t.elapsed().as_secs_f64());
        Ok(classes)
    }

    /// Accumulation shard `k` (0-based).
    fn accumulate(&self, k: usize, classes: &Classes) -> Result<(), CliError> {
        let t = Instant::now();
        let shard = self.shard(k)?;
        let part = self
            .run
            .accumulate_shard(shard, classes, &quiet, self.cancel)?;
        let bytes = part.to_bytes()?;
        write_file(&self.path("sums", k), &bytes)?;
        println!(
            "accumulation shard {}/{} (batches {}..{}): {:.2} s, {} bytes",
            k + 1,
            self.plan.len(),
            shard.start,
            shard.end,
            t.elapsed().as_secs_f64(),
            bytes.len()
        );
        Ok(())
    }

    /// Merge every shard's sums, solve, package.
    fn merge(&self, classes: Classes) -> Result<L3Table, CliError> {
        let t = Instant::now();
        let parts = (0..self.plan.len())
            .map(|k| Ok(GramPartial::from_bytes(&self.read_partial("sums", k)?)?))
            .collect::<Result<Vec<_>, CliError>>()?;
        let read = t.elapsed().as_secs_f64();
        let (table, merging) = self.run.finish_timed(classes, parts, &quiet, self.cancel)?;
        let total = t.elapsed().as_secs_f64();
        let merged = read + merging;
        println!(
            "merge: {merged:.3} s (reading {read:.3} s); solve: {:.2} s",
            total - merged
        );
        Ok(table)
    }

    /// Every step, one shard after the other.
    fn all(&self) -> Result<L3Table, CliError> {
        let started = Instant::now();
        for k in 0..self.plan.len() {
            self.survey(k)?;
        }
        let classes = self.classes()?;
        for k in 0..self.plan.len() {
            self.accumulate(k, &classes)?;
        }
        let table = self.merge(classes)?;
        println!(
            "{} shards in {:.2} s",
            self.plan.len(),
            started.elapsed().as_secs_f64()
        );
        Ok(table)
    }
}
