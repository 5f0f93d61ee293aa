//! The benchmark's markdown table (the JSON is the serde form of
//! [`BenchReport`], schema [`BENCH_SCHEMA`]).

use super::records::{BenchReport, ConfigKind, ConfigResult, FrontMetric, SensorSweep};

/// Identifier of the benchmark JSON's schema.
pub const BENCH_SCHEMA: &str = "l3.bench.v1";

fn opt(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        _ => "—".into(),
    }
}

/// A markdown rendering: one row per configuration, the baseline and the copy.
pub fn markdown_table(r: &BenchReport) -> String {
    let mut s = table_header(r);
    for c in &r.configs {
        s.push_str(&config_row(r, c));
    }
    s.push_str(&format!(
        "\nTraining: {} scenes of {}×{} px per table (the I-tables row trains one table per illuminant; its time is the sum). \
         Throughput frame: {}. Whole run: {:.0} s.\n",
        r.options.scenes, r.options.scene_size, r.options.scene_size, r.frame.source, r.total_seconds
    ));
    s.push_str(&spatial_markdown(r));
    s.push_str(&skips_markdown(r));
    if !r.encoders.is_empty() {
        s.push_str(
            "\nEncoders of the rendered frame:\n\n| encoding | ms | bytes |\n|---|---:|---:|\n",
        );
        for e in &r.encoders {
            s.push_str(&format!(
                "| {} | {:.1} | {} |\n",
                e.encoding, e.median_ms, e.bytes
            ));
        }
    }
    s
}

/// The caption, the header row and the rule of the main table.
fn table_header(r: &BenchReport) -> String {
    let mut s = format!(
        "Run time against colour error: `{}` renderer, sensor `{}`, {}×{} frame ({:.1} Mpix) → sRGB 8-bit, \
         median of {} runs, 1 thread and {} threads; ΔE2000 of patch means on the {} chart.\n\n",
        r.renderer,
        r.sensor,
        r.frame.width,
        r.frame.height,
        r.frame.megapixels,
        r.options.runs,
        r.threads,
        r.chart
    );
    s.push_str("| configuration | training (s) |");
    let low = r.options.low_light_factor;
    for a in &r.acquisitions {
        s.push_str(&format!(
            " ΔE {a} mean | ΔE {a} p90 | per-pixel {a} | per-pixel {a} at {low}× |"
        ));
    }
    s.push_str(&format!(
        " Mpix/s (1 thread) | Mpix/s ({} threads) | ms/Mpix ({} threads) | time ÷ copy | Pareto front |\n",
        r.threads, r.threads
    ));
    s.push_str("|---|---:|");
    for _ in &r.acquisitions {
        s.push_str("---:|---:|---:|---:|");
    }
    s.push_str("---:|---:|---:|---:|---|\n");
    s
}

/// One configuration's row of the main table.
fn config_row(r: &BenchReport, c: &ConfigResult) -> String {
    let name = match c.kind {
        ConfigKind::L3 => c.name.clone(),
        _ => format!("*{}*", c.name),
    };
    let mut s = format!("| {name} | {} |", opt(c.training_seconds, 1));
    for a in &r.acquisitions {
        let col = c.colour_under(a);
        s.push_str(&format!(
            " {} | {} | {} | {} |",
            opt(col.map(|x| x.mean), 2),
            opt(col.map(|x| x.p90), 2),
            opt(col.map(|x| x.pixel_mean), 2),
            opt(col.and_then(|x| x.low_light_pixel_mean), 2)
        ));
    }
    let fronts: Vec<String> = r
        .pareto
        .iter()
        .filter(|f| f.names.contains(&c.name))
        .map(|f| match f.metric {
            FrontMetric::DeltaE => f.illuminant.clone(),
            m => format!("{} ({})", f.illuminant, m.name()),
        })
        .collect();
    s.push_str(&format!(
        " {} | {} | {} | {} | {} |\n",
        opt(Some(c.one_thread.mpix_per_s), 1),
        opt(Some(c.all_threads.mpix_per_s), 1),
        opt(Some(c.all_threads.ms_per_mpix), 2),
        opt(Some(c.time_vs_copy), 1),
        if fronts.is_empty() {
            "—".to_string()
        } else {
            fronts.join(", ")
        }
    ));
    s
}

