//! Training jobs: submission (idempotent), listing, cancel, and the runner that trains on
//! rayon, persists the table and optionally activates it. A replica claims a queued job under
//! a lease it renews with a heartbeat; the heartbeat also carries the progress and brings
//! back a cancel requested through any replica. A job whose replica died (its lease expired)
//! goes back to the queue, as do the jobs a restarted replica had left running.
//!
//! A job that asks for `shards` is split into shard jobs that any replica claims the same way
//! (`super::shard_jobs`); cancelling it cancels them, and its description counts them.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::ServiceError;
use super::state::{AppState, new_id, now_ms, sha256_hex};
use super::store::{
    JOB_KIND_SHARDED, JOB_KIND_TRAIN, JobEnd, JobRow, JobStatus, NewJob, WORKER_KINDS, shard_stage,
};
use super::tables::{StoredTable, activate_table, insert_table, write_table_file};
use crate::camera::SensorDesign;
use crate::l3::L3Table;
use crate::l3::learn::{LearnError, TrainingSpec, train_table};
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

/// The most shards a job may ask for (and at most one per batch, i.e. per training scene).
pub const MAX_SHARDS: usize = 64;

/// A parsed job request: the training spec plus the sensor, whether to activate, the shards
/// and whether the table is written reproducibly.
#[derive(Debug, Clone)]
pub struct JobRequest {
    pub spec: TrainingSpec,
    pub sensor: SensorDesign,
    pub activate: bool,
    /// Train in this many shards (shard jobs any replica claims); `None` trains in one piece.
    /// Any number gives the same table bytes.
    pub shards: Option<usize>,
    /// Zero the creation time and training duration in the table (as `l3 train
    /// --reproducible`), so that equal training gives equal table bytes (and id).
    pub reproducible: bool,
}

/// A boolean field of a job request (absent: false).
fn flag(map: &mut serde_json::Map<String, Value>, name: &str) -> Result<bool, ServiceError> {
    match map.remove(name) {
        None => Ok(false),
        Some(Value::Bool(b)) => Ok(b),
        Some(v) => Err(ServiceError::InvalidJson(format!(
            "{name} is {v}; true or false expected"
        ))),
    }
}

