//! How well the light is recovered from a frame, and what a wrong light costs in colour: for
//! each acquisition light, the Natural-100 chart and a dead-leaves texture are simulated; the
//! light is taken (a) from metadata, as a DNG's AsShotNeutral would give it (the camera's
//! white response under the light, matched to a colour temperature), and (b) estimated from
//! the mosaic by each [`NeutralStatistic`]. Each row gives the colour temperatures and the
//! chart's ΔE2000 with the known light, the metadata light and each estimate (SI tables; a
//! cross-illuminant table ignores the correction, so the light would not matter).

use serde::Serialize;

use super::{ChartSetup, EvalError, Method, evaluate_capture, simulate_chart};
use crate::camera::Camera;
use crate::l3::L3Table;
use crate::l3::correct::{IlluminantRegistry, NeutralStatistic};
use crate::l3::render::Mosaic;
use crate::l3::table::TableKind;
use crate::scene::{SceneKind, SceneOptions};
use crate::spectral::{IlluminantSpec, IsetData};

/// The lights of the study: the standard and measured ones, then a colour-temperature sweep.
pub const STUDY_LIGHTS: [&str; 13] = [
    "A",
    "Tungsten",
    "D50",
    "D65",
    "F2",
    "F11",
    "cct:2700",
    "cct:3500",
    "cct:4500",
    "cct:5500",
    "cct:6500",
    "cct:8000",
    "cct:10000",
];

/// One statistic's estimate on one scene.
#[derive(Clone, Debug, Serialize)]
pub struct EstimateResult {
    pub statistic: &'static str,
    pub cct: f64,
    /// |estimate − light's correlated colour temperature|, kelvin.
    pub cct_error: f64,
    /// The same in mireds (10⁶/K), the scale on which colour differences are even.
    pub mired_error: f64,
}

/// One acquisition light.
#[derive(Clone, Debug, Serialize)]
pub struct EstimationRow {
    pub light: String,
    /// The light's correlated colour temperature (from its white's chromaticity).
    pub cct: Option<f64>,
    /// Smooth (Planckian or daylight-like) lights, for which `cct:K` can stand in.
    pub smooth: bool,
    /// The colour temperature matched from the camera's white response (the metadata path).
    pub metadata_cct: f64,
    /// Chart ΔE2000 (mean of patch means) with the known light's correction.
    pub delta_e_known: f64,
    pub delta_e_metadata: f64,
    /// On the chart: per statistic, the estimate and the chart's ΔE with it.
    pub chart: Vec<(EstimateResult, f64)>,
    /// On the dead-leaves texture: per statistic, the estimate.
    pub dead_leaves: Vec<EstimateResult>,
}

