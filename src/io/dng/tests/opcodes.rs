//! OpcodeList1/2/3: FixBadPixelsConstant and GainMap applied, other opcodes reported,
//! malformed lists refused without panicking.

use super::*;

/// An opcode list (always big-endian): (ID, flags, parameters) per opcode.
fn list(tag: u16, ops: &[(u32, u32, Vec<u8>)]) -> E {
    let mut b = (ops.len() as u32).to_be_bytes().to_vec();
    for (id, flags, params) in ops {
        for x in [*id, 0x0103_0000, *flags, params.len() as u32] {
            b.extend(x.to_be_bytes());
        }
        b.extend(params);
    }
    (tag, 7, b.len() as u32, b)
}

/// GainMap parameters: area (top, left, bottom, right), plane 0 of 1, pitches, and a map of
/// `pv` × `ph` points spread over the whole image (spacing 1 / (points − 1), origin 0).
fn gain_map(area: [u32; 4], pitch: (u32, u32), pv: u32, ph: u32, gains: &[f32]) -> Vec<u8> {
    let mut b = Vec::new();
    for x in area.into_iter().chain([0, 1, pitch.0, pitch.1, pv, ph]) {
        b.extend(x.to_be_bytes());
    }
    let sp = |n: u32| 1.0 / f64::from(n.max(2) - 1);
    for x in [sp(pv), sp(ph), 0.0, 0.0] {
        b.extend(f64::to_be_bytes(x));
    }
    b.extend(1u32.to_be_bytes());
    for g in gains {
        b.extend(g.to_be_bytes());
    }
    b
}

/// The gain the 2 × 2 map [1, 2 / 3, 4] gives at the centre of pixel (r, c) of an h × w image.
fn bilinear(r: usize, c: usize, h: usize, w: usize) -> f64 {
    let (v, u) = ((r as f64 + 0.5) / h as f64, (c as f64 + 0.5) / w as f64);
    1.0 + u + 2.0 * v
}

#[test]
fn gain_map_scales_above_black_in_active_area_coordinates() {
    let (w, h) = (8, 7);
    let img = vec![1100u16; w * h];
    let b = Builder::new(false);
    let extra = vec![
        b.short(50714, &[100]),
        b.short(50717, &[4000]),
        b.long(50829, &[1, 0, 7, 8]), // 8 × 6 active area from row 1
        b.long(50719, &[2, 1]),
        b.long(50720, &[4, 3]),
        list(
            51009,
            &[(
                9,
                0,
                gain_map([0, 0, 6, 8], (1, 1), 2, 2, &[1., 2., 3., 4.]),
            )],
        ),
    ];
    let d = decode_dng(&strips_dng(false, &img, w, h, 16, h, extra), &lim()).unwrap();
    assert!(
        d.info.skipped_opcodes.is_empty(),
        "{:?}",
        d.info.skipped_opcodes
    );
    for r in 0..3 {
        for c in 0..4 {
            // the frame's (r, c) is the active area's (r + 1, c + 2)
            let want = (100.0 + 1000.0 * bilinear(r + 1, c + 2, 6, 8)).round() as u16;
            assert_eq!(d.frame.data[r * 4 + c], want, "({r}, {c})");
        }
    }
    // a gain that would pass the white level stops at it; the map's edges are clamped
    let big = list(
        51009,
        &[(9, 0, gain_map([0, 0, 7, 8], (1, 1), 1, 1, &[5.0]))],
    );
    let extra = vec![b.short(50714, &[100]), b.short(50717, &[4000]), big];
    let d = decode_dng(&strips_dng(false, &img, w, h, 16, h, extra), &lim()).unwrap();
    assert!(d.frame.data.iter().all(|&v| v == 4000));
}

#[test]
fn gain_map_pitch_picks_one_cfa_position_and_other_planes_are_left() {
    let (w, h) = (6, 4);
    let img = vec![200u16; w * h];
    // Android's layout: one map per Bayer position, pitch 2 from (0, 1)
    let one = gain_map([0, 1, 4, 6], (2, 2), 1, 1, &[1.5]);
    let d = decode_dng(
        &strips_dng(
            true,
            &img,
            w,
            h,
            16,
            h,
            vec![list(51009, &[(9, 0, one.clone())])],
        ),
        &lim(),
    )
    .unwrap();
    for (i, &v) in d.frame.data.iter().enumerate() {
        let (r, c) = (i / w, i % w);
        let hit = r % 2 == 0 && c % 2 == 1;
        assert_eq!(v, if hit { 300 } else { 200 }, "({r}, {c})");
    }
    // plane 1 of a one-plane CFA image: nothing to scale
    let mut plane1 = one;
    plane1[16..20].copy_from_slice(&1u32.to_be_bytes());
    let f = strips_dng(
        true,
        &img,
        w,
        h,
        16,
        h,
        vec![list(51009, &[(9, 0, plane1)])],
    );
    assert_eq!(decode_dng(&f, &lim()).unwrap().frame.data, img);
}

