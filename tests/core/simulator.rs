//! Acceptance tests of the camera simulator (optics + sensor): the noise model
//! against its analytic mean and variance, clipping, the optical MTF against
//! the diffraction formula, determinism, and the XYZ target convention.

use std::sync::Arc;

use l3::camera::{Camera, Cfa, Exposure, NoiseSwitches, Optics, SensorDesign, mosaic, simulate};
use l3::scene::Scene;
use l3::spectral::{Extrapolation, Spectrum, WavelengthGrid, cie_illuminant};
use ndarray::{Array2, Array3};

fn d65(grid: &WavelengthGrid) -> Spectrum {
    cie_illuminant("D65")
        .unwrap()
        .resample(grid, Extrapolation::Zero)
}

/// A uniform scene of reflectance `refl` under D65.
fn flat_scene(rows: usize, cols: usize, refl: f32, luminance: f64) -> Scene {
    let grid = WavelengthGrid::default();
    Scene {
        name: "flat".into(),
        grid,
        reflectance: Array3::from_elem((grid.n, rows, cols), refl),
        illuminant: d65(&grid),
        illuminant_name: "D65".into(),
        mean_luminance: luminance,
        fov_deg: 10.0,
        patches: vec![],
    }
}

/// A textured scene: vertical bars of smooth spectra plus a diagonal ramp.
fn textured_scene(rows: usize, cols: usize) -> Scene {
    let grid = WavelengthGrid::default();
    let refl = Array3::from_shape_fn((grid.n, rows, cols), |(b, r, c)| {
        let l = grid.wavelength(b);
        let bar = (c / 16) % 4;
        let centre = [450.0, 530.0, 610.0, 560.0][bar];
        let s = 0.1 + 0.7 * (-0.5 * ((l - centre) / 50.0f64).powi(2)).exp();
        (s * (0.3 + 0.7 * (r + c) as f64 / (rows + cols) as f64)) as f32
    });
    Scene {
        name: "bars".into(),
        grid,
        reflectance: refl,
        illuminant: d65(&grid),
        illuminant_name: "D65".into(),
        mean_luminance: 200.0,
        fov_deg: 10.0,
        patches: vec![],
    }
}

use l3::test_support::paper_camera;

/// Mean and (population) variance of the pixels of `frame` under channel `ch`.
fn channel_stats(frame: &Array2<f32>, cfa: &Cfa, ch: usize) -> (f64, f64, usize) {
    let vals: Vec<f64> = frame
        .indexed_iter()
        .filter(|((r, c), _)| cfa.channel_at(*r, *c) == ch)
        .map(|(_, v)| *v as f64)
        .collect();
    let n = vals.len() as f64;
    let mean = vals.iter().sum::<f64>() / n;
    let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var, vals.len())
}

#[test]
fn flat_field_matches_the_analytic_noise_model() {
    let cam = paper_camera();
    let d = cam.design().clone();
    let scene = flat_scene(512, 512, 0.5, 100.0);
    let optical = cam.optical_image(&scene).unwrap();
    let rates = cam.channel_rates(&optical).unwrap();
    let cfa = cam.cfa().clone();
    let g = cfa.channel_index("G").unwrap();
    let mean_rate = mosaic(&rates, &cfa).unwrap();
    // The flat field is flat after the optics.
    let rg = rates[(g, 256, 256)] as f64;
    for v in rates.index_axis(ndarray::Axis(0), g).iter() {
        assert!((*v as f64 / rg - 1.0).abs() < 1e-5);
    }
    let cg = d.conversion_gain_v();
    let (sd, sr, sp) = (d.dsnu_v(), d.read_noise_v(), d.prnu_fraction());
    println!("G rate {rg:.1} e/s; G pixels per frame: {}", 512 * 512 / 4);
    println!(
        "{:>8} {:>10} {:>12} {:>12} {:>8} {:>13} {:>13} {:>8}",
        "fraction", "t (s)", "mean (V)", "analytic", "err %", "var (V²)", "analytic", "err %"
    );
    for (i, frac) in [0.01, 0.05, 0.2, 0.5, 0.9].into_iter().enumerate() {
        let t = frac * d.voltage_swing_v / (rg * cg + d.dark_voltage_v_per_s);
        let frame = cam
            .capture(&mean_rate, t, &NoiseSwitches::all(), 100 + i as u64)
            .unwrap();
        let (mean, var, n) = channel_stats(&frame, &cfa, g);
        assert_eq!(n, 256 * 256);
        // The model written out: S signal and D dark electrons.
        let s = rg * t;
        let dark = d.dark_voltage_v_per_s * t / cg;
        let mean_a = cg * (s + dark);
        let var_a = cg * cg * (s + dark) + (cg * s * sp).powi(2) + sd * sd + sr * sr;
        let (m2, v2) = cam.analytic_noise(rg, t, &NoiseSwitches::all());
        assert!((m2 - mean_a).abs() < 1e-15 && (v2 / var_a - 1.0).abs() < 1e-12);
        let em = 100.0 * (mean / mean_a - 1.0);
        let ev = 100.0 * (var / var_a - 1.0);
        println!(
            "{frac:>8.2} {t:>10.5} {mean:>12.6} {mean_a:>12.6} {em:>8.3} {var:>13.4e} {var_a:>13.4e} {ev:>8.3}"
        );
        assert!(em.abs() < 3.0, "mean off by {em:.2} % at {frac}");
        assert!(ev.abs() < 3.0, "variance off by {ev:.2} % at {frac}");
    }
}

