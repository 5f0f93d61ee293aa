//! The reader's leniencies (docs/dng.md, "Leniencies"): files as PiDNG and other writers make
//! them, read where their intent is unambiguous; contradictions stay errors.

use super::*;

/// A removed tag, for [`strips_dng`]'s `extra`.
fn gone(tag: u16) -> E {
    (tag, 0, 0, vec![])
}

/// Renames the first entry for tag `from` of a little-endian file's IFD0 to `to` (an unknown
/// tag number hides it from the reader).
fn rename_tag(f: &mut [u8], from: u16, to: u16) {
    assert_eq!(&f[..2], b"II");
    let at = u32::from_le_bytes(f[4..8].try_into().unwrap()) as usize;
    let n = u16::from_le_bytes([f[at], f[at + 1]]) as usize;
    let e = (0..n)
        .map(|i| at + 2 + 12 * i)
        .find(|&e| u16::from_le_bytes([f[e], f[e + 1]]) == from)
        .unwrap_or_else(|| panic!("no tag {from}"));
    f[e..e + 2].copy_from_slice(&to.to_le_bytes());
}

fn decode_err(f: &[u8]) -> String {
    decode_dng(f, &lim()).unwrap_err().to_string()
}

#[test]
fn missing_plane_color_is_the_colours_the_pattern_uses() {
    let img = ramp(4, 4, 16);
    let b = Builder::new(false);
    for (pattern, cfa, planes) in [
        ([0u8, 1, 6, 2], "RG/WB", "RGBW"),
        ([6, 2, 0, 1], "WB/RG", "RGBW"),
        ([1, 0, 2, 1], "GR/BG", "RGB"),
        ([0, 6, 6, 2], "RW/WB", "RBW"),
        ([6, 1, 1, 6], "WG/GW", "GW"),
    ] {
        let extra = vec![gone(50710), (33422, 1, 4, pattern.to_vec())];
        let d = decode_dng(&strips_dng(false, &img, 4, 4, 16, 4, extra), &lim()).unwrap();
        assert_eq!(
            (d.cfa.as_str(), d.info.plane_colors.as_str()),
            (cfa, planes)
        );
        assert_eq!(d.frame.data, img);
    }
    // AsShotNeutral and ColorMatrix1 in that order: R, G, B, W
    let extra = vec![
        gone(50710),
        b.rational(50728, &[(1, 2), (1, 1), (3, 4), (1, 4)]),
        (50721, 10, 12, b.l(&[1; 24])),
    ];
    let d = decode_dng(&strips_dng(false, &img, 4, 4, 16, 4, extra), &lim()).unwrap();
    let n = d.info.neutral().unwrap();
    let letters: String = n.iter().map(|(c, _)| c.as_str()).collect();
    assert_eq!(letters, "RGBW");
    assert_eq!(n[3].1, 0.25);
    assert_eq!(d.info.color_matrices[0].as_ref().map(Vec::len), Some(12));
}

#[test]
fn the_writers_planes_are_read_as_well_without_its_cfa_plane_color() {
    let (w, h) = (4, 4);
    let frame = RawFrame::new(w, h, ramp(w, h, 16)).unwrap();
    for cfa in ["RG/WB", "WB/GR", "RW/WB", "GR/BG", "BG/GR"] {
        let letters: Vec<String> = ["W", "B", "G", "R"]
            .into_iter()
            .filter(|l| cfa.contains(l))
            .map(String::from)
            .collect();
        let info = DngWriteInfo {
            as_shot_neutral: Some(
                letters
                    .iter()
                    .enumerate()
                    .map(|(i, l)| (l.clone(), 1.0 / (i + 1) as f64))
                    .collect(),
            ),
            color_matrix: Some(
                letters
                    .iter()
                    .enumerate()
                    .map(|(i, l)| (l.clone(), [i as f64, 0.5, -0.25]))
                    .collect(),
            ),
            ..DngWriteInfo::default()
        };
        let meta = RawMeta::new(w, h, cfa, 64, 65535, 1.0);
        let mut bytes = encode_dng(&frame, &meta, &info).unwrap();
        let with = decode_dng(&bytes, &lim()).unwrap();
        rename_tag(&mut bytes, 50710, 50709);
        let without = decode_dng(&bytes, &lim()).unwrap();
        assert_eq!(without, with, "{cfa}");
        assert_eq!(without.info.plane_colors.len(), letters.len());
    }
}

