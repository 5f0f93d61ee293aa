//! The paper's Table 1 on the paper's sensor (`rgbw-iset`: ISETCam's
//! default RGBW filters), on a small training set so it runs in CI:
//! - with the default flags (8 chroma classes, seed 7), the paper's Table 1 beaten: I_Tun
//!   ≤ 2.4 and SI_Ens+T ≤ 2.8 on the first capture and over 4 (1.96 and 2.52 here; 2.02 and
//!   2.58 over the 4), in the paper's order (I_Tun ≤ SI_Tun+T ≤ SI_Ens+T ≤ SI_D65+T, ties
//!   within 0.02 held: 1.96, 1.98, 2.52, 4.08);
//! - every L3 row within 0.4 ΔE of its matching linear map (the same
//!   least-squares channel → XYZ map in every class, evaluated on the same
//!   noisy frame), or better, on the first capture and on the mean over 4
//!   (`PaperOptions::captures`, each row's mean beside the first capture's);
//! - every L3 row better on patch means than the conventional baseline
//!   fitted under the acquisition light (the sensor's variant: of the RGB
//!   3×3 and the all-channel matrix, the one with the lower mean patch-mean
//!   ΔE over its baseline rows);
//! - every L3 row against its like-for-like baseline (an ensemble's: the
//!   conventional matrix fitted on the same lights, then T): no worse by
//!   more than 0.1 on patch means, better per pixel at every exposure (1,
//!   0.5, 0.25, 0.1×), by a quarter or more at 0.1×;
//! - the storage comparison;
//! - the camera-aware correction: a D65 table under the fluorescent lamp
//!   with C against T, and with one C per level against the brightest
//!   level's C alone at a tenth of the exposure (on rgbw-ar0132at);
//! - with chroma classes trained on tungsten alone at seed 1, I_Tun and SI_Tun+T under 2.7
//!   and 2.95 with bounded kernels.
//!
//! `l3 eval --paper-table --sensor config/sensors/rgbw-iset.toml` runs the
//! full version, under fluorescent too.

use l3::camera::SensorDesign;
use l3::eval::{ChartSetup, PaperOptions, PaperRow, PaperTable, run_paper_table};

#[test]
fn table1_on_the_papers_sensor() {
    let t = run_table1();
    check_the_papers_order(&t);
    check_the_strong_isp(&t);
    check_against_the_linear_maps(&t);
    check_like_with_like(&t);
    check_storage_and_reports(&t);
}

/// The paper's Table 1 on its sensor, on the small training set, printed.
fn run_table1() -> PaperTable {
    let sensor = concat!(env!("L3_ROOT"), "/config/sensors/rgbw-iset.toml");
    let design = SensorDesign::load(sensor, None).unwrap();
    let opts = PaperOptions {
        acquisitions: vec!["Tungsten".into()],
        scenes: 48,
        scene_size: 96,
        // `l3 eval --paper-table`'s default seed: the tables and the chart's first capture
        seed: 7,
        chart: ChartSetup::default(),
        captures: 4,
        ..PaperOptions::default()
    };
    let t = run_paper_table(&design, None, &opts, &|m| eprintln!("{m}")).unwrap();
    println!("{}", t.markdown());
    t
}

/// The row of method `m` under tungsten.
fn tungsten_row(t: &PaperTable, m: &str) -> PaperRow {
    t.row("Tungsten", m)
        .unwrap_or_else(|| panic!("row {m}"))
        .clone()
}