/// Beside ΔE: per configuration and light, the chart's S-CIELAB, the texture's, the edge's
/// MTF50 and the false colour at it, at full and at the low-light exposure.
fn spatial_markdown(r: &BenchReport) -> String {
    let low = r.options.low_light_factor;
    let mut s = format!(
        "\nSpace as well as colour (docs/accuracy.md, Sharpness and false colour): S-CIELAB of the chart and of a \
         dead-leaves texture, MTF50 of a slanted edge (cycles/pixel; the lens alone: {}) and the false colour at it, \
         at full and at {low}× exposure:\n\n\
         | configuration | light | S-CIELAB chart | at {low}× | S-CIELAB texture | at {low}× | MTF50 | at {low}× | false colour | at {low}× |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        opt(
            r.configs
                .iter()
                .flat_map(|c| &c.colour)
                .find_map(|x| x.spatial.ideal_mtf50),
            3
        )
    );
    for c in r.configs.iter().filter(|c| !c.colour.is_empty()) {
        for x in &c.colour {
            let (f, l) = (&x.spatial, &x.low_light_spatial);
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                c.name,
                x.illuminant,
                opt(x.s_cielab_mean, 2),
                opt(x.low_light_s_cielab_mean, 2),
                opt(f.s_cielab_texture, 2),
                opt(l.s_cielab_texture, 2),
                opt(f.mtf50, 3),
                opt(l.mtf50, 3),
                opt(f.false_colour, 2),
                opt(l.false_colour, 2),
            ));
        }
    }
    s
}

/// The skips' table, when they were measured.
fn skips_markdown(r: &BenchReport) -> String {
    let mut s = String::new();
    if !r.skips.is_empty() {
        s.push_str(
            "\nSkips (docs/design.md §9), default table, median ms with and without each skip, all threads:\n\n\
             | skip | case | applies | with (ms) | without (ms) | speed-up | max output difference |\n\
             |---|---|---|---:|---:|---:|---|\n",
        );
        for k in &r.skips {
            s.push_str(&format!(
                "| {} | {} | {} | {:.1} | {:.1} | {:.2}× | {:.2e} {} |\n",
                k.skip,
                k.case,
                if k.applies { "yes" } else { "no" },
                k.with_ms,
                k.without_ms,
                k.speedup,
                k.max_diff,
                k.diff_unit
            ));
        }
    }
    s
}

/// The sensor sweep as one markdown table: per sensor and light, the default
/// L3 configuration against the better per-light baseline (RGB or all
/// channels, by patch-mean ΔE at full exposure).
pub fn sensor_sweep_markdown(sweep: &SensorSweep) -> String {
    let low = sweep
        .reports
        .first()
        .map(|r| r.options.low_light_factor)
        .unwrap_or(0.1);
    let mut s = format!(
        "Sensor sweep: each L3 configuration against the better conventional baseline fitted under each light \
         (RGB or all channels, by patch mean at full exposure). ΔE2000 of patch means; per-pixel ΔE at full and \
         {low}× exposure; sRGB 8-bit throughput, all threads.\n\n\
         | sensor | light | L3 configuration | L3 mean | L3 per-pixel | L3 per-pixel {low}× | baseline | baseline mean | baseline per-pixel | baseline per-pixel {low}× | L3/baseline per-pixel {low}× | L3 Mpix/s | baseline Mpix/s |\n\
         |---|---|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|\n"
    );
    for r in &sweep.reports {
        for (l3, a) in r
            .configs
            .iter()
            .filter(|c| c.kind == ConfigKind::L3)
            .flat_map(|c| r.acquisitions.iter().map(move |a| (c, a)))
        {
            let Some(lc) = l3.colour_under(a) else {
                continue;
            };
            let best = r
                .configs
                .iter()
                .filter(|c| c.kind == ConfigKind::Baseline && c.name.contains("per light"))
                .filter_map(|c| c.colour_under(a).map(|x| (c, x)))
                .min_by(|x, y| x.1.mean.total_cmp(&y.1.mean));
            let (bname, bc, bspeed) = match best {
                Some((c, x)) => (c.name.as_str(), Some(x), Some(c.all_threads.mpix_per_s)),
                None => ("—", None, None),
            };
            let ratio = lc
                .low_light_pixel_mean
                .zip(bc.and_then(|b| b.low_light_pixel_mean))
                .map(|(l, b)| l / b);
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                r.sensor,
                a,
                l3.name,
                opt(Some(lc.mean), 2),
                opt(Some(lc.pixel_mean), 2),
                opt(lc.low_light_pixel_mean, 2),
                bname,
                opt(bc.map(|b| b.mean), 2),
                opt(bc.map(|b| b.pixel_mean), 2),
                opt(bc.and_then(|b| b.low_light_pixel_mean), 2),
                opt(ratio, 2),
                opt(Some(l3.all_threads.mpix_per_s), 1),
                opt(bspeed, 1),
            ));
        }
    }
    s
}

