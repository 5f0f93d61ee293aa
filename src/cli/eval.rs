use std::path::PathBuf;

use clap::Args;

use super::{Cli, CliError, iset, load_sensor, write_file};
use crate::baseline::ColourMatrix;
use crate::camera::{Camera, SensorDesign};
use crate::eval::{
    Border, ChannelSet, ChartSetup, ColourFit, DeltaEFormula, DeltaEReport, FilterSet, LightLevel,
    Method, MethodOnChart, PaperOptions, SweepOptions, catalogue_sweep, fit_colour_matrix,
    noise_split, paper_summary, run_paper_table,
};
use crate::l3::L3Table;
use crate::l3::correct::{IDENTITY, IlluminantEntry, IlluminantRegistry};
use crate::l3::render::ChromaMode;
use crate::l3::table::TableKind;
use crate::pipeline::{CorrectionMode, correction_for, uses_own_kernels};
use crate::spectral::{IsetData, WavelengthGrid};

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Run the paper's Table 1 (trains every table it needs).
    #[arg(long)]
    pub paper_table: bool,
    /// Accuracy on the sensor catalogue: for every `--sensor` (default: all 55 catalogue
    /// sensors, docs/sensors.md), the noise-free SI_Tun+T row of Table 1 against its matching
    /// linear map and the table's largest kernel norm; writes catalogue.json and catalogue.md
    /// to --out. Takes --scenes, --scene-size, --seed and --patch-px.
    #[arg(long, conflicts_with_all = ["paper_table", "table", "frame", "captures", "estimate_illuminant", "colour_classes", "illuminant", "no_noise", "exposure", "scene_luminance", "chroma_classes"])]
    pub catalogue: bool,
    /// The table to evaluate (not with --paper-table or --method baseline).
    #[arg(long, conflicts_with = "paper_table")]
    pub table: Option<PathBuf>,
    /// `l3` (the table), `baseline` (bilinear + colour matrix) or `isp` (the strong
    /// conventional ISP: Malvar or gradient-corrected demosaic, a denoiser driven by the
    /// sensor's noise model, colour matrix).
    #[arg(long, default_value = "l3")]
    pub method: String,
    /// With --method baseline or isp: the colour matrix's fit, `d65` (under D65, then T, as
    /// the paper's baseline) or `acquisition` (white-balanced, under the acquisition light to
    /// XYZ under D65; no T).
    #[arg(long, default_value = "d65")]
    pub fit: String,
    /// With --method baseline or isp: the channels the colour matrix uses, `rgb` (R, G and B
    /// when the CFA has them, a conventional 3×3) or `all`.
    #[arg(long, default_value = "rgb")]
    pub channels: String,
    #[command(flatten)]
    pub isp: super::demosaic::IspArgs,
    /// Acquisition illuminant(s); comma-separated with --paper-table. Default:
    /// Tungsten (Tungsten and Fluorescent with --paper-table; with --frame, the
    /// frame's metadata or an estimate from its pixels).
    #[arg(long, value_delimiter = ',')]
    pub illuminant: Vec<String>,
    /// Evaluate a captured frame of the Natural-100 chart instead of simulating
    /// one: `l3 simulate --scene natural100`'s mosaic.raw (with its sidecar),
    /// mosaic.dng, or any mosaic file `l3 render` reads, at the chart's size
    /// for --patch-px. Needs --table.
    #[arg(long, conflicts_with_all = ["paper_table", "captures", "estimate_illuminant"])]
    pub frame: Option<PathBuf>,
    /// Sensor: a design TOML or a catalogue name (`l3 sensors`; default: the paper's RGBW
    /// sensor). With --paper-table, repeat it (or give a comma-separated list) to run the
    /// table on several sensors in one go.
    #[arg(long, value_delimiter = ',')]
    pub sensor: Vec<PathBuf>,
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Simulate the chart without noise (isolates colour error from noise).
    /// With --paper-table the tables are trained without noise too
    /// (noise-free patches and colour maps).
    #[arg(long)]
    pub no_noise: bool,
    /// Exposure time relative to auto-exposure, in (0, 1]: 0.1 is a tenth of
    /// the light (low light).
    #[arg(long, conflicts_with = "scene_luminance")]
    pub exposure: Option<f64>,
    /// The chroma stage of L3 renders: `auto` (when the frame's chroma noise needs it), `on`
    /// or `off` (as `l3 render --chroma-denoise`).
    #[arg(long, default_value_t = ChromaMode::default())]
    pub chroma_denoise: ChromaMode,
    /// Mean chart luminance in cd/m². Below 100 cd/m² the camera holds its
    /// longest exposure (auto-exposure's time at 100 cd/m²), so the signal
    /// falls with the light.
    #[arg(long)]
    pub scene_luminance: Option<f64>,
    /// Side of each chart patch in pixels (8–64; the interior averaged is
    /// the patch minus a fifth, at least 3 pixels, on each side).
    #[arg(long, default_value_t = 24, value_parser = clap::value_parser!(u16).range(8..=64))]
    pub patch_px: u16,
    /// Also evaluate N noisy captures (seeds --seed, --seed + 1, …) and one
    /// noise-free capture, and split the patch-mean error: one capture's
    /// mean and spread, the patch means averaged over the captures (the
    /// bias) and the noise-free chart. 2–64. With --paper-table: every row
    /// over N captures at full exposure (its mean and spread, and its
    /// matching linear map's), beside the first capture's table.
    #[arg(long, value_parser = clap::value_parser!(u16).range(2..=64))]
    pub captures: Option<u16>,
    /// With --captures N: also fit the captured floor, a linear map from each
    /// patch's channel means to XYZ fitted on the chart itself (minimising the
    /// mean ΔE2000 over the N captures), scored on N fresh captures and
    /// 2-fold cross-validated over the patches: what a linear pipeline reaches
    /// on this capture's flare and noise given the answers, and without them.
    #[arg(long, requires = "captures", conflicts_with = "paper_table")]
    pub captured_floor: bool,
    /// Study the light taken from a frame with `--table` (an SI table): under A,
    /// Tungsten, D50, D65, F2, F11 and 2700–10000 K, the colour temperature from
    /// metadata (the camera's white, as a DNG's AsShotNeutral) and estimated from
    /// the chart's and a dead-leaves texture's pixels, with the chart's ΔE2000
    /// for each.
    #[arg(long, conflicts_with_all = ["paper_table", "captures"])]
    pub estimate_illuminant: bool,
    /// Predict, without training, a cross-illuminant table's chart error with
    /// colour maps per luminance level and per chroma class, for each count
    /// given (1 is what the trainer fits today): the maps fitted as the trainer
    /// fits them, the chart's channel means drawn from the sensor's noise model
    /// over --captures captures (default 16). See the README's "colour classes".
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["paper_table", "frame", "estimate_illuminant", "table"])]
    pub colour_classes: Vec<usize>,
    /// The correction an SI table's output gets under the acquisition light:
    /// `colorimetric` (or `t`: the paper's T, from colorimetry alone) or
    /// `camera` (C, fitted per level on the table's colour maps and the sensor under that
    /// light; what `l3 render` and the service use by default). Default: colorimetric, but
    /// camera with --colorchecker (which renders as `l3 render` does).
    #[arg(long)]
    pub correction: Option<CorrectionMode>,
    /// The chart simulated (or read with --frame): `natural100` (the paper's) or `macbeth`
    /// (ISET's Macbeth ColorChecker, as `l3 simulate --scene macbeth` draws it; with
    /// --frame its patch size is taken from the frame). The grey row of the Macbeth chart
    /// is left out of the summary, as Natural-100's grey strip is.
    #[arg(long, default_value = "natural100")]
    pub chart: String,
    /// Evaluate a capture of a ColorChecker Classic against published values: FRAME (any
    /// mosaic file `l3 render` reads) is rendered with --table as `l3 render` renders it,
    /// the 24 patches are found from --corners and compared with --reference (ΔE2000
    /// after scaling the rendering so its white patch matches the reference's). Writes
    /// JSON and an SVG figure. See docs/cli.md.
    #[arg(long, value_name = "FRAME", requires_all = ["corners", "table"], conflicts_with_all = ["paper_table", "catalogue", "frame", "captures", "estimate_illuminant", "colour_classes"])]
    pub colorchecker: Option<PathBuf>,
    /// With --colorchecker: the outer corners of the chart's 6 × 4 grid of patches in the
    /// frame, in pixels, `x1,y1,x2,y2,x3,y3,x4,y4`: dark skin's corner, bluish green's,
    /// black's, white's (clockwise as the chart is seen, whichever way up it is in the frame).
    #[arg(long, requires = "colorchecker")]
    pub corners: Option<String>,
    /// With --colorchecker: `xrite2014` (X-Rite's published values for charts made after
    /// November 2014, adapted from D50 to D65 with Bradford), `iset` (ISET's Macbeth
    /// reflectances under D65: the chart `l3 simulate --scene macbeth` draws), or a CSV file
    /// of your own chart's measured values (L,a,b under D50, or X,Y,Z under D65; docs/cli.md),
    /// such as the truth.csv `l3 simulate --scene macbeth` writes.
    #[arg(long, default_value = "xrite2014", requires = "colorchecker")]
    pub reference: String,
    /// With --colorchecker: the gap between patches as a fraction of a patch's side (0.1, a
    /// ColorChecker Classic's; 0 for `l3 simulate --scene macbeth`'s chart, drawn edge to edge).
    #[arg(long, default_value_t = crate::eval::colorchecker::CLASSIC_GAP, requires = "colorchecker")]
    pub chart_gap: f64,
    /// S-CIELAB (Zhang & Wandell 1996) between two 32-bit float XYZ TIFFs (D65, white Y = 1,
    /// same size): `--scielab IDEAL RENDERED`. Prints the per-pixel ΔE's mean, p90 and max as
    /// JSON and writes it to --out. See docs/accuracy.md.
    #[arg(long, num_args = 2, value_names = ["IDEAL", "RENDERED"], conflicts_with_all = ["paper_table", "catalogue", "frame", "captures", "estimate_illuminant", "colour_classes", "colorchecker", "table"])]
    pub scielab: Vec<PathBuf>,
    /// With --scielab: image samples per degree of visual angle (default 41.2: a 120-ppi
    /// display seen from 50 cm).
    #[arg(long, requires = "scielab")]
    pub samples_per_degree: Option<f64>,
    /// With --scielab: the ΔE formula, `2000` (CIEDE2000) or `1976`.
    #[arg(long, default_value = "2000")]
    pub delta_e: DeltaEFormula,
    /// With --scielab: the channel filters, `paper` (Zhang & Wandell's published weights and
    /// spreads) or `distribution` (their released code's, ISETCam's default).
    #[arg(long, default_value = "paper")]
    pub scielab_filters: FilterSet,
    /// With --scielab: how the image is extended past its edges, `symmetric` (mirrored) or
    /// `periodic` (wrapped, as ISETCam's FFT convolution does).
    #[arg(long, default_value = "symmetric")]
    pub border: Border,
    /// With --scielab: also write the per-pixel ΔE map here, as a 32-bit float grey TIFF.
    #[arg(long, requires = "scielab")]
    pub map: Option<PathBuf>,
    /// On a simulated chart, skip the spatial metrics (sharpness and false colour on a
    /// slanted edge, S-CIELAB on a texture; docs/accuracy.md) the report carries by default.
    #[arg(long)]
    pub no_spatial: bool,
    /// Training scenes per table (with --paper-table or --catalogue).
    #[arg(long, default_value_t = 48)]
    pub scenes: usize,
    #[arg(long, default_value_t = 96)]
    pub scene_size: usize,
    /// Chroma classes of every table trained (with --paper-table; 1: none):
    /// see `l3 train --chroma-classes`.
    #[arg(long, default_value_t = crate::l3::learn::DEFAULT_CHROMA_CLASSES)]
    pub chroma_classes: usize,
    /// Output: the ΔE JSON (or, with --paper-table, a folder for JSON + markdown).
    #[arg(long, default_value = "out/eval")]
    pub out: PathBuf,
}

