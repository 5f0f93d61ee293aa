//! ΔE2000 evaluations: simulate the chart through a table's sensor, render it, compare with the
//! ideal XYZ; or, with a frame as the body, a ColorChecker capture ([`super::colorchecker`]).
//! The report is persisted and listed.

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path as UrlPath, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, Uri, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};

use std::sync::Arc;

use super::ServiceError;
use super::state::{ActiveTable, AppState, new_id, now_ms};
use super::store::{EvaluationChart, EvaluationMethod, EvaluationRow};
use crate::camera::{Camera, SensorDesign};
use crate::eval::{
    ChartSetup, DeltaEReport, EvalError, LightLevel, Method, MethodOnChart, fit_baseline_matrix,
};
use crate::spectral::{IsetData, WavelengthGrid};

use crate::l3::correct::IlluminantEntry;

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
        "method": row.method.as_str(),
        "chart": row.chart.as_str(),
        "acquisition_illuminant": row.acquisition_illuminant,
        "mean_delta_e": row.mean_delta_e,
        "created_at_ms": row.created_at,
        "request": request,
        "report": report,
        "links": { "self": format!("/v1/evaluations/{id}") },
    }))
}

/// The request of a `POST /v1/evaluations` body: a JSON object of [`EvaluationRequest`]'s
/// fields (whole floats read as integers).
fn parse_request(body: &[u8]) -> Result<EvaluationRequest, ServiceError> {
    let mut value: Value = serde_json::from_slice(body)
        .map_err(|e| ServiceError::InvalidJson(format!("evaluation request: {e}")))?;
    super::jobs::integral_floats_to_ints(&mut value);
    if !value.is_object() {
        // (serde would read a struct from an array too, field by field)
        return Err(ServiceError::InvalidJson(
            "evaluation request: the body must be a JSON object".into(),
        ));
    }
    serde_json::from_value(value)
        .map_err(|e| ServiceError::InvalidJson(format!("evaluation request: {e}")))
}

/// What a valid request evaluates: the chart, its set-up, the method.
struct Checked {
    chart: EvaluationChart,
    setup: ChartSetup,
    method: EvaluationMethod,
}

impl EvaluationRequest {
    /// Checks the request's values (a 400 naming the first wrong one).
    fn check(&self) -> Result<Checked, ServiceError> {
        // an unknown chart is a 400 naming the charts
        let chart = EvaluationChart::parse(&self.chart)?;
        if chart == EvaluationChart::ColorChecker {
            return Err(ServiceError::BadRequest(
                "a ColorChecker evaluation takes the frame as the body (a mosaic Content-Type, as POST /v1/render takes it) with chart=colorchecker and corners in the query".into(),
            ));
        }
        if !(8..=64).contains(&self.patch_px) {
            return Err(ServiceError::BadRequest(format!(
                "patch_px {}: 8 to 64",
                self.patch_px
            )));
        }
        let setup = self.chart_setup()?;
        let method = EvaluationMethod::parse(&self.method).map_err(|_| {
            ServiceError::BadRequest(format!("method '{}': l3 or baseline", self.method))
        })?;
        Ok(Checked {
            chart,
            setup,
            method,
        })
    }
}

/// The table an `l3` evaluation uses: `table_id`'s (loaded through activation's checks
/// without activating it, unless it is the active one), else the active table.
async fn table_to_evaluate(
    state: &AppState,
    table_id: Option<&String>,
) -> Result<Arc<ActiveTable>, ServiceError> {
    let Some(id) = table_id else {
        return state.active.load_full().ok_or_else(|| {
            ServiceError::NotReady("no table is active yet and no table_id was given".into())
        });
    };
    if let Some(active) = state.active.load_full().filter(|a| &a.id == id) {
        return Ok(active);
    }
    let (_, table, _, _) = super::tables::load_verified(state, id).await?;
    Ok(Arc::new(ActiveTable {
        id: id.clone(),
        sha256: String::new(),
        table,
    }))
}

