//! A real ColorChecker capture against published values: the frame rendered as `l3 render`
//! renders it (to XYZ referred to D65), the 24 patches found from the chart's four corners
//! ([`geometry`]), each sampled in its middle, scaled so the white patch matches the
//! reference's white, and compared in CIELAB (D65 white) with CIEDE2000 ([`mod@reference`]).
//!
//! Exposure is normalised on the white patch (patch 19): the rendered image is scaled so its
//! white patch has the reference white's Y (0.880 for X-Rite's, 0.815 for ISET's). It is the
//! brightest and least noisy sample, and what the chart evaluation of a simulated chart
//! normalises by (`evaluate_chart`), so the two agree (docs/accuracy.md). A clipped white patch
//! would darken every other patch: expose the chart so that it is not clipped.

pub mod geometry;
pub mod reference;

use serde::{Deserialize, Serialize};

use super::{ErrorStats, EvalError, summarize};
use crate::colour::{D65_WHITE_XYZ, Lab, Xyz, ciede2000, xyz_to_lab};
use crate::pipeline::{Encoded, RenderOutcome};
use crate::spectral::IsetData;
pub use geometry::{CLASSIC_GAP, Corners, OUTLIER_SIGMAS, SAMPLE_FRACTION};
pub use reference::{Measured, Reference, simulated_truth_csv};

/// Identifier of the report's JSON schema (documented in openapi.yaml).
pub const COLORCHECKER_SCHEMA: &str = "l3.colorchecker.v1";
/// The white patch (0-based): `white 9.5 (.05 D)`, patch 19.
pub const WHITE_PATCH: usize = 18;

/// How to find and score the chart.
#[derive(Clone, Debug, PartialEq)]
pub struct ColorCheckerOptions {
    pub corners: Corners,
    /// The gap between patches as a fraction of a patch's side ([`CLASSIC_GAP`] for a
    /// ColorChecker Classic; 0 for the simulator's chart, drawn edge to edge).
    pub gap: f64,
    pub reference: Reference,
}

/// One patch of the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColorCheckerPatch {
    /// 1–24, row by row from dark skin.
    pub index: usize,
    pub name: String,
    /// The reference's CIELAB and XYZ under D65 (a perfect white at Y = 1).
    pub reference_lab: Lab,
    pub reference_xyz: Xyz,
    /// The rendering's, after the white-patch scaling.
    pub rendered_lab: Lab,
    pub rendered_xyz: Xyz,
    pub delta_e: f64,
    /// ΔE2000 between this reference and its counterpart ([`Reference::counterpart`]: ISET's
    /// reflectances beside X-Rite's 2014 values, X-Rite's beside the others) for this patch,
    /// the counterpart scaled as the rendering is (its white patch at this one's Y).
    pub references_delta_e: f64,
    /// Pixels averaged, and the sample's centre in the frame.
    pub pixels: usize,
    pub centre: [f64; 2],
}

/// How the rendering was scaled onto the reference.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalisation {
    /// The patch whose Y is matched.
    pub patch: String,
    pub reference_y: f64,
    pub rendered_y: f64,
    /// The factor the rendered XYZ was multiplied by.
    pub scale: f64,
}

/// The sampling geometry used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Geometry {
    pub corners: Corners,
    pub gap: f64,
    pub sample_fraction: f64,
    /// Robust standard deviations beyond which a pixel is left out of its patch's mean.
    pub outlier_sigmas: f64,
}

/// The report of one ColorChecker capture (schema `l3.colorchecker.v1`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColorCheckerReport {
    pub schema: String,
    pub chart: String,
    pub method: String,
    /// The light the frame was rendered under.
    pub acquisition_illuminant: String,
    /// `xrite2014`, `iset` or `measured` ([`Reference::as_str`]).
    pub reference: String,
    pub reference_description: String,
    pub normalisation: Normalisation,
    /// ΔE2000 over the 24 patches.
    pub summary: ErrorStats,
    /// ΔE2000 between the reference and its counterpart over the 24 patches: how much of the
    /// error the choice of reference alone accounts for.
    pub references: ErrorStats,
    pub geometry: Geometry,
    pub patches: Vec<ColorCheckerPatch>,
    /// The frame, table, correction, where the light came from.
    pub context: serde_json::Value,
}