/// The chart set-up the arguments describe.
fn chart_setup(a: &EvalArgs) -> Result<ChartSetup, CliError> {
    let chart = ChartSetup {
        chart: a.chart.parse().map_err(CliError::argument)?,
        seed: a.seed,
        noise: !a.no_noise,
        patch_px: a.patch_px.into(),
        chroma_denoise: a.chroma_denoise,
        ..ChartSetup::default()
    };
    let light = match (a.exposure, a.scene_luminance) {
        (Some(f), _) => Some(LightLevel::ExposureFactor(f)),
        (None, Some(l)) => Some(LightLevel::SceneLuminance(l)),
        (None, None) => None,
    };
    Ok(match light {
        Some(l) => l.apply(&chart).map_err(CliError::argument)?,
        None => chart,
    })
}

pub fn run(cli: &Cli, a: &EvalArgs) -> Result<(), CliError> {
    if let [ideal, rendered] = a.scielab.as_slice() {
        return super::scielab::run(&super::scielab::ScielabArgs {
            ideal,
            rendered,
            samples_per_degree: a.samples_per_degree,
            delta_e: a.delta_e,
            filters: a.scielab_filters,
            border: a.border,
            map: a.map.as_ref(),
            out: &a.out,
        });
    }
    if a.table.is_some() && a.method != "l3" {
        return Err(CliError::Usage(format!(
            "--table evaluates an L3 table: not with --method {}",
            a.method
        )));
    }
    let iset = iset(&cli.iset_dir)?;
    let chart = chart_setup(a)?;
    if a.paper_table {
        return run_paper_tables(a, iset.as_ref(), chart);
    }
    if a.catalogue {
        return run_catalogue_sweep(a, iset.as_ref());
    }
    if let Some(frame) = &a.colorchecker {
        let args = super::colorchecker::ColorCheckerArgs {
            frame,
            table: a.table.as_ref(),
            corners: a.corners.as_deref(),
            reference: &a.reference,
            gap: a.chart_gap,
            correction: a.correction,
            illuminant: a.illuminant.first().map(String::as_str),
            out: &a.out,
        };
        return super::colorchecker::run(&args, iset.as_ref());
    }
    if a.estimate_illuminant {
        return run_estimation_study(a, iset.as_ref(), &chart);
    }
    if !a.colour_classes.is_empty() {
        return run_colour_class_study(a, iset.as_ref(), &chart);
    }
    if a.sensor.len() > 1 {
        return Err(CliError::Usage(
            "several --sensor files are for --paper-table; evaluate one sensor at a time".into(),
        ));
    }
    if let Some(frame) = &a.frame {
        let report = evaluate_frame(a, frame, iset.as_ref(), &chart)?;
        return print_and_write(a, &report);
    }
    let report = evaluate_simulated(a, iset.as_ref(), &chart)?;
    print_and_write(a, &report)
}

