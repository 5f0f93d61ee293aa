//! The figure of a ColorChecker report (1200 × 660): (a) the chart as captured, each patch
//! split into the reference (left half) and the rendering (right half) with its ΔE2000, and
//! (b) the ΔE2000 per patch as bars, with the mean, the 90th percentile and, per patch, the
//! ΔE2000 between the two references (how much of the error the reference alone explains).

use std::fmt::{self, Write as _};

use super::axes::{nice_ceil, ticks};
use super::svg::{
    AXIS, FONT, GRID, INK, MEAN, MUTED, N, P90, clip_chars, de, esc, panel_title, srgb_hex, text,
};
use crate::colour::Xyz;
use crate::eval::colorchecker::{ColorCheckerPatch, ColorCheckerReport};

const W: f64 = 1200.0;
const H: f64 = 660.0;
/// The panel titles (the tests look for them).
pub(super) const CC_TITLE_A: &str = "a. Reference | rendered, per patch";
pub(super) const CC_TITLE_B: &str = "b. ΔE2000 per patch";
/// The references' difference marker.
const REF_MARK: &str = "#7a7a7a";

pub(super) fn draw_colorchecker(s: &mut String, r: &ColorCheckerReport) -> fmt::Result {
    let title = format!(
        "ColorChecker: {} under {}",
        clip_chars(&r.method, 60),
        clip_chars(&r.acquisition_illuminant, 24)
    );
    writeln!(s, r#"<?xml version="1.0" encoding="UTF-8"?>"#)?;
    writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="{FONT}" fill="{INK}">"#,
        w = N(W),
        h = N(H)
    )?;
    writeln!(s, "<title>{}</title>", esc(&title))?;
    writeln!(
        s,
        r##"<rect x="0" y="0" width="{}" height="{}" fill="#ffffff"/>"##,
        N(W),
        N(H)
    )?;
    text(
        s,
        24.0,
        32.0,
        19.0,
        "start",
        r#"font-weight="bold""#,
        &title,
    )?;
    let sm = &r.summary;
    let line = format!(
        "{} patches · ΔE2000 mean {}, median {}, p90 {}, max {} · the references differ by {} on average (max {})",
        sm.n,
        de(sm.mean),
        de(sm.median),
        de(sm.p90),
        de(sm.max),
        de(r.references.mean),
        de(r.references.max),
    );
    text(s, 24.0, 56.0, 14.0, "start", "", &line)?;
    let measured;
    let reference = match r.reference.as_str() {
        "xrite2014" => "X-Rite 2014 (ICC D50, adapted to D65 by Bradford)",
        "iset" => "ISET's Macbeth reflectances under D65",
        _ => {
            measured = r.reference_description.clone();
            &measured
        }
    };
    let note = format!(
        "reference: {reference} · exposure: the rendering scaled ×{} so that {} has Y {}",
        sig(r.normalisation.scale),
        r.normalisation.patch,
        sig(r.normalisation.reference_y),
    );
    text(
        s,
        24.0,
        76.0,
        11.5,
        "start",
        &format!(r#"fill="{MUTED}""#),
        &note,
    )?;
    writeln!(
        s,
        r#"<line x1="24" y1="90" x2="{}" y2="90" stroke="{GRID}" stroke-width="1"/>"#,
        N(W - 24.0)
    )?;
    chart(s, &r.patches)?;
    bars(s, r)?;
    writeln!(s, "</svg>")
}

fn sig(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        "n/a".into()
    }
}

fn fill(xyz: Xyz) -> String {
    srgb_hex(xyz).unwrap_or_else(|| "#ffffff".into())
}

