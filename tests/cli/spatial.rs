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