/// `--method l3` (with `--table`) or `baseline` on the simulated chart under the first
/// `--illuminant` (Tungsten).
fn evaluate_simulated(
    a: &EvalArgs,
    iset: Option<&IsetData>,
    chart: &ChartSetup,
) -> Result<DeltaEReport, CliError> {
    let design = load_sensor(&a.sensor.first().cloned(), iset)?;
    let acq = a
        .illuminant
        .first()
        .cloned()
        .unwrap_or_else(|| "Tungsten".into());
    let grid = WavelengthGrid::default();
    let camera = Camera::new(&design, grid, iset)?;
    let mut registry = IlluminantRegistry::with_defaults(grid, iset)?;
    let corr = registry.resolve(&acq, iset).map_err(CliError::argument)?;
    match a.method.as_str() {
        "l3" => {
            let path = a
                .table
                .as_ref()
                .ok_or_else(|| CliError::Usage("--table is required with --method l3".into()))?;
            let table = L3Table::load(path)?;
            if !a.sensor.is_empty() {
                check_sensor_fits(&design, &table)?;
            }
            let table_camera;
            let camera = if a.sensor.is_empty() {
                // evaluate on the sensor the table was trained for
                table_camera = Camera::new(&table.sensor_design()?, grid, iset)?;
                &table_camera
            } else {
                &camera
            };
            let mode = a.correction.unwrap_or(CorrectionMode::Colorimetric);
            let corr = correction_for(&table, &corr, mode, iset)?;
            let name = format!(
                "L3 {} ({}){}",
                table.meta.kind,
                table.meta.train_illuminants.join("+"),
                match mode {
                    CorrectionMode::Camera if !uses_own_kernels(&table) => " + camera-aware C",
                    _ => "",
                }
            );
            let m = MethodOnChart {
                camera,
                method: &Method::Table(&table),
                method_name: &name,
                acquisition: &acq,
                correction: &corr,
                iset,
            };
            evaluate_and_explain(a, &m, chart)
        }
        "baseline" | "isp" => {
            let (matrix, name, corr) = conventional_matrix(a, &camera, &acq, &corr, iset)?;
            let isp;
            let method = if a.method == "isp" {
                isp = a.isp.build(matrix, &camera)?;
                Method::Isp(&isp)
            } else {
                Method::Baseline(&matrix)
            };
            // the paper table's names: Baseline+T, Baseline_Tun, ISP_D65+T, ISP_Tun
            let stem = match (a.method.as_str(), a.fit.as_str()) {
                ("isp", "d65") => "ISP_D65",
                ("isp", _) => "ISP",
                _ => "Baseline",
            };
            let m = MethodOnChart {
                camera: &camera,
                method: &method,
                method_name: &format!("{stem}{name}"),
                acquisition: &acq,
                correction: &corr,
                iset,
            };
            evaluate_and_explain(a, &m, chart)
        }
        other => Err(CliError::Usage(format!(
            "--method '{other}': expected l3, baseline or isp"
        ))),
    }
}

