//! Panel (a): the histogram of the per-patch ΔE2000 with its mean and 90th percentile.

use std::fmt::{self, Write as _};

use super::axes::{axes, nice_ceil, nice_near, ticks, ticks_int};
use super::svg::{BAR, Frame, MEAN, N, P90, TITLE_A, de, no_data, panel_title, text, text_width};
use crate::eval::{ErrorStats, PatchResult, summarize};

pub(super) fn histogram(s: &mut String, samples: &[&PatchResult]) -> fmt::Result {
    panel_title(s, 24.0, 98.0, TITLE_A)?;
    let values: Vec<f64> = samples
        .iter()
        .map(|p| p.delta_e)
        .filter(|v| v.is_finite() && *v >= 0.0)
        .collect();
    let stats = summarize(&values);
    let (bw, counts) = bins(&values, &stats);
    let nbins = counts.len();
    let cmax = counts.iter().copied().max().unwrap_or(0);
    // head room for the mean / p90 labels
    let ymax = nice_ceil((cmax as f64 * 1.25).max(4.0));
    let f = Frame {
        left: 84.0,
        top: 118.0,
        width: 292.0,
        height: 292.0,
        x: (0.0, nbins as f64 * bw),
        y: (0.0, ymax),
    };
    axes(
        s,
        &f,
        &ticks(f.x.0, f.x.1, 6),
        &ticks_int(ymax),
        "ΔE2000 per patch",
        "patches",
    )?;
    bars(s, &f, bw, &counts)?;
    if values.is_empty() {
        return no_data(s, &f);
    }
    marks(s, &f, &stats)?;
    let skipped = samples.len() - values.len();
    if skipped > 0 {
        let note = format!("{skipped} non-finite ΔE not shown");
        text(s, f.right(), f.top - 6.0, 11.0, "end", "", &note)?;
    }
    Ok(())
}

/// The bin width (a round step) and the count in each bin.
fn bins(values: &[f64], stats: &ErrorStats) -> (f64, Vec<usize>) {
    let top = values
        .iter()
        .copied()
        .fold(0.0f64, f64::max)
        .max(stats.p90)
        .max(stats.mean);
    let target_bins = ((values.len() as f64).sqrt() * 1.6)
        .round()
        .clamp(6.0, 24.0);
    let bw = if top > 0.0 {
        nice_near(top / target_bins)
    } else {
        0.5
    };
    let nbins = ((top / bw).ceil() as usize).clamp(1, 200);
    let mut counts = vec![0usize; nbins];
    for v in values {
        let i = ((v / bw).floor() as usize).min(nbins - 1);
        counts[i] += 1;
    }
    (bw, counts)
}

/// One bar per non-empty bin.
fn bars(s: &mut String, f: &Frame, bw: f64, counts: &[usize]) -> fmt::Result {
    writeln!(s, r#"<g class="histogram">"#)?;
    for (i, &c) in counts.iter().enumerate() {
        if c == 0 {
            continue;
        }
        let x0 = f.px(i as f64 * bw);
        let x1 = f.px((i + 1) as f64 * bw);
        let y = f.py(c as f64);
        writeln!(
            s,
            r##"<rect x="{}" y="{}" width="{}" height="{}" fill="{BAR}" stroke="#ffffff" stroke-width="0.8"/>"##,
            N(x0),
            N(y),
            N((x1 - x0).max(0.0)),
            N((f.bottom() - y).max(0.0))
        )?;
    }
    writeln!(s, "</g>")
}

/// The mean and p90 lines with their labels.
fn marks(s: &mut String, f: &Frame, stats: &ErrorStats) -> fmt::Result {
    let marks = [
        (stats.mean, format!("mean {}", de(stats.mean)), MEAN, ""),
        (
            stats.p90,
            format!("p90 {}", de(stats.p90)),
            P90,
            r#" stroke-dasharray="6 4""#,
        ),
    ];
    for (row, (v, label, colour, dash)) in marks.iter().enumerate() {
        let x = f.px(*v);
        writeln!(
            s,
            r#"<line x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="{colour}" stroke-width="2"{dash}/>"#,
            N(f.bottom()),
            N(f.top),
            x = N(x),
        )?;
        let y = f.top + 16.0 + 17.0 * row as f64;
        let w = text_width(label, 12.0);
        let (lx, anchor) = if x + 5.0 + w <= f.right() - 2.0 {
            (x + 5.0, "start")
        } else {
            (x - 5.0, "end")
        };
        let attrs = format!(r#"fill="{colour}" font-weight="bold""#);
        text(s, lx, y, 12.0, anchor, &attrs, label)?;
    }
    Ok(())
}
