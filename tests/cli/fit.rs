//! Frames and sensors that do not fit the table: another CFA is refused (exit 2) whichever
//! file brings it, another sensor name is warned of.

use std::path::Path;

use crate::support::{l3, train_small_si};

/// `l3 simulate --scene uniform` through `sensor` into `out`.
fn simulate_on(d: &Path, sensor: &str, out: &str) {
    let (ok, so, se) = l3(
        &[
            "simulate", "--sensor", sensor, "--scene", "uniform", "--out", out,
        ],
        d,
    );
    assert!(ok, "simulate on {sensor}: {so}{se}");
}

/// Runs `args` in `d`: its exit code and standard error.
fn code_and_stderr(args: &[&str], d: &Path) -> (Option<i32>, String) {
    let (code, _, err) = crate::support::l3_code(args, d);
    (code, err)
}

#[test]
fn a_frame_or_sensor_that_does_not_fit_the_table_is_refused_or_warned_of() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let table = d.join("t.safetensors"); // rgbw-paper, RG/WB
    train_small_si(d, &table, &[]);
    let t = table.to_str().unwrap();
    simulate_on(d, "bayer-paper", "bayer");
    simulate_on(d, "rgbw-iset", "iset");
    another_cfa_is_refused(d, t);
    another_sensor_is_warned_of(d, t);
    eval_sensor_fits_the_table(d, t);
}

/// A .raw whose sidecar gives another CFA: refused as its DNG twin is.
fn another_cfa_is_refused(d: &Path, t: &str) {
    let cfa_msg = "CFA 'RG/GB' does not match the table's CFA 'RG/WB'";
    for (input, origin) in [
        ("bayer/mosaic.raw", "sidecar's"),
        ("bayer/mosaic.dng", "DNG's"),
    ] {
        let (code, err) = code_and_stderr(
            &["render", "--table", t, "--in", input, "--out", "o.png"],
            d,
        );
        assert_eq!(code, Some(2), "{input}: {err}");
        assert!(err.contains(&format!("the {origin} {cfa_msg}")), "{err}");
    }
    assert!(!d.join("o.png").exists());
    let (code, err) = code_and_stderr(
        &[
            "eval",
            "--table",
            t,
            "--frame",
            "bayer/mosaic.raw",
            "--out",
            "f.json",
        ],
        d,
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains(cfa_msg), "{err}");
}

/// The same CFA on another sensor: rendered, with a warning naming both sensors; the table's
/// own sensor: no warning.
fn another_sensor_is_warned_of(d: &Path, t: &str) {
    for input in ["iset/mosaic.raw", "iset/mosaic.dng"] {
        let (code, err) = code_and_stderr(
            &["render", "--table", t, "--in", input, "--out", "i.png"],
            d,
        );
        assert_eq!(code, Some(0), "{err}");
        let warning = err
            .lines()
            .find(|l| l.starts_with("warning:"))
            .unwrap_or("");
        assert!(
            warning.contains("'rgbw-iset'") && warning.contains("'rgbw-paper'"),
            "{err}"
        );
    }
    // the table's own sensor: no warning
    simulate_on(d, "rgbw-paper", "paper");
    let (code, err) = code_and_stderr(
        &[
            "render",
            "--table",
            t,
            "--in",
            "paper/mosaic.raw",
            "--out",
            "p.png",
        ],
        d,
    );
    assert_eq!(code, Some(0), "{err}");
    assert!(!err.contains("warning:"), "{err}");
}

/// `eval --sensor`: another CFA is an error, another name a warning.
fn eval_sensor_fits_the_table(d: &Path, t: &str) {
    let (code, err) = code_and_stderr(
        &[
            "eval",
            "--table",
            t,
            "--sensor",
            "bayer-paper",
            "--out",
            "e.json",
        ],
        d,
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("the sensor's CFA 'RG/GB'"), "{err}");
    let (code, err) = code_and_stderr(
        &[
            "eval",
            "--table",
            t,
            "--sensor",
            "rgbw-iset",
            "--no-spatial",
            "--patch-px",
            "8",
            "--out",
            "e.json",
        ],
        d,
    );
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("warning:") && err.contains("'rgbw-iset'") && err.contains("'rgbw-paper'"),
        "{err}"
    );
}
