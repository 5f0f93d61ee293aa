//! `l3 train`: reproducible tables in shards or one step per process, and chroma classes.

use std::path::Path;

use crate::support::{l3, l3_code};

use super::simulate_macbeth;

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
    check_transfer_maps(&one);
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

/// A step of a sharded run whose input an earlier phase writes, run before that phase: an
/// error (exit code 1, a missing file) that names the phase to run first.
#[test]
fn a_phase_run_too_early_names_the_phase_to_run_first() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let step = |phase: &[&str]| {
        let base = [
            "train",
            "--illuminants",
            "D65",
            "--scenes",
            "4",
            "--scene-size",
            "32",
            "--levels",
            "4",
            "--shards",
            "2",
            "--shard-dir",
            "parts",
            "--out",
            "t.safetensors",
        ];
        l3_code(&[&base[..], phase].concat(), d)
    };
    for phase in [
        &["--phase", "merge"][..],
        &["--phase", "accumulate", "--shard", "1"],
    ] {
        let (code, out, err) = step(phase);
        assert_eq!(code, Some(1), "{phase:?}: {out}{err}");
        assert!(
            err.contains("survey-1-of-2.l3p") && err.contains("--phase survey --shard K"),
            "{phase:?}: {err}"
        );
    }
    for k in ["1", "2"] {
        let (code, out, err) = step(&["--phase", "survey", "--shard", k]);
        assert_eq!(code, Some(0), "{out}{err}");
    }
    let (code, out, err) = step(&["--phase", "merge"]);
    assert_eq!(code, Some(1), "{out}{err}");
    assert!(
        err.contains("sums-1-of-2.l3p") && err.contains("--phase accumulate --shard K"),
        "{err}"
    );
    assert!(!d.join("t.safetensors").exists());
}

/// The transfer maps of the D65 + tungsten table of [`train_in_shards_gives_the_same_table_file`].
///
/// Its colour maps are aimed through D65's and tungsten's T. Per level, it keeps maps aimed
/// at XYZ under the light for the lights it was not trained on, and these differ where
/// tungsten's T errs.
fn check_transfer_maps(table: &l3::l3::L3Table) {
    let transfer = table.meta.params.transfer_maps.clone().unwrap();
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
