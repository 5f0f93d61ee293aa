//! Training jobs over HTTP: submission (idempotent), listing, description and cancel. A
//! replica claims a queued job under a lease ([`queue`]) and trains it ([`training`]); a job
//! that asks for `shards` is split into shard jobs that any replica claims the same way
//! ([`sharded`]); cancelling it cancels them, and its description counts them.
//!
//! The files depend on one another in one direction: [`request`] ← [`queue`] ← [`training`]
//! ← [`sharded`] ← [`worker`], and this file (the handlers) over them.

mod queue;
mod request;
mod sharded;
mod submission;
mod training;
mod worker;

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path as UrlPath, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};

pub use queue::{enqueue, enqueue_default, requeue_interrupted};
pub(super) use request::integral_floats_to_ints;
#[cfg(feature = "test-support")]
pub use request::parse_job_request;
pub use worker::worker;

use super::ServiceError;
use super::state::{AppState, now_ms, sha256_hex};
use super::store::{JobKind, JobRow, JobStage, JobStatus, ShardStage};

fn job_json(row: &JobRow) -> Value {
    let id = &row.id;
    let request: Value = serde_json::from_str(&row.request_json).unwrap_or(Value::Null);
    let now = now_ms();
    let queued_ms = row.started_at.unwrap_or(row.finished_at.unwrap_or(now)) - row.created_at;
    let running_ms = row.started_at.map(|s| row.finished_at.unwrap_or(now) - s);
    json!({
        "id": id,
        "status": row.status.as_str(),
        "progress": row.progress,
        "stage": row.stage.map(JobStage::as_str),
        // the error as recorded, without the server's directories
        "error": row.error.as_deref().map(crate::service::error::without_server_paths),
        "table_id": row.table_id,
        "activate": row.activate,
        "attempts": row.attempts,
        "idempotency_key": row.idempotency_key,
        "request": request,
        "created_at_ms": row.created_at,
        "started_at_ms": row.started_at,
        "finished_at_ms": row.finished_at,
        "timings": { "queued_ms": queued_ms.max(0), "running_ms": running_ms.map(|v| v.max(0)) },
        "links": job_links(row),
    })
}

/// A job's links: itself, `cancel` while it can be canceled, its table once it has one.
fn job_links(row: &JobRow) -> Value {
    let id = &row.id;
    let mut links = json!({ "self": format!("/v1/training-jobs/{id}") });
    if matches!(row.status, JobStatus::Queued | JobStatus::Running) {
        links["cancel"] = json!(format!("/v1/training-jobs/{id}/cancel"));
    }
    if let Some(table) = &row.table_id {
        links["table"] = json!(format!("/v1/tables/{table}"));
    }
    links
}

/// A shard in its job's description.
fn shard_json(s: &JobRow) -> Value {
    let running_ms = s
        .started_at
        .map(|t| s.finished_at.unwrap_or_else(now_ms) - t);
    json!({
        "id": s.id,
        "stage": s.kind.shard_stage().map(ShardStage::as_str),
        "shard": s.shard_index.map(|k| k + 1),
        "status": s.status.as_str(),
        "progress": s.progress,
        "attempts": s.attempts,
        "replica": s.lease_owner.as_ref().or(s.finished_by.as_ref()),
        "compute_ms": s.compute_ms,
        "running_ms": running_ms.map(|v| v.max(0)),
    })
}

