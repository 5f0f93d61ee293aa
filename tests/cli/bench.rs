//! `l3 bench --quick` end to end through the real executable: the JSON
//! parses with its schema, the markdown and the SVG plot exist, and every
//! number is finite and positive.

use std::path::Path;
use std::process::Command;

use l3::bench::{BenchReport, ConfigResult};

fn numbers(v: &serde_json::Value, path: &str, out: &mut Vec<(String, f64)>) {
    match v {
        serde_json::Value::Number(n) => {
            out.push((path.to_string(), n.as_f64().unwrap_or(f64::NAN)))
        }
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                numbers(x, &format!("{path}[{i}]"), out);
            }
        }
        serde_json::Value::Object(o) => {
            for (k, x) in o {
                numbers(x, &format!("{path}.{k}"), out);
            }
        }
        _ => {}
    }
}

/// `l3 bench --quick ARGS --out OUT`, which must succeed; its stdout.
fn quick_bench(args: &[&str], out: &std::path::Path) -> String {
    let run = Command::new(env!("L3_BIN"))
        .args(["bench", "--quick"])
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run l3");
    let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "l3 bench failed: {stdout}{stderr}");
    stdout
}

#[test]
fn quick_bench_writes_json_markdown_and_plot() {
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("bench");
    let stdout = quick_bench(&[], &out_dir);

    let (json, report) = read_the_report(&out_dir);
    low_light_errors_grow(&report);
    let isp = the_strong_isp_beside_the_baselines(&report);
    every_number_is_finite(&json);
    skips_and_encoders(&report);
    markdown_and_plot(&out_dir, &stdout, &isp);
}

/// bench.json with its schema, read as a report: the configurations and the acquisitions.
fn read_the_report(out_dir: &Path) -> (serde_json::Value, BenchReport) {
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("bench.json")).unwrap()).unwrap();
    assert_eq!(json["schema"], "l3.bench.v1");
    assert!(json["renderer"].as_str().is_some_and(|s| !s.is_empty()));
    let report: BenchReport = serde_json::from_value(json.clone()).unwrap();
    // 2 configurations + 3 baselines + 2 strong ISPs + copy
    assert_eq!(report.configs.len(), 8);
    assert_eq!(report.acquisitions, ["Tungsten", "Fluorescent"]);
    for c in &report.configs {
        let has_colour = c.kind != l3::bench::ConfigKind::Copy;
        assert_eq!(c.colour.len(), if has_colour { 2 } else { 0 }, "{}", c.name);
        assert_eq!(c.training_seconds.is_some(), has_colour, "{}", c.name);
        assert_eq!(c.one_thread.runs, 2);
        assert_eq!(c.one_thread.threads, 1);
    }
    (json, report)
}

/// A tenth of the light: every conventional pipeline's per-pixel error grows.
fn low_light_errors_grow(report: &BenchReport) {
    use l3::bench::ConfigKind::{Baseline, Isp};
    for c in report
        .configs
        .iter()
        .filter(|c| [Baseline, Isp].contains(&c.kind))
    {
        for col in &c.colour {
            let low = col.low_light_pixel_mean.expect("low-light column");
            assert!(low > col.pixel_mean, "{} {}: {low}", c.name, col.illuminant);
        }
    }
}

/// The strong ISP beside the baselines, with its own light's matrix and with D65's then T,
/// every metric measured at both exposures; returns its configurations.
fn the_strong_isp_beside_the_baselines(report: &BenchReport) -> Vec<&ConfigResult> {
    use l3::bench::ConfigKind::Isp;
    let isp: Vec<_> = report.configs.iter().filter(|c| c.kind == Isp).collect();
    assert_eq!(isp.len(), 2);
    let labels: Vec<&str> = isp.iter().map(|c| c.colour[0].method.as_str()).collect();
    assert_eq!(labels, ["ISP_Tungsten", "ISP_D65+T"]);
    for c in &isp {
        assert!(c.all_threads.mpix_per_s > 0.0 && c.one_thread.runs == 2);
        for col in &c.colour {
            let (f, l) = (&col.spatial, &col.low_light_spatial);
            let metrics = [
                Some(col.mean),
                Some(col.p90),
                Some(col.pixel_mean),
                col.low_light_pixel_mean,
                col.s_cielab_mean,
                col.low_light_s_cielab_mean,
                f.s_cielab_texture,
                l.s_cielab_texture,
                f.false_colour,
                l.false_colour,
                f.mtf50,
            ];
            assert!(
                metrics.iter().all(|m| m.is_some_and(f64::is_finite)),
                "{} {}: {col:?}",
                c.name,
                col.illuminant
            );
        }
    }
    isp
}

/// Every number of the JSON is finite and positive (some may be zero).
fn every_number_is_finite(json: &serde_json::Value) {
    let mut nums = Vec::new();
    numbers(json, "", &mut nums);
    assert!(nums.len() > 50);
    for (path, v) in &nums {
        // seeds, output differences of skips (0 when identical) and false colour (0 where
        // the render adds none beyond its noise) may be zero
        if path.ends_with(".seed") || path.ends_with(".max_diff") || path.ends_with(".false_colour")
        {
            assert!(v.is_finite() && *v >= 0.0, "{path} = {v}");
            continue;
        }
        assert!(v.is_finite() && *v > 0.0, "{path} = {v}");
    }
}

