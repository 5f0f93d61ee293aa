//! Unit tests of [`super`].

use super::*;
use crate::spectral::Extrapolation;

fn config_path(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config/sensors")
        .join(name)
}

#[test]
fn paper_default_is_valid_and_matches_figure_2() {
    let d = SensorDesign::paper_default();
    d.validate().unwrap();
    assert_eq!(d.cfa.to_string(), "RG/WB");
    assert_eq!((d.rows, d.cols), (204, 240));
    assert!((d.conversion_gain_v() - 200e-6).abs() < 1e-18);
    // Full well in volts equals the swing for the paper's sensor.
    assert!((d.well_capacity_e * d.conversion_gain_v() - d.voltage_swing_v).abs() < 1e-12);
    let curves = d.resolve_curves(&WavelengthGrid::default(), None).unwrap();
    assert_eq!(curves.len(), 4);
    // W (index 2) is the largest at every band.
    for b in 0..31 {
        for c in [0, 1, 3] {
            assert!(curves[2].values()[b] >= curves[c].values()[b]);
        }
    }
}

#[test]
fn toml_round_trip() {
    let d = SensorDesign::paper_default();
    let text = d.to_toml_string().unwrap();
    let back = SensorDesign::from_toml_str(&text).unwrap();
    assert_eq!(back, d);
    let mut csv = d.clone();
    csv.adc_bits = Some(10);
    csv.filters.insert(
        "W".into(),
        FilterSpec::Csv {
            path: "/abs/w.csv".into(),
            column: "w".into(),
            scale: 0.5,
        },
    );
    let back = SensorDesign::from_toml_str(&csv.to_toml_string().unwrap()).unwrap();
    assert_eq!(back, csv);
}

#[test]
fn shipped_paper_config_equals_default() {
    let d = SensorDesign::load(config_path("rgbw-paper.toml"), None).unwrap();
    assert_eq!(d, SensorDesign::paper_default());
}

#[test]
fn shipped_bayer_config_is_rggb() {
    let d = SensorDesign::load(config_path("bayer-paper.toml"), None).unwrap();
    assert_eq!(d.cfa.to_string(), "RG/GB");
    assert_eq!(d.cfa.channel_names, vec!["R", "G", "B"]);
    assert_eq!(d.filters["R"], parametric::RED);
    assert_eq!(d.filters["G"], parametric::GREEN);
    assert_eq!(d.filters["B"], parametric::BLUE);
    assert_eq!(
        d.resolve_curves(&WavelengthGrid::default(), None)
            .unwrap()
            .len(),
        3
    );
}

#[test]
fn ar0132at_config_loads_from_its_csv() {
    let d = SensorDesign::load(config_path("rgbw-ar0132at.toml"), None).unwrap();
    assert_eq!(d.cfa.to_string(), "RG/WB");
    let grid = WavelengthGrid::default();
    let curves = d.resolve_curves(&grid, None).unwrap();
    // Compare with the CSV, band-averaged by hand at 550 nm (band 15):
    // the mean of the 1-nm piecewise-linear curve over 545–555 nm.
    let t = IsetData::built_in()
        .table("sensor/colorfilters/auto/ar0132atRGBW.csv")
        .unwrap();
    let g = t.samples("gAR0132").unwrap();
    let manual = g.integrate(545.0, 555.0, Extrapolation::Zero) / 10.0;
    let gi = d.cfa.channel_index("G").unwrap();
    assert!((curves[gi].values()[15] - manual).abs() < 1e-12);
    assert!(manual > 0.9, "G peaks near 550 nm: {manual}");
    // A path that is in neither the ISET directory nor the built-in data
    // says where it looked.
    let mut missing = d.clone();
    if let Some(f) = missing.filters.values_mut().next() {
        *f = FilterSpec::Csv {
            path: "sensor/none.csv".into(),
            column: "x".into(),
            scale: 1.0,
        };
    }
    let e = missing.resolve_curves(&grid, None).unwrap_err().to_string();
    assert!(e.contains("ISET") && e.contains("built in"), "{e}");
    // a column that is not in the file: the error names the curve, the file and the columns
    let mut no_column = d.clone();
    if let Some(f) = no_column.filters.get_mut("G") {
        *f = FilterSpec::Csv {
            path: "sensor/colorfilters/auto/ar0132atRGBW.csv".into(),
            column: "bleu".into(),
            scale: 1.0,
        };
    }
    let e = no_column
        .resolve_curves(&grid, None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("filter 'G'") && e.contains("bleu") && e.contains("gAR0132"),
        "{e}"
    );
}

