//! The `l3` binary end to end: simulate → train → render → eval, through
//! the real executable, in a temporary folder (with no ISET data directory
//! beside it: the built-in spectral data serves).

use std::path::Path;
use std::process::Command;

use crate::support::{l3, train_small_si};

/// Runs `f` on the state of a service started on `data` (no listener in use beyond a free
/// local port, no default training), then stops the service.
pub(crate) fn with_service<F, Fut, T>(data: &Path, f: F) -> T
where
    F: FnOnce(l3::service::AppState) -> Fut,
    Fut: std::future::Future<Output = T>,
{
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut cfg = l3::service::ServiceConfig::load_with_env(None, &[]).unwrap();
        cfg.server.bind = "127.0.0.1:0".parse().unwrap();
        cfg.data.dir = data.to_path_buf();
        cfg.training.auto_train_default = false;
        let server = l3::service::start(cfg).await.unwrap();
        let out = f(server.state().clone()).await;
        server.shutdown().await.unwrap();
        out
    })
}

/// `l3 simulate` of the Macbeth chart under tungsten (seed 3) into `out`.
fn simulate_macbeth(d: &Path, out: &Path) {
    let (ok, stdout, err) = l3(
        &[
            "simulate",
            "--scene",
            "macbeth",
            "--illuminant",
            "Tungsten",
            "--seed",
            "3",
            "--out",
            out.to_str().unwrap(),
        ],
        d,
    );
    assert!(ok, "simulate failed: {stdout}{err}");
}

