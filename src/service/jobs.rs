//! Training jobs: submission (idempotent), listing, cancel, and the runner that trains on
//! rayon, persists the table and optionally activates it. A replica claims a queued job under
//! a lease it renews with a heartbeat; the heartbeat also carries the progress and brings
//! back a cancel requested through any replica. A job whose replica died (its lease expired)
//! goes back to the queue, as do the jobs a restarted replica had left running.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::ServiceError;
use super::state::{AppState, new_id, now_ms, sha256_hex};
use super::store::{JOB_KIND_TRAIN, JobEnd, JobRow, JobStatus, NewJob};
use super::tables::{activate_table, insert_table, write_table_file};
use crate::camera::SensorDesign;
use crate::l3::L3Error;
use crate::training::{TrainError, TrainingSpec, train_table};
use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path as UrlPath, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};

/// How often a running job's replica renews its lease, records progress and looks for a
/// cancel request (at most; shorter leases beat faster).
const HEARTBEAT: Duration = Duration::from_millis(250);

/// The idempotency key of the default table's training job: one per cluster.
pub const DEFAULT_TABLE_JOB_KEY: &str = "l3:default-table";

/// A parsed job request: the training spec plus the sensor and whether to activate.
#[derive(Debug, Clone)]
pub struct JobRequest {
    pub spec: TrainingSpec,
    pub sensor: SensorDesign,
    pub activate: bool,
}

/// Parses and validates a job's JSON: the [`TrainingSpec`] fields, plus `sensor` (absent or
/// `"paper_default"`, or a sensor design object) and `activate` (bool).
pub fn parse_job_request(body: &[u8]) -> Result<(JobRequest, Value), ServiceError> {
    let bad = |m: String| ServiceError::InvalidJson(m);
    let mut value: Value = serde_json::from_slice(body)
        .map_err(|e| bad(format!("the body is not valid JSON: {e}")))?;
    integral_floats_to_ints(&mut value);
    let Value::Object(mut map) = value.clone() else {
        return Err(bad(
            "the body must be a JSON object with the training spec".into()
        ));
    };
    let activate = match map.remove("activate") {
        None => false,
        Some(Value::Bool(b)) => b,
        Some(v) => return Err(bad(format!("activate is {v}; true or false expected"))),
    };
    let sensor = match map.remove("sensor") {
        None | Some(Value::Null) => SensorDesign::paper_default(),
        Some(Value::String(s)) if s == "paper_default" => SensorDesign::paper_default(),
        Some(Value::String(s)) => {
            return Err(bad(format!(
                "sensor '{s}': use \"paper_default\" or a sensor design object"
            )));
        }
        Some(v) => {
            let d: SensorDesign =
                serde_json::from_value(v).map_err(|e| bad(format!("sensor: {e}")))?;
            d.validate()
                .map_err(|e| ServiceError::BadRequest(format!("sensor: {e}")))?;
            d
        }
    };
    // the error names the field (`scenes: invalid type: floating point 4.5, …`)
    let spec: TrainingSpec = serde_path_to_error::deserialize(Value::Object(map))
        .map_err(|e| bad(format!("training spec: {}: {}", e.path(), e.inner())))?;
    spec.validate()
        .map_err(|e| ServiceError::BadRequest(e.to_string()))?;
    Ok((
        JobRequest {
            spec,
            sensor,
            activate,
        },
        value,
    ))
}

/// Rewrites numbers like `4800.0` as the integer `4800`, everywhere in `v`. JSON Schema (and
/// many clients) treat them as integers; serde's integer fields would refuse them. Float
/// fields accept integers, so the rewrite changes no meaning.
pub(super) fn integral_floats_to_ints(v: &mut Value) {
    match v {
        Value::Number(n) if n.is_f64() => {
            if let Some(f) = n.as_f64()
                && f.fract() == 0.0
                && f.abs() < 9.0e15
            {
                *v = Value::from(f as i64);
            }
        }
        Value::Array(a) => a.iter_mut().for_each(integral_floats_to_ints),
        Value::Object(m) => m.values_mut().for_each(integral_floats_to_ints),
        _ => {}
    }
}

/// A new job's row for `request_json`.
fn new_job<'a>(
    id: &'a str,
    text: &'a str,
    sha: &'a str,
    activate: bool,
    idempotency_key: Option<&'a str>,
) -> NewJob<'a> {
    NewJob {
        id,
        request_json: text,
        idempotency_key,
        request_sha256: sha,
        activate,
        created_at: now_ms(),
    }
}

fn wake_workers(state: &AppState) {
    state.job_notify.notify_waiters();
    state.job_notify.notify_one();
}

