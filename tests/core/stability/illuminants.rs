//! The correction T for near-monochromatic (LED) and degenerate illuminants.

use crate::iset_reference;

use l3::colour::{Cmfs, D65_WHITE_XYZ, ciede2000, xyz_to_lab};
use l3::l3::correct::{IDENTITY, correction_matrix, default_reflectances};
use l3::l3::render::fuse_kernels;
use l3::spectral::{Extrapolation, Spectrum, WavelengthGrid, cie_illuminant};
use l3::test_support::tiny_table;

use super::KERNEL_NORM_BOUND;

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