/// The default flags beat the paper's Table 1, in the paper's order (ties within 0.02 held).
fn check_the_papers_order(t: &PaperTable) {
    let row = |m: &str| tungsten_row(t, m);
    let (si_t, si_e, si_d) = (row("SI_Tun+T"), row("SI_Ens+T"), row("SI_D65+T"));
    // the default flags beat the paper's Table 1 on its sensor (2.5 and 2.9), on the first
    // capture and over the captures
    for (m, bound) in [("I_Tun", 2.4), ("SI_Ens+T", 2.8)] {
        let r = row(m);
        let over = r.captures.as_ref().map_or(f64::NAN, |c| c.mean);
        assert!(
            r.mean <= bound && over <= bound,
            "{m}: {:.2}, over the captures {over:.2}; the bound is {bound}",
            r.mean
        );
    }
    // the paper's order, ties within 0.02 held
    assert!(
        si_t.mean <= si_e.mean + 0.02 && si_e.mean <= si_d.mean + 0.02,
        "SI order: Tun {} Ens {} D65 {}",
        si_t.mean,
        si_e.mean,
        si_d.mean
    );
    // an SI_Tun table aimed through T, with the cross table's averaging, is the cross table
    // followed by T⁻¹ (least squares commutes with T); their chroma classes differ (the SI
    // table's are balanced by the light's neutral), so the paper's I_Tun ≤ SI_Tun+T holds to
    // a few hundredths (1.96 and 1.98 here)
    let i_tun = row("I_Tun");
    assert!(
        i_tun.mean <= si_t.mean + 0.02 && (i_tun.mean - si_t.mean).abs() <= 0.05,
        "I_Tun {} and SI_Tun+T {}",
        i_tun.mean,
        si_t.mean
    );
}

/// The strong ISP's rows: its denoiser beats the bilinear baseline per pixel at 0.1×.
fn check_the_strong_isp(t: &PaperTable) {
    let row = |m: &str| tungsten_row(t, m);
    for (isp, bilinear) in [("ISP_Tun", "Baseline_Tun"), ("ISP_D65+T", "Baseline+T")] {
        let low = |m: &str| {
            let r = row(m);
            r.exposures
                .iter()
                .find(|p| p.factor == 0.1)
                .unwrap_or_else(|| panic!("{m} has no 0.1× point"))
                .pixel_mean
        };
        assert!(
            low(isp) < low(bilinear),
            "{isp} {} against {bilinear} {}",
            low(isp),
            low(bilinear)
        );
    }
}

/// Every L3 row within 0.4 of its matching linear map, on the first capture and over 4, and
/// the tungsten rows better than the acquisition-fit baseline.
fn check_against_the_linear_maps(t: &PaperTable) {
    let row = |m: &str| tungsten_row(t, m);
    let base = row("Baseline_Tun").mean.min(row("Baseline_Tun all").mean);
    let conventional = |m: &str| m.starts_with("Baseline") || m.starts_with("ISP");
    for r in t.rows.iter().filter(|r| !conventional(&r.method)) {
        let lin = r
            .linear_mean
            .unwrap_or_else(|| panic!("{} has no linear map", r.method));
        assert!(
            r.mean <= lin + 0.4,
            "{} {} is worse than its matching linear map {lin}",
            r.method,
            r.mean
        );
        let over = r
            .captures
            .as_ref()
            .unwrap_or_else(|| panic!("{} has no captures", r.method));
        assert_eq!(over.per_capture.len(), 4, "{}", r.method);
        assert_eq!(
            over.per_capture[0], r.mean,
            "{}: the first capture",
            r.method
        );
        let lin4 = over.linear_mean.unwrap();
        assert!(
            over.mean <= lin4 + 0.4,
            "{} over 4 captures {} is worse than its matching linear map's {lin4}",
            r.method,
            over.mean
        );
        if r.method.contains("Tun") {
            assert!(
                r.mean < base,
                "{} {} does not beat the acquisition-fit baseline {base}",
                r.method,
                r.mean
            );
        }
    }
}

/// Like with like: every L3 row against its baseline family (in the sensor's variant, RGB or
/// all channels), on patch means and per pixel at every exposure, by a quarter at a tenth of
/// the light.
fn check_like_with_like(t: &PaperTable) {
    assert_eq!(t.comparisons.len(), 6, "{:?}", t.comparisons);
    let ens = t
        .comparisons
        .iter()
        .find(|c| c.method == "SI_Ens+T")
        .unwrap();
    assert!(ens.baseline.starts_with("Baseline_Ens+T"), "{ens:?}");
    for c in &t.comparisons {
        assert!(
            c.mean_difference <= 0.1,
            "{} is {:+.2} against {}",
            c.method,
            c.mean_difference,
            c.baseline
        );
        let factors: Vec<f64> = c.pixel_ratios.iter().map(|p| p.0).collect();
        assert_eq!(factors, [1.0, 0.5, 0.25, 0.1], "{}", c.method);
        for (f, ratio) in &c.pixel_ratios {
            let bound = if *f <= 0.1 { 0.75 } else { 1.0 };
            assert!(
                *ratio < bound,
                "{} per pixel at {f}×: {ratio:.2} of {}",
                c.method,
                c.baseline
            );
        }
    }
}

