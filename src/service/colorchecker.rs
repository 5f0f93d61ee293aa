//! `POST /v1/evaluations` with a frame as the body: a ColorChecker capture, rendered as
//! `POST /v1/render` renders it (the same query parameters decode it), scored against
//! published values by the core ([`crate::eval::colorchecker`]). The evaluation's own
//! parameters (`chart=colorchecker`, `corners`, `reference`, `gap`, `table_id`) are in the
//! query too; the report is persisted and listed with the other evaluations.

use std::sync::atomic::AtomicBool;

use axum::body::Bytes;
use axum::extract::Query;
use axum::http::{HeaderMap, Uri};
use serde::{Deserialize, Serialize};
use tokio::sync::OwnedSemaphorePermit;

use super::ServiceError;
use super::render::{RenderQuery, ServiceRender, render_request};
use super::state::{AppState, new_id, now_ms};
use super::store::{EvaluationChart, EvaluationMethod, EvaluationRow};
use super::table_choice::table_for;
use crate::eval::colorchecker::{
    CLASSIC_GAP, ColorCheckerOptions, Labels, evaluate_colorchecker, rendered_xyz,
};
use crate::eval::{ColorCheckerReport, EvalError};
use crate::pipeline::OutputFormat;

/// The query of a ColorChecker evaluation.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ColorCheckerQuery {
    /// `colorchecker`.
    pub chart: String,
    /// `x1,y1,…,x4,y4`: the outer corners of the patch grid (dark skin's, bluish green's,
    /// black's, white's).
    pub corners: String,
    /// `xrite2014` (default) or `iset`.
    #[serde(default)]
    pub reference: Option<String>,
    /// The gap between patches as a fraction of a patch's side (default 0.1).
    #[serde(default)]
    pub gap: Option<f64>,
    /// The table that renders (default: the active one).
    #[serde(default)]
    pub table_id: Option<String>,
    // decoding and light, as `POST /v1/render` takes them
    #[serde(default)]
    pub width: Option<usize>,
    #[serde(default)]
    pub height: Option<usize>,
    #[serde(default)]
    pub cfa: Option<String>,
    #[serde(default)]
    pub black_level: Option<u16>,
    #[serde(default)]
    pub white_level: Option<u16>,
    #[serde(default)]
    pub illuminant: Option<String>,
    #[serde(default)]
    pub correction: Option<String>,
}

impl ColorCheckerQuery {
    /// The evaluation's options, or a 400 naming what is wrong.
    fn options(&self) -> Result<ColorCheckerOptions, ServiceError> {
        if !self.chart.eq_ignore_ascii_case("colorchecker") {
            return Err(ServiceError::BadRequest(format!(
                "chart '{}': a frame in the body is evaluated as a ColorChecker capture (chart=colorchecker); the simulated charts take a JSON body",
                self.chart
            )));
        }
        let bad = |e: EvalError| ServiceError::BadRequest(e.to_string());
        let gap = self.gap.unwrap_or(CLASSIC_GAP);
        if !(gap.is_finite() && (0.0..=1.0).contains(&gap)) {
            return Err(ServiceError::BadRequest(format!(
                "gap {gap}: 0 to 1 (a fraction of a patch's side)"
            )));
        }
        Ok(ColorCheckerOptions {
            corners: self.corners.parse().map_err(bad)?,
            gap,
            reference: self
                .reference
                .as_deref()
                .unwrap_or("xrite2014")
                .parse()
                .map_err(bad)?,
        })
    }

    /// The render the query asks for (as `POST /v1/render`'s query, to float XYZ).
    fn render_query(&self) -> RenderQuery {
        RenderQuery {
            width: self.width,
            height: self.height,
            cfa: self.cfa.clone(),
            black_level: self.black_level,
            white_level: self.white_level,
            illuminant: self.illuminant.clone(),
            correction: self.correction.clone(),
            ..RenderQuery::default()
        }
    }
}