#[test]
fn a_plane_color_or_neutral_that_contradicts_the_pattern_is_refused() {
    let img = ramp(4, 4, 16);
    let b = Builder::new(false);
    let cases: Vec<(Vec<E>, &str)> = vec![
        (
            vec![(50710, 1, 3, vec![0, 1, 2])],
            "CFAPattern uses W, which CFAPlaneColor (RGB) does not list",
        ),
        (
            vec![(50710, 1, 3, vec![0, 2, 6])],
            "CFAPattern uses G, which CFAPlaneColor (RBW) does not list",
        ),
        (
            vec![(50710, 1, 4, vec![0, 1, 6, 6])],
            "CFAPlaneColor lists W twice",
        ),
        (
            vec![b.short(50710, &[0, 1, 2, 3])],
            "CFAPlaneColor lists colour code 3 (cyan)",
        ),
        // without CFAPlaneColor the planes are R, G, B, W: three values say nothing of W
        (
            vec![gone(50710), b.rational(50728, &[(1, 2), (1, 1), (3, 4)])],
            "4 positive values (one per colour plane, RGBW: the colours CFAPattern uses, R, G, B then W, as the file has no CFAPlaneColor)",
        ),
        (
            vec![gone(50710), (50721, 10, 9, b.l(&[1; 18]))],
            "ColorMatrix1 (50721) has 9 values; 3 × 4 colour planes (RGBW: the colours",
        ),
    ];
    for (extra, want) in cases {
        let e = decode_err(&strips_dng(false, &img, 4, 4, 16, 4, extra));
        assert!(e.contains(want), "want {want:?}: {e}");
    }
}

#[test]
fn a_four_value_pattern_without_repeat_dim_is_2x2() {
    let img = ramp(4, 4, 16);
    let d = decode_dng(
        &strips_dng(false, &img, 4, 4, 16, 4, vec![gone(33421)]),
        &lim(),
    )
    .unwrap();
    assert_eq!(d.cfa, "RG/WB");
    // 2 or 9 values could be any shape
    for pattern in [vec![0u8, 1], vec![0, 1, 2, 1, 2, 0, 2, 0, 1]] {
        let n = pattern.len();
        let extra = vec![gone(33421), (33422, 1, n as u32, pattern)];
        let e = decode_err(&strips_dng(false, &img, 4, 4, 16, 4, extra));
        assert!(
            e.contains(&format!(
                "no CFARepeatPatternDim (33421) and its CFAPattern has {n} values"
            )),
            "{e}"
        );
    }
    let e = decode_err(&strips_dng(
        false,
        &img,
        4,
        4,
        16,
        4,
        vec![gone(33421), gone(33422)],
    ));
    assert!(e.contains("no CFARepeatPatternDim"), "{e}");
}

/// A pattern written as a repeat of a smaller one is that one: `R G / W B` as 4 × 4, 2 × 4 or
/// 4 × 2 reads as 2 × 2 (the same pixels as the 2 × 2 file), a 1 × 2 repeat of one column
/// stays as it is written.
#[test]
fn a_pattern_written_as_a_repeat_is_its_smallest_tile() {
    let img = ramp(8, 8, 16);
    let want = decode_dng(&strips_dng(false, &img, 8, 8, 16, 8, vec![]), &lim()).unwrap();
    let tile = |rows: usize, cols: usize| -> Vec<u8> {
        let base = [[0u8, 1], [6, 2]];
        (0..rows)
            .flat_map(|r| (0..cols).map(move |c| base[r % 2][c % 2]))
            .collect()
    };
    for (rows, cols) in [(4usize, 4usize), (2, 4), (4, 2), (2, 6)] {
        let p = tile(rows, cols);
        let b = Builder::new(false);
        let extra = vec![
            b.short(33421, &[rows as u16, cols as u16]),
            (33422, 1, p.len() as u32, p),
        ];
        let d = decode_dng(&strips_dng(false, &img, 8, 8, 16, 8, extra), &lim()).unwrap();
        assert_eq!(d.cfa, "RG/WB", "{rows}×{cols}");
        assert_eq!(d.frame, want.frame, "{rows}×{cols}");
    }
    // not a repeat: a 2 × 4 tile whose halves differ
    let b = Builder::new(false);
    let extra = vec![
        b.short(33421, &[2, 4]),
        (33422, 1, 8, vec![0, 1, 1, 0, 6, 2, 2, 6]),
        (50710, 1, 4, vec![0, 1, 2, 6]),
    ];
    let d = decode_dng(&strips_dng(false, &img, 8, 8, 16, 8, extra), &lim()).unwrap();
    assert_eq!(d.cfa, "RGGR/WBBW");
}

