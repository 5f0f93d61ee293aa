//! Panel (b): true → estimated chromaticity in the CIE 1931 xy diagram, over the spectral
//! locus and the sRGB gamut.

use std::fmt::{self, Write as _};

use super::axes::{axes, ticks};
use super::svg::{
    AXIS, Frame, INK, N, TITLE_B, clip_path, marker, no_data, panel_title, text, text_width,
};
use crate::colour::{D65_WHITE_XYZ, SRGB_PRIMARIES_XY, Xyz};
use crate::eval::PatchResult;
use crate::spectral::cie1931_cmfs;

/// x, y of XYZ, when it has a positive finite sum.
pub(super) fn chroma(xyz: Xyz) -> Option<[f64; 2]> {
    let sum = xyz[0] + xyz[1] + xyz[2];
    let p = [xyz[0] / sum, xyz[1] / sum];
    (sum > 0.0 && p.iter().all(|v| v.is_finite())).then_some(p)
}

/// The spectral locus, 380–700 nm every 5 nm.
pub(super) fn spectral_locus() -> Vec<(usize, [f64; 2])> {
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
pub(super) type XyPair<'a> = (&'a PatchResult, Option<[f64; 2]>, Option<[f64; 2]>);

pub(super) fn chromaticity(s: &mut String, patches: &[PatchResult]) -> fmt::Result {
    panel_title(s, 420.0, 98.0, TITLE_B)?;
    let white = chroma(D65_WHITE_XYZ).unwrap_or([0.3127, 0.329]);
    let pts: Vec<XyPair> = patches
        .iter()
        .map(|p| (p, chroma(p.true_xyz), chroma(p.est_xyz)))
        .collect();
    let f = xy_frame(white, &pts);
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
    locus_and_gamut(s, &f, white)?;
    xy_points(s, &f, &pts)?;
    writeln!(s, "</g>")?;
    if pts.iter().all(|(_, t, _)| t.is_none()) {
        no_data(s, &f)?;
    }
    legend(s, &f)
}

/// The square window around the data (and the white point).
fn xy_frame(white: [f64; 2], pts: &[XyPair]) -> Frame {
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
    Frame {
        left: 474.0,
        top: 118.0,
        width: 292.0,
        height: 292.0,
        x: (c[0] - span / 2.0, c[0] + span / 2.0),
        y: (c[1] - span / 2.0, c[1] + span / 2.0),
    }
}

/// An SVG `points` list of xy chromaticities in the frame.
fn points_attr(f: &Frame, ps: impl Iterator<Item = [f64; 2]>) -> Result<String, fmt::Error> {
    let mut a = String::new();
    for p in ps {
        write!(a, "{},{} ", N(f.px(p[0])), N(f.py(p[1])))?;
    }
    Ok(a)
}

/// The spectral locus (closed by the purple line) with its wavelength labels, the sRGB
/// gamut and the D65 white point.
fn locus_and_gamut(s: &mut String, f: &Frame, white: [f64; 2]) -> fmt::Result {
    let locus = spectral_locus();
    let a = points_attr(f, locus.iter().map(|(_, p)| *p))?;
    writeln!(
        s,
        r##"<polygon class="spectral-locus" points="{}" fill="none" stroke="#9a9a9a" stroke-width="1.2"/>"##,
        a.trim_end()
    )?;
    for (nm, p) in &locus {
        if [460, 480, 490, 500, 520, 540, 560, 580, 600, 620].contains(nm) {
            locus_label(s, f, white, *nm, *p)?;
        }
    }
    let a = points_attr(f, SRGB_PRIMARIES_XY.iter().copied())?;
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
    )
}

/// A wavelength's dot on the locus and its label, outward from the white point.
fn locus_label(s: &mut String, f: &Frame, white: [f64; 2], nm: usize, p: [f64; 2]) -> fmt::Result {
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
    Ok(())
}

/// The error segments (true → estimated) under the markers, then the markers.
fn xy_points(s: &mut String, f: &Frame, pts: &[XyPair]) -> fmt::Result {
    // error segments under the markers
    writeln!(
        s,
        r#"<g class="xy-errors" stroke="{INK}" stroke-width="1.2">"#
    )?;
    for (_, t, e) in pts {
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
    for (p, t, e) in pts {
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
    Ok(())
}

/// The legend, under the plot.
fn legend(s: &mut String, f: &Frame) -> fmt::Result {
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
