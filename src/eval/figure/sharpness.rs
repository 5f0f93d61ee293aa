//! Panels (e) and (f), drawn when the report carries an [`EdgePanel`]: the SFR curves of the
//! ideal edge and of each method, with their MTF50 and false colour, and the crops of the edge
//! from each (PNG data URIs, magnified without smoothing).

use std::fmt::{self, Write as _};

use super::axes::{axes, ticks};
use super::svg::{
    Frame, MUTED, N, TITLE_E, TITLE_F, clip_path, de, esc, no_data, panel_title, text,
};
use crate::eval::{EdgeCurve, EdgePanel};

/// The height the two panels add below the figure.
pub(super) const PANEL_HEIGHT: f64 = 380.0;

/// The series colours: the ideal edge first (grey, dashed), then each method.
const COLOURS: [&str; 5] = ["#666666", "#1f77b4", "#d62728", "#2ca02c", "#9467bd"];

/// Both panels, their top at `top`.
pub(super) fn sharpness(s: &mut String, panel: &EdgePanel, top: f64) -> fmt::Result {
    writeln!(
        s,
        r#"<line x1="24" y1="{y}" x2="1176" y2="{y}" stroke="{MUTED}" stroke-width="0.5"/>"#,
        y = N(top - 8.0)
    )?;
    let curves: Vec<&EdgeCurve> = std::iter::once(&panel.ideal)
        .chain(panel.methods.iter())
        .collect();
    sfr_curves(s, &curves, top)?;
    crops(s, &curves, top)
}

/// (e): the SFR of each edge from 0 to Nyquist, with the MTF50 level.
fn sfr_curves(s: &mut String, curves: &[&EdgeCurve], top: f64) -> fmt::Result {
    panel_title(s, 24.0, top + 18.0, TITLE_E)?;
    let f = Frame {
        left: 84.0,
        top: top + 38.0,
        width: 440.0,
        height: 260.0,
        x: (0.0, 0.5),
        y: (0.0, 1.1),
    };
    axes(
        s,
        &f,
        &ticks(0.0, 0.5, 5),
        &ticks(0.0, 1.0, 5),
        "cycles per pixel",
        "SFR",
    )?;
    clip_path(s, "clip-sfr", &f)?;
    writeln!(s, r#"<g clip-path="url(#clip-sfr)">"#)?;
    writeln!(
        s,
        r#"<line x1="{}" y1="{y}" x2="{}" y2="{y}" stroke="{MUTED}" stroke-width="0.8" stroke-dasharray="2 3"/>"#,
        N(f.left),
        N(f.right()),
        y = N(f.py(0.5))
    )?;
    for (k, c) in curves.iter().enumerate() {
        if c.frequencies.is_empty() {
            continue;
        }
        let pts: Vec<String> = c
            .frequencies
            .iter()
            .zip(&c.sfr)
            .map(|(x, y)| format!("{},{}", N(f.px(*x)), N(f.py(*y))))
            .collect();
        let dash = if k == 0 {
            r#" stroke-dasharray="6 4""#
        } else {
            ""
        };
        writeln!(
            s,
            r#"<polyline class="sfr-curve" fill="none" stroke="{}" stroke-width="2"{dash} points="{}"/>"#,
            COLOURS[k % COLOURS.len()],
            pts.join(" ")
        )?;
    }
    writeln!(s, "</g>")?;
    if curves.iter().all(|c| c.frequencies.is_empty()) {
        no_data(s, &f)?;
    }
    // the legend: name, MTF50, false colour
    for (k, c) in curves.iter().enumerate() {
        let y = f.top + 16.0 + 17.0 * k as f64;
        let x = f.right() - 250.0;
        writeln!(
            s,
            r#"<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="{}" stroke-width="2"/>"#,
            N(x),
            N(y - 4.0),
            N(x + 18.0),
            N(y - 4.0),
            COLOURS[k % COLOURS.len()]
        )?;
        let fc = c
            .false_colour
            .map_or_else(String::new, |v| format!(", false colour {}", de(v)));
        let label = format!(
            "{}: MTF50 {}{fc}",
            super::svg::clip_chars(&c.name, 16),
            c.mtf50.map_or_else(|| "n/a".into(), |v| format!("{v:.3}"))
        );
        text(s, x + 24.0, y, 11.0, "start", "", &label)?;
    }
    Ok(())
}

/// (f): each edge's crop, magnified ×4 without smoothing, under its name.
fn crops(s: &mut String, curves: &[&EdgeCurve], top: f64) -> fmt::Result {
    panel_title(s, 600.0, top + 18.0, TITLE_F)?;
    let side = 160.0;
    for (k, c) in curves.iter().enumerate() {
        let (col, row) = (k % 3, k / 3);
        let x = 600.0 + col as f64 * (side + 24.0);
        let y = top + 38.0 + row as f64 * (side + 34.0);
        let scale = side / c.crop.width.max(c.crop.height).max(1) as f64;
        // the base64 alphabet needs no escaping; anything else is refused rather than drawn
        let clean = c
            .crop
            .png_base64
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"+/=".contains(&b));
        if clean {
            writeln!(
                s,
                r#"<image class="edge-crop" x="{}" y="{}" width="{}" height="{}" preserveAspectRatio="none" style="image-rendering:pixelated" href="data:image/png;base64,{}"/>"#,
                N(x),
                N(y),
                N(c.crop.width as f64 * scale),
                N(c.crop.height as f64 * scale),
                c.crop.png_base64
            )?;
        }
        writeln!(
            s,
            r#"<rect x="{}" y="{}" width="{}" height="{}" fill="none" stroke="{}" stroke-width="2"/>"#,
            N(x),
            N(y),
            N(c.crop.width as f64 * scale),
            N(c.crop.height as f64 * scale),
            COLOURS[k % COLOURS.len()]
        )?;
        writeln!(
            s,
            r#"<text x="{}" y="{}" font-size="12" text-anchor="middle">{}</text>"#,
            N(x + side / 2.0),
            N(y + side + 16.0),
            esc(&super::svg::clip_chars(&c.name, 24))
        )?;
    }
    Ok(())
}
