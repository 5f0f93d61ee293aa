//! ΔE2000 evaluations: simulate the chart through a table's sensor, render it, compare with the
//! ideal XYZ; the report is persisted and listed.

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path as UrlPath, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};

use super::ServiceError;
use super::state::{AppState, new_id, now_ms};
use super::store::EvaluationRow;
use crate::camera::{Camera, SensorDesign};
use crate::eval::{ChartSetup, LightLevel, Method, evaluate_method, fit_baseline_matrix};
use crate::spectral::WavelengthGrid;

/// Charts an evaluation can use.
pub const CHARTS: [&str; 1] = ["natural100"];

/// The body of `POST /v1/evaluations`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvaluationRequest {
    /// Table to evaluate (default: the active one). Ignored by `baseline`.
    #[serde(default)]
    pub table_id: Option<String>,
    /// `l3` (default) or `baseline` (bilinear + 3×3 matrix fitted under D65, then T).
    #[serde(default = "default_method")]
    pub method: String,
    #[serde(default = "default_chart")]
    pub chart: String,
    /// Illuminant the chart is captured under (default Tungsten).
    #[serde(default = "default_acq")]
    pub acquisition_illuminant: String,
    #[serde(default = "default_seed")]
    pub seed: u64,
    #[serde(default = "default_true")]
    pub noise: bool,
    /// Side of each chart patch in pixels (8–64, default 24).
    #[serde(default = "default_patch_px")]
    pub patch_px: usize,
    /// Exposure time relative to auto-exposure, in (0, 1] (default 1).
    #[serde(default)]
    pub exposure_factor: Option<f64>,
    /// Mean chart luminance in cd/m² (instead of `exposure_factor`): below
    /// 100 cd/m² the camera holds its longest exposure.
    #[serde(default)]
    pub scene_luminance: Option<f64>,
}

impl EvaluationRequest {
    /// The chart set-up the request asks for, or a 400 naming what is wrong.
    fn chart_setup(&self) -> Result<ChartSetup, ServiceError> {
        let chart = ChartSetup {
            seed: self.seed,
            noise: self.noise,
            patch_px: self.patch_px,
            ..ChartSetup::default()
        };
        let light = match (self.exposure_factor, self.scene_luminance) {
            (Some(_), Some(_)) => {
                return Err(ServiceError::BadRequest(
                    "give exposure_factor or scene_luminance, not both".into(),
                ));
            }
            (Some(f), None) => LightLevel::ExposureFactor(f),
            (None, Some(l)) => LightLevel::SceneLuminance(l),
            (None, None) => return Ok(chart),
        };
        light
            .apply(&chart)
            .map_err(|e| ServiceError::BadRequest(e.to_string()))
    }
}

fn default_method() -> String {
    "l3".into()
}
fn default_chart() -> String {
    "natural100".into()
}
fn default_acq() -> String {
    "Tungsten".into()
}
fn default_seed() -> u64 {
    7
}
fn default_true() -> bool {
    true
}
fn default_patch_px() -> usize {
    24
}

fn evaluation_json(row: &EvaluationRow) -> Result<Value, ServiceError> {
    let id = &row.id;
    let report: Value = serde_json::from_str(&row.report_json)
        .map_err(|e| ServiceError::Internal(format!("stored report {id}: {e}")))?;
    let request: Value = serde_json::from_str(&row.request_json).unwrap_or(Value::Null);
    Ok(json!({
        "id": id,
        "table_id": row.table_id,
        "method": row.method,
        "chart": row.chart,
        "acquisition_illuminant": row.acquisition_illuminant,
        "mean_delta_e": row.mean_delta_e,
        "created_at_ms": row.created_at,
        "request": request,
        "report": report,
        "links": { "self": format!("/v1/evaluations/{id}") },
    }))
}

async fn evaluation_row(state: &AppState, id: &str) -> Result<EvaluationRow, ServiceError> {
    state
        .store
        .evaluation(id)
        .await?
        .ok_or_else(|| ServiceError::NotFound(format!("no evaluation with id '{id}'")))
}

