//! Which conventional baseline each L3 row is judged against, and the comparisons.

use super::rows::{BaselineComparison, BaselineFamily, ExposurePoint, PaperRow, PaperTable};

impl PaperTable {
    /// The row of `method` under `acquisition`.
    pub fn row(&self, acquisition: &str, method: &str) -> Option<&PaperRow> {
        self.rows
            .iter()
            .find(|r| r.acquisition.eq_ignore_ascii_case(acquisition) && r.method == method)
    }

    /// Whether this sensor's baseline is the all-channel variant: the one,
    /// of RGB and all channels, whose baseline rows (every acquisition and
    /// both fits, in pairs present in both variants) have the lower mean
    /// patch-mean ΔE at full exposure. One variant per sensor, as the
    /// acceptance asks ("on each sensor, use the one with the lower
    /// patch-mean ΔE"); a choice per light flips on differences of 0.01.
    pub fn all_channel_baseline(&self) -> bool {
        let (mut rgb, mut all, mut n) = (0.0, 0.0, 0usize);
        for r in self
            .rows
            .iter()
            .filter(|r| r.method.starts_with("Baseline"))
        {
            if r.method.ends_with(" all") {
                continue;
            }
            if let Some(a) = self.row(&r.acquisition, &format!("{} all", r.method)) {
                rgb += r.mean;
                all += a.mean;
                n += 1;
            }
        }
        n > 0 && all < rgb
    }

    /// The baseline row an L3 row is judged against: its family's row in
    /// the sensor's variant ([`Self::all_channel_baseline`]), or the other
    /// variant when that one is missing.
    pub fn baseline_for(&self, row: &PaperRow) -> Option<&PaperRow> {
        let stem = match row.baseline? {
            BaselineFamily::AcquisitionFit => format!("Baseline_{}", short(&row.acquisition)),
            BaselineFamily::D65FitThenT => "Baseline+T".to_string(),
            // `SI_Ens+T` against `Baseline_Ens+T`
            BaselineFamily::EnsembleFitThenT => row.method.replacen("SI_", "Baseline_", 1),
        };
        self.baseline_row(&row.acquisition, &stem)
    }

    /// The strong ISP row an L3 row is compared with: `ISP_<light>` for the rows judged
    /// against the acquisition fit, `ISP_D65+T` for the rest, in the sensor's baseline
    /// variant ([`Self::all_channel_baseline`]).
    pub fn isp_for(&self, row: &PaperRow) -> Option<&PaperRow> {
        let stem = match row.baseline? {
            BaselineFamily::AcquisitionFit => format!("ISP_{}", short(&row.acquisition)),
            BaselineFamily::D65FitThenT | BaselineFamily::EnsembleFitThenT => {
                "ISP_D65+T".to_string()
            }
        };
        self.baseline_row(&row.acquisition, &stem)
    }

    /// An ensemble row's D65-fit + T baseline, which judged the ensembles
    /// before [`BaselineFamily::EnsembleFitThenT`]: shown beside its own.
    pub fn d65_baseline_for(&self, row: &PaperRow) -> Option<&PaperRow> {
        (row.baseline? == BaselineFamily::EnsembleFitThenT)
            .then(|| self.baseline_row(&row.acquisition, "Baseline+T"))?
    }

    /// The baseline `stem` under `acquisition` in the sensor's variant, or
    /// the other variant when that one is missing.
    fn baseline_row(&self, acquisition: &str, stem: &str) -> Option<&PaperRow> {
        let all = format!("{stem} all");
        let (first, second) = if self.all_channel_baseline() {
            (all.as_str(), stem)
        } else {
            (stem, all.as_str())
        };
        self.row(acquisition, first)
            .or_else(|| self.row(acquisition, second))
    }

    pub(super) fn compare_with_baselines(&self) -> Vec<BaselineComparison> {
        self.rows
            .iter()
            .filter_map(|r| {
                let b = self.baseline_for(r)?;
                let ratio = |l: f64, b: f64| if b > 0.0 { l / b } else { f64::NAN };
                let mut pixel_ratios = vec![(1.0, ratio(r.pixel_mean, b.pixel_mean))];
                for p in &r.exposures {
                    if let Some(q) = b.exposures.iter().find(|q| q.factor == p.factor) {
                        pixel_ratios.push((p.factor, ratio(p.pixel_mean, q.pixel_mean)));
                    }
                }
                Some(BaselineComparison {
                    acquisition: r.acquisition.clone(),
                    method: r.method.clone(),
                    baseline: b.method.clone(),
                    mean_difference: r.mean - b.mean,
                    capture_mean_difference: r
                        .captures
                        .as_ref()
                        .zip(b.captures.as_ref())
                        .map(|(r, b)| r.mean - b.mean),
                    pixel_ratios,
                })
            })
            .collect()
    }

    /// The lowest exposure factor evaluated (the low-light column).
    pub(super) fn low_light(row: &PaperRow) -> Option<&ExposurePoint> {
        row.exposures
            .iter()
            .min_by(|a, b| a.factor.total_cmp(&b.factor))
    }

    /// The captures a run was evaluated on: 1, or [`PaperOptions::captures`].
    ///
    /// [`PaperOptions::captures`]: crate::eval::PaperOptions::captures
    pub fn n_captures(&self) -> usize {
        self.rows
            .iter()
            .filter_map(|r| r.captures.as_ref())
            .map(|c| c.per_capture.len())
            .max()
            .unwrap_or(1)
    }
}

/// The short name of an acquisition light in the row names (`Tun` for tungsten).
pub(crate) fn short(name: &str) -> String {
    match name.to_ascii_lowercase().as_str() {
        "tungsten" => "Tun".into(),
        "fluorescent" => "Flu".into(),
        _ => name.to_string(),
    }
}
