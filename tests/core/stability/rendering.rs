//! Rendering hostile input: non-finite, out-of-range, uniform, tiny, huge frames and DN levels.

use l3::camera::{NoiseSwitches, SensorDesign};
use l3::io::{Limits, RawMeta, decode_mosaic, decode_raw_u16_le};
use l3::l3::L3Params;
use l3::l3::render::{fuse_kernels, render_reference};
use l3::test_support::{synthetic_frame, tiny_table};

use super::{
    camera_frames, check_table, learn_camera, learn_synthetic, package_synthetic, small_params,
};

fn assert_finite(label: &str, xyz: &[f32]) {
    if let Some(i) = xyz.iter().position(|v| !v.is_finite()) {
        panic!("{label}: pixel {} is {}", i / 3, xyz[i]);
    }
}

#[test]
fn non_finite_input_is_a_clear_error() {
    let t = tiny_table();
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut v = vec![0.3f32; 6 * 5];
        v[2 * 6 + 4] = bad;
        let e = render_reference(t, &t.kernels, &v, 6, 5)
            .unwrap_err()
            .to_string();
        println!("{bad}: {e}");
        assert!(
            e.contains("row 2, column 4") && e.contains("not finite"),
            "{e}"
        );
    }
}

#[test]
fn out_of_range_input_is_clamped_and_counted() {
    let t = tiny_table();
    let swing = t.meta.voltage_swing as f32;
    let mut v: Vec<f32> = (0..64).map(|i| i as f32 / 64.0).collect();
    v[3] = -1.0;
    v[10] = -f32::MAX;
    v[20] = swing * 1.5;
    v[30] = f32::MAX;
    v[40] = f32::MIN_POSITIVE;
    let (xyz, st) = render_reference(t, &t.kernels, &v, 8, 8).unwrap();
    assert_eq!(st.clamped, 4);
    assert_finite("out of range", &xyz);
    // clamping is exactly rendering the clamped frame
    let c: Vec<f32> = v.iter().map(|x| x.clamp(0.0, swing)).collect();
    let (xyz2, _) = render_reference(t, &t.kernels, &c, 8, 8).unwrap();
    assert_eq!(xyz, xyz2);
}

#[test]
fn all_zero_and_all_saturated_frames_are_finite() {
    let t = tiny_table();
    let swing = t.meta.voltage_swing as f32;
    for (label, v) in [
        ("zero", 0.0f32),
        ("saturated", swing),
        ("beyond white", 10.0 * swing),
    ] {
        let (xyz, st) = render_reference(t, &t.kernels, &vec![v; 16 * 12], 16, 12).unwrap();
        assert_finite(label, &xyz);
        println!("{label}: first pixel XYZ {:?}, stats {st:?}", &xyz[..3]);
        // a uniform frame renders the same colour at every pixel of one CFA position
        for r in 2..10 {
            for c in 2..14 {
                let (a, b) = ((r * 16 + c) * 3, (((r % 2) + 2) * 16 + (c % 2) + 2) * 3);
                for k in 0..3 {
                    assert!((xyz[a + k] - xyz[b + k]).abs() <= 1e-4 * (1.0 + xyz[b + k].abs()));
                }
            }
        }
    }
    // a saturated frame through a table with saturation cases
    let design = SensorDesign::paper_default();
    let p = small_params();
    let ts = learn_camera(&p, &design, 4, |i| {
        camera_frames(
            &design,
            i,
            24,
            [0.5, 2.0, 4.0, 8.0][i % 4],
            &NoiseSwitches::none(),
        )
    })
    .unwrap();
    let (xyz, st) = render_reference(&ts, &ts.kernels, &vec![1.8; 10 * 10], 10, 10).unwrap();
    assert_finite("saturated, table with saturation cases", &xyz);
    println!(
        "all-saturated frame, sat cases {:?}: {st:?}",
        ts.meta.sat_cases
    );
    assert_eq!(st.pixels, 100);
    // every channel saturated: no such case, every pixel falls back
    assert_eq!(st.fallback, 100);
}

