//! Training jobs: submission (idempotent), listing, cancel, and the runner that trains on
//! rayon, persists the table and optionally activates it. Jobs found `running` at start
//! (a crash or a restart) go back to `queued` and run again.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path as UrlPath, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};
use sqlx::Row;

use super::ServiceError;
use super::state::{AppState, new_id, now_ms, sha256_hex};
use super::tables::{activate_table, insert_table, write_table_file_with_pause};
use crate::camera::SensorDesign;
use crate::l3::L3Error;
use crate::training::{TrainError, TrainingSpec, train_table};

/// Every job state, in lifecycle order.
pub const JOB_STATES: [&str; 5] = ["queued", "running", "succeeded", "failed", "canceled"];

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

/// Inserts a queued job; returns its id.
pub async fn enqueue(
    state: &AppState,
    request_json: &Value,
    activate: bool,
    idempotency_key: Option<&str>,
) -> Result<String, ServiceError> {
    let id = new_id("job");
    let text = request_json.to_string();
    sqlx::query(
        "INSERT INTO training_jobs (id, status, request_json, idempotency_key, request_sha256, activate, progress, stage, created_at)
         VALUES ($1, 'queued', $2, $3, $4, $5, 0, 'queued', $6)",
    )
    .bind(&id)
    .bind(&text)
    .bind(idempotency_key)
    .bind(sha256_hex(text.as_bytes()))
    .bind(i64::from(activate))
    .bind(now_ms())
    .execute(&state.db)
    .await?;
    state.job_notify.notify_waiters();
    state.job_notify.notify_one();
    tracing::info!(job = id, "training job queued");
    Ok(id)
}

fn job_json(row: &sqlx::sqlite::SqliteRow) -> Result<Value, ServiceError> {
    let id: String = row.try_get("id")?;
    let created: i64 = row.try_get("created_at")?;
    let started: Option<i64> = row.try_get("started_at")?;
    let finished: Option<i64> = row.try_get("finished_at")?;
    let request: Value =
        serde_json::from_str(&row.try_get::<String, _>("request_json")?).unwrap_or(Value::Null);
    let now = now_ms();
    let queued_ms = started.unwrap_or(finished.unwrap_or(now)) - created;
    let running_ms = started.map(|s| finished.unwrap_or(now) - s);
    Ok(json!({
        "id": id,
        "status": row.try_get::<String, _>("status")?,
        "progress": row.try_get::<f64, _>("progress")?,
        "stage": row.try_get::<Option<String>, _>("stage")?,
        "error": row.try_get::<Option<String>, _>("error")?,
        "table_id": row.try_get::<Option<String>, _>("table_id")?,
        "activate": row.try_get::<i64, _>("activate")? != 0,
        "attempts": row.try_get::<i64, _>("attempts")?,
        "idempotency_key": row.try_get::<Option<String>, _>("idempotency_key")?,
        "request": request,
        "created_at_ms": created,
        "started_at_ms": started,
        "finished_at_ms": finished,
        "timings": { "queued_ms": queued_ms.max(0), "running_ms": running_ms.map(|v| v.max(0)) },
        "links": { "self": format!("/v1/training-jobs/{id}"), "cancel": format!("/v1/training-jobs/{id}/cancel") },
    }))
}

