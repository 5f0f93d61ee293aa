//! `l3 sfr` on image files as a user has them: a 16-bit grey PNG and an RGB TIFF, with and
//! without a region, against the analytic MTF50 of a linear-ramp edge.

use std::path::Path;

use crate::support::run_l3;

fn sfr(args: &[&str], dir: &Path) -> (bool, String) {
    let mut all = vec!["sfr"];
    all.extend_from_slice(args);
    run_l3(&all, dir)
}

/// A ramp edge `width` px wide (its LSF a box: MTF |sinc(π f width)|, MTF50 = 0.60335 /
/// width), slanted `deg` from vertical, from `lo` to `hi`, point-sampled.
fn ramp(x: f64, y: f64, deg: f64, width: f64, (cx, cy): (f64, f64)) -> f64 {
    let th = deg.to_radians();
    let d = ((x - cx) - (y - cy) * th.tan()) * th.cos();
    (d / width + 0.5).clamp(0.0, 1.0)
}

#[test]
fn sfr_measures_edges_in_png_and_tiff() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let width = 3.0;
    let analytic = 0.60335 / width;

    // a rising vertical edge in the right half of a 16-bit grey PNG; the left half is noise
    let png = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(160, 100, |x, y| {
        let v = if x < 80 {
            ((x * 7919 + y * 104729) % 65536) as f64 / 65535.0
        } else {
            0.1 + 0.7 * ramp(f64::from(x), f64::from(y), 5.0, width, (120.0, 50.0))
        };
        image::Luma([(v * 65535.0).round() as u16])
    });
    png.save(d.join("edge.png")).unwrap();
    let (ok, out) = sfr(&["--in", "edge.png", "--roi", "80,0,80,100"], d);
    assert!(ok, "{out}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let mtf50 = v["mtf50_cycles_per_pixel"].as_f64().unwrap();
    assert!(
        (mtf50 / analytic - 1.0).abs() < 0.03,
        "{mtf50} vs {analytic}"
    );
    assert_eq!(v["orientation"], "vertical");
    assert!(v["sfr"].as_array().unwrap().len() > 10);

    // a falling horizontal edge in an RGB 16-bit TIFF, the whole image
    let tiff = image::ImageBuffer::<image::Rgb<u16>, _>::from_fn(90, 70, |x, y| {
        let v = 0.8 - 0.6 * ramp(f64::from(y), f64::from(x), -6.0, width, (35.0, 45.0));
        let c = (v * 65535.0).round() as u16;
        image::Rgb([c, c, c])
    });
    tiff.save(d.join("edge.tiff")).unwrap();
    let (ok, out) = sfr(&["--in", "edge.tiff", "--out", "sfr.json"], d);
    assert!(ok, "{out}");
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("sfr.json")).unwrap()).unwrap();
    let mtf50 = v["mtf50_cycles_per_pixel"].as_f64().unwrap();
    assert!(
        (mtf50 / analytic - 1.0).abs() < 0.03,
        "{mtf50} vs {analytic}"
    );
    assert_eq!(v["orientation"], "horizontal");
    assert_eq!(v["falling"], true);

    // errors a user can act on
    let (ok, out) = sfr(&["--in", "edge.png", "--roi", "150,0,80,100"], d);
    assert!(!ok && out.contains("not inside"), "{out}");
    let (ok, out) = sfr(&["--in", "edge.png", "--roi", "0,0,60,100"], d);
    assert!(!ok && out.contains("edge"), "{out}");
    let (ok, out) = sfr(&["--in", "missing.png"], d);
    assert!(!ok && out.contains("missing.png"), "{out}");
}