/// Inserts a queued job; returns its id, or `None` when `idempotency_key` is already taken.
pub async fn enqueue(
    state: &AppState,
    request_json: &Value,
    activate: bool,
    idempotency_key: Option<&str>,
) -> Result<Option<String>, ServiceError> {
    let id = new_id("job");
    let text = request_json.to_string();
    let sha = sha256_hex(text.as_bytes());
    let job = new_job(&id, &text, &sha, activate, idempotency_key);
    if !state.store.insert_job(&job).await? {
        return Ok(None);
    }
    wake_workers(state);
    tracing::info!(job = id, "training job queued");
    Ok(Some(id))
}

/// Queues the default table's job once per database (replicas starting together queue one),
/// again only when its earlier run failed or was canceled; returns its id when queued.
pub async fn enqueue_default(
    state: &AppState,
    request_json: &Value,
) -> Result<Option<String>, ServiceError> {
    let id = new_id("job");
    let text = request_json.to_string();
    let sha = sha256_hex(text.as_bytes());
    let job = new_job(&id, &text, &sha, true, Some(DEFAULT_TABLE_JOB_KEY));
    let queued = state.store.queue_once(&job).await?;
    if queued.is_some() {
        wake_workers(state);
    }
    Ok(queued)
}

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
        "stage": row.stage,
        "error": row.error,
        "table_id": row.table_id,
        "activate": row.activate != 0,
        "attempts": row.attempts,
        "idempotency_key": row.idempotency_key,
        "request": request,
        "created_at_ms": row.created_at,
        "started_at_ms": row.started_at,
        "finished_at_ms": row.finished_at,
        "timings": { "queued_ms": queued_ms.max(0), "running_ms": running_ms.map(|v| v.max(0)) },
        "links": { "self": format!("/v1/training-jobs/{id}"), "cancel": format!("/v1/training-jobs/{id}/cancel") },
    })
}

async fn job_row(state: &AppState, id: &str) -> Result<JobRow, ServiceError> {
    state
        .store
        .job(id)
        .await?
        .ok_or_else(|| ServiceError::NotFound(format!("no training job with id '{id}'")))
}

fn created(id: &str, body: Value, status: StatusCode) -> Response {
    let mut resp = (status, Json(body)).into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/training-jobs/{id}")) {
        resp.headers_mut().insert(header::LOCATION, v);
    }
    resp
}

/// `POST /v1/training-jobs`
pub async fn submit(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ServiceError> {
    super::render::require_json(&headers)?;
    let body = super::render::body_bytes(body, state.config.server.max_body_bytes)?;
    let (req, value) = parse_job_request(&body)?;
    let key = match headers.get("idempotency-key") {
        None => None,
        Some(v) => {
            let k = v
                .to_str()
                .ok()
                .filter(|k| !k.is_empty() && k.len() <= 200)
                .ok_or_else(|| {
                    ServiceError::BadRequest(
                        "Idempotency-Key must be 1–200 visible ASCII characters".into(),
                    )
                })?;
            Some(k.to_string())
        }
    };
    // insert, or find the job the key already names (two replicas may race on one key)
    if let Some(id) = enqueue(&state, &value, req.activate, key.as_deref()).await? {
        let row = job_row(&state, &id).await?;
        return Ok(created(&id, job_json(&row), StatusCode::ACCEPTED));
    }
    let k = key.unwrap_or_default();
    let row = state.store.job_by_key(&k).await?.ok_or_else(|| {
        ServiceError::Internal(format!(
            "Idempotency-Key '{k}': no job, yet the key is taken"
        ))
    })?;
    if row.request_sha256 != sha256_hex(value.to_string().as_bytes()) {
        return Err(ServiceError::Conflict(format!(
            "Idempotency-Key '{k}' was already used with a different request body"
        )));
    }
    Ok(created(&row.id, job_json(&row), StatusCode::OK))
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
    let status = q
        .status
        .as_deref()
        .map(|s| {
            s.parse::<JobStatus>().map_err(|_| {
                let all: Vec<&str> = JobStatus::ALL.iter().map(|j| j.as_str()).collect();
                ServiceError::BadRequest(format!("status '{s}': one of {}", all.join(", ")))
            })
        })
        .transpose()?;
    let rows = state.store.list_jobs(status, limit).await?;
    let items: Vec<Value> = rows.iter().map(job_json).collect();
    Ok(Json(json!({ "items": items })))
}

/// `GET /v1/training-jobs/{id}`
pub async fn get(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    Ok(Json(job_json(&job_row(&state, &id).await?)))
}

/// `POST /v1/training-jobs/{id}/cancel`: a queued job is canceled at once; a running one is
/// signalled (through its row, whichever replica runs it) and the answer waits (up to 2 s)
/// until it has stopped.
pub async fn cancel(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    let mut status = job_row(&state, &id).await?.status;
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
            let flag = state
                .running_jobs
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .get(&id)
                .cloned();
            if let Some(f) = flag {
                f.store(true, Ordering::SeqCst);
            }
            let deadline = Instant::now() + Duration::from_secs(2);
            while Instant::now() < deadline {
                if job_row(&state, &id).await?.status != JobStatus::Running {
                    break;
                }
                tokio::time::sleep(Duration::from_millis(25)).await;
            }
        }
        other => {
            return Err(ServiceError::Conflict(format!(
                "job '{id}' is {other}; only queued or running jobs can be canceled"
            )));
        }
    }
    Ok(Json(job_json(&job_row(&state, &id).await?)))
}

