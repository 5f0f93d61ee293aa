use proptest::prelude::*;

use super::*;
use crate::l3::classify::mirror;

const PHASES: [&str; 4] = ["RG/GB", "GR/BG", "GB/RG", "BG/GR"];

/// A frame whose pixel (r, c) holds `f(channel, r, c)`.
fn mosaic(cfa: &Cfa, w: usize, h: usize, f: impl Fn(usize, f32, f32) -> f32) -> Vec<f32> {
    (0..w * h)
        .map(|i| f(cfa.channel_at(i / w, i % w), (i / w) as f32, (i % w) as f32))
        .collect()
}

/// Deterministic standard normal draws (Box–Muller on a 64-bit LCG).
fn normals(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut u = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| ((-2.0 * u().ln()).sqrt() * (std::f64::consts::TAU * u()).cos()) as f32)
        .collect()
}

#[test]
fn demosaic_of_a_flat_field_is_flat_and_fit_recovers_a_matrix() {
    let cfa = Cfa::parse("RG/WB").unwrap();
    let vals = [0.2f32, 0.4, 0.3, 0.9];
    let (w, h) = (7, 5);
    let v = mosaic(&cfa, w, h, |k, _, _| vals[k]);
    for dm in [
        bilinear_demosaic(&v, w, h, &cfa).unwrap(),
        gradient_demosaic(&v, w, h, &cfa, 2.0).unwrap(),
    ] {
        for px in dm.chunks_exact(4) {
            for ch in 0..4 {
                assert!((px[ch] - vals[ch]).abs() < 1e-6);
            }
        }
    }
    let truth = [
        [0.5, 0.1, 0.0],
        [0.2, 0.8, 0.1],
        [0.0, 0.1, 0.9],
        [0.1, 0.1, 0.1],
    ];
    let chans: Vec<Vec<f64>> = (0..20)
        .map(|i| {
            (0..4)
                .map(|c| ((i * 7 + c * 3) % 11) as f64 / 11.0 + c as f64 * 0.01)
                .collect()
        })
        .collect();
    let xyz: Vec<[f64; 3]> = chans
        .iter()
        .map(|ch| [0, 1, 2].map(|k| (0..4).map(|c| truth[c][k] * ch[c]).sum()))
        .collect();
    let m = ColourMatrix::fit(&chans, &xyz).unwrap();
    for c in 0..4 {
        for k in 0..3 {
            assert!((m.m[c][k] - truth[c][k]).abs() < 1e-9);
        }
    }
    assert!(ColourMatrix::fit(&chans[..2], &xyz[..2]).is_err());
    let out = render_baseline(&v, w, h, &cfa, &m).unwrap();
    assert_eq!(out.len(), w * h * 3);
}

#[test]
fn bayer_layout_is_found_for_the_four_phases_only() {
    for p in PHASES {
        let cfa = Cfa::parse(p).unwrap();
        let lay = BayerLayout::of(&cfa).unwrap();
        assert_eq!(cfa.channel_at(lay.r_at.0, lay.r_at.1), lay.r);
    }
    for p in ["RG/WB", "RG/BG", "RGGB", "RG/GB/RG/GB"] {
        assert!(BayerLayout::of(&Cfa::parse(p).unwrap()).is_none(), "{p}");
    }
    let v = vec![0.5f32; 16];
    assert!(malvar_demosaic(&v, 4, 4, &Cfa::parse("RG/WB").unwrap()).is_err());
    assert!(malvar_demosaic(&v, 5, 4, &Cfa::parse("RG/GB").unwrap()).is_err());
}

/// The paper's kernels written out (eighths), applied by direct convolution (the frame
/// mirrored about its edges).
fn malvar_reference(
    v: &[f32],
    (w, h): (usize, usize),
    r: usize,
    c: usize,
    kernel: &[[f32; 5]; 5],
) -> f32 {
    let mut s = 0f32;
    for (dy, row) in kernel.iter().enumerate() {
        for (dx, k) in row.iter().enumerate() {
            let rr = mirror(r as isize + dy as isize - 2, h);
            s += k * v[rr * w + mirror(c as isize + dx as isize - 2, w)];
        }
    }
    s / 8.0
}