#[test]
fn validation_errors_are_clear() {
    let check = |edit: &dyn Fn(&mut SensorDesign), needle: &str| {
        let mut d = SensorDesign::paper_default();
        edit(&mut d);
        let e = d.validate().unwrap_err().to_string();
        assert!(e.contains(needle), "expected '{needle}' in: {e}");
    };
    check(&|d| d.fill_factor = 1.5, "fill_factor = 1.5");
    check(&|d| d.fill_factor = 0.0, "fill_factor");
    check(&|d| d.pixel_size_um = f64::NAN, "pixel_size_um");
    check(&|d| d.voltage_swing_v = -1.0, "voltage_swing_v");
    check(&|d| d.read_noise_mv = f64::INFINITY, "read_noise_mv");
    check(&|d| d.prnu_percent = -0.1, "prnu_percent");
    check(&|d| d.optics.f_number = 0.0, "f_number");
    check(&|d| d.adc_bits = Some(40), "adc_bits");
    check(&|d| d.offset_v = 2.0, "offset_v");

    check(&|d| d.rows = 0, "size");
    check(&|d| d.name = String::new(), "name is empty");
    check(
        &|d| d.cfa = Cfa::parse("RG/YB").unwrap(),
        "'Y' has no entry",
    );
    check(&|d| d.cfa = Cfa::parse("RG/GB").unwrap(), "'W' is not used");
    check(
        &|d| {
            d.filters.insert(
                "R".into(),
                FilterSpec::Gaussian {
                    center_nm: 600.0,
                    sigma_nm: 0.0,
                    peak: 1.0,
                },
            );
        },
        "filter 'R': sigma_nm",
    );
    check(&|d| d.qe = FilterSpec::Constant(1.2), "qe: constant = 1.2");
    check(&|d| d.cfa.pattern = vec![0, 1, 2, 7], "out of range");
}

#[test]
fn toml_errors_are_clear() {
    let e = |t: &str| SensorDesign::from_toml_str(t).unwrap_err().to_string();
    assert!(e("fill_factr = 0.4").contains("fill_factr"));
    assert!(e("cfa = \"RG/W\"").contains("rectangular"));
    assert!(e("fill_factor = \"a\"").contains("fill_factor"));
    let both = "[qe]\nconstant = 1.0\ngaussian = { center_nm = 500.0, sigma_nm = 10.0 }";
    assert!(e(both).contains("exactly one"));
    assert!(e("[qe]\ncsv = \"x.csv\"").contains("column"));
    assert!(e("[qe]\nconstant = 1.0\ncolumn = \"x\"").contains("only goes with `csv`"));
    assert!(e("[qe]\nconstant = 1.0\nscale = 2.0").contains("only goes with `csv` or `samples`"));
    // Omitted fields take the paper defaults.
    let d = SensorDesign::from_toml_str("name = \"x\"\nread_noise_mv = 2.0").unwrap();
    assert_eq!(d.read_noise_mv, 2.0);
    assert_eq!(d.well_capacity_e, 9000.0);
}

#[test]
fn csv_values_out_of_range_are_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("qe.csv");
    std::fs::write(&p, "wavelength_nm,qe\n380,40\n780,60\n").unwrap();
    let spec = FilterSpec::Csv {
        path: p.display().to_string(),
        column: "qe".into(),
        scale: 1.0,
    };
    let g = WavelengthGrid::default();
    let e = spec.resolve(&g, None, "qe").unwrap_err().to_string();
    assert!(e.contains("outside [0, 1]"), "{e}");
    let pct = FilterSpec::Csv {
        path: p.display().to_string(),
        column: "qe".into(),
        scale: 0.01,
    };
    let s = pct.resolve(&g, None, "qe").unwrap();
    assert!((s.values()[10] - (0.4 + 0.2 * (500.0 - 380.0) / 400.0)).abs() < 1e-12);
}

