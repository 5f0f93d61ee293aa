//! The markdown of a Table 1 run, and the summary over several sensors' runs.

use super::rows::PaperTable;

impl PaperTable {
    /// With several captures: every row's mean over them beside its first
    /// capture and, for L3 rows, the matching linear map's; else nothing.
    fn captures_markdown(&self) -> String {
        let n = self.n_captures();
        if n < 2 {
            return String::new();
        }
        let seed = self.options.chart.seed;
        let mut s = format!(
            "\nOver {n} noisy captures of the chart (seeds {seed}–{}): each row's mean patch-mean ΔE2000 and its spread from capture to capture.\n\n\
             | acquisition | method | first capture | mean over {n} (std) | matching linear map over {n} | L3 − linear |\n|---|---|---|---|---|---|\n",
            seed.wrapping_add(n as u64 - 1)
        );
        for r in &self.rows {
            let Some(c) = &r.captures else { continue };
            let (lin, gap) = match c.linear_mean {
                Some(l) => (format!("{l:.2}"), format!("{:+.2}", c.mean - l)),
                None => ("—".into(), "—".into()),
            };
            s.push_str(&format!(
                "| {} | {} | {:.2} | {:.2} ({:.2}) | {lin} | {gap} |\n",
                r.acquisition, r.method, r.mean, c.mean, c.std
            ));
        }
        s
    }

    /// Every row's S-CIELAB on the chart and the texture, MTF50 and false colour at full
    /// exposure and at the lowest; nothing when the run left them out.
    fn spatial_markdown(&self) -> String {
        let has = |s: &super::rows::Spatial| s.s_cielab_mean.is_some() || s.mtf50.is_some();
        if !self.rows.iter().any(|r| has(&r.spatial)) {
            return String::new();
        }
        let px = self.options.spatial_px;
        let low = self
            .rows
            .first()
            .and_then(Self::low_light)
            .map(|p| format!("{}×", p.factor))
            .unwrap_or_else(|| "low light".into());
        let mut s = format!(
            "\nSpatial metrics (docs/accuracy.md, \"Sharpness and false colour\"): S-CIELAB mean ΔE2000 of the chart's and of a {px} px dead-leaves texture's render against their ideal images; MTF50 (cycles per pixel) of a {px} px slanted edge's rendered luminance and the C*ab the render adds at the neutral edge (false colour), at full exposure and at {low}.\n\n\
             | acquisition | method | S-CIELAB chart | S-CIELAB texture | MTF50 | false colour | S-CIELAB chart {low} | S-CIELAB texture {low} | MTF50 {low} | false colour {low} |\n\
             |---|---|---|---|---|---|---|---|---|---|\n"
        );
        let f = |v: Option<f64>, d: usize| v.map_or("—".to_string(), |v| format!("{v:.d$}"));
        let cells = |sp: Option<&super::rows::Spatial>| {
            let sp = sp.cloned().unwrap_or_default();
            format!(
                "{} | {} | {} | {}",
                f(sp.s_cielab_mean, 2),
                f(sp.s_cielab_texture, 2),
                f(sp.mtf50, 3),
                f(sp.false_colour, 2)
            )
        };
        for r in &self.rows {
            s.push_str(&format!(
                "| {} | {} | {} | {} |\n",
                r.acquisition,
                r.method,
                cells(Some(&r.spatial)),
                cells(Self::low_light(r).map(|p| &p.spatial))
            ));
        }
        s
    }

    /// Every L3 row against the strong ISP of its family ([`Self::isp_for`]): patch-mean
    /// difference and per-pixel ΔE ratio at each exposure; empty without ISP rows.
    fn isp_markdown(&self) -> String {
        let mut s = String::new();
        for r in &self.rows {
            let Some(isp) = self.isp_for(r) else { continue };
            if s.is_empty() {
                s.push_str("\nEach L3 row against the strong ISP (Malvar or gradient-corrected demosaic, noise-model denoiser, colour matrix) of its family: patch-mean difference, and per-pixel ΔE as a ratio L3 / ISP at each exposure factor.\n\n| acquisition | method | ISP | Δ patch mean | per-pixel L3/ISP |\n|---|---|---|---|---|\n");
            }
            let ratio = |l: f64, b: f64| if b > 0.0 { l / b } else { f64::NAN };
            let mut ratios = vec![format!("1×: {:.2}", ratio(r.pixel_mean, isp.pixel_mean))];
            for p in &r.exposures {
                if let Some(q) = isp.exposures.iter().find(|q| q.factor == p.factor) {
                    ratios.push(format!(
                        "{}×: {:.2}",
                        p.factor,
                        ratio(p.pixel_mean, q.pixel_mean)
                    ));
                }
            }
            s.push_str(&format!(
                "| {} | {} | {} | {:+.2} | {} |\n",
                r.acquisition,
                r.method,
                isp.method,
                r.mean - isp.mean,
                ratios.join(", ")
            ));
        }
        s
    }

