//! Property tests missing from `colour_reference.rs` and
//! `render_properties.rs` (issue 6):
//! - T(D65) = identity for any reflectance subset, D65 scale and constraint;
//! - fused T·K equals applying K then T, over random matrices and frames;
//! - the full sRGB8 → sRGB → linear → XYZ → Lab → XYZ → linear → sRGB8 chain.
//!
//! Already covered elsewhere (not repeated here): CIEDE2000 symmetric, zero on
//! identity and non-negative, XYZ ↔ Lab, linear sRGB ↔ XYZ and sRGB encode ↔
//! decode round trips (`colour_reference.rs`); a CFA-period shift of the input
//! shifts the output, and a uniform grey field renders to a uniform neutral
//! interior (`render_properties.rs`).

use std::sync::OnceLock;

use l3::colour::{
    Cmfs, D65_WHITE_XYZ, encode_srgb8, lab_to_xyz, linear_srgb_to_xyz, srgb_decode, xyz_to_lab,
    xyz_to_linear_srgb,
};
use l3::l3::correct::{IDENTITY, correction_matrix, default_reflectances};
use l3::l3::render::{fuse_kernels, render_reference};
use l3::spectral::{Extrapolation, Spectrum, WavelengthGrid, cie_illuminant};
use l3::test_support::tiny_table;
use proptest::prelude::*;

fn reflectances() -> &'static Vec<Spectrum> {
    static R: OnceLock<Vec<Spectrum>> = OnceLock::new();
    R.get_or_init(|| default_reflectances(&WavelengthGrid::default()))
}

fn matrix_strategy() -> impl Strategy<Value = [[f64; 3]; 3]> {
    prop::array::uniform3(prop::array::uniform3(-3.0..3.0f64))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn t_of_d65_is_the_identity(
        start in 0usize..1200, len in 3usize..200, scale in 1e-3..1e3f64, white_preserving: bool
    ) {
        let grid = WavelengthGrid::default();
        let cmfs = Cmfs::cie1931(&grid);
        let all = reflectances();
        let start = start.min(all.len() - len);
        let subset = &all[start..start + len];
        let d65 = cie_illuminant("D65").unwrap().resample(&grid, Extrapolation::Zero);
        // the acquisition side scaled: T normalises each side by its white
        let t = correction_matrix(&cmfs, subset, &d65.scaled(scale), &d65, white_preserving).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                prop_assert!((t[i][j] - IDENTITY[i][j]).abs() < 1e-8, "T = {t:?}");
            }
        }
    }

    #[test]
    fn fused_kernels_equal_kernels_then_t(
        m in matrix_strategy(),
        seed in 0u64..10_000,
        w in 1usize..20,
        h in 1usize..20,
        gain in 0.0f32..2.0,
    ) {
        let t = tiny_table();
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let volts: Vec<f32> = (0..w * h)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 40) as f32 / (1u64 << 24) as f32 * gain
            })
            .collect();
        let fused = fuse_kernels(t, &m);
        let (a, sa) = render_reference(t, &t.kernels, &volts, w, h).unwrap();
        let (b, sb) = render_reference(t, &fused, &volts, w, h).unwrap();
        prop_assert_eq!(sa, sb);
        let scale = a.iter().fold(0f32, |acc, v| acc.max(v.abs())).max(1e-3);
        for (pa, pb) in a.chunks_exact(3).zip(b.chunks_exact(3)) {
            for i in 0..3 {
                let want: f64 = (0..3).map(|k| m[i][k] * pa[k] as f64).sum();
                let tol = 1e-5 * (1.0 + 9.0 * scale as f64);
                prop_assert!((want - pb[i] as f64).abs() <= tol, "{want} vs {}", pb[i]);
            }
        }
    }

    #[test]
    fn srgb8_lab_chain_round_trips(r in 0u8..=255, g in 0u8..=255, b in 0u8..=255) {
        let code = [r, g, b];
        let lin = code.map(|c| srgb_decode(c as f64 / 255.0));
        let xyz = linear_srgb_to_xyz(lin);
        let lab = xyz_to_lab(xyz, D65_WHITE_XYZ);
        prop_assert!(lab.iter().all(|v| v.is_finite()));
        prop_assert!((0.0..=100.0 + 1e-9).contains(&lab[0]));
        let back = xyz_to_linear_srgb(lab_to_xyz(lab, D65_WHITE_XYZ));
        for k in 0..3 {
            prop_assert!((back[k] - lin[k]).abs() < 1e-9, "{lin:?} -> {back:?}");
            prop_assert_eq!(encode_srgb8(back[k]), code[k]);
        }
        // neutral codes are neutral in Lab (the sRGB white is D65)
        if r == g && g == b {
            prop_assert!(lab[1].abs() < 1e-3 && lab[2].abs() < 1e-3, "{lab:?}");
        }
    }
}