/// Simulates the chart under `acquisition` through the camera of `table`'s sensor (the
/// paper's default sensor for the baseline, `table` `None`), renders it with the table (or the
/// baseline matrix fitted under D65), corrects with `correction` and scores it, with the
/// render's S-CIELAB and the method's spatial metrics (a slanted edge and a texture under the
/// same set-up) (blocking).
fn evaluate(
    table: Option<&ActiveTable>,
    acquisition: &str,
    correction: &IlluminantEntry,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<DeltaEReport, ServiceError> {
    let grid = WavelengthGrid::default();
    let design = match table {
        Some(t) => t
            .table
            .sensor_design()
            .map_err(|e| ServiceError::from_l3(e, ServiceError::Unprocessable))?,
        None => SensorDesign::paper_default(),
    };
    let camera = Camera::new(&design, grid, iset)
        .map_err(|e| ServiceError::from_camera(e, ServiceError::Unprocessable))?;
    let eval_err = |e: EvalError| ServiceError::from_eval(e, ServiceError::Unprocessable);
    let baseline;
    let (method, name) = match table {
        Some(t) => (
            Method::Table(&t.table),
            format!(
                "L3 {} ({})",
                t.table.meta.kind,
                t.table.meta.train_illuminants.join("+")
            ),
        ),
        None => {
            baseline =
                fit_baseline_matrix(&camera, &["D65".to_string()], iset).map_err(eval_err)?;
            (Method::Baseline(&baseline), "Baseline+T".to_string())
        }
    };
    let on_chart = MethodOnChart {
        camera: &camera,
        method: &method,
        method_name: &name,
        acquisition,
        correction,
        iset,
    };
    let mut report = on_chart.evaluate_with_spatial(setup).map_err(eval_err)?;
    if let Value::Object(m) = &mut report.context {
        m.insert("table_id".into(), json!(table.map(|t| t.id.clone())));
    }
    Ok(report)
}

/// An evaluation slot, or 503 when evaluations already run at capacity.
fn evaluation_slot(state: &AppState) -> Result<tokio::sync::OwnedSemaphorePermit, ServiceError> {
    state
        .eval_slots
        .clone()
        .try_acquire_owned()
        .map_err(|_| ServiceError::Overloaded {
            msg: "evaluations are already running at capacity; retry shortly".into(),
            retry_after_s: 2,
        })
}

/// Runs `evaluation` and stores its row on a task of its own, then answers 201 with it and
/// its Location. An evaluation whose request is dropped meanwhile (timed out, or its client
/// gone) still completes and is stored, so nothing it computed is lost: its CPU time is spent
/// either way (it holds its evaluation slot until then), and `GET /v1/evaluations` lists it.
async fn complete_and_store<F>(state: &AppState, evaluation: F) -> Result<Response, ServiceError>
where
    F: std::future::Future<Output = Result<EvaluationRow, ServiceError>> + Send + 'static,
{
    let st = state.clone();
    let row = tokio::spawn(async move {
        let row = evaluation.await?;
        st.store.insert_evaluation(&row).await?;
        Ok::<_, ServiceError>(row)
    })
    .await
    .map_err(|e| ServiceError::Internal(format!("the evaluation's task: {e}")))??;
    let mut resp = (StatusCode::CREATED, Json(evaluation_json(&row)?)).into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/evaluations/{}", row.id)) {
        resp.headers_mut().insert(header::LOCATION, v);
    }
    Ok(resp)
}

