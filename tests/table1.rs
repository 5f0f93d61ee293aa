//! The paper's Table 1 on the paper's sensor (`rgbw-iset`: ISETCam's
//! default RGBW filters), on a small training set so it runs in CI:
//! - the SI rows in the paper's order under tungsten (SI_Tun+T < SI_Ens+T <
//!   SI_D65+T);
//! - every L3 row within 0.4 ΔE of its matching linear map (the same
//!   least-squares channel → XYZ map in every class, evaluated on the same
//!   noisy frame), or better;
//! - every L3 row better on patch means than the conventional baseline
//!   fitted under the acquisition light (the better of its RGB 3×3 and
//!   all-channel variants);
//! - every L3 row against its like-for-like baseline: no worse by more than
//!   0.1 on patch means, better per pixel at every exposure (1, 0.5, 0.25,
//!   0.1×), by a quarter or more at 0.1×;
//! - the storage comparison.
//!
//! `l3 eval --paper-table --sensor config/sensors/rgbw-iset.toml` runs the
//! full version, under fluorescent too.

use l3::camera::SensorDesign;
use l3::eval::{ChartSetup, PaperOptions, run_paper_table};

#[test]
fn table1_on_the_papers_sensor() {
    let sensor = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sensors/rgbw-iset.toml");
    let design = SensorDesign::load(sensor, None).unwrap();
    let opts = PaperOptions {
        acquisitions: vec!["Tungsten".into()],
        scenes: 48,
        scene_size: 96,
        seed: 1,
        chart: ChartSetup::default(),
        ..PaperOptions::default()
    };
    let t = run_paper_table(&design, None, &opts, &|m| eprintln!("{m}")).unwrap();
    println!("{}", t.markdown());
    let row = |m: &str| {
        t.row("Tungsten", m)
            .unwrap_or_else(|| panic!("row {m}"))
            .clone()
    };
    let (si_t, si_e, si_d) = (row("SI_Tun+T"), row("SI_Ens+T"), row("SI_D65+T"));
    assert!(
        si_t.mean < si_e.mean && si_e.mean < si_d.mean,
        "SI order: Tun {} Ens {} D65 {}",
        si_t.mean,
        si_e.mean,
        si_d.mean
    );
    let base = row("Baseline_Tun").mean.min(row("Baseline_Tun all").mean);
    for r in t.rows.iter().filter(|r| !r.method.starts_with("Baseline")) {
        let lin = r
            .linear_mean
            .unwrap_or_else(|| panic!("{} has no linear map", r.method));
        assert!(
            r.mean <= lin + 0.4,
            "{} {} is worse than its matching linear map {lin}",
            r.method,
            r.mean
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
    // like with like: every L3 row against its baseline family (the better
    // of RGB and all channels), on patch means and per pixel at every
    // exposure, by a quarter at a tenth of the light
    assert_eq!(t.comparisons.len(), 4, "{:?}", t.comparisons);
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
