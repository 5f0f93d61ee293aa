//! Replays every saved fuzz input under `tests/fuzz_regressions/<target>/`
//! (minimised crashers kept by `scripts/fuzz.sh`) and the seed corpora under
//! `fuzz/seeds/<target>/` through the same bodies the cargo-fuzz targets run
//! (`l3::fuzzing`). A body panics when an invariant breaks, failing the test.
//!
//! `cargo test --test fuzz_regressions -- --ignored write_seed_corpus`
//! regenerates the seed corpora.

use std::path::{Path, PathBuf};

use l3::fuzzing::{FUZZ_TARGETS, run_target};
use l3::io::{
    DngWriteInfo, RawFrame, RawMeta, encode_dng, encode_png_gray16, encode_tiff_gray_f32,
    encode_tiff_gray16,
};
use l3::test_support::tiny_table;

fn root() -> PathBuf {
    PathBuf::from(env!("L3_ROOT"))
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| p.is_file())
                .filter(|p| p.file_name().is_some_and(|n| n != ".gitkeep"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn replay(base: &Path) -> usize {
    let mut n = 0;
    for t in FUZZ_TARGETS {
        for f in files_in(&base.join(t)) {
            let data = std::fs::read(&f).unwrap();
            eprintln!("replaying {} ({} bytes)", f.display(), data.len());
            assert!(run_target(t, &data));
            n += 1;
        }
    }
    n
}

#[test]
fn saved_crashers_no_longer_crash() {
    let n = replay(&root().join("tests/fuzz_regressions"));
    eprintln!("{n} saved fuzz inputs replayed");
}

#[test]
fn seed_corpora_run_clean() {
    let n = replay(&root().join("fuzz/seeds"));
    eprintln!("{n} seed inputs replayed");
    assert!(n >= FUZZ_TARGETS.len(), "every target has seeds");
}

#[test]
fn unknown_target_is_reported() {
    assert!(!run_target("no_such_target", b""));
}

/// Hand-picked hostile inputs, one group per target (cheap to keep here).
#[test]
fn hostile_inputs_are_errors_not_panics() {
    let cases: &[(&str, &[u8])] = &[
        ("raw_query", b""),
        ("raw_query", b"?width=1&height=1\n\x00\x00"),
        ("raw_query", b"?width=0&height=5\n"),
        (
            "raw_query",
            b"?width=3&height=1&black_level=9&white_level=9\n\x01\x00\x02\x00\x03\x00",
        ),
        ("raw_query", b"?width=18446744073709551615&height=2\n\x00"),
        ("raw_query", b"?white=nan&width=1&height=1\n\x00\x00"),
        ("raw_query", b"?white=-1&width=1&height=1\n\x00\x00"),
        ("raw_query", b"\x01\x01\xff\xff\x00\x00\xff\xff"),
        ("mosaic_decode", b"P5\n1 1\n0\n\x00"),
        ("mosaic_decode", b"P5\n99999 99999\n255\n"),
        ("mosaic_decode", b"P2\n2 1\n65535\n70000 1\n"),
        ("mosaic_decode", b"II*\0\x08\0\0\0\xff\xff"),
        ("mosaic_decode", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR"),
        ("dng_decode", b""),
        (
            "dng_decode",
            b"II*\0\x08\0\0\0\x01\0\x12\xc6\x01\0\x04\0\0\0\x01\x04\0\0",
        ),
        ("dng_decode", b"MM\0*\0\0\0\x08\xff\xff"),
        ("dng_decode", b"II*\0\xff\xff\xff\xff"),
        (
            "mosaic_decode",
            b"II*\0\x08\0\0\0\x01\0\x12\xc6\x01\0\x04\0\0\0\x01\x04\0\0",
        ),
        ("table_file", b"\xff\xff\xff\xff\xff\xff\xff\x7f{}"),
        ("table_file", b"\x02\0\0\0\0\0\0\0{}"),
        ("training_json", b"{\"levels\": 1e400}"),
        ("training_json", b"{\"scenes\": -1}"),
        ("training_json", b"{\"sensor\": {\"voltage_swing_v\": 0}}"),
        ("training_json", b"[]"),
        (
            "illuminant_upload",
            b"x\n{\"matrix\": [[1e308,0,0],[0,1e308,0],[0,0,1e308]]}",
        ),
        (
            "illuminant_upload",
            b"x\n{\"matrix\": [[0,0,0],[0,0,0],[0,0,0]]}",
        ),
        (
            "illuminant_upload",
            b"x\n{\"spd\": {\"wavelengths_nm\": [400, 700], \"values\": [0, 0]}}",
        ),
        (
            "illuminant_upload",
            b"x\n{\"spd\": {\"wavelengths_nm\": [550, 551], \"values\": [1, 1]}}",
        ),
        (
            "illuminant_upload",
            b"x\n{\"spd\": {\"wavelengths_nm\": [700, 400], \"values\": [1, 1]}}",
        ),
        ("illuminant_upload", b"x\n{\"cct\": 1e9}"),
        ("illuminant_upload", b"\n{\"cct\": 3000}"),
        ("illuminant_upload", b"D65\n{\"cct\": 3000}"),
    ];
    for (t, data) in cases {
        eprintln!("{t}: {:?}", String::from_utf8_lossy(data));
        assert!(run_target(t, data));
    }
}

fn write(dir: &Path, name: &str, data: &[u8]) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join(name), data).unwrap();
}

/// Writes small valid inputs for every target into `fuzz/seeds/`.
#[test]
#[ignore = "regenerates fuzz/seeds; run explicitly"]
fn write_seed_corpus() {
    let seeds = root().join("fuzz/seeds");
    // raw u16 + query: binary header form and query-string form
    let (w, h) = (6usize, 4usize);
    let dn: Vec<u16> = (0..w * h).map(|i| (i * 37 % 1024) as u16).collect();
    let body: Vec<u8> = dn.iter().flat_map(|v| v.to_le_bytes()).collect();
    let mut bin = vec![w as u8, h as u8, 0, 0, 0xff, 0x03];
    bin.extend_from_slice(&body);
    write(&seeds.join("raw_query"), "seed-binary", &bin);
    let mut q =
        format!("?width={w}&height={h}&black_level=64&white_level=1023&white=auto\n").into_bytes();
    q.extend_from_slice(&body);
    write(&seeds.join("raw_query"), "seed-query", &q);
    // mosaics
    let frame = RawFrame::new(w, h, dn.iter().map(|v| v * 60).collect()).unwrap();
    let md = seeds.join("mosaic_decode");
    write(
        &md,
        "seed-gray16.png",
        &encode_png_gray16(&frame, l3::io::PngCompression::Fast).unwrap(),
    );
    write(&md, "seed-gray16.tif", &encode_tiff_gray16(&frame).unwrap());
    let f: Vec<f32> = dn.iter().map(|&v| v as f32 / 1023.0 * 1.8).collect();
    write(
        &md,
        "seed-f32.tif",
        &encode_tiff_gray_f32(w, h, &f).unwrap(),
    );
    let mut pgm = format!("P5\n{w} {h}\n1023\n").into_bytes();
    for v in &dn {
        pgm.extend_from_slice(&v.to_be_bytes());
    }
    write(&md, "seed-p5.pgm", &pgm);
    let p2 = format!(
        "P2\n# comment\n{w} {h}\n255\n{}\n",
        dn.iter()
            .map(|v| (v / 4).to_string())
            .collect::<Vec<_>>()
            .join(" ")
    );
    write(&md, "seed-p2.pgm", p2.as_bytes());
    // DNGs: the third-party fixtures and one of ours
    let dd = seeds.join("dng_decode");
    for e in std::fs::read_dir(root().join("tests/fixtures/dng")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "dng") {
            let name = format!("seed-{}", p.file_name().unwrap().to_string_lossy());
            write(&dd, &name, &std::fs::read(&p).unwrap());
        }
    }
    let meta = RawMeta::new(w, h, "RG/WB", 64, 1023, 1.8);
    let dng = encode_dng(
        &RawFrame::new(w, h, dn.clone()).unwrap(),
        &meta,
        &DngWriteInfo {
            as_shot_neutral: Some(vec![
                ("R".into(), 0.5),
                ("G".into(), 1.0),
                ("W".into(), 1.0),
                ("B".into(), 0.4),
            ]),
            calibration_illuminant: Some(17),
            ..DngWriteInfo::default()
        },
    )
    .unwrap();
    write(&dd, "seed-l3.dng", &dng);
    // table file
    write(
        &seeds.join("table_file"),
        "seed-tiny.safetensors",
        &tiny_table().to_bytes().unwrap(),
    );
    // training job JSON
    let tj = seeds.join("training_json");
    write(
        &tj,
        "seed-spec.json",
        br#"{"kind": "si", "illuminants": ["D65", "A", "cct:3200"], "patch_size": 5, "levels": 8, "seed": 1, "scenes": 4, "scene_size": 32, "noise": true, "contrast_classes": true, "saturation_classes": true, "mean_luminance": 100.0, "activate": false}"#,
    );
    let sensor = serde_json::to_value(l3::camera::SensorDesign::paper_default()).unwrap();
    let with_sensor = serde_json::json!({"kind": "cross", "levels": 4, "sensor": sensor});
    write(&tj, "seed-sensor.json", with_sensor.to_string().as_bytes());
    // illuminant uploads
    let iu = seeds.join("illuminant_upload");
    write(
        &iu,
        "seed-matrix",
        b"warm\n{\"matrix\": [[1.1, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.7]]}",
    );
    write(&iu, "seed-cct", b"tungsten-ish\n{\"cct\": 3200}");
    write(
        &iu,
        "seed-spd",
        b"led\n{\"spd\": {\"wavelengths_nm\": [380, 450, 500, 550, 600, 650, 700, 780], \"values\": [0.0, 1.0, 0.3, 0.6, 0.7, 0.4, 0.1, 0.0]}}",
    );
}