#[test]
fn each_noise_source_alone_has_its_variance() {
    let cam = paper_camera();
    let d = cam.design().clone();
    let rate = 5.0e4f64; // e/s
    let t = 0.1; // 5000 e: 1.0 V
    let mean_rate = Array2::from_elem((256, 256), rate as f32);
    let cfa = Cfa::parse("A").unwrap();
    let off = NoiseSwitches::none();
    let cases = [
        ("shot", NoiseSwitches { shot: true, ..off }),
        ("read", NoiseSwitches { read: true, ..off }),
        ("dsnu", NoiseSwitches { dsnu: true, ..off }),
        ("prnu", NoiseSwitches { prnu: true, ..off }),
        ("dark", NoiseSwitches { dark: true, ..off }),
    ];
    for (name, sw) in cases {
        let frame = cam.capture(&mean_rate, t, &sw, 5).unwrap();
        let (mean, var, _) = channel_stats(&frame, &cfa, 0);
        let (mean_a, var_a) = cam.analytic_noise(rate, t, &sw);
        println!("{name}: mean {mean:.6} ({mean_a:.6}) var {var:.4e} ({var_a:.4e})");
        assert!((mean / mean_a - 1.0).abs() < 1e-3, "{name} mean");
        if var_a > 0.0 {
            assert!((var / var_a - 1.0).abs() < 0.03, "{name} variance");
        } else {
            assert!(var < 1e-12, "{name}: no noise expected, var {var}");
        }
    }
    // Dark current adds its mean: 1e-5 V/s × 0.1 s = 1 µV.
    let (m_dark, _) = cam.analytic_noise(rate, t, &NoiseSwitches { dark: true, ..off });
    assert!((m_dark - (rate * t * d.conversion_gain_v() + 1e-6)).abs() < 1e-12);
}

#[test]
fn bright_field_clips_at_the_swing_and_the_well() {
    let cam = paper_camera();
    let swing = cam.design().voltage_swing_v as f32;
    let mean_rate = Array2::from_elem((128, 128), 1.0e6f32);
    // 10× saturation.
    let t = 10.0 * 9000.0 / 1.0e6;
    let all = cam
        .capture(&mean_rate, t, &NoiseSwitches::all(), 3)
        .unwrap();
    assert!(all.iter().all(|v| *v <= swing));
    let at_swing = all.iter().filter(|v| **v == swing).count();
    // Noise after the well is symmetric, so about half the pixels sit at the swing.
    assert!(
        at_swing > all.len() / 3,
        "{at_swing} of {} at the swing",
        all.len()
    );
    let none = cam
        .capture(&mean_rate, t, &NoiseSwitches::none(), 3)
        .unwrap();
    assert!(none.iter().all(|v| *v == swing));

    // A smaller well (5000 e⁻ = 1.0 V) clips the electrons below the swing.
    let mut small = SensorDesign::paper_default();
    small.well_capacity_e = 5000.0;
    let cam = Camera::new(&small, WavelengthGrid::default(), None).unwrap();
    let none = cam
        .capture(&mean_rate, t, &NoiseSwitches::none(), 3)
        .unwrap();
    assert!(none.iter().all(|v| (*v - 1.0).abs() < 1e-6));
    let all = cam
        .capture(&mean_rate, t, &NoiseSwitches::all(), 3)
        .unwrap();
    let sigma = (1.41e-3f64.powi(2) + 1.34e-3f64.powi(2)).sqrt();
    let (mean, var, _) = channel_stats(&all, &Cfa::parse("A").unwrap(), 0);
    let max = all.iter().fold(0.0f32, |a, b| a.max(*b)) as f64;
    println!(
        "well-clipped: mean {mean:.6} V, σ {:.3} mV, max {max:.5} V",
        var.sqrt() * 1e3
    );
    assert!((mean - 1.0).abs() < 1e-3, "{mean}");
    assert!((var.sqrt() / sigma - 1.0).abs() < 0.05);
    assert!(
        max < 1.0 + 6.0 * sigma,
        "electrons above the well: max {max}"
    );
}