/// The storage comparison, and every report carries the documented fields.
fn check_storage_and_reports(t: &PaperTable) {
    let s = &t.storage;
    assert!(
        s.illuminants >= 5,
        "registry has {} illuminants",
        s.illuminants
    );
    assert!(s.si_plus_matrices_bytes * 4 < s.cross_tables_bytes, "{s:?}");
    assert_eq!(s.si_plus_matrices_bytes, s.table_bytes + s.illuminants * 72);
    // every report carries the documented fields
    let json = serde_json::to_value(&t.reports[0]).unwrap();
    for k in [
        "schema",
        "chart",
        "acquisition_illuminant",
        "method",
        "summary",
        "per_pixel",
        "per_category",
        "white_patch",
        "patches",
        "context",
    ] {
        assert!(json.get(k).is_some(), "report lacks {k}");
    }
}

/// A D65 table of a shipped sensor, to be judged under ISET's fluorescent
/// lamp: the lamp's colorimetric T and the table's camera-aware C.
struct D65TableUnderTheLamp {
    table: l3::l3::L3Table,
    camera: l3::camera::Camera,
    t: l3::l3::correct::IlluminantEntry,
    c: l3::l3::correct::IlluminantEntry,
}

impl D65TableUnderTheLamp {
    fn train(sensor: &str) -> Self {
        use l3::camera::Camera;
        use l3::l3::correct::{IlluminantRegistry, camera_corrected, noise_model};
        use l3::l3::learn::{TrainingSpec, train_table};
        use l3::l3::table::TableKind;
        use l3::spectral::WavelengthGrid;

        let path = format!("{}/config/sensors/{sensor}.toml", env!("L3_ROOT"));
        let design = SensorDesign::load(&path, None).unwrap();
        let spec = TrainingSpec {
            kind: TableKind::SameIlluminant,
            illuminants: vec!["D65".into()],
            seed: 1,
            scenes: 48,
            scene_size: 96,
            ..TrainingSpec::default()
        };
        let cancel = std::sync::atomic::AtomicBool::new(false);
        let table = train_table(&design, &spec, None, &|_, _| {}, &cancel).unwrap();
        let grid = WavelengthGrid::default();
        let camera = Camera::new(&design, grid, None).unwrap();
        let t = IlluminantRegistry::with_defaults(grid, None)
            .unwrap()
            .resolve("Fluorescent", None)
            .unwrap();
        let c = camera_corrected(
            &camera,
            &table.level_colour_maps(&noise_model(&design)).unwrap(),
            &t,
            None,
        )
        .unwrap();
        Self {
            table,
            camera,
            t,
            c,
        }
    }

    /// Mean patch-mean ΔE2000 of the chart under the lamp with `corr`.
    fn mean(&self, corr: &l3::l3::correct::IlluminantEntry, chart: &ChartSetup) -> f64 {
        use l3::eval::{Method, evaluate_method};
        evaluate_method(
            &self.camera,
            &Method::Table(&self.table),
            "SI_D65",
            "Fluorescent",
            corr,
            None,
            chart,
        )
        .unwrap()
        .summary
        .mean
    }
}

