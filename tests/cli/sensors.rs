//! Sensors named as users name them: a catalogue camera by name, and a design TOML whose CSV
//! curves sit beside it, trained from another working directory.

use std::path::Path;

use crate::support::run_l3 as l3;

const TINY: [&str; 8] = [
    "--illuminants",
    "D65",
    "--scenes",
    "3",
    "--scene-size",
    "32",
    "--levels",
    "4",
];

fn train(sensor: &str, out: &Path, cwd: &Path) -> (bool, String) {
    let mut args = vec!["train", "--sensor", sensor];
    args.extend_from_slice(&TINY);
    args.extend_from_slice(&["--out", out.to_str().unwrap()]);
    l3(&args, cwd)
}

/// A design with Gaussian-free measured curves in `my_camera.csv` beside it.
fn write_design(dir: &Path, csv_name: &str) {
    std::fs::create_dir_all(dir).unwrap();
    let mut csv = String::from("wavelength_nm,R,G,B\n");
    for nm in (380..=780).step_by(5) {
        let g = |c: f64, s: f64| (-0.5 * ((f64::from(nm) - c) / s).powi(2)).exp();
        csv += &format!(
            "{nm},{:.6},{:.6},{:.6}\n",
            g(600.0, 40.0),
            g(540.0, 40.0),
            g(450.0, 30.0)
        );
    }
    std::fs::write(dir.join("my_camera.csv"), csv).unwrap();
    let toml = format!(
        "name = \"my-camera\"\ncfa = \"RG/GB\"\n\n[filters]\n\
         R = {{ csv = \"{csv_name}\", column = \"R\" }}\n\
         G = {{ csv = \"{csv_name}\", column = \"G\" }}\n\
         B = {{ csv = \"{csv_name}\", column = \"B\" }}\n\n\
         [ir_cut]\nconstant = 1.0\n\n[qe]\nconstant = 1.0\n"
    );
    std::fs::write(dir.join("my_camera.toml"), toml).unwrap();
}

#[test]
fn a_toml_beside_its_csv_trains_from_any_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let cam = tmp.path().join("cams/mine");
    let elsewhere = tmp.path().join("work");
    std::fs::create_dir_all(&elsewhere).unwrap();
    write_design(&cam, "my_camera.csv");
    let out = tmp.path().join("t.safetensors");
    // by absolute path, and by a path relative to another working directory
    let abs = cam.join("my_camera.toml");
    let (ok, text) = train(abs.to_str().unwrap(), &out, &elsewhere);
    assert!(ok, "{text}");
    let (ok, text) = train("../cams/mine/my_camera.toml", &out, &elsewhere);
    assert!(ok, "{text}");
    let t = l3::l3::L3Table::load(&out).unwrap();
    assert_eq!(t.meta.sensor_name, "my-camera");

    // a CSV that is nowhere: the error names every place looked in
    write_design(&cam, "missing.csv");
    let (ok, text) = train(abs.to_str().unwrap(), &out, &elsewhere);
    assert!(!ok);
    for place in [
        "missing.csv",
        "beside the sensor TOML",
        "ISET data directory",
        "built in",
    ] {
        assert!(text.contains(place), "{place} in: {text}");
    }
    assert!(text.contains(cam.to_str().unwrap()), "{text}");
}

#[test]
fn a_catalogue_camera_trains_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sony.safetensors");
    let (ok, text) = train("bayer-sony-ilce-9", &out, tmp.path());
    assert!(ok, "{text}");
    let t = l3::l3::L3Table::load(&out).unwrap();
    assert_eq!(t.meta.sensor_name, "bayer-sony-ilce-9");
    let (ok, text) = train("bayer-sony-ilce-99", &out, tmp.path());
    assert!(!ok);
    assert!(
        text.contains("neither a TOML file nor a catalogue sensor"),
        "{text}"
    );
}