/// Modulation of `row` at `period` samples (an integer), by projection on
/// sine and cosine over whole periods.
fn modulation(row: &[f32], period: usize) -> f64 {
    let n = (row.len() / period) * period;
    let (mut s, mut c, mut m) = (0.0, 0.0, 0.0);
    for (i, &v) in row[..n].iter().enumerate() {
        let ph = std::f64::consts::TAU * i as f64 / period as f64;
        s += v as f64 * ph.sin();
        c += v as f64 * ph.cos();
        m += v as f64;
    }
    let amp = 2.0 * (s * s + c * c).sqrt() / n as f64;
    amp / (m / n as f64)
}

#[test]
fn optical_mtf_matches_diffraction() {
    let optics = Optics::default();
    for lambda in [450.0, 550.0, 650.0] {
        for frac in [0.25, 0.5, 0.75] {
            let fc = optics.cutoff_cyc_per_mm(lambda);
            let f = frac * fc; // cycles/mm
            let period = 24usize; // samples per period
            let dx_um = 1e3 / (f * period as f64);
            let (rows, cols) = (8, period * 16);
            let grid = WavelengthGrid {
                start_nm: lambda,
                step_nm: 10.0,
                n: 1,
            };
            let refl = Array3::from_shape_fn((1, rows, cols), |(_, _, c)| {
                (0.5 + 0.4 * (std::f64::consts::TAU * c as f64 / period as f64).sin()) as f32
            });
            let scene = Scene {
                name: "sine".into(),
                grid,
                reflectance: refl,
                illuminant: Spectrum::constant(grid, 1.0),
                illuminant_name: "E".into(),
                mean_luminance: 100.0,
                fov_deg: 1.0,
                patches: vec![],
            };
            let img = optics.image(&scene, dx_um).unwrap();
            let b = &img.blurred_reflectance;
            // Central rows, skipping 4 periods at each edge.
            let row: Vec<f32> = (4 * period..12 * period)
                .map(|c| b[(0, rows / 2, c)])
                .collect();
            let m_in = 0.4 / 0.5;
            let mtf = modulation(&row, period) / m_in;
            let expected = optics.otf(f, lambda);
            let err = 100.0 * (mtf / expected - 1.0);
            println!(
                "λ {lambda} nm, f = {frac} fc = {f:.1} cyc/mm: MTF {mtf:.4}, diffraction {expected:.4}, error {err:.3} %"
            );
            assert!(err.abs() < 5.0);
            if frac == 0.5 {
                assert!((expected - 0.3910).abs() < 1e-3);
            }
        }
    }
}

