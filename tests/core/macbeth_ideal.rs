//! Simulator acceptance 5: the Macbeth chart under D65, through the
//! noise-free ideal-XYZ path (scene → optics → ideal XYZ on the sensor grid),
//! reproduces each patch's colorimetric XYZ (reflectance × D65 × CMFs)
//! within 0.5 ΔE2000 (patches large enough that lens flare from the
//! neighbours does not reach their interiors).

use l3::camera::{Camera, Exposure, NoiseSwitches, SensorDesign, simulate};
use l3::colour::{Cmfs, D65_WHITE_XYZ, ciede2000, xyz_to_lab};
use l3::eval::patch_means;
use l3::scene::{SceneOptions, macbeth};
use l3::spectral::{Extrapolation, IsetData, WavelengthGrid, cie_illuminant};

#[test]
fn macbeth_ideal_xyz_matches_colorimetry() {
    let grid = WavelengthGrid::default();
    let camera = Camera::new(&SensorDesign::paper_default(), grid, None).unwrap();
    let d65 = cie_illuminant("D65")
        .unwrap()
        .resample(&grid, Extrapolation::Zero);
    let opts = SceneOptions::new(grid, d65.clone(), "D65").unwrap();
    // 96-px patches: the diffraction tail of the f/4 lens (about 5 % of a
    // neighbour's light lands beyond 4 px) stays out of the patch interiors.
    let scene = macbeth(IsetData::built_in(), &opts, 96).unwrap();
    let cap = simulate(
        &camera,
        &scene,
        Exposure::default(),
        &NoiseSwitches::none(),
        1,
    )
    .unwrap();
    let (h, w) = cap.volts.dim();
    assert_eq!(cap.ideal_xyz.dim(), (h, w, 3));
    let means = patch_means(&scene.patches, cap.ideal_xyz.as_slice().unwrap(), w);
    let cmfs = Cmfs::cie1931(&grid);
    let truth: Vec<_> = scene
        .patches
        .iter()
        .map(|p| cmfs.reflectance_xyz(&p.reflectance, &d65).unwrap())
        .collect();
    // both sides normalised by the white patch (the brightest)
    let wi = (0..truth.len())
        .max_by(|&a, &b| truth[a][1].total_cmp(&truth[b][1]))
        .unwrap();
    let mut worst = 0f64;
    for (i, p) in scene.patches.iter().enumerate() {
        let t = truth[i].map(|v| v / truth[wi][1]);
        let e = means[i].map(|v| v / means[wi][1]);
        let de = ciede2000(xyz_to_lab(t, D65_WHITE_XYZ), xyz_to_lab(e, D65_WHITE_XYZ));
        println!("{:<24} ΔE2000 {de:.3}", p.name);
        worst = worst.max(de);
    }
    println!("worst {worst:.3}");
    assert!(worst < 0.5, "worst patch ΔE2000 {worst}");
}