#[test]
fn malvar_is_the_papers_kernels_and_reproduces_ramps_in_every_phase() {
    let g_at_rb = [
        [0., 0., -1., 0., 0.],
        [0., 0., 2., 0., 0.],
        [-1., 2., 4., 2., -1.],
        [0., 0., 2., 0., 0.],
        [0., 0., -1., 0., 0.],
    ];
    let row_nb = [
        [0., 0., 0.5, 0., 0.],
        [0., -1., 0., -1., 0.],
        [-1., 4., 5., 4., -1.],
        [0., -1., 0., -1., 0.],
        [0., 0., 0.5, 0., 0.],
    ];
    let col_nb: [[f32; 5]; 5] = std::array::from_fn(|i| std::array::from_fn(|j| row_nb[j][i]));
    let opposite = [
        [0., 0., -1.5, 0., 0.],
        [0., 2., 0., 2., 0.],
        [-1.5, 0., 6., 0., -1.5],
        [0., 2., 0., 2., 0.],
        [0., 0., -1.5, 0., 0.],
    ];
    // every pixel, the border too, at any size
    for (w, h) in [(13, 11), (1, 1), (2, 3), (3, 2), (4, 5)] {
        for p in PHASES {
            let cfa = Cfa::parse(p).unwrap();
            let lay = BayerLayout::of(&cfa).unwrap();
            let noise = normals(w * h, 3);
            let v: Vec<f32> = noise.iter().map(|n| 0.5 + 0.1 * n).collect();
            let dm = malvar_demosaic(&v, w, h, &cfa).unwrap();
            for r in 0..h {
                for c in 0..w {
                    let own = cfa.channel_at(r, c);
                    let px = &dm[(r * w + c) * 3..][..3];
                    assert_eq!(px[own], v[r * w + c]);
                    let rb_row = cfa.channel_at(r, c + 1);
                    for k in (0..3).filter(|&k| k != own) {
                        let kern = if own != lay.g {
                            if k == lay.g { &g_at_rb } else { &opposite }
                        } else if k == rb_row {
                            &row_nb
                        } else {
                            &col_nb
                        };
                        let want = malvar_reference(&v, (w, h), r, c, kern);
                        assert!((px[k] - want).abs() < 1e-5, "{p} {w}×{h} ({r},{c}) ch {k}");
                    }
                }
            }
        }
    }
    let (w, h) = (13, 11);
    for p in PHASES {
        let cfa = Cfa::parse(p).unwrap();
        // channel-specific linear ramps are reproduced exactly away from the border
        let ramp = |k: usize, r: f32, c: f32| {
            0.1 + 0.01 * k as f32 + 0.003 * r - 0.002 * c * (k as f32 + 1.0)
        };
        let v = mosaic(&cfa, w, h, ramp);
        let dm = malvar_demosaic(&v, w, h, &cfa).unwrap();
        for r in 2..h - 2 {
            for c in 2..w - 2 {
                for k in 0..3 {
                    let got = dm[(r * w + c) * 3 + k];
                    assert!((got - ramp(k, r as f32, c as f32)).abs() < 1e-5, "{p}");
                }
            }
        }
    }
}

