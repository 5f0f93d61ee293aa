//! `l3 eval --colorchecker FRAME --corners …`: a real ColorChecker capture rendered as
//! `l3 render` renders it, scored against published values
//! ([`crate::eval::colorchecker`]), written as JSON and an SVG figure.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::render::{light_source, render_file_xyz};
use super::{CliError, write_file};
use crate::eval::EvalError;
use crate::eval::colorchecker::geometry::sample_patches;
use crate::eval::colorchecker::{
    ColorCheckerOptions, ColorCheckerReport, Labels, Measured, Reference, rendered_xyz,
    score_colorchecker,
};
use crate::l3::L3Table;
use crate::pipeline::CorrectionMode;
use crate::spectral::IsetData;

/// What `l3 eval --colorchecker` was asked (its flags).
pub struct ColorCheckerArgs<'a> {
    pub frame: &'a Path,
    pub table: Option<&'a PathBuf>,
    pub corners: Option<&'a str>,
    pub reference: &'a str,
    pub gap: f64,
    pub correction: Option<CorrectionMode>,
    pub illuminant: Option<&'a str>,
    pub out: &'a Path,
}

pub fn run(a: &ColorCheckerArgs, iset: Option<&IsetData>) -> Result<(), CliError> {
    let frame = a.frame;
    let table_path = a
        .table
        .ok_or_else(|| CliError::Usage("--colorchecker needs --table".into()))?;
    let corners = a
        .corners
        .ok_or_else(|| CliError::Usage("--colorchecker needs --corners".into()))?;
    let opts = ColorCheckerOptions {
        corners: corners.parse().map_err(CliError::argument)?,
        gap: a.gap,
        reference: reference_arg(a.reference)?,
    };
    let table = L3Table::load(table_path)?;
    let correction = a.correction.unwrap_or(CorrectionMode::Camera);
    let named = a.illuminant;
    let out = render_file_xyz(&table, frame, named, correction, iset)?;
    let (light, origin) = (out.light.clone(), light_source(out.light_origin));
    let (xyz, width, height) = rendered_xyz(out)?;
    let method = format!(
        "L3 {} ({})",
        table.meta.kind,
        table.meta.train_illuminants.join("+")
    );
    let labels = Labels {
        method: &method,
        illuminant: &light,
        context: serde_json::json!({
            "frame": frame.display().to_string(),
            "table": table_path.display().to_string(),
            "width": width,
            "height": height,
            "correction": correction.as_str(),
            "illuminant_source": origin,
        }),
    };
    // where the corners and the gap put the patches: a chart that does not fit the frame is
    // the flags' mistake
    let samples =
        sample_patches(&xyz, width, height, &opts.corners, opts.gap).map_err(CliError::argument)?;
    let report = score_colorchecker(&samples, &opts, iset, labels)?;
    print_report(&report, origin);
    let path = if a.out.extension().is_some() {
        a.out.to_path_buf()
    } else {
        a.out.join("colorchecker.json")
    };
    let json = serde_json::to_vec_pretty(&report)?;
    write_file(&path, &json)?;
    let svg = path.with_extension("svg");
    write_file(&svg, crate::eval::colorchecker_svg(&report)?.as_bytes())?;
    println!("wrote {} and {}", path.display(), svg.display());
    Ok(())
}

/// `--reference`: `xrite2014`, `iset`, or a CSV file of a measured chart's values.
fn reference_arg(s: &str) -> Result<Reference, CliError> {
    if ["xrite2014", "iset"].contains(&s.to_ascii_lowercase().as_str()) {
        return s
            .parse()
            .map_err(|e: EvalError| CliError::Usage(e.to_string()));
    }
    let text = std::fs::read_to_string(s).map_err(|source| CliError::File {
        path: format!("{s} (--reference: xrite2014, iset or a CSV file)"),
        source,
    })?;
    let measured = Measured::from_csv(&text, s).map_err(|e| CliError::Usage(e.to_string()))?;
    Ok(Reference::Measured(Arc::new(measured)))
}

/// The per-patch table and the summary, on stdout.
fn print_report(r: &ColorCheckerReport, origin: &str) {
    println!(
        "{} under {} (from {origin}) against {}: exposure scaled ×{:.4} so that {} has Y {:.4}",
        r.method,
        r.acquisition_illuminant,
        r.reference.as_str(),
        r.normalisation.scale,
        r.normalisation.patch,
        r.normalisation.reference_y
    );
    println!(
        "{:>2}  {:<20} {:>20} {:>20} {:>6} {:>9}",
        "#", "patch", "reference L*a*b*", "rendered L*a*b*", "ΔE00", "refs ΔE00"
    );
    let lab = |l: [f64; 3]| format!("{:6.2} {:6.2} {:6.2}", l[0], l[1], l[2]);
    for p in &r.patches {
        println!(
            "{:>2}  {:<20} {:>20} {:>20} {:>6.2} {:>9.2}",
            p.index,
            p.name,
            lab(p.reference_lab),
            lab(p.rendered_lab),
            p.delta_e,
            p.references_delta_e
        );
    }
    let (s, b) = (&r.summary, &r.references);
    println!(
        "ΔE2000 over 24 patches: mean {:.2}, median {:.2}, p90 {:.2}, max {:.2}; between the two references ({}): mean {:.2}, max {:.2}",
        s.mean,
        s.median,
        s.p90,
        s.max,
        r.references_label(),
        b.mean,
        b.max
    );
}
