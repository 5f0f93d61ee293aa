//! The ΔE2000 report: per patch, per category, summary statistics.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::EvalError;
use crate::colour::{D65_WHITE_XYZ, Lab, Xyz, ciede2000, xyz_to_lab};
use crate::scene::Patch;

/// Identifier of the report's JSON schema (documented in openapi.yaml).
pub const REPORT_SCHEMA: &str = "l3.delta_e.v1";

/// Mean, spread and tail of a set of ΔE values.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    pub n: usize,
    pub mean: f64,
    pub std: f64,
    pub median: f64,
    pub p90: f64,
    pub max: f64,
}

/// Per-pixel ΔE2000 over patch interiors (noise included).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PixelStats {
    pub n: usize,
    pub mean: f64,
    pub p90: f64,
}

/// One patch's result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PatchResult {
    pub name: String,
    pub category: String,
    /// Ideal XYZ under D65, normalised so the white patch has Y = 1.
    pub true_xyz: Xyz,
    /// Mean rendered XYZ over the patch interior, normalised by its white patch.
    pub est_xyz: Xyz,
    pub true_lab: Lab,
    pub est_lab: Lab,
    /// ΔE2000 of the patch means.
    pub delta_e: f64,
    /// Mean per-pixel ΔE2000 over the interior.
    pub pixel_delta_e: f64,
}

/// The ΔE report of one rendering of one chart.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeltaEReport {
    pub schema: String,
    pub chart: String,
    pub acquisition_illuminant: String,
    pub method: String,
    /// Summary over the chart samples (the grey strip excluded).
    pub summary: ErrorStats,
    pub per_pixel: PixelStats,
    pub per_category: BTreeMap<String, ErrorStats>,
    pub white_patch: String,
    pub patches: Vec<PatchResult>,
    /// S-CIELAB ([`crate::eval::scielab`], CIEDE2000, default viewing condition and filters)
    /// of the whole rendered image against the chart's ideal image, both normalised by their
    /// white patch; absent where the ideal image was not computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub s_cielab_mean: Option<f64>,
    /// The slanted edge rendered by this method and by its conventional rival, beside the
    /// edge's ideal image: the figure's sharpness panel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_panel: Option<crate::eval::EdgePanel>,
    /// Sharpness, false colour and texture S-CIELAB of the same method
    /// ([`crate::eval::spatial_score`]; flattened: `mtf50`, `mtf_at_half_nyquist`,
    /// `ideal_mtf50`, `false_colour`, `s_cielab_texture`), each absent where not measured.
    #[serde(flatten, default)]
    pub spatial: crate::eval::SpatialScore,
    /// Free-form context: exposure, table id, seeds, timings.
    pub context: serde_json::Value,
}

/// The chart's truth: its patches and their ideal XYZ under D65 (any scale).
pub struct ChartTruth<'a> {
    pub name: &'a str,
    pub patches: &'a [Patch],
    pub ideal_d65: &'a [Xyz],
}

/// Statistics of a list of values.
pub fn summarize(values: &[f64]) -> ErrorStats {
    let n = values.len();
    if n == 0 {
        return ErrorStats::default();
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
    let mut s = values.to_vec();
    s.sort_by(f64::total_cmp);
    ErrorStats {
        n,
        mean,
        std: var.sqrt(),
        median: percentile(&s, 0.5),
        p90: percentile(&s, 0.9),
        max: s[n - 1],
    }
}

/// Linear-interpolated percentile of sorted values (q in 0–1).
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let n = sorted.len();
    if n == 1 {
        return sorted[0];
    }
    let pos = q * (n - 1) as f64;
    let i = pos.floor() as usize;
    let f = pos - i as f64;
    if i + 1 >= n {
        sorted[n - 1]
    } else {
        sorted[i] * (1.0 - f) + sorted[i + 1] * f
    }
}

/// The interior of a patch: its rectangle shrunk by a margin that keeps the
/// kernel footprint and optical blur of the neighbours out.
pub fn interior(p: &Patch) -> (usize, usize, usize, usize) {
    let m = (p.height.min(p.width) / 5).max(3);
    let (h, w) = (
        p.height.saturating_sub(2 * m).max(1),
        p.width.saturating_sub(2 * m).max(1),
    );
    (p.row + (p.height - h) / 2, p.col + (p.width - w) / 2, h, w)
}