/// Mean CIELAB ΔE76 of the best linear map from channel responses to XYZ
/// over the 99 CES reflectances under `illuminant` (noise-free, the
/// sensor's colorimetric floor).
fn linear_floor(curves: &[Spectrum], illuminant: &str) -> f64 {
    use crate::spectral::{ces_reflectances, cie_illuminant, cie1931_cmfs};
    use nalgebra::DMatrix;
    let grid = *curves[0].grid();
    let ill = cie_illuminant(illuminant)
        .unwrap()
        .resample(&grid, Extrapolation::Zero);
    let cmfs = cie1931_cmfs().map(|c| c.resample(&grid, Extrapolation::Zero));
    let quanta = Spectrum::from_fn(grid, |l| l);
    let refl = ces_reflectances();
    let (n, c) = (refl.len(), curves.len());
    let mut a = DMatrix::<f64>::zeros(n, c);
    let mut y = DMatrix::<f64>::zeros(n, 3);
    let white: Vec<f64> = (0..3)
        .map(|k| cmfs[k].integral_of_product(&ill).unwrap())
        .collect();
    for (i, (_, r)) in refl.iter().enumerate() {
        let e = r
            .resample(&grid, Extrapolation::Hold)
            .product(&ill)
            .unwrap();
        for j in 0..c {
            let q = curves[j].product(&quanta).unwrap();
            a[(i, j)] = q.integral_of_product(&e).unwrap();
        }
        for k in 0..3 {
            y[(i, k)] = cmfs[k].integral_of_product(&e).unwrap() / white[k];
        }
    }
    let m = (a.transpose() * &a).try_inverse().unwrap() * a.transpose() * &y;
    let p = &a * m;
    let f = |t: f64| {
        if t > 216.0 / 24389.0 {
            t.cbrt()
        } else {
            (24389.0 / 27.0 * t + 16.0) / 116.0
        }
    };
    let lab = |x: f64, yy: f64, z: f64| {
        let (fx, fy, fz) = (f(x), f(yy), f(z));
        [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
    };
    (0..n)
        .map(|i| {
            let t = lab(y[(i, 0)], y[(i, 1)], y[(i, 2)]);
            let e = lab(p[(i, 0)], p[(i, 1)], p[(i, 2)]);
            (0..3).map(|k| (t[k] - e[k]).powi(2)).sum::<f64>().sqrt()
        })
        .sum::<f64>()
        / n as f64
}

#[test]
fn parametric_filters_are_near_colorimetric() {
    let g = WavelengthGrid::default();
    let rgbw = SensorDesign::paper_default()
        .resolve_curves(&g, None)
        .unwrap();
    let bayer = SensorDesign::load(config_path("bayer-paper.toml"), None)
        .unwrap()
        .resolve_curves(&g, None)
        .unwrap();
    for ill in ["D65", "A"] {
        let (f4, f3) = (linear_floor(&rgbw, ill), linear_floor(&bayer, ill));
        println!("linear floor under {ill}: RGBW {f4:.3}, RGB {f3:.3} mean ΔE76 (CES)");
        assert!(f4 < 0.8 && f3 < 0.9, "{ill}: {f4} {f3}");
    }
    let ar = SensorDesign::load(config_path("rgbw-ar0132at.toml"), None)
        .unwrap()
        .resolve_curves(&g, None)
        .unwrap();
    let fa = linear_floor(&ar, "A");
    println!("linear floor under A: AR0132AT RGBW {fa:.3}");
    assert!(fa > linear_floor(&rgbw, "A"));
}

#[test]
fn a_design_must_name_itself_and_give_filters_with_its_own_cfa() {
    let e = |t: &str| SensorDesign::from_toml_str(t).unwrap_err().to_string();
    assert!(e("read_noise_mv = 2.0").contains("`name` is missing"));
    let cfa_only = e("name = \"b\"\ncfa = \"RG/GB\"");
    assert!(
        cfa_only.contains("a file giving its own cfa must give the matching filters"),
        "{cfa_only}"
    );
    // the paper's own CFA needs no filters of its own
    assert!(SensorDesign::from_toml_str("name = \"p\"\ncfa = \"RG/WB\"").is_ok());
    // a training job's design object, checked the same way
    let j = |v: serde_json::Value| SensorDesign::from_json(v).map(|d| d.name);
    assert_eq!(
        j(serde_json::json!({"name": "noisy", "read_noise_mv": 2.68})).unwrap(),
        "noisy"
    );
    let e = j(serde_json::json!({"read_noise_mv": 2.68})).unwrap_err();
    assert!(e.to_string().contains("`name` is missing"), "{e}");
    let e = j(serde_json::json!({"name": "n", "fill_factr": 0.4})).unwrap_err();
    assert!(matches!(e, CameraError::Json(_)), "{e}");
}

/// A table records its design's curves: a CSV of the user's (an absolute path once loaded)
/// as its samples, a table of the built-in data by its name; either way the recorded design
/// resolves to the curves it was trained on, and keeps doing so when the file goes.
#[test]
fn a_portable_design_needs_only_the_built_in_data() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("mine.csv");
    let rows: String = (380..=780)
        .step_by(5)
        .map(|nm| {
            let x = (nm as f64 - 560.0) / 60.0;
            format!("{nm},{:.6}\n", (-0.5 * x * x).exp())
        })
        .collect();
    std::fs::write(&csv, format!("wavelength,G\n{rows}")).unwrap();
    let toml = dir.path().join("mine.toml");
    std::fs::write(
        &toml,
        "name = \"mine\"\ncfa = \"RG/WB\"\n[filters]\n\
         R = { csv = \"sensor/colorfilters/RGBW.csv\", column = \"rDefault\" }\n\
         G = { csv = \"mine.csv\", column = \"G\" }\n\
         B = { gaussian = { center_nm = 445.0, sigma_nm = 30.0, peak = 1.0 } }\n\
         W = { constant = 1.0 }\n",
    )
    .unwrap();
    let d = SensorDesign::load(&toml, None).unwrap();
    let grid = WavelengthGrid::default();
    let want = d.resolve_curves(&grid, None).unwrap();
    let p = d.clone().portable(None);
    assert!(matches!(p.filters["G"], FilterSpec::Samples { .. }));
    assert_eq!(
        p.filters["R"], d.filters["R"],
        "a built-in table keeps its name"
    );
    assert_eq!(p.filters["B"], d.filters["B"]);
    drop(dir);
    let back: SensorDesign = serde_json::from_value(serde_json::to_value(&p).unwrap()).unwrap();
    back.validate().unwrap();
    let got = back.resolve_curves(&grid, None).unwrap();
    for (a, b) in want.iter().zip(&got) {
        assert_eq!(a.values(), b.values());
    }
    // a design of the built-in data alone is recorded as it is
    let shipped = SensorDesign::load(config_path("rgbw-ar0132at.toml"), None).unwrap();
    assert_eq!(shipped.clone().portable(None), shipped);
}

