//! The fast renderer against the reference renderer on simulated frames:
//! RGBW and Bayer CFAs, patch sizes 3 to 9, noise, clipped highlights, fused
//! illuminant correction, u16 input, regions and 8-bit sRGB output.

use std::sync::atomic::AtomicBool;

use l3::camera::{Camera, Exposure, NoiseSwitches, SensorDesign, simulate};
use l3::l3::L3Table;
use l3::l3::correct::IlluminantRegistry;
use l3::l3::learn::{TrainingSpec, train_table};
use l3::l3::render::{
    FastOptions, FastRenderer, Mosaic, Region, WhiteLevel, fuse_kernels, render_reference, white_y,
    xyz_to_srgb8,
};
use l3::scene::{DeadLeavesParams, SceneOptions, dead_leaves};
use l3::spectral::{Extrapolation, WavelengthGrid, ces_reflectances, cie_illuminant};
use proptest::prelude::*;

fn design(name: &str) -> SensorDesign {
    let path = format!("{}/config/sensors/{name}.toml", env!("L3_ROOT"));
    SensorDesign::load(path, None).expect("sensor design")
}

fn train(design: &SensorDesign, patch: usize) -> L3Table {
    train_classes(design, patch, 1)
}

fn train_classes(design: &SensorDesign, patch: usize, chroma_classes: usize) -> L3Table {
    let spec = TrainingSpec {
        illuminants: vec!["D65".into(), "A".into()],
        patch_size: patch,
        levels: 10,
        scenes: 6,
        scene_size: 48,
        seed: 5,
        chroma_classes,
        ..TrainingSpec::default()
    };
    train_table(design, &spec, None, &|_, _| {}, &AtomicBool::new(false)).expect("train")
}

