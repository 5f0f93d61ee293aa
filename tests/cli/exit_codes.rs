//! docs/cli.md's exit codes, whichever layer finds the mistake: 2 for a bad argument or
//! configuration (a flag's value the core refuses, an invalid sensor design), 1 for an error
//! (a file that cannot be read, no table to render with).

use std::path::Path;

use crate::support::l3_code;

/// Runs `l3 args` in `d` and checks its exit code is `code` and its standard error holds
/// `says`.
fn expect(d: &Path, args: &[&str], code: i32, says: &str) {
    let (got, out, err) = l3_code(args, d);
    assert_eq!(got, Some(code), "{args:?}: {out}{err}");
    assert!(err.contains(says), "{args:?}: {err}");
}

/// A table and an 8×8 mosaic in `d`: enough for `render` to reach the checks of its flags.
fn table_and_mosaic(d: &Path) {
    l3::test_support::tiny_table()
        .save(&d.join("t.safetensors"))
        .unwrap();
    let mut pgm = b"P5\n8 8\n255\n".to_vec();
    pgm.extend((0..64u8).map(|v| v * 3));
    std::fs::write(d.join("m.pgm"), pgm).unwrap();
}

#[test]
fn values_the_core_refuses_from_flags_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    table_and_mosaic(d);
    let render = ["render", "--table", "t.safetensors", "--in", "m.pgm"];
    let render = |extra: &[&'static str]| [&render[..], extra, &["--out", "o.png"]].concat();
    for (extra, says) in [
        (
            &["--illuminant", "Nonesuch"][..],
            "unknown illuminant 'Nonesuch'",
        ),
        (&["--illuminant", "cct:100"], "1000–25000 K"),
        (&["--illuminant", "xy:0.9,0.9"], "spectrum locus"),
        (&["--white-level", "abc"], "white level 'abc'"),
    ] {
        expect(d, &render(extra), 2, says);
    }
    assert!(!d.join("o.png").exists());
    let eval = ["eval", "--table", "t.safetensors", "--out", "e.json"];
    for (extra, says) in [
        (&["--exposure", "2"][..], "exposure factor 2"),
        (&["--chart", "foo"], "chart 'foo'"),
        (
            &["--illuminant", "Nonesuch"],
            "unknown illuminant 'Nonesuch'",
        ),
    ] {
        expect(d, &[&eval[..], extra].concat(), 2, says);
    }
    let train = ["train", "--scene-size", "32", "--out", "x.safetensors"];
    for (extra, says) in [
        (&["--patch", "4"][..], "patch_size 4"),
        (&["--levels", "0"], "levels 0"),
        (&["--scenes", "0"], "scenes 0"),
        (&["--chroma-classes", "0"], "chroma_classes 0"),
        (
            &["--illuminants", "Nonesuch"],
            "unknown illuminant 'Nonesuch'",
        ),
    ] {
        expect(d, &[&train[..], extra].concat(), 2, says);
    }
    assert!(!d.join("x.safetensors").exists());
    let simulate = ["simulate", "--out", "sim"];
    for (extra, says) in [
        (&["--scene", "foo"][..], "unknown scene 'foo'"),
        (
            &["--sensor", "nosuch"],
            "neither a TOML file nor a catalogue sensor",
        ),
        (&["--iset-dir", "nowhere"], "ISET data directory not found"),
    ] {
        expect(d, &[&simulate[..], extra].concat(), 2, says);
    }
    let demosaic = [
        "demosaic", "--in", "m.pgm", "--out", "x.tiff", "--cfa", "RG/G",
    ];
    expect(d, &demosaic, 2, "invalid CFA 'RG/G'");
}

/// Every kind of invalid sensor design is a configuration error.
#[test]
fn an_invalid_sensor_design_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (file, toml, says) in [
        (
            "key.toml",
            "name = \"x\"\nfil_factor = 0.5\n",
            "unknown field `fil_factor`",
        ),
        (
            "cfa.toml",
            "name = \"x\"\ncfa = \"RG/G\"\n",
            "invalid CFA 'RG/G'",
        ),
        (
            "channel.toml",
            "name = \"x\"\ncfa = \"RG/GB\"\n[filters]\nR = { constant = 0.5 }\n\
             G = { constant = 0.5 }\n",
            "CFA channel 'B' has no entry in [filters]",
        ),
        (
            "range.toml",
            "name = \"x\"\nfill_factor = 1.5\n",
            "fill_factor = 1.5",
        ),
        (
            "csv.toml",
            "name = \"x\"\n[filters]\nR = { csv = \"none.csv\", column = \"r\" }\n\
          G = { constant = 0.5 }\nW = { constant = 1.0 }\nB = { constant = 0.5 }\n",
            "none.csv",
        ),
    ] {
        std::fs::write(d.join(file), toml).unwrap();
        expect(d, &["simulate", "--sensor", file, "--out", "sim"], 2, says);
    }
}

/// A file a flag names that cannot be read, and no table to render with, are errors (1), not
/// usage errors.
#[test]
fn a_missing_file_or_table_exits_1() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    table_and_mosaic(d);
    let render = [
        "render",
        "--table",
        "t.safetensors",
        "--in",
        "m.pgm",
        "--out",
        "o.png",
    ];
    let light = [&render[..], &["--illuminant", "csv:light.csv"]].concat();
    expect(d, &light, 1, "light.csv");
    expect(
        d,
        &[
            "render",
            "--table",
            "none.safetensors",
            "--in",
            "m.pgm",
            "--out",
            "o.png",
        ],
        1,
        "none.safetensors",
    );
    // no --table, and a data directory without an active table
    let data = d.join("data");
    let no_table = [
        "render",
        "--data-dir",
        data.to_str().unwrap(),
        "--in",
        "m.pgm",
        "--out",
        "o.png",
    ];
    expect(d, &no_table, 1, "no --table given");
}