/// One D65 table serves a light it was not trained for through the light's
/// correction: on the paper's sensor under ISET's fluorescent lamp the
/// paper's colorimetric T leaves the chart unusable (about 16 ΔE2000), and
/// the camera-aware C, fitted on the table's own colour maps and the sensor's
/// response under the lamp, brings it close to a table trained under the lamp.
#[test]
fn camera_aware_correction_serves_a_d65_table_under_fluorescent() {
    let d = D65TableUnderTheLamp::train("rgbw-iset");
    let chart = ChartSetup::default();
    let (with_t, with_c) = (d.mean(&d.t, &chart), d.mean(&d.c, &chart));
    println!("SI_D65 under Fluorescent: +T {with_t:.2}, +C {with_c:.2}");
    assert!(
        with_c < 4.0 && with_c * 3.0 < with_t,
        "+T {with_t} +C {with_c}"
    );
}

/// In dim light a same-illuminant table's darker levels carry colour maps
/// shrunk for its own light's noise; under another light that shrinkage is a
/// colour cast one 3×3 cannot undo at every level. The camera-aware
/// correction is therefore fitted per level, on each level's own colour map.
/// rgbw-ar0132at's D65 table under the fluorescent lamp at a tenth of the
/// exposure: about 3 ΔE2000 with a C per level, 9 with the brightest level's
/// C alone.
#[test]
fn per_level_camera_correction_serves_a_d65_table_in_dim_light() {
    let d = D65TableUnderTheLamp::train("rgbw-ar0132at");
    assert_eq!(d.c.level_corrections.len(), d.table.n_bands());
    let brightest_only = l3::l3::correct::IlluminantEntry {
        level_corrections: Vec::new(),
        ..d.c.clone()
    };
    let dim = l3::eval::LightLevel::ExposureFactor(0.1)
        .apply(&ChartSetup::default())
        .unwrap();
    let (levels, top) = (d.mean(&d.c, &dim), d.mean(&brightest_only, &dim));
    println!(
        "SI_D65+C under Fluorescent at 0.1×: C per level {levels:.2}, brightest level's C {top:.2}"
    );
    assert!(
        levels < 4.5 && levels * 1.5 < top,
        "per level {levels}, brightest {top}"
    );
}

/// Chroma classes (`chroma_classes`, 8 asked, 6 kept on this sensor) take
/// the paper's sensor under the targets under tungsten, where one
/// class sat on the linear floor (2.67 on this capture for both, 2.77 over
/// 16): I_Tun ≤ 2.7 and SI_Tun+T ≤ 2.95 (2.22 and 2.22 here), in the
/// paper's order (to rounding), with every kernel norm under 100.
#[test]
fn chroma_classes_take_the_papers_sensor_under_its_targets() {
    use l3::camera::Camera;
    use l3::eval::{Method, evaluate_method};
    use l3::l3::correct::IlluminantRegistry;
    use l3::l3::learn::{TrainingSpec, train_table};
    use l3::l3::table::TableKind;
    use l3::spectral::WavelengthGrid;

    let sensor = concat!(env!("L3_ROOT"), "/config/sensors/rgbw-iset.toml");
    let design = SensorDesign::load(sensor, None).unwrap();
    let cancel = std::sync::atomic::AtomicBool::new(false);
    let train = |kind| {
        let spec = TrainingSpec {
            kind,
            illuminants: vec!["Tungsten".into()],
            seed: 1,
            scenes: 48,
            scene_size: 96,
            chroma_classes: 8,
            ..TrainingSpec::default()
        };
        train_table(&design, &spec, None, &|_, _| {}, &cancel).unwrap()
    };
    let (cross, si) = (
        train(TableKind::CrossIlluminant),
        train(TableKind::SameIlluminant),
    );
    let grid = WavelengthGrid::default();
    let camera = Camera::new(&design, grid, None).unwrap();
    let t = IlluminantRegistry::with_defaults(grid, None)
        .unwrap()
        .resolve("Tungsten", None)
        .unwrap();
    let mean = |table: &l3::l3::L3Table, name: &str| {
        let m = Method::Table(table);
        evaluate_method(
            &camera,
            &m,
            name,
            "Tungsten",
            &t,
            None,
            &ChartSetup::default(),
        )
        .unwrap()
        .summary
        .mean
    };
    let (i_tun, si_tun) = (mean(&cross, "I_Tun"), mean(&si, "SI_Tun"));
    println!(
        "rgbw-iset with {} chroma classes: I_Tun {i_tun:.2}, SI_Tun+T {si_tun:.2}",
        cross.n_chroma()
    );
    assert!(cross.n_chroma() > 1 && si.n_chroma() > 1);
    assert!(
        i_tun <= 2.7 && si_tun <= 2.95 && i_tun <= si_tun + 1e-3,
        "{i_tun} {si_tun}"
    );
    for table in [&cross, &si] {
        let worst = table
            .reports
            .iter()
            .map(|r| r.kernel_norm)
            .fold(0.0, f64::max);
        assert!(worst <= 100.0, "max kernel norm {worst}");
    }
}