/// The query of a request whose body is a frame, or a 400 saying what it needs.
pub fn query(uri: &Uri) -> Result<ColorCheckerQuery, ServiceError> {
    let Query(q) = Query::<ColorCheckerQuery>::try_from_uri(uri).map_err(|e| {
        ServiceError::BadRequest(format!(
            "a frame body needs chart=colorchecker and corners in the query: {}",
            e.body_text()
        ))
    })?;
    Ok(q)
}

/// The evaluation of a frame `body` (`POST /v1/evaluations` with a mosaic body, its query
/// `q`): renders it with `table`, scores the chart on the background pool while holding the
/// evaluation `slot`, and gives the row to store.
pub async fn evaluate(
    state: &AppState,
    headers: &HeaderMap,
    q: ColorCheckerQuery,
    body: Bytes,
    slot: OwnedSemaphorePermit,
) -> Result<EvaluationRow, ServiceError> {
    let opts = q.options()?;
    let frame_bytes = body.len();
    let request = render_request(
        q.render_query(),
        headers,
        body,
        OutputFormat::F32,
        &state.config.server,
    )?;
    let correction = request.correction;
    // the table is chosen as `POST /v1/render` chooses it: `table_id`, else the DNG's camera's,
    // else the active one
    let chosen = table_for(state, q.table_id.as_deref(), &request.input).await?;
    let table_id = chosen.table.id.clone();
    let ctx = ServiceRender {
        state: state.clone(),
        active: chosen.table,
        keep_renderers: chosen.keep_renderers,
    };
    // a wrong CFA or an unknown light is refused before the frame is decoded
    let prepared = request.prepare(&ctx)?;
    let iset = state.iset.clone();
    let context = serde_json::json!({
        "table_id": table_id,
        "table_choice": chosen.choice.as_str(),
        "correction": correction.as_str(),
    });
    let report = super::cpu::run(&state.pools.background, "the evaluation", move || {
        let scored = score(prepared, &ctx, &opts, iset.as_ref(), context);
        drop(slot);
        scored
    })
    .await??;
    let mut request_json = serde_json::to_value(&q).unwrap_or_default();
    request_json["frame_bytes"] = serde_json::json!(frame_bytes);
    let report_json = serde_json::to_string(&report)
        .map_err(|e| ServiceError::Internal(format!("report: {e}")))?;
    Ok(EvaluationRow {
        id: new_id("eval"),
        table_id: Some(table_id),
        method: EvaluationMethod::L3,
        chart: EvaluationChart::ColorChecker,
        acquisition_illuminant: report.acquisition_illuminant.clone(),
        mean_delta_e: report.summary.mean,
        request_json: request_json.to_string(),
        report_json,
        created_at: now_ms(),
    })
}

/// Renders the frame and scores it (blocking).
fn score(
    prepared: crate::pipeline::Prepared,
    ctx: &ServiceRender,
    opts: &ColorCheckerOptions,
    iset: Option<&crate::spectral::IsetData>,
    mut context: serde_json::Value,
) -> Result<ColorCheckerReport, ServiceError> {
    let out = prepared.run(ctx, &AtomicBool::new(false))?;
    let light = out.light.clone();
    context["illuminant_source"] = serde_json::json!(match out.light_origin {
        crate::pipeline::LightOrigin::Named => "query",
        crate::pipeline::LightOrigin::Frame(source) => source.name(),
    });
    let eval_err = |e: EvalError| ServiceError::from_eval(e, ServiceError::Unprocessable);
    let (xyz, width, height) = rendered_xyz(out).map_err(eval_err)?;
    let t = &ctx.active.table.meta;
    let method = format!("L3 {} ({})", t.kind, t.train_illuminants.join("+"));
    let labels = Labels {
        method: &method,
        illuminant: &light,
        context,
    };
    evaluate_colorchecker(&xyz, width, height, opts, iset, labels).map_err(eval_err)
}