#[test]
fn equal_black_levels_need_no_repeat_dim() {
    let img = ramp(4, 2, 10);
    let b = Builder::new(false);
    for extra in [
        vec![b.short(50714, &[64; 4])],
        vec![b.rational(50714, &[(128, 2); 4])],
        vec![b.short(50713, &[2, 2]), b.long(50714, &[64; 8])],
    ] {
        let d = decode_dng(&strips_dng(false, &img, 4, 2, 10, 2, extra), &lim()).unwrap();
        assert_eq!(d.black_level, 64);
        assert_eq!(d.frame.data, img, "the values are kept");
    }
    // different values: which position has which is not said
    let e = decode_err(&strips_dng(
        false,
        &img,
        4,
        2,
        10,
        2,
        vec![b.short(50714, &[60, 62, 64, 66])],
    ));
    assert!(
        e.contains("BlackLevel has 4 values; BlackLevelRepeatDim 1×1 needs 1"),
        "{e}"
    );
    let e = decode_err(&strips_dng(
        false,
        &img,
        4,
        2,
        10,
        2,
        vec![(50714, 3, 0, vec![])],
    ));
    assert!(e.contains("BlackLevel has 0 values"), "{e}");
}

#[test]
fn one_tile_without_a_tile_size_is_the_whole_image() {
    let (w, h) = (6, 4);
    let img = ramp(w, h, 12);
    // strips renamed to tiles, with no TileWidth or TileLength
    let tiles = |rps: usize| {
        let mut f = strips_dng(false, &img, w, h, 12, rps, vec![gone(278)]);
        rename_tag(&mut f, 273, 324);
        rename_tag(&mut f, 279, 325);
        f
    };
    let d = decode_dng(&tiles(h), &lim()).unwrap();
    assert_eq!(d.frame.data, img);
    let e = decode_err(&tiles(2));
    assert!(e.contains("the raw image has no TileWidth (322)"), "{e}");
}

#[test]
fn integer_tags_of_any_integer_type_and_levels_of_any_numeric_type() {
    let (w, h) = (4, 4);
    let img = ramp(w, h, 12);
    let b = Builder::new(true);
    let base = vec![
        b.short(50714, &[64]),
        b.short(50717, &[4000]),
        b.short(50720, &[2, 2]),
    ];
    let want = decode_dng(&strips_dng(true, &img, w, h, 12, h, base.clone()), &lim()).unwrap();
    assert_eq!((want.black_level, want.white_level), (64, 4000));
    let variants: Vec<E> = vec![
        b.long(258, &[12]),
        b.long(33421, &[2, 2]),
        b.short(33422, &[0, 1, 6, 2]),
        (33422, 7, 4, vec![0, 1, 6, 2]),
        b.short(50710, &[0, 1, 2, 6]),
        b.short(50706, &[1, 4, 0, 0]),
        b.long(50714, &[64]),
        b.rational(50714, &[(64, 1)]),
        b.long(50717, &[4000]),
        b.rational(50717, &[(8000, 2)]),
        b.long(50720, &[2, 2]),
        b.rational(50720, &[(2, 1), (4, 2)]),
    ];
    for v in variants {
        let (tag, typ) = (v.0, v.1);
        let mut extra = base.clone();
        extra.push(v);
        let d = decode_dng(&strips_dng(true, &img, w, h, 12, h, extra), &lim())
            .unwrap_or_else(|e| panic!("tag {tag} as type {typ}: {e}"));
        assert_eq!(
            (&d.frame, &d.cfa, d.black_level, d.white_level),
            (&want.frame, &want.cfa, want.black_level, want.white_level),
            "tag {tag} as type {typ}"
        );
    }
}

