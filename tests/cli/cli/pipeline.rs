//! `l3` end to end: simulate → train → render → eval in one run, and bad arguments.

use std::path::Path;

use crate::support::{l3, train_small_si};

use super::eval::{eval_captured_frames, eval_noise_split, eval_report_and_light_levels};
use super::{simulate_macbeth, with_service};

#[test]
fn simulate_train_render_eval() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let sim = d.join("sim");
    let size = simulate_and_check(d, &sim);

    let table = d.join("t.safetensors");
    let out = train_small_si(d, &table, &[]);
    assert!(out.contains("trained si table"), "{out}");

    render_to_every_format(d, &sim, &table, size);
    render_without_a_table(d, &sim, &table);
    let mean = eval_report_and_light_levels(d, &table);
    eval_noise_split(d, &table, mean);
    eval_captured_frames(d, &table, mean);
}

/// `l3 simulate` of the Macbeth chart into `sim`: its files, its sidecar, the same mosaic as
/// DNG, and the same bytes for the same seed. The mosaic's width and height.
fn simulate_and_check(d: &Path, sim: &Path) -> (u64, u64) {
    simulate_macbeth(d, sim);
    for f in [
        "mosaic.raw",
        "mosaic.json",
        "mosaic.dng",
        "mosaic.png",
        "ideal_xyz.tiff",
        "preview.png",
    ] {
        assert!(sim.join(f).is_file(), "missing {f}");
    }
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(sim.join("mosaic.json")).unwrap()).unwrap();
    assert_eq!(meta["cfa"], "RG/WB");
    assert_eq!(meta["illuminant"], "Tungsten");
    let (w, h) = (
        meta["width"].as_u64().unwrap(),
        meta["height"].as_u64().unwrap(),
    );
    assert_eq!(
        std::fs::metadata(sim.join("mosaic.raw")).unwrap().len(),
        w * h * 2
    );
    // the same mosaic as DNG, with the sidecar's levels and the light's neutral
    let lim = l3::io::Limits::default();
    let dng = l3::io::read_mosaic(&sim.join("mosaic.dng"), &lim).unwrap();
    let raw = l3::io::read_mosaic(&sim.join("mosaic.raw"), &lim).unwrap();
    assert_eq!(dng.mosaic, raw.mosaic);
    let (dm, rm) = (dng.meta.unwrap(), raw.meta.unwrap());
    assert_eq!(
        (dm.cfa, dm.black_level, dm.white_level),
        (rm.cfa, rm.black_level, rm.white_level)
    );
    let info = dng.dng.unwrap();
    assert_eq!(info.plane_colors, "RGBW");
    assert_eq!(info.calibration_illuminants, [Some(3), None]);
    assert!(info.as_shot_neutral.unwrap().contains(&1.0));
    // same seed → same bytes
    let sim2 = d.join("sim2");
    simulate_macbeth(d, &sim2);
    assert_eq!(
        std::fs::read(sim.join("mosaic.raw")).unwrap(),
        std::fs::read(sim2.join("mosaic.raw")).unwrap()
    );
    (w, h)
}