/// `POST /v1/evaluations`: runs the evaluation (on rayon) and answers 201 with the ΔE JSON.
pub async fn create(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ServiceError> {
    super::render::require_json(&headers)?;
    let body = super::render::body_bytes(body, state.config.server.max_body_bytes)?;
    let mut value: Value = serde_json::from_slice(&body)
        .map_err(|e| ServiceError::InvalidJson(format!("evaluation request: {e}")))?;
    super::jobs::integral_floats_to_ints(&mut value);
    if !value.is_object() {
        // (serde would read a struct from an array too, field by field)
        return Err(ServiceError::InvalidJson(
            "evaluation request: the body must be a JSON object".into(),
        ));
    }
    let req: EvaluationRequest = serde_json::from_value(value)
        .map_err(|e| ServiceError::InvalidJson(format!("evaluation request: {e}")))?;
    if !CHARTS.contains(&req.chart.as_str()) {
        return Err(ServiceError::BadRequest(format!(
            "chart '{}': one of {}",
            req.chart,
            CHARTS.join(", ")
        )));
    }
    if !(8..=64).contains(&req.patch_px) {
        return Err(ServiceError::BadRequest(format!(
            "patch_px {}: 8 to 64",
            req.patch_px
        )));
    }
    let chart = req.chart_setup()?;
    let is_l3 = match req.method.as_str() {
        "l3" => true,
        "baseline" => false,
        other => {
            return Err(ServiceError::BadRequest(format!(
                "method '{other}': l3 or baseline"
            )));
        }
    };
    let lower = req.acquisition_illuminant.to_ascii_lowercase();
    if lower.starts_with("csv:") || lower.starts_with("iset:") || lower.starts_with("xy:") {
        return Err(ServiceError::UnknownIlluminant(format!(
            "acquisition illuminant '{}': use a named illuminant or cct:K (its spectrum is needed to simulate the chart)",
            req.acquisition_illuminant
        )));
    }
    let correction = state.resolve_illuminant(&req.acquisition_illuminant)?;
    let table = if is_l3 {
        match &req.table_id {
            Some(id) => {
                if state.active.load().as_ref().is_some_and(|a| &a.id == id) {
                    state.active.load_full()
                } else {
                    // load through activation's checks without activating
                    let (_, t, _, _) = super::tables::load_verified(&state, id).await?;
                    let id2 = id.clone();
                    Some(std::sync::Arc::new(super::state::ActiveTable {
                        id: id2,
                        sha256: String::new(),
                        table: t,
                    }))
                }
            }
            None => Some(state.active.load_full().ok_or_else(|| {
                ServiceError::NotReady("no table is active yet and no table_id was given".into())
            })?),
        }
    } else {
        None
    };
    let slot =
        state
            .eval_slots
            .clone()
            .try_acquire_owned()
            .map_err(|_| ServiceError::Overloaded {
                msg: "evaluations are already running at capacity; retry shortly".into(),
                retry_after_s: 2,
            })?;
    let table_id = table.as_ref().map(|t| t.id.clone());
    let iset = state.iset.clone();
    let r2 = req.clone();
    let pool_state = state.clone();
    let report = super::cpu::run(&pool_state.pools.background, "the evaluation", move || {
        let run = || -> Result<crate::eval::DeltaEReport, ServiceError> {
            let grid = WavelengthGrid::default();
            let design = match &table {
                Some(t) => t
                    .table
                    .sensor_design()
                    .map_err(|e| ServiceError::from_l3(e, ServiceError::Unprocessable))?,
                None => SensorDesign::paper_default(),
            };
            let camera = Camera::new(&design, grid, iset.as_ref())
                .map_err(|e| ServiceError::from_camera(e, ServiceError::Unprocessable))?;
            let eval_err =
                |e: crate::eval::EvalError| ServiceError::from_eval(e, ServiceError::Unprocessable);
            let mut report = match &table {
                Some(t) => {
                    let name = format!(
                        "L3 {} ({})",
                        t.table.meta.kind,
                        t.table.meta.train_illuminants.join("+")
                    );
                    evaluate_method(
                        &camera,
                        &Method::Table(&t.table),
                        &name,
                        &r2.acquisition_illuminant,
                        &correction,
                        iset.as_ref(),
                        &chart,
                    )
                    .map_err(eval_err)?
                }
                None => {
                    let m = fit_baseline_matrix(&camera, &["D65".to_string()], iset.as_ref())
                        .map_err(eval_err)?;
                    evaluate_method(
                        &camera,
                        &Method::Baseline(&m),
                        "Baseline+T",
                        &r2.acquisition_illuminant,
                        &correction,
                        iset.as_ref(),
                        &chart,
                    )
                    .map_err(eval_err)?
                }
            };
            if let Value::Object(m) = &mut report.context {
                m.insert(
                    "table_id".into(),
                    json!(table.as_ref().map(|t| t.id.clone())),
                );
            }
            Ok(report)
        };
        let report = run();
        drop(slot);
        report
    })
    .await??;
    let id = new_id("eval");
    let report_json = serde_json::to_string(&report)
        .map_err(|e| ServiceError::Internal(format!("report: {e}")))?;
    let request_json = String::from_utf8_lossy(&body).to_string();
    let row = EvaluationRow {
        id: id.clone(),
        table_id: table_id.clone(),
        method: req.method.clone(),
        chart: req.chart.clone(),
        acquisition_illuminant: req.acquisition_illuminant.clone(),
        mean_delta_e: report.summary.mean,
        request_json,
        report_json,
        created_at: now_ms(),
    };
    state.store.insert_evaluation(&row).await?;
    let mut resp = (StatusCode::CREATED, Json(evaluation_json(&row)?)).into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/evaluations/{id}")) {
        resp.headers_mut().insert(header::LOCATION, v);
    }
    Ok(resp)
}

