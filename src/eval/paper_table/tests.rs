use super::rows::CaptureSpread;
use super::{
    BaselineFamily, PaperOptions, PaperRow, PaperTable, StorageComparison, paper_summary,
    run_paper_table,
};
use crate::camera::SensorDesign;
use crate::eval::{ChartSetup, EvalError};

fn row(acq: &str, method: &str, mean: f64, baseline: Option<BaselineFamily>) -> PaperRow {
    PaperRow {
        acquisition: acq.into(),
        method: method.into(),
        mean,
        std: 0.0,
        median: mean,
        p90: mean,
        max: mean,
        pixel_mean: mean,
        linear_mean: baseline.map(|_| mean),
        exposures: Vec::new(),
        baseline,
        paper: None,
        training_seconds: None,
        captures: None,
        spatial: Default::default(),
    }
}

fn table(rows: Vec<PaperRow>) -> PaperTable {
    PaperTable {
        sensor: "s".into(),
        chart: "natural100".into(),
        rows,
        storage: StorageComparison {
            illuminants: 0,
            table_bytes: 0,
            matrix_bytes: 0,
            si_plus_matrices_bytes: 0,
            cross_tables_bytes: 0,
        },
        reports: Vec::new(),
        options: PaperOptions::default(),
        comparisons: Vec::new(),
    }
}

#[test]
fn one_baseline_variant_per_sensor_by_its_mean_over_every_baseline_row() {
    use BaselineFamily::*;
    // RGB wins under tungsten by 0.01, all channels wins overall
    let t = table(vec![
        row("Tungsten", "I_Tun", 2.7, Some(AcquisitionFit)),
        row("Tungsten", "SI_D65+T", 4.0, Some(D65FitThenT)),
        row("Tungsten", "Baseline_Tun", 4.52, None),
        row("Tungsten", "Baseline_Tun all", 4.53, None),
        row("Tungsten", "Baseline+T", 9.04, None),
        row("Tungsten", "Baseline+T all", 4.55, None),
    ]);
    assert!(t.all_channel_baseline());
    let base = |m: &str| {
        let r = t.row("Tungsten", m).unwrap();
        t.baseline_for(r).unwrap().method.clone()
    };
    assert_eq!(base("I_Tun"), "Baseline_Tun all");
    assert_eq!(base("SI_D65+T"), "Baseline+T all");
    // no ISP rows: no ISP comparison
    assert!(t.isp_for(t.row("Tungsten", "I_Tun").unwrap()).is_none());
    // RGB wins overall: every row uses it, and a missing variant falls
    // back to the other
    let t = table(vec![
        row("Tungsten", "I_Tun", 2.7, Some(AcquisitionFit)),
        row("Tungsten", "SI_D65+T", 4.0, Some(D65FitThenT)),
        row("Tungsten", "Baseline_Tun", 4.0, None),
        row("Tungsten", "Baseline_Tun all", 4.5, None),
        row("Tungsten", "Baseline+T all", 4.55, None),
    ]);
    assert!(!t.all_channel_baseline());
    let i = t.row("Tungsten", "I_Tun").unwrap();
    assert_eq!(t.baseline_for(i).unwrap().method, "Baseline_Tun");
    let s = t.row("Tungsten", "SI_D65+T").unwrap();
    assert_eq!(t.baseline_for(s).unwrap().method, "Baseline+T all");
    // the strong ISP of each family, in the sensor's variant (RGB here)
    let mut t = t;
    for m in ["ISP_Tun", "ISP_Tun all", "ISP_D65+T", "ISP_D65+T all"] {
        t.rows.push(row("Tungsten", m, 3.0, None));
    }
    let isp = |m: &str| {
        t.isp_for(t.row("Tungsten", m).unwrap())
            .unwrap()
            .method
            .clone()
    };
    assert_eq!(isp("I_Tun"), "ISP_Tun");
    assert_eq!(isp("SI_D65+T"), "ISP_D65+T");
    assert!(
        t.markdown()
            .contains("| Tungsten | I_Tun | ISP_Tun | -0.30 |")
    );
}

#[test]
fn an_ensemble_is_judged_against_the_matrix_fitted_on_its_lights() {
    use BaselineFamily::*;
    let t = table(vec![
        row("Fluorescent", "SI_D65+T", 1.53, Some(D65FitThenT)),
        row("Fluorescent", "SI_Ens+T", 1.61, Some(EnsembleFitThenT)),
        row("Fluorescent", "SI_Ens3+T", 1.46, Some(EnsembleFitThenT)),
        row("Fluorescent", "Baseline+T", 1.96, None),
        row("Fluorescent", "Baseline+T all", 1.48, None),
        row("Fluorescent", "Baseline_Ens+T", 1.89, None),
        row("Fluorescent", "Baseline_Ens+T all", 1.57, None),
        row("Fluorescent", "Baseline_Ens3+T", 1.57, None),
        row("Fluorescent", "Baseline_Ens3+T all", 1.52, None),
    ]);
    assert!(t.all_channel_baseline());
    let r = |m: &str| t.row("Fluorescent", m).unwrap();
    let base = |m: &str| t.baseline_for(r(m)).unwrap().method.clone();
    assert_eq!(base("SI_D65+T"), "Baseline+T all");
    assert_eq!(base("SI_Ens+T"), "Baseline_Ens+T all");
    assert_eq!(base("SI_Ens3+T"), "Baseline_Ens3+T all");
    // the D65 fit, which judged the ensembles before, is shown beside
    let d65 = |m: &str| t.d65_baseline_for(r(m)).map(|b| b.method.clone());
    assert_eq!(d65("SI_Ens+T").as_deref(), Some("Baseline+T all"));
    assert_eq!(d65("SI_D65+T"), None);
    let summary = paper_summary(std::slice::from_ref(&t));
    assert!(
        summary.contains("| Baseline_Ens+T all 1.57 (D65 fit: 1.48, +0.13) | +0.04 |"),
        "{summary}"
    );
}