#[test]
fn same_seed_same_bytes_other_seed_same_statistics() {
    let cam = paper_camera();
    let scene = textured_scene(96, 128);
    let exp = Exposure::Auto {
        target_fraction: 0.95,
    };
    let a = simulate(&cam, &scene, exp, &NoiseSwitches::all(), 11).unwrap();
    let b = simulate(&cam, &scene, exp, &NoiseSwitches::all(), 11).unwrap();
    let bits = |x: &Array2<f32>| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a.volts), bits(&b.volts));
    assert_eq!(a.exposure_s, b.exposure_s);
    let c = simulate(&cam, &scene, exp, &NoiseSwitches::all(), 12).unwrap();
    let differ = a
        .volts
        .iter()
        .zip(c.volts.iter())
        .filter(|(x, y)| x != y)
        .count();
    assert!(
        differ > a.volts.len() * 9 / 10,
        "only {differ} pixels differ"
    );

    // Statistics: on a flat field, two seeds give the same mean and variance.
    let flat = flat_scene(256, 256, 0.4, 100.0);
    let f1 = simulate(&cam, &flat, exp, &NoiseSwitches::all(), 1).unwrap();
    let f2 = simulate(&cam, &flat, exp, &NoiseSwitches::all(), 2).unwrap();
    for ch in 0..cam.cfa().n_channels() {
        let (m1, v1, _) = channel_stats(&f1.volts, cam.cfa(), ch);
        let (m2, v2, _) = channel_stats(&f2.volts, cam.cfa(), ch);
        println!(
            "channel {}: mean {m1:.5} / {m2:.5} V, var {v1:.4e} / {v2:.4e}",
            cam.cfa().channel_names[ch]
        );
        assert!((m1 / m2 - 1.0).abs() < 0.01);
        assert!((v1 / v2 - 1.0).abs() < 0.06);
    }
    // Frame noise (not the fixed pattern) differs: the difference of two
    // frames has twice the shot + read variance.
    let w = cam.cfa().channel_index("W").unwrap();
    let diff = &f1.volts - &f2.volts;
    let (_, vd, _) = channel_stats(&diff, cam.cfa(), w);
    let rates = cam
        .channel_rates(&cam.optical_image(&flat).unwrap())
        .unwrap();
    let rw = rates[(w, 10, 10)] as f64;
    let sw = NoiseSwitches {
        shot: true,
        read: true,
        ..NoiseSwitches::none()
    };
    let (_, v_frame) = cam.analytic_noise(rw, f1.exposure_s, &sw);
    let dark_e = 1e-5 * f1.exposure_s / 200e-6;
    let v_frame = v_frame + (200e-6f64).powi(2) * dark_e;
    println!(
        "frame-difference variance {vd:.4e}, expected {:.4e}",
        2.0 * v_frame
    );
    assert!((vd / (2.0 * v_frame) - 1.0).abs() < 0.05);
}

#[test]
fn auto_exposure_and_xyz_target_convention() {
    let grid = WavelengthGrid::default();
    let cam = paper_camera();
    // Equal-energy light on a perfect white.
    let mut scene = flat_scene(32, 32, 1.0, 100.0);
    scene.illuminant = Spectrum::constant(grid, 1.0);
    let cap = simulate(
        &cam,
        &scene,
        Exposure::Auto {
            target_fraction: 0.95,
        },
        &NoiseSwitches::none(),
        0,
    )
    .unwrap();
    // The brightest channel (W) sits at 95 % of the swing.
    let max = cap.volts.iter().fold(0.0f32, |a, b| a.max(*b)) as f64;
    assert!((max / (0.95 * 1.8) - 1.0).abs() < 1e-5, "{max}");
    // Y equals the mean over channels of the channel volts.
    let mean_ch: f64 = (0..4)
        .map(|ch| channel_stats(&cap.volts, &cap.cfa, ch).0)
        .sum::<f64>()
        / 4.0;
    let y = cap.ideal_xyz[(16, 16, 1)] as f64;
    println!(
        "equal-energy white: Y {y:.6} V, mean channel {mean_ch:.6} V, X {:.6} Z {:.6}, κ {:.4e} e/J",
        cap.ideal_xyz[(16, 16, 0)],
        cap.ideal_xyz[(16, 16, 2)],
        cam.xyz_scale()
    );
    assert_eq!(cap.ideal_xyz.dim(), (32, 32, 3));
    // Minus the tiny dark signal in the channel volts.
    let dark_v = 1e-5 * cap.exposure_s;
    assert!(((mean_ch - dark_v) / y - 1.0).abs() < 1e-5);
    // CIE E: X ≈ Y ≈ Z (the CMFs have equal areas over 360–830 nm; cut to
    // 400–700 nm, X and Z lose 0.1–0.2 % more than Y).
    let x = cap.ideal_xyz[(16, 16, 0)] as f64;
    let z = cap.ideal_xyz[(16, 16, 2)] as f64;
    assert!(
        (x / y - 1.0).abs() < 4e-3 && (z / y - 1.0).abs() < 4e-3,
        "{x} {y} {z}"
    );
}

