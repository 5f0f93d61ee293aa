//! DNGs written by a third party (PiDNG, `scripts/make_dng_fixtures.py`) against their raw
//! twins: the same mosaic as `.raw` + JSON sidecar. Every DNG must decode to its twin's
//! pixels, CFA and levels, and render byte for byte as the twin does, through the library
//! and through `l3 render`.

use std::path::{Path, PathBuf};
use std::process::Command;

use l3::io::{
    DecodedMosaic, Limits, MosaicFormat, PngCompression, decode_mosaic_with_meta, encode_png_rgb8,
    read_mosaic,
};
use l3::l3::render::{FastRenderer, Mosaic, WhiteLevel};
use l3::test_support::tiny_table;

fn fixtures() -> Vec<PathBuf> {
    let dir = PathBuf::from(env!("L3_ROOT")).join("tests/fixtures/dng");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "dng"))
        .collect();
    v.sort();
    v
}

fn u16_of(m: DecodedMosaic) -> Vec<u16> {
    match m {
        DecodedMosaic::U16(f) => f.data,
        other => panic!("integer mosaic expected, got {other:?}"),
    }
}

/// An sRGB PNG of `data` rendered with the tiny table from DN with the given levels, as the
/// service renders integer input.
fn render_dn(data: &[u16], w: usize, h: usize, black: u16, white: u16) -> Vec<u8> {
    let t = tiny_table();
    let r = FastRenderer::new(t, &t.kernels).unwrap();
    let (rgb, _, _) = r
        .render_srgb8(
            Mosaic::Dn { data, black, white },
            w,
            h,
            None,
            WhiteLevel::Auto,
        )
        .unwrap();
    encode_png_rgb8(w, h, &rgb, PngCompression::Fast).unwrap()
}

#[test]
fn every_fixture_decodes_to_its_raw_twin_and_renders_identically() {
    let files = fixtures();
    assert_eq!(files.len(), 12, "2 CFAs × 3 bit depths × 2 compressions");
    let limits = Limits::default();
    let swing = tiny_table().meta.voltage_swing;
    for dng in &files {
        let twin = dng.with_extension("raw");
        let a = read_mosaic(dng, &limits).unwrap();
        let b = read_mosaic(&twin, &limits).unwrap();
        assert_eq!(a.info.format, MosaicFormat::Dng);
        let (ma, mb) = (a.meta.clone().unwrap(), b.meta.clone().unwrap());
        let name = dng.file_name().unwrap().to_string_lossy().into_owned();
        assert_eq!(
            (&ma.cfa, ma.black_level, ma.white_level, ma.width, ma.height),
            (&mb.cfa, mb.black_level, mb.white_level, mb.width, mb.height),
            "{name}"
        );
        let info = a.dng.clone().unwrap();
        let bits: u8 = name.split('_').nth(1).unwrap().parse().unwrap();
        assert_eq!(info.bits_per_sample, bits, "{name}");
        assert_eq!(info.compression, if name.contains("lj92") { 7 } else { 1 });
        assert!(info.as_shot_neutral.is_some(), "{name}");
        let (w, h) = (ma.width, ma.height);
        let (da, db) = (u16_of(a.mosaic), u16_of(b.mosaic));
        assert!(da == db, "{name}: pixels differ from the raw twin");
        // the service's path: DN with the file's levels
        let pa = render_dn(&da, w, h, ma.black_level, ma.white_level);
        let pb = render_dn(&db, w, h, mb.black_level, mb.white_level);
        assert!(pa == pb, "{name}: renders differ");
        // the CLI's path: volts from the levels at the table's swing
        let (mut ma, mut mb) = (ma.clone(), mb.clone());
        ma.voltage_swing = swing;
        mb.voltage_swing = swing;
        let fa = l3::io::RawFrame::new(w, h, da.clone()).unwrap();
        let fb = l3::io::RawFrame::new(w, h, db.clone()).unwrap();
        assert!(
            fa.to_volts(&ma).unwrap() == fb.to_volts(&mb).unwrap(),
            "{name}: volts differ"
        );
        // the bytes through the format detector, as a request body
        let bytes = std::fs::read(dng).unwrap();
        let l = decode_mosaic_with_meta(&bytes, &limits).unwrap();
        assert_eq!(u16_of(l.mosaic), db, "{name}");
        eprintln!(
            "{name}: {w}×{h} {} black {} white {}, {bits}-bit, compression {}: identical to its twin",
            ma.cfa, ma.black_level, ma.white_level, info.compression
        );
    }
}

fn l3(args: &[&str], dir: &Path) -> std::process::Output {
    Command::new(env!("L3_BIN"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run l3")
}

#[test]
fn l3_render_of_a_dng_equals_its_twin_and_checks_the_cfa() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    tiny_table().save(&d.join("t.safetensors")).unwrap();
    let dir = PathBuf::from(env!("L3_ROOT")).join("tests/fixtures/dng");
    for stem in ["rgbw_16_raw", "rgbw_10_lj92"] {
        let mut outs = Vec::new();
        for ext in ["dng", "raw"] {
            let input = dir.join(format!("{stem}.{ext}"));
            let out = d.join(format!("{stem}-{ext}.png"));
            let o = l3(
                &[
                    "render",
                    "--table",
                    "t.safetensors",
                    "--illuminant",
                    "D65",
                    "--in",
                    input.to_str().unwrap(),
                    "--out",
                    out.to_str().unwrap(),
                ],
                d,
            );
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            outs.push(std::fs::read(&out).unwrap());
        }
        assert!(
            outs[0] == outs[1],
            "{stem}: l3 render of the DNG differs from its twin"
        );
    }
    // a Bayer DNG with an RGBW table: both CFAs named
    let o = l3(
        &[
            "render",
            "--table",
            "t.safetensors",
            "--in",
            dir.join("bayer_12_raw.dng").to_str().unwrap(),
            "--out",
            "x.png",
        ],
        d,
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(e.contains("'RG/GB'") && e.contains("'RG/WB'"), "{e}");
    // the synthetic table has no sensor to match AsShotNeutral with: said, not guessed
    let o = l3(
        &[
            "render",
            "--table",
            "t.safetensors",
            "--in",
            dir.join("rgbw_16_raw.dng").to_str().unwrap(),
            "--out",
            "x.png",
        ],
        d,
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("sensor"), "{e}");
}