/// The conventional pipelines' colour matrix for `--fit` and `--channels`, the suffix of
/// the method's name (`+T`, `_Tun`, with ` all`) and the correction it is rendered with (T,
/// or none for the acquisition fit, which aims at D65 itself).
fn conventional_matrix(
    a: &EvalArgs,
    camera: &Camera,
    acq: &str,
    corr: &IlluminantEntry,
    iset: Option<&IsetData>,
) -> Result<(ColourMatrix, String, IlluminantEntry), CliError> {
    let channels = match a.channels.as_str() {
        "rgb" => ChannelSet::Rgb,
        "all" => ChannelSet::All,
        o => {
            return Err(CliError::Usage(format!(
                "--channels '{o}': expected rgb or all"
            )));
        }
    };
    let all = if channels == ChannelSet::All {
        " all"
    } else {
        ""
    };
    let (lights, kind, name, corr) = match a.fit.as_str() {
        "d65" => (
            vec!["D65".to_string()],
            TableKind::SameIlluminant,
            format!("+T{all}"),
            corr.clone(),
        ),
        "acquisition" => (
            vec![acq.to_string()],
            TableKind::CrossIlluminant,
            format!("_{}{all}", crate::eval::paper_table::short(acq)),
            IlluminantEntry {
                t: IDENTITY,
                ..corr.clone()
            },
        ),
        o => {
            return Err(CliError::Usage(format!(
                "--fit '{o}': expected d65 or acquisition"
            )));
        }
    };
    let fit = ColourFit {
        illuminants: &lights,
        kind,
        channels,
        preserve_white: kind == TableKind::CrossIlluminant,
        through_correction: false,
    };
    Ok((fit_colour_matrix(camera, &fit, iset)?, name, corr))
}