#[test]
fn simulate_train_render_eval() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let sim = d.join("sim");
    simulate_macbeth(d, &sim);
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

    let table = d.join("t.safetensors");
    let out = train_small_si(d, &table, &[]);
    assert!(out.contains("trained si table"), "{out}");

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
    std::fs::copy(&table, data.join("tables/t1.safetensors")).unwrap();
    let (ok, _, err) = no_table("none.png");
    assert!(!ok && err.contains("no active table"), "{err}");
    // a service on the directory stores the trained table and makes it active; then the
    // tiny synthetic table, not active
    let trained = l3::l3::L3Table::load(&table).unwrap();
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

    let report = d.join("report.json");
    let (ok, out, err) = l3(
        &[
            "eval",
            "--table",
            table.to_str().unwrap(),
            "--illuminant",
            "Tungsten",
            "--out",
            report.to_str().unwrap(),
        ],
        d,
    );
    assert!(ok, "eval failed: {out}{err}");
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(r["schema"], "l3.delta_e.v1");
    assert_eq!(r["chart"], "natural100");
    assert_eq!(r["patches"].as_array().unwrap().len(), 110);
    let mean = r["summary"]["mean"].as_f64().unwrap();
    assert!(
        mean.is_finite() && mean > 0.0 && mean < 6.0,
        "mean ΔE {mean}"
    );
    // the figure is written beside the JSON
    let svg = std::fs::read_to_string(d.join("report.svg")).unwrap();
    assert!(
        svg.contains("<svg") && svg.contains("d. Worst patches"),
        "{svg}"
    );
    assert!(out.contains("report.svg"), "{out}");

    // light level: a tenth of the exposure, and the same light given as a
    // scene luminance (10 cd/m² at the longest exposure)
    let low_light = |flag: &str, value: &str, name: &str| {
        let path = d.join(name);
        let (ok, out, err) = l3(
            &[
                "eval",
                "--table",
                table.to_str().unwrap(),
                flag,
                value,
                "--out",
                path.to_str().unwrap(),
            ],
            d,
        );
        assert!(ok, "eval {flag} {value} failed: {out}{err}");
        serde_json::from_slice::<serde_json::Value>(&std::fs::read(&path).unwrap()).unwrap()
    };
    let dim = low_light("--exposure", "0.1", "dim.json");
    let lum = low_light("--scene-luminance", "10", "lum.json");
    let px = |v: &serde_json::Value| v["per_pixel"]["mean"].as_f64().unwrap();
    assert!(px(&dim) > px(&r), "0.1×: {} vs {}", px(&dim), px(&r));
    assert!(
        (px(&dim) - px(&lum)).abs() < 0.05,
        "{} vs {}",
        px(&dim),
        px(&lum)
    );
    assert_eq!(dim["context"]["setup"]["exposure_factor"], 0.1);
    let (ok, _, err) = l3(
        &[
            "eval",
            "--table",
            table.to_str().unwrap(),
            "--exposure",
            "2",
        ],
        d,
    );
    assert!(!ok && err.contains("exposure factor 2"), "{err}");
    let (ok, _, err) = l3(
        &[
            "eval",
            "--table",
            table.to_str().unwrap(),
            "--patch-px",
            "4",
        ],
        d,
    );
    assert!(!ok && err.contains("patch-px"), "{err}");

    // the noise split: the first capture is the plain evaluation's, the
    // averaged patch means lie below the per-capture mean (noise averages
    // out), and the noise-free chart is reported too
    let split_path = d.join("split.json");
    let (ok, out, err) = l3(
        &[
            "eval",
            "--table",
            table.to_str().unwrap(),
            "--captures",
            "4",
            "--captured-floor",
            "--out",
            split_path.to_str().unwrap(),
        ],
        d,
    );
    assert!(ok, "eval --captures failed: {out}{err}");
    assert!(out.contains("noise split over 4 captures"), "{out}");
    assert!(out.contains("captured floor"), "{out}");
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&split_path).unwrap()).unwrap();
    let split = &v["context"]["noise_split"];
    let per: Vec<f64> = split["per_capture"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!(per.len(), 4);
    assert_eq!(split["seeds"], serde_json::json!([7, 8, 9, 10]));
    assert!((per[0] - mean).abs() < 1e-9, "{} vs {mean}", per[0]);
    let averaged = split["averaged"]["mean"].as_f64().unwrap();
    let per_mean = split["per_capture_stats"]["mean"].as_f64().unwrap();
    assert!(averaged < per_mean, "{averaged} vs {per_mean}");
    assert!(split["noise_free"]["mean"].as_f64().unwrap() > 0.0);
    // the captured floor: a 4-channel map fitted on the chart, its figures
    // finite, the cross-validated one the mean of its two folds
    let floor = &v["context"]["captured_floor"];
    assert_eq!(floor["captures"], 4);
    assert_eq!(floor["map"].as_array().unwrap().len(), 4);
    let fig = |k: &str| floor[k].as_f64().unwrap();
    for k in ["fitted", "fresh", "noise_free", "cross_validated"] {
        assert!(fig(k).is_finite() && fig(k) > 0.0, "{k}: {floor}");
    }
    let folds: Vec<f64> = floor["folds"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!((fig("cross_validated") - 0.5 * (folds[0] + folds[1])).abs() < 1e-12);
    let (ok, _, err) = l3(
        &[
            "eval",
            "--table",
            table.to_str().unwrap(),
            "--captured-floor",
        ],
        d,
    );
    assert!(!ok && err.contains("captures"), "{err}");
    let (ok, _, err) = l3(
        &[
            "eval",
            "--table",
            table.to_str().unwrap(),
            "--captures",
            "1",
        ],
        d,
    );
    assert!(!ok && err.contains("captures"), "{err}");
    // Table 1 over several captures: refused without noise (before any
    // training) and with the captured floor, which is a one-table study
    let (ok, _, err) = l3(
        &["eval", "--paper-table", "--no-noise", "--captures", "4"],
        d,
    );
    assert!(!ok && err.contains("needs noise"), "{err}");
    let (ok, _, err) = l3(
        &[
            "eval",
            "--paper-table",
            "--captures",
            "4",
            "--captured-floor",
        ],
        d,
    );
    assert!(!ok && err.contains("captured-floor"), "{err}");

    // a captured chart frame: the simulated chart written by `l3 simulate` scores as the
    // chart eval simulates itself (the same seed; u16 quantisation apart), with the light
    // from --illuminant, the sidecar, the DNG's AsShotNeutral or an estimate from the pixels
    let chart = d.join("chart");
    let (ok, out, err) = l3(
        &[
            "simulate",
            "--scene",
            "natural100",
            "--illuminant",
            "Tungsten",
            "--seed",
            "7",
            "--out",
            chart.to_str().unwrap(),
        ],
        d,
    );
    assert!(ok, "simulate natural100 failed: {out}{err}");
    std::fs::create_dir(d.join("bare")).unwrap();
    std::fs::copy(chart.join("mosaic.png"), d.join("bare/mosaic.png")).unwrap();
    let frame_eval = |frame: &std::path::Path, extra: &[&str], expect: &str| {
        let path = d.join("frame.json");
        let mut args = vec![
            "eval",
            "--table",
            table.to_str().unwrap(),
            "--frame",
            frame.to_str().unwrap(),
            "--out",
            path.to_str().unwrap(),
        ];
        args.extend(extra);
        let (ok, out, err) = l3(&args, d);
        assert!(ok, "eval --frame {} failed: {out}{err}", frame.display());
        assert!(out.contains(expect), "{expect}: {out}");
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        v["summary"]["mean"].as_f64().unwrap()
    };
    let named = frame_eval(
        &chart.join("mosaic.raw"),
        &["--illuminant", "Tungsten"],
        "(from --illuminant)",
    );
    assert!((named - mean).abs() < 0.05, "{named} vs {mean}");
    let sidecar = frame_eval(
        &chart.join("mosaic.raw"),
        &[],
        "Tungsten (from the frame's metadata)",
    );
    assert_eq!(sidecar, named);
    // the light read from AsShotNeutral is a CCT near tungsten, not ISET's tungsten: its T and
    // its neutral (which balances the table's chroma classes) are a little off. With one chroma
    // class this cost under 0.5; with the default 8 classes it is 0.71 here (1.54 against 0.83).
    let neutral = frame_eval(&chart.join("mosaic.dng"), &[], "cct:");
    assert!(
        (neutral - named).abs() < 0.8,
        "AsShotNeutral {neutral} vs {named}"
    );
    let estimated = frame_eval(
        &d.join("bare/mosaic.png"),
        &[],
        "(from an estimate from the frame)",
    );
    assert!(
        (estimated - named).abs() < 1.0,
        "estimated {estimated} vs {named}"
    );
    let (ok, _, err) = l3(
        &[
            "eval",
            "--table",
            table.to_str().unwrap(),
            "--frame",
            chart.join("mosaic.raw").to_str().unwrap(),
            "--patch-px",
            "30",
        ],
        d,
    );
    assert!(
        !ok && err.contains("Natural-100 chart with 30 px patches"),
        "{err}"
    );
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

/// `l3 train <base> --reproducible --out <out> <extra>` in `d`, which must
/// succeed: the table file's bytes and the command's output.
fn train_reproducibly(d: &Path, base: &[&str], out: &str, extra: &[&str]) -> (Vec<u8>, String) {
    let mut args = vec!["train"];
    args.extend_from_slice(base);
    args.extend_from_slice(&["--reproducible", "--out", out]);
    args.extend_from_slice(extra);
    let (ok, stdout, err) = l3(&args, d);
    assert!(ok, "train {extra:?} failed: {stdout}{err}");
    (std::fs::read(d.join(out)).unwrap_or_default(), stdout)
}

#[test]
fn train_in_shards_gives_the_same_table_file() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let base = [
        "--illuminants",
        "D65,Tungsten",
        "--scenes",
        "5",
        "--scene-size",
        "32",
        "--levels",
        "6",
    ];
    let train = |out: &str, extra: &[&str]| train_reproducibly(d, &base, out, extra);
    let (one_bytes, _) = train("one.safetensors", &[]);
    let (two, stdout) = train(
        "two.safetensors",
        &["--shards", "2", "--shard-dir", "parts"],
    );
    assert_eq!(one_bytes, two, "2 shards give the single run's bytes");
    // by default an SI table renders with maps fitted for a mean over 48
    // pixels per channel (a cross table's) and keeps maps for foreign lights
    // fitted for 128; --colour-averaging-px sets both, 0 the noise-free maps
    // (the spec, stored in the header, differs; kernels and maps tell)
    train("avg48.safetensors", &["--colour-averaging-px", "48"]);
    train("avg128.safetensors", &["--colour-averaging-px", "128"]);
    train("avg0.safetensors", &["--colour-averaging-px", "0"]);
    let load = |f: &str| l3::l3::L3Table::load(&d.join(f)).unwrap();
    let (one, avg48, avg128) = (
        load("one.safetensors"),
        load("avg48.safetensors"),
        load("avg128.safetensors"),
    );
    assert_eq!(one.kernels, avg48.kernels, "the rendered maps: 48 px");
    assert_ne!(one.kernels, avg128.kernels);
    let transfer = |t: &l3::l3::L3Table| t.meta.params.transfer_maps.clone().unwrap();
    assert_eq!(
        transfer(&one),
        transfer(&avg128),
        "the transfer maps: 128 px"
    );
    assert_ne!(transfer(&one), transfer(&avg48));
    assert_ne!(one.kernels, load("avg0.safetensors").kernels);
    // its colour maps are aimed through D65's and tungsten's T; it keeps, per
    // level, maps aimed at XYZ under the light for the lights it was not
    // trained on, and these differ where tungsten's T errs
    let table = &one;
    let transfer = transfer(table);
    assert_eq!(transfer.len(), 6);
    assert!(table.transfers_to("Fluorescent") && !table.transfers_to("tungsten"));
    let top = table.colour_map_at(table.n_bands() - 1).unwrap();
    let gap = top
        .m
        .iter()
        .flatten()
        .zip(transfer[5].m.iter().flatten())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(gap > 1e-3, "aimed and transfer maps differ: {gap}");
    // the transfer maps' fit was chosen on the standard lights the table was
    // not trained on, and the summary says which, with both scores
    let choice = &table.meta.summary["transfer_fit"];
    assert_eq!(
        choice["held_out"],
        serde_json::json!(["D50", "A", "F2", "F11"])
    );
    // both fits on both lights together, then on each light alone, and the
    // winner is the one with the lowest score
    let candidates = choice["candidates"].as_array().unwrap();
    let tried: Vec<(String, String)> = candidates
        .iter()
        .map(|c| (c["fit"].to_string(), c["lights"].to_string()))
        .collect();
    let fits = ["\"perceptual\"", "\"least-squares\""];
    let subsets = [r#"["D65","Tungsten"]"#, r#"["D65"]"#, r#"["Tungsten"]"#];
    let expected: Vec<(String, String)> = subsets
        .iter()
        .flat_map(|l| fits.iter().map(move |f| (f.to_string(), l.to_string())))
        .collect();
    assert_eq!(tried, expected, "{choice}");
    let scores: Vec<f64> = candidates
        .iter()
        .map(|c| c["held_out_delta_e"].as_f64().unwrap())
        .collect();
    assert!(scores.iter().all(|s| s.is_finite() && *s > 0.0), "{choice}");
    let best = (0..scores.len()).fold(0, |b, i| if scores[i] < scores[b] { i } else { b });
    assert_eq!(choice["fit"], candidates[best]["fit"], "{choice}");
    assert_eq!(choice["lights"], candidates[best]["lights"], "{choice}");
    assert!(stdout.contains("accumulation shard 2/2"), "{stdout}");
    assert!(d.join("parts/sums-2-of-2.l3p").is_file());
    // one step per process, as on separate machines: surveys, then sums
    // (shards in any order), then the merge
    let steps: [&[&str]; 5] = [
        &["--phase", "survey", "--shard", "2"],
        &["--phase", "survey", "--shard", "1"],
        &["--phase", "accumulate", "--shard", "2"],
        &["--phase", "accumulate", "--shard", "1"],
        &["--phase", "merge"],
    ];
    for step in steps {
        let args = [&["--shards", "2", "--shard-dir", "steps"][..], step].concat();
        train("steps.safetensors", &args);
    }
    assert_eq!(
        std::fs::read(d.join("steps.safetensors")).unwrap(),
        one_bytes
    );
    // more shards than batches is a clear error
    let (ok, _, err) = l3(&["train", "--shards", "6", "--scenes", "5"], d);
    assert!(!ok && err.contains("6 shards for 5 batches"), "{err}");
}

/// `l3 train --chroma-classes K` trains a table whose levels are split by
/// chroma class: the same bytes in shards, and it renders a simulated frame
/// under another light (the camera-aware correction fitted per band).
#[test]
fn train_with_chroma_classes_shards_and_renders() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let base = [
        "--illuminants",
        "D65",
        "--scenes",
        "4",
        "--scene-size",
        "32",
        "--levels",
        "4",
        "--chroma-classes",
        "3",
    ];
    let train = |out: &str, extra: &[&str]| train_reproducibly(d, &base, out, extra);
    let (one, stdout) = train("c.safetensors", &[]);
    assert!(stdout.contains("× 3 chroma classes ×"), "{stdout}");
    let (two, _) = train("c2.safetensors", &["--shards", "2", "--shard-dir", "parts"]);
    assert_eq!(one, two, "2 shards give the single run's bytes");
    let table = l3::l3::L3Table::load(&d.join("c.safetensors")).unwrap();
    assert_eq!((table.n_chroma(), table.n_bands()), (3, 12));
    // the classes balance by the light: the table keeps its training light's
    // neutral, the sensor's response to white under D65 (largest channel 1)
    let design = table.sensor_design().unwrap();
    let camera = l3::camera::Camera::new(&design, table.meta.grid, None).unwrap();
    let d65 = l3::spectral::cie_illuminant("D65").unwrap();
    let white = camera.white_response(&d65).unwrap();
    let max = white.iter().copied().fold(0.0, f64::max);
    let stored = table
        .meta
        .params
        .chroma
        .as_ref()
        .unwrap()
        .white
        .clone()
        .unwrap();
    assert!(table.chroma_balances());
    // a same-illuminant table keeps the maps over every class for other lights' T
    let transfer = table.meta.params.transfer_maps.as_ref().unwrap();
    assert_eq!(transfer.len(), table.n_levels());
    assert!(transfer.iter().all(|m| m.n_channels == white.len()));
    assert!(table.transfers_to("Tungsten") && !table.transfers_to("d65"));
    assert_eq!(stored.len(), white.len());
    for (s, w) in stored.iter().zip(&white) {
        assert!((s - w / max).abs() < 1e-9, "{stored:?} against {white:?}");
    }
    let sim = d.join("sim");
    simulate_macbeth(d, &sim);
    let table = d.join("c.safetensors");
    let mosaic = sim.join("mosaic.raw");
    // with C (the default), and through T under that light: the transfer kernels
    for (correction, out_name) in [("camera", "c.png"), ("colorimetric", "t.png")] {
        let png = d.join(out_name);
        let args = [
            "render",
            "--table",
            table.to_str().unwrap(),
            "--illuminant",
            "Tungsten",
            "--correction",
            correction,
            "--in",
            mosaic.to_str().unwrap(),
            "--out",
            png.to_str().unwrap(),
        ];
        let (ok, out, err) = l3(&args, d);
        assert!(ok, "render with {correction} failed: {out}{err}");
        assert!(image::open(&png).is_ok());
    }
    for bad in ["0", "33"] {
        let (ok, _, err) = l3(
            &["train", "--chroma-classes", bad, "--out", "x.safetensors"],
            d,
        );
        assert!(!ok && err.contains("chroma_classes"), "{bad}: {err}");
    }
}

/// `l3 serve --bind ADDR --data-dir DIR` listens where the flags say and keeps its database
/// in that directory, over the configuration's defaults, a `--config` file and the `L3_*`
/// variables that name others.
#[test]
fn serve_takes_bind_and_data_dir_flags() {
    use std::io::{Read, Write};
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("served");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let bind = format!("127.0.0.1:{port}");
    let config = tmp.path().join("l3.toml");
    std::fs::write(
        &config,
        "[server]\nbind = \"127.0.0.1:1\"\n[data]\ndir = \"from-file\"\n",
    )
    .unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_l3"))
        .args(["serve", "--config"])
        .arg(&config)
        .args(["--bind", &bind, "--data-dir"])
        .arg(&data)
        .env("L3_BIND", "127.0.0.1:2")
        .env("L3_DATA_DIR", tmp.path().join("from-env"))
        .env("L3_AUTO_TRAIN", "false")
        .env("L3_ISET_DIR", tmp.path().join("no-iset"))
        .current_dir(tmp.path())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("spawn l3 serve");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    let answer = loop {
        let got = std::net::TcpStream::connect(&bind).and_then(|mut s| {
            s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")?;
            let mut text = String::new();
            s.read_to_string(&mut text)?;
            Ok(text)
        });
        match got {
            Ok(text) => break text,
            Err(_) if std::time::Instant::now() < deadline => {
                std::thread::sleep(std::time::Duration::from_millis(50))
            }
            Err(e) => {
                let _ = child.kill();
                panic!("l3 serve did not answer on {bind}: {e}");
            }
        }
    };
    let db = data.join("l3.sqlite").exists();
    let _ = child.kill();
    let _ = child.wait();
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
    assert!(db, "no database in --data-dir");
    for other in ["data", "from-file", "from-env"] {
        assert!(!tmp.path().join(other).exists(), "{other} was used");
    }
}

/// A bad configuration value stops `l3 serve` with exit code 2 and a message naming it: the
/// variable, or the key and the file.
#[test]
fn serve_names_a_bad_configuration_value() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let (code, err) = serve_until_exit(d, &[], &[("L3_MAX_PIXELS", "lots")]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("L3_MAX_PIXELS=\"lots\" is not a valid number"),
        "{err}"
    );
    let config = d.join("bad.toml");
    std::fs::write(&config, "[server]\nmax_pixels = \"many\"\n").unwrap();
    let (code, err) = serve_until_exit(d, &["--config", config.to_str().unwrap()], &[]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("server.max_pixels") && err.contains("bad.toml"),
        "{err}"
    );
}