/// `l3 render` of the simulated mosaic with `table` to PNG, TIFF and 16-bit TIFF, from the
/// 16-bit PNG too, with an `xy:` illuminant, a region and a preview, and bad render flags.
fn render_to_every_format(d: &Path, sim: &Path, table: &Path, (w, h): (u64, u64)) {
    for (name, extra) in [
        ("out.png", vec![]),
        ("out.tiff", vec![]),
        ("out16.tiff", vec!["--tiff", "srgb16"]),
    ] {
        let mut args = vec![
            "render",
            "--table",
            table.to_str().unwrap(),
            "--illuminant",
            "Tungsten",
            "--in",
        ];
        let input = sim.join("mosaic.raw");
        args.push(input.to_str().unwrap());
        let o = d.join(name);
        args.extend(["--out", o.to_str().unwrap()]);
        args.extend(extra);
        let (ok, out, err) = l3(&args, d);
        assert!(ok, "render {name} failed: {out}{err}");
        assert!(std::fs::metadata(&o).unwrap().len() > 1000);
    }
    // the rendered PNG decodes at the input's size
    let png = image::open(d.join("out.png")).unwrap();
    assert_eq!((png.width() as u64, png.height() as u64), (w, h));
    // a 16-bit PNG input renders the same as the raw
    let (ok, _, err) = l3(
        &[
            "render",
            "--table",
            table.to_str().unwrap(),
            "--illuminant",
            "Tungsten",
            "--in",
            sim.join("mosaic.png").to_str().unwrap(),
            "--out",
            d.join("from_png.tiff").to_str().unwrap(),
        ],
        d,
    );
    assert!(ok, "{err}");
    assert_eq!(
        std::fs::read(d.join("out.tiff")).unwrap(),
        std::fs::read(d.join("from_png.tiff")).unwrap()
    );

    // an xy: illuminant, a region and a preview
    let render = |extra: &[&str], out: &str| {
        let input = sim.join("mosaic.raw");
        let out = d.join(out);
        let mut args = vec![
            "render",
            "--table",
            table.to_str().unwrap(),
            "--in",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        l3(&args, d)
    };
    let (ok, out, err) = render(&["--illuminant", "xy:0.4476,0.4074"], "xy.png");
    assert!(ok, "xy: render failed: {out}{err}");
    assert!(out.contains("cct:28"), "{out}");
    let (ok, out, err) = render(
        &[
            "--illuminant",
            "Tungsten",
            "--region",
            "8,8,32,16",
            "--preview",
            "2",
        ],
        "crop.png",
    );
    assert!(ok, "region render failed: {out}{err}");
    let crop = image::open(d.join("crop.png")).unwrap();
    assert_eq!((crop.width(), crop.height()), (16, 8));
    let (ok, out, err) = render(&["--region", "8,8,32,16", "--preview", "2"], "crop.raw");
    assert!(ok, "{out}{err}");
    assert_eq!(
        std::fs::metadata(d.join("crop.raw")).unwrap().len(),
        16 * 8 * 3 * 4
    );
    for (extra, says) in [
        (vec!["--region", "0,0,100000,4"], "not inside"),
        (vec!["--region", "1,2,3"], "four numbers"),
        (vec!["--preview", "17"], "from 1 to 16"),
        (vec!["--illuminant", "xy:0.9,0.9"], "spectrum locus"),
    ] {
        let (ok, out, err) = render(&extra, "bad.png");
        assert!(!ok, "{extra:?} succeeded: {out}");
        assert!(err.contains(says), "{extra:?}: {err}");
    }
}

/// `l3 render --data-dir` without `--table`: the data directory's active table, the last good
/// one when its file is damaged, else an error that says what to do.
fn render_without_a_table(d: &Path, sim: &Path, table: &Path) {
    // without --table: the data directory's active table (recorded in its database), else an
    // error that says what to do
    let data = d.join("data");
    let input = sim.join("mosaic.raw");
    let no_table = |out: &str| {
        l3(
            &[
                "render",
                "--data-dir",
                data.to_str().unwrap(),
                "--illuminant",
                "Tungsten",
                "--in",
                input.to_str().unwrap(),
                "--out",
                out,
            ],
            d,
        )
    };
    let (ok, out, err) = no_table("none.png");
    assert!(!ok, "render without a table succeeded: {out}");
    assert!(
        err.contains("no --table given") && err.contains("l3 train"),
        "{err}"
    );
    // a table file alone is not an active table
    std::fs::create_dir_all(data.join("tables")).unwrap();
    std::fs::copy(table, data.join("tables/t1.safetensors")).unwrap();
    let (ok, _, err) = no_table("none.png");
    assert!(!ok && err.contains("no active table"), "{err}");
    // a service on the directory stores the trained table and makes it active; then the
    // tiny synthetic table, not active
    let trained = l3::l3::L3Table::load(table).unwrap();
    let (active_id, other_id) = with_service(&data, |state| async move {
        let a = l3::service::import_table(&state, &trained, true)
            .await
            .unwrap();
        let b = l3::service::import_table(&state, l3::test_support::tiny_table(), false)
            .await
            .unwrap();
        (a, b)
    });
    let (ok, out, err) = no_table("data.png");
    assert!(
        ok,
        "render with the data directory's table failed: {out}{err}"
    );
    assert!(err.contains(&format!("table: {active_id}")), "{err}");
    assert!(out.contains(&format!("{active_id}.safetensors")), "{out}");
    assert_eq!(
        std::fs::read(d.join("data.png")).unwrap(),
        std::fs::read(d.join("out.png")).unwrap()
    );
    // the active table's file damaged: passed over (said) for the last good one, as a
    // service start would
    let active_file = data.join(format!("tables/{active_id}.safetensors"));
    let good = std::fs::read(&active_file).unwrap();
    std::fs::write(&active_file, b"damaged").unwrap();
    let (ok, out, err) = no_table("fallback.png");
    assert!(ok, "{out}{err}");
    assert!(
        err.contains(&format!("table {active_id}")) && err.contains(&format!("table: {other_id}")),
        "{err}"
    );
    std::fs::write(&active_file, good).unwrap();
}

#[test]
fn bad_arguments_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let (ok, _, err) = l3(&["simulate", "--illuminant", "nonsense", "--out", "x"], d);
    assert!(!ok && err.contains("unknown illuminant"), "{err}");
    let (ok, _, err) = l3(
        &[
            "render",
            "--table",
            "missing.safetensors",
            "--in",
            "x.raw",
            "--out",
            "y.png",
        ],
        d,
    );
    assert!(!ok && err.contains("missing.safetensors"), "{err}");
    std::fs::write(d.join("bad.safetensors"), b"not a table").unwrap();
    let (ok, _, err) = l3(
        &[
            "render",
            "--table",
            "bad.safetensors",
            "--in",
            "x.raw",
            "--out",
            "y.png",
        ],
        d,
    );
    assert!(!ok && err.contains("bad.safetensors"), "{err}");
    let (ok, _, err) = l3(&["train", "--patch", "4", "--out", "t.safetensors"], d);
    assert!(!ok && err.contains("patch"), "{err}");
    let (ok, _, err) = l3(
        &[
            "train",
            "--colour-averaging-px",
            "0.5",
            "--out",
            "t.safetensors",
        ],
        d,
    );
    assert!(!ok && err.contains("colour_averaging_px 0.5"), "{err}");
    let (ok, _, err) = l3(
        &["train", "--colour-loss", "median", "--out", "t.safetensors"],
        d,
    );
    assert!(!ok && err.contains("--colour-loss"), "{err}");
    assert!(!d.join("t.safetensors").exists());
    let (ok, _, err) = l3(&["simulate", "--exposure=-1", "--out", "x"], d);
    assert!(!ok && err.contains("exposure"), "{err}");
}