impl ColorCheckerReport {
    /// The two references `references` compares, by name: the report's own and its
    /// counterpart ([`Reference::counterpart`]), e.g. "X-Rite 2014 and ISET".
    pub fn references_label(&self) -> String {
        match self.reference.as_str() {
            "xrite2014" => "X-Rite 2014 and ISET".into(),
            "iset" => "ISET and X-Rite 2014".into(),
            _ => "the measured values and X-Rite 2014".into(),
        }
    }
}

/// The labels of a report: what rendered, under which light.
pub struct Labels<'a> {
    pub method: &'a str,
    pub illuminant: &'a str,
    pub context: serde_json::Value,
}

/// The XYZ image of a render to [`crate::pipeline::OutputFormat::F32`] (what `l3 render --out
/// frame.raw` writes), with its width and height.
pub fn rendered_xyz(out: RenderOutcome) -> Result<(Vec<f32>, usize, usize), EvalError> {
    let (w, h) = (out.rendered.width, out.rendered.height);
    let bytes = match out.rendered.output {
        Encoded::Whole(b) => b,
        Encoded::Framed { .. } => {
            return Err(EvalError::Invalid("the render is not float XYZ".into()));
        }
    };
    if bytes.len() != w * h * 12 {
        return Err(EvalError::Invalid(format!(
            "the render holds {} bytes, {w}×{h} float XYZ expected",
            bytes.len()
        )));
    }
    let xyz = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok((xyz, w, h))
}

/// Scores a rendered XYZ image (`width × height × 3`, interleaved, referred to D65) of a
/// ColorChecker against `opts.reference`: its patches sampled
/// ([`geometry::sample_patches`]), then scored ([`score_colorchecker`]).
pub fn evaluate_colorchecker(
    xyz: &[f32],
    width: usize,
    height: usize,
    opts: &ColorCheckerOptions,
    iset: Option<&IsetData>,
    labels: Labels,
) -> Result<ColorCheckerReport, EvalError> {
    let samples = geometry::sample_patches(xyz, width, height, &opts.corners, opts.gap)?;
    score_colorchecker(&samples, opts, iset, labels)
}