#[test]
fn gradient_demosaic_reproduces_ramps_matches_bilinear_at_gain_0_and_falls_back() {
    let (w, h) = (12, 10);
    for s in ["RG/WB", "GR/BW", "WB/RG", "BW/GR", "RG/GB"] {
        let cfa = Cfa::parse(s).unwrap();
        let nc = cfa.n_channels();
        let ramp = |k: usize, r: f32, c: f32| 0.2 + 0.05 * k as f32 + 0.004 * r + 0.003 * c;
        let v = mosaic(&cfa, w, h, ramp);
        let dm = gradient_demosaic(&v, w, h, &cfa, 1.0).unwrap();
        for r in 2..h - 2 {
            for c in 2..w - 2 {
                for k in 0..nc {
                    let got = dm[(r * w + c) * nc + k];
                    assert!((got - ramp(k, r as f32, c as f32)).abs() < 1e-5, "{s}");
                }
            }
        }
        let noisy: Vec<f32> = normals(w * h, 9).iter().map(|n| 0.4 + 0.1 * n).collect();
        let a = gradient_demosaic(&noisy, w, h, &cfa, 0.0).unwrap();
        let b = bilinear_demosaic(&noisy, w, h, &cfa).unwrap();
        assert!(a.iter().zip(&b).all(|(a, b)| (a - b).abs() < 1e-6), "{s}");
    }
    // a quadratic shared by the channels: the correction removes bilinear's bias
    let cfa = Cfa::parse("RG/WB").unwrap();
    let quad =
        |_k: usize, r: f32, c: f32| 0.3 + 0.001 * (r - 5.0).powi(2) + 0.002 * (c - 6.0).powi(2);
    let v = mosaic(&cfa, w, h, quad);
    let err = |dm: &[f32]| {
        let mut e = 0f32;
        for r in 2..h - 2 {
            for c in 2..w - 2 {
                for k in 0..4 {
                    e = e.max((dm[(r * w + c) * 4 + k] - quad(k, r as f32, c as f32)).abs());
                }
            }
        }
        e
    };
    let corrected = err(&gradient_demosaic(&v, w, h, &cfa, 1.0).unwrap());
    let bilinear = err(&bilinear_demosaic(&v, w, h, &cfa).unwrap());
    assert!(
        corrected < 1e-5 && bilinear > 1e-3,
        "{corrected} {bilinear}"
    );
    // a 4×4 tile falls back to bilinear
    let big = Cfa::parse("RGBW/GBWR/BWRG/WRGB").unwrap();
    let a = gradient_demosaic(&v, w, h, &big, 1.0).unwrap();
    assert_eq!(a, bilinear_demosaic(&v, w, h, &big).unwrap());
}

/// A neighbour group: its offsets, its channel, the curvature it carries along x and y.
type Group = (&'static [(isize, isize)], usize, f32, f32);

/// The gradient-corrected demosaic from the module doc's formula, tap by tap (the frame
/// mirrored about its edges; the neighbours' channels those of the true CFA positions).
fn gradient_reference(v: &[f32], w: usize, h: usize, cfa: &Cfa, gain: f32) -> Vec<f32> {
    let nc = cfa.n_channels();
    let mut out = vec![0f32; w * h * nc];
    for r in 0..h {
        for c in 0..w {
            let at = |dy: isize, dx: isize| {
                v[mirror(r as isize + dy, h) * w + mirror(c as isize + dx, w)]
            };
            let x = at(0, 0);
            let (h2, v2) = (at(0, -2) + at(0, 2), at(-2, 0) + at(2, 0));
            let (lx, ly) = (x - 0.5 * h2, x - 0.5 * v2);
            let own_mean = 0.5 * x + 0.125 * (h2 + v2);
            let groups: [Group; 3] = [
                (&[(0, -1), (0, 1)], cfa.channel_at(r, c + 1), 1.0, 0.0),
                (&[(-1, 0), (1, 0)], cfa.channel_at(r + 1, c), 0.0, 1.0),
                (
                    &[(-1, -1), (-1, 1), (1, -1), (1, 1)],
                    cfa.channel_at(r + 1, c + 1),
                    2.0,
                    2.0,
                ),
            ];
            for k in 0..nc {
                out[(r * w + c) * nc + k] = if k == cfa.channel_at(r, c) {
                    x
                } else {
                    let (mut s, mut n, mut axx, mut ayy) = (0f32, 0usize, 0f32, 0f32);
                    for (offs, _, xx, yy) in groups.iter().filter(|g| g.1 == k) {
                        for &(dy, dx) in *offs {
                            s += at(dy, dx);
                            n += 1;
                        }
                        (axx, ayy) = (axx + xx, ayy + yy);
                    }
                    let n = n.max(1) as f32;
                    let mean = s / n;
                    let rho = if own_mean > 0.0 {
                        (mean / own_mean).clamp(0.0, 4.0)
                    } else {
                        1.0
                    };
                    mean + gain * rho * (axx / (2.0 * n) * lx + ayy / (2.0 * n) * ly)
                };
            }
        }
    }
    out
}

#[test]
fn gradient_demosaic_is_its_formula_at_every_pixel_and_size() {
    for (w, h) in [(12, 10), (1, 1), (2, 3), (3, 2), (5, 4)] {
        for s in ["RG/WB", "GR/BW", "WB/RG", "BW/GR", "RG/GB", "GB/RG"] {
            let cfa = Cfa::parse(s).unwrap();
            let v: Vec<f32> = normals(w * h, 7).iter().map(|n| 0.4 + 0.1 * n).collect();
            for gain in [1.0, 0.5] {
                let got = gradient_demosaic(&v, w, h, &cfa, gain).unwrap();
                let want = gradient_reference(&v, w, h, &cfa, gain);
                for (i, (g, t)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        (g - t).abs() < 1e-6,
                        "{s} {w}×{h} gain {gain} at {i}: {g} vs {t}"
                    );
                }
            }
        }
    }
}

