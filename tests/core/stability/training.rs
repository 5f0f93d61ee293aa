//! Degenerate training: too few, collinear or flat samples; dark, saturated and noisy scenes.

use std::sync::atomic::AtomicBool;

use l3::camera::{NoiseSwitches, SensorDesign};
use l3::l3::L3Params;
use l3::l3::learn::{TrainingFrame, TrainingSpec, train_table};
use l3::l3::params::RidgeChoice;
use l3::test_support::synthetic_frame;

use super::{
    camera_frames, check_table, flat_frame, learn_camera, learn_synthetic, package_synthetic,
    small_params,
};

#[test]
fn zero_samples_is_an_error() {
    let p = small_params();
    // no frames at all
    let e = learn_synthetic(&p, 0, |_| Ok(vec![])).err().unwrap();
    println!("0 frames: {e}");
    assert!(e.to_string().contains("no training frames"));
    // frames that hold no pixels
    let e = learn_synthetic(&p, 3, |_| {
        Ok(vec![TrainingFrame {
            width: 0,
            height: 0,
            volts: vec![],
            xyz: vec![],
            cfa_shift: (0, 0),
            neutral: None,
        }])
    })
    .err()
    .expect("an empty training set must be an error");
    println!("empty frames: {e}");
    assert!(e.to_string().contains("no samples"), "{e}");
    // frames whose buffers do not match their size are skipped, not indexed
    let e = learn_synthetic(&p, 2, |_| {
        Ok(vec![TrainingFrame {
            width: 8,
            height: 8,
            volts: vec![0.1; 10],
            xyz: vec![0.1; 30],
            cfa_shift: (0, 0),
            neutral: None,
        }])
    })
    .err()
    .expect("malformed frames give no samples");
    assert!(e.to_string().contains("no samples"), "{e}");
}

#[test]
fn non_finite_training_data_is_an_error() {
    let p = small_params();
    for (label, bad_volts) in [("NaN target", false), ("NaN volts", true)] {
        let r = learn_synthetic(&p, 4, |i| {
            let mut f = synthetic_frame(i as u64, 8, 0.3, 0.001, (i / 2, i % 2));
            if bad_volts {
                f.volts[9] = f32::NAN;
            } else {
                f.xyz[30] = f32::INFINITY;
            }
            Ok(vec![f])
        });
        match r {
            Err(e) => {
                println!("{label}: {e}");
                assert!(e.to_string().contains("non-finite"), "{e}");
            }
            Ok(l) => {
                check_table(label, &package_synthetic(&p, l));
            }
        }
    }
}

#[test]
fn a_saturation_case_missing_at_one_position_still_trains() {
    // Regression: the survey accepted a saturation case seen at some CFA
    // positions only; training then failed with "class (position 0, level 0,
    // case 1) has no samples at any level". Such classes now borrow the
    // samples of their fallback case with the case's channels zeroed.
    let t = l3::test_support::train_tiny_table().unwrap();
    println!("tiny table saturation cases: {:?}", t.meta.sat_cases);
    assert!(t.n_sat_cases() > 1);
    check_table("tiny synthetic table", &t);
}

#[test]
fn one_sample_per_position_gives_finite_kernels() {
    let p = small_params();
    // four 1×1 frames, one per CFA shift: one sample per position, one level
    let learned = learn_synthetic(&p, 4, |i| {
        Ok(vec![flat_frame(
            i as u64,
            1,
            [0.2, 0.25, 0.3],
            0.0,
            (i / 2, i % 2),
        )])
    })
    .unwrap();
    assert_eq!(learned.samples, 4);
    let t = package_synthetic(&p, learned);
    check_table("1 sample per position", &t);
    // a class of one sample has no varying regressor: an intercept-only
    // class, reported as such (condition 1, no active pixels), never `inf`
    assert!(t.reports.iter().all(|r| r.condition.is_finite()));
    assert!(
        t.reports
            .iter()
            .any(|r| r.active == Some(0) && r.note().is_some_and(|n| n.contains("intercept")))
    );
    // a 1×1 frame only has position 0: the other positions have no samples
    let e = learn_synthetic(&p, 1, |_| Ok(vec![flat_frame(0, 1, [0.2; 3], 0.0, (0, 0))]))
        .err()
        .expect("positions without samples must be an error");
    println!("1 sample, 1 position: {e}");
    assert!(e.to_string().contains("position 1"), "{e}");
}

#[test]
fn few_samples_give_finite_bounded_kernels() {
    let p = small_params();
    for size in [2usize, 3, 5] {
        let learned = learn_synthetic(&p, 4, |i| {
            Ok(vec![synthetic_frame(
                i as u64,
                size,
                0.3,
                0.002,
                (i / 2, i % 2),
            )])
        })
        .unwrap();
        let n = learned.samples;
        let t = package_synthetic(&p, learned);
        check_table(&format!("{n} samples ({size}×{size} frames)"), &t);
    }
}

#[test]
fn collinear_samples_give_finite_bounded_kernels() {
    let p = small_params();
    // flat frames of one grey at several exposures: every patch is a multiple
    // of one vector, noise-free (exactly collinear) and noisy
    for noise in [0.0f32, 1e-4] {
        let learned = learn_synthetic(&p, 12, |i| {
            let k = [0.002f32, 0.01, 0.05, 0.2, 0.6, 1.2][i % 6];
            Ok(vec![flat_frame(
                i as u64,
                8,
                [k, k, k],
                noise,
                ((i / 6) % 2, i % 2),
            )])
        })
        .unwrap();
        let t = package_synthetic(&p, learned);
        check_table(&format!("collinear (one grey, noise {noise} V)"), &t);
    }
}