async fn job_row(state: &AppState, id: &str) -> Result<sqlx::sqlite::SqliteRow, ServiceError> {
    sqlx::query("SELECT * FROM training_jobs WHERE id = $1")
        .bind(id)
        .fetch_optional(&state.db)
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
    if let Some(k) = &key
        && let Some(row) = sqlx::query("SELECT * FROM training_jobs WHERE idempotency_key = $1")
            .bind(k)
            .fetch_optional(&state.db)
            .await?
    {
        let same: String = row.try_get("request_sha256")?;
        if same != sha256_hex(value.to_string().as_bytes()) {
            return Err(ServiceError::Conflict(format!(
                "Idempotency-Key '{k}' was already used with a different request body"
            )));
        }
        let id: String = row.try_get("id")?;
        return Ok(created(&id, job_json(&row)?, StatusCode::OK));
    }
    let id = enqueue(&state, &value, req.activate, key.as_deref()).await?;
    let row = job_row(&state, &id).await?;
    Ok(created(&id, job_json(&row)?, StatusCode::ACCEPTED))
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
    let rows = match &q.status {
        Some(s) => {
            if !JOB_STATES.contains(&s.as_str()) {
                return Err(ServiceError::BadRequest(format!(
                    "status '{s}': one of {}",
                    JOB_STATES.join(", ")
                )));
            }
            sqlx::query(
                "SELECT * FROM training_jobs WHERE status = $1 ORDER BY created_at DESC, id LIMIT $2",
            )
            .bind(s)
            .bind(limit)
            .fetch_all(&state.db)
            .await?
        }
        None => {
            sqlx::query("SELECT * FROM training_jobs ORDER BY created_at DESC, id LIMIT $1")
                .bind(limit)
                .fetch_all(&state.db)
                .await?
        }
    };
    let items = rows.iter().map(job_json).collect::<Result<Vec<_>, _>>()?;
    Ok(Json(json!({ "items": items })))
}

/// `GET /v1/training-jobs/{id}`
pub async fn get(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    Ok(Json(job_json(&job_row(&state, &id).await?)?))
}

