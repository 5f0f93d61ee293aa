//! Scene builders: Natural-100, Macbeth, dead leaves, image lift, errors.

use std::collections::{HashMap, HashSet};

use l3::colour::{Cmfs, encode_srgb8, linear_srgb_to_xyz, srgb_decode, xyz_to_linear_srgb};
use l3::scene::*;
use l3::spectral::{Extrapolation, IsetData, Spectrum, WavelengthGrid, ces_reflectances};

fn opts() -> SceneOptions {
    SceneOptions::d65(WavelengthGrid::default()).unwrap()
}

#[test]
fn natural100_has_100_distinct_samples_in_category_counts_and_is_deterministic() {
    let iset = IsetData::built_in();
    let samples = natural100_samples(iset).unwrap();
    assert_eq!(samples.len(), 100);
    let names: HashSet<_> = samples.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names.len(), 100, "samples must be distinct");
    let mut counts: HashMap<&str, usize> = HashMap::new();
    for s in &samples {
        *counts.entry(s.category.as_str()).or_default() += 1;
    }
    for cat in NATURAL100_CATEGORIES {
        assert_eq!(counts.get(cat.name), Some(&cat.count), "{}", cat.name);
        // Every pick belongs to its category's files.
        let mut members = HashSet::new();
        for f in cat.files {
            members.extend(iset.table(f).unwrap().names);
        }
        let picks: Vec<_> = samples
            .iter()
            .filter(|s| s.category == cat.name)
            .map(|s| s.name.clone())
            .collect();
        assert!(picks.iter().all(|n| members.contains(n)), "{}", cat.name);
        println!("{:8} {}", cat.name, picks.join(" "));
    }
    // Distinct spectra, not just distinct names.
    let spectra: HashSet<Vec<u64>> = samples
        .iter()
        .map(|s| s.samples.values().iter().map(|v| v.to_bits()).collect())
        .collect();
    assert_eq!(spectra.len(), 100);

    let a = natural100_chart(iset, &opts(), NATURAL100_PATCH_PX).unwrap();
    let b = natural100_chart(iset, &opts(), NATURAL100_PATCH_PX).unwrap();
    assert_eq!(a.patches.len(), 110);
    assert_eq!((a.rows(), a.cols()), (11 * 24, 10 * 24));
    let greys: Vec<_> = a.patches.iter().filter(|p| p.category == "grey").collect();
    assert_eq!(greys.len(), 10);
    assert!(greys.iter().all(|p| p.row == 10 * 24));
    assert_eq!(a.reflectance, b.reflectance);
    let pa: Vec<_> = a.patches.iter().map(|p| (&p.name, p.row, p.col)).collect();
    let pb: Vec<_> = b.patches.iter().map(|p| (&p.name, p.row, p.col)).collect();
    assert_eq!(pa, pb);
    // A patch's pixels hold its reflectance.
    let p = &a.patches[37];
    for (band, v) in p.reflectance.values().iter().enumerate() {
        let got = a.reflectance[[band, p.row + 5, p.col + 7]];
        assert!((got as f64 - v).abs() < 1e-6);
    }
    // Another seed gives another (still valid) selection.
    let other = natural100_samples_seeded(iset, 7).unwrap();
    let other_names: HashSet<_> = other.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(other_names.len(), 100);
    println!(
        "seed 7 shares {} of 100 samples with the default seed",
        other_names.intersection(&names).count()
    );
}

#[test]
fn ces_chart_has_the_99_ces_and_the_grey_strip() {
    let s = ces_chart(&opts(), 8).unwrap();
    assert_eq!(s.name, "ces99");
    assert_eq!(s.patches.len(), 109);
    assert_eq!((s.rows(), s.cols()), (11 * 8, 10 * 8));
    assert_eq!(ces_samples().len(), 99);
}

#[test]
fn macbeth_has_24_patches_with_the_grey_series_in_the_bottom_row() {
    let s = macbeth(IsetData::built_in(), &opts(), 10).unwrap();
    assert_eq!(s.patches.len(), 24);
    assert_eq!((s.rows(), s.cols()), (40, 60));
    let cmfs = Cmfs::cie1931(&s.grid);
    let mut last_y = f64::INFINITY;
    for (i, p) in s.patches.iter().enumerate() {
        let (row, col) = (p.row / 10, p.col / 10);
        assert_eq!(row * 6 + col, i);
        let grey = p.category == "grey";
        assert_eq!(grey, row == 3, "{}", p.name);
        if grey {
            let xyz = cmfs.reflectance_xyz(&p.reflectance, &s.illuminant).unwrap();
            println!("{:20} Y = {:.3}", p.name, xyz[1]);
            assert!(xyz[1] < last_y, "neutral series gets darker left to right");
            last_y = xyz[1];
            // Neutral: flat within a few percent of its mean.
            let v = p.reflectance.values();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            assert!(
                v.iter().all(|x| (x - mean).abs() < 0.35 * mean + 0.01),
                "{}",
                p.name
            );
        }
    }
    assert!(s.patches[0].name.contains("dark_skin"));
    assert!(s.patches[18].name.contains("white"));
    assert!(s.patches[23].name.contains("black"));
}

