//! Panel (d): true and estimated sRGB swatches of the worst chart samples.

use std::fmt::{self, Write as _};

use super::svg::{
    AXIS, GRID, MEAN, MUTED, N, TITLE_D, WIDTH, WORST, clip_chars, de, panel_title, srgb_hex, text,
};
use crate::colour::Xyz;
use crate::eval::PatchResult;

pub(super) fn swatches(s: &mut String, samples: &[&PatchResult]) -> fmt::Result {
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
pub(super) fn swatch(
    s: &mut String,
    xyz: Xyz,
    x: f64,
    y: f64,
    size: f64,
    class: &str,
) -> fmt::Result {
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
