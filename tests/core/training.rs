//! Training from the simulator: bit-for-bit reproducible whatever the
//! thread count or the sharding, cancellable, and every table finite with
//! bounded kernels.

use std::sync::atomic::{AtomicBool, Ordering};

use l3::camera::SensorDesign;
use l3::l3::L3Table;
use l3::l3::learn::{
    Classes, GramPartial, LearnError, SurveyPartial, TrainingRun, TrainingSpec, train_table,
};
use l3::l3::table::TableKind;

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
    // each training light's white, recorded beside its name: D65's and A's
    let w = &a.meta.train_white_xy;
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(
        (w[0][0] - 0.3127).abs() < 2e-3 && (w[0][1] - 0.3290).abs() < 2e-3,
        "{w:?}"
    );
    assert!(
        (w[1][0] - 0.4476).abs() < 2e-3 && (w[1][1] - 0.4074).abs() < 2e-3,
        "{w:?}"
    );
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
    assert!(matches!(r, Err(LearnError::Canceled)), "{:?}", r.err());
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

/// A table's bytes with its time stamps zeroed: what two equal runs share.
fn table_bytes(mut t: L3Table) -> Vec<u8> {
    t.meta.created_unix_s = 0;
    t.meta.training_seconds = 0.0;
    t.to_bytes().unwrap()
}

/// The shards of `run`, each partial written to bytes and read back, the
/// shards taken in reverse order (the merge orders them).
fn shard_parts(run: &TrainingRun, n: usize) -> (Vec<SurveyPartial>, Classes, Vec<GramPartial>) {
    let cancel = AtomicBool::new(false);
    let plan = run.plan(n).unwrap();
    let surveys: Vec<SurveyPartial> = plan
        .iter()
        .rev()
        .map(|s| {
            let part = run.survey_shard(s, &|_, _| {}, &cancel).unwrap();
            SurveyPartial::from_bytes(&part.to_bytes().unwrap()).unwrap()
        })
        .collect();
    let classes = run.classes(&surveys).unwrap();
    let sums = plan
        .iter()
        .rev()
        .map(|s| {
            let part = run
                .accumulate_shard(s, &classes, &|_, _| {}, &cancel)
                .unwrap();
            GramPartial::from_bytes(&part.to_bytes().unwrap()).unwrap()
        })
        .collect();
    (surveys, classes, sums)
}

#[test]
fn sharded_training_gives_the_single_run_table_byte_for_byte() {
    let design = SensorDesign::paper_default();
    let cancel = AtomicBool::new(false);
    let quiet = |_: &str, _: f64| {};
    let spec = tiny(3);
    let single = train_table(&design, &spec, None, &quiet, &cancel).unwrap();
    let single_bytes = table_bytes(single);
    let run = TrainingRun::new(&design, &spec, None).unwrap();
    assert_eq!(
        table_bytes(run.train(&quiet, &cancel).unwrap()),
        single_bytes,
        "equal runs give equal bytes"
    );
    for n in [2, 3] {
        let (surveys, classes, sums) = shard_parts(&run, n);
        let table = run.finish(classes.clone(), sums.clone(), &quiet, &cancel);
        assert_eq!(table_bytes(table.unwrap()), single_bytes, "{n} shards");

        // a missing, doubled or foreign shard is refused
        assert!(run.classes(&surveys[1..]).is_err());
        let missing = sums[1..].to_vec();
        assert!(
            run.finish(classes.clone(), missing, &quiet, &cancel)
                .is_err()
        );
        let mut doubled = sums.clone();
        doubled.push(sums[0].clone());
        assert!(
            run.finish(classes.clone(), doubled, &quiet, &cancel)
                .is_err()
        );
        let mut foreign = sums.clone();
        foreign[0].run_key = "another run".into();
        assert!(
            run.finish(classes.clone(), foreign, &quiet, &cancel)
                .is_err()
        );
        let mut other_classes = classes.clone();
        other_classes.thresholds[0] *= 2.0;
        assert!(run.finish(other_classes, sums, &quiet, &cancel).is_err());
    }
    assert!(run.plan(0).is_err());
    assert!(run.plan(spec.scenes + 1).is_err());
}

