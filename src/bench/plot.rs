//! The SVG plot: milliseconds per megapixel against mean ΔE2000, one marker
//! series per acquisition illuminant, the Pareto front of each drawn as a
//! step line, and the plain copy as a vertical reference line.

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::labels::{GAP, PxBox, TextMetrics, place_labels};
use super::records::{BenchReport, FrontMetric};

/// Errors of drawing the plot.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("nothing to plot: {0}")]
    Empty(String),
    #[error("{0}")]
    Draw(String),
}

/// Stroke width used only by the Pareto front lines (post-processing tags
/// those lines with `class="pareto-front"`).
const FRONT_WIDTH: u32 = 3;

/// Indices of the non-dominated points when both coordinates are minimised
/// (the lower-left Pareto front), sorted by x then y. A point is dominated
/// when another is no worse in both and better in one, so equal points are
/// all kept. Points with a non-finite coordinate are ignored.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let ok = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let dominates =
        |a: &(f64, f64), b: &(f64, f64)| a.0 <= b.0 && a.1 <= b.1 && (a.0 < b.0 || a.1 < b.1);
    let mut idx: Vec<usize> = (0..points.len())
        .filter(|&i| ok(&points[i]))
        .filter(|&i| !points.iter().any(|q| ok(q) && dominates(q, &points[i])))
        .collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[a].1.total_cmp(&points[b].1))
            .then(a.cmp(&b))
    });
    idx
}

/// The step line through a front sorted by x: right at the current error,
/// then down to the next point's.
fn step_line(front: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(front.len() * 2);
    for (i, p) in front.iter().enumerate() {
        if i > 0 {
            out.push((p.0, front[i - 1].1));
        }
        out.push(*p);
    }
    out
}

const SERIES: [RGBColor; 4] = [
    RGBColor(200, 80, 20),
    RGBColor(30, 90, 200),
    RGBColor(40, 150, 60),
    RGBColor(140, 50, 160),
];

fn draw_err<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError::Draw(e.to_string())
}

/// One plotted configuration: its name, ms/Mpix (all threads) and mean ΔE per acquisition.
type PlotRow<'a> = (&'a str, f64, Vec<Option<f64>>);

/// The chart the plot draws on: log ms/Mpix against mean ΔE.
type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<LogCoord<f64>, RangedCoordf64>>;

/// Draw the report as an SVG document: run time against mean ΔE.
pub fn svg_plot(report: &BenchReport) -> Result<String, PlotError> {
    svg_plot_metric(report, FrontMetric::DeltaE)
}

/// Draw the report as an SVG document: run time against `metric`, with its Pareto fronts.
pub fn svg_plot_metric(report: &BenchReport, metric: FrontMetric) -> Result<String, PlotError> {
    let rows = plot_rows(report, metric);
    if rows.is_empty() {
        return Err(PlotError::Empty(
            "no configuration has colour results".into(),
        ));
    }
    let copy_x = report
        .copy()
        .map(|c| c.all_threads.ms_per_mpix)
        .filter(|x| x.is_finite() && *x > 0.0);
    let xs = rows.iter().map(|r| r.1).chain(copy_x);
    let x_lo = xs.clone().fold(f64::INFINITY, f64::min) / 1.6;
    let x_hi = xs.fold(0.0, f64::max) * 3.0;
    let y_hi = rows
        .iter()
        .flat_map(|r| r.2.iter().flatten().copied())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        .max(0.1)
        * 1.2;

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 640)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let what = match metric {
            FrontMetric::DeltaE => "colour error",
            FrontMetric::SCielab => "S-CIELAB",
            FrontMetric::Mtf50 => "sharpness",
        };
        let caption = format!(
            "L3 run time against {what} ({} renderer, {}×{} frame, {} threads)",
            report.renderer, report.frame.width, report.frame.height, report.threads
        );
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(60)
            .build_cartesian_2d((x_lo..x_hi).log_scale(), 0.0..y_hi)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_desc("milliseconds per megapixel, all threads (log scale)")
            .y_desc(metric.label())
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(draw_err)?;
        if let Some(cx) = copy_x {
            copy_line(&mut chart, cx, y_hi)?;
        }
        // the legend's lines, for the labels to keep out of it
        let mut legend: Vec<String> = copy_x
            .map(|cx| format!("plain copy of the frame: {cx:.2} ms/Mpix (no colour)"))
            .into_iter()
            .collect();
        for ill in &report.acquisitions {
            legend.push(format!("Pareto front under {ill}"));
            legend.push(format!("{} under {ill}", metric.name()));
        }
        for (k, ill) in report.acquisitions.iter().enumerate() {
            acquisition_series(&mut chart, &rows, (k, ill), metric, &legend)?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .draw()
            .map_err(draw_err)?;
        root.present().map_err(draw_err)?;
    }
    Ok(tag_front_lines(&svg))
}