#[test]
fn optional_tags_take_their_defaults() {
    // what PiDNG leaves out unless asked: no DNGBackwardVersion, CFAPlaneColor, CFALayout,
    // BlackLevel(RepeatDim), WhiteLevel, DefaultCrop, ActiveArea, UniqueCameraModel, Make,
    // Model, SamplesPerPixel, NewSubFileType
    let (w, h) = (4, 4);
    let img = ramp(w, h, 14);
    let extra = vec![gone(50710), gone(277)];
    let f = strips_dng(false, &img, w, h, 14, h, extra);
    let t = ifd::Tiff::parse(&f).unwrap();
    let ifd0 = t.first_ifd().unwrap();
    for tag in [
        254, 271, 272, 277, 50707, 50708, 50710, 50711, 50713, 50714, 50717, 50719, 50720, 50829,
    ] {
        assert!(!ifd0.has(tag), "{tag}");
    }
    let d = decode_dng(&f, &lim()).unwrap();
    assert_eq!(d.frame.data, img);
    assert_eq!((d.black_level, d.white_level), (0, 16383));
    assert_eq!(
        (d.cfa.as_str(), d.info.plane_colors.as_str()),
        ("RG/WB", "RGBW")
    );
    assert_eq!(
        (&d.info.unique_camera_model, &d.info.make, &d.info.model),
        (&None, &None, &None)
    );
    assert_eq!(d.raw_meta(1.0).sensor, None);
}

#[test]
fn a_tag_written_twice_is_read_from_its_first_entry() {
    let img = ramp(4, 4, 16);
    // DNGVersion 1.4, then DNGBackwardVersion 1.1 renamed to a second DNGVersion
    let mut f = strips_dng(
        false,
        &img,
        4,
        4,
        16,
        4,
        vec![(50707, 1, 4, vec![1, 1, 0, 0])],
    );
    rename_tag(&mut f, 50707, 50706);
    let t = ifd::Tiff::parse(&f).unwrap();
    assert!(!t.first_ifd().unwrap().has(50707));
    let d = decode_dng(&f, &lim()).unwrap();
    assert_eq!(d.info.version, [1, 4, 0, 0]);
    assert_eq!(d.frame.data, img);
}

#[test]
fn make_and_model_are_read_trimmed() {
    let img = ramp(4, 4, 16);
    let extra = vec![
        (271, 2, 8, b"SONY\0\0\0\0".to_vec()),
        (272, 2, 10, b"\0 ILCE-9  ".to_vec()),
        (50708, 2, 2, b" \0".to_vec()),
    ];
    let d = decode_dng(&strips_dng(false, &img, 4, 4, 16, 4, extra), &lim()).unwrap();
    assert_eq!(d.info.make.as_deref(), Some("SONY"));
    assert_eq!(d.info.model.as_deref(), Some("ILCE-9"));
    assert_eq!(d.info.unique_camera_model, None, "blank");
}

#[test]
fn pidng_rgbw_without_plane_color() {
    // PiDNG 4.0.9 as its README uses it (scripts/pidng_fixtures.py): no CFAPlaneColor,
    // DNGVersion and DNGBackwardVersion twice, no UniqueCameraModel
    let dng = include_bytes!("../../../../tests/fixtures/pidng/rgbw_pidng.dng");
    let raw = include_bytes!("../../../../tests/fixtures/pidng/rgbw_pidng.raw");
    let t = ifd::Tiff::parse(dng).unwrap();
    let ifd0 = t.first_ifd().unwrap();
    assert!(!ifd0.has(50710) && !ifd0.has(50708));
    let d = decode_dng(dng, &lim()).unwrap();
    let want: Vec<u16> = raw
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    assert_eq!(d.frame.data, want);
    assert_eq!((d.frame.width, d.frame.height), (64, 48));
    assert_eq!(
        (d.cfa.as_str(), d.info.plane_colors.as_str()),
        ("RG/WB", "RGBW")
    );
    assert_eq!((d.black_level, d.white_level), (4096, 65535));
    assert_eq!(d.info.version, [1, 4, 0, 0]);
    assert_eq!(
        (d.info.make.as_deref(), d.info.model.as_deref()),
        (Some("PiDNG"), Some("RGBW fixture"))
    );
    let n = d.info.neutral().unwrap();
    assert_eq!(n[0], ("R".to_string(), 0.6));
    assert_eq!(n[3], ("W".to_string(), 1.0));
}