/// Mean of an interleaved XYZ image over each patch's interior.
pub fn patch_means(patches: &[Patch], xyz: &[f32], width: usize) -> Vec<Xyz> {
    patches
        .iter()
        .map(|p| {
            let (r0, c0, h, w) = interior(p);
            let mut s = [0f64; 3];
            for r in r0..r0 + h {
                for c in c0..c0 + w {
                    for k in 0..3 {
                        s[k] += xyz.get((r * width + c) * 3 + k).copied().unwrap_or(0.0) as f64;
                    }
                }
            }
            s.map(|v| v / (h * w) as f64)
        })
        .collect()
}

/// Which patches a chart's score counts: every patch but the grey strip.
pub fn scored_patches(patches: &[Patch]) -> Vec<bool> {
    patches.iter().map(|p| p.category != "grey").collect()
}

/// The chart's white patch, which both sides are normalised by: the grey
/// patch with the highest ideal Y (any patch, on a chart without greys).
pub fn white_patch_index(patches: &[Patch], ideal: &[Xyz]) -> usize {
    let greys: Vec<usize> = (0..patches.len().min(ideal.len()))
        .filter(|&i| patches[i].category == "grey")
        .collect();
    let pool: Vec<usize> = if greys.is_empty() {
        (0..patches.len().min(ideal.len())).collect()
    } else {
        greys
    };
    pool.iter()
        .copied()
        .max_by(|&a, &b| ideal[a][1].total_cmp(&ideal[b][1]))
        .unwrap_or(0)
}

/// Evaluate a rendered XYZ image (`width × height × 3`, interleaved) of a
/// chart. Both sides are normalised by their white patch (the grey patch
/// with the highest ideal Y) and compared in CIELAB with the D65 white.
pub fn evaluate_chart(
    truth: &ChartTruth,
    xyz: &[f32],
    width: usize,
    height: usize,
    acquisition: &str,
    method: &str,
    context: serde_json::Value,
) -> Result<DeltaEReport, EvalError> {
    check_chart(truth, xyz, width, height)?;
    let wi = white_patch_index(truth.patches, truth.ideal_d65);
    let means = patch_means(truth.patches, xyz, width);
    let y_true = truth.ideal_d65[wi][1];
    let y_est = means[wi][1];
    if !(y_true > 0.0 && y_est > 0.0 && y_est.is_finite()) {
        return Err(EvalError::Invalid(format!(
            "white patch '{}' has no signal (ideal Y {y_true}, rendered Y {y_est})",
            truth.patches[wi].name
        )));
    }
    let image = Normalised {
        xyz,
        width,
        y_true,
        y_est,
    };
    let mut results = Vec::with_capacity(truth.patches.len());
    let mut pixel_all = Vec::new();
    for (i, p) in truth.patches.iter().enumerate() {
        let (result, pix) = image.patch(p, truth.ideal_d65[i], means[i]);
        if p.category != "grey" {
            pixel_all.extend_from_slice(&pix);
        }
        results.push(result);
    }
    if results.iter().any(|r| !r.delta_e.is_finite()) {
        return Err(EvalError::Invalid(
            "non-finite ΔE (rendered image has non-finite values)".into(),
        ));
    }
    let main: Vec<f64> = results
        .iter()
        .filter(|r| r.category != "grey")
        .map(|r| r.delta_e)
        .collect();
    let main = if main.is_empty() {
        results.iter().map(|r| r.delta_e).collect()
    } else {
        main
    };
    let mut cats: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in &results {
        cats.entry(r.category.clone()).or_default().push(r.delta_e);
    }
    let pix_stats = summarize(&pixel_all);
    Ok(DeltaEReport {
        schema: REPORT_SCHEMA.to_string(),
        chart: truth.name.to_string(),
        acquisition_illuminant: acquisition.to_string(),
        method: method.to_string(),
        summary: summarize(&main),
        per_pixel: PixelStats {
            n: pix_stats.n,
            mean: pix_stats.mean,
            p90: pix_stats.p90,
        },
        per_category: cats.into_iter().map(|(k, v)| (k, summarize(&v))).collect(),
        white_patch: truth.patches[wi].name.clone(),
        patches: results,
        s_cielab_mean: None,
        edge_panel: None,
        spatial: Default::default(),
        context,
    })
}

