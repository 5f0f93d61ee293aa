use std::path::PathBuf;

use clap::Args;

use super::{Cli, CliError, iset, load_sensor, write_file};
use crate::bench::{
    BenchOptions, FrontMetric, markdown_table, run_bench, run_sensor_sweep, sensor_sweep_markdown,
    svg_plot, svg_plot_metric,
};
use crate::spectral::IsetData;

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
    /// Sensor: a design TOML or a catalogue name (default: the paper's RGBW sensor). Several (repeat
    /// it, or a comma-separated list) run the sensor sweep: the default
    /// configuration and the baselines on each sensor.
    #[arg(long, value_delimiter = ',')]
    pub sensor: Vec<PathBuf>,
    /// The sensor sweep over every shipped sensor (`config/sensors/*.toml`).
    #[arg(long, conflicts_with = "sensor")]
    pub all_sensors: bool,
}

/// The shipped sensor designs: `config/sensors/*.toml`, sorted by name.
fn shipped_sensors() -> Result<Vec<PathBuf>, CliError> {
    let dir = PathBuf::from("config/sensors");
    let rd = std::fs::read_dir(&dir).map_err(|source| CliError::File {
        path: format!("{} (run from the repository root)", dir.display()),
        source,
    })?;
    let mut v: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    v.sort();
    Ok(v)
}

pub fn run(cli: &Cli, a: &BenchArgs) -> Result<(), CliError> {
    let iset = iset(&cli.iset_dir)?;
    let sensors = if a.all_sensors {
        shipped_sensors()?
    } else {
        a.sensor.clone()
    };
    let opts = bench_options(a)?;
    if sensors.len() > 1 {
        return run_sensor_sweep_to(a, &sensors, iset.as_ref(), &opts);
    }
    let design = load_sensor(&sensors.first().cloned(), iset.as_ref())?;
    let report = run_bench(&design, iset.as_ref(), &opts, &|m| eprintln!("… {m}"))?;
    let md = markdown_table(&report);
    let svg = svg_plot(&report).map_err(crate::bench::BenchError::from)?;
    let json = serde_json::to_vec_pretty(&report)?;
    write_file(&a.out.join("bench.json"), &json)?;
    write_file(&a.out.join("bench.md"), md.as_bytes())?;
    write_file(&a.out.join("bench.svg"), svg.as_bytes())?;
    // the same run time against S-CIELAB and against sharpness, where they were measured
    for metric in [FrontMetric::SCielab, FrontMetric::Mtf50] {
        if let Ok(svg) = svg_plot_metric(&report, metric) {
            let name = format!("bench-{}.svg", metric.name());
            write_file(&a.out.join(name), svg.as_bytes())?;
        }
    }
    println!("{md}");
    println!(
        "wrote {0}/bench.json, {0}/bench.md and {0}/bench.svg (and bench-s_cielab.svg, bench-mtf50.svg)",
        a.out.display()
    );
    Ok(())
}

/// The benchmark options: full or `--quick`, with `--scenes` and `--runs` over them.
fn bench_options(a: &BenchArgs) -> Result<BenchOptions, CliError> {
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
    Ok(opts)
}

/// The sensor sweep over `sensors`: sensors.json and sensors.md in `--out`.
fn run_sensor_sweep_to(
    a: &BenchArgs,
    sensors: &[PathBuf],
    iset: Option<&IsetData>,
    opts: &BenchOptions,
) -> Result<(), CliError> {
    let designs = sensors
        .iter()
        .map(|p| load_sensor(&Some(p.clone()), iset))
        .collect::<Result<Vec<_>, _>>()?;
    let sweep = run_sensor_sweep(&designs, iset, opts, &|m| eprintln!("… {m}"))?;
    let mut md = sensor_sweep_markdown(&sweep);
    for r in &sweep.reports {
        md.push('\n');
        md.push_str(&markdown_table(r));
    }
    let json = serde_json::to_vec_pretty(&sweep)?;
    write_file(&a.out.join("sensors.json"), &json)?;
    write_file(&a.out.join("sensors.md"), md.as_bytes())?;
    println!("{md}");
    println!("wrote {0}/sensors.json and {0}/sensors.md", a.out.display());
    Ok(())
}
