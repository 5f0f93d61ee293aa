//! Numerical stability under degenerate conditions (issue 6, DESIGN.md §11).
//!
//! Training: classes with 0, 1, few and collinear samples; flat-only scenes;
//! extreme noise; very dark and fully saturated scenes; near-monochromatic
//! (LED) illuminants for T; f32 against f64 accumulation. Every resulting
//! table is finite, kernel norms stay under [`KERNEL_NORM_BOUND`] (the max is
//! printed), condition numbers are printed, nothing panics, and an error is
//! returned where an error is the right answer.
//!
//! Rendering: NaN/Inf, negative and above-white input; all-zero and
//! all-saturated frames; 1×1, one-row, one-column and odd sizes; the widest
//! allowed rows; the pixel limit. Each gets a clear error or a finite output.
//!
//! Run with `--nocapture` to see the measured numbers.

// Index loops read best in numeric code (as in the library).
#![allow(clippy::needless_range_loop)]

use crate::iset_reference;

use std::sync::atomic::AtomicBool;

use l3::camera::{Camera, NoiseSwitches, SensorDesign, mosaic};
use l3::colour::{Cmfs, D65_WHITE_XYZ, ciede2000, xyz_to_lab};
use l3::io::{Limits, RawMeta, decode_mosaic, decode_raw_u16_le};
use l3::l3::classify::PatchGeometry;
use l3::l3::correct::{IDENTITY, NoiseModel, correction_matrix, default_reflectances};
use l3::l3::learn::{
    LearnError, Learned, TrainControl, TrainingFrame, TrainingScenes, TrainingSpec, learn, package,
    train_table,
};
use l3::l3::params::RidgeChoice;
use l3::l3::render::{fuse_kernels, render_reference};
use l3::l3::{L3Params, L3Table};
use l3::spectral::{Extrapolation, Spectrum, WavelengthGrid, cie_illuminant};
use l3::test_support::{
    synthetic_channel, synthetic_frame, synthetic_meta, synthetic_volts, tiny_table,
};
use nalgebra::{DMatrix, DVector};

/// Every kernel's Frobenius norm (3 outputs × patch + constant) stays below
/// this. Kernels map volts to volts-equivalent XYZ, so sensible weights are
/// O(1) per pixel; the ridge floor keeps degenerate classes far below it.
const KERNEL_NORM_BOUND: f64 = 1e3;

fn ctl_parts() -> AtomicBool {
    AtomicBool::new(false)
}

fn noise_model() -> NoiseModel {
    NoiseModel {
        conversion_gain_v: 2e-4,
        read_noise_v: 1.34e-3,
        dsnu_v: 1.41e-3,
        prnu_fraction: 0.002218,
    }
}

fn small_params() -> L3Params {
    L3Params {
        patch_size: 3,
        levels: L3Params::levels_for(6, 1.8).unwrap(),
        min_class_samples: 40,
        ..L3Params::default()
    }
}

/// Learn from synthetic `RG/WB` frames produced by `frames(i)` (the paper's noise).
fn learn_synthetic<F>(params: &L3Params, n: usize, frames: F) -> Result<Learned, LearnError>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, LearnError> + Sync,
{
    l3::test_support::learn_synthetic(params, noise_model(), n, frames)
}