/// A same-illuminant table under a light it was not trained on renders with
/// its transfer maps, whose fit (the colour maps' ΔE00 fit or plain least
/// squares, on all its training lights or, for an ensemble, on one of them)
/// the trainer chooses on standard lights held out from training (CIE D50,
/// A, F2, F11). On the paper's sensor the D65 + tungsten table under ISET's
/// fluorescent lamp, noise-free, was 15.04 against its matching linear map's
/// 14.63 with both lights' ΔE00 fit and 14.64 with their least squares; the
/// held-out lights now choose tungsten's least squares, 12.65. The D65 table
/// keeps the ΔE00 fit, which beats its linear map under tungsten (3.19
/// against 4.21).
#[test]
fn held_out_lights_choose_the_fit_a_table_takes_to_a_foreign_light() {
    use l3::camera::Camera;
    use l3::eval::{Method, evaluate_capture, linear_table, matching_linear_map, simulate_chart};
    use l3::l3::correct::IlluminantRegistry;
    use l3::l3::learn::{TrainingSpec, train_table};
    use l3::spectral::WavelengthGrid;

    let sensor = concat!(env!("L3_ROOT"), "/config/sensors/rgbw-iset.toml");
    let design = SensorDesign::load(sensor, None).unwrap();
    let grid = WavelengthGrid::default();
    let camera = Camera::new(&design, grid, None).unwrap();
    let mut registry = IlluminantRegistry::with_defaults(grid, None).unwrap();
    let chart = ChartSetup {
        noise: false,
        ..ChartSetup::default()
    };
    let cancel = std::sync::atomic::AtomicBool::new(false);
    for (lights, acquisition, fit, fitted_on) in [
        (
            &["D65", "Tungsten"][..],
            "Fluorescent",
            "least-squares",
            "Tungsten",
        ),
        (&["D65"][..], "Tungsten", "perceptual", "D65"),
    ] {
        let spec = TrainingSpec {
            illuminants: lights.iter().map(|s| s.to_string()).collect(),
            seed: 7,
            noise: false,
            colour_averaging_px: Some(0.0),
            ..TrainingSpec::default()
        };
        let table = train_table(&design, &spec, None, &|_, _| {}, &cancel).unwrap();
        let choice = &table.meta.summary["transfer_fit"];
        assert_eq!(choice["fit"], fit, "{lights:?}: {choice}");
        assert_eq!(choice["lights"], serde_json::json!([fitted_on]), "{choice}");
        assert!(table.transfers_to(acquisition));
        let cap = simulate_chart(&camera, acquisition, None, &chart).unwrap();
        let corr = registry.resolve(acquisition, None).unwrap();
        let map = matching_linear_map(&camera, &table, acquisition, None).unwrap();
        let linear = linear_table(&table, &map).unwrap();
        let mean = |t: &l3::l3::L3Table| {
            evaluate_capture(&camera, &cap, &Method::Table(t), "m", &corr, &chart)
                .unwrap()
                .summary
                .mean
        };
        let (l3_mean, lin_mean) = (mean(&table), mean(&linear));
        println!(
            "{lights:?} under {acquisition}: {l3_mean:.2}, linear map {lin_mean:.2} ({choice})"
        );
        // the noise-free bound is 0.2; both tables beat their linear map
        assert!(
            l3_mean < lin_mean,
            "{lights:?} under {acquisition}: {l3_mean} against {lin_mean}"
        );
    }
}