/// `--sensor`'s design against the table's: another CFA is a usage error, another name a
/// warning (a prototype may be evaluated with another sensor's table).
fn check_sensor_fits(design: &SensorDesign, table: &L3Table) -> Result<(), CliError> {
    match crate::pipeline::design_fit(design, table) {
        Ok(Some(m)) => eprintln!("warning: --sensor: {m}"),
        Ok(None) => {}
        Err(e) => return Err(CliError::Usage(format!("--sensor {}: {e}", design.name))),
    }
    Ok(())
}

/// `--frame`: a captured chart frame rendered with `--table` under the light named by
/// `--illuminant`, else the frame's metadata, else an estimate from its pixels.
fn evaluate_frame(
    a: &EvalArgs,
    frame: &std::path::Path,
    iset: Option<&IsetData>,
    chart: &ChartSetup,
) -> Result<DeltaEReport, CliError> {
    let path = a
        .table
        .as_ref()
        .ok_or_else(|| CliError::Usage("--frame needs --table".into()))?;
    let table = L3Table::load(path)?;
    let named = a.illuminant.first().map(String::as_str);
    let (input, spec, source) = super::render::frame_and_light(frame, &table, named, iset)?;
    let (width, height) = (input.width, input.height);
    let grid = table.meta.grid;
    let design = match a.sensor.first() {
        Some(p) => {
            let design = load_sensor(&Some(p.clone()), iset)?;
            check_sensor_fits(&design, &table)?;
            design
        }
        None => table.sensor_design()?,
    };
    let camera = Camera::new(&design, grid, iset)?;
    let mut registry = IlluminantRegistry::with_defaults(grid, iset)?;
    let corr = registry.resolve(&spec, iset).map_err(|e| match named {
        Some(_) => CliError::argument(e),
        None => e.into(),
    })?;
    let mode = a.correction.unwrap_or(CorrectionMode::Colorimetric);
    let corr = correction_for(&table, &corr, mode, iset)?;
    println!("illuminant {} (from {source})", corr.name);
    let cap = crate::eval::frame_chart_capture(
        &camera,
        input.into_volts(table.meta.voltage_swing)?,
        width,
        height,
        &corr.name,
        iset,
        chart,
    )?
    .with_ideal_image(&camera)?;
    let name = format!(
        "L3 {} ({})",
        table.meta.kind,
        table.meta.train_illuminants.join("+")
    );
    let mut report =
        crate::eval::evaluate_capture(&camera, &cap, &Method::Table(&table), &name, &corr, chart)?;
    report.context["frame"] = serde_json::json!(frame.display().to_string());
    report.context["correction_mode"] = serde_json::json!(mode.as_str());
    report.context["illuminant_source"] = serde_json::json!(source);
    Ok(report)
}

