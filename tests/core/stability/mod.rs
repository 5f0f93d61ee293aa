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
//!
//! By topic: `training` (degenerate classes, scenes and noise), `accumulation` (f32 against
//! f64 sums), `illuminants` (T for LED and degenerate lights) and `rendering`. The helpers
//! below train and check the tables they share.

// Index loops read best in numeric code (as in the library).
#![allow(clippy::needless_range_loop)]

use std::sync::atomic::AtomicBool;

use l3::camera::{Camera, NoiseSwitches, SensorDesign, mosaic};
use l3::l3::classify::PatchGeometry;
use l3::l3::correct::NoiseModel;
use l3::l3::learn::{
    LearnError, Learned, TrainControl, TrainingFrame, TrainingScenes, learn, package,
};
use l3::l3::render::render_reference;
use l3::l3::{L3Params, L3Table};
use l3::spectral::{Extrapolation, WavelengthGrid, cie_illuminant};
use l3::test_support::{synthetic_channel, synthetic_frame, synthetic_meta, synthetic_volts};

mod accumulation;
mod illuminants;
mod rendering;
mod training;

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
