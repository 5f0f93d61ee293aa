//! Where a method's patch-mean error comes from once the chart is captured
//! with noise: the noise a single capture leaves in its patch means, the
//! bias that remains when many captures are averaged, and the noise-free
//! capture (optics and demosaicking, no noise).
//!
//! A patch mean averages only the patch interior (16 × 16 pixels on the
//! default 24-pixel chart, 64 samples per RGBW channel), so on a sensor
//! whose colour map amplifies noise one capture's patch means still carry
//! visible noise. Averaging the patch means of `n` captures with different
//! noise seeds divides that residual by √n and leaves the bias: what the
//! method would give on large patches or a stack of frames.

use serde::{Deserialize, Serialize};

use super::workflow::{ChartSetup, Method, evaluate_capture, evaluate_method, simulate_chart};
use super::{DeltaEReport, ErrorStats, EvalError, summarize};
use crate::baseline::NoiseProfile;
use crate::camera::Camera;
use crate::colour::{D65_WHITE_XYZ, Xyz, ciede2000, xyz_to_lab};
use crate::l3::correct::IlluminantEntry;
use crate::spectral::IsetData;

/// Fewest captures a split is computed from.
pub const MIN_CAPTURES: usize = 2;
/// Most captures a split is computed from.
pub const MAX_CAPTURES: usize = 64;

/// Refuse a number of captures outside [`MIN_CAPTURES`]..=[`MAX_CAPTURES`]
/// for `what` (the study, named in the error).
pub(super) fn check_captures(captures: usize, what: &str) -> Result<(), EvalError> {
    if (MIN_CAPTURES..=MAX_CAPTURES).contains(&captures) {
        Ok(())
    } else {
        Err(EvalError::Invalid(format!(
            "{captures} captures: {what} takes {MIN_CAPTURES} to {MAX_CAPTURES}"
        )))
    }
}

/// A method's patch-mean ΔE2000 on the chart, split by noise.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct NoiseSplit {
    /// The noise seeds of the captures (the set-up's seed, then the next ones).
    pub seeds: Vec<u64>,
    /// Mean patch-mean ΔE of each capture (grey strip excluded).
    pub per_capture: Vec<f64>,
    /// Statistics of `per_capture`: what one capture gives, and its spread.
    pub per_capture_stats: ErrorStats,
    /// ΔE of the patch means averaged over every capture: the bias, with
    /// the residual noise divided by √n.
    pub averaged: ErrorStats,
    /// The same chart captured without noise.
    pub noise_free: ErrorStats,
}

/// A method rendering the chart under one acquisition light: what [`noise_split`] splits.
pub struct MethodOnChart<'a> {
    pub camera: &'a Camera,
    pub method: &'a Method<'a>,
    pub method_name: &'a str,
    pub acquisition: &'a str,
    pub correction: &'a IlluminantEntry,
    pub iset: Option<&'a IsetData>,
}

