//! How the command line ends: quietly on a closed pipe, with exit code 2 on flags that do
//! not go together.

use std::io::Read;
use std::process::{Command, Stdio};

/// `l3 args` with its standard output closed before it writes: it must end without a panic.
fn with_closed_stdout(args: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("L3_BIN"))
        .args(args)
        .current_dir(dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        e.read_to_string(&mut err).unwrap();
    }
    let status = child.wait().unwrap();
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    assert_ne!(status.code(), Some(101), "{args:?}: {err}");
}

#[test]
fn a_closed_pipe_ends_the_command_quietly() {
    with_closed_stdout(&["sensors"]);
    with_closed_stdout(&["simulate", "--scene", "uniform", "--out", "x"]);
}

#[test]
fn a_table_with_a_method_or_the_paper_table_that_ignores_it_is_a_usage_error() {
    let dir = tempfile::tempdir().unwrap();
    for args in [
        &["eval", "--method", "baseline", "--table", "t.safetensors"][..],
        &["eval", "--method", "isp", "--table", "t.safetensors"],
        &["eval", "--paper-table", "--table", "t.safetensors"],
    ] {
        let out = Command::new(env!("L3_BIN"))
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("--table"), "{err}");
    }
}

#[test]
fn demosaic_refuses_an_output_it_would_not_write_and_names_every_method() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // a 4×4 Bayer mosaic as PGM
    let mut pgm = b"P5\n4 4\n255\n".to_vec();
    pgm.extend((0..16u8).map(|v| v * 10));
    std::fs::write(d.join("m.pgm"), pgm).unwrap();
    let run = |args: &[&str]| {
        let out = Command::new(env!("L3_BIN"))
            .args(args)
            .current_dir(d)
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let base = ["demosaic", "--in", "m.pgm", "--cfa", "RG/GB", "--out"];
    let (code, err) = run(&[&base[..], &["x.png"]].concat());
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains(".tiff"), "{err}");
    assert!(!d.join("x.png").exists());
    let (code, err) = run(&[&base[..], &["x.tiff", "--method", "foo"]].concat());
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("isp"), "{err}");
    let (code, err) = run(&[&base[..], &["x.tiff"]].concat());
    assert_eq!(code, Some(0), "{err}");
}

/// `$L3_ISET_DIR` set to a folder that is not an ISET data directory is an error naming the
/// variable, as `--iset-dir` with the same folder is.
#[test]
fn a_missing_iset_dir_in_the_environment_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(env!("L3_BIN"))
        .args(["simulate", "--scene", "uniform", "--out", "x"])
        .env("L3_ISET_DIR", tmp.path().join("nowhere"))
        .current_dir(tmp.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("L3_ISET_DIR") && err.contains("nowhere"),
        "{err}"
    );
}
