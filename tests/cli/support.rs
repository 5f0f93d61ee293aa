//! What the modules of this binary share.

use std::path::Path;
use std::process::Command;

/// Runs the `l3` executable with `args` in `dir`: whether it succeeded, and its standard
/// output followed by its standard error.
pub fn run_l3(args: &[&str], dir: &Path) -> (bool, String) {
    let out = Command::new(env!("L3_BIN"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run l3");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

/// Runs the `l3` executable with `args` in `dir`: whether it succeeded, its standard output
/// and its standard error.
pub fn l3(args: &[&str], dir: &Path) -> (bool, String, String) {
    let (code, out, err) = l3_code(args, dir);
    (code == Some(0), out, err)
}

/// Runs the `l3` executable with `args` in `dir`: its exit code, standard output and
/// standard error.
pub fn l3_code(args: &[&str], dir: &Path) -> (Option<i32>, String, String) {
    let out = Command::new(env!("L3_BIN"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run l3");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `l3 train` of a small SI table (D65 and tungsten, 4 scenes of 48 px, 10 levels) in `dir`
/// to `table`; its standard output.
pub fn train_small_si(dir: &Path, table: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "train",
        "--kind",
        "si",
        "--illuminants",
        "D65,Tungsten",
        "--scenes",
        "4",
        "--scene-size",
        "48",
        "--levels",
        "10",
        "--out",
        table.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let (ok, out, err) = l3(&args, dir);
    assert!(ok, "train failed: {out}{err}");
    out
}
