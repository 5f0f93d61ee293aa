use super::axes::{nice_near, nice_step, ticks};
use super::report_svg;
use super::svg::{N, TITLE_A, TITLE_B, TITLE_C, TITLE_D, WORST, clip_chars, de, esc, srgb_hex};
use super::well_formed::assert_well_formed;
use crate::colour::{D65_WHITE_XYZ, Xyz, ciede2000, xyz_to_lab};
use crate::eval::{DeltaEReport, PatchResult, PixelStats, summarize};

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
        s_cielab_mean: None,
        edge_panel: None,
        spatial: Default::default(),
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

#[test]
fn an_edge_panel_adds_the_sfr_curves_and_the_crops() {
    use crate::eval::{EdgeCurve, EdgePanel};
    let (w, h) = (48, 48);
    let xyz: Vec<f32> = (0..w * h)
        .flat_map(|i| {
            let y = if i % w < w / 2 { 0.1 } else { 0.6 };
            [0.95 * y, y, 1.09 * y]
        })
        .collect();
    let sfr = crate::eval::Sfr {
        mtf50_cycles_per_pixel: 0.31,
        mtf_at_half_nyquist: 0.62,
        mtf_at_nyquist: 0.2,
        orientation: crate::eval::EdgeOrientation::Vertical,
        slant_degrees: 5.0,
        falling: false,
        lines_used: 44,
        frequencies: (0..=8).map(|k| k as f64 / 8.0).collect(),
        sfr: (0..=8).map(|k| (-(k as f64) / 3.0).exp()).collect(),
    };
    let curve = |name: &str, sfr: Option<&crate::eval::Sfr>| {
        EdgeCurve::new(name, &xyz, w, h, sfr, Some(0.5)).unwrap()
    };
    let mut rep = sample_report();
    rep.edge_panel = Some(EdgePanel {
        ideal: curve("ideal <lens>", Some(&sfr)),
        methods: vec![curve("L3", Some(&sfr)), curve("ISP_Tun", None)],
    });
    let svg = report_svg(&rep).unwrap();
    assert_well_formed(&svg);
    assert!(svg.contains(r#"height="1180""#), "the figure grows");
    assert!(svg.contains(super::svg::TITLE_E) && svg.contains(super::svg::TITLE_F));
    // a curve per edge with an SFR, a crop per edge, names escaped
    assert_eq!(svg.matches(r#"class="sfr-curve""#).count(), 2);
    assert_eq!(svg.matches(r#"class="edge-crop""#).count(), 3);
    assert!(svg.contains("ideal &lt;lens&gt;: MTF50 0.310"));
    assert!(svg.contains("ISP_Tun: MTF50 n/a"));
    // a crop that is not base64 is not drawn
    if let Some(p) = rep.edge_panel.as_mut() {
        p.methods[0].crop.png_base64 = r#""/><script>x</script>"#.into();
    }
    let svg = report_svg(&rep).unwrap();
    assert_well_formed(&svg);
    assert_eq!(svg.matches(r#"class="edge-crop""#).count(), 2);
    assert!(!svg.contains("<script"));
    // without the panel the figure keeps its size
    assert!(
        report_svg(&sample_report())
            .unwrap()
            .contains(r#"height="800""#)
    );
}
