//! Panel (c): estimated against true lightness L*.

use std::fmt::{self, Write as _};

use super::axes::{axes, ticks};
use super::svg::{Frame, MUTED, N, TITLE_C, clip_path, de, marker, no_data, panel_title, text};
use crate::eval::PatchResult;

pub(super) fn lightness(s: &mut String, patches: &[PatchResult]) -> fmt::Result {
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