fn profile() -> NoiseProfile {
    NoiseProfile::from_design(&crate::camera::SensorDesign::paper_default(), 0.01)
}

#[test]
fn noise_profile_follows_the_sensor_model() {
    let d = crate::camera::SensorDesign::paper_default();
    let p = profile();
    let floor = d.read_noise_v().powi(2) + d.dsnu_v().powi(2);
    assert!((p.variance(0.0) - floor).abs() < 1e-12);
    // shot noise: 200 µV per electron, so 0.5 V has 2500 e⁻ and σ² ≈ 0.5 · 200e-6 V²
    let v = p.variance(0.5) - floor;
    let want = 0.5 * 200e-6 + (0.5f64 * d.prnu_fraction()).powi(2);
    assert!((v - want).abs() < 1e-3 * want, "{v} {want}");
    // a tenth of the signal has a higher relative noise
    assert!(p.sigma(0.05) / 0.05 > 2.5 * p.sigma(0.5) / 0.5);
}

#[test]
fn denoiser_reduces_a_flat_fields_noise_per_the_model_and_keeps_a_step_edge() {
    let (w, h, nc) = (64, 48, 4);
    let p = profile();
    let levels = [0.05f32, 0.08, 0.04, 0.2];
    let z = normals(w * h * nc, 5);
    let noisy: Vec<f32> = z
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let m = levels[i % nc];
            m + p.sigma(m as f64) as f32 * n
        })
        .collect();
    let out = denoise(&noisy, w, h, nc, &p, &DenoiseParams::default()).unwrap();
    let std = |img: &[f32], k: usize| {
        let v: Vec<f64> = img.iter().skip(k).step_by(nc).map(|&x| x as f64).collect();
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt(),
            m,
        )
    };
    for k in 0..nc {
        let (s_in, _) = std(&noisy, k);
        let (s_out, m_out) = std(&out, k);
        assert!(s_out < 0.5 * s_in, "channel {k}: {s_out} vs {s_in}");
        assert!(
            (m_out - levels[k] as f64).abs() < 0.1 * s_in,
            "channel {k} mean {m_out}"
        );
    }
    // a noisy step from 0.05 to 0.4 V (every channel): columns 2 px from the edge keep
    // their level within the noise
    let step: Vec<f32> = (0..w * h * nc)
        .map(|i| {
            let m = if (i / nc) % w < w / 2 { 0.05 } else { 0.4 };
            m + p.sigma(m as f64) as f32 * z[i]
        })
        .collect();
    let out = denoise(&step, w, h, nc, &p, &DenoiseParams::default()).unwrap();
    for (col, want) in [(w / 2 - 3, 0.05f32), (w / 2 + 2, 0.4)] {
        let mean: f32 = (0..h).map(|r| out[(r * w + col) * nc]).sum::<f32>() / h as f32;
        assert!(
            (mean - want).abs() < 0.01 * want.max(0.1),
            "column {col}: {mean}"
        );
    }
    assert!(denoise(&step[1..], w, h, nc, &p, &DenoiseParams::default()).is_err());
}

