use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::colour::lab_to_xyz;

fn opts(formula: DeltaEFormula, filters: FilterSet) -> ScielabOptions {
    ScielabOptions {
        formula,
        filters,
        ..ScielabOptions::default()
    }
}

fn uniform(w: usize, h: usize, xyz: [f64; 3]) -> Vec<f64> {
    (0..w * h).flat_map(|_| xyz).collect()
}

#[test]
fn default_viewing_condition_is_41_samples_per_degree() {
    let v = ViewingCondition::default();
    assert!((v.samples_per_degree - 41.23).abs() < 0.01, "{v:?}");
    assert_eq!(
        channel_filters(&ScielabOptions::default()).unwrap()[0].taps(),
        41
    );
}

#[test]
fn filters_sum_to_one_and_are_symmetric_and_separable() {
    for set in [FilterSet::Paper, FilterSet::Distribution] {
        for spd in [12.0, 41.25, 100.0] {
            let o = ScielabOptions {
                viewing: ViewingCondition {
                    samples_per_degree: spd,
                },
                ..opts(DeltaEFormula::Ciede2000, set)
            };
            for f in channel_filters(&o).unwrap() {
                let n = f.taps();
                assert_eq!(n % 2, 1);
                let wsum: f64 = f.terms.iter().map(|(w, _)| w).sum();
                assert!((wsum - 1.0).abs() < 1e-12);
                for (_, g) in &f.terms {
                    assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                    for i in 0..n {
                        assert_eq!(g[i], g[n - 1 - i], "1D taps symmetric");
                    }
                }
                let k = f.kernel_2d();
                assert!((k.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                for r in 0..n {
                    for c in 0..n {
                        // symmetric in x, in y and under transposition
                        assert!((k[r * n + c] - k[c * n + r]).abs() < 1e-15);
                        assert!((k[r * n + c] - k[(n - 1 - r) * n + c]).abs() < 1e-15);
                    }
                }
            }
        }
    }
}

#[test]
fn separable_filtering_equals_the_direct_2d_convolution() {
    let (w, h) = (23, 17);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let plane: Vec<f64> = (0..w * h).map(|_| rng.random_range(0.0..1.0)).collect();
    let o = ScielabOptions {
        viewing: ViewingCondition {
            samples_per_degree: 9.0,
        },
        ..ScielabOptions::default()
    };
    let f = &channel_filters(&o).unwrap()[0];
    let n = f.taps();
    let k = f.kernel_2d();
    for border in [Border::Symmetric, Border::Periodic] {
        let sep = filter_plane(&plane, w, h, f, border);
        let r = (n / 2) as isize;
        for y in 0..h {
            for x in 0..w {
                let mut direct = 0.0;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let sy = fold(y as isize + dy, h, border);
                        let sx = fold(x as isize + dx, w, border);
                        direct +=
                            k[((dy + r) as usize) * n + (dx + r) as usize] * plane[sy * w + sx];
                    }
                }
                assert!(
                    (sep[y * w + x] - direct).abs() < 1e-12,
                    "{border:?} ({x},{y})"
                );
            }
        }
    }
}

#[test]
fn borders_fold_as_documented() {
    let s: Vec<usize> = (-3..7).map(|i| fold(i, 4, Border::Symmetric)).collect();
    assert_eq!(s, [2, 1, 0, 0, 1, 2, 3, 3, 2, 1]);
    let p: Vec<usize> = (-3..7).map(|i| fold(i, 4, Border::Periodic)).collect();
    assert_eq!(p, [1, 2, 3, 0, 1, 2, 3, 0, 1, 2]);
    // an image narrower than the filter still folds inside it
    assert!((-50..50).all(|i| fold(i, 3, Border::Symmetric) < 3));
}

#[test]
fn uniform_pairs_give_plain_cielab_delta_e() {
    let white = D65_WHITE_XYZ;
    let pairs = [
        ([0.2, 0.21, 0.25], [0.22, 0.2, 0.18]),
        ([0.05, 0.04, 0.02], [0.045, 0.05, 0.03]),
        ([0.9, 0.95, 1.0], [0.7, 0.75, 0.9]),
        ([0.002, 0.002, 0.003], [0.004, 0.003, 0.001]),
    ];
    for formula in [DeltaEFormula::Cie1976, DeltaEFormula::Ciede2000] {
        for set in [FilterSet::Paper, FilterSet::Distribution] {
            for border in [Border::Symmetric, Border::Periodic] {
                for (a, b) in pairs {
                    let o = ScielabOptions {
                        border,
                        ..opts(formula, set)
                    };
                    let (w, h) = (37, 29);
                    let s = scielab(&uniform(w, h, a), &uniform(w, h, b), w, h, &o, true).unwrap();
                    let plain = delta_e(xyz_to_lab(a, white), xyz_to_lab(b, white), formula);
                    for v in s.map.unwrap() {
                        assert!(
                            (v - plain).abs() < 1e-6,
                            "{formula:?} {set:?}: {v} vs {plain}"
                        );
                    }
                    assert!((s.stats.mean - plain).abs() < 1e-6);
                    assert!((s.stats.max - plain).abs() < 1e-6);
                }
            }
        }
    }
}

