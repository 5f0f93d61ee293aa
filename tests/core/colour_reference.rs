//! Reference values for the colour module: the Sharma (2005) CIEDE2000 pairs,
//! CIE white points, sRGB round trips, CCT; plus property tests.

use std::path::PathBuf;

use l3::colour::*;
use l3::spectral::{Extrapolation, Spectrum, WavelengthGrid, cie_illuminant};
use proptest::prelude::*;

fn ref_file(name: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("L3_ROOT"))
        .join("../shared/data/ref")
        .join(name);
    if p.is_file() {
        Some(p)
    } else if std::env::var_os("CI").is_some() {
        panic!("CI is set but {} is missing", p.display());
    } else {
        eprintln!("skipped: {} not found", p.display());
        None
    }
}

#[test]
fn sharma_2005_pairs() {
    let Some(path) = ref_file("sharma2005_ciede2000.csv") else {
        return;
    };
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<&str> = lines.next().unwrap().split(',').map(str::trim).collect();
    assert_eq!(header, ["L1", "a1", "b1", "L2", "a2", "b2", "dE"]);
    let mut n = 0;
    let mut worst: f64 = 0.0;
    for line in lines {
        let v: Vec<f64> = line.split(',').map(|c| c.trim().parse().unwrap()).collect();
        assert_eq!(v.len(), 7, "{line}");
        let a = [v[0], v[1], v[2]];
        let b = [v[3], v[4], v[5]];
        let d = ciede2000(a, b);
        let e = (d - v[6]).abs();
        worst = worst.max(e);
        assert!(e < 1e-4, "pair {}: {d} vs {}", n + 1, v[6]);
        // The formula is symmetric.
        assert!((ciede2000(b, a) - d).abs() < 1e-12);
        n += 1;
    }
    println!("CIEDE2000: {n} pairs, max |error| {worst:.2e}");
    assert_eq!(n, 34);
}

fn white_100(name: &str, grid: WavelengthGrid) -> Xyz {
    let cmfs = Cmfs::cie1931(&grid);
    let spd = cie_illuminant(name)
        .unwrap()
        .resample(&grid, Extrapolation::Zero);
    cmfs.white(&spd).unwrap().map(|v| 100.0 * v)
}

fn assert_close(got: Xyz, want: Xyz, tol: f64, what: &str) {
    println!("{what}: {got:.3?} (reference {want:?})");
    for k in 0..3 {
        assert!(
            (got[k] - want[k]).abs() <= tol,
            "{what}: {got:?} vs {want:?}"
        );
    }
}

#[test]
fn cie_white_points() {
    let g1 = WavelengthGrid::new(380.0, 780.0, 1.0).unwrap();
    let g10 = WavelengthGrid::new(380.0, 780.0, 10.0).unwrap();
    let d65 = [95.047, 100.0, 108.883];
    assert_close(white_100("D65", g1), d65, 0.05, "D65 at 1 nm");
    assert_close(white_100("D65", g10), d65, 0.2, "D65 at 10 nm");
    let a = [109.85, 100.0, 35.58];
    assert_close(white_100("A", g1), a, 0.2, "A at 1 nm");
    assert_close(white_100("A", g10), a, 0.2, "A at 10 nm");
    // The default grid (400–700 nm at 10 nm) loses the tails: say by how much.
    let d = white_100("D65", WavelengthGrid::default());
    println!("D65 on the default 400–700/10 grid: {d:.3?}");
    assert_close(d, d65, 0.5, "D65 on 400–700 nm");
}

#[test]
fn cct_of_d65_and_a() {
    let g1 = WavelengthGrid::new(380.0, 780.0, 1.0).unwrap();
    let t65 = cct_from_xy(xy(white_100("D65", g1))).unwrap();
    let ta = cct_from_xy(xy(white_100("A", g1))).unwrap();
    let t65_const = cct_from_xy(xy(D65_WHITE_XYZ)).unwrap();
    println!("CCT: D65 {t65:.1} K (constant white {t65_const:.1} K), A {ta:.1} K");
    assert!((t65 - 6504.0).abs() <= 5.0, "{t65}");
    assert!((t65_const - 6504.0).abs() <= 5.0, "{t65_const}");
    assert!((ta - 2856.0).abs() <= 5.0, "{ta}");
}