/// Scores the 24 patches sampled with `opts`' corners and gap against `opts.reference`.
/// Apart from the sampling, whose errors are about the corners and the gap (the chart's place
/// in the frame), what [`evaluate_colorchecker`] does.
pub fn score_colorchecker(
    samples: &[geometry::Sample],
    opts: &ColorCheckerOptions,
    iset: Option<&IsetData>,
    labels: Labels,
) -> Result<ColorCheckerReport, EvalError> {
    if samples.len() != geometry::ROWS * geometry::COLS {
        return Err(EvalError::Invalid(format!(
            "{} patch samples, a ColorChecker has {}",
            samples.len(),
            geometry::ROWS * geometry::COLS
        )));
    }
    let refs = opts.reference.patches(iset)?;
    let other = opts.reference.counterpart().patches(iset)?;
    let (reference_y, rendered_y) = (refs[WHITE_PATCH].xyz[1], samples[WHITE_PATCH].xyz[1]);
    if !(rendered_y.is_finite() && rendered_y > 0.0) {
        return Err(EvalError::Invalid(format!(
            "the white patch (19) has no signal in the rendering (Y {rendered_y}): check the corners and the exposure"
        )));
    }
    let scale = reference_y / rendered_y;
    // the other reference, scaled as the rendering is: its white patch at this one's Y
    let other_scale = reference_y / other[WHITE_PATCH].xyz[1];
    let other_lab: Vec<Lab> = other
        .iter()
        .map(|o| xyz_to_lab(o.xyz.map(|v| v * other_scale), D65_WHITE_XYZ))
        .collect();
    let patches: Vec<ColorCheckerPatch> = samples
        .iter()
        .zip(refs.iter().zip(&other_lab))
        .enumerate()
        .map(|(k, (s, (r, o)))| {
            let rendered_xyz = s.xyz.map(|v| v * scale);
            let rendered_lab = xyz_to_lab(rendered_xyz, D65_WHITE_XYZ);
            ColorCheckerPatch {
                index: k + 1,
                name: r.name.clone(),
                reference_lab: r.lab,
                reference_xyz: r.xyz,
                rendered_lab,
                rendered_xyz,
                delta_e: ciede2000(r.lab, rendered_lab),
                references_delta_e: ciede2000(r.lab, *o),
                pixels: s.pixels,
                centre: s.centre,
            }
        })
        .collect();
    if patches.iter().any(|p| !p.delta_e.is_finite()) {
        return Err(EvalError::Invalid(
            "non-finite ΔE (the rendering has non-finite values in a patch)".into(),
        ));
    }
    let de: Vec<f64> = patches.iter().map(|p| p.delta_e).collect();
    let between: Vec<f64> = patches.iter().map(|p| p.references_delta_e).collect();
    Ok(ColorCheckerReport {
        schema: COLORCHECKER_SCHEMA.into(),
        chart: "colorchecker".into(),
        method: labels.method.into(),
        acquisition_illuminant: labels.illuminant.into(),
        reference: opts.reference.as_str().into(),
        reference_description: opts.reference.describe(),
        normalisation: Normalisation {
            patch: refs[WHITE_PATCH].name.clone(),
            reference_y,
            rendered_y,
            scale,
        },
        summary: summarize(&de),
        references: summarize(&between),
        geometry: Geometry {
            corners: opts.corners,
            gap: opts.gap,
            sample_fraction: SAMPLE_FRACTION,
            outlier_sigmas: OUTLIER_SIGMAS,
        },
        patches,
        context: labels.context,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rendering that is the ISET reference itself, at another exposure, drawn with gaps:
    /// ΔE 0 against it after the white scaling; against X-Rite's, the references' own gap.
    #[test]
    fn a_perfect_rendering_scores_zero_against_its_own_reference() {
        let refs = Reference::Iset.patches(None).unwrap();
        // patches of 30 px, gaps of 3 px, and a border of 10 px
        let (p, g, b) = (30usize, 3usize, 10usize);
        let (gw, gh) = (6 * p + 5 * g, 4 * p + 3 * g);
        let (w, h) = (gw + 2 * b, gh + 2 * b);
        let mut xyz = vec![0.02f32; w * h * 3];
        for (k, r) in refs.iter().enumerate() {
            let (x0, y0) = (b + (k % 6) * (p + g), b + (k / 6) * (p + g));
            for y in y0..y0 + p {
                for x in x0..x0 + p {
                    for c in 0..3 {
                        xyz[(y * w + x) * 3 + c] = (r.xyz[c] * 0.37) as f32;
                    }
                }
            }
        }
        let corners: Corners = format!("{b},{b},{r},{b},{r},{d},{b},{d}", r = b + gw, d = b + gh)
            .parse()
            .unwrap();
        let labels = || Labels {
            method: "test",
            illuminant: "D65",
            context: serde_json::Value::Null,
        };
        let mut opts = ColorCheckerOptions {
            corners,
            gap: g as f64 / p as f64,
            reference: Reference::Iset,
        };
        let r = evaluate_colorchecker(&xyz, w, h, &opts, None, labels()).unwrap();
        assert_eq!(r.patches.len(), 24);
        assert!(r.summary.max < 1e-3, "{:?}", r.summary);
        assert!((r.normalisation.scale - 1.0 / 0.37).abs() < 1e-3);
        opts.reference = Reference::Xrite2014;
        let x = evaluate_colorchecker(&xyz, w, h, &opts, None, labels()).unwrap();
        for p in &x.patches {
            // the rendering is ISET's chart: its error is the references' difference
            assert!((p.delta_e - p.references_delta_e).abs() < 1e-3, "{p:?}");
        }
        let json = serde_json::to_value(&x).unwrap();
        assert_eq!(json["schema"], COLORCHECKER_SCHEMA);
        assert_eq!(json["reference"], "xrite2014");
        assert_eq!(json["patches"][0]["name"], "dark skin");
    }
}
