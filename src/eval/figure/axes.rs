//! Plot axes: the frame, grid and ticks of a panel, and round tick steps.

use std::fmt::{self, Write as _};

use super::svg::{AXIS, Frame, GRID, N, esc, text};

/// The frame, grid, ticks and axis titles of a plot.
pub(super) fn axes(
    s: &mut String,
    f: &Frame,
    xt: &(Vec<f64>, usize),
    yt: &(Vec<f64>, usize),
    xlabel: &str,
    ylabel: &str,
) -> fmt::Result {
    writeln!(s, r#"<g class="axes" stroke-width="1">"#)?;
    for &v in &xt.0 {
        let x = f.px(v);
        writeln!(
            s,
            r#"<line x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="{GRID}"/><line x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="{AXIS}"/>"#,
            N(f.top),
            N(f.bottom()),
            N(f.bottom()),
            N(f.bottom() + 5.0),
            x = N(x)
        )?;
        text(
            s,
            x,
            f.bottom() + 18.0,
            11.0,
            "middle",
            "",
            &format!("{:.*}", xt.1, v),
        )?;
    }
    for &v in &yt.0 {
        let y = f.py(v);
        writeln!(
            s,
            r#"<line x1="{}" y1="{y}" x2="{}" y2="{y}" stroke="{GRID}"/><line x1="{}" y1="{y}" x2="{}" y2="{y}" stroke="{AXIS}"/>"#,
            N(f.left),
            N(f.right()),
            N(f.left - 5.0),
            N(f.left),
            y = N(y)
        )?;
        text(
            s,
            f.left - 8.0,
            y + 4.0,
            11.0,
            "end",
            "",
            &format!("{:.*}", yt.1, v),
        )?;
    }
    writeln!(
        s,
        r#"<rect x="{}" y="{}" width="{}" height="{}" fill="none" stroke="{AXIS}"/>"#,
        N(f.left),
        N(f.top),
        N(f.width),
        N(f.height)
    )?;
    writeln!(s, "</g>")?;
    text(
        s,
        f.left + f.width / 2.0,
        f.bottom() + 36.0,
        12.5,
        "middle",
        "",
        xlabel,
    )?;
    let (yx, yy) = (f.left - 46.0, f.top + f.height / 2.0);
    writeln!(
        s,
        r#"<text x="{x}" y="{y}" font-size="12.5" text-anchor="middle" transform="rotate(-90 {x} {y})">{}</text>"#,
        esc(ylabel),
        x = N(yx),
        y = N(yy)
    )
}

/// A round step near `raw`: 1, 2 or 5 × 10ⁿ.
pub(super) fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let e = 10f64.powf(raw.log10().floor());
    let m = raw / e;
    let n = if m <= 1.0 {
        1.0
    } else if m <= 2.0 {
        2.0
    } else if m <= 5.0 {
        5.0
    } else {
        10.0
    };
    n * e
}

/// The 1, 2 or 5 × 10ⁿ nearest to `raw` (in ratio).
pub(super) fn nice_near(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let e = 10f64.powf(raw.log10().floor());
    let m = raw / e;
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .min_by(|a: &f64, b: &f64| (m / a).ln().abs().total_cmp(&(m / b).ln().abs()))
        .unwrap_or(1.0)
        * e
}

/// The smallest 1, 2 or 5 × 10ⁿ multiple-of-step bound at or above `v`.
pub(super) fn nice_ceil(v: f64) -> f64 {
    let step = nice_step(v / 5.0);
    ((v / step).ceil() * step).max(step)
}

/// About `target` round ticks inside [lo, hi], and the decimals to print them with.
pub(super) fn ticks(lo: f64, hi: f64, target: usize) -> (Vec<f64>, usize) {
    if !(lo.is_finite() && hi.is_finite() && hi > lo) {
        return (Vec::new(), 0);
    }
    let step = nice_step((hi - lo) / target.max(1) as f64);
    let decimals = (-step.log10().floor()).clamp(0.0, 6.0) as usize;
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    let v = (first..=last)
        .take(100)
        .map(|k| k as f64 * step)
        .map(|v| if v.abs() < step * 1e-9 { 0.0 } else { v })
        .collect();
    (v, decimals)
}

/// Integer ticks from 0 to `hi`.
pub(super) fn ticks_int(hi: f64) -> (Vec<f64>, usize) {
    let step = nice_step(hi / 5.0).max(1.0).round();
    let n = (hi / step + 1e-9).floor().clamp(0.0, 100.0) as usize;
    ((0..=n).map(|k| k as f64 * step).collect(), 0)
}