#[test]
fn srgb_round_trip_f64() {
    let mut worst: f64 = 0.0;
    let n = 20;
    for r in 0..=n {
        for g in 0..=n {
            for b in 0..=n {
                let rgb = [r, g, b].map(|v| v as f64 / n as f64);
                let back = xyz_to_linear_srgb(linear_srgb_to_xyz(rgb));
                let enc = rgb.map(|v| srgb_decode(srgb_encode(v)));
                for k in 0..3 {
                    worst = worst.max((back[k] - rgb[k]).abs());
                    worst = worst.max((enc[k] - rgb[k]).abs());
                }
            }
        }
    }
    println!("sRGB round trip max error {worst:.2e}");
    assert!(worst < 1e-6);
    // D65 white (constant) maps to (near) equal RGB.
    let w = xyz_to_linear_srgb(D65_WHITE_XYZ);
    assert!(w.iter().all(|v| (v - 1.0).abs() < 1e-3), "{w:?}");
}

#[test]
fn reflectance_xyz_of_grey_is_proportional_to_white() {
    let g = WavelengthGrid::default();
    let cmfs = Cmfs::cie1931(&g);
    let d65 = cie_illuminant("D65")
        .unwrap()
        .resample(&g, Extrapolation::Zero);
    let grey = cmfs
        .reflectance_xyz(&Spectrum::constant(g, 0.18), &d65)
        .unwrap();
    let white = cmfs.white(&d65).unwrap();
    for k in 0..3 {
        assert!((grey[k] - 0.18 * white[k]).abs() < 1e-12);
    }
    let lab = xyz_to_lab(grey, white);
    assert!((lab[0] - 49.496).abs() < 0.01, "{lab:?}");
}

fn lab_strategy() -> impl Strategy<Value = Lab> {
    (0.0..100.0f64, -128.0..128.0f64, -128.0..128.0f64).prop_map(|(l, a, b)| [l, a, b])
}

proptest! {
    #[test]
    fn ciede2000_is_a_symmetric_nonnegative_distance(a in lab_strategy(), b in lab_strategy()) {
        let d = ciede2000(a, b);
        prop_assert!(d >= 0.0 && d.is_finite());
        prop_assert!((d - ciede2000(b, a)).abs() < 1e-9);
        prop_assert_eq!(ciede2000(a, a), 0.0);
        if a != b {
            prop_assert!(d > 0.0);
        }
    }

    #[test]
    fn ciede2000_metric_is_its_second_order_expansion(
        a in lab_strategy(),
        dir in (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64),
    ) {
        // away from the neutral axis, where ΔE00's hue term is smooth
        prop_assume!(a[1].hypot(a[2]) > 2.0);
        let d = [dir.0, dir.1, dir.2];
        prop_assume!(d.iter().map(|v| v * v).sum::<f64>() > 0.01);
        let h = 1e-4;
        let q = ciede2000_metric(a);
        let quad: f64 = (0..3)
            .map(|i| (0..3).map(|j| d[i] * q[i][j] * d[j]).sum::<f64>())
            .sum::<f64>()
            * h
            * h;
        let de = ciede2000(a, [a[0] + h * d[0], a[1] + h * d[1], a[2] + h * d[2]]);
        prop_assert!(quad >= 0.0);
        prop_assert!((quad - de * de).abs() <= 1e-3 * de * de, "{:?} {:?}: {} against {}", a, d, quad, de * de);
    }

    #[test]
    fn xyz_lab_round_trip(x in 0.0..1.2f64, y in 0.0..1.2f64, z in 0.0..1.2f64) {
        let v = [x, y, z];
        let back = lab_to_xyz(xyz_to_lab(v, D65_WHITE_XYZ), D65_WHITE_XYZ);
        for k in 0..3 {
            prop_assert!((back[k] - v[k]).abs() < 1e-10, "{:?} -> {:?}", v, back);
        }
    }

    #[test]
    fn linear_srgb_xyz_round_trip(r in -0.5..1.5f64, g in -0.5..1.5f64, b in -0.5..1.5f64) {
        let v = [r, g, b];
        let back = xyz_to_linear_srgb(linear_srgb_to_xyz(v));
        for k in 0..3 {
            prop_assert!((back[k] - v[k]).abs() < 1e-12);
        }
    }

    #[test]
    fn srgb_encode_decode_round_trip(v in 0.0..1.0f64, code in 0u8..=255) {
        prop_assert!((srgb_decode(srgb_encode(v)) - v).abs() < 1e-12);
        let lin = srgb_decode(code as f64 / 255.0);
        prop_assert_eq!(encode_srgb8(lin), code);
        let lut = SrgbLut::new();
        prop_assert!((lut.encode(v as f32) as i32 - encode_srgb8(v) as i32).abs() <= 1);
    }
}
