use std::path::PathBuf;

use clap::Args;

use super::{Cli, CliError, iset, load_sensor, write_file};
use crate::bench::{BenchOptions, markdown_table, run_bench, svg_plot};

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Output folder for bench.json, bench.md and bench.svg.
    #[arg(long, default_value = "out/bench")]
    pub out: PathBuf,
    /// Training scenes per table (default: 48; 6 with --quick).
    #[arg(long)]
    pub scenes: Option<usize>,
    /// Timed runs per throughput figure, after one warm-up (default: 5; 2 with --quick).
    #[arg(long)]
    pub runs: Option<usize>,
    /// A tiny run (2 configurations, 6 scenes, a 0.6 MP frame, 2 runs) for smoke tests.
    #[arg(long)]
    pub quick: bool,
    /// Sensor design TOML (default: the paper's RGBW sensor).
    #[arg(long)]
    pub sensor: Option<PathBuf>,
}

pub fn run(cli: &Cli, a: &BenchArgs) -> Result<(), CliError> {
    let iset = iset(&cli.iset_dir)?;
    let design = load_sensor(&a.sensor, iset.as_ref())?;
    let mut opts = if a.quick {
        BenchOptions::quick()
    } else {
        BenchOptions::full()
    };
    if let Some(s) = a.scenes {
        opts.scenes = s;
    }
    if let Some(r) = a.runs {
        if r < 1 {
            return Err(CliError::Usage("--runs must be at least 1".into()));
        }
        opts.runs = r;
    }
    let report = run_bench(&design, iset.as_ref(), &opts, &|m| eprintln!("… {m}"))?;
    let md = markdown_table(&report);
    let svg = svg_plot(&report).map_err(crate::bench::BenchError::from)?;
    let json = serde_json::to_vec_pretty(&report).map_err(|e| CliError::Usage(e.to_string()))?;
    write_file(&a.out.join("bench.json"), &json)?;
    write_file(&a.out.join("bench.md"), md.as_bytes())?;
    write_file(&a.out.join("bench.svg"), svg.as_bytes())?;
    println!("{md}");
    println!(
        "wrote {0}/bench.json, {0}/bench.md and {0}/bench.svg",
        a.out.display()
    );
    Ok(())
}