#[test]
fn tiny_and_odd_sizes_render_finite() {
    let t = tiny_table();
    for (w, h) in [
        (1, 1),
        (1, 2),
        (2, 1),
        (7, 1),
        (1, 7),
        (3, 5),
        (5, 3),
        (2, 2),
        (9, 4),
        (13, 11),
    ] {
        let v: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 100) as f32 / 60.0).collect();
        let (xyz, st) = render_reference(t, &t.kernels, &v, w, h).unwrap();
        assert_eq!(xyz.len(), w * h * 3);
        assert_eq!(st.pixels as usize, w * h);
        assert_finite(&format!("{w}×{h}"), &xyz);
    }
    // size mismatches are errors
    assert!(render_reference(t, &t.kernels, &[0.1; 5], 2, 3).is_err());
    assert!(render_reference(t, &t.kernels, &[], 0, 4).is_err());
    assert!(render_reference(t, &t.kernels, &[0.1; 4], 2, 2).is_ok());
    assert!(render_reference(t, &t.kernels[..10], &[0.1; 4], 2, 2).is_err());
    // 5×5 and 9×9 patches on frames smaller than the patch (mirroring twice)
    let p = L3Params {
        patch_size: 9,
        ..small_params()
    };
    let learned = learn_synthetic(&p, 8, |i| {
        Ok(vec![synthetic_frame(
            i as u64,
            20,
            [0.01f32, 0.1, 0.5, 1.5][i % 4],
            0.002,
            (i % 2, (i / 4) % 2),
        )])
    })
    .unwrap();
    let t9 = package_synthetic(&p, learned);
    check_table("9×9 patches", &t9);
    for (w, h) in [(1, 1), (2, 3), (4, 1), (1, 9)] {
        let (xyz, _) = render_reference(&t9, &t9.kernels, &vec![0.4; w * h], w, h).unwrap();
        assert_finite(&format!("9×9 patch on {w}×{h}"), &xyz);
    }
}

#[test]
fn largest_frames_and_the_pixel_limit() {
    let lim = Limits::default();
    // the pixel and side limits are checked before any allocation or length check
    // a frame one column wider than the pixel limit allows at 10000 rows
    let wide = lim.max_pixels / 10_000;
    let over_pixels = decode_raw_u16_le(&[], wide + 1, 10_000, &lim).unwrap_err();
    println!("{}×10000 raw: {over_pixels}", wide + 1);
    assert!(over_pixels.to_string().contains("pixels"), "{over_pixels}");
    let over_side = decode_raw_u16_le(&[], lim.max_dim + 1, 1, &lim).unwrap_err();
    println!("{}×1 raw: {over_side}", lim.max_dim + 1);
    let overflow = decode_raw_u16_le(&[], usize::MAX, usize::MAX, &lim).unwrap_err();
    println!("usize::MAX² raw: {overflow}");
    let pgm = format!("P5\n{} {}\n255\n", wide + 1, 10_000);
    let e = decode_mosaic(pgm.as_bytes(), &lim).unwrap_err();
    println!("{}×10000 PGM header: {e}", wide + 1);
    // exactly at the limit: the size is accepted, only the body length is wrong
    let e = decode_raw_u16_le(&[0, 0], wide, 10_000, &lim).unwrap_err();
    assert!(e.to_string().contains("bytes"), "{e}");
    // the widest and tallest allowed frames one pixel thick, and 4096×2 rows,
    // decoded from raw and rendered
    let t = tiny_table();
    for (w, h) in [(lim.max_dim, 1), (1, lim.max_dim), (4096, 2)] {
        let dn: Vec<u8> = (0..w * h)
            .flat_map(|i| (((i * 7919) % 1000) as u16 * 60).to_le_bytes())
            .collect();
        let frame = decode_raw_u16_le(&dn, w, h, &lim).unwrap();
        let meta = RawMeta::new(w, h, "RG/WB", 0, 65535, 1.8);
        let v = frame.to_volts(&meta).unwrap();
        let (xyz, st) = render_reference(t, &t.kernels, &v, w, h).unwrap();
        assert_eq!(st.pixels as usize, w * h);
        assert_finite(&format!("{w}×{h}"), &xyz);
    }
}

#[test]
fn hostile_dn_levels_are_clear_errors() {
    let frame = decode_raw_u16_le(&[1, 0, 2, 0], 2, 1, &Limits::default()).unwrap();
    for (black, white, swing) in [
        (10u16, 10u16, 1.8),
        (20, 10, 1.8),
        (0, 100, 0.0),
        (0, 100, f64::NAN),
        (0, 100, f64::INFINITY),
    ] {
        let meta = RawMeta::new(2, 1, "RG/WB", black, white, swing);
        let e = frame.to_volts(&meta).unwrap_err();
        println!("black {black}, white {white}, swing {swing}: {e}");
    }
    // values above the white level clamp to the swing
    let frame = decode_raw_u16_le(&[0xff, 0xff, 0, 0], 2, 1, &Limits::default()).unwrap();
    let v = frame
        .to_volts(&RawMeta::new(2, 1, "RG/WB", 100, 1000, 1.8))
        .unwrap();
    assert_eq!(v, vec![1.8, 0.0]);
}

#[test]
fn extreme_corrections_fused_into_kernels_stay_finite() {
    // an ill-conditioned but registrable T (determinant above the registry's
    // 1e-9 floor) fused into the kernels, rendered on a saturated frame
    let t = tiny_table();
    let m = [[300.0, -299.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let k = fuse_kernels(t, &m);
    assert!(k.iter().all(|v| v.is_finite()));
    let (xyz, _) = render_reference(t, &k, &vec![1.8; 64], 8, 8).unwrap();
    assert_finite("fused extreme T", &xyz);
}