    /// A markdown rendering beside the paper's figures.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "Natural-100 chart ({}), sensor `{}`, CIEDE2000 of patch means\n\n",
            self.chart, self.sensor
        );
        let low = self
            .rows
            .first()
            .and_then(Self::low_light)
            .map(|p| format!("per-pixel at {}×", p.factor))
            .unwrap_or_else(|| "low light".into());
        s.push_str(&format!("| acquisition | method | mean ΔE (std) | median | p90 | max | per-pixel mean | {low} | matching linear map | paper mean (std) / p90 |\n"));
        s.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
        for r in &self.rows {
            let paper = r
                .paper
                .map(|p| format!("{:.1} ({:.1}) / {:.1}", p[0], p[1], p[2]))
                .unwrap_or_else(|| "—".into());
            let linear = r
                .linear_mean
                .map(|v| format!("{v:.2}"))
                .unwrap_or_else(|| "—".into());
            let low = Self::low_light(r)
                .map(|p| format!("{:.2}", p.pixel_mean))
                .unwrap_or_else(|| "—".into());
            s.push_str(&format!(
                "| {} | {} | {:.2} ({:.2}) | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} |\n",
                r.acquisition,
                r.method,
                r.mean,
                r.std,
                r.median,
                r.p90,
                r.max,
                r.pixel_mean,
                low,
                linear,
                paper
            ));
        }
        s.push_str(&self.captures_markdown());
        s.push_str(&self.spatial_markdown());
        if !self.comparisons.is_empty() {
            s.push_str("\nEach L3 row against its conventional baseline (of RGB and all channels, the one with the lower mean patch-mean ΔE over this sensor's baseline rows at full exposure): patch-mean difference, and per-pixel ΔE as a ratio L3 / baseline at each exposure factor.\n\n");
            let several = self.n_captures() > 1;
            s.push_str(if several {
                "| acquisition | method | baseline | Δ patch mean | Δ over the captures | per-pixel L3/baseline |\n|---|---|---|---|---|---|\n"
            } else {
                "| acquisition | method | baseline | Δ patch mean | per-pixel L3/baseline |\n|---|---|---|---|---|\n"
            });
            for c in &self.comparisons {
                let ratios: Vec<String> = c
                    .pixel_ratios
                    .iter()
                    .map(|(f, r)| format!("{f}×: {r:.2}"))
                    .collect();
                let over = match (several, c.capture_mean_difference) {
                    (false, _) => String::new(),
                    (true, Some(d)) => format!(" {d:+.2} |"),
                    (true, None) => " — |".into(),
                };
                s.push_str(&format!(
                    "| {} | {} | {} | {:+.2} |{over} {} |\n",
                    c.acquisition,
                    c.method,
                    c.baseline,
                    c.mean_difference,
                    ratios.join(", ")
                ));
            }
        }
        s.push_str(&self.isp_markdown());
        let st = &self.storage;
        s.push_str(&format!(
            "\nStorage for {} illuminants: one SI table + {} matrices = {} bytes; {} cross-illuminant tables = {} bytes ({:.1}× more).\n",
            st.illuminants,
            st.illuminants,
            st.si_plus_matrices_bytes,
            st.illuminants,
            st.cross_tables_bytes,
            st.cross_tables_bytes as f64 / st.si_plus_matrices_bytes.max(1) as f64
        ));
        s
    }
}

/// One markdown table over several sensors' Table 1 runs: every L3 row with
/// its matching linear map and its baseline, so that a regression on any
/// sensor shows in one place.
pub fn paper_summary(tables: &[PaperTable]) -> String {
    let n = tables.iter().map(PaperTable::n_captures).max().unwrap_or(1);
    let (more, more_rule) = if n > 1 {
        (
            format!(
                " mean over {n} captures (std) | matching linear map over {n} | Δ over {n} vs baseline |"
            ),
            "---|---|---|",
        )
    } else {
        (String::new(), "")
    };
    let mut s = format!(
        "Table 1 on every sensor (patch-mean ΔE2000; per-pixel ΔE at full and lowest exposure)\n\n\
         | sensor | acquisition | method | mean | matching linear map | per-pixel | low light per-pixel | baseline | Δ mean vs baseline | low light L3/baseline |{more}\n\
         |---|---|---|---|---|---|---|---|---|---|{more_rule}\n",
    );
    let f2 = |v: Option<f64>| v.map(|v| format!("{v:.2}")).unwrap_or_else(|| "—".into());
    for t in tables {
        for r in t.rows.iter().filter(|r| r.linear_mean.is_some()) {
            let b = t.baseline_for(r);
            let low = PaperTable::low_light(r);
            let low_b = b.and_then(PaperTable::low_light);
            let over = match (&r.captures, n > 1) {
                (Some(c), true) => format!(
                    " {:.2} ({:.2}) | {} | {} |",
                    c.mean,
                    c.std,
                    f2(c.linear_mean),
                    b.and_then(|b| b.captures.as_ref())
                        .map(|bc| format!("{:+.2}", c.mean - bc.mean))
                        .unwrap_or_else(|| "—".into())
                ),
                (None, true) => " — | — | — |".into(),
                _ => String::new(),
            };
            s.push_str(&format!(
                "| {} | {} | {} | {:.2} | {} | {:.2} | {} | {} | {} | {} |{over}\n",
                t.sensor,
                r.acquisition,
                r.method,
                r.mean,
                f2(r.linear_mean),
                r.pixel_mean,
                f2(low.map(|p| p.pixel_mean)),
                b.map(|b| {
                    let d65 = t
                        .d65_baseline_for(r)
                        .map(|d| format!(" (D65 fit: {:.2}, {:+.2})", d.mean, r.mean - d.mean))
                        .unwrap_or_default();
                    format!("{} {:.2}{d65}", b.method, b.mean)
                })
                .unwrap_or_else(|| "—".into()),
                b.map(|b| format!("{:+.2}", r.mean - b.mean))
                    .unwrap_or_else(|| "—".into()),
                f2(low
                    .zip(low_b)
                    .map(|(l, b)| l.pixel_mean / b.pixel_mean.max(1e-12))),
            ));
        }
    }
    s
}