/// Runs `l3 serve` with `env` until it exits (it must, within 60 s); returns its exit code
/// and its standard error.
fn serve_until_exit(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> (Option<i32>, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_l3"));
    cmd.arg("serve")
        .args(args)
        .env("L3_AUTO_TRAIN", "false")
        .env("L3_ISET_DIR", dir.join("no-iset"))
        .env("L3_LOG_FORMAT", "text")
        .env("NO_COLOR", "1")
        .current_dir(dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().expect("spawn l3 serve");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let status = loop {
        match child.try_wait().expect("wait for l3 serve") {
            Some(s) => break s,
            None if std::time::Instant::now() < deadline => {
                std::thread::sleep(std::time::Duration::from_millis(50))
            }
            None => {
                let _ = child.kill();
                let _ = child.wait();
                panic!("l3 serve {args:?} did not exit");
            }
        }
    };
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        use std::io::Read;
        let _ = e.read_to_string(&mut err);
    }
    (status.code(), err)
}

/// A start that fails is no usage error: a busy address and a database that cannot be opened
/// exit with code 1 (not 2) and say why, and a busy address leaves the data directory alone.
#[test]
fn serve_start_failures_exit_1_with_the_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let bind = taken.local_addr().unwrap().to_string();
    let data = d.join("busy");
    let (code, err) = serve_until_exit(
        d,
        &["--bind", &bind, "--data-dir", data.to_str().unwrap()],
        &[],
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains(&format!("cannot listen on {bind}")) && err.contains("--bind"),
        "{err}"
    );
    assert!(
        !data.exists(),
        "a start that cannot listen created {data:?}"
    );
    drop(taken);

    let free = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string();
    let data = d.join("db");
    let data_arg = ["--bind", &free, "--data-dir", data.to_str().unwrap()];
    // an unknown scheme
    let (code, err) = serve_until_exit(d, &data_arg, &[("L3_DATABASE_URL", "mysql://db/l3")]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("database_url 'mysql://db/l3'") && err.contains("postgres://"),
        "{err}"
    );
    // a SQLite file that cannot be created (its directory does not exist)
    let (code, err) = serve_until_exit(
        d,
        &data_arg,
        &[("L3_DATABASE_URL", "sqlite:///nonexistent-dir/l3/l3.sqlite")],
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("database"), "{err}");
}

