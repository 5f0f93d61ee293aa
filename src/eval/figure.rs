//! An SVG figure of a ΔE report, in the spirit of Figure 5 of Germain et al., *Efficient
//! illuminant correction in the L3 method*: (a) the histogram of the per-patch ΔE2000 with its
//! mean and 90th percentile, (b) true → estimated chromaticity in the CIE 1931 xy diagram,
//! (c) estimated against true lightness L*, (d) true/estimated sRGB swatches of the worst
//! patches, under a header with the method, chart, illuminant and summary statistics.
//!
//! The SVG is written by hand: every number goes through a formatter that never prints a
//! non-finite value, and every string from the report is escaped for XML.

use std::fmt::{self, Write as _};

use super::{DeltaEReport, EvalError, PatchResult, summarize};
use crate::colour::{D65_WHITE_XYZ, SRGB_PRIMARIES_XY, Xyz, encode_srgb8, xyz_to_linear_srgb};
use crate::spectral::cie1931_cmfs;

/// Size of the figure in pixels.
const WIDTH: f64 = 1200.0;
const HEIGHT: f64 = 800.0;
/// How many of the worst chart samples panel (d) shows.
const WORST: usize = 12;
/// The panel titles (the tests and the service test look for them).
const TITLE_A: &str = "a. ΔE2000 distribution";
const TITLE_B: &str = "b. Chromaticity (CIE 1931 xy)";
const TITLE_C: &str = "c. Lightness L*: estimated vs true";
const TITLE_D: &str = "d. Worst patches: true | estimated (sRGB)";

const FONT: &str = "DejaVu Sans, Helvetica, Arial, sans-serif";
const INK: &str = "#222222";
const AXIS: &str = "#444444";
const GRID: &str = "#e6e6e6";
const MUTED: &str = "#666666";
const BAR: &str = "#4c78a8";
const MEAN: &str = "#d62728";
const P90: &str = "#e07b00";

/// The report as an SVG document (1200 × 800 px): histogram, chromaticity, lightness and the
/// swatches of the worst patches. The chart samples are the patches the report's summary is
/// over (every patch but the grey strip, or all patches when there are only greys). An empty
/// report gives a valid figure with empty panels; non-finite values are left out of the plots
/// and shown as "n/a".
pub fn report_svg(report: &DeltaEReport) -> Result<String, EvalError> {
    let mut s = String::with_capacity(64 * 1024);
    draw(&mut s, report)
        .map_err(|_| EvalError::Invalid("could not format the ΔE figure".into()))?;
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
    writeln!(s, r#"<?xml version="1.0" encoding="UTF-8"?>"#)?;
    writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="{FONT}" fill="{INK}">"#,
        w = N(WIDTH),
        h = N(HEIGHT),
    )?;
    writeln!(s, "<title>{}</title>", esc(&summary_title))?;
    writeln!(
        s,
        r##"<rect x="0" y="0" width="{}" height="{}" fill="#ffffff"/>"##,
        N(WIDTH),
        N(HEIGHT)
    )?;
    header(s, report, samples.len())?;
    histogram(s, &samples)?;
    chromaticity(s, &report.patches)?;
    lightness(s, &report.patches)?;
    swatches(s, &samples)?;
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

// ---------------------------------------------------------------- (a) histogram

fn histogram(s: &mut String, samples: &[&PatchResult]) -> fmt::Result {
    panel_title(s, 24.0, 98.0, TITLE_A)?;
    let values: Vec<f64> = samples
        .iter()
        .map(|p| p.delta_e)
        .filter(|v| v.is_finite() && *v >= 0.0)
        .collect();
    let stats = summarize(&values);
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
    for v in &values {
        let i = ((v / bw).floor() as usize).min(nbins - 1);
        counts[i] += 1;
    }
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
    writeln!(s, "</g>")?;
    if values.is_empty() {
        return no_data(s, &f);
    }
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
    let skipped = samples.len() - values.len();
    if skipped > 0 {
        let note = format!("{skipped} non-finite ΔE not shown");
        text(s, f.right(), f.top - 6.0, 11.0, "end", "", &note)?;
    }
    Ok(())
}

// ---------------------------------------------------------------- (b) chromaticity

/// x, y of XYZ, when it has a positive finite sum.
fn chroma(xyz: Xyz) -> Option<[f64; 2]> {
    let sum = xyz[0] + xyz[1] + xyz[2];
    let p = [xyz[0] / sum, xyz[1] / sum];
    (sum > 0.0 && p.iter().all(|v| v.is_finite())).then_some(p)
}

/// The spectral locus, 380–700 nm every 5 nm.
fn spectral_locus() -> Vec<(usize, [f64; 2])> {
    let [x, y, z] = cie1931_cmfs();
    let (x, y, z) = (x.values(), y.values(), z.values());
    (380usize..=700)
        .step_by(5)
        .filter_map(|nm| {
            let i = nm - 380;
            chroma([*x.get(i)?, *y.get(i)?, *z.get(i)?]).map(|p| (nm, p))
        })
        .collect()
}

/// A patch with its true and estimated chromaticity (when defined).
type XyPair<'a> = (&'a PatchResult, Option<[f64; 2]>, Option<[f64; 2]>);