#[test]
fn a_design_file_must_name_itself_and_give_filters_with_its_cfa() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_design(d, "my_camera.csv");
    let named = std::fs::read_to_string(d.join("my_camera.toml")).unwrap();
    std::fs::write(
        d.join("noname.toml"),
        named.replace("name = \"my-camera\"\n", ""),
    )
    .unwrap();
    let (ok, text) = l3(&["simulate", "--sensor", "noname.toml", "--out", "x"], d);
    assert!(!ok, "{text}");
    assert!(
        text.contains("noname.toml") && text.contains("`name` is missing"),
        "{text}"
    );
    std::fs::write(d.join("cfaonly.toml"), "name = \"c\"\ncfa = \"RG/GB\"\n").unwrap();
    let (ok, text) = l3(&["simulate", "--sensor", "cfaonly.toml", "--out", "x"], d);
    assert!(!ok, "{text}");
    assert!(
        text.contains("cfaonly.toml")
            && text.contains("a file giving its own cfa must give the matching filters"),
        "{text}"
    );
}

/// `l3 sensors --design` prints a design that reads no file: its CSV curves as samples, the
/// same design the TOML describes.
#[test]
fn a_design_prints_with_its_curves_inline() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_design(d, "my_camera.csv");
    let (ok, text) = l3(&["sensors", "--design", "my_camera.toml"], d);
    assert!(ok, "{text}");
    let inline: l3::camera::SensorDesign = serde_json::from_str(&text).unwrap();
    assert_eq!(inline.name, "my-camera");
    let r = serde_json::to_value(&inline).unwrap()["filters"]["R"].clone();
    let nm = r["samples"]["wavelength_nm"].as_array().unwrap();
    // the file's 380–780 nm at 5 nm, cut to what the 400–700 nm grid reaches (390–710 nm)
    // and one sample beyond either end
    let ends = (nm[0].as_f64(), nm[nm.len() - 1].as_f64());
    assert_eq!((nm.len(), ends), (67, (Some(385.0), Some(715.0))), "{r}");
    let from_file = l3::camera::SensorDesign::load(d.join("my_camera.toml"), None).unwrap();
    let grid = l3::spectral::WavelengthGrid::default();
    let (a, b) = (
        from_file.resolve_curves(&grid, None).unwrap(),
        inline.resolve_curves(&grid, None).unwrap(),
    );
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.values(), y.values());
    }
    let (ok, text) = l3(&["sensors", "--design", "missing.toml"], d);
    assert!(!ok && text.contains("missing.toml"), "{text}");
}

/// Curves from a CSV that covers only part of the simulation grid are taken (zero outside
/// their range) with a warning per curve naming the sensor file, the curve, the CSV and both
/// ranges; curves covering the grid get none.
#[test]
fn a_csv_covering_part_of_the_grid_is_warned_of() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_design(d, "my_camera.csv");
    let simulate = |toml: &str, out: &str| {
        crate::support::l3(
            &[
                "simulate", "--sensor", toml, "--scene", "uniform", "--out", out,
            ],
            d,
        )
    };
    let (ok, _, err) = simulate("my_camera.toml", "full");
    assert!(ok, "{err}");
    assert!(!err.contains("warning:"), "{err}");
    // the same curves from 500 to 600 nm only
    let full = std::fs::read_to_string(d.join("my_camera.csv")).unwrap();
    let short: Vec<&str> = full
        .lines()
        .filter(|l| {
            let nm = l.split(',').next().and_then(|w| w.parse::<u32>().ok());
            nm.is_none_or(|nm| (500..=600).contains(&nm))
        })
        .collect();
    std::fs::write(d.join("short.csv"), short.join("\n")).unwrap();
    let toml = std::fs::read_to_string(d.join("my_camera.toml")).unwrap();
    std::fs::write(
        d.join("short.toml"),
        toml.replace("my_camera.csv", "short.csv"),
    )
    .unwrap();
    let (ok, _, err) = simulate("short.toml", "short");
    assert!(ok, "{err}");
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning:")).collect();
    assert_eq!(warnings.len(), 3, "{err}");
    let r = warnings
        .iter()
        .find(|l| l.contains("filter 'R'"))
        .unwrap_or(&"");
    for part in [
        "warning: short.toml:",
        "short.csv (column 'R')",
        "500–600 nm",
        "400–700 nm",
    ] {
        assert!(r.contains(part), "{part} in: {err}");
    }
}
