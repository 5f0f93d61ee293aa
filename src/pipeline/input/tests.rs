use super::*;
use crate::io::{DngInfo, MosaicFormat, SourceInfo};
use crate::test_support::tiny_table;

/// A decoded file of `w` × `h` samples `data`, as the readers return it.
fn decoded(
    (w, h): (usize, usize),
    data: Vec<u16>,
    info: SourceInfo,
    meta: Option<RawMeta>,
    dng: Option<DngInfo>,
) -> Input {
    Input::Decoded(Box::new(LoadedMosaic {
        mosaic: DecodedMosaic::U16(RawFrame {
            width: w,
            height: h,
            data,
        }),
        info,
        meta,
        dng,
    }))
}

/// A decoded DNG of `w` × `h` with the CFA `cfa` and `info`, as the reader returns it.
fn dng_input(w: usize, h: usize, cfa: &str, info: DngInfo) -> Input {
    let data = (0..w * h).map(|i| (i % 997) as u16 + 64).collect();
    let source = SourceInfo {
        format: MosaicFormat::Dng,
        bits_per_sample: 16,
        max_value: None,
    };
    let meta = RawMeta::new(w, h, cfa, 64, 4095, 1.0);
    decoded((w, h), data, source, Some(meta), Some(info))
}

fn table_cfa() -> String {
    tiny_table().meta.cfa.to_string()
}

#[test]
fn as_shot_white_xy_is_the_light_when_there_is_no_neutral() {
    let (table, lim) = (tiny_table(), Limits::default());
    let info = DngInfo {
        as_shot_white_xy: Some([0.4476, 0.4074]),
        ..DngInfo::default()
    };
    let input = dng_input(8, 6, &table_cfa(), info.clone());
    let frame = decode(input, Levels::default(), table, &lim).unwrap();
    assert_eq!(frame.illuminant.as_deref(), Some("xy:0.447600,0.407400"));
    let (spec, source) = frame.light(table, None).unwrap();
    assert_eq!(
        (spec.as_str(), source),
        ("xy:0.447600,0.407400", IlluminantSource::Metadata)
    );
    // AsShotNeutral, when there is one, says the light instead
    let both = DngInfo {
        as_shot_neutral: Some(vec![0.5, 1.0, 0.8, 1.0]),
        plane_colors: "RGBW".into(),
        ..info
    };
    let input = dng_input(8, 6, &table_cfa(), both);
    let frame = decode(input, Levels::default(), table, &lim).unwrap();
    assert_eq!(frame.illuminant, None);
    assert!(frame.neutral.is_some());
}

#[test]
fn cfa_phase_finds_the_shift_to_the_tables_cfa() {
    assert_eq!(cfa_phase("RG/GB", "RG/GB"), Some((0, 0)));
    assert_eq!(cfa_phase("GR/BG", "RG/GB"), Some((0, 1)));
    assert_eq!(cfa_phase("GB/RG", "RG/GB"), Some((1, 0)));
    assert_eq!(cfa_phase("BG/GR", "RG/GB"), Some((1, 1)));
    assert_eq!(cfa_phase("WB/RG", "rg/wb"), Some((1, 0)));
    assert_eq!(cfa_phase("RG/GB", "RG/WB"), None);
    assert_eq!(cfa_phase("RG/GB", "RGGB/GBRG"), None);
    assert_eq!(cfa_phase("RGG/GB", "RG/GB"), None);
}