#[test]
fn relighting_keeps_luminance_and_shares_the_blur() {
    let grid = WavelengthGrid::default();
    let cam = paper_camera();
    let scene = textured_scene(40, 48);
    let optical = cam.optical_image(&scene).unwrap();
    // The radiance scale makes the mean luminance the scene's.
    let ybar = l3::spectral::cie1931_cmfs()[1].resample(&grid, Extrapolation::Zero);
    let lum = |o: &l3::camera::OpticalImage| {
        (0..grid.n)
            .map(|b| {
                683.0
                    * ybar.values()[b]
                    * o.mean_reflectance[b]
                    * o.illuminant.values()[b]
                    * o.radiance_scale
                    * grid.step_nm
            })
            .sum::<f64>()
    };
    assert!((lum(&optical) / 200.0 - 1.0).abs() < 1e-9);
    let a = cie_illuminant("A")
        .unwrap()
        .resample(&grid, Extrapolation::Zero);
    let relit = optical.relit(&a, 50.0).unwrap();
    assert!(Arc::ptr_eq(
        &relit.blurred_reflectance,
        &optical.blurred_reflectance
    ));
    assert!((lum(&relit) / 50.0 - 1.0).abs() < 1e-9);
    // XYZ under another light at the same luminance: mean Y is unchanged
    // (mean Y is linear in the mean reflectance, which blur preserves up to
    // the boundary).
    let y_mean = |x: &Array3<f32>| {
        x.index_axis(ndarray::Axis(2), 1)
            .iter()
            .map(|v| *v as f64)
            .sum::<f64>()
            / x.len() as f64
            * 3.0
    };
    let xyz_d65 = cam.xyz_rates(&optical, &scene.illuminant).unwrap();
    let xyz_a = cam.xyz_rates(&optical, &a).unwrap();
    let (yd, ya) = (y_mean(&xyz_d65), y_mean(&xyz_a));
    println!("mean Y rate: D65 {yd:.5} V/s, A {ya:.5} V/s");
    assert!((yd / ya - 1.0).abs() < 1e-3);
    // Errors: wrong grid, negative luminance.
    let other = WavelengthGrid::new(400.0, 700.0, 20.0).unwrap();
    assert!(
        optical
            .relit(&Spectrum::constant(other, 1.0), 10.0)
            .is_err()
    );
    assert!(optical.relit(&a, -1.0).is_err());
}

#[test]
fn finer_optical_sampling_bins_into_pixels() {
    // A flat scene sampled at half the pixel pitch gives the same rates as
    // at the pitch (each pixel integrates 2×2 samples).
    let cam = paper_camera();
    let scene = flat_scene(16, 16, 0.3, 80.0);
    let coarse = cam
        .channel_rates(&cam.optical_image(&scene).unwrap())
        .unwrap();
    let fine_scene = flat_scene(32, 32, 0.3, 80.0);
    let fine = cam
        .channel_rates(&cam.optics().image(&fine_scene, 1.1).unwrap())
        .unwrap();
    assert_eq!(fine.dim(), coarse.dim());
    for (a, b) in fine.iter().zip(coarse.iter()) {
        assert!((a / b - 1.0).abs() < 1e-5);
    }
    // A spacing that does not divide the pixel is refused.
    let odd = cam.optics().image(&fine_scene, 1.5).unwrap();
    assert!(cam.channel_rates(&odd).is_err());
}

#[test]
fn ar0132at_camera_simulates_on_its_built_in_curves() {
    let path = std::path::Path::new(env!("L3_ROOT")).join("config/sensors/rgbw-ar0132at.toml");
    let design = SensorDesign::load(&path, None).unwrap();
    let cam = Camera::new(&design, WavelengthGrid::default(), None).unwrap();
    let cap = simulate(
        &cam,
        &textured_scene(64, 64),
        Exposure::default(),
        &NoiseSwitches::all(),
        9,
    )
    .unwrap();
    assert!(
        cap.volts
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0 && *v <= 1.8)
    );
    assert!(cap.ideal_xyz.iter().all(|v| v.is_finite() && *v >= 0.0));
    println!(
        "AR0132AT: exposure {:.4} ms, κ {:.4e} e/J",
        cap.exposure_s * 1e3,
        cam.xyz_scale()
    );
}

