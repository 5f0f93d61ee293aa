//! f32 against f64 accumulation of a class's sums on an ill-conditioned class.

use l3::camera::{NoiseSwitches, SensorDesign};
use l3::l3::L3Params;
use l3::l3::classify::PatchGeometry;
use nalgebra::{DMatrix, DVector};

use super::camera_frames;

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