#[test]
fn inlined_curves_resolve_as_their_csv_and_survive_json() {
    let d = SensorDesign::load(config_path("rgbw-ar0132at.toml"), None).unwrap();
    let grid = WavelengthGrid::default();
    let from_csv = d.resolve_curves(&grid, None).unwrap();
    let inline = d.clone().inlined(None).unwrap();
    assert!(
        inline
            .filters
            .values()
            .chain([&inline.ir_cut, &inline.qe])
            .all(|f| !matches!(f, FilterSpec::Csv { .. })),
        "no curve reads a file"
    );
    // through JSON, as a design object reaches the service
    let back: SensorDesign =
        serde_json::from_value(serde_json::to_value(&inline).unwrap()).unwrap();
    assert_eq!(back, inline);
    let curves = back.resolve_curves(&grid, None).unwrap();
    for (a, b) in from_csv.iter().zip(&curves) {
        assert_eq!(a.values(), b.values());
    }
    // bad samples name the curve and the fault
    let mut bad = inline.clone();
    if let Some(f) = bad.filters.values_mut().next() {
        *f = FilterSpec::Samples {
            wavelength_nm: vec![500.0, 400.0],
            values: vec![0.5, 0.5],
            scale: 1.0,
        };
    }
    let e = bad.validate().unwrap_err().to_string();
    assert!(e.contains("filter") && e.contains("increasing"), "{e}");
    let t = toml::from_str::<SensorDesign>(
        "name = \"x\"\ncfa = \"RG/GB\"\n[filters]\nR = { samples = { wavelength_nm = [400.0, 700.0], values = [0.5, 0.5] }, column = \"r\" }\nG = { constant = 1.0 }\nB = { constant = 1.0 }\n",
    );
    assert!(t.is_err(), "column goes only with csv");
}