/// The Natural-100 chart on ISET's RGBW under tungsten, noise-free: the
/// mean and the largest relative difference, over patches and channels,
/// between a patch interior's bilinear-demosaicked channel mean and the
/// same mean of the channel at every pixel (no mosaic).
fn mosaic_error_on_chart(samples_per_pixel: u32) -> (f64, f64) {
    let path = std::path::Path::new(env!("L3_ROOT")).join("config/sensors/rgbw-iset.toml");
    let mut design = SensorDesign::load(&path, None).unwrap();
    design.optics.samples_per_pixel = samples_per_pixel;
    let cam = Camera::new(&design, WavelengthGrid::default(), None).unwrap();
    let setup = l3::eval::ChartSetup {
        noise: false,
        ..Default::default()
    };
    let (scene, _) = l3::eval::chart_scene(&cam, "Tungsten", None, &setup).unwrap();
    let rates = cam
        .channel_rates(&cam.optical_image(&scene).unwrap())
        .unwrap();
    let (nc, rows, cols) = rates.dim();
    let cfa = cam.cfa();
    let raw: Vec<f32> = (0..rows * cols)
        .map(|i| rates[[cfa.channel_at(i / cols, i % cols), i / cols, i % cols]])
        .collect();
    let dm = l3::baseline::bilinear_demosaic(&raw, cols, rows, cfa).unwrap();
    let (mut worst, mut sum, mut n) = (0f64, 0f64, 0usize);
    for p in &scene.patches {
        let (r0, c0, h, w) = l3::eval::interior(p);
        for ch in 0..nc {
            let (mut full, mut demosaicked) = (0f64, 0f64);
            for r in r0..r0 + h {
                for c in c0..c0 + w {
                    full += f64::from(rates[[ch, r, c]]);
                    demosaicked += f64::from(dm[(r * cols + c) * nc + ch]);
                }
            }
            let e = (demosaicked / full - 1.0).abs();
            worst = worst.max(e);
            sum += e;
            n += 1;
        }
    }
    (sum / n as f64, worst)
}

#[test]
fn pixel_aperture_sampling_halves_the_mosaic_error_on_a_chart() {
    // One optical sample per pixel cuts the OTF at the pixel Nyquist, so the
    // chart's edges ring there and the mosaic turns the ringing into colour
    // inside flat patches (mean 0.065 %, worst 0.95 % of a channel here,
    // which this sensor's colour map amplifies to 0.6 ΔE2000 on the chart);
    // two samples per pixel, binned, leave the blur's own gradient (0.030 %,
    // 0.37 %).
    let one = mosaic_error_on_chart(1);
    let two = mosaic_error_on_chart(2);
    eprintln!("mean and largest relative error: one sample {one:?}, two {two:?}");
    assert!(one.1 > 0.005, "one sample per pixel: {one:?}");
    assert!(
        two.0 < one.0 / 2.0,
        "two samples per pixel: {two:?} against {one:?}"
    );
    assert!(
        two.1 < one.1 / 2.0,
        "two samples per pixel: {two:?} against {one:?}"
    );
}

#[test]
fn samples_per_pixel_keep_a_flat_scene_and_the_design_bounds_them() {
    let mut design = SensorDesign::paper_default();
    assert_eq!(
        design.optics.samples_per_pixel,
        l3::camera::DEFAULT_SAMPLES_PER_PIXEL
    );
    let scene = flat_scene(16, 16, 0.3, 80.0);
    let rates = |d: &SensorDesign| {
        let cam = Camera::new(d, WavelengthGrid::default(), None).unwrap();
        cam.channel_rates(&cam.optical_image(&scene).unwrap())
            .unwrap()
    };
    let two = rates(&design);
    design.optics.samples_per_pixel = 1;
    let one = rates(&design);
    assert_eq!(one.dim(), two.dim());
    for (a, b) in one.iter().zip(two.iter()) {
        assert!((a / b - 1.0).abs() < 1e-5);
    }
    for bad in [0, l3::camera::MAX_SAMPLES_PER_PIXEL + 1] {
        design.optics.samples_per_pixel = bad;
        let e = design.validate().unwrap_err().to_string();
        assert!(e.contains("samples_per_pixel"), "{e}");
    }
}