/// The study over `lights` with `table` (an SI table) on its own sensor.
pub fn illuminant_estimation_study(
    table: &L3Table,
    lights: &[String],
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<Vec<EstimationRow>, EvalError> {
    if table.meta.kind != TableKind::SameIlluminant {
        return Err(EvalError::Invalid(
            "the illuminant estimation study needs a same-illuminant (si) table: a cross table ignores the correction".into(),
        ));
    }
    let grid = table.meta.grid;
    let camera = Camera::new(&table.sensor_design()?, grid, iset)
        .map_err(|e| EvalError::Invalid(e.to_string()))?;
    let mut registry = IlluminantRegistry::with_defaults(grid, iset)?;
    let statistics = [NeutralStatistic::GreyWorld, NeutralStatistic::BrightTiles];
    let method = Method::Table(table);
    let mut rows = Vec::with_capacity(lights.len());
    for light in lights {
        let known = registry.resolve(light, iset)?;
        let named = IlluminantSpec::parse(light)?.resolve(iset)?;
        let true_cct = known.cct;
        let delta_e = |entry: &crate::l3::correct::IlluminantEntry,
                       cap: &super::ChartCapture|
         -> Result<f64, EvalError> {
            Ok(evaluate_capture(&camera, cap, &method, "L3", entry, setup)?
                .summary
                .mean)
        };
        let cap = simulate_chart(&camera, light, iset, setup)?;
        let delta_e_known = delta_e(&known, &cap)?;
        let neutral = camera
            .white_neutral(&named.spd)
            .map_err(|e| EvalError::Invalid(e.to_string()))?;
        let metadata = table.illuminant_from_neutral(&neutral, iset)?;
        let delta_e_metadata = delta_e(&registry.resolve(&metadata.spec(), iset)?, &cap)?;
        let result = |statistic: NeutralStatistic, volts: &[f32], w: usize, h: usize| {
            let e = table.estimate_illuminant(&Mosaic::Volts(volts), w, h, statistic, iset)?;
            Ok::<_, EvalError>(EstimateResult {
                statistic: statistic.name(),
                cct: e.cct,
                cct_error: true_cct.map_or(f64::NAN, |t| (e.cct - t).abs()),
                mired_error: true_cct.map_or(f64::NAN, |t| (1e6 / e.cct - 1e6 / t).abs()),
            })
        };
        let mut chart = Vec::new();
        for s in statistics {
            let r = result(s, &cap.volts, cap.width, cap.height)?;
            let de = delta_e(&registry.resolve(&format!("cct:{}", r.cct), iset)?, &cap)?;
            chart.push((r, de));
        }
        let leaves = dead_leaves_frame(&camera, &named, iset, setup)?;
        let dead_leaves = statistics
            .iter()
            .map(|&s| result(s, &leaves.0, leaves.1, leaves.2))
            .collect::<Result<_, _>>()?;
        rows.push(EstimationRow {
            light: known.name.clone(),
            cct: true_cct,
            smooth: !light.to_ascii_uppercase().starts_with('F')
                && !light.eq_ignore_ascii_case("fluorescent"),
            metadata_cct: metadata.cct,
            delta_e_known,
            delta_e_metadata,
            chart,
            dead_leaves,
        });
    }
    Ok(rows)
}

/// The default dead-leaves texture simulated under `light`, as `setup` says: volts, width,
/// height.
fn dead_leaves_frame(
    camera: &Camera,
    light: &crate::spectral::NamedSpd,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<(Vec<f32>, usize, usize), EvalError> {
    let opts = SceneOptions::from_samples(*camera.grid(), &light.spd, light.name.clone())?
        .with_mean_luminance(setup.mean_luminance);
    let scene = SceneKind::DeadLeaves.build(iset, &opts, setup.seed)?;
    let cap = super::capture_scene(camera, &scene, setup)?;
    let (h, w) = cap.volts.dim();
    Ok((cap.volts.into_raw_vec_and_offset().0, w, h))
}

/// The study as a markdown table, with the medians over the smooth lights under it.
pub fn estimation_markdown(rows: &[EstimationRow]) -> String {
    let mut s = String::from(
        "| light | CCT | metadata CCT | ΔE known | ΔE metadata | grey world: chart CCT / ΔE / leaves CCT | bright tiles: chart CCT / ΔE / leaves CCT |\n|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let est = |i: usize| {
            format!(
                "{:.0} / {:.2} / {:.0}",
                r.chart[i].0.cct, r.chart[i].1, r.dead_leaves[i].cct
            )
        };
        s += &format!(
            "| {} | {} | {:.0} | {:.2} | {:.2} | {} | {} |\n",
            r.light,
            r.cct.map_or("—".into(), |c| format!("{c:.0}")),
            r.metadata_cct,
            r.delta_e_known,
            r.delta_e_metadata,
            est(0),
            est(1)
        );
    }
    let smooth: Vec<&EstimationRow> = rows.iter().filter(|r| r.smooth).collect();
    if !smooth.is_empty() {
        for (i, name) in ["grey world", "bright tiles"].iter().enumerate() {
            let med = |mut v: Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            let chart_err = med(smooth.iter().map(|r| r.chart[i].0.cct_error).collect());
            let leaves_err = med(smooth.iter().map(|r| r.dead_leaves[i].cct_error).collect());
            let de_gap = smooth
                .iter()
                .map(|r| r.chart[i].1 - r.delta_e_known)
                .fold(f64::NEG_INFINITY, f64::max);
            s += &format!(
                "\n{name}, smooth lights: median CCT error {chart_err:.0} K on the chart, {leaves_err:.0} K on dead leaves; largest ΔE over the known light's {de_gap:+.2}"
            );
        }
        let meta_gap = smooth
            .iter()
            .map(|r| r.delta_e_metadata - r.delta_e_known)
            .fold(f64::NEG_INFINITY, f64::max);
        s += &format!(
            "\nmetadata (AsShotNeutral), smooth lights: largest ΔE over the known light's {meta_gap:+.2}\n"
        );
    }
    s
}