/// A measured curve whose samples stop well inside the grid is noted, naming the curve, its
/// source and both ranges; one within [`COVERAGE_SLACK_NM`] of the grid's ends, or beyond
/// them, or a parametric curve, is not.
#[test]
fn a_curve_covering_part_of_the_grid_is_noted() {
    let grid = WavelengthGrid::default();
    let with_r = |from: f64, to: f64| {
        let mut d = SensorDesign::paper_default();
        d.name = "short".into();
        let wavelength_nm: Vec<f64> = (0..=10)
            .map(|i| from + (to - from) * i as f64 / 10.0)
            .collect();
        let values = vec![0.5; wavelength_nm.len()];
        d.filters.insert(
            "R".into(),
            FilterSpec::Samples {
                wavelength_nm,
                values,
                scale: 1.0,
            },
        );
        d.resolve_curves_noted(&grid, None).unwrap().1
    };
    let notes = with_r(500.0, 600.0);
    assert_eq!(notes.len(), 1, "{notes:?}");
    let n = &notes[0];
    assert_eq!(n.curve, "'short': filter 'R'");
    assert_eq!((n.covered_nm, n.grid_nm), ((500.0, 600.0), (400.0, 700.0)));
    let text = n.to_string();
    assert!(
        text.contains("filter 'R'") && text.contains("500–600 nm") && text.contains("400–700 nm"),
        "{text}"
    );
    // one end short is enough
    assert_eq!(with_r(380.0, 650.0).len(), 1);
    assert_eq!(with_r(420.0, 780.0).len(), 1);
    // within the slack, or past the grid: no note
    for (from, to) in [(400.0, 700.0), (410.0, 690.0), (380.0, 780.0)] {
        assert!(with_r(from, to).is_empty(), "{from}–{to}");
    }
    // the paper's parametric curves
    let paper = SensorDesign::paper_default();
    assert!(
        paper
            .resolve_curves_noted(&grid, None)
            .unwrap()
            .1
            .is_empty()
    );
}

/// A CSV column cut short is noted with its file and column, and `load_noted` returns it.
#[test]
fn a_short_csv_is_noted_when_the_design_is_loaded() {
    let dir = tempfile::tempdir().unwrap();
    let mut csv = String::from("wavelength_nm,red,green,blue\n");
    for l in (500..=600).step_by(10) {
        csv.push_str(&format!("{l},0.5,0.5,0.5\n"));
    }
    std::fs::write(dir.path().join("short.csv"), csv).unwrap();
    let toml = "name = \"cut\"\ncfa = \"RG/GB\"\n[filters]\n\
                R = { csv = \"short.csv\", column = \"red\" }\n\
                G = { gaussian = { center_nm = 540.0, sigma_nm = 40.0 } }\n\
                B = { gaussian = { center_nm = 460.0, sigma_nm = 30.0 } }\n";
    let path = dir.path().join("cut.toml");
    std::fs::write(&path, toml).unwrap();
    let loaded = SensorDesign::load_noted(&path, None).unwrap();
    assert_eq!(loaded.design.name, "cut");
    assert_eq!(loaded.notes.len(), 1, "{:?}", loaded.notes);
    let text = loaded.notes[0].to_string();
    assert!(
        text.contains("'cut': filter 'R'")
            && text.contains("short.csv (column 'red')")
            && text.contains("500–600 nm"),
        "{text}"
    );
}

/// Every catalogue sensor's curves cover the grid: none is noted.
#[test]
fn no_catalogue_sensor_is_noted() {
    let grid = WavelengthGrid::default();
    for e in crate::camera::catalogue::catalogue() {
        let d = e.design().unwrap();
        let notes = d.resolve_curves_noted(&grid, None).unwrap().1;
        assert!(notes.is_empty(), "{}: {notes:?}", d.name);
    }
}

