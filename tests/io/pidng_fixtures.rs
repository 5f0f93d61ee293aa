//! DNGs written by PiDNG 4.0.9 the way its README uses it (`scripts/pidng_fixtures.py`,
//! tests/fixtures/pidng/): an RGBW file without CFAPlaneColor, with DNGVersion written twice
//! and no UniqueCameraModel, and two Bayer files with Make, Model and UniqueCameraModel (one a
//! simulated frame of the Sony ILCE-9). Each
//! decodes to its raw twin, and `l3 render` gives the same PNG bytes for the DNG and the twin.

use std::path::{Path, PathBuf};
use std::process::Command;

use l3::io::{DecodedMosaic, Limits, MosaicFormat, read_mosaic};
use l3::test_support::tiny_table;

fn dir() -> PathBuf {
    PathBuf::from(env!("L3_ROOT")).join("tests/fixtures/pidng")
}

fn u16_of(m: DecodedMosaic) -> Vec<u16> {
    match m {
        DecodedMosaic::U16(f) => f.data,
        other => panic!("integer mosaic expected, got {other:?}"),
    }
}

/// The raw twin's pixels, read as plain little-endian u16 bytes.
fn raw_bytes(stem: &str) -> Vec<u16> {
    std::fs::read(dir().join(format!("{stem}.raw")))
        .unwrap()
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect()
}

#[test]
fn pidng_dngs_decode_to_their_raw_twins() {
    let limits = Limits::default();
    for (stem, cfa, planes, size) in [
        ("rgbw_pidng", "RG/WB", "RGBW", (64, 48)),
        ("bayer_sony", "RG/GB", "RGB", (32, 24)),
        ("sony_macbeth", "RG/GB", "RGB", (192, 128)),
    ] {
        let dng = read_mosaic(&dir().join(format!("{stem}.dng")), &limits).unwrap();
        let twin = read_mosaic(&dir().join(format!("{stem}.raw")), &limits).unwrap();
        assert_eq!(dng.info.format, MosaicFormat::Dng);
        let (md, mt) = (dng.meta.clone().unwrap(), twin.meta.clone().unwrap());
        assert_eq!((md.width, md.height), size, "{stem}");
        assert_eq!(md.cfa, cfa, "{stem}");
        assert_eq!(
            (&md.cfa, md.black_level, md.white_level, md.width, md.height),
            (&mt.cfa, mt.black_level, mt.white_level, mt.width, mt.height),
            "{stem}"
        );
        let info = dng.dng.clone().unwrap();
        assert_eq!(info.plane_colors, planes, "{stem}");
        let pixels = u16_of(dng.mosaic);
        assert!(
            pixels == raw_bytes(stem),
            "{stem}: pixels differ from the raw bytes"
        );
        assert!(
            pixels == u16_of(twin.mosaic),
            "{stem}: pixels differ from the twin"
        );
    }
}

#[test]
fn pidng_camera_names_are_read() {
    let limits = Limits::default();
    let d = read_mosaic(&dir().join("bayer_sony.dng"), &limits).unwrap();
    let info = d.dng.unwrap();
    assert_eq!(info.make.as_deref(), Some("SONY"));
    assert_eq!(info.model.as_deref(), Some("ILCE-9"));
    assert_eq!(info.unique_camera_model.as_deref(), Some("Sony ILCE-9"));
    assert_eq!(d.meta.unwrap().sensor.as_deref(), Some("Sony ILCE-9"));
    let d = read_mosaic(&dir().join("rgbw_pidng.dng"), &limits).unwrap();
    let info = d.dng.unwrap();
    assert_eq!(
        (info.make.as_deref(), info.model.as_deref()),
        (Some("PiDNG"), Some("RGBW fixture"))
    );
    assert_eq!(info.unique_camera_model, None);
}

fn l3(args: &[&str], dir: &Path) -> std::process::Output {
    Command::new(env!("L3_BIN"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run l3")
}

#[test]
fn l3_render_of_the_pidng_rgbw_dng_equals_its_raw_twin() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    tiny_table().save(&d.join("t.safetensors")).unwrap();
    let mut outs = Vec::new();
    for ext in ["dng", "raw"] {
        let input = dir().join(format!("rgbw_pidng.{ext}"));
        let out = d.join(format!("rgbw_pidng-{ext}.png"));
        let o = l3(
            &[
                "render",
                "--table",
                "t.safetensors",
                "--illuminant",
                "A",
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
    assert!(outs[0].starts_with(b"\x89PNG"));
    assert!(
        outs[0] == outs[1],
        "l3 render of the PiDNG RGBW DNG differs from its raw twin"
    );
}
