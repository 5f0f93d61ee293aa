//! What the modules of this binary share.

use std::path::Path;
use std::process::Command;

/// Runs the `l3` executable with `args` in `dir`: whether it succeeded, and its standard
/// output followed by its standard error.
pub fn run_l3(args: &[&str], dir: &Path) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_l3"))
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