/// What a file must say for itself: the CFA its filters fit, a Bayer tile as rows, its own
/// description.
#[test]
fn a_file_states_its_cfa_and_description() {
    let rgb = "[filters]\nR = { constant = 0.5 }\nG = { constant = 0.6 }\nB = { constant = 0.4 }\n";
    let e = SensorDesign::from_toml_str(&format!("name = \"s\"\n{rgb}")).unwrap_err();
    assert!(
        e.to_string().contains("without a cfa") && e.to_string().contains("RG/WB"),
        "{e}"
    );
    let e =
        SensorDesign::from_toml_str(&format!("name = \"s\"\ncfa = \"RGGB\"\n{rgb}")).unwrap_err();
    assert!(e.to_string().contains("\"RG/GB\""), "{e}");
    let d = SensorDesign::from_toml_str(&format!("name = \"s\"\ncfa = \"RG/GB\"\n{rgb}")).unwrap();
    assert_eq!(d.description, "");
    let d = SensorDesign::from_toml_str(&format!(
        "name = \"s\"\ndescription = \"mine\"\ncfa = \"RG/GB\"\n{rgb}"
    ))
    .unwrap();
    assert_eq!(d.description, "mine");
    let j = SensorDesign::from_json(serde_json::json!({"name": "s"})).unwrap();
    assert_eq!(j.description, "");
    // a name that would be a path, an offset that leaves the signal too little room (auto-
    // exposure aims at 95 % of the swing): refused in a design described now, as a file or
    // as JSON, while a table's stored design keeps passing `validate`
    for (toml, needle) in [
        ("name = \"../escaped\"", "identifier"),
        ("name = \"a b\"", "identifier"),
        ("name = \"s\"\noffset_v = 1.71", "half the swing"),
        // a well that fills below the swing (6000 e⁻ × 200 µV = 1.2 V), or an analog gain
        // that keeps the full well below it, would clip unseen
        (
            "name = \"s\"\nwell_capacity_e = 6000.0",
            "fills at 1.2000 V (× 200 µV/e⁻ × analog_gain 1), below voltage_swing_v = 1.8 V",
        ),
        (
            "name = \"s\"\nanalog_gain = 0.5",
            "set voltage_swing_v = 0.9000",
        ),
        (
            "name = \"s\"\nwell_capacity_e = 6000.0",
            "well_capacity_e ≥ 9000",
        ),
    ] {
        let e = SensorDesign::from_toml_str(toml).unwrap_err();
        assert!(e.to_string().contains(needle), "{toml}: {e}");
    }
    let e = SensorDesign::from_json(serde_json::json!({"name": "../x"})).unwrap_err();
    assert!(e.to_string().contains("identifier"), "{e}");
    let mut stored = SensorDesign::paper_default();
    stored.name = "My Sensor".into();
    stored.offset_v = 1.0;
    stored.validate().unwrap();
    // a well that fills at the swing or above it is the pixel's own business
    for toml in [
        "name = \"s\"\nwell_capacity_e = 20000.0",
        "name = \"s\"\nanalog_gain = 2.0",
    ] {
        SensorDesign::from_toml_str(toml).unwrap();
    }
}

/// Small negatives in a measured curve's tails are noise, taken as zero; larger ones are
/// refused, naming the samples' source.
#[test]
fn negative_noise_in_a_curve_is_zero() {
    let grid = WavelengthGrid::default();
    let curve = |tail: f64| FilterSpec::Samples {
        wavelength_nm: vec![390.0, 550.0, 690.0, 710.0],
        values: vec![0.2, 0.8, tail, tail],
        scale: 1.0,
    };
    let (s, _) = curve(-0.004).resolve_noted(&grid, None, "f").unwrap();
    assert!(s.values().iter().all(|&v| v >= 0.0));
    assert_eq!(s.values()[30], 0.0);
    let e = curve(-0.1).resolve_noted(&grid, None, "f").unwrap_err();
    assert!(e.to_string().contains("negative"), "{e}");
}

/// A finely sampled file inlines to the samples the grid reaches (within the service's
/// limit) and resolves as the file does.
#[test]
fn a_fine_csv_inlines_within_the_limit() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let csv = dir.join("fine.csv");
    let mut text = String::from("wavelength_nm,R,G,B\n");
    for i in 0..=8000 {
        let w = 300.0 + f64::from(i) * 0.1;
        let g = |c: f64| (-0.5 * ((w - c) / 40.0).powi(2)).exp();
        text.push_str(&format!("{w:.1},{},{},{}\n", g(600.0), g(540.0), g(450.0)));
    }
    std::fs::write(&csv, text).unwrap();
    let toml = "name = \"fine\"\ncfa = \"RG/GB\"\n[filters]\n\
                R = { csv = \"fine.csv\", column = \"R\" }\n\
                G = { csv = \"fine.csv\", column = \"G\" }\n\
                B = { csv = \"fine.csv\", column = \"B\" }\n";
    let path = dir.join("fine.toml");
    std::fs::write(&path, toml).unwrap();
    let d = SensorDesign::load(&path, None).unwrap();
    let inline = d.clone().inlined(None).unwrap();
    let grid = WavelengthGrid::default();
    for f in inline.filters.values() {
        let FilterSpec::Samples { wavelength_nm, .. } = f else {
            panic!("not inlined: {f:?}");
        };
        assert!(wavelength_nm.len() <= filter::MAX_INLINE_SAMPLES);
    }
    inline.validate().unwrap();
    let (a, b) = (
        d.resolve_curves(&grid, None).unwrap(),
        inline.resolve_curves(&grid, None).unwrap(),
    );
    for (a, b) in a.iter().zip(&b) {
        for (x, y) in a.values().iter().zip(b.values()) {
            assert!((x - y).abs() < 1e-12, "{x} {y}");
        }
    }
}
