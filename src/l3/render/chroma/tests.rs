use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;

/// A stage with a flat noise curve: variance `var` for both chroma planes at every level.
fn stage(var: f64) -> ChromaStage {
    ChromaStage {
        y: vec![0.01, 0.1, 1.0],
        var: [vec![var; 3], vec![var; 3]],
        edges: vec![0.05, 0.5],
        noisy: vec![true, false, false],
        swing: 1.0,
        radius: RADIUS,
        strength: STRENGTH,
    }
}

/// `w × h` XYZ of `f(x, y)`'s (Y, c₁, c₂).
fn image(w: usize, h: usize, mut f: impl FnMut(usize, usize) -> [f32; 3]) -> Vec<f32> {
    let [kx, _, kz] = D65_WHITE_XYZ.map(|v| v as f32);
    let mut out = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            let [l, c1, c2] = f(x, y);
            out.extend([c1 + kx * l, l, c2 + kz * l]);
        }
    }
    out
}

fn chroma(px: &[f32]) -> [f32; 2] {
    let [kx, _, kz] = D65_WHITE_XYZ.map(|v| v as f32);
    [px[0] - kx * px[1], px[2] - kz * px[1]]
}

fn chroma_variance(xyz: &[f32]) -> f64 {
    let c: Vec<[f32; 2]> = xyz.chunks_exact(3).map(chroma).collect();
    let n = c.len() as f64;
    (0..2)
        .map(|k| {
            let m = c.iter().map(|v| f64::from(v[k])).sum::<f64>() / n;
            c.iter().map(|v| (f64::from(v[k]) - m).powi(2)).sum::<f64>() / n
        })
        .sum()
}

#[test]
fn modes_parse_and_print() {
    for m in [ChromaMode::Auto, ChromaMode::On, ChromaMode::Off] {
        assert_eq!(m.to_string().parse::<ChromaMode>(), Ok(m));
    }
    assert_eq!(" ON ".parse::<ChromaMode>(), Ok(ChromaMode::On));
    let e = "sometimes".parse::<ChromaMode>().unwrap_err();
    assert!(e.to_string().contains("auto, on or off"), "{e}");
}

#[test]
fn chroma_noise_is_flattened_and_luminance_kept() {
    let sigma = 0.01f32;
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let noisy = image(64, 48, |x, y| {
        [
            0.2 + 0.001 * (x + y) as f32,
            sigma * (rng.random::<f32>() - 0.5) * 12f32.sqrt(),
            sigma * (rng.random::<f32>() - 0.5) * 12f32.sqrt(),
        ]
    });
    let out = stage(f64::from(sigma * sigma))
        .apply(&noisy, 64, 48)
        .unwrap();
    let (before, after) = (chroma_variance(&noisy), chroma_variance(&out));
    assert!(after < 0.2 * before, "chroma variance {before} → {after}");
    for (a, b) in noisy.chunks_exact(3).zip(out.chunks_exact(3)) {
        assert_eq!(a[1], b[1], "Y changed");
    }
}

#[test]
fn a_chroma_step_well_above_the_noise_is_kept() {
    // an isoluminant red | green step, no noise; the stage expects σ = 0.002
    let img = image(40, 24, |x, _| {
        let c = if x < 20 { 0.05 } else { -0.05 };
        [0.3, c, -c]
    });
    let out = stage(4e-6).apply(&img, 40, 24).unwrap();
    let worst = img
        .iter()
        .zip(&out)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(worst < 0.005, "the step moved by {worst} (of 0.1)");
}

#[test]
fn a_neutral_image_is_unchanged() {
    let img = image(33, 17, |x, y| {
        [0.01 * ((x * 7 + y * 3) % 11) as f32, 0.0, 0.0]
    });
    let out = stage(1e-4).apply(&img, 33, 17).unwrap();
    for (a, b) in img.iter().zip(&out) {
        assert!((a - b).abs() < 1e-6, "{a} → {b}");
    }
}

#[test]
fn a_buffer_of_the_wrong_size_is_an_error() {
    assert!(stage(1e-4).apply(&[0.0; 10], 2, 2).is_err());
    assert!(stage(1e-4).apply(&[], 0, 0).unwrap().is_empty());
}

#[test]
fn auto_runs_when_enough_pixels_sit_at_noisy_levels() {
    let s = stage(1e-4);
    let dark = vec![0.01f32; 100];
    let bright = vec![0.8f32; 100];
    let mixed: Vec<f32> = (0..100).map(|i| if i < 5 { 0.01 } else { 0.8 }).collect();
    assert!(s.runs(ChromaMode::Auto, dark.iter().copied()));
    assert!(!s.runs(ChromaMode::Auto, bright.iter().copied()));
    assert!(!s.runs(ChromaMode::Auto, mixed.iter().copied()));
    assert!(s.runs(ChromaMode::On, bright.iter().copied()));
    assert!(!s.runs(ChromaMode::Off, dark.iter().copied()));
    assert!(!s.runs(ChromaMode::Auto, std::iter::empty()));
}

#[test]
fn the_curve_interpolates_between_levels_and_holds_at_the_ends() {
    let mut s = stage(0.0);
    s.var = [vec![1.0, 2.0, 4.0], vec![0.0; 3]];
    assert_eq!(s.variance(0, 0.0), 1.0);
    assert!((s.variance(0, 0.055) - 1.5).abs() < 1e-12);
    assert_eq!(s.variance(0, 5.0), 4.0);
}
