//! `l3 eval --scielab IDEAL RENDERED` on float XYZ TIFFs: a uniform pair scores plain CIELAB
//! ΔE, the map is written, the formula flag is honoured, and a user's mistakes are errors.

use std::path::Path;

use l3::colour::{D65_WHITE_XYZ, ciede2000, xyz_to_lab};

use crate::support::run_l3;

fn write_xyz(path: &Path, w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) {
    let mut data = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            data.extend_from_slice(&f(x, y));
        }
    }
    l3::io::write_tiff_f32_rgb(path, w, h, &data).unwrap();
}

fn json(out: &str) -> serde_json::Value {
    serde_json::from_str(out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

#[test]
fn scielab_scores_tiff_pairs() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let (a, b) = ([0.2f32, 0.21, 0.25], [0.22f32, 0.2, 0.18]);
    write_xyz(&d.join("a.tiff"), 40, 30, |_, _| a);
    write_xyz(&d.join("b.tiff"), 40, 30, |_, _| b);
    let (ok, out) = run_l3(
        &["eval", "--scielab", "a.tiff", "b.tiff", "--out", "s.json"],
        d,
    );
    assert!(ok, "{out}");
    let v = json(&out);
    let lab = |x: [f32; 3]| xyz_to_lab(x.map(f64::from), D65_WHITE_XYZ);
    let plain = ciede2000(lab(a), lab(b));
    let mean = v["stats"]["mean"].as_f64().unwrap();
    assert!((mean - plain).abs() < 1e-6, "{mean} vs {plain}");
    assert_eq!(v["stats"]["n"], 1200);
    assert_eq!(v["options"]["formula"], "2000");
    assert_eq!(v["filter_taps"], 41);
    assert!(v.get("map").is_none());
    assert_eq!(json(&std::fs::read_to_string(d.join("s.json")).unwrap()), v);

    // fine noise, ΔE 1976, 20 samples per degree, and the map
    write_xyz(&d.join("n.tiff"), 40, 30, |x, y| {
        let k = if (x * 7 + y * 13) % 3 == 0 {
            1.08
        } else {
            0.95
        };
        a.map(|c| c * k)
    });
    let args = [
        "eval",
        "--scielab",
        "a.tiff",
        "n.tiff",
        "--delta-e",
        "1976",
        "--samples-per-degree",
        "20",
        "--map",
        "map.tiff",
        "--out",
        "n.json",
    ];
    let (ok, out) = run_l3(&args, d);
    assert!(ok, "{out}");
    let v = json(&out);
    assert_eq!(v["options"]["formula"], "1976");
    assert_eq!(v["filter_taps"], 19);
    // the per-pixel map goes to its TIFF, neither to stdout nor to the JSON file
    assert!(v.get("map").is_none(), "{out}");
    let written = json(&std::fs::read_to_string(d.join("n.json")).unwrap());
    assert!(written.get("map").is_none());
    let (mean, max) = (
        v["stats"]["mean"].as_f64().unwrap(),
        v["stats"]["max"].as_f64().unwrap(),
    );
    assert!(mean > 0.0 && mean <= max, "{v}");
    let mut dec =
        tiff::decoder::Decoder::new(std::fs::File::open(d.join("map.tiff")).unwrap()).unwrap();
    assert_eq!(dec.dimensions().unwrap(), (40, 30));
    let tiff::decoder::DecodingResult::F32(map) = dec.read_image().unwrap() else {
        panic!("a float map was expected");
    };
    let map_mean = map.iter().map(|&v| f64::from(v)).sum::<f64>() / map.len() as f64;
    assert!((map_mean - mean).abs() < 1e-4, "{map_mean} vs {mean}");

    // mistakes
    write_xyz(&d.join("small.tiff"), 20, 30, |_, _| a);
    let (ok, out) = run_l3(&["eval", "--scielab", "a.tiff", "small.tiff"], d);
    assert!(!ok && out.contains("20×30"), "{out}");
    let (ok, out) = run_l3(
        &["eval", "--scielab", "a.tiff", "b.tiff", "--delta-e", "1994"],
        d,
    );
    assert!(!ok && out.contains("1994"), "{out}");
    let (ok, out) = run_l3(
        &[
            "eval",
            "--scielab",
            "a.tiff",
            "b.tiff",
            "--samples-per-degree",
            "0",
        ],
        d,
    );
    assert!(!ok && out.contains("samples per degree"), "{out}");
    let (ok, out) = run_l3(&["eval", "--scielab", "a.tiff", "missing.tiff"], d);
    assert!(!ok && out.contains("missing.tiff"), "{out}");
}