/// A mid-grey image, and the same with each pixel moved by `delta` CIELAB units along `axis`
/// (0: L*, 1: a*, 2: b*), the sign at random: the per-pixel ΔE 1976 is `delta` everywhere.
fn noisy_pair(axis: usize, delta: f64, w: usize, h: usize) -> (Vec<f64>, Vec<f64>) {
    let base: Lab = [50.0, 0.0, 0.0];
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let ideal = uniform(w, h, lab_to_xyz(base, D65_WHITE_XYZ));
    let noisy = (0..w * h)
        .flat_map(|_| {
            let mut lab = base;
            lab[axis] += if rng.random_bool(0.5) { delta } else { -delta };
            lab_to_xyz(lab, D65_WHITE_XYZ)
        })
        .collect();
    (ideal, noisy)
}

#[test]
fn fine_chromatic_noise_scores_lower_than_fine_luminance_noise() {
    let (w, h) = (64, 64);
    let delta = 3.0;
    let (ideal, lum) = noisy_pair(0, delta, w, h);
    let (_, red_green) = noisy_pair(1, delta, w, h);
    let (_, blue_yellow) = noisy_pair(2, delta, w, h);
    // the same per-pixel CIELAB ΔE 1976 before blurring
    for noisy in [&lum, &red_green, &blue_yellow] {
        for (a, b) in ideal.chunks(3).zip(noisy.chunks(3)) {
            let d = delta_e(
                xyz_to_lab([a[0], a[1], a[2]], D65_WHITE_XYZ),
                xyz_to_lab([b[0], b[1], b[2]], D65_WHITE_XYZ),
                DeltaEFormula::Cie1976,
            );
            assert!((d - delta).abs() < 1e-9);
        }
    }
    for formula in [DeltaEFormula::Cie1976, DeltaEFormula::Ciede2000] {
        for set in [FilterSet::Paper, FilterSet::Distribution] {
            let o = opts(formula, set);
            let l = scielab(&ideal, &lum, w, h, &o, false).unwrap().stats.mean;
            let rg = scielab(&ideal, &red_green, w, h, &o, false)
                .unwrap()
                .stats
                .mean;
            let by = scielab(&ideal, &blue_yellow, w, h, &o, false)
                .unwrap()
                .stats
                .mean;
            assert!(
                rg < l && by < l,
                "{formula:?} {set:?}: L {l}, rg {rg}, by {by}"
            );
            // blurring removes most of fine noise
            assert!(l < delta, "{formula:?} {set:?}: L {l}");
        }
    }
}

#[test]
fn identical_images_score_zero_and_f32_input_works() {
    let (ideal, noisy) = noisy_pair(0, 2.0, 16, 9);
    let f: Vec<f32> = noisy.iter().map(|&v| v as f32).collect();
    let s = scielab(&f, &f, 16, 9, &ScielabOptions::default(), false).unwrap();
    assert_eq!(s.stats.max, 0.0);
    assert_eq!(s.stats.n, 16 * 9);
    assert!(s.map.is_none());
    let s = scielab(&ideal, &noisy, 16, 9, &ScielabOptions::default(), false).unwrap();
    assert!(s.stats.mean > 0.0 && s.stats.p90 <= s.stats.max);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let o = ScielabOptions::default();
    let a = uniform(4, 3, [0.2, 0.2, 0.2]);
    assert!(scielab(&a, &a[..33], 4, 3, &o, false).is_err());
    assert!(scielab(&a, &a, 3, 4 + 1, &o, false).is_err());
    assert!(scielab::<f64>(&[], &[], 0, 0, &o, false).is_err());
    assert!(scielab(&a, &a, usize::MAX, 2, &o, false).is_err());
    let mut nan = a.clone();
    nan[5] = f64::NAN;
    assert!(scielab(&a, &nan, 4, 3, &o, false).is_err());
    for spd in [0.0, -3.0, f64::NAN, f64::INFINITY] {
        let bad = ScielabOptions {
            viewing: ViewingCondition {
                samples_per_degree: spd,
            },
            ..o
        };
        assert!(scielab(&a, &a, 4, 3, &bad, false).is_err());
    }
    let bad = ScielabOptions {
        support_deg: 0.0,
        ..o
    };
    assert!(scielab(&a, &a, 4, 3, &bad, false).is_err());
    assert!("1994".parse::<DeltaEFormula>().is_err());
    assert_eq!("1976".parse::<DeltaEFormula>(), Ok(DeltaEFormula::Cie1976));
}