/// A job as the API describes it. A sharded job counts its shards (`shards`: done of total,
/// the fraction, each shard, the merge time) and its progress is theirs; a shard names its job.
async fn job_view(state: &AppState, row: &JobRow) -> Result<Value, ServiceError> {
    let mut v = job_json(row);
    if let Some(parent) = &row.parent_id {
        v["parent_id"] = json!(parent);
        v["shard"] = json!({
            "stage": row.kind.shard_stage().map(ShardStage::as_str),
            "shard": row.shard_index.map(|k| k + 1),
            "count": row.shard_count,
        });
        if v["links"].get("cancel").is_some() {
            v["links"]["cancel"] = json!(format!("/v1/training-jobs/{parent}/cancel"));
        }
    }
    if row.kind == JobKind::Sharded {
        let shards = state.store.shards(&row.id).await?;
        let count = row.shard_count.unwrap_or(0).max(0);
        // a survey and an accumulation shard per shard
        let total = (2 * count).max(1) as f64;
        let done = shards
            .iter()
            .filter(|s| s.status == JobStatus::Succeeded)
            .count();
        let partly: f64 = shards
            .iter()
            .map(|s| match s.status {
                JobStatus::Succeeded => 1.0,
                JobStatus::Running => s.progress.clamp(0.0, 1.0),
                _ => 0.0,
            })
            .sum();
        v["progress"] = json!(if row.status == JobStatus::Succeeded {
            1.0
        } else {
            (partly / total).min(1.0)
        });
        v["shards"] = json!({
            "count": count,
            "done": done,
            "total": 2 * count,
            "fraction": done as f64 / total,
            "merge_ms": row.merge_ms,
            "items": shards.iter().map(shard_json).collect::<Vec<_>>(),
        });
    }
    Ok(v)
}

/// The job `id` (404 when there is none).
async fn job_row(state: &AppState, id: &str) -> Result<JobRow, ServiceError> {
    Ok(state.store.existing_job(id).await?)
}

fn created(id: &str, body: Value, status: StatusCode) -> Response {
    let mut resp = (status, Json(body)).into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/training-jobs/{id}")) {
        resp.headers_mut().insert(header::LOCATION, v);
    }
    resp
}

/// The `Idempotency-Key` header, if any (1–200 visible ASCII characters).
fn idempotency_key(headers: &HeaderMap) -> Result<Option<String>, ServiceError> {
    let Some(v) = headers.get("idempotency-key") else {
        return Ok(None);
    };
    let k = v
        .to_str()
        .ok()
        .filter(|k| !k.is_empty() && k.len() <= 200)
        .ok_or_else(|| {
            ServiceError::BadRequest(
                "Idempotency-Key must be 1–200 visible ASCII characters".into(),
            )
        })?;
    Ok(Some(k.to_string()))
}

/// `POST /v1/training-jobs`
pub async fn submit(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ServiceError> {
    super::render::require_json(&headers)?;
    let body = super::render::body_bytes(body, state.config.server.max_body_bytes)?;
    let (req, value) = submission::parse_submission(&state, &body)?;
    if value.get("sensor").is_some_and(Value::is_object) {
        submission::check_curves(&state, &req).await?;
    }
    let key = idempotency_key(&headers)?;
    // insert, or find the job the key already names (two replicas may race on one key)
    if let Some(id) = enqueue(&state, &value, &req, key.as_deref()).await? {
        let row = job_row(&state, &id).await?;
        return Ok(created(
            &id,
            job_view(&state, &row).await?,
            StatusCode::ACCEPTED,
        ));
    }
    let k = key.unwrap_or_default();
    // another request under the key is a conflict
    let sha = sha256_hex(value.to_string().as_bytes());
    let row = state.store.job_for_key(&k, &sha).await?.ok_or_else(|| {
        ServiceError::Internal(format!(
            "Idempotency-Key '{k}': no job, yet the key is taken"
        ))
    })?;
    Ok(created(
        &row.id,
        job_view(&state, &row).await?,
        StatusCode::OK,
    ))
}

/// Query of `GET /v1/training-jobs`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ListQuery {
    pub status: Option<String>,
    pub limit: Option<i64>,
}