/// Puts the jobs this replica left `running` (a crash or restart) back in the queue.
pub async fn requeue_interrupted(state: &AppState) -> Result<u64, ServiceError> {
    state.store.requeue_owned(&state.replica_id).await
}

fn lease(state: &AppState) -> Duration {
    Duration::from_secs_f64(state.config.training.job_lease_s)
}

fn lease_until(state: &AppState) -> i64 {
    now_ms() + lease(state).as_millis() as i64
}

/// One job worker: returns the jobs of dead replicas to the queue, claims the oldest queued
/// job, runs it, repeats until shutdown.
pub async fn worker(state: AppState) {
    loop {
        if state.shutting_down.load(Ordering::SeqCst) {
            return;
        }
        match state.store.requeue_expired(now_ms()).await {
            Ok(0) => {}
            Ok(n) => tracing::warn!("{n} training job(s) whose replica stopped beating re-queued"),
            Err(e) => tracing::error!("job queue: {e}"),
        }
        let claimed = state
            .store
            .claim_job(
                JOB_KIND_TRAIN,
                &state.replica_id,
                now_ms(),
                lease_until(&state),
            )
            .await;
        match claimed {
            Ok(Some(job)) => run_job(&state, &job.id, &job.request_json).await,
            Ok(None) => {
                tokio::select! {
                    _ = state.job_notify.notified() => {}
                    _ = state.shutdown_notify.notified() => {}
                    _ = tokio::time::sleep(Duration::from_secs(1)) => {}
                }
            }
            Err(e) => {
                tracing::error!("job queue: {e}");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

async fn finish(
    state: &AppState,
    id: &str,
    status: JobStatus,
    error: Option<&str>,
    table_id: Option<&str>,
) -> Result<(), ServiceError> {
    let end = JobEnd {
        status,
        error,
        table_id,
        finished_at: now_ms(),
    };
    if !state.store.finish_job(id, &state.replica_id, &end).await? {
        tracing::warn!(
            job = id,
            "the job's lease was lost before it ended {status}; its outcome is not recorded here"
        );
    }
    Ok(())
}

enum Outcome {
    Done(Box<crate::l3::L3Table>, super::tables::StoredTable),
    Canceled,
    Failed(String),
}

async fn run_job(state: &AppState, id: &str, request: &str) {
    let parsed = parse_job_request(request.as_bytes());
    let req = match parsed {
        Ok((r, _)) => r,
        Err(e) => {
            let _ = finish(state, id, JobStatus::Failed, Some(&e.to_string()), None).await;
            return;
        }
    };
    tracing::info!(job = id, "training job started");
    let cancel = Arc::new(AtomicBool::new(false));
    state
        .running_jobs
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .insert(id.to_string(), cancel.clone());
    let (ptx, mut prx) = tokio::sync::mpsc::unbounded_channel::<(String, f64)>();
    let (tx, mut rx) = tokio::sync::oneshot::channel::<Outcome>();
    let st = state.clone();
    let cancel2 = cancel.clone();
    let pool_state = state.clone();
    let train = move || {
        let progress = move |stage: &str, f: f64| {
            let _ = ptx.send((stage.to_string(), f));
        };
        match train_table(
            &req.sensor,
            &req.spec,
            st.iset.as_ref(),
            &progress,
            &cancel2,
        ) {
            Ok(table) => match write_table_file(&st.tables_dir, &table) {
                Ok(stored) => Outcome::Done(Box::new(table), stored),
                Err(e) => Outcome::Failed(e.to_string()),
            },
            Err(TrainError::L3(L3Error::Canceled)) => Outcome::Canceled,
            Err(e) => Outcome::Failed(e.to_string()),
        }
    };
    // a panic fails the job (logged) instead of aborting the process
    let job = id.to_string();
    super::cpu::spawn_catching(&pool_state.pools.background, train, move |r| {
        let outcome = r.unwrap_or_else(|msg| {
            tracing::error!(job = %job, panic = %msg, "training panicked");
            Outcome::Failed(format!("training failed unexpectedly: {msg}"))
        });
        let _ = tx.send(outcome);
    });
    let beat = HEARTBEAT.min(lease(state) / 3);
    let mut last_beat = Instant::now();
    let mut last_stage = String::new();
    let mut pending: Option<(String, f64)> = None;
    let mut lease_lost = false;
    let outcome = loop {
        tokio::select! {
            r = &mut rx => break r,
            Some(p) = prx.recv() => {
                pending = Some(p);
            }
            _ = state.shutdown_notify.notified() => {
                cancel.store(true, Ordering::SeqCst);
            }
            _ = tokio::time::sleep(Duration::from_millis(100)) => {}
        }
        if state.shutting_down.load(Ordering::SeqCst) {
            cancel.store(true, Ordering::SeqCst);
        }
        let new_stage = pending.as_ref().is_some_and(|(s, _)| *s != last_stage);
        if lease_lost || !(new_stage || last_beat.elapsed() >= beat) {
            continue;
        }
        // the heartbeat: renew the lease, record progress, look for a cancel request
        let progress = pending
            .as_ref()
            .map(|(s, f)| (s.as_str(), f.clamp(0.0, 1.0)));
        match state
            .store
            .heartbeat(
                id,
                &state.replica_id,
                now_ms(),
                lease_until(state),
                progress,
            )
            .await
        {
            Ok(Some(cancel_requested)) => {
                if cancel_requested {
                    cancel.store(true, Ordering::SeqCst);
                }
            }
            Ok(None) => {
                tracing::warn!(
                    job = id,
                    "the job's lease was lost (it expired or the job was re-queued); stopping it here"
                );
                lease_lost = true;
                cancel.store(true, Ordering::SeqCst);
            }
            Err(e) => tracing::error!(job = id, "heartbeat: {e}"),
        }
        last_beat = Instant::now();
        if let Some((stage, f)) = pending.take()
            && stage != last_stage
        {
            tracing::info!(job = id, stage = %stage, progress = format!("{:.0} %", f * 100.0), "training");
            last_stage = stage;
        }
    };
    state
        .running_jobs
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .remove(id);
    let result = match outcome {
        _ if lease_lost => Ok(()),
        Err(_) => {
            finish(
                state,
                id,
                JobStatus::Failed,
                Some("the training task was lost"),
                None,
            )
            .await
        }
        Ok(Outcome::Canceled) if state.shutting_down.load(Ordering::SeqCst) => {
            tracing::info!(job = id, "training job interrupted by shutdown; re-queued");
            state
                .store
                .requeue_job(id, &state.replica_id, "interrupted by shutdown")
                .await
        }
        Ok(Outcome::Canceled) => {
            tracing::info!(job = id, "training job canceled");
            finish(state, id, JobStatus::Canceled, None, None).await
        }
        Ok(Outcome::Failed(msg)) => {
            tracing::warn!(job = id, "training job failed: {msg}");
            finish(state, id, JobStatus::Failed, Some(&msg), None).await
        }
        Ok(Outcome::Done(table, stored)) => {
            let r = async {
                insert_table(state, &stored, &table, Some(id)).await?;
                if req_activate(state, id).await? {
                    activate_table(state, &stored.id).await?;
                }
                finish(state, id, JobStatus::Succeeded, None, Some(&stored.id)).await
            }
            .await;
            tracing::info!(job = id, table = stored.id, "training job succeeded");
            match r {
                Ok(()) => Ok(()),
                Err(e) => finish(state, id, JobStatus::Failed, Some(&e.to_string()), None).await,
            }
        }
    };
    if let Err(e) = result {
        tracing::error!(job = id, "cannot record the job's outcome: {e}");
    }
}

async fn req_activate(state: &AppState, id: &str) -> Result<bool, ServiceError> {
    Ok(job_row(state, id).await?.activate != 0)
}

/// Job counts by state (for /metrics).
pub async fn counts(state: &AppState) -> Result<Vec<(String, i64)>, ServiceError> {
    state.store.job_counts().await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn job_request_parsing() {
        let (r, _) =
            parse_job_request(br#"{"illuminants":["D65"],"scenes":4,"activate":true}"#).unwrap();
        assert!(r.activate);
        assert_eq!(r.spec.scenes, 4);
        let (r, _) = parse_job_request(br#"{"scenes":48.0,"levels":1e1}"#).unwrap();
        assert_eq!((r.spec.scenes, r.spec.levels), (48, 10));
        for (body, needle) in [
            (&b"{"[..], "not valid JSON"),
            (b"[1]", "JSON object"),
            (br#"{"bogus":1}"#, "bogus"),
            (br#"{"levels":1}"#, "levels 1"),
            (br#"{"activate":"yes"}"#, "activate"),
            (br#"{"sensor":"nikon"}"#, "nikon"),
            (br#"{"scenes":4.5}"#, "scenes"),
        ] {
            let e = parse_job_request(body).unwrap_err();
            assert!(e.to_string().contains(needle), "{e}");
            assert_eq!(e.status().as_u16(), 400);
        }
    }
}