#[test]
fn several_captures_need_noise_and_a_count_in_range() {
    let design = SensorDesign::paper_default();
    let run = |captures: usize, noise: bool| {
        let opts = PaperOptions {
            captures,
            chart: ChartSetup {
                noise,
                ..ChartSetup::default()
            },
            ..PaperOptions::default()
        };
        // (refused before any table is trained)
        match run_paper_table(&design, None, &opts, &|_| {}) {
            Err(EvalError::Invalid(m)) => m,
            other => panic!(
                "{captures} captures, noise {noise}: {:?}",
                other.map(|_| ())
            ),
        }
    };
    assert!(run(4, false).contains("needs noise"), "{}", run(4, false));
    for n in [0, super::super::MAX_CAPTURES + 1] {
        assert!(run(n, true).contains("captures"), "{}", run(n, true));
    }
}

#[test]
fn rows_over_several_captures_are_reported_beside_the_first() {
    use BaselineFamily::*;
    let with = |mut r: PaperRow, means: &[f64], linear: Option<&[f64]>| {
        r.captures = Some(CaptureSpread::new(means.to_vec(), linear));
        r
    };
    let mut t = table(vec![
        with(
            row("Tungsten", "I_Tun", 2.67, Some(AcquisitionFit)),
            &[2.67, 2.87],
            Some(&[5.0, 5.2]),
        ),
        with(
            row("Tungsten", "Baseline_Tun", 4.0, None),
            &[4.0, 4.4],
            None,
        ),
        row("Tungsten", "Baseline_Tun all", 4.5, None),
    ]);
    let spread = t.rows[0].captures.clone().unwrap();
    assert!((spread.mean - 2.77).abs() < 1e-12, "{spread:?}");
    assert!((spread.linear_mean.unwrap() - 5.1).abs() < 1e-12);
    assert_eq!(t.n_captures(), 2);
    t.comparisons = t.compare_with_baselines();
    let c = &t.comparisons[0];
    assert!((c.mean_difference - (2.67 - 4.0)).abs() < 1e-12);
    assert!((c.capture_mean_difference.unwrap() - (2.77 - 4.2)).abs() < 1e-12);
    let md = t.markdown();
    assert!(
        md.contains("Over 2 noisy captures of the chart (seeds 7–8)"),
        "{md}"
    );
    assert!(md.contains("| Tungsten | I_Tun | 2.67 | 2.77 ("), "{md}");
    assert!(md.contains("| 5.10 | -2.33 |"), "{md}");
    assert!(md.contains("| -1.33 | -1.43 |"), "{md}");
    let summary = paper_summary(std::slice::from_ref(&t));
    assert!(summary.contains("mean over 2 captures (std)"), "{summary}");
    assert!(
        summary.contains("| 2.77 (0.10) | 5.10 | -1.43 |"),
        "{summary}"
    );
    assert!(
        md.contains("| Δ patch mean | Δ over the captures |"),
        "{md}"
    );
    // one capture: the columns are not there
    let mut one = table(vec![
        row("Tungsten", "I_Tun", 2.67, Some(AcquisitionFit)),
        row("Tungsten", "Baseline_Tun", 4.0, None),
    ]);
    one.comparisons = one.compare_with_baselines();
    assert_eq!(one.n_captures(), 1);
    let md = one.markdown();
    assert!(
        !md.contains("noisy captures") && !md.contains("captures |"),
        "{md}"
    );
    assert!(md.contains("| Baseline_Tun | -1.33 | 1×"), "{md}");
    assert!(!paper_summary(&[one]).contains("captures"));
}

#[test]
fn the_spatial_metrics_have_a_table_of_their_own_when_measured() {
    use super::{ExposurePoint, Spatial};
    let mut r = row("Tungsten", "I_Tun", 2.7, None);
    assert!(
        !table(vec![r.clone()])
            .markdown()
            .contains("Spatial metrics")
    );
    let sp = |m: f64| Spatial {
        s_cielab_mean: Some(3.21),
        s_cielab_texture: Some(4.32),
        mtf50: Some(m),
        false_colour: Some(1.5),
    };
    r.spatial = sp(0.245);
    r.exposures = vec![ExposurePoint {
        factor: 0.1,
        mean: 3.0,
        pixel_mean: 5.0,
        spatial: sp(0.201),
    }];
    let md = table(vec![r.clone()]).markdown();
    assert!(
        md.contains(
            "| Tungsten | I_Tun | 3.21 | 4.32 | 0.245 | 1.50 | 3.21 | 4.32 | 0.201 | 1.50 |"
        ),
        "{md}"
    );
    // flattened into the row's JSON, and read back
    let v = serde_json::to_value(&r).unwrap();
    assert_eq!(v["mtf50"], 0.245);
    assert_eq!(v["exposures"][0]["false_colour"], 1.5);
    let back: PaperRow = serde_json::from_value(v).unwrap();
    assert_eq!(back.spatial, r.spatial);
}
