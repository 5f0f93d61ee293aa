//! The job queue and its leases: queueing a job (idempotent, once per database for the
//! default table), and the lease of a job this replica runs, renewed by a heartbeat that
//! records its progress and brings back a cancel requested through any replica. A job whose
//! replica died (its lease expired) goes back to the queue, as do the jobs a restarted replica
//! had left running.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::Value;

use super::request::JobRequest;
use crate::service::ServiceError;
use crate::service::state::{AppState, new_id, now_ms, sha256_hex};
use crate::service::store::{JobEnd, JobKind, JobStage, JobStatus, NewJob, Progress};

/// How often a running job's replica renews its lease, records progress and looks for a
/// cancel request (at most; shorter leases beat faster).
const HEARTBEAT: Duration = Duration::from_millis(250);

/// The idempotency key of the default table's training job: one per cluster.
pub const DEFAULT_TABLE_JOB_KEY: &str = "l3:default-table";

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
            JobKind::Sharded
        } else {
            JobKind::Train
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

/// Puts the jobs this replica left `running` (a crash or restart) back in the queue.
pub async fn requeue_interrupted(state: &AppState) -> Result<u64, ServiceError> {
    Ok(state.store.requeue_owned(&state.replica_id).await?)
}

pub(super) fn lease(state: &AppState) -> Duration {
    Duration::from_secs_f64(state.config.training.job_lease_s)
}

pub(super) fn lease_until(state: &AppState) -> i64 {
    now_ms() + lease(state).as_millis() as i64
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
        // a stage of the training's that the service does not know leaves the recorded one
        let p = current.as_ref().map(|(s, f)| Progress {
            stage: JobStage::parse(s).ok(),
            fraction: f.clamp(0.0, 1.0),
        });
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
            if JobStage::parse(&stage).is_err() {
                tracing::warn!(
                    job = id,
                    "training stage '{stage}' is not one the job records"
                );
            }
            last_stage = stage;
        }
    }
}
