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
    let runs = |mode, v: &[f32]| s.runs_on(mode, &Mosaic::Volts(v), 1.0);
    let dark = vec![0.01f32; 100];
    let bright = vec![0.8f32; 100];
    let mixed: Vec<f32> = (0..100).map(|i| if i < 5 { 0.01 } else { 0.8 }).collect();
    assert!(runs(ChromaMode::Auto, &dark));
    assert!(!runs(ChromaMode::Auto, &bright));
    assert!(!runs(ChromaMode::Auto, &mixed));
    assert!(runs(ChromaMode::On, &bright));
    assert!(!runs(ChromaMode::Off, &dark));
    assert!(!runs(ChromaMode::Auto, &[]));
}

/// The decision as first written: every 7th value in volts, one binary search each.
fn runs_by_search(s: &ChromaStage, volts: impl Iterator<Item = f32>) -> bool {
    let (mut noisy, mut n) = (0usize, 0usize);
    for v in volts.step_by(7) {
        let l = s.edges.partition_point(|&e| e < v.clamp(0.0, s.swing));
        noisy += usize::from(s.noisy.get(l).copied().unwrap_or(false));
        n += 1;
    }
    n > 0 && noisy as f64 >= AUTO_FRACTION * n as f64
}

/// The table of codes and the parallel count decide as the search did, on DN mosaics with
/// any black and white level and on volts outside the swing, around the fraction's edge.
#[test]
fn auto_decides_on_dn_and_volts_as_the_search_did() {
    let mut s = stage(1e-4);
    s.edges = vec![0.02, 0.07, 0.2, 0.45, 0.7];
    s.noisy = vec![true, true, false, true, false, false];
    s.swing = 0.9;
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut agreed = [0usize; 2];
    for case in 0..60 {
        let n = rng.random_range(0..200_000usize);
        let (black, white) = match case % 3 {
            0 => (0, u16::MAX),
            1 => (rng.random_range(0..2000), rng.random_range(3000..16384)),
            _ => (rng.random_range(0..70), rng.random_range(0..1024)),
        };
        let top = rng.random_range(1..=u16::MAX);
        let data: Vec<u16> = (0..n).map(|_| rng.random_range(0..=top)).collect();
        let swing = rng.random_range(0.5f32..1.2);
        let k = swing / f32::from(white.saturating_sub(black).max(1));
        let volts = data.iter().map(|&d| f32::from(d.saturating_sub(black)) * k);
        let want = runs_by_search(&s, volts);
        let dn = Mosaic::Dn {
            data: &data,
            black,
            white,
        };
        assert_eq!(s.runs_on(ChromaMode::Auto, &dn, swing), want, "case {case}");
        let v: Vec<f32> = (0..n).map(|_| rng.random_range(-0.2f32..1.1)).collect();
        let want_v = runs_by_search(&s, v.iter().copied());
        assert_eq!(s.runs_on(ChromaMode::Auto, &Mosaic::Volts(&v), 1.0), want_v);
        agreed[usize::from(want)] += 1;
    }
    // both answers occurred
    assert!(agreed[0] > 0 && agreed[1] > 0, "{agreed:?}");
}

#[test]
fn the_curve_interpolates_between_levels_and_holds_at_the_ends() {
    let mut s = stage(0.0);
    s.var = [vec![1.0, 2.0, 4.0], vec![0.0; 3]];
    assert_eq!(s.variance_near(0, 0.0, &mut 0), 1.0);
    assert!((s.variance_near(0, 0.055, &mut 2) - 1.5).abs() < 1e-12);
    assert_eq!(s.variance_near(0, 5.0, &mut 0), 4.0);
}

/// The segment found from any hint is `partition_point`'s: the curve's value is the same
/// whichever pixel came before, at the levels, between them, past both ends and at NaN.
#[test]
fn the_curve_from_a_hint_is_the_binary_search_s() {
    let mut s = stage(0.0);
    s.var = [vec![1.0, 2.0, 4.0], vec![3.0, 0.5, 7.0]];
    let reference = |s: &ChromaStage, k: usize, y: f64| {
        let i = s.y.partition_point(|&l| l < y);
        let var = &s.var[k];
        if i == 0 {
            var[0]
        } else if i >= s.y.len() {
            var[s.y.len() - 1]
        } else {
            let t = (y - s.y[i - 1]) / (s.y[i] - s.y[i - 1]);
            var[i - 1] + t * (var[i] - var[i - 1])
        }
    };
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let top = s.y[s.y.len() - 1];
    let mut ys: Vec<f64> = (0..2000)
        .map(|_| rng.random_range(-0.5 * top..1.5 * top))
        .collect();
    ys.extend(s.y.clone());
    ys.extend([f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 0.0]);
    for k in 0..2 {
        for &start in &[0, 1, 2, 3, 99] {
            let mut hint = start;
            for &y in &ys {
                let (got, want) = (s.variance_near(k, y, &mut hint), reference(&s, k, y));
                assert!(
                    got == want || (got.is_nan() && want.is_nan()),
                    "y {y}: {got} vs {want}"
                );
            }
        }
    }
}

/// The stage over the whole image as one strip, out of place: the reference for the strips
/// filtered in place.
fn one_strip(s: &ChromaStage, xyz: &[f32], width: usize, height: usize) -> Vec<f32> {
    let [kx, _, kz] = D65_WHITE_XYZ.map(|v| v as f32);
    let (white, row) = ([kx, kz], width * 3);
    let mut out = xyz.to_vec();
    let mut filters = [
        SelfGuided::new(height, s.radius),
        SelfGuided::new(height, s.radius),
    ];
    run_side_by_side(
        &mut filters,
        width,
        0..height,
        |k, t, plane| {
            for (p, px) in plane
                .iter_mut()
                .zip(xyz[t * row..(t + 1) * row].chunks_exact(3))
            {
                *p = px[2 * k] - white[k] * px[1];
            }
        },
        |k, t, _, e| {
            let mut hint = 0;
            for (e, px) in e
                .iter_mut()
                .zip(xyz[t * row..(t + 1) * row].chunks_exact(3))
            {
                let var = s.variance_near(k, f64::from(px[1]), &mut hint);
                *e = (s.strength * var as f32).max(f32::MIN_POSITIVE);
            }
        },
        |k, y, filtered| {
            for (px, &c) in out[y * row..(y + 1) * row]
                .chunks_exact_mut(3)
                .zip(filtered)
            {
                px[2 * k] = c + white[k] * px[1];
            }
        },
    );
    out
}

/// In place, strip by strip, the stage gives what one pass over the whole image gives, bit
/// for bit: the strips read their neighbours' rows as they were before filtering. (Reading a
/// neighbour's row one row off moves the result by 5e-5 on these images.)
#[test]
fn strips_filtered_in_place_match_one_pass() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for (w, h) in [
        (37, 300),
        (5, 129),
        (3, 256),
        (16, 2 * STRIP + 2 * RADIUS),
        (9, 127),
        (1, 1),
    ] {
        let noisy = image(w, h, |x, y| {
            [
                0.1 + 0.002 * ((x * 3 + y) % 50) as f32,
                0.01 * (rng.random::<f32>() - 0.5),
                0.01 * (rng.random::<f32>() - 0.5),
            ]
        });
        let s = stage(1e-5);
        let mut in_place = noisy.clone();
        s.apply_in_place(&mut in_place, w, h).unwrap();
        let reference = one_strip(&s, &noisy, w, h);
        assert_eq!(in_place, reference, "{w}×{h}");
    }
}