/// Print a report's summary line and write its JSON and SVG figure.
fn print_and_write(a: &EvalArgs, report: &DeltaEReport) -> Result<(), CliError> {
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
    if let Some(s) = report.s_cielab_mean {
        println!("S-CIELAB of the render against the ideal image: mean ΔE2000 {s:.2}");
    }
    let sp = &report.spatial;
    let f = |v: Option<f64>, d: usize| v.map_or("—".to_string(), |v| format!("{v:.d$}"));
    if sp.mtf50.is_some() || sp.false_colour.is_some() || sp.s_cielab_texture.is_some() {
        println!(
            "slanted edge: MTF50 {} cycles/pixel (the lens's own {}), SFR at half Nyquist {}, false colour {} C*ab; texture S-CIELAB mean ΔE2000 {}",
            f(sp.mtf50, 3),
            f(sp.ideal_mtf50, 3),
            f(sp.mtf_at_half_nyquist, 3),
            f(sp.false_colour, 2),
            f(sp.s_cielab_texture, 2)
        );
    }
    let out = if a.out.extension().is_some() {
        a.out.clone()
    } else {
        a.out.join("report.json")
    };
    let json = serde_json::to_vec_pretty(report)?;
    write_file(&out, &json)?;
    println!("wrote {}", out.display());
    let svg = out.with_extension("svg");
    if svg != out {
        write_file(&svg, crate::eval::report_svg(report)?.as_bytes())?;
        println!("wrote {}", svg.display());
    }
    Ok(())
}

/// `--estimate-illuminant`: the study, printed as markdown and written as JSON.
fn run_estimation_study(
    a: &EvalArgs,
    iset: Option<&IsetData>,
    chart: &ChartSetup,
) -> Result<(), CliError> {
    let path = a.table.as_ref().ok_or_else(|| {
        CliError::Usage("--estimate-illuminant needs --table (a same-illuminant table)".into())
    })?;
    let table = L3Table::load(path)?;
    let lights: Vec<String> = crate::eval::STUDY_LIGHTS
        .iter()
        .map(|s| s.to_string())
        .collect();
    let rows = crate::eval::illuminant_estimation_study(&table, &lights, iset, chart)?;
    println!("{}", crate::eval::estimation_markdown(&rows));
    write_study(a, "illuminant_estimation.json", &rows)
}

