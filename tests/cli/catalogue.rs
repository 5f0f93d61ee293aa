//! `l3 eval --catalogue` end to end on two sensors at the smallest training size: the JSON
//! rows are finite and consistent, the markdown has a row per sensor (sorted by name) and the
//! summary line; an unknown sensor and a clashing mode are refused before any training.

/// `l3 args` in the working directory.
fn l3(args: &[&str]) -> (bool, String, String) {
    crate::support::l3(args, std::path::Path::new("."))
}

#[test]
fn catalogue_sweep_on_two_sensors() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cat");
    let (ok, stdout, err) = l3(&[
        "eval",
        "--catalogue",
        "--sensor",
        "bayer-paper,bayer-arri-d21",
        "--scenes",
        "2",
        "--scene-size",
        "48",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "eval --catalogue failed: {stdout}{err}");
    assert!(err.contains("[2/2]"), "no progress: {err}");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("catalogue.json")).unwrap()).unwrap();
    assert_eq!(json["options"]["scenes"], 2);
    let rows = json["rows"].as_array().unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["sensor"].as_str().unwrap()).collect();
    assert_eq!(names, ["bayer-arri-d21", "bayer-paper"]);
    for r in rows {
        assert_eq!(r["cfa"], "RG/GB");
        let f = |k: &str| {
            r[k].as_f64()
                .unwrap_or_else(|| panic!("{k} missing in {r}"))
        };
        for k in ["l3_mean", "l3_p90", "linear_mean", "max_kernel_norm"] {
            assert!(f(k).is_finite() && f(k) > 0.0, "{k} in {r}");
        }
        assert!(f("training_seconds") >= 0.0, "{r}");
        assert!((f("delta") - (f("l3_mean") - f("linear_mean"))).abs() < 1e-12);
    }
    let md = std::fs::read_to_string(out.join("catalogue.md")).unwrap();
    assert_eq!(
        md,
        stdout.split("wrote ").next().unwrap().trim_end().to_owned() + "\n"
    );
    let d21 = md
        .find("| bayer-arri-d21 | `RG/GB` |")
        .expect("row bayer-arri-d21");
    let paper = md
        .find("| bayer-paper | `RG/GB` |")
        .expect("row bayer-paper");
    assert!(d21 < paper, "{md}");
    assert!(
        md.contains("of 2 sensors within 0.2 of their linear map"),
        "{md}"
    );

    // refused before training: a sensor that does not exist, a second mode
    let (ok, _, err) = l3(&["eval", "--catalogue", "--sensor", "bayer-nosuch-cam"]);
    assert!(!ok && err.contains("bayer-nosuch-cam"), "{err}");
    let (ok, _, err) = l3(&["eval", "--catalogue", "--paper-table"]);
    assert!(!ok && err.contains("--paper-table"), "{err}");
}
