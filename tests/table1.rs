//! The paper's Table 1 acceptance, on a small training set so it runs in CI:
//! the paper's ordering under tungsten (I_Tun ≤ SI_Tun+T < SI_Ens+T <
//! SI_D65+T), SI_Ens+T within the paper's 3.0 mean / 6.0 p90, every L3 row
//! better than the conventional baseline, and the storage comparison.
//! `l3 eval --paper-table` runs the full-size version.

use l3::camera::SensorDesign;
use l3::eval::{ChartSetup, PaperOptions, run_paper_table};
use l3::spectral::IsetData;

#[test]
fn table1_ordering_thresholds_and_storage() {
    let Some(iset) = IsetData::for_tests() else {
        return;
    };
    let opts = PaperOptions {
        acquisitions: vec!["Tungsten".into()],
        scenes: 48,
        scene_size: 96,
        seed: 1,
        chart: ChartSetup::default(),
    };
    let t = run_paper_table(&SensorDesign::paper_default(), Some(&iset), &opts, &|m| {
        eprintln!("{m}")
    })
    .unwrap();
    println!("{}", t.markdown());
    let row = |m: &str| {
        t.row("Tungsten", m)
            .unwrap_or_else(|| panic!("row {m}"))
            .clone()
    };
    let (i, si_t, si_e, si_d) = (
        row("I_Tun"),
        row("SI_Tun+T"),
        row("SI_Ens+T"),
        row("SI_D65+T"),
    );
    let base = row("Baseline+T");
    assert!(
        i.mean <= si_t.mean,
        "I_Tun {} > SI_Tun+T {}",
        i.mean,
        si_t.mean
    );
    assert!(
        si_t.mean < si_e.mean,
        "SI_Tun+T {} ≥ SI_Ens+T {}",
        si_t.mean,
        si_e.mean
    );
    assert!(
        si_e.mean < si_d.mean,
        "SI_Ens+T {} ≥ SI_D65+T {}",
        si_e.mean,
        si_d.mean
    );
    assert!(
        si_e.mean <= 3.0 && si_e.p90 <= 6.0,
        "SI_Ens+T {} / {}",
        si_e.mean,
        si_e.p90
    );
    for r in t.rows.iter().filter(|r| r.method != "Baseline+T") {
        assert!(
            r.mean < base.mean,
            "{} {} does not beat the baseline {}",
            r.method,
            r.mean,
            base.mean
        );
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