#[test]
fn unsupported_opcodes_are_skipped_and_reported() {
    let (w, h) = (4, 4);
    let img = ramp(w, h, 12);
    let extra = vec![
        list(51008, &[(99, 0, vec![1, 2, 3])]),
        list(51009, &[(8, 0, vec![0; 36])]),
        list(51022, &[(1, 1, vec![0; 12]), (3, 1, vec![])]),
    ];
    let d = decode_dng(&strips_dng(false, &img, w, h, 16, h, extra), &lim()).unwrap();
    assert_eq!(d.frame.data, img);
    assert_eq!(
        d.info.skipped_opcodes,
        [
            "opcode 99 (OpcodeList1)",
            "MapPolynomial (OpcodeList2)",
            "WarpRectilinear (OpcodeList3, optional)",
            "FixVignetteRadial (OpcodeList3, optional)",
        ]
    );
}

#[test]
fn fix_bad_pixels_constant_takes_the_nearest_same_colour_mean() {
    let (w, h) = (6, 6);
    let mut img = ramp(w, h, 12);
    // R G / W B: (2, 2) is R, (2, 3) G, (3, 3) B
    for i in [2 * w + 2, 2 * w + 3, 3 * w + 3] {
        img[i] = 65535;
    }
    let params = [65535u32.to_be_bytes(), 0u32.to_be_bytes()].concat();
    let extra = vec![list(51008, &[(4, 0, params)])];
    let d = decode_dng(&strips_dng(false, &img, w, h, 16, h, extra), &lim()).unwrap();
    let mean = |p: &[(usize, usize)]| {
        let s: u32 = p.iter().map(|&(r, c)| u32::from(img[r * w + c])).sum();
        ((s + p.len() as u32 / 2) / p.len() as u32) as u16
    };
    let at = |r: usize, c: usize| d.frame.data[r * w + c];
    assert_eq!(at(2, 2), mean(&[(0, 2), (4, 2), (2, 0), (2, 4)]));
    assert_eq!(at(2, 3), mean(&[(0, 3), (4, 3), (2, 1), (2, 5)]));
    // (3, 3)'s B neighbours two away: (1, 3), (5, 3), (3, 1), (3, 5)
    assert_eq!(at(3, 3), mean(&[(1, 3), (5, 3), (3, 1), (3, 5)]));
    assert!(d.info.skipped_opcodes.is_empty());
}

#[test]
fn malformed_opcode_lists_are_refused_list3_is_reported() {
    let (w, h) = (4, 4);
    let img = ramp(w, h, 12);
    let good = gain_map([0, 0, 4, 4], (1, 1), 2, 2, &[1.0; 4]);
    let mut short = good.clone();
    short.truncate(good.len() - 4);
    let cases: Vec<(E, &str)> = vec![
        ((51009, 7, 2, vec![0, 0]), "no opcode count"),
        (
            (51009, 7, 4, 1_000_000u32.to_be_bytes().to_vec()),
            "opcodes; at most",
        ),
        ((51009, 7, 4, 1u32.to_be_bytes().to_vec()), "ends early"),
        (list(51009, &[(9, 0, short)]), "GainMap"),
        (
            list(
                51009,
                &[(9, 0, gain_map([0, 0, 4, 4], (1, 1), 2, 2, &[f32::NAN; 4]))],
            ),
            "gain",
        ),
        (
            list(
                51009,
                &[(9, 0, gain_map([0, 0, 4, 4], (0, 1), 1, 1, &[1.0]))],
            ),
            "pitch",
        ),
        (list(51008, &[(4, 0, vec![0; 4])]), "FixBadPixelsConstant"),
    ];
    for (entry, want) in cases {
        let e = decode_dng(&strips_dng(false, &img, w, h, 16, h, vec![entry]), &lim())
            .unwrap_err()
            .to_string();
        assert!(e.contains(want) && e.contains("OpcodeList"), "{want}: {e}");
    }
    // a list the reader would not apply anyway is reported, not refused
    let extra = vec![(51022, 7, 4, 9u32.to_be_bytes().to_vec())];
    let d = decode_dng(&strips_dng(false, &img, w, h, 16, h, extra), &lim()).unwrap();
    assert_eq!(d.info.skipped_opcodes.len(), 1);
    assert!(d.info.skipped_opcodes[0].starts_with("OpcodeList3 (unreadable"));
}