#[test]
fn eval_colour_classes_predicts_without_a_table() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let out_path = d.join("classes.json");
    let (ok, out, err) = l3(
        &[
            "eval",
            "--colour-classes",
            "1,6",
            "--captures",
            "3",
            "--out",
            out_path.to_str().unwrap(),
        ],
        d,
    );
    assert!(ok, "eval --colour-classes failed: {out}{err}");
    assert!(out.contains("| chroma classes |"), "{out}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out_path).unwrap()).unwrap();
    assert_eq!(v["captures"], 3);
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0]["classes"], 1);
    for r in rows {
        for k in ["one_capture", "one_capture_std", "noise_free"] {
            assert!(r[k].as_f64().is_some_and(f64::is_finite), "{k}: {r}");
        }
    }
    // the classes lower the noise-free error of the default sensor's colour maps
    assert!(
        rows[1]["noise_free"].as_f64() < rows[0]["noise_free"].as_f64(),
        "{v}"
    );
    for bad in [
        &["--colour-classes", "0"][..],
        &["--colour-classes", "2", "--paper-table"],
    ] {
        let mut args = vec!["eval"];
        args.extend_from_slice(bad);
        let (ok, _, err) = l3(&args, d);
        assert!(!ok && !err.is_empty(), "{bad:?} was accepted");
    }
}