/// Checks a table: finite kernels, bounded norms; prints norms and
/// condition numbers. Returns the largest kernel norm.
fn check_table(name: &str, t: &L3Table) -> f64 {
    t.validate().unwrap();
    assert!(
        t.kernels.iter().all(|v| v.is_finite()),
        "{name}: non-finite kernel"
    );
    let nf = t.n_features();
    let norms: Vec<f64> = t
        .kernels
        .chunks_exact(3 * nf)
        .map(|k| k.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt())
        .collect();
    let max_norm = norms.iter().copied().fold(0.0, f64::max);
    for (r, n) in t.reports.iter().zip(&norms) {
        assert!(r.kernel_norm.is_finite() && r.lambda.is_finite() && r.lambda > 0.0);
        assert!((r.kernel_norm - n).abs() <= 1e-3 * (1.0 + n), "report norm");
        assert!(!r.condition.is_nan());
    }
    let mut conds: Vec<f64> = t.reports.iter().map(|r| r.condition).collect();
    conds.sort_by(f64::total_cmp);
    let finite: Vec<f64> = conds.iter().copied().filter(|c| c.is_finite()).collect();
    let infinite = conds.len() - finite.len();
    let filled = t.reports.iter().filter(|r| r.filled_from >= 0).count();
    println!(
        "{name}: {} classes, {} sat cases, max kernel norm {max_norm:.4}, condition min {:.3e} median {:.3e} max {:.3e} ({infinite} singular), {filled} filled from other levels",
        t.n_classes(),
        t.n_sat_cases(),
        finite.first().copied().unwrap_or(f64::NAN),
        conds[conds.len() / 2],
        finite.last().copied().unwrap_or(f64::NAN),
    );
    assert!(
        max_norm < KERNEL_NORM_BOUND,
        "{name}: kernel norm {max_norm} ≥ {KERNEL_NORM_BOUND}"
    );
    // the table renders a textured frame to finite values
    let f = synthetic_frame(77, 16, 0.3, 0.01, (0, 0));
    let (xyz, _) = render_reference(t, &t.kernels, &f.volts, 16, 16).unwrap();
    assert!(xyz.iter().all(|v| v.is_finite()), "{name}: NaN in render");
    max_norm
}

fn package_synthetic(params: &L3Params, learned: Learned) -> L3Table {
    package(synthetic_meta(params).unwrap(), learned).unwrap()
}