/// The skips' measurements, the encoders' sizes and the Pareto front.
fn skips_and_encoders(report: &BenchReport) {
    // every skip measured where it applies and where it does not, outputs (nearly) equal
    assert!(report.skips.len() >= 10, "{} skips", report.skips.len());
    assert!(report.skips.iter().any(|k| k.applies) && report.skips.iter().any(|k| !k.applies));
    for k in &report.skips {
        let bound = if k.diff_unit == "sRGB codes" {
            1.0
        } else {
            1e-4
        };
        assert!(
            k.max_diff <= bound,
            "{}: {} differs by {}",
            k.skip,
            k.case,
            k.max_diff
        );
    }
    assert_eq!(report.encoders.len(), 6);
    // the PPM is its header and the 8-bit pixels, uncompressed
    let ppm = report
        .encoders
        .iter()
        .find(|e| e.encoding.starts_with("PPM"))
        .expect("PPM encoder timed");
    let png = report
        .encoders
        .iter()
        .find(|e| e.encoding.starts_with("PNG fast"))
        .expect("PNG encoder timed");
    assert!(ppm.bytes > png.bytes && ppm.median_ms.is_finite());
    let jpeg = report
        .encoders
        .iter()
        .find(|e| e.encoding.starts_with("JPEG"))
        .expect("JPEG encoder timed");
    assert!(jpeg.bytes < png.bytes, "{} vs {}", jpeg.bytes, png.bytes);
    assert!(!report.pareto.is_empty() && report.pareto.iter().all(|f| !f.names.is_empty()));
}

/// bench.md (and the printed table) with the plain copy and the strong ISP; the SVG plot
/// with its Pareto front and an ISP point.
fn markdown_and_plot(out_dir: &Path, stdout: &str, isp: &[&ConfigResult]) {
    let md = std::fs::read_to_string(out_dir.join("bench.md")).unwrap();
    assert!(md.contains("| configuration |") && md.contains("plain copy"));
    assert!(md.contains(&format!("| *{}* |", isp[1].name)), "{md}");
    assert!(stdout.contains("| configuration |"));
    let svg = std::fs::read_to_string(out_dir.join("bench.svg")).unwrap();
    assert!(svg.trim_start().starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    assert!(
        svg.contains("class=\"pareto-front\""),
        "no Pareto front element"
    );
    assert!(svg.contains("ISP (demosaic"), "no ISP point in the plot");
}

#[test]
fn sensor_sweep_runs_every_sensor_in_one_go() {
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("sweep");
    let root = env!("L3_ROOT");
    let sensors = format!(
        "{root}/config/sensors/rgbw-iset.toml,{root}/config/sensors/bayer-nikon-d5100.toml"
    );
    quick_bench(&["--sensor", &sensors], &out_dir);
    let sweep: l3::bench::SensorSweep =
        serde_json::from_slice(&std::fs::read(out_dir.join("sensors.json")).unwrap()).unwrap();
    let names: Vec<&str> = sweep.reports.iter().map(|r| r.sensor.as_str()).collect();
    assert_eq!(names, ["rgbw-iset", "bayer-nikon-d5100"]);
    for r in &sweep.reports {
        // default + I tables, each with 8 and with one chroma class, 3 baselines, 2 strong
        // ISPs, copy; no skips in a sweep
        assert_eq!(r.configs.len(), 10, "{}", r.sensor);
        assert!(
            r.configs
                .iter()
                .any(|c| c.name == "I tables, one chroma class"),
            "{}",
            r.sensor
        );
        assert!(r.skips.is_empty());
        for c in r
            .configs
            .iter()
            .filter(|c| c.kind != l3::bench::ConfigKind::Copy)
        {
            for col in &c.colour {
                assert!(col.mean.is_finite() && col.mean > 0.0);
                assert!(
                    col.low_light_pixel_mean
                        .is_some_and(|v| v.is_finite() && v > 0.0)
                );
            }
        }
    }
    let md = std::fs::read_to_string(out_dir.join("sensors.md")).unwrap();
    // 2 sensors × 4 L3 configurations × 2 lights
    let rows = md
        .lines()
        .filter(|l| l.starts_with("| rgbw-iset |") || l.starts_with("| bayer-nikon-d5100 |"))
        .count();
    assert_eq!(rows, 16, "{md}");
    // every row of the summary table has as many cells as its header
    let table: Vec<&str> = md
        .lines()
        .skip_while(|l| !l.starts_with("| sensor |"))
        .take_while(|l| l.starts_with('|'))
        .collect();
    let cells = |l: &str| l.matches('|').count();
    assert!(table.len() == 18, "{md}");
    assert!(table.iter().all(|l| cells(l) == cells(table[0])), "{md}");
}