/// Write a study's JSON to `--out` (a file, or `name` in that folder).
fn write_study(a: &EvalArgs, name: &str, study: &impl serde::Serialize) -> Result<(), CliError> {
    let out = if a.out.extension().is_some() {
        a.out.clone()
    } else {
        a.out.join(name)
    };
    let json = serde_json::to_vec_pretty(study)?;
    write_file(&out, &json)?;
    println!("wrote {}", out.display());
    Ok(())
}

/// `--colour-classes`: the study for the first `--sensor` under the first
/// `--illuminant` (Tungsten), printed as markdown and written as JSON.
fn run_colour_class_study(
    a: &EvalArgs,
    iset: Option<&IsetData>,
    chart: &ChartSetup,
) -> Result<(), CliError> {
    if a.sensor.len() > 1 {
        return Err(CliError::Usage(
            "--colour-classes studies one --sensor at a time".into(),
        ));
    }
    if a.colour_classes.contains(&0) {
        return Err(CliError::Usage(format!(
            "--colour-classes {}: each count must be at least 1",
            a.colour_classes
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(",")
        )));
    }
    let sensor = a.sensor.first().cloned();
    let design = load_sensor(&sensor, iset)?;
    let camera = Camera::new(&design, WavelengthGrid::default(), iset)?;
    let acq = a
        .illuminant
        .first()
        .cloned()
        .unwrap_or_else(|| "Tungsten".into());
    let captures = a.captures.map_or(16, usize::from);
    let study =
        crate::eval::colour_class_study(&camera, &acq, iset, chart, &a.colour_classes, captures)?;
    println!(
        "{}",
        crate::eval::colour_class_markdown(&design.name, &study)
    );
    write_study(a, "colour_classes.json", &study)
}

/// Table 1 on every `--sensor` (the default sensor when none is given):
/// one folder of JSON, markdown and figures per sensor, and a summary.
fn run_paper_tables(
    a: &EvalArgs,
    iset: Option<&IsetData>,
    chart: ChartSetup,
) -> Result<(), CliError> {
    let sensors: Vec<Option<PathBuf>> = if a.sensor.is_empty() {
        vec![None]
    } else {
        a.sensor.iter().cloned().map(Some).collect()
    };
    let opts = PaperOptions {
        acquisitions: if a.illuminant.is_empty() {
            vec!["Tungsten".into(), "Fluorescent".into()]
        } else {
            a.illuminant.clone()
        },
        scenes: a.scenes,
        scene_size: a.scene_size,
        seed: a.seed,
        chart,
        chroma_classes: a.chroma_classes,
        captures: a.captures.map_or(1, usize::from),
        ..PaperOptions::default()
    };
    let mut tables = Vec::new();
    for s in &sensors {
        let design = load_sensor(s, iset)?;
        let started = std::time::Instant::now();
        let t = run_paper_table(&design, iset, &opts, &|m| {
            eprintln!("… [{}] {m}", design.name)
        })?;
        let md = t.markdown();
        println!("{md}");
        println!("(took {:.1} s)", started.elapsed().as_secs_f64());
        let dir = if sensors.len() > 1 {
            a.out.join(&design.name)
        } else {
            a.out.clone()
        };
        let json = serde_json::to_vec_pretty(&t)?;
        write_file(&dir.join("paper_table.json"), &json)?;
        write_file(&dir.join("paper_table.md"), md.as_bytes())?;
        for r in &t.reports {
            let file = format!(
                "{}_{}.svg",
                r.acquisition_illuminant,
                r.method.replace(['+', ' ', '/'], "_")
            );
            write_file(
                &dir.join("figures").join(file),
                crate::eval::report_svg(r)?.as_bytes(),
            )?;
        }
        println!(
            "wrote {0}/paper_table.json, {0}/paper_table.md and {0}/figures/",
            dir.display()
        );
        tables.push(t);
    }
    if tables.len() > 1 {
        let md = paper_summary(&tables);
        println!("{md}");
        write_file(&a.out.join("summary.md"), md.as_bytes())?;
        println!("wrote {}/summary.md", a.out.display());
    }
    Ok(())
}