/// A constant-colour (flat) synthetic frame: every pixel of a channel has the
/// same value (plus optional noise), so the patches of a frame are collinear.
fn flat_frame(
    seed: u64,
    size: usize,
    xyz: [f32; 3],
    noise: f32,
    shift: (usize, usize),
) -> TrainingFrame {
    let mut f = synthetic_frame(seed, size, 1.0, 0.0, shift);
    // rebuild the volts from one colour
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    for r in 0..size {
        for c in 0..size {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let n = ((s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * noise;
            f.volts[r * size + c] = synthetic_volts(synthetic_channel(r, c, shift), xyz, n);
            f.xyz[(r * size + c) * 3..(r * size + c) * 3 + 3].copy_from_slice(&xyz);
        }
    }
    f
}

// ---------------------------------------------------------------- training

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

/// Frames of one training scene through the paper's camera, with the median
/// noise-free pixel at `median_volts`, at every CFA shift (as `train_table`
/// builds them). `noise` selects the noise sources.
fn camera_frames(
    design: &SensorDesign,
    scene_index: usize,
    size: usize,
    median_volts: f64,
    noise: &NoiseSwitches,
) -> Vec<TrainingFrame> {
    let grid = WavelengthGrid::default();
    let camera = Camera::new(design, grid, None).unwrap();
    let d65 = cie_illuminant("D65")
        .unwrap()
        .resample(&grid, Extrapolation::Zero);
    let scenes = TrainingScenes::new(grid, None, 5, size, 100.0).unwrap();
    let scene = scenes.scene(scene_index, &d65, "D65").unwrap();
    let optical = camera.optical_image(&scene).unwrap();
    let rates = camera.channel_rates(&optical).unwrap();
    let xyz_rates = camera.xyz_rates(&optical, &d65).unwrap();
    let xyz_rates = xyz_rates.as_slice().unwrap().to_vec();
    let (nch, rows, cols) = rates.dim();
    let mut lum: Vec<f32> = (0..rows * cols)
        .map(|p| {
            (0..nch)
                .map(|ch| rates[[ch, p / cols, p % cols]])
                .sum::<f32>()
                / nch as f32
        })
        .collect();
    lum.sort_by(f32::total_cmp);
    let median_rate =
        lum[lum.len() / 2].max(1e-3) as f64 * design.conversion_gain_v() * design.analog_gain;
    let exposure = median_volts / median_rate;
    let cfa = camera.cfa().clone();
    (0..cfa.n_positions())
        .map(|shift| {
            let (dr, dc) = (shift / cfa.cols, shift % cfa.cols);
            let mean = mosaic(&rates, &cfa.shifted(dr, dc)).unwrap();
            let seed = (scene_index * 16 + shift) as u64;
            let volts = camera.capture(&mean, exposure, noise, seed).unwrap();
            TrainingFrame {
                width: cols,
                height: rows,
                volts: volts.into_raw_vec_and_offset().0,
                xyz: xyz_rates.iter().map(|v| v * exposure as f32).collect(),
                cfa_shift: (dr, dc),
                neutral: None,
            }
        })
        .collect()
}

fn learn_camera(
    params: &L3Params,
    design: &SensorDesign,
    n: usize,
    frames: impl Fn(usize) -> Vec<TrainingFrame> + Sync,
) -> Result<L3Table, LearnError> {
    let grid = WavelengthGrid::default();
    let camera = Camera::new(design, grid, None).unwrap();
    let geo = PatchGeometry::new(
        params.patch_size,
        camera.cfa(),
        &params.levels,
        design.voltage_swing_v - params.saturation_margin_v,
    )?;
    let cancel = ctl_parts();
    let ctl = TrainControl {
        progress: &|_, _| {},
        cancel: &cancel,
    };
    let nm = NoiseModel {
        conversion_gain_v: design.conversion_gain_v(),
        read_noise_v: design.read_noise_v(),
        dsnu_v: design.dsnu_v(),
        prnu_fraction: design.prnu_fraction(),
    };
    let learned = learn(&geo, params, nm, n, |i| Ok(frames(i)), None, &ctl)?;
    let mut meta = synthetic_meta(params).unwrap();
    meta.cfa = camera.cfa().clone();
    meta.voltage_swing = design.voltage_swing_v;
    meta.saturation_threshold = design.voltage_swing_v - params.saturation_margin_v;
    package(meta, learned)
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

// ------------------------------------------------ f32 against f64 accumulation

/// Ridge solution (λ relative to the mean eigenvalue) from raw sums
/// Σxxᵀ, Σxy, Σx, Σy, n — the same algebra for both precisions.
fn solve_from_sums(
    sxx: &DMatrix<f64>,
    sxy: &DMatrix<f64>,
    sx: &DVector<f64>,
    sy: &DVector<f64>,
    n: f64,
) -> (DMatrix<f64>, f64) {
    let mx = sx / n;
    let my = sy / n;
    let cxx = sxx / n - &mx * mx.transpose();
    let cxy = sxy / n - &mx * my.transpose();
    let eig = cxx.clone().symmetric_eigen();
    let emax = eig.eigenvalues.max();
    let emin = eig.eigenvalues.min();
    let cond = emax / emin.abs().max(emax * 1e-16);
    let lam = 1e-6 * eig.eigenvalues.iter().map(|e| e.max(0.0)).sum::<f64>()
        / eig.eigenvalues.len() as f64;
    let a = cxx + DMatrix::identity(mx.len(), mx.len()) * lam;
    let w = a
        .cholesky()
        .map(|c| c.solve(&cxy))
        .unwrap_or_else(|| DMatrix::from_element(mx.len(), 3, f64::NAN));
    (w, cond)
}

#[test]
fn f64_accumulation_is_needed_on_an_ill_conditioned_class() {
    // one class of a realistic scene: 5×5 patches at a bright level (median
    // 0.9 V) where the signal varies by a few mV around a large mean — the
    // centred covariance is a small difference of large sums.
    let design = SensorDesign::paper_default();
    let mut frames = Vec::new();
    for s in 0..6 {
        frames.extend(camera_frames(
            &design,
            s + 1,
            64,
            0.9,
            &NoiseSwitches::all(),
        ));
    }
    let cfa = l3::camera::Cfa::parse("RG/WB").unwrap();
    let levels = L3Params::default().levels;
    let geo = PatchGeometry::new(5, &cfa, &levels, 1.799).unwrap();
    let p = 25;
    let mut s64 = (
        DMatrix::<f64>::zeros(p, p),
        DMatrix::<f64>::zeros(p, 3),
        DVector::<f64>::zeros(p),
        DVector::<f64>::zeros(3),
    );
    let mut s32 = (
        DMatrix::<f32>::zeros(p, p),
        DMatrix::<f32>::zeros(p, 3),
        DVector::<f32>::zeros(p),
        DVector::<f32>::zeros(3),
    );
    let mut n = 0u64;
    let mut patch = vec![0f32; p];
    let target_level = geo.level_of(0.9);
    // a big class streams ~10⁵ samples: pass over the frames 64 times
    for f in frames.iter().cycle().take(frames.len() * 64) {
        for r in 0..f.height {
            for c in 0..f.width {
                geo.gather(&f.volts, f.width, f.height, r, c, &mut patch);
                let pos = geo.position(r + f.cfa_shift.0, c + f.cfa_shift.1);
                let st = geo.stats(&patch, pos);
                // one class: position 0 (R), the 0.9 V level, unsaturated
                if pos != 0 || st.sat_mask != 0 || geo.level_of(st.luminance) != target_level {
                    continue;
                }
                let y = &f.xyz[(r * f.width + c) * 3..(r * f.width + c) * 3 + 3];
                for i in 0..p {
                    for j in 0..p {
                        s64.0[(i, j)] += patch[i] as f64 * patch[j] as f64;
                        s32.0[(i, j)] += patch[i] * patch[j];
                    }
                    for k in 0..3 {
                        s64.1[(i, k)] += patch[i] as f64 * y[k] as f64;
                        s32.1[(i, k)] += patch[i] * y[k];
                    }
                    s64.2[i] += patch[i] as f64;
                    s32.2[i] += patch[i];
                }
                for k in 0..3 {
                    s64.3[k] += y[k] as f64;
                    s32.3[k] += y[k];
                }
                n += 1;
            }
        }
    }
    assert!(n > 500 * 64, "class has {n} samples");
    let (w64, cond64) = solve_from_sums(&s64.0, &s64.1, &s64.2, &s64.3, n as f64);
    let up = |m: &DMatrix<f32>| m.map(|v| v as f64);
    let (w32, cond32) = solve_from_sums(
        &up(&s32.0),
        &up(&s32.1),
        &s32.2.map(|v| v as f64),
        &s32.3.map(|v| v as f64),
        n as f64,
    );
    let rel = if w32.iter().all(|v| v.is_finite()) {
        (&w32 - &w64).norm() / w64.norm()
    } else {
        f64::INFINITY
    };
    println!(
        "f32 vs f64 accumulation: {n} samples, condition f64 {cond64:.3e}, f32 {cond32:.3e}, relative kernel difference {rel:.3e}, kernel norm f64 {:.4}",
        w64.norm()
    );
    assert!(w64.iter().all(|v| v.is_finite()));
    // f32 sums lose the small centred covariance: the kernels differ
    assert!(rel > 1e-4, "f32 accumulation was harmless here ({rel:.3e})");
}

// ------------------------------------------------------- LED illuminants for T

#[test]
fn led_illuminants_give_finite_bounded_t() {
    // every ISET LED light: reference data beyond the built-in set
    let Some(iset) = iset_reference::iset_dir("led_illuminants_give_finite_bounded_t") else {
        return;
    };
    let grid = WavelengthGrid::default();
    let cmfs = Cmfs::cie1931(&grid);
    let refl = default_reflectances(&grid);
    let d65 = cie_illuminant("D65")
        .unwrap()
        .resample(&grid, Extrapolation::Zero);
    let d65_white = cmfs.white(&d65).unwrap();
    let mut tried = 0;
    for name in iset.light_names() {
        if !name.to_ascii_lowercase().contains("led") {
            continue;
        }
        let table = iset.table(&format!("lights/{name}.csv")).unwrap();
        for (col, samples) in table.all().unwrap() {
            let spd = samples.resample(&grid, Extrapolation::Zero);
            tried += 1;
            let label = format!("{name}:{col}");
            match correction_matrix(&cmfs, &refl, &spd, &d65, false) {
                Ok(t) => {
                    assert!(t.iter().flatten().all(|v| v.is_finite()), "{label}");
                    let m = nalgebra::Matrix3::from_fn(|i, j| t[i][j]);
                    let sv = m.singular_values();
                    let cond = sv.max() / sv.min();
                    let norm = m.norm();
                    // ΔE2000 of T alone over the reflectances
                    let white = cmfs.white(&spd).unwrap();
                    let mut de = Vec::new();
                    for r in &refl {
                        let xa = cmfs.reflectance_xyz(r, &spd).unwrap();
                        let xt = cmfs.reflectance_xyz(r, &d65).unwrap();
                        let _ = white;
                        let mapped = l3::colour::mat3_mul_vec(&t, xa);
                        de.push(ciede2000(
                            xyz_to_lab(mapped, D65_WHITE_XYZ),
                            xyz_to_lab(xt, d65_white),
                        ));
                    }
                    de.sort_by(f64::total_cmp);
                    let mean = de.iter().sum::<f64>() / de.len() as f64;
                    println!(
                        "T({label}): ‖T‖ {norm:.3}, cond {cond:.3e}, ΔE2000 of T alone mean {mean:.2}, p90 {:.2}, max {:.2}",
                        de[de.len() * 9 / 10],
                        de[de.len() - 1]
                    );
                    assert!(norm < KERNEL_NORM_BOUND, "{label}: ‖T‖ = {norm}");
                    assert!(de.iter().all(|d| d.is_finite()));
                    // fused kernels stay finite
                    let fused = fuse_kernels(tiny_table(), &t);
                    assert!(fused.iter().all(|v| v.is_finite()));
                }
                Err(e) => {
                    println!("T({label}): error: {e}");
                    assert!(!e.to_string().is_empty());
                }
            }
        }
    }
    assert!(tried >= 2, "no LED lights found");
    // D65 itself is the identity
    let t = correction_matrix(&cmfs, &refl, &d65, &d65, false).unwrap();
    for i in 0..3 {
        for j in 0..3 {
            assert!((t[i][j] - IDENTITY[i][j]).abs() < 1e-9);
        }
    }
}

#[test]
fn degenerate_illuminants_for_t_are_errors() {
    let grid = WavelengthGrid::default();
    let cmfs = Cmfs::cie1931(&grid);
    let refl = default_reflectances(&grid);
    let d65 = cie_illuminant("D65")
        .unwrap()
        .resample(&grid, Extrapolation::Zero);
    // all-zero light, and a single-band spike (every surface's XYZ is on one line)
    let zero = Spectrum::constant(grid, 0.0);
    let e = correction_matrix(&cmfs, &refl, &zero, &d65, false).unwrap_err();
    println!("zero SPD: {e}");
    let spike = Spectrum::from_fn(grid, |w| if (w - 550.0).abs() < 1.0 { 1.0 } else { 0.0 });
    match correction_matrix(&cmfs, &refl, &spike, &d65, false) {
        Err(e) => println!("single-band spike: {e}"),
        Ok(t) => {
            let n = t.iter().flatten().map(|v| v * v).sum::<f64>().sqrt();
            println!("single-band spike: ‖T‖ = {n:.3e}");
            assert!(t.iter().flatten().all(|v| v.is_finite()));
            assert!(n < KERNEL_NORM_BOUND, "‖T‖ = {n}");
        }
    }
    // too few reflectances
    assert!(correction_matrix(&cmfs, &refl[..2], &d65, &d65, false).is_err());
}

// --------------------------------------------------------------- rendering

fn assert_finite(label: &str, xyz: &[f32]) {
    if let Some(i) = xyz.iter().position(|v| !v.is_finite()) {
        panic!("{label}: pixel {} is {}", i / 3, xyz[i]);
    }
}

#[test]
fn non_finite_input_is_a_clear_error() {
    let t = tiny_table();
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut v = vec![0.3f32; 6 * 5];
        v[2 * 6 + 4] = bad;
        let e = render_reference(t, &t.kernels, &v, 6, 5)
            .unwrap_err()
            .to_string();
        println!("{bad}: {e}");
        assert!(
            e.contains("row 2, column 4") && e.contains("not finite"),
            "{e}"
        );
    }
}

#[test]
fn out_of_range_input_is_clamped_and_counted() {
    let t = tiny_table();
    let swing = t.meta.voltage_swing as f32;
    let mut v: Vec<f32> = (0..64).map(|i| i as f32 / 64.0).collect();
    v[3] = -1.0;
    v[10] = -f32::MAX;
    v[20] = swing * 1.5;
    v[30] = f32::MAX;
    v[40] = f32::MIN_POSITIVE;
    let (xyz, st) = render_reference(t, &t.kernels, &v, 8, 8).unwrap();
    assert_eq!(st.clamped, 4);
    assert_finite("out of range", &xyz);
    // clamping is exactly rendering the clamped frame
    let c: Vec<f32> = v.iter().map(|x| x.clamp(0.0, swing)).collect();
    let (xyz2, _) = render_reference(t, &t.kernels, &c, 8, 8).unwrap();
    assert_eq!(xyz, xyz2);
}

#[test]
fn all_zero_and_all_saturated_frames_are_finite() {
    let t = tiny_table();
    let swing = t.meta.voltage_swing as f32;
    for (label, v) in [
        ("zero", 0.0f32),
        ("saturated", swing),
        ("beyond white", 10.0 * swing),
    ] {
        let (xyz, st) = render_reference(t, &t.kernels, &vec![v; 16 * 12], 16, 12).unwrap();
        assert_finite(label, &xyz);
        println!("{label}: first pixel XYZ {:?}, stats {st:?}", &xyz[..3]);
        // a uniform frame renders the same colour at every pixel of one CFA position
        for r in 2..10 {
            for c in 2..14 {
                let (a, b) = ((r * 16 + c) * 3, (((r % 2) + 2) * 16 + (c % 2) + 2) * 3);
                for k in 0..3 {
                    assert!((xyz[a + k] - xyz[b + k]).abs() <= 1e-4 * (1.0 + xyz[b + k].abs()));
                }
            }
        }
    }
    // a saturated frame through a table with saturation cases
    let design = SensorDesign::paper_default();
    let p = small_params();
    let ts = learn_camera(&p, &design, 4, |i| {
        camera_frames(
            &design,
            i,
            24,
            [0.5, 2.0, 4.0, 8.0][i % 4],
            &NoiseSwitches::none(),
        )
    })
    .unwrap();
    let (xyz, st) = render_reference(&ts, &ts.kernels, &vec![1.8; 10 * 10], 10, 10).unwrap();
    assert_finite("saturated, table with saturation cases", &xyz);
    println!(
        "all-saturated frame, sat cases {:?}: {st:?}",
        ts.meta.sat_cases
    );
    assert_eq!(st.pixels, 100);
    // every channel saturated: no such case, every pixel falls back
    assert_eq!(st.fallback, 100);
}

#[test]
fn tiny_and_odd_sizes_render_finite() {
    let t = tiny_table();
    for (w, h) in [
        (1, 1),
        (1, 2),
        (2, 1),
        (7, 1),
        (1, 7),
        (3, 5),
        (5, 3),
        (2, 2),
        (9, 4),
        (13, 11),
    ] {
        let v: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 100) as f32 / 60.0).collect();
        let (xyz, st) = render_reference(t, &t.kernels, &v, w, h).unwrap();
        assert_eq!(xyz.len(), w * h * 3);
        assert_eq!(st.pixels as usize, w * h);
        assert_finite(&format!("{w}×{h}"), &xyz);
    }
    // size mismatches are errors
    assert!(render_reference(t, &t.kernels, &[0.1; 5], 2, 3).is_err());
    assert!(render_reference(t, &t.kernels, &[], 0, 4).is_err());
    assert!(render_reference(t, &t.kernels, &[0.1; 4], 2, 2).is_ok());
    assert!(render_reference(t, &t.kernels[..10], &[0.1; 4], 2, 2).is_err());
    // 5×5 and 9×9 patches on frames smaller than the patch (mirroring twice)
    let p = L3Params {
        patch_size: 9,
        ..small_params()
    };
    let learned = learn_synthetic(&p, 8, |i| {
        Ok(vec![synthetic_frame(
            i as u64,
            20,
            [0.01f32, 0.1, 0.5, 1.5][i % 4],
            0.002,
            (i % 2, (i / 4) % 2),
        )])
    })
    .unwrap();
    let t9 = package_synthetic(&p, learned);
    check_table("9×9 patches", &t9);
    for (w, h) in [(1, 1), (2, 3), (4, 1), (1, 9)] {
        let (xyz, _) = render_reference(&t9, &t9.kernels, &vec![0.4; w * h], w, h).unwrap();
        assert_finite(&format!("9×9 patch on {w}×{h}"), &xyz);
    }
}