impl MethodOnChart<'_> {
    /// The method's report on the chart simulated with `setup`.
    pub fn evaluate(&self, setup: &ChartSetup) -> Result<DeltaEReport, EvalError> {
        evaluate_method(
            self.camera,
            self.method,
            self.method_name,
            self.acquisition,
            self.correction,
            self.iset,
            setup,
        )
    }

    /// [`Self::evaluate`] with the S-CIELAB of the whole render against the chart's ideal
    /// image (`DeltaEReport::s_cielab_mean`).
    pub fn evaluate_with_s_cielab(&self, setup: &ChartSetup) -> Result<DeltaEReport, EvalError> {
        let cap = simulate_chart(self.camera, self.acquisition, self.iset, setup)?
            .with_ideal_image(self.camera)?;
        evaluate_capture(
            self.camera,
            &cap,
            self.method,
            self.method_name,
            self.correction,
            setup,
        )
    }

    /// [`Self::evaluate_with_s_cielab`] with the spatial metrics of the same method under the
    /// same set-up ([`super::spatial_score`]: sharpness and false colour on a slanted edge,
    /// S-CIELAB on a texture; `DeltaEReport::spatial`).
    ///
    /// The report also gets the figure's edge panel ([`DeltaEReport::edge_panel`]): the
    /// edge's ideal image, this method's render and the strong ISP fitted under the
    /// acquisition light ([`super::acquisition_isp`]), on the same capture.
    pub fn evaluate_with_spatial(&self, setup: &ChartSetup) -> Result<DeltaEReport, EvalError> {
        use super::{EdgePanel, SPATIAL_SIZE, method_correction, render_method, simulate_spatial};
        let mut report = self.evaluate_with_s_cielab(setup)?;
        let (camera, cfa) = (self.camera, self.camera.cfa());
        let caps = simulate_spatial(camera, self.acquisition, self.iset, setup, SPATIAL_SIZE)?;
        report.spatial = caps.score(camera, self.method, self.correction)?;
        let e = &caps.edge;
        let corr = method_correction(camera, self.method, self.correction)?;
        let size = (e.width, e.height);
        let own = render_method(
            self.method,
            &corr,
            &e.volts,
            size,
            cfa,
            setup.chroma_denoise,
        )?;
        let isp = super::acquisition_isp(camera, self.acquisition, self.iset, setup.noise)?;
        let isp = isp.with_noise(isp.noise().map(|_| NoiseProfile::new(camera, e.exposure_s)));
        let identity = IlluminantEntry {
            t: crate::l3::correct::IDENTITY,
            ..self.correction.clone()
        };
        let rival = render_method(
            &Method::Isp(&isp),
            &identity,
            &e.volts,
            size,
            cfa,
            setup.chroma_denoise,
        )?;
        // by the light's resolved name (a light given by its samples goes by its own)
        let rival_name = format!("ISP_{}", super::paper_table::short(&e.acquisition));
        report.edge_panel = Some(EdgePanel::new(
            e,
            &[(self.method_name.to_string(), own), (rival_name, rival)],
        )?);
        Ok(report)
    }
}

/// Evaluate `m` on `captures` noisy captures of the chart (seeds
/// `setup.seed`, `setup.seed + 1`, …) and once without noise; see
/// [`NoiseSplit`].
pub fn noise_split(
    m: &MethodOnChart,
    setup: &ChartSetup,
    captures: usize,
) -> Result<NoiseSplit, EvalError> {
    check_captures(captures, "a noise split")?;
    let eval = |seed: u64, noise: bool| {
        let s = ChartSetup {
            seed,
            noise,
            ..setup.clone()
        };
        m.evaluate(&s)
    };
    let seeds: Vec<u64> = (0..captures as u64)
        .map(|k| setup.seed.wrapping_add(k))
        .collect();
    let reports = seeds
        .iter()
        .map(|&s| eval(s, true))
        .collect::<Result<Vec<_>, _>>()?;
    let per_capture: Vec<f64> = reports.iter().map(|r| r.summary.mean).collect();
    Ok(NoiseSplit {
        per_capture_stats: summarize(&per_capture),
        averaged: averaged_patch_means(&reports)?,
        noise_free: eval(setup.seed, false)?.summary,
        seeds,
        per_capture,
    })
}

