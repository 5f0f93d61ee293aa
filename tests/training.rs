//! Training from the simulator: bit-for-bit reproducible whatever the
//! thread count, cancellable, and every table finite with bounded kernels.

use std::sync::atomic::{AtomicBool, Ordering};

use l3::camera::SensorDesign;
use l3::l3::{L3Error, TableKind};
use l3::training::{TrainError, TrainingSpec, train_table};

fn tiny(seed: u64) -> TrainingSpec {
    TrainingSpec {
        kind: TableKind::SameIlluminant,
        illuminants: vec!["D65".into(), "A".into()],
        levels: 10,
        scenes: 6,
        scene_size: 48,
        seed,
        ..TrainingSpec::default()
    }
}

#[test]
fn training_is_reproducible_and_thread_count_independent() {
    let design = SensorDesign::paper_default();
    let cancel = AtomicBool::new(false);
    let a = train_table(&design, &tiny(5), None, &|_, _| {}, &cancel).unwrap();
    let b = train_table(&design, &tiny(5), None, &|_, _| {}, &cancel).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let c = pool.install(|| train_table(&design, &tiny(5), None, &|_, _| {}, &cancel).unwrap());
    assert_eq!(a.kernels, b.kernels);
    assert_eq!(a.kernels, c.kernels);
    assert_eq!(a.contrast_thresholds, c.contrast_thresholds);
    let d = train_table(&design, &tiny(6), None, &|_, _| {}, &cancel).unwrap();
    assert_ne!(a.kernels, d.kernels, "another seed gives another table");
    // finite, bounded, reported
    assert!(a.kernels.iter().all(|v| v.is_finite()));
    let max_norm = a.reports.iter().map(|r| r.kernel_norm).fold(0.0, f64::max);
    println!("classes {}, max kernel norm {max_norm:.3}", a.n_classes());
    assert!(max_norm < 1e3, "kernel norm {max_norm}");
    assert_eq!(a.reports.len(), a.n_classes());
    assert!(a.meta.sat_cases[0] == 0);
}

#[test]
fn cancel_stops_training() {
    let design = SensorDesign::paper_default();
    let cancel = AtomicBool::new(false);
    let progress = |_: &str, f: f64| {
        if f > 0.1 {
            cancel.store(true, Ordering::Relaxed);
        }
    };
    let r = train_table(&design, &tiny(1), None, &progress, &cancel);
    assert!(
        matches!(r, Err(TrainError::L3(L3Error::Canceled))),
        "{:?}",
        r.err()
    );
}

#[test]
fn bad_specs_are_rejected() {
    let design = SensorDesign::paper_default();
    let cancel = AtomicBool::new(false);
    for spec in [
        TrainingSpec {
            patch_size: 4,
            ..tiny(1)
        },
        TrainingSpec {
            levels: 1,
            ..tiny(1)
        },
        TrainingSpec {
            scenes: 0,
            ..tiny(1)
        },
        TrainingSpec {
            illuminants: vec![],
            ..tiny(1)
        },
        TrainingSpec {
            illuminants: vec!["nonsense".into()],
            ..tiny(1)
        },
        TrainingSpec {
            mean_luminance: f64::NAN,
            ..tiny(1)
        },
    ] {
        assert!(train_table(&design, &spec, None, &|_, _| {}, &cancel).is_err());
    }
    let bad_json = r#"{"kind":"si","illuminants":["D65"],"bogus":1}"#;
    assert!(serde_json::from_str::<TrainingSpec>(bad_json).is_err());
}