#[test]
fn largest_frames_and_the_pixel_limit() {
    let lim = Limits::default();
    // the pixel and side limits are checked before any allocation or length check
    let over_pixels = decode_raw_u16_le(&[], 10_001, 10_000, &lim).unwrap_err();
    println!("10001×10000 raw: {over_pixels}");
    assert!(over_pixels.to_string().contains("pixels"), "{over_pixels}");
    let over_side = decode_raw_u16_le(&[], lim.max_dim + 1, 1, &lim).unwrap_err();
    println!("{}×1 raw: {over_side}", lim.max_dim + 1);
    let overflow = decode_raw_u16_le(&[], usize::MAX, usize::MAX, &lim).unwrap_err();
    println!("usize::MAX² raw: {overflow}");
    let pgm = format!("P5\n{} {}\n255\n", 10_001, 10_000);
    let e = decode_mosaic(pgm.as_bytes(), &lim).unwrap_err();
    println!("10001×10000 PGM header: {e}");
    // exactly at the limit: the size is accepted, only the body length is wrong
    let e = decode_raw_u16_le(&[0, 0], 10_000, 10_000, &lim).unwrap_err();
    assert!(e.to_string().contains("bytes"), "{e}");
    // the widest and tallest allowed frames one pixel thick, and 4096×2 rows,
    // decoded from raw and rendered
    let t = tiny_table();
    for (w, h) in [(lim.max_dim, 1), (1, lim.max_dim), (4096, 2)] {
        let dn: Vec<u8> = (0..w * h)
            .flat_map(|i| (((i * 7919) % 1000) as u16 * 60).to_le_bytes())
            .collect();
        let frame = decode_raw_u16_le(&dn, w, h, &lim).unwrap();
        let meta = RawMeta::new(w, h, "RG/WB", 0, 65535, 1.8);
        let v = frame.to_volts(&meta).unwrap();
        let (xyz, st) = render_reference(t, &t.kernels, &v, w, h).unwrap();
        assert_eq!(st.pixels as usize, w * h);
        assert_finite(&format!("{w}×{h}"), &xyz);
    }
}