#[test]
fn flat_only_training_scenes() {
    let p = L3Params {
        patch_size: 5,
        ..small_params()
    };
    // every frame a single colour (no texture anywhere), realistic noise
    let learned = learn_synthetic(&p, 24, |i| {
        let mut s = i as u64 * 7 + 3;
        let mut r = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let y = [0.003f32, 0.02, 0.1, 0.4, 1.0, 1.6][i % 6] * (0.7 + 0.3 * r());
        let xyz = [y * (0.6 + 0.6 * r()), y, y * (0.5 + 0.8 * r())];
        Ok(vec![flat_frame(
            i as u64,
            12,
            xyz,
            1.5e-3,
            ((i / 6) % 2, (i / 12) % 2),
        )])
    })
    .unwrap();
    let t = package_synthetic(&p, learned);
    check_table("flat-only scenes", &t);
}

#[test]
fn very_dark_scenes() {
    // median pixel at 0.5 mV: below read noise and DSNU (1.34, 1.41 mV)
    let design = SensorDesign::paper_default();
    let p = small_params();
    let t = learn_camera(&p, &design, 4, |i| {
        camera_frames(&design, i, 24, 5e-4, &NoiseSwitches::all())
    })
    .unwrap();
    let max_v = (0..4)
        .flat_map(|i| camera_frames(&design, i, 24, 5e-4, &NoiseSwitches::none()))
        .flat_map(|f| f.volts)
        .fold(0f32, f32::max);
    println!(
        "very dark: brightest noise-free pixel {:.3} mV",
        max_v * 1e3
    );
    check_table("very dark (median 0.5 mV)", &t);
    // every sample sits at the lowest levels; the rest were filled
    assert!(t.reports.iter().any(|r| r.filled_from >= 0));
}

#[test]
fn fully_saturated_scenes_are_an_error_and_mostly_saturated_train() {
    let design = SensorDesign::paper_default();
    let p = small_params();
    // every pixel at the swing: no unsaturated sample exists anywhere
    let r = learn_camera(&p, &design, 2, |i| {
        camera_frames(&design, i, 16, 1e3, &NoiseSwitches::none())
    });
    match r {
        Err(e) => {
            println!("fully saturated: {e}");
            assert!(e.to_string().contains("no samples"), "{e}");
        }
        Ok(t) => {
            check_table("fully saturated", &t);
        }
    }
    // heavily over-exposed, noisy: saturated cases dominate, but train
    let t = learn_camera(&p, &design, 4, |i| {
        camera_frames(
            &design,
            i,
            24,
            [0.5, 2.0, 4.0, 8.0][i % 4],
            &NoiseSwitches::all(),
        )
    })
    .unwrap();
    println!("over-exposed saturation cases: {:?}", t.meta.sat_cases);
    assert!(t.n_sat_cases() > 1);
    check_table("over-exposed (median 0.5–8 V)", &t);
}

#[test]
fn extreme_read_noise_trains_through_the_public_api() {
    let mut design = SensorDesign::paper_default();
    design.read_noise_mv *= 100.0; // 134 mV
    let spec = TrainingSpec {
        illuminants: vec!["D65".into()],
        patch_size: 3,
        levels: 4,
        scenes: 2,
        scene_size: 16,
        seed: 9,
        ..TrainingSpec::default()
    };
    let t = train_table(&design, &spec, None, &|_, _| {}, &AtomicBool::new(false)).unwrap();
    check_table("read noise ×100 (train_table)", &t);
    // the noise-variance ridge (noise-free patches) with the same model
    let spec = TrainingSpec {
        noise: false,
        ..spec
    };
    let t = train_table(&design, &spec, None, &|_, _| {}, &AtomicBool::new(false)).unwrap();
    check_table("read noise ×100, noise-variance ridge", &t);
    // synthetic: noise of ±0.5 V on a 1.8 V swing
    let p = small_params();
    let learned = learn_synthetic(&p, 12, |i| {
        Ok(vec![synthetic_frame(
            i as u64,
            16,
            [0.01f32, 0.2, 1.0][i % 3],
            0.5,
            (i % 2, (i / 2) % 2),
        )])
    })
    .unwrap();
    check_table("synthetic noise ±0.5 V", &package_synthetic(&p, learned));
}

#[test]
fn every_ridge_choice_survives_degenerate_classes() {
    for ridge in [
        RidgeChoice::Gcv,
        RidgeChoice::Fixed { relative: 0.0 },
        RidgeChoice::Fixed { relative: 1e6 },
        RidgeChoice::NoiseVariance,
    ] {
        let p = L3Params {
            ridge,
            ..small_params()
        };
        let learned = learn_synthetic(&p, 4, |i| {
            Ok(vec![flat_frame(
                i as u64,
                3,
                [0.3, 0.3, 0.3],
                0.0,
                (i / 2, i % 2),
            )])
        })
        .unwrap();
        check_table(
            &format!("collinear, {ridge:?}"),
            &package_synthetic(&p, learned),
        );
    }
    // a negative relative ridge is refused up front
    let p = L3Params {
        ridge: RidgeChoice::Fixed { relative: -1.0 },
        ..small_params()
    };
    assert!(learn_synthetic(&p, 1, |_| Ok(vec![])).is_err());
}