/// The configurations with colour results and a positive finite time, with `metric`.
fn plot_rows(report: &BenchReport, metric: FrontMetric) -> Vec<PlotRow<'_>> {
    report
        .configs
        .iter()
        .filter(|r| !r.colour.is_empty())
        .map(|r| {
            (
                r.name.as_str(),
                r.all_threads.ms_per_mpix,
                report
                    .acquisitions
                    .iter()
                    .map(|a| r.colour_under(a).and_then(|c| metric.value(c)))
                    .collect(),
            )
        })
        .filter(|(_, x, _)| x.is_finite() && *x > 0.0)
        .collect()
}

/// The plain copy as a vertical reference line at `cx`, labelled.
fn copy_line(chart: &mut Chart<'_, '_>, cx: f64, y_hi: f64) -> Result<(), PlotError> {
    let grey = RGBColor(120, 120, 120);
    chart
        .draw_series(LineSeries::new(
            vec![(cx, 0.0), (cx, y_hi)],
            grey.stroke_width(1),
        ))
        .map_err(draw_err)?
        .label(format!(
            "plain copy of the frame: {cx:.2} ms/Mpix (no colour)"
        ))
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey));
    chart
        .draw_series(std::iter::once(Text::new(
            "plain copy".to_string(),
            (cx * 1.05, y_hi * 0.97),
            ("sans-serif", 16).into_font().color(&grey),
        )))
        .map_err(draw_err)?;
    Ok(())
}

/// The series of acquisition `k` (`ill`): its Pareto front as a step line with a ring round
/// each of its points, the points, and (for the first) the configuration names.
fn acquisition_series(
    chart: &mut Chart<'_, '_>,
    rows: &[PlotRow<'_>],
    (k, ill): (usize, &str),
    metric: FrontMetric,
    legend: &[String],
) -> Result<(), PlotError> {
    let colour = SERIES[k % SERIES.len()];
    let pts: Vec<(usize, (f64, f64))> = rows
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.2.get(k).copied().flatten().map(|y| (i, (r.1, y))))
        .filter(|(_, p)| p.1.is_finite())
        .collect();
    let xy: Vec<(f64, f64)> = pts.iter().map(|p| p.1).collect();
    // the front minimises the metric's cost (MTF50 is maximised)
    let sign = if metric == FrontMetric::Mtf50 {
        -1.0
    } else {
        1.0
    };
    let cost: Vec<(f64, f64)> = xy.iter().map(|p| (p.0, sign * p.1)).collect();
    let front: Vec<(f64, f64)> = pareto_front(&cost).into_iter().map(|i| xy[i]).collect();
    // the front: a step line and a ring round each of its points
    chart
        .draw_series(LineSeries::new(
            step_line(&front),
            colour.stroke_width(FRONT_WIDTH),
        ))
        .map_err(draw_err)?
        .label(format!("Pareto front under {ill}"))
        .legend(move |(x, y)| {
            PathElement::new(
                vec![(x, y), (x + 20, y)],
                colour.stroke_width(FRONT_WIDTH - 1),
            )
        });
    chart
        .draw_series(
            front
                .iter()
                .map(|&p| Circle::new(p, 9, colour.stroke_width(2))),
        )
        .map_err(draw_err)?;
    // the points
    let label = format!("{} under {ill}", metric.name());
    if k.is_multiple_of(2) {
        chart
            .draw_series(xy.iter().map(|&p| Circle::new(p, 5, colour.filled())))
            .map_err(draw_err)?
            .label(label)
            .legend(move |(x, y)| Circle::new((x + 10, y), 5, colour.filled()));
    } else {
        chart
            .draw_series(
                xy.iter()
                    .map(|&p| TriangleMarker::new(p, 6, colour.filled())),
            )
            .map_err(draw_err)?
            .label(label)
            .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 6, colour.filled()));
    }
    if k == 0 {
        point_labels(chart, rows, &pts, legend)?;
    }
    Ok(())
}

