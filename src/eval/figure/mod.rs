//! An SVG figure of a ΔE report, in the spirit of Figure 5 of Germain et al., *Efficient
//! illuminant correction in the L3 method*: (a) the histogram of the per-patch ΔE2000 with its
//! mean and 90th percentile, (b) true → estimated chromaticity in the CIE 1931 xy diagram,
//! (c) estimated against true lightness L*, (d) true/estimated sRGB swatches of the worst
//! patches, under a header with the method, chart, illuminant and summary statistics.
//!
//! The SVG is written by hand: every number goes through a formatter that never prints a
//! non-finite value, and every string from the report is escaped for XML.

mod axes;
mod chromaticity;
mod colorchecker;
mod histogram;
mod lightness;
mod sharpness;
mod svg;
mod swatches;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod well_formed;

use std::fmt::{self, Write as _};

use crate::eval::{DeltaEReport, EvalError, PatchResult};
use chromaticity::chromaticity;
use histogram::histogram;
use lightness::lightness;
use svg::{FONT, GRID, HEIGHT, INK, N, WIDTH, clip_chars, de, esc, text};
use swatches::swatches;

/// The report as an SVG document (1200 × 800 px): histogram, chromaticity, lightness and the
/// swatches of the worst patches; with an edge panel ([`DeltaEReport::edge_panel`]), 1200 ×
/// 1180 with the SFR curves and the edge crops below. The chart samples are the patches the report's summary is
/// over (every patch but the grey strip, or all patches when there are only greys). An empty
/// report gives a valid figure with empty panels; non-finite values are left out of the plots
/// and shown as "n/a".
pub fn report_svg(report: &DeltaEReport) -> Result<String, EvalError> {
    let mut s = String::with_capacity(64 * 1024);
    draw(&mut s, report)
        .map_err(|_| EvalError::Invalid("could not format the ΔE figure".into()))?;
    Ok(s)
}

/// The figure of a ColorChecker report (1200 × 660): the chart with each patch split into
/// reference and rendering, and the ΔE2000 per patch as bars beside the references' own
/// difference.
pub fn colorchecker_svg(
    report: &crate::eval::colorchecker::ColorCheckerReport,
) -> Result<String, EvalError> {
    let mut s = String::with_capacity(48 * 1024);
    colorchecker::draw_colorchecker(&mut s, report)
        .map_err(|_| EvalError::Invalid("could not format the ColorChecker figure".into()))?;
    Ok(s)
}

/// The patches the report's summary is over (as in `evaluate_chart`).
fn chart_samples(report: &DeltaEReport) -> Vec<&PatchResult> {
    let main: Vec<&PatchResult> = report
        .patches
        .iter()
        .filter(|p| p.category != "grey")
        .collect();
    if main.is_empty() {
        report.patches.iter().collect()
    } else {
        main
    }
}

fn draw(s: &mut String, report: &DeltaEReport) -> fmt::Result {
    let samples = chart_samples(report);
    let summary_title = format!(
        "ΔE2000 evaluation of {} on {} under {}",
        report.method, report.chart, report.acquisition_illuminant
    );
    let height = HEIGHT
        + report
            .edge_panel
            .as_ref()
            .map_or(0.0, |_| sharpness::PANEL_HEIGHT);
    writeln!(s, r#"<?xml version="1.0" encoding="UTF-8"?>"#)?;
    writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="{FONT}" fill="{INK}">"#,
        w = N(WIDTH),
        h = N(height),
    )?;
    writeln!(s, "<title>{}</title>", esc(&summary_title))?;
    writeln!(
        s,
        r##"<rect x="0" y="0" width="{}" height="{}" fill="#ffffff"/>"##,
        N(WIDTH),
        N(height)
    )?;
    header(s, report, samples.len())?;
    histogram(s, &samples)?;
    chromaticity(s, &report.patches)?;
    lightness(s, &report.patches)?;
    swatches(s, &samples)?;
    if let Some(panel) = &report.edge_panel {
        sharpness::sharpness(s, panel, HEIGHT)?;
    }
    writeln!(s, "</svg>")
}

// ---------------------------------------------------------------- header

fn header(s: &mut String, report: &DeltaEReport, n_samples: usize) -> fmt::Result {
    let title = format!(
        "ΔE2000 evaluation: {} on {}, acquired under {}",
        clip_chars(&report.method, 48),
        clip_chars(&report.chart, 24),
        clip_chars(&report.acquisition_illuminant, 24)
    );
    text(
        s,
        24.0,
        32.0,
        19.0,
        "start",
        r#"font-weight="bold""#,
        &title,
    )?;
    let sm = &report.summary;
    let grey = report.patches.len().saturating_sub(n_samples);
    let excluded = if grey > 0 {
        format!(" (grey strip of {grey} excluded)")
    } else {
        String::new()
    };
    let line = format!(
        "{} chart samples{excluded} · ΔE2000 mean {}, median {}, p90 {}, max {} · per-pixel mean {}",
        sm.n,
        de(sm.mean),
        de(sm.median),
        de(sm.p90),
        de(sm.max),
        de(report.per_pixel.mean),
    );
    text(s, 24.0, 56.0, 14.0, "start", "", &line)?;
    writeln!(
        s,
        r#"<line x1="24" y1="70" x2="{}" y2="70" stroke="{GRID}" stroke-width="1"/>"#,
        N(WIDTH - 24.0)
    )
}
