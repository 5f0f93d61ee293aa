//! Where the tests find the repository and the `l3` binary: `L3_ROOT` (the root package's
//! directory) and `L3_BIN` (the `l3` executable that `cargo test` at the root builds beside this
//! package's test binaries, in the same profile directory).
use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let root = manifest.parent().unwrap_or(&manifest).to_path_buf();
    // OUT_DIR is <target>/<profile>/build/<package>-<hash>/out
    let out = PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default());
    let profile_dir = out.ancestors().nth(3).unwrap_or(&out).to_path_buf();
    let bin = profile_dir.join(format!("l3{}", std::env::consts::EXE_SUFFIX));
    println!("cargo:rustc-env=L3_ROOT={}", root.display());
    println!("cargo:rustc-env=L3_BIN={}", bin.display());
    println!("cargo:rerun-if-changed=build.rs");
}