#[test]
fn the_colour_loss_defaults_by_illuminant_count_and_is_recorded_in_the_table() {
    use l3::l3::params::ColourLoss;
    let design = SensorDesign::paper_default();
    let cancel = AtomicBool::new(false);
    let one_light = TrainingSpec {
        illuminants: vec!["Tungsten".into()],
        ..tiny(3)
    };
    assert_eq!(one_light.colour_loss(), ColourLoss::MeanDeltaE);
    assert_eq!(tiny(3).colour_loss(), ColourLoss::SquaredDeltaE);
    let recorded = |t: &L3Table| t.meta.params.colour_map.map(|f| f.loss);
    let mean = train_table(&design, &one_light, None, &|_, _| {}, &cancel).unwrap();
    assert_eq!(recorded(&mean), Some(ColourLoss::MeanDeltaE));
    let squared_spec = TrainingSpec {
        colour_loss: Some(ColourLoss::SquaredDeltaE),
        ..one_light.clone()
    };
    let squared = train_table(&design, &squared_spec, None, &|_, _| {}, &cancel).unwrap();
    assert_eq!(recorded(&squared), Some(ColourLoss::SquaredDeltaE));
    assert_ne!(
        mean.kernels, squared.kernels,
        "the loss changes the colour maps"
    );
    assert!(squared.kernels.iter().all(|v| v.is_finite()));
    // a spec names the loss in kebab case, and an unknown one is refused
    let json = serde_json::to_value(&squared_spec).unwrap();
    assert_eq!(json["colour_loss"], "squared-delta-e");
    let mut bad = json.clone();
    bad["colour_loss"] = "median".into();
    assert!(serde_json::from_value::<TrainingSpec>(bad).is_err());
}

/// Per texture class of the unsaturated case, the sum over outputs and channels of the
/// absolute channel sums of its kernel: how strongly it weighs the channels against each
/// other on a uniform patch.
fn texture_channel_weight(t: &L3Table) -> f64 {
    let geo = t.geometry().unwrap();
    let nf = t.n_features();
    let mut total = 0.0;
    for pos in 0..t.n_positions() {
        for band in 0..t.n_bands() {
            let kernel = t.kernel(t.class_index(pos, band, 0, true));
            for out in kernel.chunks_exact(nf).take(3) {
                let mut sums = vec![0.0f64; geo.n_channels()];
                for (&c, &w) in geo.channels_of(pos).iter().zip(out) {
                    sums[c as usize] += f64::from(w);
                }
                total += sums.iter().map(|s| s.abs()).sum::<f64>();
            }
        }
    }
    total
}

#[test]
fn texture_classes_take_their_own_colour_maps_and_flat_classes_keep_theirs() {
    let design = SensorDesign::paper_default();
    let cancel = AtomicBool::new(false);
    let shared = TrainingSpec {
        texture_colour_averaging_px: None,
        ..tiny(3)
    };
    let own = TrainingSpec {
        texture_colour_averaging_px: Some(4.0),
        ..tiny(3)
    };
    let a = train_table(&design, &shared, None, &|_, _| {}, &cancel).unwrap();
    let b = train_table(&design, &own, None, &|_, _| {}, &cancel).unwrap();
    assert_eq!(a.meta.params.texture_averaging_px, None);
    assert_eq!(b.meta.params.texture_averaging_px, Some(4.0));
    // the flat classes (what a uniform patch renders with) are the same kernels
    let mut texture_differs = false;
    for pos in 0..a.n_positions() {
        for band in 0..a.n_bands() {
            let (flat, tex) = (
                a.class_index(pos, band, 0, false),
                a.class_index(pos, band, 0, true),
            );
            assert_eq!(a.kernel(flat), b.kernel(flat), "flat class {pos}/{band}");
            texture_differs |= a.kernel(tex) != b.kernel(tex);
        }
    }
    assert!(texture_differs);
    // maps fitted for 4 pixels' noise weigh the channels against each other less
    let (wa, wb) = (texture_channel_weight(&a), texture_channel_weight(&b));
    assert!(wb < 0.95 * wa, "texture channel weights {wb} against {wa}");
}