/// Panel (a): the 6 × 4 chart on its black card.
fn chart(s: &mut String, patches: &[ColorCheckerPatch]) -> fmt::Result {
    let (left, top) = (24.0, 122.0);
    panel_title(s, left, top - 10.0, CC_TITLE_A)?;
    let (cell, gap, pad) = (94.0, 8.0, 12.0);
    let (cw, ch) = (6.0 * cell + 5.0 * gap, 4.0 * cell + 3.0 * gap);
    writeln!(
        s,
        r##"<rect x="{}" y="{}" width="{}" height="{}" rx="6" fill="#1b1b1b"/>"##,
        N(left),
        N(top),
        N(cw + 2.0 * pad),
        N(ch + 2.0 * pad)
    )?;
    for p in patches {
        let k = p.index.saturating_sub(1);
        let x = left + pad + (k % 6) as f64 * (cell + gap);
        let y = top + pad + (k / 6) as f64 * (cell + gap);
        writeln!(s, r#"<g class="cc-patch" data-index="{}">"#, p.index)?;
        writeln!(
            s,
            r#"<rect class="reference" x="{}" y="{}" width="{}" height="{}" fill="{}"/><rect class="rendered" x="{}" y="{}" width="{}" height="{}" fill="{}"/>"#,
            N(x),
            N(y),
            N(cell / 2.0),
            N(cell),
            fill(p.reference_xyz),
            N(x + cell / 2.0),
            N(y),
            N(cell / 2.0),
            N(cell),
            fill(p.rendered_xyz)
        )?;
        // text dark on light patches, light on dark ones
        let ink = |lab_l: f64| if lab_l > 58.0 { "#111111" } else { "#f4f4f4" };
        let label = format!(r#"fill="{}""#, ink(p.reference_lab[0]));
        text(
            s,
            x + 5.0,
            y + 13.0,
            10.5,
            "start",
            &label,
            &p.index.to_string(),
        )?;
        let badge = format!(r#"fill="{}" font-weight="bold""#, ink(p.rendered_lab[0]));
        text(
            s,
            x + cell - 5.0,
            y + cell - 7.0,
            12.0,
            "end",
            &badge,
            &de(p.delta_e),
        )?;
        writeln!(s, "</g>")?;
    }
    let below = top + ch + 2.0 * pad;
    let cap = format!(r#"fill="{MUTED}""#);
    text(
        s,
        left,
        below + 20.0,
        11.5,
        "start",
        &cap,
        "each patch: left half the reference, right half the rendering (sRGB, clipped to its gamut); number: ΔE2000",
    )?;
    let names: Vec<String> = patches
        .iter()
        .map(|p| format!("{} {}", p.index, p.name))
        .collect();
    for (row, chunk) in names.chunks(6).enumerate() {
        text(
            s,
            left,
            below + 40.0 + row as f64 * 15.0,
            10.5,
            "start",
            &cap,
            &chunk.join(" · "),
        )?;
    }
    Ok(())
}

/// Panel (b)'s value axis: ΔE2000 from 0 to `xmax` over `width` pixels from `left`.
struct BarAxis {
    left: f64,
    width: f64,
    xmax: f64,
}

impl BarAxis {
    /// The x of ΔE `v` (0 for a value that is not finite).
    fn px(&self, v: f64) -> f64 {
        let v = if v.is_finite() { v } else { 0.0 };
        self.left + (v / self.xmax).clamp(0.0, 1.0) * self.width
    }
}

/// Panel (b): one horizontal bar per patch, in the patch's reference colour.
fn bars(s: &mut String, r: &ColorCheckerReport) -> fmt::Result {
    let (left, top, width) = (820.0, 122.0, 330.0);
    panel_title(s, 680.0, top - 10.0, CC_TITLE_B)?;
    let row_h = 17.0;
    let height = 24.0 * row_h;
    let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
    let top_v = r
        .patches
        .iter()
        .flat_map(|p| [finite(p.delta_e), finite(p.references_delta_e)])
        .fold(1.0f64, f64::max);
    let axis = BarAxis {
        left,
        width,
        xmax: nice_ceil(top_v * 1.08),
    };
    let (tk, dec) = ticks(0.0, axis.xmax, 5);
    for v in &tk {
        writeln!(
            s,
            r#"<line x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="{GRID}"/>"#,
            N(top),
            N(top + height),
            x = N(axis.px(*v))
        )?;
        text(
            s,
            axis.px(*v),
            top + height + 16.0,
            11.0,
            "middle",
            "",
            &format!("{v:.dec$}"),
        )?;
    }
    text(
        s,
        left + width / 2.0,
        top + height + 34.0,
        12.5,
        "middle",
        "",
        "ΔE2000",
    )?;
    for (i, p) in r.patches.iter().enumerate() {
        bar_row(s, p, &axis, top + i as f64 * row_h, row_h)?;
    }
    writeln!(
        s,
        r#"<line x1="{l}" y1="{t}" x2="{l}" y2="{b}" stroke="{AXIS}"/>"#,
        l = N(left),
        t = N(top),
        b = N(top + height)
    )?;
    bar_legend(s, r, &axis, top, height)
}

/// One patch's bar in panel (b), its row's top at `y`.
fn bar_row(
    s: &mut String,
    p: &ColorCheckerPatch,
    axis: &BarAxis,
    y: f64,
    row_h: f64,
) -> fmt::Result {
    writeln!(s, r#"<g class="cc-bar" data-index="{}">"#, p.index)?;
    text(
        s,
        axis.left - 8.0,
        y + row_h - 5.0,
        11.0,
        "end",
        "",
        &format!("{} {}", p.index, clip_chars(&p.name, 17)),
    )?;
    writeln!(
        s,
        r#"<rect x="{}" y="{}" width="{}" height="{}" fill="{}" stroke="{AXIS}" stroke-width="0.6"/>"#,
        N(axis.left),
        N(y + 2.5),
        N(axis.px(p.delta_e) - axis.left),
        N(row_h - 5.0),
        fill(p.reference_xyz)
    )?;
    let m = axis.px(p.references_delta_e);
    writeln!(
        s,
        r#"<path class="references" d="M{} {}l4 4l-4 4l-4 -4z" fill="{REF_MARK}"/>"#,
        N(m),
        N(y + row_h / 2.0 - 4.0)
    )?;
    text(
        s,
        axis.px(p.delta_e).max(m + 4.0) + 6.0,
        y + row_h - 5.0,
        10.5,
        "start",
        "",
        &de(p.delta_e),
    )?;
    writeln!(s, "</g>")
}

/// Panel (b)'s mean and p90 lines over the bars (`top`, `height`), and the key to the
/// references' marks below them.
fn bar_legend(
    s: &mut String,
    r: &ColorCheckerReport,
    axis: &BarAxis,
    top: f64,
    height: f64,
) -> fmt::Result {
    for (v, colour, name) in [(r.summary.mean, MEAN, "mean"), (r.summary.p90, P90, "p90")] {
        if !v.is_finite() {
            continue;
        }
        writeln!(
            s,
            r#"<line x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="{colour}" stroke-width="1.5" stroke-dasharray="5 3"/>"#,
            N(top - 4.0),
            N(top + height),
            x = N(axis.px(v))
        )?;
        text(
            s,
            axis.px(v),
            top + height + 50.0 + if name == "p90" { 14.0 } else { 0.0 },
            11.0,
            "middle",
            &format!(r#"fill="{colour}""#),
            &format!("{name} {}", de(v)),
        )?;
    }
    let ly = top + height + 84.0;
    writeln!(
        s,
        r#"<path d="M{} {}l4 4l-4 4l-4 -4z" fill="{REF_MARK}"/>"#,
        N(680.0 + 4.0),
        N(ly - 8.0)
    )?;
    text(
        s,
        680.0 + 14.0,
        ly,
        11.5,
        "start",
        &format!(r#"fill="{MUTED}""#),
        &format!(
            "ΔE2000 between the two references ({})",
            r.references_label()
        ),
    )
}
