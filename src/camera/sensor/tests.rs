//! Unit tests of [`super`].

use super::*;

use crate::test_support::paper_camera as camera;

#[test]
fn fixed_patterns_are_positional_and_have_their_sigma() {
    let cam = camera();
    let (d1, p1) = cam.fixed_patterns(64, 80);
    let (d2, p2) = cam.fixed_patterns(100, 40);
    for r in 0..64 {
        for c in 0..40 {
            assert_eq!(d1[(r, c)], d2[(r, c)]);
            assert_eq!(p1[(r, c)], p2[(r, c)]);
        }
    }
    let (d, p) = cam.fixed_patterns(256, 256);
    let n = d.len() as f64;
    let sd = (d.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / n).sqrt();
    let sp = (p.iter().map(|v| (*v as f64 - 1.0).powi(2)).sum::<f64>() / n).sqrt();
    assert!((sd / 1.41e-3 - 1.0).abs() < 0.02, "dsnu σ {sd}");
    assert!((sp / 2.218e-3 - 1.0).abs() < 0.02, "prnu σ {sp}");
    // DSNU and PRNU are uncorrelated.
    let corr = d
        .iter()
        .zip(p.iter())
        .map(|(a, b)| *a as f64 * (*b as f64 - 1.0))
        .sum::<f64>()
        / n
        / (sd * sp);
    assert!(corr.abs() < 0.02, "corr {corr}");
    // Another sensor (seed) has another pattern.
    let mut other = SensorDesign::paper_default();
    other.fpn_seed = 2;
    let cam2 = Camera::new(&other, WavelengthGrid::default(), None).unwrap();
    assert_ne!(cam2.fixed_patterns(4, 4).0, cam.fixed_patterns(4, 4).0);
}

#[test]
fn capture_is_thread_count_independent() {
    let cam = camera();
    let rate = Array2::from_shape_fn((37, 29), |(r, c)| 1000.0 + 50.0 * (r + c) as f32);
    let a = cam.capture(&rate, 0.5, &NoiseSwitches::all(), 7).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let b = pool
        .install(|| cam.capture(&rate, 0.5, &NoiseSwitches::all(), 7))
        .unwrap();
    assert_eq!(a, b);
}

#[test]
fn noise_free_capture_is_the_mean_and_adc_quantises() {
    let mut d = SensorDesign::paper_default();
    let cam = Camera::new(&d, WavelengthGrid::default(), None).unwrap();
    let rate = Array2::from_elem((3, 4), 1.0e4f32);
    let v = cam.capture(&rate, 0.1, &NoiseSwitches::none(), 1).unwrap();
    // 1000 electrons × 200 µV.
    assert!(v.iter().all(|x| (*x - 0.2).abs() < 1e-6));
    d.adc_bits = Some(4);
    d.offset_v = 0.01;
    let cam = Camera::new(&d, WavelengthGrid::default(), None).unwrap();
    let v = cam.capture(&rate, 0.1, &NoiseSwitches::none(), 1).unwrap();
    // 0.21 V → code round(0.21/0.12) = 2 → 0.24 V.
    assert!(v.iter().all(|x| (*x - 0.24).abs() < 1e-6), "{v:?}");
}

#[test]
fn rejects_bad_capture_inputs() {
    let cam = camera();
    let ok = Array2::from_elem((2, 2), 1.0f32);
    assert!(cam.capture(&ok, -1.0, &NoiseSwitches::all(), 0).is_err());
    assert!(
        cam.capture(&ok, f64::NAN, &NoiseSwitches::all(), 0)
            .is_err()
    );
    let bad = Array2::from_elem((2, 2), f32::NAN);
    assert!(cam.capture(&bad, 1.0, &NoiseSwitches::all(), 0).is_err());
    let neg = Array2::from_elem((2, 2), -1.0f32);
    assert!(cam.capture(&neg, 1.0, &NoiseSwitches::all(), 0).is_err());
    let rates = Array3::from_elem((2, 2, 2), 1.0f32);
    assert!(mosaic(&rates, cam.cfa()).is_err());
    let rates4 = Array3::from_elem((4, 2, 2), 1.0f32);
    assert!(cam.auto_exposure(&rates4, cam.cfa(), 1.5).is_err());
    assert!(cam.auto_exposure(&rates4, cam.cfa(), 0.0).is_err());
    let empty = Array3::<f32>::zeros((4, 0, 0));
    assert!(cam.auto_exposure(&empty, cam.cfa(), 0.95).is_err());
}

#[test]
fn auto_exposure_hits_the_target() {
    let cam = camera();
    let mut rates = Array3::from_elem((4, 100, 100), 1000.0f32);
    // W (channel 2) is brighter; one hot pixel must not drive exposure.
    rates.index_axis_mut(ndarray::Axis(0), 2).fill(4000.0);
    rates[(2, 1, 0)] = 1e9;
    let t = cam.auto_exposure(&rates, cam.cfa(), 0.95).unwrap();
    let volts = (4000.0 * 200e-6 + 1e-5) * t;
    assert!((volts - 0.95 * 1.8).abs() < 1e-9, "{volts}");
    let dark = Array3::zeros((4, 8, 8));
    let t = cam.auto_exposure(&dark, cam.cfa(), 0.95).unwrap();
    assert!(t <= MAX_AUTO_EXPOSURE_S && t > 0.0);
}

#[test]
fn project_bins_subsamples() {
    let cube = Array3::from_shape_fn((2, 4, 6), |(b, r, c)| (b * 100 + r * 10 + c) as f32);
    let w = vec![vec![1.0, 0.0], vec![0.5, 1.0]];
    let out = project_cube(cube.view(), &w, 2);
    assert_eq!(out.dim(), (2, 2, 3));
    // Pixel (1, 2) of plane 0: mean of rows 2–3, cols 4–5 of band 0 = 29.5.
    assert!((out[(0, 1, 2)] - 29.5).abs() < 1e-6);
    assert!((out[(1, 0, 0)] - (0.5 * 5.5 + 105.5)).abs() < 1e-5);
    let same = project_cube(cube.view(), &w, 1);
    assert_eq!(same[(1, 3, 5)], 0.5 * 35.0 + 135.0);
}