fn ces_set(grid: &WavelengthGrid) -> Vec<Spectrum> {
    ces_reflectances()
        .iter()
        .take(20)
        .map(|(_, s)| s.resample(grid, Extrapolation::Hold))
        .collect()
}

#[test]
fn dead_leaves_is_reproducible_by_seed() {
    let o = opts();
    let set = ces_set(&o.grid);
    let p = DeadLeavesParams::new(96, 128, 42);
    let a = dead_leaves(&o, &set, &p).unwrap();
    let b = dead_leaves(&o, &set, &p).unwrap();
    assert_eq!(a.reflectance, b.reflectance);
    let c = dead_leaves(&o, &set, &DeadLeavesParams { seed: 43, ..p }).unwrap();
    assert_ne!(a.reflectance, c.reflectance);
    // Every pixel holds one of the set's reflectances.
    let labels = dead_leaves_labels(&p, set.len()).unwrap();
    let used: HashSet<_> = labels.iter().collect();
    println!(
        "dead leaves 96×128: {} of {} reflectances used",
        used.len(),
        set.len()
    );
    assert!(used.len() >= 10);
    for (i, &l) in labels.iter().enumerate().step_by(97) {
        let (r, c) = (i / 128, i % 128);
        let want = set[l as usize].values()[10] as f32;
        assert_eq!(a.reflectance[[10, r, c]], want);
    }
}

/// The XYZ scaling the lift documents: sRGB white → spectral D65 white.
fn rendered_srgb8(scene: &Scene, row: usize, col: usize) -> [u8; 3] {
    let cmfs = Cmfs::cie1931(&scene.grid);
    let d65 = &scene.illuminant;
    let r: Vec<f64> = (0..scene.bands())
        .map(|b| scene.reflectance[[b, row, col]] as f64)
        .collect();
    let xyz = cmfs
        .reflectance_xyz(&Spectrum::new(scene.grid, r).unwrap(), d65)
        .unwrap();
    let white = cmfs.white(d65).unwrap();
    let srgb_white = linear_srgb_to_xyz([1.0; 3]);
    let xyz = [0, 1, 2].map(|k| xyz[k] * srgb_white[k] / white[k]);
    xyz_to_linear_srgb(xyz).map(encode_srgb8)
}