/// Where the upper-right legend with the entries `legend` lies (an estimate from the text's
/// size, on the generous side; plotters does not report it).
fn legend_box(area: PxBox, legend: &[String]) -> PxBox {
    let chars = legend.iter().map(|s| s.chars().count()).max().unwrap_or(0);
    PxBox {
        l: area.r - (chars as f64 * 8.0) as i32 - 60,
        t: area.t,
        r: area.r,
        b: area.t + 22 * legend.len() as i32 + 30,
    }
}

/// The configuration names beside their points ([`place_labels`]), with a leader line to
/// each one moved off its point's row.
fn point_labels(
    chart: &mut Chart<'_, '_>,
    rows: &[PlotRow<'_>],
    pts: &[(usize, (f64, f64))],
    legend: &[String],
) -> Result<(), PlotError> {
    let at: Vec<(i32, i32)> = pts.iter().map(|(_, p)| chart.backend_coord(p)).collect();
    let texts: Vec<&str> = pts.iter().map(|&(i, _)| rows[i].0).collect();
    let (xr, yr) = chart.plotting_area().get_pixel_range();
    let area = PxBox {
        l: xr.start,
        t: yr.start,
        r: xr.end,
        b: yr.end,
    };
    let metrics = TextMetrics {
        char_w: 8.0,
        line_h: 17,
    };
    let placed = place_labels(&at, &texts, area, &[legend_box(area, legend)], metrics);
    let grey = RGBColor(150, 150, 150);
    let labelled = || pts.iter().zip(&texts).zip(&placed);
    // a leader meets its label's near edge at its middle
    let leaders = labelled()
        .filter(|(_, q)| q.leader)
        .map(|((&(_, p), &t), q)| {
            let w = (t.chars().count() as f64 * metrics.char_w) as i32;
            let edge = if q.dx > 0 { q.dx } else { q.dx + w };
            EmptyElement::at(p)
                + PathElement::new(
                    vec![(0, 0), (edge, q.dy + metrics.line_h / 2)],
                    grey.stroke_width(1),
                )
        });
    chart.draw_series(leaders).map_err(draw_err)?;
    // a label left of its point ends at the gap whatever its true width
    let font = ("sans-serif", 15)
        .into_font()
        .into_text_style(chart.plotting_area());
    let right_of = font.clone().pos(Pos::new(HPos::Left, VPos::Top));
    let left_of = font.pos(Pos::new(HPos::Right, VPos::Top));
    let names = labelled().map(|((&(_, p), &t), q)| {
        let (x, style) = if q.dx > 0 {
            (q.dx, right_of.clone())
        } else {
            (-GAP, left_of.clone())
        };
        EmptyElement::at(p) + Text::new(t.to_string(), (x, q.dy), style)
    });
    chart.draw_series(names).map_err(draw_err)?;
    Ok(())
}

/// Mark the front's polylines (the only ones with [`FRONT_WIDTH`]) with
/// `class="pareto-front"` so the element can be found and styled.
fn tag_front_lines(svg: &str) -> String {
    let width = format!("stroke-width=\"{FRONT_WIDTH}\"");
    let mut out = String::with_capacity(svg.len() + 256);
    for (i, part) in svg.split("<polyline").enumerate() {
        if i == 0 {
            out.push_str(part);
            continue;
        }
        out.push_str("<polyline");
        let end = part.find("/>").unwrap_or(part.len());
        if part[..end].contains(&width) {
            out.push_str(" class=\"pareto-front\"");
        }
        out.push_str(part);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_non_dominated_points_and_ties() {
        let pts = [
            (10.0, 3.0),     // 0 front
            (20.0, 2.0),     // 1 front
            (15.0, 3.5),     // 2 dominated by 0
            (30.0, 2.0),     // 3 dominated by 1 (same error, slower)
            (5.0, 5.0),      // 4 front (fastest)
            (20.0, 2.0),     // 5 tie with 1: kept
            (40.0, 1.0),     // 6 front
            (f64::NAN, 0.1), // 7 ignored
            (10.0, 4.0),     // 8 dominated by 0 (same time, worse)
        ];
        assert_eq!(pareto_front(&pts), vec![4, 0, 1, 5, 6]);
        assert!(pareto_front(&[]).is_empty());
        assert_eq!(pareto_front(&[(1.0, 1.0)]), vec![0]);
        // one point dominating all others
        assert_eq!(pareto_front(&[(2.0, 2.0), (1.0, 1.0), (3.0, 1.0)]), vec![1]);
        let step = step_line(&[(1.0, 3.0), (2.0, 2.0), (4.0, 1.0)]);
        assert_eq!(
            step,
            vec![(1.0, 3.0), (2.0, 3.0), (2.0, 2.0), (4.0, 2.0), (4.0, 1.0)]
        );
    }

    #[test]
    fn front_lines_are_tagged() {
        let s = r#"<svg><polyline stroke-width="3" points="1,2"/><polyline stroke-width="1" points="1,2"/></svg>"#;
        let t = tag_front_lines(s);
        assert_eq!(t.matches("class=\"pareto-front\"").count(), 1);
        assert!(t.starts_with("<svg><polyline class=\"pareto-front\" stroke-width=\"3\""));
    }

    /// Tags balance, names match, text has no raw `<` or `&` outside entities.
    fn assert_well_formed(svg: &str) {
        let mut stack: Vec<String> = Vec::new();
        let mut rest = svg.trim();
        assert!(
            rest.starts_with("<svg") || rest.starts_with("<?xml"),
            "{}",
            &rest[..40]
        );
        while let Some(open) = rest.find('<') {
            let text = &rest[..open];
            for (i, _) in text.match_indices('&') {
                let ent = &text[i..];
                assert!(
                    ent.find(';').is_some_and(|e| e < 10),
                    "bare & in text: {}",
                    &text[..text.len().min(60)]
                );
            }
            let close = rest[open..].find('>').expect("unclosed tag") + open;
            let tag = &rest[open + 1..close];
            assert!(!tag.contains('<'), "'<' inside a tag: {tag}");
            if tag.starts_with('?') || tag.starts_with('!') || tag.ends_with('/') {
            } else if let Some(name) = tag.strip_prefix('/') {
                assert_eq!(
                    stack.pop().as_deref(),
                    Some(name.trim()),
                    "mismatched </{name}>"
                );
            } else {
                let name = tag.split_whitespace().next().expect("tag name");
                stack.push(name.to_string());
            }
            rest = &rest[close + 1..];
        }
        assert!(stack.is_empty(), "unclosed: {stack:?}");
        assert!(rest.trim().is_empty());
    }

    #[test]
    fn svg_is_well_formed_with_front_copy_line_and_labels() {
        let r = crate::bench::report::test_support::sample_report();
        let svg = svg_plot(&r).unwrap();
        assert_well_formed(&svg);
        assert!(svg.trim_end().ends_with("</svg>"));
        // one front line per illuminant
        assert_eq!(svg.matches("class=\"pareto-front\"").count(), 2, "{svg}");
        assert!(svg.contains("Pareto front under Tungsten"));
        assert!(svg.contains("plain copy"));
        assert!(svg.contains("patch 7") && svg.contains("baseline") && svg.contains("ISP_D65+T"));
        // the label with markup characters is escaped
        assert!(!svg.contains("<5×5>"));
        let mut empty = r.clone();
        empty.configs.retain(|c| c.colour.is_empty());
        assert!(svg_plot(&empty).is_err());
    }
}