/// `POST /v1/evaluations`: runs the evaluation (on rayon) and answers 201 with the ΔE JSON. A
/// mosaic body is a ColorChecker capture ([`super::colorchecker::evaluate`]).
pub async fn create(
    State(state): State<AppState>,
    headers: HeaderMap,
    uri: Uri,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ServiceError> {
    if super::render::is_mosaic(&headers) {
        let body = super::render::body_bytes(body, state.config.server.max_body_bytes)?;
        let q = super::colorchecker::query(&uri)?;
        let slot = evaluation_slot(&state)?;
        let (st, h) = (state.clone(), headers.clone());
        return complete_and_store(&state, async move {
            super::colorchecker::evaluate(&st, &h, q, body, slot).await
        })
        .await;
    }
    super::render::require_json(&headers).map_err(|_| {
        ServiceError::UnsupportedMediaType(
            "POST /v1/evaluations takes application/json (an evaluation request) or a mosaic \
             (application/octet-stream, image/png, image/tiff, image/x-adobe-dng, \
             image/x-portable-graymap: a ColorChecker capture)"
                .into(),
        )
    })?;
    if let Some(q) = uri.query().filter(|q| !q.is_empty()) {
        return Err(ServiceError::BadRequest(format!(
            "a JSON evaluation request takes its parameters in the body, not the query ('{q}'); \
             the query's parameters are a ColorChecker capture's, sent as a mosaic body"
        )));
    }
    let body = super::render::body_bytes(body, state.config.server.max_body_bytes)?;
    let req = parse_request(&body)?;
    let checked = req.check()?;
    // the light the chart is simulated under (its spectrum)
    let acquisition = super::illuminants::spectral_spec(&state, &req.acquisition_illuminant)?;
    let table = match checked.method {
        EvaluationMethod::L3 => Some(table_to_evaluate(&state, req.table_id.as_ref()).await?),
        EvaluationMethod::Baseline => None,
    };
    let slot = evaluation_slot(&state)?;
    let table_id = table.as_ref().map(|t| t.id.clone());
    let (st, light) = (state.clone(), req.acquisition_illuminant.clone());
    let pools = state.clone();
    complete_and_store(&state, async move {
        let report = super::cpu::run(&pools.pools.background, "the evaluation", move || {
            // its correction (fitted here for a light given by its samples)
            let report = st.resolve_light(&light).and_then(|correction| {
                evaluate(
                    table.as_deref(),
                    &acquisition,
                    &correction,
                    st.iset.as_ref(),
                    &checked.setup,
                )
            });
            drop(slot);
            report
        })
        .await??;
        let report_json = serde_json::to_string(&report)
            .map_err(|e| ServiceError::Internal(format!("report: {e}")))?;
        let row = EvaluationRow {
            id: new_id("eval"),
            table_id,
            method: checked.method,
            chart: checked.chart,
            acquisition_illuminant: req.acquisition_illuminant,
            mean_delta_e: report.summary.mean,
            request_json: String::from_utf8_lossy(&body).to_string(),
            report_json,
            created_at: now_ms(),
        };
        Ok(row)
    })
    .await
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
    let offers = [
        ("application/json", EvaluationFormat::Json),
        ("image/svg+xml", EvaluationFormat::Svg),
    ];
    super::accept::preferred(accept, &offers).unwrap_or(EvaluationFormat::Json)
}

/// `GET /v1/evaluations/{id}`: the evaluation as JSON, or its figure as SVG (by `Accept`).
pub async fn get(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
    headers: HeaderMap,
) -> Result<Response, ServiceError> {
    let format = negotiate(headers.get(header::ACCEPT).and_then(|v| v.to_str().ok()));
    let row = state.store.evaluation(&id).await?;
    let mut resp = match format {
        EvaluationFormat::Json => Json(evaluation_json(&row)?).into_response(),
        EvaluationFormat::Svg => figure(&row)?.into_response(),
    };
    let h = resp.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(format.content_type()),
    );
    h.insert(header::VARY, HeaderValue::from_static("Accept"));
    Ok(resp)
}

/// The figure of a stored evaluation: the ΔE report's, or the ColorChecker report's.
fn figure(row: &EvaluationRow) -> Result<String, ServiceError> {
    let id = &row.id;
    let stored = |e: serde_json::Error| ServiceError::Internal(format!("stored report {id}: {e}"));
    let drawn = |e: EvalError| ServiceError::Internal(format!("figure of evaluation {id}: {e}"));
    match row.chart {
        EvaluationChart::Natural100 => {
            let report: DeltaEReport = serde_json::from_str(&row.report_json).map_err(stored)?;
            crate::eval::report_svg(&report).map_err(drawn)
        }
        EvaluationChart::ColorChecker => {
            let report: crate::eval::ColorCheckerReport =
                serde_json::from_str(&row.report_json).map_err(stored)?;
            crate::eval::colorchecker_svg(&report).map_err(drawn)
        }
    }
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