#[test]
fn isp_renders_a_flat_field_flat_and_refuses_non_finite_input() {
    for s in ["RG/GB", "RG/WB", "RGBW/GBWR/BWRG/WRGB"] {
        let cfa = Cfa::parse(s).unwrap();
        let nc = cfa.n_channels();
        let m = ColourMatrix {
            m: (0..nc).map(|c| [0.1 * (c + 1) as f64, 0.2, 0.05]).collect(),
            n_channels: nc,
        };
        let isp = Isp::new(m.clone(), Some(profile()));
        let (w, h) = (20, 16);
        let v = mosaic(&cfa, w, h, |k, _, _| 0.1 + 0.05 * k as f32);
        let xyz = isp.render(&v, w, h, &cfa).unwrap();
        assert_eq!(xyz.len(), w * h * 3);
        // (bilinear's mirrored border keeps the channels of 2×2 tiles only)
        if cfa.rows == 2 {
            let first: Vec<f32> = xyz[..3].to_vec();
            assert!(
                xyz.chunks_exact(3)
                    .all(|p| (0..3).all(|k| (p[k] - first[k]).abs() < 1e-5)),
                "{s}"
            );
        }
        let mut bad = v.clone();
        bad[7] = f32::NAN;
        assert!(isp.render(&bad, w, h, &cfa).is_err());
        assert!(
            isp.with_matrix(ColourMatrix {
                m: vec![[1.0; 3]; nc + 1],
                n_channels: nc + 1
            })
            .render(&v, w, h, &cfa)
            .is_err()
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Any frame size (down to 2×2), any phase: a uniform scene stays uniform, and the
    /// demosaics are linear in the frame.
    #[test]
    fn demosaics_keep_flat_fields_and_are_linear(
        w in 2usize..14, h in 2usize..14, phase in 0usize..4, level in 0.0f32..1.5, seed in 0u64..1000,
    ) {
        let bayer = Cfa::parse(PHASES[phase]).unwrap();
        let rgbw = Cfa::parse("RG/WB").unwrap().shifted(phase / 2, phase % 2);
        let flat_b = mosaic(&bayer, w, h, |k, _, _| level * (1.0 + 0.3 * k as f32));
        let flat_w = mosaic(&rgbw, w, h, |k, _, _| level * (1.0 + 0.3 * k as f32));
        let mb = malvar_demosaic(&flat_b, w, h, &bayer).unwrap();
        for px in mb.chunks_exact(3) {
            for k in 0..3 {
                prop_assert!((px[k] - level * (1.0 + 0.3 * k as f32)).abs() < 1e-5);
            }
        }
        let gw = gradient_demosaic(&flat_w, w, h, &rgbw, 1.0).unwrap();
        for px in gw.chunks_exact(4) {
            for k in 0..4 {
                prop_assert!((px[k] - level * (1.0 + 0.3 * k as f32)).abs() < 1e-5);
            }
        }
        let a = normals(w * h, seed);
        let b = normals(w * h, seed + 1);
        let sum: Vec<f32> = a.iter().zip(&b).map(|(x, y)| 2.0 * x - y).collect();
        let (ma, mb2, ms) = (
            malvar_demosaic(&a, w, h, &bayer).unwrap(),
            malvar_demosaic(&b, w, h, &bayer).unwrap(),
            malvar_demosaic(&sum, w, h, &bayer).unwrap(),
        );
        for i in 0..ms.len() {
            prop_assert!((ms[i] - (2.0 * ma[i] - mb2[i])).abs() < 1e-4);
        }
    }
}