#[test]
fn a_dng_crop_on_another_cfa_phase_is_moved_to_the_tables() {
    let (table, lim) = (tiny_table(), Limits::default());
    let cfa = table_cfa();
    let (w, h) = (8, 6);
    // the table's CFA seen from (1, 1): what a crop one row and column on reads as
    let shifted = cfa_seen_from(&cfa, 1, 1).unwrap();
    assert_ne!(shifted, cfa, "the tiny table's CFA has a phase to move");
    let info = DngInfo {
        skipped_opcodes: vec!["WarpRectilinear (OpcodeList3, optional)".into()],
        ..DngInfo::default()
    };
    let frame = decode(
        dng_input(w, h, &shifted, info),
        Levels::default(),
        table,
        &lim,
    )
    .unwrap();
    assert_eq!((frame.width, frame.height), (w - 1, h - 1));
    let Samples::Dn { data, .. } = &frame.samples else {
        panic!("DN samples expected");
    };
    let original: Vec<u16> = (0..w * h).map(|i| (i % 997) as u16 + 64).collect();
    assert_eq!(data[0], original[w + 1]);
    assert_eq!(data[(h - 2) * (w - 1) + w - 2], original[w * h - 1]);
    let shift = frame.notes.cfa_shift.as_ref().unwrap();
    assert_eq!(
        (shift.rows, shift.cols, shift.from.as_str()),
        (1, 1, shifted.as_str())
    );
    assert!(
        shift.describe().contains("first 1 row and 1 column"),
        "{}",
        shift.describe()
    );
    assert_eq!(frame.notes.skipped_opcodes.len(), 1);
    // a CFA that is no shift of the table's stays a mismatch
    let other = if cfa.contains('W') { "RG/GB" } else { "RG/WB" };
    let e = decode(
        dng_input(w, h, other, DngInfo::default()),
        Levels::default(),
        table,
        &lim,
    )
    .err()
    .unwrap();
    assert!(matches!(e, PipelineError::CfaMismatch { .. }), "{e}");
    // a frame too small to move says so, naming both CFAs
    for (w, h) in [(1, 6), (8, 1), (1, 1)] {
        let e = decode(
            dng_input(w, h, &shifted, DngInfo::default()),
            Levels::default(),
            table,
            &lim,
        )
        .err()
        .unwrap();
        assert_eq!(
            e.to_string(),
            format!(
                "the DNG's CFA '{shifted}' is the table's '{cfa}' seen from another pixel, but its {w}×{h} frame is too small to leave out its first 1 row and 1 column"
            )
        );
    }
    // the same CFA: nothing moved
    let frame = decode(
        dng_input(w, h, &cfa, DngInfo::default()),
        Levels::default(),
        table,
        &lim,
    )
    .unwrap();
    assert_eq!(
        (frame.width, frame.height, frame.notes),
        (w, h, FrameNotes::default())
    );
}

/// An 8-bit PNG-like input without a sidecar: samples 0..=255 in a container whose largest value
/// is 255.
fn png8_input(w: usize, h: usize) -> Input {
    let data = (0..w * h).map(|i| (i * 37 % 256) as u16).collect();
    let source = SourceInfo {
        format: MosaicFormat::Png,
        bits_per_sample: 8,
        max_value: Some(255),
    };
    decoded((w, h), data, source, None, None)
}

fn dn_levels(frame: &DecodedFrame) -> (u16, u16) {
    match &frame.samples {
        Samples::Dn { black, white, .. } => (*black, *white),
        Samples::Volts(_) => panic!("integer input stays in DN when the renderer scales it"),
    }
}

#[test]
fn without_levels_white_is_the_containers_largest_value() {
    let (table, lim) = (tiny_table(), Limits::default());
    let decoded = |levels| decode(png8_input(8, 6), levels, table, &lim);
    assert_eq!(dn_levels(&decoded(Levels::default()).unwrap()), (0, 255));
    // the request's level wins over the container's
    let given = Levels {
        black: Some(16),
        white: Some(4095),
    };
    assert_eq!(dn_levels(&decoded(given).unwrap()), (16, 4095));
    // a black the container's white does not clear is the frame's levels' fault
    let black_only = Levels {
        black: Some(300),
        white: None,
    };
    assert!(matches!(
        decoded(black_only),
        Err(PipelineError::Levels {
            black: 300,
            white: 255
        })
    ));
    // a sidecar's (or DNG's) white still comes before the container's
    let dng = dng_input(8, 6, &table_cfa(), DngInfo::default());
    let frame = decode(dng, Levels::default(), table, &lim).unwrap();
    assert_eq!(dn_levels(&frame), (64, 4095));
}
