//! The figure's size, colours and panel titles, and the SVG primitives every panel draws
//! with: numbers that never print a non-finite value, XML-escaped text, the plot frame and
//! the patch markers.

use std::fmt::{self, Write as _};

use crate::colour::{Xyz, encode_srgb8, xyz_to_linear_srgb};
use crate::eval::PatchResult;

/// Size of the figure in pixels.
pub(super) const WIDTH: f64 = 1200.0;
pub(super) const HEIGHT: f64 = 800.0;
/// How many of the worst chart samples panel (d) shows.
pub(super) const WORST: usize = 12;
/// The panel titles (the tests and the service test look for them).
pub(super) const TITLE_A: &str = "a. ΔE2000 distribution";
pub(super) const TITLE_B: &str = "b. Chromaticity (CIE 1931 xy)";
pub(super) const TITLE_C: &str = "c. Lightness L*: estimated vs true";
pub(super) const TITLE_D: &str = "d. Worst patches: true | estimated (sRGB)";
pub(super) const TITLE_E: &str = "e. Sharpness: SFR of the slanted edge";
pub(super) const TITLE_F: &str = "f. The edge: ideal image and renders (×4)";

pub(super) const FONT: &str = "DejaVu Sans, Helvetica, Arial, sans-serif";
pub(super) const INK: &str = "#222222";
pub(super) const AXIS: &str = "#444444";
pub(super) const GRID: &str = "#e6e6e6";
pub(super) const MUTED: &str = "#666666";
pub(super) const BAR: &str = "#4c78a8";
pub(super) const MEAN: &str = "#d62728";
pub(super) const P90: &str = "#e07b00";

/// A plot area and the data ranges it shows.
pub(super) struct Frame {
    pub(super) left: f64,
    pub(super) top: f64,
    pub(super) width: f64,
    pub(super) height: f64,
    pub(super) x: (f64, f64),
    pub(super) y: (f64, f64),
}

impl Frame {
    pub(super) fn right(&self) -> f64 {
        self.left + self.width
    }
    pub(super) fn bottom(&self) -> f64 {
        self.top + self.height
    }
    pub(super) fn px(&self, v: f64) -> f64 {
        self.left + unit(v, self.x) * self.width
    }
    pub(super) fn py(&self, v: f64) -> f64 {
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
pub(super) struct N(pub(super) f64);

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
pub(super) fn de(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "n/a".into()
    }
}

/// Text escaped for XML character data and attribute values; characters XML 1.0 cannot
/// carry become U+FFFD.
pub(super) fn esc(t: &str) -> String {
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
pub(super) fn clip_chars(t: &str, max: usize) -> String {
    if t.chars().count() <= max {
        t.to_string()
    } else {
        let mut c: String = t.chars().take(max.saturating_sub(1)).collect();
        c.push('…');
        c
    }
}

/// A rough width of `t` in the figure's sans-serif font.
pub(super) fn text_width(t: &str, size: f64) -> f64 {
    t.chars().count() as f64 * size * 0.6
}

/// A `<text>` element; `content` is escaped here.
pub(super) fn text(
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

pub(super) fn panel_title(s: &mut String, x: f64, y: f64, title: &str) -> fmt::Result {
    writeln!(
        s,
        r#"<text class="panel-title" x="{}" y="{}" font-size="15" font-weight="bold">{}</text>"#,
        N(x),
        N(y),
        esc(title)
    )
}

pub(super) fn no_data(s: &mut String, f: &Frame) -> fmt::Result {
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

pub(super) fn clip_path(s: &mut String, id: &str, f: &Frame) -> fmt::Result {
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
pub(super) fn marker(s: &mut String, p: &PatchResult, x: f64, y: f64, r: f64) -> fmt::Result {
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

/// `#rrggbb` of XYZ (white Y = 1) in sRGB, each channel clipped to [0, 1]; `None` for a
/// non-finite value.
pub(super) fn srgb_hex(xyz: Xyz) -> Option<String> {
    if !xyz.iter().all(|v| v.is_finite()) {
        return None;
    }
    let [r, g, b] = xyz_to_linear_srgb(xyz).map(encode_srgb8);
    Some(format!("#{r:02x}{g:02x}{b:02x}"))
}
