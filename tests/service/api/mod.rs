//! The render service end to end on a real listener: render parity with `l3 render`, every
//! table / illuminant / evaluation / health endpoint, limits, auth and hostile input.
//!
//! By topic: renders equal to `l3 render`'s, DNG input and the light a frame's metadata names
//! (`render`), the read endpoints for tables, illuminants, evaluations and metrics (`reads`),
//! hostile input (`hostile`), backpressure, auth, readiness, an injected panic and the time
//! limit (`limits`), concurrent illuminant changes (`concurrency`), what a client cannot make
//! the service do (`trust`), and lights registered from SPD samples in training and
//! evaluations (`spd_lights`).

use std::path::Path;
use std::process::Command;

mod concurrency;
mod hostile;
mod limits;
mod reads;
mod render;
mod spd_lights;
mod trust;

fn l3_cli(args: &[&str], dir: &Path) {
    let out = Command::new(env!("L3_BIN"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run l3");
    assert!(
        out.status.success(),
        "l3 {args:?} failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `l3 render` of the simulated frame `sim/mosaic.raw` in `dir` with `table.safetensors`
/// under tungsten, with the options `extra`, to `out`.
fn cli_render(dir: &Path, extra: &[&str], out: &str) {
    let mut args = vec![
        "render",
        "--table",
        "table.safetensors",
        "--in",
        "sim/mosaic.raw",
        "--illuminant",
        "Tungsten",
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", out]);
    l3_cli(&args, dir);
}

fn decode_png(bytes: &[u8]) -> image::RgbImage {
    image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
        .expect("png")
        .to_rgb8()
}