/// ΔE2000 statistics (grey strip excluded) of the patch means averaged
/// over `reports` of the same chart, each normalised by its white patch.
pub fn averaged_patch_means(reports: &[DeltaEReport]) -> Result<ErrorStats, EvalError> {
    let first = reports
        .first()
        .ok_or_else(|| EvalError::Invalid("no reports to average".into()))?;
    let n = first.patches.len();
    if reports.iter().any(|r| r.patches.len() != n) {
        return Err(EvalError::Invalid(
            "the reports are of different charts".into(),
        ));
    }
    let mut de = Vec::with_capacity(n);
    for (i, p) in first.patches.iter().enumerate() {
        if p.category == "grey" {
            continue;
        }
        let mut sum: Xyz = [0.0; 3];
        for r in reports {
            for (s, v) in sum.iter_mut().zip(r.patches[i].est_xyz) {
                *s += v;
            }
        }
        let mean = sum.map(|v| v / reports.len() as f64);
        de.push(ciede2000(p.true_lab, xyz_to_lab(mean, D65_WHITE_XYZ)));
    }
    if de.iter().any(|d| !d.is_finite()) {
        return Err(EvalError::Invalid("non-finite averaged ΔE".into()));
    }
    Ok(summarize(&de))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::PatchResult;

    fn report(est: [f64; 3]) -> DeltaEReport {
        let t = [0.3, 0.3, 0.3];
        let patch = |name: &str, category: &str, e: [f64; 3]| PatchResult {
            name: name.into(),
            category: category.into(),
            true_xyz: t,
            est_xyz: e,
            true_lab: xyz_to_lab(t, D65_WHITE_XYZ),
            est_lab: xyz_to_lab(e, D65_WHITE_XYZ),
            delta_e: ciede2000(xyz_to_lab(t, D65_WHITE_XYZ), xyz_to_lab(e, D65_WHITE_XYZ)),
            pixel_delta_e: 0.0,
        };
        DeltaEReport {
            schema: String::new(),
            chart: "c".into(),
            acquisition_illuminant: "D65".into(),
            method: "m".into(),
            summary: ErrorStats::default(),
            per_pixel: Default::default(),
            per_category: Default::default(),
            white_patch: "w".into(),
            patches: vec![patch("a", "Food", est), patch("w", "grey", [1.0; 3])],
            s_cielab_mean: None,
            edge_panel: None,
            spatial: Default::default(),
            context: serde_json::Value::Null,
        }
    }

    #[test]
    fn averaging_cancels_symmetric_noise_and_keeps_bias() {
        // two captures whose errors cancel: the average is exact
        let a =
            averaged_patch_means(&[report([0.33, 0.3, 0.3]), report([0.27, 0.3, 0.3])]).unwrap();
        assert!(a.mean < 1e-9, "{}", a.mean);
        assert_eq!(a.n, 1, "the grey strip is left out");
        // a common offset (bias) survives averaging
        let b =
            averaged_patch_means(&[report([0.33, 0.3, 0.3]), report([0.33, 0.3, 0.3])]).unwrap();
        assert!(b.mean > 1.0, "{}", b.mean);
    }

    #[test]
    fn s_cielab_is_reported_against_the_ideal_image_when_asked() {
        use crate::eval::{fit_baseline_matrix, simulate_chart};
        let camera = crate::test_support::paper_camera();
        let matrix = fit_baseline_matrix(&camera, &["D65".to_string()], None).unwrap();
        let correction =
            crate::l3::correct::IlluminantRegistry::with_defaults(*camera.grid(), None)
                .unwrap()
                .resolve("Tungsten", None)
                .unwrap();
        let method = Method::Baseline(&matrix);
        let m = MethodOnChart {
            camera: &camera,
            method: &method,
            method_name: "Baseline+T",
            acquisition: "Tungsten",
            correction: &correction,
            iset: None,
        };
        let setup = ChartSetup {
            patch_px: 8,
            noise: false,
            ..ChartSetup::default()
        };
        assert_eq!(m.evaluate(&setup).unwrap().s_cielab_mean, None);
        let s = m
            .evaluate_with_s_cielab(&setup)
            .unwrap()
            .s_cielab_mean
            .unwrap();
        assert!(s.is_finite() && s > 0.0, "{s}");
        // the ideal image scored against itself, at another scale: no error
        let cap = simulate_chart(&camera, "Tungsten", None, &setup)
            .unwrap()
            .with_ideal_image(&camera)
            .unwrap();
        let ideal: Vec<f32> = cap.ideal_image.clone().unwrap();
        let scaled: Vec<f32> = ideal.iter().map(|v| v * 2.0).collect();
        let r = cap
            .score(&scaled, "ideal", serde_json::Value::Null)
            .unwrap();
        assert!(r.s_cielab_mean.unwrap() < 1e-9, "{:?}", r.s_cielab_mean);
    }

    #[test]
    fn mismatched_or_empty_reports_are_refused() {
        assert!(averaged_patch_means(&[]).is_err());
        let mut r = report([0.3; 3]);
        r.patches.pop();
        assert!(averaged_patch_means(&[report([0.3; 3]), r]).is_err());
    }
}
