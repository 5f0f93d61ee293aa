use std::path::PathBuf;

use clap::Args;

use super::{Cli, CliError, iset, load_sensor, write_file};
use crate::camera::Camera;
use crate::eval::{
    ChartSetup, Method, PaperOptions, evaluate_method, fit_baseline_matrix, run_paper_table,
};
use crate::l3::{IlluminantRegistry, L3Table};
use crate::spectral::WavelengthGrid;

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Run the paper's Table 1 (trains every table it needs).
    #[arg(long)]
    pub paper_table: bool,
    /// The table to evaluate (not with --paper-table or --method baseline).
    #[arg(long)]
    pub table: Option<PathBuf>,
    /// `l3` (the table) or `baseline` (bilinear + colour matrix fitted under D65).
    #[arg(long, default_value = "l3")]
    pub method: String,
    /// Acquisition illuminant(s); comma-separated with --paper-table.
    #[arg(long, default_value = "Tungsten", value_delimiter = ',')]
    pub illuminant: Vec<String>,
    /// Sensor design TOML (default: the paper's RGBW sensor).
    #[arg(long)]
    pub sensor: Option<PathBuf>,
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Simulate the chart without noise (isolates colour error from noise).
    #[arg(long)]
    pub no_noise: bool,
    /// Training scenes per table (with --paper-table).
    #[arg(long, default_value_t = 48)]
    pub scenes: usize,
    #[arg(long, default_value_t = 96)]
    pub scene_size: usize,
    /// Output: the ΔE JSON (or, with --paper-table, a folder for JSON + markdown).
    #[arg(long, default_value = "out/eval")]
    pub out: PathBuf,
}

/// The sensor design stored in a table.
pub fn table_sensor(table: &L3Table) -> Result<crate::camera::SensorDesign, CliError> {
    let d: crate::camera::SensorDesign = serde_json::from_value(table.meta.sensor.clone())
        .map_err(|e| {
            CliError::Usage(format!("the table's sensor description is unreadable: {e}"))
        })?;
    d.validate()?;
    Ok(d)
}

pub fn run(cli: &Cli, a: &EvalArgs) -> Result<(), CliError> {
    let iset = iset(&cli.iset_dir)?;
    let design = load_sensor(&a.sensor, iset.as_ref())?;
    let chart = ChartSetup {
        seed: a.seed,
        noise: !a.no_noise,
        ..ChartSetup::default()
    };
    if a.paper_table {
        let opts = PaperOptions {
            acquisitions: if a.illuminant == ["Tungsten"] {
                vec!["Tungsten".into(), "Fluorescent".into()]
            } else {
                a.illuminant.clone()
            },
            scenes: a.scenes,
            scene_size: a.scene_size,
            seed: a.seed,
            chart,
        };
        let started = std::time::Instant::now();
        let t = run_paper_table(&design, iset.as_ref(), &opts, &|m| eprintln!("… {m}"))?;
        let md = t.markdown();
        println!("{md}");
        println!("(took {:.1} s)", started.elapsed().as_secs_f64());
        let json = serde_json::to_vec_pretty(&t).map_err(|e| CliError::Usage(e.to_string()))?;
        write_file(&a.out.join("paper_table.json"), &json)?;
        write_file(&a.out.join("paper_table.md"), md.as_bytes())?;
        println!(
            "wrote {}/paper_table.json and paper_table.md",
            a.out.display()
        );
        return Ok(());
    }
    let acq = a
        .illuminant
        .first()
        .cloned()
        .unwrap_or_else(|| "Tungsten".into());
    let grid = WavelengthGrid::default();
    let camera = Camera::new(&design, grid, iset.as_ref())?;
    let mut registry = IlluminantRegistry::with_defaults(grid, iset.as_ref())?;
    let corr = registry.resolve(&acq, iset.as_ref())?;
    let report = match a.method.as_str() {
        "l3" => {
            let path = a
                .table
                .as_ref()
                .ok_or_else(|| CliError::Usage("--table is required with --method l3".into()))?;
            let table = L3Table::load(path)?;
            let table_camera;
            let camera = if a.sensor.is_none() {
                // evaluate on the sensor the table was trained for
                table_camera = Camera::new(&table_sensor(&table)?, grid, iset.as_ref())?;
                &table_camera
            } else {
                &camera
            };
            let name = format!(
                "L3 {} ({})",
                table.meta.kind,
                table.meta.train_illuminants.join("+")
            );
            let r = evaluate_method(
                camera,
                &Method::Table(&table),
                &name,
                &acq,
                &corr,
                iset.as_ref(),
                &chart,
            )?;
            print_budget(camera, &acq, &corr, iset.as_ref(), &chart, r)?
        }
        "baseline" => {
            let m = fit_baseline_matrix(&camera, &["D65".to_string()], iset.as_ref())?;
            let r = evaluate_method(
                &camera,
                &Method::Baseline(&m),
                "Baseline+T",
                &acq,
                &corr,
                iset.as_ref(),
                &chart,
            )?;
            print_budget(&camera, &acq, &corr, iset.as_ref(), &chart, r)?
        }
        other => {
            return Err(CliError::Usage(format!(
                "--method '{other}': expected l3 or baseline"
            )));
        }
    };
    let s = &report.summary;
    println!(
        "{} on {} under {}: mean ΔE2000 {:.2} (std {:.2}), median {:.2}, p90 {:.2}, max {:.2}; per-pixel mean {:.2}",
        report.method,
        report.chart,
        report.acquisition_illuminant,
        s.mean,
        s.std,
        s.median,
        s.p90,
        s.max,
        report.per_pixel.mean
    );
    let out = if a.out.extension().is_some() {
        a.out.clone()
    } else {
        a.out.join("report.json")
    };
    let json = serde_json::to_vec_pretty(&report).map_err(|e| CliError::Usage(e.to_string()))?;
    write_file(&out, &json)?;
    println!("wrote {}", out.display());
    let svg = out.with_extension("svg");
    if svg != out {
        write_file(&svg, crate::eval::report_svg(&report)?.as_bytes())?;
        println!("wrote {}", svg.display());
    }
    Ok(())
}

fn print_budget(
    camera: &Camera,
    acq: &str,
    corr: &crate::l3::IlluminantEntry,
    iset: Option<&crate::spectral::IsetData>,
    chart: &ChartSetup,
    mut report: crate::eval::DeltaEReport,
) -> Result<crate::eval::DeltaEReport, CliError> {
    let budget = crate::eval::error_budget(camera, acq, corr, iset, chart)?;
    println!(
        "error budget: T alone {:.2} (p90 {:.2}); linear floor {:.2} (p90 {:.2}); linear SI + T {:.2} (p90 {:.2})",
        budget.t_only.mean,
        budget.t_only.p90,
        budget.linear_floor.mean,
        budget.linear_floor.p90,
        budget.linear_si_then_t.mean,
        budget.linear_si_then_t.p90
    );
    report.context["error_budget"] = serde_json::to_value(&budget).unwrap_or_default();
    Ok(report)
}