/// Parses and validates a job's JSON: the [`TrainingSpec`] fields, plus `sensor` (absent or
/// `"paper_default"`, or a sensor design object), `activate` (bool), `shards` (1 to
/// [`MAX_SHARDS`], at most `scenes`) and `reproducible` (bool).
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
    let activate = flag(&mut map, "activate")?;
    let reproducible = flag(&mut map, "reproducible")?;
    let shards = match map.remove("shards") {
        None | Some(Value::Null) => None,
        Some(v) => Some(
            v.as_u64()
                .ok_or_else(|| bad(format!("shards is {v}; a whole number from 1 expected")))?,
        ),
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
    let shards = shards
        .map(|n| {
            let max = spec.n_batches().min(MAX_SHARDS);
            usize::try_from(n)
                .ok()
                .filter(|n| (1..=max).contains(n))
                .ok_or_else(|| {
                    ServiceError::BadRequest(format!(
                        "shards {n}: 1 to {max} (at most one per training scene, of which the job has {}, and at most {MAX_SHARDS})",
                        spec.n_batches()
                    ))
                })
        })
        .transpose()?;
    Ok((
        JobRequest {
            spec,
            sensor,
            activate,
            shards,
            reproducible,
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

/// A new job's row for `request_json` (sharded when `shards` is given).
fn new_job<'a>(
    id: &'a str,
    text: &'a str,
    sha: &'a str,
    activate: bool,
    shards: Option<usize>,
    idempotency_key: Option<&'a str>,
) -> NewJob<'a> {
    NewJob {
        id,
        kind: if shards.is_some() {
            JOB_KIND_SHARDED
        } else {
            JOB_KIND_TRAIN
        },
        shard_count: shards.map(|n| n as i64),
        request_json: text,
        idempotency_key,
        request_sha256: sha,
        activate,
        created_at: now_ms(),
    }
}

pub(super) fn wake_workers(state: &AppState) {
    state.job_notify.notify_waiters();
    state.job_notify.notify_one();
}

/// Inserts a queued job (with its survey shards when it asks for shards); returns its id, or
/// `None` when `idempotency_key` is already taken.
pub async fn enqueue(
    state: &AppState,
    request_json: &Value,
    req: &JobRequest,
    idempotency_key: Option<&str>,
) -> Result<Option<String>, ServiceError> {
    let id = new_id("job");
    let text = request_json.to_string();
    let sha = sha256_hex(text.as_bytes());
    let job = new_job(&id, &text, &sha, req.activate, req.shards, idempotency_key);
    if !state.store.insert_job(&job).await? {
        return Ok(None);
    }
    wake_workers(state);
    match req.shards {
        Some(n) => tracing::info!(job = id, shards = n, "training job queued in shards"),
        None => tracing::info!(job = id, "training job queued"),
    }
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
    let job = new_job(&id, &text, &sha, true, None, Some(DEFAULT_TABLE_JOB_KEY));
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

/// A shard in its job's description.
fn shard_json(s: &JobRow) -> Value {
    let running_ms = s
        .started_at
        .map(|t| s.finished_at.unwrap_or_else(now_ms) - t);
    json!({
        "id": s.id,
        "stage": shard_stage(&s.kind),
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
            "stage": shard_stage(&row.kind),
            "shard": row.shard_index.map(|k| k + 1),
            "count": row.shard_count,
        });
        v["links"]["cancel"] = json!(format!("/v1/training-jobs/{parent}/cancel"));
    }
    if row.kind == JOB_KIND_SHARDED {
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
    if let Some(id) = enqueue(&state, &value, &req, key.as_deref()).await? {
        let row = job_row(&state, &id).await?;
        return Ok(created(
            &id,
            job_view(&state, &row).await?,
            StatusCode::ACCEPTED,
        ));
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
    if row.kind == JOB_KIND_SHARDED {
        let Some(stopping) = state
            .store
            .end_sharded(&id, JobStatus::Canceled, None, now_ms())
            .await?
        else {
            let status = job_row(&state, &id).await?.status;
            return Err(ServiceError::Conflict(format!(
                "job '{id}' is {status}; only queued or running jobs can be canceled"
            )));
        };
        tracing::info!(job = id, "sharded training job canceled");
        for s in &stopping {
            signal_local(&state, s);
        }
        wait_stopped(&state, &stopping).await?;
        let row = job_row(&state, &id).await?;
        return Ok(Json(job_view(&state, &row).await?));
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

/// Puts the jobs this replica left `running` (a crash or restart) back in the queue.
pub async fn requeue_interrupted(state: &AppState) -> Result<u64, ServiceError> {
    state.store.requeue_owned(&state.replica_id).await
}

pub(super) fn lease(state: &AppState) -> Duration {
    Duration::from_secs_f64(state.config.training.job_lease_s)
}

pub(super) fn lease_until(state: &AppState) -> i64 {
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
                WORKER_KINDS,
                &state.replica_id,
                now_ms(),
                lease_until(&state),
            )
            .await;
        match claimed {
            Ok(Some(job)) if job.kind == JOB_KIND_TRAIN => {
                run_job(&state, &job.id, &job.request_json).await
            }
            Ok(Some(job)) => super::shard_jobs::run_shard(&state, job).await,
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

pub(super) async fn finish(
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
        compute_ms: None,
    };
    if !state.store.finish_job(id, &state.replica_id, &end).await? {
        tracing::warn!(
            job = id,
            "the job's lease was lost before it ended {status}; its outcome is not recorded here"
        );
    }
    Ok(())
}

/// The lease of a job this replica runs, renewed by a heartbeat task until [`Lease::end`]:
/// the heartbeat records the latest progress, brings back a cancel requested through any
/// replica (and a shutdown) as the cancel flag, and notices a lease lost (the job expired and
/// went back to the queue): then it stops beating and sets the flag.
pub(super) struct Lease {
    state: AppState,
    id: String,
    cancel: Arc<AtomicBool>,
    lost: Arc<AtomicBool>,
    ending: Arc<AtomicBool>,
    progress: Arc<Mutex<Option<(String, f64)>>>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    task: Option<tokio::task::JoinHandle<()>>,
}

impl Lease {
    /// Starts beating for the claimed job `id` (and registers its cancel flag).
    pub(super) fn start(state: &AppState, id: &str) -> Lease {
        let cancel = Arc::new(AtomicBool::new(false));
        state
            .running_jobs
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(id.to_string(), cancel.clone());
        let lost = Arc::new(AtomicBool::new(false));
        let ending = Arc::new(AtomicBool::new(false));
        let progress = Arc::new(Mutex::new(None));
        let (stop, stopped) = tokio::sync::oneshot::channel();
        let task = tokio::spawn(beat(
            state.clone(),
            id.to_string(),
            cancel.clone(),
            lost.clone(),
            ending.clone(),
            progress.clone(),
            stopped,
        ));
        Lease {
            state: state.clone(),
            id: id.to_string(),
            cancel,
            lost,
            ending,
            progress,
            stop: Some(stop),
            task: Some(task),
        }
    }

    /// The job's cancel flag (a cancel request, a shutdown, a lost lease).
    pub(super) fn cancel_flag(&self) -> Arc<AtomicBool> {
        self.cancel.clone()
    }

    pub(super) fn canceled(&self) -> bool {
        self.cancel.load(Ordering::SeqCst)
    }

    /// The progress callback of the job's work (`stage`, fraction).
    pub(super) fn reporter(&self) -> impl Fn(&str, f64) + Send + Sync + 'static {
        let p = self.progress.clone();
        move |stage: &str, f: f64| {
            let mut g = p.lock().unwrap_or_else(|e| e.into_inner());
            *g = Some((stage.to_string(), f));
        }
    }

    /// Says that the job is about to end its own lease (a shard's end recorded in the
    /// database): a heartbeat that finds the lease gone from then on is expected, not logged.
    pub(super) fn ending(&self) {
        self.ending.store(true, Ordering::SeqCst);
    }

    /// Stops the heartbeat; returns whether the lease was lost.
    pub(super) async fn end(mut self) -> bool {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(task) = self.task.take() {
            let _ = task.await;
        }
        self.lost.load(Ordering::SeqCst)
    }
}

impl Drop for Lease {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        self.state
            .running_jobs
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&self.id);
    }
}

/// The heartbeat of [`Lease`]: renews the lease, records progress (at once on a new stage),
/// looks for a cancel request.
async fn beat(
    state: AppState,
    id: String,
    cancel: Arc<AtomicBool>,
    lost: Arc<AtomicBool>,
    ending: Arc<AtomicBool>,
    progress: Arc<Mutex<Option<(String, f64)>>>,
    mut stop: tokio::sync::oneshot::Receiver<()>,
) {
    let every = HEARTBEAT.min(lease(&state) / 3);
    let mut last_beat = Instant::now();
    let mut last_stage = String::new();
    loop {
        tokio::select! {
            _ = &mut stop => return,
            _ = state.shutdown_notify.notified() => {
                cancel.store(true, Ordering::SeqCst);
            }
            _ = tokio::time::sleep(Duration::from_millis(50)) => {}
        }
        if state.shutting_down.load(Ordering::SeqCst) {
            cancel.store(true, Ordering::SeqCst);
        }
        let current = progress.lock().unwrap_or_else(|p| p.into_inner()).clone();
        let new_stage = current.as_ref().is_some_and(|(s, _)| *s != last_stage);
        if !(new_stage || last_beat.elapsed() >= every) {
            continue;
        }
        let p = current
            .as_ref()
            .map(|(s, f)| (s.as_str(), f.clamp(0.0, 1.0)));
        match state
            .store
            .heartbeat(&id, &state.replica_id, now_ms(), lease_until(&state), p)
            .await
        {
            Ok(Some(cancel_requested)) => {
                if cancel_requested {
                    cancel.store(true, Ordering::SeqCst);
                }
            }
            Ok(None) => {
                if !ending.load(Ordering::SeqCst) {
                    tracing::warn!(
                        job = id,
                        "the job's lease was lost (it expired or the job was re-queued); stopping it here"
                    );
                }
                lost.store(true, Ordering::SeqCst);
                cancel.store(true, Ordering::SeqCst);
                return;
            }
            Err(e) => tracing::error!(job = id, "heartbeat: {e}"),
        }
        last_beat = Instant::now();
        if let Some((stage, f)) = current
            && stage != last_stage
        {
            tracing::info!(job = id, stage = %stage, progress = format!("{:.0} %", f * 100.0), "training");
            last_stage = stage;
        }
    }
}

/// Runs `work` on the background pool and waits for it without blocking the runtime; a panic
/// (logged) or a lost task is an `Err` with what to record.
pub(super) async fn on_background<T, F>(state: &AppState, job: &str, work: F) -> Result<T, String>
where
    T: Send + 'static,
    F: FnOnce() -> T + Send + 'static,
{
    let (tx, rx) = tokio::sync::oneshot::channel();
    let job = job.to_string();
    super::cpu::spawn_catching(&state.pools.background, work, move |r| {
        let r = r.map_err(|msg| {
            tracing::error!(job = %job, panic = %msg, "training panicked");
            format!("training failed unexpectedly: {msg}")
        });
        let _ = tx.send(r);
    });
    rx.await
        .unwrap_or_else(|_| Err("the training task was lost".into()))
}

/// Writes a trained table as a job's table file (blocking): its times zeroed when the job
/// asked for a reproducible table, written atomically (with the fault-injection pause).
pub(super) fn write_job_table(
    state: &AppState,
    mut table: L3Table,
    reproducible: bool,
) -> Result<(L3Table, StoredTable), ServiceError> {
    if reproducible {
        table.meta.created_unix_s = 0;
        table.meta.training_seconds = 0.0;
    }
    let stored = write_table_file(&state.tables_dir, &table)?;
    Ok((table, stored))
}

/// Records a job's table in the database and activates it when job `job_id` asked for it.
pub(super) async fn publish_table(
    state: &AppState,
    job_id: &str,
    table: &L3Table,
    stored: &StoredTable,
) -> Result<(), ServiceError> {
    insert_table(state, stored, table, Some(job_id)).await?;
    if req_activate(state, job_id).await? {
        activate_table(state, &stored.id).await?;
    }
    Ok(())
}

enum Outcome {
    Done(Box<L3Table>, StoredTable),
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
    let lease = Lease::start(state, id);
    let (progress, cancel) = (lease.reporter(), lease.cancel_flag());
    let st = state.clone();
    let train =
        move || match train_table(&req.sensor, &req.spec, st.iset.as_ref(), &progress, &cancel) {
            Ok(table) => match write_job_table(&st, table, req.reproducible) {
                Ok((table, stored)) => Outcome::Done(Box::new(table), stored),
                Err(e) => Outcome::Failed(e.to_string()),
            },
            Err(LearnError::Canceled) => Outcome::Canceled,
            Err(e) => Outcome::Failed(e.to_string()),
        };
    let outcome = on_background(state, id, train).await;
    let lease_lost = lease.end().await;
    let result = match outcome {
        _ if lease_lost => Ok(()),
        Err(msg) => finish(state, id, JobStatus::Failed, Some(&msg), None).await,
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
                publish_table(state, id, &table, &stored).await?;
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
        assert_eq!((r.shards, r.reproducible), (None, false));
        let (r, _) =
            parse_job_request(br#"{"scenes":4,"shards":4.0,"reproducible":true}"#).unwrap();
        assert_eq!((r.shards, r.reproducible), (Some(4), true));
        for (body, needle) in [
            (&b"{"[..], "not valid JSON"),
            (b"[1]", "JSON object"),
            (br#"{"bogus":1}"#, "bogus"),
            (br#"{"levels":1}"#, "levels 1"),
            (br#"{"activate":"yes"}"#, "activate"),
            (br#"{"sensor":"nikon"}"#, "nikon"),
            (br#"{"scenes":4.5}"#, "scenes"),
            (br#"{"shards":0}"#, "shards 0: 1 to 48"),
            (br#"{"scenes":3,"shards":4}"#, "shards 4: 1 to 3"),
            (br#"{"scenes":100,"shards":65}"#, "at most 64"),
            (br#"{"shards":-1}"#, "shards"),
            (br#"{"shards":"2"}"#, "shards"),
            (br#"{"reproducible":1}"#, "reproducible"),
        ] {
            let e = parse_job_request(body).unwrap_err();
            assert!(e.to_string().contains(needle), "{e}");
            assert_eq!(e.status().as_u16(), 400);
        }
    }
}