#[cfg(test)]
pub(super) mod test_support {
    use crate::bench::{
        BenchOptions, BenchReport, ColourResult, ConfigKind, ConfigResult, FrameInfo, L3Config,
        ParetoFront, Throughput,
    };

    fn tp(ms: f64, threads: usize) -> Throughput {
        Throughput {
            threads,
            runs: 3,
            median_ms: ms,
            ms_per_mpix: ms / 12.0,
            mpix_per_s: 12.0 / (ms / 1e3),
            samples_ms: vec![ms; 3],
        }
    }

    fn colour(ill: &str, mean: f64) -> ColourResult {
        ColourResult {
            illuminant: ill.into(),
            method: "m".into(),
            mean,
            std: 1.0,
            median: mean,
            p90: mean * 2.0,
            max: mean * 3.0,
            pixel_mean: mean * 1.5,
            low_light_pixel_mean: Some(mean * 3.0),
            s_cielab_mean: Some(mean * 1.2),
            low_light_s_cielab_mean: None,
            spatial: crate::eval::SpatialScore {
                mtf50: Some(0.3),
                ..Default::default()
            },
            low_light_spatial: Default::default(),
        }
    }

    fn row(name: &str, kind: ConfigKind, ms: f64, tun: f64, flu: f64) -> ConfigResult {
        ConfigResult {
            name: name.into(),
            kind,
            config: (kind == ConfigKind::L3).then(L3Config::default_config),
            training_seconds: (kind != ConfigKind::Copy).then_some(2.5),
            colour: if kind == ConfigKind::Copy {
                vec![]
            } else {
                vec![colour("Tungsten", tun), colour("Fluorescent", flu)]
            },
            one_thread: tp(ms * 2.0, 1),
            all_threads: tp(ms, 2),
            time_vs_copy: ms / 12.0,
        }
    }

