//! `l3 sensors` and `l3 render --data-dir`: the table trained for a DNG's camera, the one
//! `--table-id` names, else the active one, chosen as the service chooses.

use std::path::Path;

use crate::cli::with_service;
use crate::support::{l3, l3_code};

/// `l3 simulate` through the catalogue sensor `sensor` into `out`, and its DNG written again
/// (the crate's writer) naming the camera `unique_model`; returns that DNG's path.
fn camera_dng(d: &Path, sensor: &str, unique_model: &str) -> std::path::PathBuf {
    let sim = d.join("sim");
    let args = [
        "simulate", "--sensor", sensor, "--scene", "macbeth", "--out",
    ];
    let (ok, out, err) = l3(&[&args[..], &[sim.to_str().unwrap()]].concat(), d);
    assert!(ok, "simulate failed: {out}{err}");
    let lim = l3::io::Limits::default();
    let loaded = l3::io::read_mosaic(&sim.join("mosaic.dng"), &lim).unwrap();
    let l3::io::DecodedMosaic::U16(frame) = loaded.mosaic else {
        panic!("a float DNG");
    };
    let info = l3::io::DngWriteInfo {
        camera_model: Some(unique_model.into()),
        ..Default::default()
    };
    let path = d.join("camera.dng");
    l3::io::write_dng(&path, &frame, &loaded.meta.unwrap(), &info).unwrap();
    path
}

#[test]
fn render_chooses_the_table_of_the_dngs_camera_and_sensors_lists_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let dng = camera_dng(d, "bayer-sony-ilce-9", "Sony ILCE-9");
    let data = d.join("data");
    let run = |extra: &[&str], out: &str| {
        let base = ["render", "--data-dir", data.to_str().unwrap()];
        let io = ["--in", dng.to_str().unwrap(), "--out", out];
        l3_code(&[&base[..], extra, &io[..]].concat(), d)
    };
    let render = |extra: &[&str], out: &str| {
        let (code, out, err) = run(extra, out);
        (code == Some(0), out, err)
    };
    // no table for the camera's sensor: an error (exit code 1, a missing table) naming it
    // and how to train one
    let (code, out, err) = run(&[], "none.png");
    assert_eq!(code, Some(1), "{out}{err}");
    assert!(
        err.contains("bayer-sony-ilce-9") && err.contains("l3 train --sensor bayer-sony-ilce-9"),
        "{err}"
    );
    // a table trained for the sensor, stored (not active) beside an active one
    let (ok, out, err) = l3(
        &[
            "train",
            "--sensor",
            "bayer-sony-ilce-9",
            "--illuminants",
            "D65",
            "--scenes",
            "4",
            "--scene-size",
            "48",
            "--levels",
            "10",
            "--out",
            "sony.safetensors",
        ],
        d,
    );
    assert!(ok, "train failed: {out}{err}");
    let sony = l3::l3::L3Table::load(&d.join("sony.safetensors")).unwrap();
    let (active_id, sony_id) = with_service(&data, |state| async move {
        let a = l3::service::import_table(&state, l3::test_support::tiny_table(), true)
            .await
            .unwrap();
        let s = l3::service::import_table(&state, &sony, false)
            .await
            .unwrap();
        (a, s)
    });
    let (ok, out, err) = render(&[], "camera.png");
    assert!(ok, "{out}{err}");
    assert!(
        err.contains(&format!("table: {sony_id}")) && err.contains("trained for bayer-sony-ilce-9"),
        "{err}"
    );
    let (ok, out, err) = render(&["--table-id", &sony_id], "named.png");
    assert!(ok, "{out}{err}");
    assert!(
        err.contains(&format!("table: {sony_id} (--table-id")),
        "{err}"
    );
    assert_eq!(
        std::fs::read(d.join("camera.png")).unwrap(),
        std::fs::read(d.join("named.png")).unwrap()
    );
    // the active table named: its CFA refuses the Bayer frame; an unknown id fails
    let (ok, _, err) = render(&["--table-id", &active_id], "active.png");
    assert!(!ok && err.contains("CFA"), "{err}");
    let (ok, _, err) = render(&["--table-id", "tbl_0000000000000000"], "x.png");
    assert!(
        !ok && err.contains("no table with id 'tbl_0000000000000000'"),
        "{err}"
    );

    // l3 sensors: the catalogue, the Sony sensor trained with its table
    let (ok, out, err) = l3(
        &["sensors", "--data-dir", data.to_str().unwrap(), "--json"],
        d,
    );
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let items = v["items"].as_array().unwrap();
    assert_eq!(items.len(), 55);
    let s = items
        .iter()
        .find(|s| s["name"] == "bayer-sony-ilce-9")
        .unwrap();
    assert_eq!((&s["trained"], &s["cfa"]), (&true.into(), &"RG/GB".into()));
    assert_eq!(s["table_id"], sony_id.as_str());
    assert_eq!(items.iter().filter(|s| s["trained"] == true).count(), 1);
    let (ok, out, _) = l3(&["sensors", "--data-dir", data.to_str().unwrap()], d);
    assert!(ok);
    let line = out
        .lines()
        .find(|l| l.starts_with("bayer-sony-ilce-9 "))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(line.contains("RG/GB") && line.contains(&sony_id), "{line}");
    assert!(out.contains("55 sensors, 1 with a table"), "{out}");
}