/// `GET /v1/training-jobs`
pub async fn list(
    State(state): State<AppState>,
    q: Result<Query<ListQuery>, axum::extract::rejection::QueryRejection>,
) -> Result<Json<Value>, ServiceError> {
    let Query(q) = q.map_err(|e| ServiceError::BadRequest(e.body_text()))?;
    let limit = q.limit.unwrap_or(100);
    if !(1..=1000).contains(&limit) {
        return Err(ServiceError::BadRequest(format!(
            "limit {limit}: 1 to 1000"
        )));
    }
    // an unknown state is a 400 naming the states
    let status = q.status.as_deref().map(JobStatus::parse).transpose()?;
    let rows = state.store.list_jobs(status, limit).await?;
    let mut items = Vec::with_capacity(rows.len());
    for row in &rows {
        items.push(job_view(&state, row).await?);
    }
    Ok(Json(json!({ "items": items })))
}

/// `GET /v1/training-jobs/{id}`
pub async fn get(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    let row = job_row(&state, &id).await?;
    Ok(Json(job_view(&state, &row).await?))
}

/// Sets the local cancel flag of `id` if this replica runs it.
fn signal_local(state: &AppState, id: &str) {
    let flag = state
        .running_jobs
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .get(id)
        .cloned();
    if let Some(f) = flag {
        f.store(true, Ordering::SeqCst);
    }
}

/// Waits (up to 2 s) until none of `ids` is running.
async fn wait_stopped(state: &AppState, ids: &[String]) -> Result<(), ServiceError> {
    let deadline = Instant::now() + Duration::from_secs(2);
    for id in ids {
        while Instant::now() < deadline {
            if job_row(state, id).await?.status != JobStatus::Running {
                break;
            }
            tokio::time::sleep(Duration::from_millis(25)).await;
        }
    }
    Ok(())
}

/// Cancels the sharded job `id` with its queued shards, and signals its running shards.
async fn cancel_sharded(state: &AppState, id: &str) -> Result<Json<Value>, ServiceError> {
    let Some(stopping) = state
        .store
        .end_sharded(id, JobStatus::Canceled, None, now_ms())
        .await?
    else {
        let status = job_row(state, id).await?.status;
        return Err(ServiceError::Conflict(format!(
            "job '{id}' is {status}; only queued or running jobs can be canceled"
        )));
    };
    tracing::info!(job = id, "sharded training job canceled");
    for s in &stopping {
        signal_local(state, s);
    }
    wait_stopped(state, &stopping).await?;
    let row = job_row(state, id).await?;
    Ok(Json(job_view(state, &row).await?))
}

/// `POST /v1/training-jobs/{id}/cancel`: a queued job is canceled at once; a running one is
/// signalled (through its row, whichever replica runs it) and the answer waits (up to 2 s)
/// until it has stopped. A sharded job is canceled at once with its queued shards, and its
/// running shards are signalled like running jobs. A shard is canceled through its job.
pub async fn cancel(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    let row = job_row(&state, &id).await?;
    if let Some(parent) = &row.parent_id {
        return Err(ServiceError::Conflict(format!(
            "job '{id}' is a shard of job '{parent}'; cancel that job"
        )));
    }
    if row.kind == JobKind::Sharded {
        return cancel_sharded(&state, &id).await;
    }
    let mut status = row.status;
    if status == JobStatus::Queued {
        if state.store.cancel_queued(&id, now_ms()).await? {
            return Ok(Json(job_json(&job_row(&state, &id).await?)));
        }
        // claimed meanwhile
        status = job_row(&state, &id).await?.status;
    }
    match status {
        JobStatus::Running => {
            state.store.request_cancel(&id).await?;
            signal_local(&state, &id);
            wait_stopped(&state, std::slice::from_ref(&id)).await?;
        }
        other => {
            return Err(ServiceError::Conflict(format!(
                "job '{id}' is {other}; only queued or running jobs can be canceled"
            )));
        }
    }
    Ok(Json(job_json(&job_row(&state, &id).await?)))
}

/// Job counts by state (for /metrics).
pub async fn counts(state: &AppState) -> Result<Vec<(JobStatus, i64)>, ServiceError> {
    Ok(state.store.job_counts().await?)
}
