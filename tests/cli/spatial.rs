//! `l3 eval --method baseline` on the simulated chart reports the spatial metrics (sharpness and
//! false colour on a slanted edge, S-CIELAB on a texture) in its output and its JSON, and
//! `l3 simulate --scene edge` draws the edge.

use crate::support::run_l3;

#[test]
fn eval_reports_sharpness_false_colour_and_texture_s_cielab() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let (ok, out) = run_l3(
        &[
            "eval",
            "--method",
            "baseline",
            "--patch-px",
            "8",
            "--out",
            "r.json",
        ],
        d,
    );
    assert!(ok, "{out}");
    assert!(out.contains("slanted edge: MTF50"), "{out}");
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("r.json")).unwrap()).unwrap();
    let num = |k: &str| {
        v[k].as_f64()
            .unwrap_or_else(|| panic!("{k} missing from {v}"))
    };
    let (m, ideal) = (num("mtf50"), num("ideal_mtf50"));
    // a bilinear demosaic is softer than the lens, and the lens is below Nyquist
    assert!(m > 0.05 && m < ideal && ideal < 0.5, "{m} vs {ideal}");
    assert!(num("false_colour").is_finite());
    assert!(num("s_cielab_texture") > 0.0);
    assert!(num("s_cielab_mean") > 0.0);

    // --no-spatial leaves them out
    let (ok, out) = run_l3(
        &[
            "eval",
            "--method",
            "baseline",
            "--patch-px",
            "8",
            "--no-spatial",
            "--out",
            "n.json",
        ],
        d,
    );
    assert!(ok, "{out}");
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("n.json")).unwrap()).unwrap();
    assert!(v.get("mtf50").is_none() && v.get("false_colour").is_none());

    let (ok, out) = run_l3(&["simulate", "--scene", "edge", "--out", "edge"], d);
    assert!(ok, "{out}");
    assert!(out.contains("slanted-edge (128×128)"), "{out}");
}

/// At a tenth of the exposure the chroma stage (`--chroma-denoise auto`, the default) runs on a
/// table trained for a sensor with a noise model: the per-pixel error and S-CIELAB fall against
/// `off`, and the sharpness, measured on luminance, which the stage keeps, is the same.
#[test]
fn the_chroma_stage_runs_at_low_light_and_keeps_luminance() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    crate::support::train_small_si(d, &d.join("t.safetensors"), &[]);
    let eval = |mode: &str| {
        let out = format!("{mode}.json");
        let (ok, text) = run_l3(
            &[
                "eval",
                "--table",
                "t.safetensors",
                "--illuminant",
                "Tungsten",
                "--exposure",
                "0.1",
                "--patch-px",
                "12",
                "--chroma-denoise",
                mode,
                "--out",
                &out,
            ],
            d,
        );
        assert!(ok, "{text}");
        let v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.join(&out)).unwrap()).unwrap();
        v
    };
    let (off, auto) = (eval("off"), eval("auto"));
    let f = |v: &serde_json::Value, p: &str| v.pointer(p).and_then(|x| x.as_f64()).unwrap();
    assert!(
        f(&auto, "/per_pixel/mean") < 0.9 * f(&off, "/per_pixel/mean"),
        "per pixel: {} with the stage, {} without",
        f(&auto, "/per_pixel/mean"),
        f(&off, "/per_pixel/mean")
    );
    assert!(f(&auto, "/s_cielab_mean") < f(&off, "/s_cielab_mean"));
    assert_eq!(f(&auto, "/mtf50"), f(&off, "/mtf50"));

    let (ok, text) = run_l3(&["eval", "--chroma-denoise", "sometimes"], d);
    assert!(!ok && text.contains("auto, on or off"), "{text}");
}