#[test]
fn image_lift_reproduces_in_gamut_srgb() {
    // Macbeth-like sRGB colours, greys, and a gentle gradient.
    let colours: [[u8; 3]; 12] = [
        [115, 82, 68],
        [194, 150, 130],
        [98, 122, 157],
        [87, 108, 67],
        [133, 128, 177],
        [103, 189, 170],
        [214, 126, 44],
        [80, 91, 166],
        [193, 90, 99],
        [160, 160, 160],
        [243, 243, 242],
        [52, 52, 52],
    ];
    let img = image::RgbImage::from_fn(12, 3, |x, y| {
        let c = colours[x as usize];
        image::Rgb(c.map(|v| v.saturating_sub(10 * y as u8)))
    });
    let s = from_srgb_image(&opts(), &img).unwrap();
    assert_eq!((s.rows(), s.cols(), s.bands()), (3, 12, 31));
    assert!(s.reflectance.iter().all(|&v| (0.0..=1.0).contains(&v)));
    let mut worst = 0i32;
    for y in 0..3 {
        for x in 0..12 {
            let want = img.get_pixel(x, y).0;
            let got = rendered_srgb8(&s, y as usize, x as usize);
            for k in 0..3 {
                worst = worst.max((want[k] as i32 - got[k] as i32).abs());
            }
        }
    }
    println!("image lift: worst sRGB error {worst} codes over 36 in-gamut pixels");
    assert!(worst <= 1);

    // The file path gives the same scene (PNG round trip).
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("colours.png");
    img.save(&path).unwrap();
    let f = from_srgb_file(&opts(), &path).unwrap();
    assert_eq!(f.name, "colours");
    let max_diff = f
        .reflectance
        .iter()
        .zip(s.reflectance.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(max_diff < 1e-5, "{max_diff}");

    // Saturated primaries fall outside what the 3-component basis can reach
    // within [0, 1]: measure (not assert) how far clipping moves them.
    let prim = image::RgbImage::from_fn(3, 1, |x, _| {
        let mut c = [0u8; 3];
        c[x as usize] = 255;
        image::Rgb(c)
    });
    let ps = from_srgb_image(&opts(), &prim).unwrap();
    for x in 0..3 {
        println!(
            "image lift of primary {:?} renders as {:?}",
            prim.get_pixel(x, 0).0,
            rendered_srgb8(&ps, 0, x as usize)
        );
    }

    // The lift's own inverse agrees where nothing clips.
    let lift = SrgbLift::new(&s.grid).unwrap();
    let rgb = [115u8, 82, 68].map(|v| srgb_decode(v as f64 / 255.0));
    let refl = lift.reflectance(rgb);
    let back = lift.linear_rgb_of(refl.values());
    for k in 0..3 {
        assert!((back[k] - rgb[k]).abs() < 1e-9);
    }
}

#[test]
fn bad_parameters_are_errors_not_panics() {
    let o = opts();
    let g = o.grid;
    let set = ces_set(&g);
    assert!(dead_leaves(&o, &[], &DeadLeavesParams::new(8, 8, 1)).is_err());
    assert!(dead_leaves(&o, &set, &DeadLeavesParams::new(0, 8, 1)).is_err());
    let huge = DeadLeavesParams::new(1 << 20, 1 << 20, 1);
    assert!(dead_leaves(&o, &set, &huge).is_err());
    assert!(ces_chart(&o, 0).is_err());
    assert!(grey_ramp(&o, 8, 8, 0).is_err());
    assert!(uniform(&o, &Spectrum::constant(g, f64::INFINITY), 2, 2).is_err());
    assert!(from_srgb_pixels(&o, 2, 2, &[0.5; 11]).is_err());
    assert!(from_srgb_pixels(&o, usize::MAX, 3, &[]).is_err());
    let missing = std::path::Path::new("/nonexistent/nothing.png");
    assert!(matches!(
        from_srgb_file(&o, missing),
        Err(SceneError::Image { .. })
    ));
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.png");
    std::fs::write(&junk, b"not an image").unwrap();
    assert!(matches!(
        from_srgb_file(&o, &junk),
        Err(SceneError::Image { .. })
    ));
    // An ISET folder overrides the built-in tables file by file: without the
    // surfaces the built-in ones serve; a broken copy is a clear error.
    std::fs::create_dir(dir.path().join("lights")).unwrap();
    let partial = IsetData::at(dir.path()).unwrap();
    assert_eq!(macbeth(&partial, &o, 8).unwrap().patches.len(), 24);
    let surfaces = dir.path().join("surfaces/reflectances");
    std::fs::create_dir_all(&surfaces).unwrap();
    std::fs::write(
        surfaces.join("macbethChart.csv"),
        "wavelength_nm,grey\n400,0.5\n700,0.5\n",
    )
    .unwrap();
    let e = macbeth(&partial, &o, 8).unwrap_err().to_string();
    assert!(
        e.contains("macbethChart.csv") && e.contains("expected 24 patches"),
        "{e}"
    );
    std::fs::write(surfaces.join("Food_Vhrel.csv"), "not a table").unwrap();
    let e = natural100_chart(&partial, &o, 8).unwrap_err().to_string();
    assert!(e.contains("Food_Vhrel.csv"), "{e}");
    println!("broken-data error: {e}");
    // Options.
    let wrong_grid = Spectrum::constant(WavelengthGrid::new(400.0, 700.0, 5.0).unwrap(), 1.0);
    assert!(SceneOptions::new(g, wrong_grid, "X").is_err());
    assert!(SceneOptions::new(g, Spectrum::constant(g, 0.0), "dark").is_err());
    assert!(uniform(&o.clone().with_fov(0.0), &set[0], 2, 2).is_err());
    assert!(uniform(&o.clone().with_mean_luminance(f64::NAN), &set[0], 2, 2).is_err());
    assert!("image:".parse::<SceneKind>().is_err());
    assert_eq!(
        SceneKind::Macbeth.build(None, &o, 1).unwrap().patches.len(),
        24
    );
}

#[test]
fn scene_kinds_build_with_defaults() {
    let o = opts();
    for k in ["natural100", "dead-leaves", "uniform", "grey-ramp"] {
        let kind: SceneKind = k.parse().unwrap();
        let s = kind.build(None, &o, 5).unwrap();
        assert_eq!(s.bands(), 31, "{k}");
        assert!(
            s.reflectance.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{k}"
        );
        assert_eq!(s.mean_luminance, 100.0);
    }
}