fn chromaticity(s: &mut String, patches: &[PatchResult]) -> fmt::Result {
    panel_title(s, 420.0, 98.0, TITLE_B)?;
    let white = chroma(D65_WHITE_XYZ).unwrap_or([0.3127, 0.329]);
    let pts: Vec<XyPair> = patches
        .iter()
        .map(|p| (p, chroma(p.true_xyz), chroma(p.est_xyz)))
        .collect();
    // the square window around the data (and the white point)
    let (mut lo, mut hi) = (white, white);
    for q in pts.iter().flat_map(|(_, t, e)| [t, e]).flatten() {
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    for k in 0..2 {
        lo[k] = lo[k].max(-0.05);
        hi[k] = hi[k].min(0.95);
    }
    let span = ((hi[0] - lo[0]).max(hi[1] - lo[1]) * 1.12).max(0.08);
    let c = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let f = Frame {
        left: 474.0,
        top: 118.0,
        width: 292.0,
        height: 292.0,
        x: (c[0] - span / 2.0, c[0] + span / 2.0),
        y: (c[1] - span / 2.0, c[1] + span / 2.0),
    };
    axes(
        s,
        &f,
        &ticks(f.x.0, f.x.1, 5),
        &ticks(f.y.0, f.y.1, 5),
        "x",
        "y",
    )?;
    clip_path(s, "clip-xy", &f)?;
    writeln!(s, r#"<g clip-path="url(#clip-xy)">"#)?;
    // spectral locus (closed by the purple line) and sRGB gamut
    let locus = spectral_locus();
    let pts_attr = |ps: &mut dyn Iterator<Item = [f64; 2]>| -> Result<String, fmt::Error> {
        let mut a = String::new();
        for p in ps {
            write!(a, "{},{} ", N(f.px(p[0])), N(f.py(p[1])))?;
        }
        Ok(a)
    };
    let a = pts_attr(&mut locus.iter().map(|(_, p)| *p))?;
    writeln!(
        s,
        r##"<polygon class="spectral-locus" points="{}" fill="none" stroke="#9a9a9a" stroke-width="1.2"/>"##,
        a.trim_end()
    )?;
    for (nm, p) in &locus {
        if [460, 480, 490, 500, 520, 540, 560, 580, 600, 620].contains(nm) {
            // label outward from the white point
            let (dx, dy) = (p[0] - white[0], p[1] - white[1]);
            let len = (dx * dx + dy * dy).sqrt().max(1e-9);
            let (ox, oy) = (dx / len * 14.0, -dy / len * 14.0);
            let (x, y) = (f.px(p[0]), f.py(p[1]));
            writeln!(
                s,
                r##"<circle cx="{}" cy="{}" r="1.5" fill="#9a9a9a"/>"##,
                N(x),
                N(y)
            )?;
            let (tx, ty, label) = (x + ox, y + oy + 3.5, format!("{nm}"));
            let w = text_width(&label, 9.5);
            let (anchor, x0) = if ox < -3.0 {
                ("end", tx - w)
            } else if ox > 3.0 {
                ("start", tx)
            } else {
                ("middle", tx - w / 2.0)
            };
            // only labels that fit whole inside the plot
            if x0 >= f.left + 2.0
                && x0 + w <= f.right() - 2.0
                && ty - 9.0 >= f.top + 2.0
                && ty <= f.bottom() - 2.0
            {
                text(s, tx, ty, 9.5, anchor, r##"fill="#8a8a8a""##, &label)?;
            }
        }
    }
    let a = pts_attr(&mut SRGB_PRIMARIES_XY.iter().copied())?;
    writeln!(
        s,
        r##"<polygon class="srgb-gamut" points="{}" fill="none" stroke="#b8b8b8" stroke-width="1" stroke-dasharray="4 3"/>"##,
        a.trim_end()
    )?;
    // D65
    let (wx, wy) = (f.px(white[0]), f.py(white[1]));
    writeln!(
        s,
        r#"<path d="M{} {}h12M{} {}v12" stroke="{AXIS}" stroke-width="1.2"/>"#,
        N(wx - 6.0),
        N(wy),
        N(wx),
        N(wy - 6.0)
    )?;
    // error segments under the markers
    writeln!(
        s,
        r#"<g class="xy-errors" stroke="{INK}" stroke-width="1.2">"#
    )?;
    for (_, t, e) in &pts {
        if let (Some(t), Some(e)) = (t, e) {
            writeln!(
                s,
                r#"<line x1="{}" y1="{}" x2="{}" y2="{}"/>"#,
                N(f.px(t[0])),
                N(f.py(t[1])),
                N(f.px(e[0])),
                N(f.py(e[1]))
            )?;
        }
    }
    writeln!(s, "</g>")?;
    writeln!(s, r#"<g class="xy-points">"#)?;
    for (p, t, e) in &pts {
        if let Some(e) = e {
            writeln!(
                s,
                r#"<circle cx="{}" cy="{}" r="1.7" fill="{INK}"/>"#,
                N(f.px(e[0])),
                N(f.py(e[1]))
            )?;
        }
        if let Some(t) = t {
            marker(s, p, f.px(t[0]), f.py(t[1]), 3.6)?;
        }
    }
    writeln!(s, "</g>")?;
    writeln!(s, "</g>")?;
    if pts.iter().all(|(_, t, _)| t.is_none()) {
        no_data(s, &f)?;
    }
    // legend, under the plot
    let ly = f.bottom() + 52.0;
    let lx = f.left - 40.0;
    writeln!(
        s,
        r##"<circle cx="{}" cy="{}" r="4.2" fill="#c8a27a" stroke="{INK}" stroke-width="0.8"/>"##,
        N(lx),
        N(ly - 4.0)
    )?;
    writeln!(
        s,
        r#"<line x1="{}" y1="{y}" x2="{}" y2="{y}" stroke="{INK}" stroke-width="1"/><circle cx="{}" cy="{y}" r="1.7" fill="{INK}"/>"#,
        N(lx),
        N(lx + 22.0),
        N(lx + 22.0),
        y = N(ly - 4.0)
    )?;
    text(s, lx + 28.0, ly, 11.0, "start", "", "true → estimated")?;
    writeln!(
        s,
        r##"<rect x="{}" y="{}" width="8" height="8" fill="#b0b0b0" stroke="{INK}" stroke-width="0.8"/>"##,
        N(lx + 136.0),
        N(ly - 8.0)
    )?;
    text(s, lx + 148.0, ly, 11.0, "start", "", "grey strip")?;
    writeln!(
        s,
        r#"<path d="M{} {}h12M{} {}v12" stroke="{AXIS}" stroke-width="1.2"/>"#,
        N(lx + 220.0),
        N(ly - 4.0),
        N(lx + 226.0),
        N(ly - 10.0)
    )?;
    text(s, lx + 236.0, ly, 11.0, "start", "", "D65")?;
    writeln!(
        s,
        r##"<line x1="{}" y1="{y}" x2="{}" y2="{y}" stroke="#b8b8b8" stroke-width="1" stroke-dasharray="4 3"/>"##,
        N(lx + 272.0),
        N(lx + 292.0),
        y = N(ly - 4.0)
    )?;
    text(s, lx + 297.0, ly, 11.0, "start", "", "sRGB")
}

// ---------------------------------------------------------------- (c) lightness

fn lightness(s: &mut String, patches: &[PatchResult]) -> fmt::Result {
    panel_title(s, 820.0, 98.0, TITLE_C)?;
    let pairs: Vec<(&PatchResult, f64, f64)> = patches
        .iter()
        .filter(|p| p.true_lab[0].is_finite() && p.est_lab[0].is_finite())
        .map(|p| (p, p.true_lab[0], p.est_lab[0]))
        .collect();
    let (mut lo, mut hi) = (0.0f64, 100.0f64);
    for (_, t, e) in &pairs {
        lo = lo.min(*t).min(*e);
        hi = hi.max(*t).max(*e);
    }
    let lo = ((lo / 10.0).floor() * 10.0).max(-50.0);
    let hi = ((hi / 10.0).ceil() * 10.0).min(200.0);
    let f = Frame {
        left: 874.0,
        top: 118.0,
        width: 292.0,
        height: 292.0,
        // a margin so that markers at the ends (the white at 100) show whole
        x: (lo - 0.03 * (hi - lo), hi + 0.03 * (hi - lo)),
        y: (lo - 0.03 * (hi - lo), hi + 0.03 * (hi - lo)),
    };
    let t = ticks(lo, hi, 5);
    axes(s, &f, &t, &t, "true L*", "estimated L*")?;
    clip_path(s, "clip-l", &f)?;
    writeln!(s, r#"<g clip-path="url(#clip-l)">"#)?;
    writeln!(
        s,
        r#"<line class="identity" x1="{}" y1="{}" x2="{}" y2="{}" stroke="{MUTED}" stroke-width="1" stroke-dasharray="5 4"/>"#,
        N(f.px(f.x.0)),
        N(f.py(f.x.0)),
        N(f.px(f.x.1)),
        N(f.py(f.x.1))
    )?;
    writeln!(s, r#"<g class="lightness-points">"#)?;
    for (p, t, e) in &pairs {
        marker(s, p, f.px(*t), f.py(*e), 3.8)?;
    }
    writeln!(s, "</g>")?;
    writeln!(s, "</g>")?;
    if pairs.is_empty() {
        return no_data(s, &f);
    }
    let mean_abs = pairs.iter().map(|(_, t, e)| (e - t).abs()).sum::<f64>() / pairs.len() as f64;
    let bias = pairs.iter().map(|(_, t, e)| e - t).sum::<f64>() / pairs.len() as f64;
    text(
        s,
        f.left + 8.0,
        f.top + 17.0,
        11.5,
        "start",
        "",
        &format!("mean |ΔL*| {}", de(mean_abs)),
    )?;
    text(
        s,
        f.left + 8.0,
        f.top + 32.0,
        11.5,
        "start",
        "",
        &format!(
            "mean ΔL* {}{}",
            if bias >= 0.0 { "+" } else { "" },
            de(bias)
        ),
    )?;
    let ly = f.bottom() + 52.0;
    writeln!(
        s,
        r#"<line x1="{}" y1="{y}" x2="{}" y2="{y}" stroke="{MUTED}" stroke-width="1" stroke-dasharray="5 4"/>"#,
        N(f.left),
        N(f.left + 22.0),
        y = N(ly - 4.0)
    )?;
    text(
        s,
        f.left + 28.0,
        ly,
        11.0,
        "start",
        "",
        "identity (estimated = true)",
    )
}

// ---------------------------------------------------------------- (d) worst swatches

fn swatches(s: &mut String, samples: &[&PatchResult]) -> fmt::Result {
    let top = 494.0;
    writeln!(
        s,
        r#"<line x1="24" y1="{}" x2="{}" y2="{}" stroke="{GRID}" stroke-width="1"/>"#,
        N(top - 20.0),
        N(WIDTH - 24.0),
        N(top - 20.0)
    )?;
    let mut worst: Vec<&PatchResult> = samples.to_vec();
    // non-finite ΔE counts as the worst
    let key = |p: &PatchResult| {
        if p.delta_e.is_finite() {
            p.delta_e
        } else {
            f64::INFINITY
        }
    };
    worst.sort_by(|a, b| key(b).total_cmp(&key(a)));
    worst.truncate(WORST);
    panel_title(s, 24.0, top, TITLE_D)?;
    let sub = format!(
        "the {} chart samples with the largest ΔE2000, worst first; left square: ideal XYZ under D65, right: the rendering (white patch at Y = 1, clipped to the sRGB gamut)",
        worst.len()
    );
    text(
        s,
        24.0,
        top + 18.0,
        11.5,
        "start",
        &format!(r#"fill="{MUTED}""#),
        &sub,
    )?;
    if worst.is_empty() {
        return text(
            s,
            WIDTH / 2.0,
            top + 120.0,
            14.0,
            "middle",
            &format!(r#"fill="{MUTED}""#),
            "no chart samples",
        );
    }
    let (cols, cell_w, cell_h, sq, gap) = (6usize, 190.0, 140.0, 72.0, 4.0);
    let left = (WIDTH - cols as f64 * cell_w) / 2.0;
    for (i, p) in worst.iter().enumerate() {
        let (r, c) = (i / cols, i % cols);
        let x0 = left + c as f64 * cell_w + (cell_w - 2.0 * sq - gap) / 2.0;
        let y0 = top + 34.0 + r as f64 * cell_h;
        let cx = x0 + sq + gap / 2.0;
        writeln!(s, r#"<g class="swatch-pair" data-rank="{}">"#, i + 1)?;
        swatch(s, p.true_xyz, x0, y0, sq, "swatch true")?;
        swatch(s, p.est_xyz, x0 + sq + gap, y0, sq, "swatch estimated")?;
        let cap = format!(r#"fill="{MUTED}""#);
        text(
            s,
            x0 + sq / 2.0,
            y0 + sq + 13.0,
            10.0,
            "middle",
            &cap,
            "true",
        )?;
        text(
            s,
            x0 + 1.5 * sq + gap,
            y0 + sq + 13.0,
            10.0,
            "middle",
            &cap,
            "estimated",
        )?;
        let name = format!("{}. {}", i + 1, clip_chars(&p.name, 22));
        text(
            s,
            cx,
            y0 + sq + 30.0,
            12.5,
            "middle",
            r#"font-weight="bold""#,
            &name,
        )?;
        let detail = format!("ΔE {} · {}", de(p.delta_e), clip_chars(&p.category, 14));
        text(s, cx, y0 + sq + 45.0, 11.5, "middle", "", &detail)?;
        writeln!(s, "</g>")?;
    }
    Ok(())
}

/// One square filled with the sRGB colour of `xyz`, or crossed out when it has none.
fn swatch(s: &mut String, xyz: Xyz, x: f64, y: f64, size: f64, class: &str) -> fmt::Result {
    match srgb_hex(xyz) {
        Some(hex) => writeln!(
            s,
            r#"<rect class="{class}" x="{}" y="{}" width="{}" height="{}" fill="{hex}" stroke="{AXIS}" stroke-width="0.8"/>"#,
            N(x),
            N(y),
            N(size),
            N(size)
        ),
        None => writeln!(
            s,
            r##"<rect class="{class}" x="{x}" y="{y}" width="{w}" height="{w}" fill="#ffffff" stroke="{AXIS}" stroke-width="0.8"/><path d="M{x} {y}l{w} {w}M{x2} {y}l-{w} {w}" stroke="{MEAN}" stroke-width="1"/>"##,
            x = N(x),
            y = N(y),
            w = N(size),
            x2 = N(x + size),
        ),
    }
}

// ---------------------------------------------------------------- drawing helpers

/// A plot area and the data ranges it shows.
struct Frame {
    left: f64,
    top: f64,
    width: f64,
    height: f64,
    x: (f64, f64),
    y: (f64, f64),
}

impl Frame {
    fn right(&self) -> f64 {
        self.left + self.width
    }
    fn bottom(&self) -> f64 {
        self.top + self.height
    }
    fn px(&self, v: f64) -> f64 {
        self.left + unit(v, self.x) * self.width
    }
    fn py(&self, v: f64) -> f64 {
        self.bottom() - unit(v, self.y) * self.height
    }
}

/// Position of `v` in `range` (0–1 inside), bounded so that far-off or non-finite values
/// stay representable (the plots clip them).
fn unit(v: f64, (lo, hi): (f64, f64)) -> f64 {
    let u = (v - lo) / (hi - lo);
    if u.is_finite() {
        u.clamp(-4.0, 5.0)
    } else {
        0.0
    }
}

/// A coordinate or size in the SVG: one decimal; non-finite values print as 0.
struct N(f64);

impl fmt::Display for N {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = if self.0.is_finite() {
            self.0.clamp(-1e6, 1e6)
        } else {
            0.0
        };
        let r = (v * 10.0).round() / 10.0;
        if r == r.trunc() {
            write!(f, "{}", r as i64)
        } else {
            write!(f, "{r:.1}")
        }
    }
}

/// A ΔE (or L*) value for a label: two decimals, or "n/a".
fn de(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "n/a".into()
    }
}

/// Text escaped for XML character data and attribute values; characters XML 1.0 cannot
/// carry become U+FFFD.
fn esc(t: &str) -> String {
    let mut out = String::with_capacity(t.len());
    for ch in t.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            '\t' | '\n' | '\r' => out.push(' '),
            c if (c as u32) < 0x20 || c == '\u{fffe}' || c == '\u{ffff}' => out.push('\u{fffd}'),
            c => out.push(c),
        }
    }
    out
}

/// At most `max` characters, with an ellipsis when cut.
fn clip_chars(t: &str, max: usize) -> String {
    if t.chars().count() <= max {
        t.to_string()
    } else {
        let mut c: String = t.chars().take(max.saturating_sub(1)).collect();
        c.push('…');
        c
    }
}

/// A rough width of `t` in the figure's sans-serif font.
fn text_width(t: &str, size: f64) -> f64 {
    t.chars().count() as f64 * size * 0.6
}

/// A `<text>` element; `content` is escaped here.
fn text(
    s: &mut String,
    x: f64,
    y: f64,
    size: f64,
    anchor: &str,
    attrs: &str,
    content: &str,
) -> fmt::Result {
    let sep = if attrs.is_empty() { "" } else { " " };
    writeln!(
        s,
        r#"<text x="{}" y="{}" font-size="{}" text-anchor="{anchor}"{sep}{attrs}>{}</text>"#,
        N(x),
        N(y),
        N(size),
        esc(content)
    )
}

fn panel_title(s: &mut String, x: f64, y: f64, title: &str) -> fmt::Result {
    writeln!(
        s,
        r#"<text class="panel-title" x="{}" y="{}" font-size="15" font-weight="bold">{}</text>"#,
        N(x),
        N(y),
        esc(title)
    )
}

fn no_data(s: &mut String, f: &Frame) -> fmt::Result {
    text(
        s,
        f.left + f.width / 2.0,
        f.top + f.height / 2.0,
        14.0,
        "middle",
        &format!(r#"fill="{MUTED}""#),
        "no data",
    )
}

fn clip_path(s: &mut String, id: &str, f: &Frame) -> fmt::Result {
    writeln!(
        s,
        r#"<defs><clipPath id="{id}"><rect x="{}" y="{}" width="{}" height="{}"/></clipPath></defs>"#,
        N(f.left),
        N(f.top),
        N(f.width),
        N(f.height)
    )
}

/// A patch marker: a circle for a chart sample, a square for the grey strip, filled with the
/// patch's true colour.
fn marker(s: &mut String, p: &PatchResult, x: f64, y: f64, r: f64) -> fmt::Result {
    let fill = srgb_hex(p.true_xyz).unwrap_or_else(|| "#ffffff".into());
    if p.category == "grey" {
        writeln!(
            s,
            r#"<rect x="{}" y="{}" width="{w}" height="{w}" fill="{fill}" stroke="{INK}" stroke-width="0.8"/>"#,
            N(x - r),
            N(y - r),
            w = N(2.0 * r)
        )
    } else {
        writeln!(
            s,
            r#"<circle cx="{}" cy="{}" r="{}" fill="{fill}" stroke="{INK}" stroke-width="0.8"/>"#,
            N(x),
            N(y),
            N(r)
        )
    }
}

/// The frame, grid, ticks and axis titles of a plot.
fn axes(
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
fn nice_step(raw: f64) -> f64 {
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
fn nice_near(raw: f64) -> f64 {
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
fn nice_ceil(v: f64) -> f64 {
    let step = nice_step(v / 5.0);
    ((v / step).ceil() * step).max(step)
}

/// About `target` round ticks inside [lo, hi], and the decimals to print them with.
fn ticks(lo: f64, hi: f64, target: usize) -> (Vec<f64>, usize) {
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
fn ticks_int(hi: f64) -> (Vec<f64>, usize) {
    let step = nice_step(hi / 5.0).max(1.0).round();
    let n = (hi / step + 1e-9).floor().clamp(0.0, 100.0) as usize;
    ((0..=n).map(|k| k as f64 * step).collect(), 0)
}

/// `#rrggbb` of XYZ (white Y = 1) in sRGB, each channel clipped to [0, 1]; `None` for a
/// non-finite value.
fn srgb_hex(xyz: Xyz) -> Option<String> {
    if !xyz.iter().all(|v| v.is_finite()) {
        return None;
    }
    let [r, g, b] = xyz_to_linear_srgb(xyz).map(encode_srgb8);
    Some(format!("#{r:02x}{g:02x}{b:02x}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::{ciede2000, xyz_to_lab};
    use crate::eval::PixelStats;

    fn patch(name: &str, category: &str, t: Xyz, e: Xyz) -> PatchResult {
        let (tl, el) = (xyz_to_lab(t, D65_WHITE_XYZ), xyz_to_lab(e, D65_WHITE_XYZ));
        PatchResult {
            name: name.into(),
            category: category.into(),
            true_xyz: t,
            est_xyz: e,
            true_lab: tl,
            est_lab: el,
            delta_e: ciede2000(tl, el),
            pixel_delta_e: ciede2000(tl, el) * 1.5,
        }
    }

    fn report(patches: Vec<PatchResult>) -> DeltaEReport {
        let main: Vec<f64> = patches
            .iter()
            .filter(|p| p.category != "grey")
            .map(|p| p.delta_e)
            .collect();
        DeltaEReport {
            schema: crate::eval::REPORT_SCHEMA.into(),
            chart: "natural100".into(),
            acquisition_illuminant: "Tungsten".into(),
            method: "Baseline+T".into(),
            summary: summarize(&main),
            per_pixel: PixelStats {
                n: 1,
                mean: 2.0,
                p90: 3.0,
            },
            per_category: Default::default(),
            white_patch: "grey_95".into(),
            patches,
            context: serde_json::Value::Null,
        }
    }

    /// 30 coloured samples (ΔE growing with the index) and 5 greys (ΔE 20).
    fn sample_report() -> DeltaEReport {
        let mut ps = Vec::new();
        for i in 0..30 {
            let a = i as f64 / 30.0 * std::f64::consts::TAU;
            let t = [
                0.3 + 0.15 * a.cos(),
                0.3 + 0.1 * a.sin(),
                0.3 - 0.12 * a.cos(),
            ];
            let k = 1.0 + 0.004 * i as f64;
            let e = [t[0] * k, t[1], t[2] / k];
            let mut p = patch(&format!("obj{i:03}"), "Food", t, e);
            p.delta_e = 0.5 + 0.2 * i as f64;
            ps.push(p);
        }
        for g in 0..5 {
            let y = 0.1 + 0.2 * g as f64;
            let t = D65_WHITE_XYZ.map(|v| v * y);
            let mut p = patch(&format!("grey_{g}"), "grey", t, t.map(|v| v * 1.02));
            // larger than any sample's: the greys must still stay out of panel (d)
            p.delta_e = 20.0;
            ps.push(p);
        }
        report(ps)
    }

    /// A small well-formedness check: balanced, properly nested tags with one root, quoted
    /// attributes, no raw `<` or stray `&` in text or attribute values, and no non-finite
    /// numbers.
    fn assert_well_formed(svg: &str) {
        fn entity_ok(rest: &str) -> bool {
            let Some(end) = rest.find(';') else {
                return false;
            };
            let e = &rest[1..end];
            matches!(e, "amp" | "lt" | "gt" | "quot" | "apos")
                || e.strip_prefix("#x")
                    .is_some_and(|h| !h.is_empty() && h.chars().all(|c| c.is_ascii_hexdigit()))
                || e.strip_prefix('#')
                    .is_some_and(|d| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()))
        }
        fn check_chars(t: &str, what: &str) {
            for (i, c) in t.char_indices() {
                assert!(c != '<', "raw '<' in {what}: {t:?}");
                if c == '&' {
                    assert!(entity_ok(&t[i..]), "stray '&' in {what}: {t:?}");
                }
            }
        }
        let mut stack: Vec<String> = Vec::new();
        let mut roots = 0;
        let mut rest = svg;
        while let Some(lt) = rest.find('<') {
            let text = &rest[..lt];
            check_chars(text, "text");
            if stack.is_empty() {
                assert!(text.trim().is_empty(), "text outside the root: {text:?}");
            }
            rest = &rest[lt..];
            if let Some(r) = rest.strip_prefix("<?") {
                let end = r.find("?>").expect("unterminated declaration");
                rest = &r[end + 2..];
                continue;
            }
            if let Some(r) = rest.strip_prefix("<!--") {
                let end = r.find("-->").expect("unterminated comment");
                rest = &r[end + 3..];
                continue;
            }
            // a tag: scan to its '>' outside quotes
            let mut quote = None;
            let mut end = None;
            for (i, c) in rest.char_indices().skip(1) {
                match (quote, c) {
                    (None, '"' | '\'') => quote = Some(c),
                    (Some(q), c) if c == q => quote = None,
                    (None, '>') => {
                        end = Some(i);
                        break;
                    }
                    (None, '<') => panic!("'<' inside a tag: {}", &rest[..i]),
                    _ => {}
                }
            }
            let end = end.expect("unterminated tag");
            let tag = &rest[1..end];
            rest = &rest[end + 1..];
            if let Some(name) = tag.strip_prefix('/') {
                let open = stack.pop().expect("close tag without an open one");
                assert_eq!(open, name.trim(), "mismatched close tag");
                continue;
            }
            let self_closing = tag.ends_with('/');
            let body = tag.trim_end_matches('/');
            let name_end = body.find(|c: char| c.is_whitespace()).unwrap_or(body.len());
            let name = &body[..name_end];
            assert!(
                !name.is_empty()
                    && name
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == ':'),
                "bad tag name {name:?}"
            );
            // attributes: name="value" pairs
            let mut attrs = body[name_end..].trim();
            let mut seen = Vec::new();
            while !attrs.is_empty() {
                let eq = attrs.find('=').expect("attribute without a value");
                let an = attrs[..eq].trim();
                assert!(
                    !an.is_empty() && !an.contains(char::is_whitespace),
                    "bad attribute name {an:?} in <{name}>"
                );
                assert!(!seen.contains(&an), "duplicate attribute {an} in <{name}>");
                seen.push(an);
                let v = attrs[eq + 1..].trim_start();
                let q = v.chars().next().expect("attribute value");
                assert!(q == '"' || q == '\'', "unquoted attribute {an} in <{name}>");
                let close = v[1..].find(q).expect("unterminated attribute value");
                let value = &v[1..1 + close];
                check_chars(value, "attribute value");
                for bad in ["NaN", "inf"] {
                    assert!(!value.contains(bad), "non-finite {an}={value:?}");
                }
                attrs = v[close + 2..].trim_start();
            }
            if stack.is_empty() {
                roots += 1;
            }
            if !self_closing {
                stack.push(name.to_string());
            }
        }
        check_chars(rest, "text");
        assert!(rest.trim().is_empty(), "text after the root");
        assert!(stack.is_empty(), "unclosed tags: {stack:?}");
        assert_eq!(roots, 1, "one root element");
    }

    #[test]
    fn the_well_formedness_check_rejects_broken_documents() {
        assert_well_formed(
            r#"<?xml version="1.0"?><svg a="1"><g><text>a &amp; b</text></g><rect/></svg>"#,
        );
        for bad in [
            "<svg><g></svg>",
            "<svg></svg><svg></svg>",
            "<svg><text>a < b</text></svg>",
            "<svg><text>a & b</text></svg>",
            r#"<svg a="<"></svg>"#,
            r#"<svg a=1></svg>"#,
            r#"<svg x="NaN"></svg>"#,
            r#"<svg a="1" a="2"></svg>"#,
            "<svg>",
        ] {
            let r = std::panic::catch_unwind(|| assert_well_formed(bad));
            assert!(r.is_err(), "accepted {bad:?}");
        }
    }

    fn count(svg: &str, needle: &str) -> usize {
        svg.matches(needle).count()
    }

    #[test]
    fn figure_is_well_formed_with_the_four_panels() {
        let rep = sample_report();
        let svg = report_svg(&rep).unwrap();
        assert_well_formed(&svg);
        assert!(svg.contains(r#"<svg xmlns="http://www.w3.org/2000/svg""#));
        for t in [TITLE_A, TITLE_B, TITLE_C, TITLE_D] {
            assert!(svg.contains(&esc(t)), "panel title {t:?} missing");
        }
        assert_eq!(count(&svg, r#"class="panel-title""#), 4);
        // the header carries the summary
        assert!(svg.contains(&format!("mean {}", de(rep.summary.mean))));
        assert!(svg.contains(&format!("p90 {}", de(rep.summary.p90))));
        assert!(svg.contains("Baseline+T") && svg.contains("Tungsten"));
        // one marker per patch in (b) and (c): 30 circles and 5 grey squares each
        assert!(svg.contains(r#"class="spectral-locus""#));
        assert!(svg.contains(r#"class="identity""#));
    }

    #[test]
    fn one_swatch_pair_per_worst_chart_sample() {
        let rep = sample_report();
        let svg = report_svg(&rep).unwrap();
        assert_eq!(count(&svg, r#"class="swatch-pair""#), WORST);
        assert_eq!(count(&svg, r#"class="swatch true""#), WORST);
        assert_eq!(count(&svg, r#"class="swatch estimated""#), WORST);
        // the worst are the last samples (ΔE grows with the index), worst first; no grey
        let d = &svg[svg.find(r#"class="swatch-pair""#).unwrap()..];
        assert!(d.contains(">1. obj029<"), "worst first");
        assert!(d.contains(&format!(">{WORST}. obj0{}<", 30 - WORST)));
        assert!(!d.contains("grey_"));
        // fewer samples than WORST: one pair each
        let mut small = sample_report();
        small.patches.drain(5..30);
        let svg = report_svg(&small).unwrap();
        assert_well_formed(&svg);
        assert_eq!(count(&svg, r#"class="swatch-pair""#), 5);
    }

    #[test]
    fn hostile_text_is_escaped() {
        let mut rep = sample_report();
        rep.patches[29].name = r#"<&>"'x"#.into();
        rep.patches[29].category = "<script>".into();
        rep.method = r#"a<b & "c" </svg>"#.into();
        rep.chart = "]]><!--".into();
        rep.acquisition_illuminant = "\u{1}\u{7}bell".into();
        let svg = report_svg(&rep).unwrap();
        assert_well_formed(&svg);
        assert!(svg.contains("&lt;&amp;&gt;&quot;&apos;x"));
        assert!(svg.contains("a&lt;b &amp; &quot;c&quot; &lt;/svg&gt;"));
        assert!(!svg.contains("<&>"));
        assert!(!svg.contains("<script>"));
        assert!(!svg.contains("<!--"));
        assert!(!svg.contains('\u{1}'));
        assert_eq!(count(&svg, "</svg>"), 1);
    }

    #[test]
    fn empty_and_non_finite_reports_give_valid_figures() {
        let empty = report(Vec::new());
        let svg = report_svg(&empty).unwrap();
        assert_well_formed(&svg);
        for t in [TITLE_A, TITLE_B, TITLE_C, TITLE_D] {
            assert!(svg.contains(&esc(t)));
        }
        assert_eq!(count(&svg, r#"class="swatch-pair""#), 0);
        assert!(svg.contains("no chart samples"));

        let mut rep = sample_report();
        rep.patches[0].est_xyz = [f64::NAN, 1.0, f64::INFINITY];
        rep.patches[0].est_lab = [f64::NAN; 3];
        rep.patches[0].delta_e = f64::NAN;
        rep.patches[1].true_xyz = [f64::INFINITY, -1.0, 0.0];
        rep.patches[2].est_xyz = [1e300, -1e300, 1e300];
        rep.patches[2].delta_e = f64::INFINITY;
        rep.summary.mean = f64::NAN;
        rep.per_pixel.mean = f64::NEG_INFINITY;
        let svg = report_svg(&rep).unwrap();
        assert_well_formed(&svg);
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
        assert!(svg.contains("n/a"));
        // the non-finite ΔE counts among the worst
        assert_eq!(count(&svg, r#"class="swatch-pair""#), WORST);

        // only greys: they are the samples, as in the summary
        let mut greys = sample_report();
        greys.patches.drain(..30);
        let svg = report_svg(&greys).unwrap();
        assert_well_formed(&svg);
        assert_eq!(count(&svg, r#"class="swatch-pair""#), 5);
    }

    #[test]
    fn colours_ticks_and_numbers() {
        assert_eq!(srgb_hex(D65_WHITE_XYZ).as_deref(), Some("#ffffff"));
        assert_eq!(srgb_hex([0.0; 3]).as_deref(), Some("#000000"));
        // out of gamut clips; 18 % grey encodes to 118
        assert_eq!(srgb_hex([2.0, 2.0, 2.0]).as_deref(), Some("#ffffff"));
        assert_eq!(
            srgb_hex(D65_WHITE_XYZ.map(|v| v * 0.18)).as_deref(),
            Some("#767676")
        );
        assert_eq!(srgb_hex([f64::NAN, 0.0, 0.0]), None);
        assert_eq!(nice_step(0.587), 1.0);
        assert_eq!(nice_step(0.43), 0.5);
        assert_eq!(nice_step(f64::NAN), 1.0);
        assert_eq!(nice_near(0.55), 0.5);
        assert_eq!(nice_near(0.16), 0.2);
        let (t, d) = ticks(0.17, 0.62, 5);
        assert_eq!(d, 1);
        assert_eq!(t.len(), 5);
        for (v, want) in t.iter().zip([0.2, 0.3, 0.4, 0.5, 0.6]) {
            assert!((v - want).abs() < 1e-12, "{t:?}");
        }
        assert!(ticks(1.0, f64::NAN, 5).0.is_empty());
        assert_eq!(N(f64::NAN).to_string(), "0");
        assert_eq!(N(12.04).to_string(), "12");
        assert_eq!(N(-3.25).to_string(), "-3.3");
        assert_eq!(clip_chars("abcdef", 4), "abc…");
        assert_eq!(de(f64::INFINITY), "n/a");
    }
}