/// A noisy dead-leaves frame under A, exposed so that highlights clip.
fn frame(design: &SensorDesign, size: usize, seed: u64) -> (Vec<f32>, usize, usize) {
    let grid = WavelengthGrid::default();
    let camera = Camera::new(design, grid, None).expect("camera");
    let a = cie_illuminant("A")
        .expect("A")
        .resample(&grid, Extrapolation::Zero);
    let opts = SceneOptions::new(grid, a, "A").expect("options");
    let refl: Vec<_> = ces_reflectances()
        .into_iter()
        .map(|(_, s)| s.resample(&grid, Extrapolation::Hold))
        .collect();
    let scene =
        dead_leaves(&opts, &refl, &DeadLeavesParams::new(size, size + 7, seed)).expect("scene");
    let auto = Exposure::Auto {
        target_fraction: 0.95,
    };
    let probe = simulate(&camera, &scene, auto, &NoiseSwitches::none(), seed).expect("simulate");
    // 1.6× the auto exposure: the brightest leaves clip
    let exposure = Exposure::Seconds(probe.exposure_s * 1.6);
    let cap = simulate(&camera, &scene, exposure, &NoiseSwitches::all(), seed).expect("simulate");
    let (h, w) = cap.volts.dim();
    (cap.volts.as_slice().expect("contiguous").to_vec(), w, h)
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// `part` (3 bytes per pixel) is `reg` cut from `whole`, an image `width` pixels wide.
fn assert_is_crop(whole: &[u8], width: usize, part: &[u8], reg: Region) {
    assert_eq!(part.len(), reg.width * reg.height * 3);
    for y in 0..reg.height {
        let row = (reg.y + y) * width + reg.x;
        assert!(
            whole[row * 3..(row + reg.width) * 3]
                == part[y * reg.width * 3..(y + 1) * reg.width * 3],
            "row {y} of the region differs"
        );
    }
}

fn tungsten_kernels(table: &L3Table) -> Vec<f32> {
    let grid = WavelengthGrid::default();
    let mut reg = IlluminantRegistry::with_defaults(grid, None).expect("registry");
    fuse_kernels(table, &reg.resolve("A", None).expect("A").t)
}

/// Fast and reference agree to 1e-4 in XYZ, pixel for pixel, with every option
/// combination, and report the same saturation statistics.
fn check(design_name: &str, patch: usize) {
    check_table(design_name, &train(&design(design_name), patch));
}

fn check_table(design_name: &str, table: &L3Table) {
    let (d, patch) = (design(design_name), table.meta.params.patch_size);
    let table = table.clone();
    let kernels = tungsten_kernels(&table);
    let (volts, w, h) = frame(&d, 72, 9);
    let (want, ws) = render_reference(&table, &kernels, &volts, w, h).expect("reference");
    assert!(ws.saturated > 0, "the frame should clip somewhere");
    // AVX-512 (where the CPU has it), AVX2 + FMA, portable
    for (simd, avx512) in [(true, true), (true, false), (false, false)] {
        for skip in [true, false] {
            let mut fast = FastRenderer::new(&table, &kernels).expect("fast");
            fast.options = FastOptions {
                simd,
                avx512,
                skip_unsaturated_tiles: skip,
                skip_equal_contrast_kernels: skip,
            };
            let (got, gs) = fast
                .render_xyz(Mosaic::Volts(&volts), w, h, None)
                .expect("fast render");
            let d = max_abs_diff(&want, &got);
            println!(
                "{design_name} patch {patch} simd {simd} avx512 {}: skips {skip}: max |ΔXYZ| {d:.2e}, {} of {} pixels on the exact path",
                fast.uses_avx512(),
                gs.exact_path,
                gs.pixels
            );
            assert!(d <= 1e-4, "max diff {d}");
            assert_eq!(
                (gs.pixels, gs.saturated, gs.fallback, gs.clamped),
                (ws.pixels, ws.saturated, ws.fallback, ws.clamped)
            );
        }
    }
}

#[test]
fn rgbw_patch5_matches_reference() {
    check("rgbw-paper", 5);
    // chroma classes: the AVX-512 classification scores them too
    check_chroma("rgbw-paper", 8);
}

/// [`check_table`] on a patch-5 table of `classes` chroma classes (asked).
fn check_chroma(design_name: &str, classes: usize) {
    let table = train_classes(&design(design_name), 5, classes);
    assert!(table.n_chroma() > 1);
    check_table(design_name, &table);
}

#[test]
fn rgbw_patch3_and_7_match_reference() {
    check("rgbw-paper", 3);
    check("rgbw-paper", 7);
}

#[test]
fn rgbw_patch9_takes_the_exact_path_and_matches() {
    check("rgbw-paper", 9);
}

#[test]
fn bayer_matches_reference() {
    // two phases share the green channel: the AVX-512 classification takes a
    // 4 × 4 phase map per CFA position
    check("bayer-paper", 3);
    check("bayer-paper", 5);
    check("bayer-paper", 7);
    check_chroma("bayer-paper", 4);
}

#[test]
fn bayer_takes_the_avx512_path_where_rgbw_does() {
    let render = |name: &str| {
        let table = train(&design(name), 5);
        let kernels = tungsten_kernels(&table);
        FastRenderer::new(&table, &kernels).expect("fast")
    };
    let (rgbw, bayer) = (render("rgbw-paper"), render("bayer-paper"));
    println!("AVX-512 kernels on this CPU: {}", rgbw.uses_avx512());
    assert_eq!(bayer.uses_avx512(), rgbw.uses_avx512());
}

#[test]
fn srgb8_u16_and_regions_match_the_reference_pipeline() {
    let d = design("rgbw-paper");
    let table = train(&d, 5);
    let kernels = tungsten_kernels(&table);
    let (volts, w, h) = frame(&d, 64, 3);
    // the same frame as 12-bit DN with a black level
    let (black, white) = (64u16, 4095u16);
    let dn: Vec<u16> = volts
        .iter()
        .map(|v| (v / 1.8 * f32::from(white - black)).round() as u16 + black)
        .collect();
    let scale = 1.8 / (f64::from(white) - f64::from(black));
    let dn_volts: Vec<f32> = dn
        .iter()
        .map(|&x| ((f64::from(x) - f64::from(black)) * scale).clamp(0.0, 1.8) as f32)
        .collect();
    let fast = FastRenderer::new(&table, &kernels).expect("fast");
    let mosaic = Mosaic::Dn {
        data: &dn,
        black,
        white,
    };
    let (want, _) = render_reference(&table, &kernels, &dn_volts, w, h).expect("reference");
    let (got, _) = fast.render_xyz(mosaic, w, h, None).expect("fast");
    assert!(max_abs_diff(&want, &got) <= 1e-4);
    // sRGB: the same white level, codes within one step (rounding of the fused matrix)
    let wy = white_y(&want, w, h, WhiteLevel::Auto);
    let (rgb, wy_fast, _) = fast
        .render_srgb8(mosaic, w, h, None, WhiteLevel::Auto)
        .expect("srgb");
    assert!((wy - wy_fast).abs() <= 1e-5 * wy, "white {wy} vs {wy_fast}");
    let want_rgb = xyz_to_srgb8(&want, wy);
    let worst = rgb
        .iter()
        .zip(&want_rgb)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap_or(0);
    let off = rgb.iter().zip(&want_rgb).filter(|(a, b)| a != b).count();
    println!("sRGB8: {off} of {} codes differ by 1", rgb.len());
    assert!(
        worst <= 1 && off * 200 <= rgb.len(),
        "{off} codes differ, worst {worst}"
    );
    // a region is the crop of the whole render, also in sRGB
    let reg = Region {
        x: 5,
        y: 9,
        width: 23,
        height: 17,
    };
    let (part, _, _) = fast
        .render_srgb8(mosaic, w, h, Some(reg), WhiteLevel::Y(wy_fast))
        .expect("region");
    assert_is_crop(&rgb, w, &part, reg);
    // into a caller's buffer (reused, so first filled with garbage): the same bytes
    let mut buf = vec![7u8; w * h * 3];
    let (wy_into, _) = fast
        .render_srgb8_into(mosaic, w, h, None, WhiteLevel::Auto, &mut buf)
        .expect("into");
    assert_eq!((wy_into, &buf[..]), (wy_fast, &rgb[..]));
    let mut short = vec![0u8; w * h * 3 - 1];
    assert!(
        fast.render_srgb8_into(mosaic, w, h, None, WhiteLevel::Auto, &mut short)
            .is_err()
    );
    // every instruction set gives the same codes but for rounding of the kernel sums
    for (simd, avx512) in [(true, false), (false, false)] {
        let mut other = FastRenderer::new(&table, &kernels).expect("fast");
        other.options.simd = simd;
        other.options.avx512 = avx512;
        let (o, _, _) = other
            .render_srgb8(mosaic, w, h, None, WhiteLevel::Y(wy_fast))
            .expect("srgb");
        let off = o.iter().zip(rgb.iter()).filter(|(a, b)| a != b).count();
        let worst = o.iter().zip(rgb.iter()).map(|(a, b)| a.abs_diff(*b)).max();
        println!(
            "simd {simd} avx512 {avx512}: {off} of {} codes differ",
            o.len()
        );
        assert!(
            worst <= Some(1) && off * 200 <= o.len(),
            "{off} codes differ"
        );
    }
}

/// `size × size` tiles of a small frame, shifted by an even offset (the CFA
/// phase is kept) so that neighbouring tiles differ.
fn tiled(volts: &[f32], w: usize, h: usize, size: (usize, usize), shift: usize) -> Vec<f32> {
    let (tw, th) = size;
    (0..tw * th)
        .map(|i| {
            let (x, y) = (i % tw, i / tw);
            volts[((y + shift) % h) * w + (x + 2 * (y / h) + shift) % w]
        })
        .collect()
}

/// sRGB frames come from a pool: a frame dropped by one render serves the
/// next, and the renderer overwrites every byte of the earlier image.
#[test]
fn pooled_srgb8_frames_hold_only_the_new_image() {
    let d = design("rgbw-paper");
    let table = train(&d, 5);
    let kernels = tungsten_kernels(&table);
    let fast = FastRenderer::new(&table, &kernels).expect("fast");
    let (volts, w, h) = frame(&d, 72, 9);
    // 1.15 MB of sRGB: large enough to be pooled (no other test here renders one)
    let (bw, bh) = (640, 600);
    let first = tiled(&volts, w, h, (bw, bh), 0);
    let second = tiled(&volts, w, h, (bw, bh), 6);
    let white = WhiteLevel::Y(0.9);
    let (a, _, _) = fast
        .render_srgb8(Mosaic::Volts(&first), bw, bh, None, white)
        .expect("first");
    let ptr = a.as_ptr();
    drop(a);
    let (b, _, _) = fast
        .render_srgb8(Mosaic::Volts(&second), bw, bh, None, white)
        .expect("second");
    assert_eq!(b.as_ptr(), ptr, "the dropped frame served the next render");
    let mut fresh = vec![0u8; bw * bh * 3];
    fast.render_srgb8_into(Mosaic::Volts(&second), bw, bh, None, white, &mut fresh)
        .expect("into");
    assert!(b[..] == fresh[..], "bytes of the first image were left");
    // a smaller region takes the same buffer, shortened: the crop of the whole
    drop(b);
    let reg = Region {
        x: 4,
        y: 2,
        width: 620,
        height: 570,
    };
    let (part, _, _) = fast
        .render_srgb8(Mosaic::Volts(&first), bw, bh, Some(reg), white)
        .expect("region");
    assert_eq!(part.as_ptr(), ptr);
    let (whole, _, _) = fast
        .render_srgb8(Mosaic::Volts(&first), bw, bh, None, white)
        .expect("whole");
    assert_is_crop(&whole, bw, &part, reg);
    // a frame taken out of the pool is a plain vector
    let v: Vec<u8> = whole.into_vec();
    assert_eq!(v.len(), bw * bh * 3);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// Random frames (values past both ends of the range included), sizes and regions.
    #[test]
    fn random_frames_and_regions_match(
        seed in 0u64..10_000, w in 1usize..40, h in 1usize..40,
        rx in 0usize..40, ry in 0usize..40, rw in 1usize..40, rh in 1usize..40
    ) {
        use std::sync::OnceLock;
        static T: OnceLock<(L3Table, Vec<f32>)> = OnceLock::new();
        let (table, kernels) = T.get_or_init(|| {
            let t = train(&design("rgbw-paper"), 5);
            let k = tungsten_kernels(&t);
            (t, k)
        });
        let mut s = seed;
        let mut next = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let volts: Vec<f32> = (0..w * h).map(|_| next() * 2.0 - 0.1).collect();
        let (want, ws) = render_reference(table, kernels, &volts, w, h).unwrap();
        let fast = FastRenderer::new(table, kernels).unwrap();
        let (got, gs) = fast.render_xyz(Mosaic::Volts(&volts), w, h, None).unwrap();
        prop_assert!(max_abs_diff(&want, &got) <= 1e-4);
        prop_assert_eq!(ws.clamped, gs.clamped);
        let mut avx2 = fast.clone();
        avx2.options.avx512 = false;
        let (got2, _) = avx2.render_xyz(Mosaic::Volts(&volts), w, h, None).unwrap();
        prop_assert!(max_abs_diff(&want, &got2) <= 1e-4);
        let (rx, ry) = (rx % w, ry % h);
        let reg = Region { x: rx, y: ry, width: rw.min(w - rx), height: rh.min(h - ry) };
        let (part, _) = fast.render_xyz(Mosaic::Volts(&volts), w, h, Some(reg)).unwrap();
        for y in 0..reg.height {
            let row = (reg.y + y) * w + reg.x;
            prop_assert_eq!(&want[row * 3..(row + reg.width) * 3].len(), &part[y * reg.width * 3..(y + 1) * reg.width * 3].len());
            prop_assert!(max_abs_diff(&want[row * 3..(row + reg.width) * 3], &part[y * reg.width * 3..(y + 1) * reg.width * 3]) <= 1e-4);
        }
    }
}