#[test]
fn hostile_dn_levels_are_clear_errors() {
    let frame = decode_raw_u16_le(&[1, 0, 2, 0], 2, 1, &Limits::default()).unwrap();
    for (black, white, swing) in [
        (10u16, 10u16, 1.8),
        (20, 10, 1.8),
        (0, 100, 0.0),
        (0, 100, f64::NAN),
        (0, 100, f64::INFINITY),
    ] {
        let meta = RawMeta::new(2, 1, "RG/WB", black, white, swing);
        let e = frame.to_volts(&meta).unwrap_err();
        println!("black {black}, white {white}, swing {swing}: {e}");
    }
    // values above the white level clamp to the swing
    let frame = decode_raw_u16_le(&[0xff, 0xff, 0, 0], 2, 1, &Limits::default()).unwrap();
    let v = frame
        .to_volts(&RawMeta::new(2, 1, "RG/WB", 100, 1000, 1.8))
        .unwrap();
    assert_eq!(v, vec![1.8, 0.0]);
}

#[test]
fn extreme_corrections_fused_into_kernels_stay_finite() {
    // an ill-conditioned but registrable T (determinant above the registry's
    // 1e-9 floor) fused into the kernels, rendered on a saturated frame
    let t = tiny_table();
    let m = [[300.0, -299.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let k = fuse_kernels(t, &m);
    assert!(k.iter().all(|v| v.is_finite()));
    let (xyz, _) = render_reference(t, &k, &vec![1.8; 64], 8, 8).unwrap();
    assert_finite("fused extreme T", &xyz);
}