/// `--catalogue`: the sweep over every `--sensor` (default: the whole catalogue), its
/// markdown printed, its JSON and markdown written to `--out`.
fn run_catalogue_sweep(a: &EvalArgs, iset: Option<&IsetData>) -> Result<(), CliError> {
    let designs = if a.sensor.is_empty() {
        crate::camera::catalogue::catalogue()
            .iter()
            .map(|e| e.load(iset))
            .collect::<Result<Vec<_>, _>>()?
    } else {
        a.sensor
            .iter()
            .map(|s| load_sensor(&Some(s.clone()), iset))
            .collect::<Result<Vec<_>, _>>()?
    };
    let opts = SweepOptions {
        scenes: a.scenes,
        scene_size: a.scene_size,
        seed: a.seed,
        patch_px: a.patch_px.into(),
    };
    eprintln!(
        "… training {} sensors ({} scenes of {} px each)",
        designs.len(),
        opts.scenes,
        opts.scene_size
    );
    let sweep = catalogue_sweep(&designs, iset, &opts, &|m| eprintln!("… {m}"))?;
    let md = sweep.markdown();
    println!("{md}");
    let json = serde_json::to_vec_pretty(&sweep)?;
    write_file(&a.out.join("catalogue.json"), &json)?;
    write_file(&a.out.join("catalogue.md"), md.as_bytes())?;
    println!(
        "wrote {0}/catalogue.json and {0}/catalogue.md",
        a.out.display()
    );
    Ok(())
}

/// Evaluate `m` on the chart and explain its error: the sensor's
/// error budget and, with `--captures N`, the noise split, both printed and
/// added to the report's context.
fn evaluate_and_explain(
    a: &EvalArgs,
    m: &MethodOnChart,
    chart: &ChartSetup,
) -> Result<DeltaEReport, CliError> {
    let (camera, acq, corr, iset) = (m.camera, m.acquisition, m.correction, m.iset);
    let mut report = if a.no_spatial {
        m.evaluate_with_s_cielab(chart)?
    } else {
        m.evaluate_with_spatial(chart)?
    };
    if let Some(n) = a.captures {
        let split = noise_split(m, chart, n.into())?;
        println!(
            "noise split over {n} captures: one capture {:.2} (std {:.2}, {:.2}–{:.2}); patch means averaged over the captures {:.2}; noise-free {:.2}",
            split.per_capture_stats.mean,
            split.per_capture_stats.std,
            split
                .per_capture
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min),
            split.per_capture_stats.max,
            split.averaged.mean,
            split.noise_free.mean,
        );
        report.context["noise_split"] = serde_json::to_value(&split).unwrap_or_default();
        if a.captured_floor {
            let floor = crate::eval::captured_floor(camera, acq, iset, chart, n.into())?;
            println!(
                "captured floor (a linear map fitted on this chart's patch channel means, minimising ΔE2000 over {n} captures): {:.2} on them, {:.2} on {n} fresh captures, {:.2} noise-free; 2-fold cross-validated over the patches {:.2} ({:.2}, {:.2})",
                floor.fitted,
                floor.fresh,
                floor.noise_free,
                floor.cross_validated,
                floor.folds[0],
                floor.folds[1],
            );
            report.context["captured_floor"] = serde_json::to_value(&floor).unwrap_or_default();
        }
    }
    let budget = crate::eval::error_budget(camera, acq, corr, iset, chart)?;
    println!(
        "error budget: T alone {:.2} (p90 {:.2}); linear floor {:.2} (p90 {:.2}); linear SI + T {:.2} (p90 {:.2}); linear cross {:.2}",
        budget.t_only.mean,
        budget.t_only.p90,
        budget.linear_floor.mean,
        budget.linear_floor.p90,
        budget.linear_si_then_t.mean,
        budget.linear_si_then_t.p90,
        budget.linear_cross.as_ref().map_or(f64::NAN, |s| s.mean)
    );
    report.context["error_budget"] = serde_json::to_value(&budget).unwrap_or_default();
    Ok(report)
}