/// Refuse an image of the wrong size, a truth whose patches and values differ in number,
/// and patches outside the image.
fn check_chart(
    truth: &ChartTruth,
    xyz: &[f32],
    width: usize,
    height: usize,
) -> Result<(), EvalError> {
    if xyz.len() != width * height * 3 {
        return Err(EvalError::Invalid(format!(
            "image has {} values, {width}×{height}×3 expected",
            xyz.len()
        )));
    }
    if truth.patches.len() != truth.ideal_d65.len() || truth.patches.is_empty() {
        return Err(EvalError::Invalid(
            "patches and ideal values differ in number".into(),
        ));
    }
    for p in truth.patches {
        if p.row + p.height > height || p.col + p.width > width || p.height == 0 || p.width == 0 {
            return Err(EvalError::Invalid(format!(
                "patch {} lies outside the image",
                p.name
            )));
        }
    }
    Ok(())
}

/// The rendered image and the white-patch Y of each side, which both are normalised by.
struct Normalised<'a> {
    xyz: &'a [f32],
    width: usize,
    y_true: f64,
    y_est: f64,
}

impl Normalised<'_> {
    /// One patch's result (from its ideal XYZ and its rendered mean) and the ΔE of each
    /// pixel of its interior.
    fn patch(&self, p: &Patch, ideal: Xyz, mean: Xyz) -> (PatchResult, Vec<f64>) {
        let (xyz, width, y_est) = (self.xyz, self.width, self.y_est);
        let white = D65_WHITE_XYZ;
        let t = ideal.map(|v| v / self.y_true);
        let e = mean.map(|v| v / y_est);
        let tl = xyz_to_lab(t, white);
        let el = xyz_to_lab(e, white);
        let de = ciede2000(tl, el);
        let (r0, c0, h, w) = interior(p);
        let mut pix = Vec::with_capacity(h * w);
        for r in r0..r0 + h {
            for c in c0..c0 + w {
                let o = (r * width + c) * 3;
                let px = [xyz[o], xyz[o + 1], xyz[o + 2]].map(|v| v as f64 / y_est);
                pix.push(ciede2000(tl, xyz_to_lab(px, white)));
            }
        }
        let pmean = pix.iter().sum::<f64>() / pix.len().max(1) as f64;
        let result = PatchResult {
            name: p.name.clone(),
            category: p.category.clone(),
            true_xyz: t,
            est_xyz: e,
            true_lab: tl,
            est_lab: el,
            delta_e: de,
            pixel_delta_e: pmean,
        };
        (result, pix)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectral::{Spectrum, WavelengthGrid};

    #[test]
    fn stats_match_hand_values() {
        let s = summarize(&[1.0, 2.0, 3.0, 4.0, 10.0]);
        assert_eq!(s.n, 5);
        assert!((s.mean - 4.0).abs() < 1e-12);
        assert!((s.median - 3.0).abs() < 1e-12);
        assert!((s.p90 - 7.6).abs() < 1e-12);
        assert_eq!(s.max, 10.0);
        assert!((s.std - (10.0f64).sqrt()).abs() < 1e-12);
        assert_eq!(summarize(&[]).n, 0);
    }

    fn patch(name: &str, cat: &str, row: usize, col: usize) -> Patch {
        Patch {
            name: name.into(),
            category: cat.into(),
            row,
            col,
            height: 10,
            width: 10,
            reflectance: Spectrum::constant(WavelengthGrid::default(), 0.5),
        }
    }

    #[test]
    fn a_perfect_rendering_scores_zero_at_any_scale() {
        let patches = vec![patch("w", "grey", 0, 0), patch("red", "Food", 0, 10)];
        let ideal = vec![[0.9, 0.95, 1.0], [0.3, 0.2, 0.1]];
        let (w, h) = (20, 10);
        let mut img = vec![0f32; w * h * 3];
        for r in 0..h {
            for c in 0..w {
                let v = if c < 10 { ideal[0] } else { ideal[1] };
                for k in 0..3 {
                    img[(r * w + c) * 3 + k] = (v[k] * 0.37) as f32; // any exposure scale
                }
            }
        }
        let t = ChartTruth {
            name: "t",
            patches: &patches,
            ideal_d65: &ideal,
        };
        let rep = evaluate_chart(&t, &img, w, h, "A", "test", serde_json::Value::Null).unwrap();
        assert!(rep.summary.mean < 1e-4, "{:?}", rep.summary);
        assert_eq!(rep.summary.n, 1);
        assert_eq!(rep.white_patch, "w");
        assert!(rep.per_category.contains_key("Food"));
        assert!(rep.per_pixel.mean < 1e-4);
        // wrong sizes and dark images are errors
        assert!(evaluate_chart(&t, &img[..30], w, h, "A", "x", serde_json::Value::Null).is_err());
        let dark = vec![0f32; w * h * 3];
        assert!(evaluate_chart(&t, &dark, w, h, "A", "x", serde_json::Value::Null).is_err());
    }
}