    /// A hand-made report: a copy, three L3 rows, a baseline and a strong ISP.
    pub fn sample_report() -> BenchReport {
        BenchReport {
            skips: Vec::new(),
            encoders: Vec::new(),
            schema: crate::bench::BENCH_SCHEMA.into(),
            renderer: "reference".into(),
            sensor: "paper RGBW".into(),
            chart: "Natural-100".into(),
            acquisitions: vec!["Tungsten".into(), "Fluorescent".into()],
            frame: FrameInfo {
                width: 4000,
                height: 3000,
                megapixels: 12.0,
                source: "test".into(),
            },
            threads: 2,
            configs: vec![
                row("plain copy", ConfigKind::Copy, 12.0, 0.0, 0.0),
                row("default <5×5> & co", ConfigKind::L3, 1200.0, 2.0, 2.5),
                row("patch 3", ConfigKind::L3, 600.0, 2.6, 3.0),
                row("patch 7", ConfigKind::L3, 2400.0, 2.1, 2.4),
                row("baseline", ConfigKind::Baseline, 300.0, 3.5, 4.0),
                row("ISP_D65+T", ConfigKind::Isp, 900.0, 3.0, 3.2),
            ],
            pareto: vec![
                ParetoFront {
                    illuminant: "Tungsten".into(),
                    metric: crate::bench::FrontMetric::DeltaE,
                    names: vec![
                        "baseline".into(),
                        "patch 3".into(),
                        "default <5×5> & co".into(),
                    ],
                },
                ParetoFront {
                    illuminant: "Fluorescent".into(),
                    metric: crate::bench::FrontMetric::DeltaE,
                    names: vec![
                        "baseline".into(),
                        "patch 3".into(),
                        "default <5×5> & co".into(),
                        "patch 7".into(),
                    ],
                },
            ],
            total_seconds: 100.0,
            options: BenchOptions::quick(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::sample_report;
    use super::*;

    #[test]
    fn markdown_has_a_row_per_configuration_with_aligned_columns() {
        let r = sample_report();
        let md = markdown_table(&r);
        // the main table: the first run of table lines
        let table: Vec<&str> = md
            .lines()
            .skip_while(|l| !l.starts_with('|'))
            .take_while(|l| l.starts_with('|'))
            .collect();
        assert_eq!(table.len(), 2 + r.configs.len(), "{md}");
        // then space beside colour: a row per configuration and light with colour results
        let spatial: Vec<&str> = md
            .lines()
            .skip_while(|l| !l.starts_with("| configuration | light | S-CIELAB chart"))
            .take_while(|l| l.starts_with('|'))
            .collect();
        let with_colour: usize = r.configs.iter().map(|c| c.colour.len()).sum();
        assert_eq!(spatial.len(), 2 + with_colour, "{md}");
        assert!(spatial[2].contains("| 0.300 |"), "{}", spatial[2]);
        let cols = table[0].matches('|').count();
        assert!(table.iter().all(|l| l.matches('|').count() == cols), "{md}");
        assert!(table[0].contains("ΔE Tungsten mean") && table[0].contains("ΔE Fluorescent p90"));
        // copy: no colour, no training; italic name
        assert!(
            table[2].starts_with("| *plain copy* | — | — | — | — | — |"),
            "{}",
            table[2]
        );
        // default row: mean 2.00, p90 4.00, per-pixel 3.00 and 6.00 at low light
        // under tungsten, then fluorescent; 100.0 ms/Mpix, on both fronts
        let d = table[3];
        assert!(
            d.contains("| 2.00 | 4.00 | 3.00 | 6.00 | 2.50 | 5.00 | 3.75 | 7.50 |"),
            "{d}"
        );
        assert!(
            d.contains("| 100.00 |") && d.ends_with("| Tungsten, Fluorescent |"),
            "{d}"
        );
        assert!(table[5].ends_with("| Fluorescent |"), "{}", table[5]);
        // the conventional rows in italics, the strong ISP's with its figures and off the fronts
        assert!(
            table[6].starts_with("| *baseline* | 2.5 | 3.50 |"),
            "{}",
            table[6]
        );
        assert!(
            table[7].starts_with("| *ISP_D65+T* | 2.5 | 3.00 | 6.00 | 4.50 | 9.00 |")
                && table[7].ends_with("| — |"),
            "{}",
            table[7]
        );
        assert!(
            spatial
                .iter()
                .any(|l| l.starts_with("| ISP_D65+T | Fluorescent |"))
        );
        assert!(md.contains("median of 2 runs"));
    }

    #[test]
    fn json_round_trips_with_the_schema() {
        let r = sample_report();
        let j = serde_json::to_string(&r).unwrap();
        let back: crate::bench::BenchReport = serde_json::from_str(&j).unwrap();
        // (serde_json's default float parsing may differ in the last bit)
        let names = |r: &crate::bench::BenchReport| -> Vec<String> {
            r.configs.iter().map(|c| c.name.clone()).collect()
        };
        assert_eq!(names(&back), names(&r));
        assert_eq!(back.configs[1].colour, r.configs[1].colour);
        assert_eq!(back.pareto, r.pareto);
        assert!(
            j.contains("\"schema\":\"l3.bench.v1\"") && j.contains("\"renderer\":\"reference\"")
        );
    }
}