/// `POST /v1/training-jobs/{id}/cancel`: a queued job is canceled at once; a running one is
/// signalled and the answer waits (up to 2 s) until it has stopped.
pub async fn cancel(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    let row = job_row(&state, &id).await?;
    let status: String = row.try_get("status")?;
    match status.as_str() {
        "queued" => {
            sqlx::query(
                "UPDATE training_jobs SET status = 'canceled', stage = 'canceled', finished_at = $1
                 WHERE id = $2 AND status = 'queued'",
            )
            .bind(now_ms())
            .bind(&id)
            .execute(&state.db)
            .await?;
        }
        "running" => {
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
                let s: String = job_row(&state, &id).await?.try_get("status")?;
                if s != "running" {
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
    Ok(Json(job_json(&job_row(&state, &id).await?)?))
}

/// Puts jobs left `running` by a crash or restart back in the queue.
pub async fn requeue_interrupted(state: &AppState) -> Result<u64, ServiceError> {
    let r = sqlx::query(
        "UPDATE training_jobs SET status = 'queued', stage = 'requeued after restart', progress = 0
         WHERE status = 'running'",
    )
    .execute(&state.db)
    .await?;
    Ok(r.rows_affected())
}

/// One job worker: claims the oldest queued job, runs it, repeats until shutdown.
pub async fn worker(state: AppState) {
    loop {
        if state.shutting_down.load(Ordering::SeqCst) {
            return;
        }
        match claim_next(&state).await {
            Ok(Some((id, request))) => run_job(&state, &id, &request).await,
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

async fn claim_next(state: &AppState) -> Result<Option<(String, String)>, ServiceError> {
    loop {
        let Some(row) = sqlx::query(
            "SELECT id, request_json FROM training_jobs WHERE status = 'queued'
             ORDER BY created_at, id LIMIT 1",
        )
        .fetch_optional(&state.db)
        .await?
        else {
            return Ok(None);
        };
        let id: String = row.try_get("id")?;
        let claimed = sqlx::query(
            "UPDATE training_jobs SET status = 'running', stage = 'starting', progress = 0,
             attempts = attempts + 1, started_at = $1 WHERE id = $2 AND status = 'queued'",
        )
        .bind(now_ms())
        .bind(&id)
        .execute(&state.db)
        .await?
        .rows_affected();
        if claimed == 1 {
            return Ok(Some((id, row.try_get("request_json")?)));
        }
    }
}

async fn finish(
    state: &AppState,
    id: &str,
    status: &str,
    error: Option<&str>,
    table_id: Option<&str>,
) -> Result<(), ServiceError> {
    let progress = if status == "succeeded" { 1.0 } else { -1.0 };
    sqlx::query(
        "UPDATE training_jobs SET status = $1, stage = $1, error = $2, table_id = $3,
         progress = CASE WHEN $4 >= 0 THEN $4 ELSE progress END, finished_at = $5 WHERE id = $6",
    )
    .bind(status)
    .bind(error)
    .bind(table_id)
    .bind(progress)
    .bind(now_ms())
    .bind(id)
    .execute(&state.db)
    .await?;
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
            let _ = finish(state, id, "failed", Some(&e.to_string()), None).await;
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
            Ok(table) => match write_table_file_with_pause(
                &st.tables_dir,
                &table,
                super::debug_hooks::activation_pause_ms(),
            ) {
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
    let mut last_write = Instant::now() - Duration::from_secs(1);
    let mut last_stage = String::new();
    let mut pending: Option<(String, f64)> = None;
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
        if let Some((stage, f)) = &pending
            && (last_write.elapsed() >= Duration::from_millis(200) || *stage != last_stage)
        {
            let _ = sqlx::query(
                "UPDATE training_jobs SET stage = $1, progress = $2 WHERE id = $3 AND status = 'running'",
            )
            .bind(stage)
            .bind(f.clamp(0.0, 1.0))
            .bind(id)
            .execute(&state.db)
            .await;
            if *stage != last_stage {
                tracing::info!(job = id, stage = %stage, progress = format!("{:.0} %", f * 100.0), "training");
            }
            last_stage = stage.clone();
            last_write = Instant::now();
            pending = None;
        }
    };
    state
        .running_jobs
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .remove(id);
    let result = match outcome {
        Err(_) => {
            finish(
                state,
                id,
                "failed",
                Some("the training task was lost"),
                None,
            )
            .await
        }
        Ok(Outcome::Canceled) if state.shutting_down.load(Ordering::SeqCst) => {
            tracing::info!(job = id, "training job interrupted by shutdown; re-queued");
            sqlx::query(
                "UPDATE training_jobs SET status = 'queued', stage = 'interrupted by shutdown', progress = 0 WHERE id = $1",
            )
            .bind(id)
            .execute(&state.db)
            .await
            .map(|_| ())
            .map_err(ServiceError::from)
        }
        Ok(Outcome::Canceled) => {
            tracing::info!(job = id, "training job canceled");
            finish(state, id, "canceled", None, None).await
        }
        Ok(Outcome::Failed(msg)) => {
            tracing::warn!(job = id, "training job failed: {msg}");
            finish(state, id, "failed", Some(&msg), None).await
        }
        Ok(Outcome::Done(table, stored)) => {
            let r = async {
                insert_table(state, &stored, &table, Some(id)).await?;
                if req_activate(state, id).await? {
                    activate_table(state, &stored.id).await?;
                }
                finish(state, id, "succeeded", None, Some(&stored.id)).await
            }
            .await;
            tracing::info!(job = id, table = stored.id, "training job succeeded");
            match r {
                Ok(()) => Ok(()),
                Err(e) => finish(state, id, "failed", Some(&e.to_string()), None).await,
            }
        }
    };
    if let Err(e) = result {
        tracing::error!(job = id, "cannot record the job's outcome: {e}");
    }
}

async fn req_activate(state: &AppState, id: &str) -> Result<bool, ServiceError> {
    Ok(job_row(state, id).await?.try_get::<i64, _>("activate")? != 0)
}

/// Job counts by state (for /metrics).
pub async fn counts(state: &AppState) -> Result<Vec<(String, i64)>, ServiceError> {
    let rows = sqlx::query("SELECT status, COUNT(*) AS n FROM training_jobs GROUP BY status")
        .fetch_all(&state.db)
        .await?;
    rows.iter()
        .map(|r| Ok((r.try_get("status")?, r.try_get("n")?)))
        .collect()
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