/// `GET /v1/evaluations`
pub async fn list(State(state): State<AppState>) -> Result<Json<Value>, ServiceError> {
    let rows = state.store.evaluations().await?;
    let items = rows
        .iter()
        .map(|r| {
            evaluation_json(r).map(|mut v| {
                // the list omits the per-patch detail
                if let Some(rep) = v.get_mut("report").and_then(Value::as_object_mut) {
                    rep.remove("patches");
                }
                v
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Json(json!({ "items": items })))
}

/// What `GET /v1/evaluations/{id}` answers with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EvaluationFormat {
    /// The evaluation as JSON (`application/json`).
    Json,
    /// The report's figure (`image/svg+xml`): ΔE histogram, chromaticity, lightness and the
    /// worst patches' swatches.
    Svg,
}

impl EvaluationFormat {
    fn content_type(self) -> &'static str {
        match self {
            EvaluationFormat::Json => "application/json",
            EvaluationFormat::Svg => "image/svg+xml",
        }
    }
}

/// Chooses the answer of `GET /v1/evaluations/{id}` from an `Accept` header (q-values
/// honoured, the first of equal preference wins). JSON unless the client prefers
/// `image/svg+xml` (or `image/*`); a header naming neither also gets JSON.
pub fn negotiate(accept: Option<&str>) -> EvaluationFormat {
    let Some(accept) = accept.map(str::trim).filter(|a| !a.is_empty()) else {
        return EvaluationFormat::Json;
    };
    super::accept::preferred(accept, |media| match media {
        "application/json" | "application/*" | "*/*" => Some(EvaluationFormat::Json),
        "image/svg+xml" | "image/*" => Some(EvaluationFormat::Svg),
        _ => None,
    })
    .unwrap_or(EvaluationFormat::Json)
}

/// `GET /v1/evaluations/{id}`: the evaluation as JSON, or its figure as SVG (by `Accept`).
pub async fn get(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let format = negotiate(headers.get(header::ACCEPT).and_then(|v| v.to_str().ok()));
    let row = evaluation_row(&state, &id).await?;
    let mut resp = match format {
        EvaluationFormat::Json => Json(evaluation_json(&row)?).into_response(),
        EvaluationFormat::Svg => {
            let report: crate::eval::DeltaEReport = serde_json::from_str(&row.report_json)
                .map_err(|e| ServiceError::Internal(format!("stored report {id}: {e}")))?;
            let svg = crate::eval::report_svg(&report)
                .map_err(|e| ServiceError::Internal(format!("figure of evaluation {id}: {e}")))?;
            svg.into_response()
        }
    };
    let h = resp.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(format.content_type()),
    );
    h.insert(header::VARY, HeaderValue::from_static("Accept"));
    Ok(resp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accept_negotiation() {
        use EvaluationFormat::{Json, Svg};
        assert_eq!(negotiate(None), Json);
        assert_eq!(negotiate(Some("")), Json);
        assert_eq!(negotiate(Some("*/*")), Json);
        assert_eq!(negotiate(Some("application/json")), Json);
        assert_eq!(negotiate(Some("image/svg+xml")), Svg);
        assert_eq!(negotiate(Some("IMAGE/SVG+XML; charset=utf-8")), Svg);
        assert_eq!(
            negotiate(Some("application/json;q=0.5, image/svg+xml")),
            Svg
        );
        assert_eq!(negotiate(Some("image/svg+xml;q=0.4, */*;q=0.8")), Json);
        assert_eq!(negotiate(Some("image/svg+xml;q=0, application/json")), Json);
        assert_eq!(negotiate(Some("text/html, image/*;q=0.2")), Svg);
        assert_eq!(negotiate(Some("text/html")), Json);
    }
}
