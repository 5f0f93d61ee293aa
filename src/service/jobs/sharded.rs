//! Training sharded across replicas: a job that asks for `shards: N` is queued as N survey
//! shards (then N accumulation shards), rows of their own that any replica claims like jobs,
//! under the same lease and heartbeat ([`super::queue::Lease`]), retried after a lease expiry.
//!
//! The steps are those of `l3 train --phase survey|accumulate|merge` (`src/cli/train.rs`),
//! through the same core calls ([`TrainingRun::survey_shard`], [`TrainingRun::classes`],
//! [`TrainingRun::accumulate_shard`], [`TrainingRun::finish_timed`]), with the partial sums
//! kept in the database instead of files:
//!
//! 1. A survey shard surveys its batches and stores the partial's bytes. The last survey shard
//!    to end queues the accumulation shards.
//! 2. An accumulation shard derives the run's classes from every survey partial, accumulates
//!    its batches' normal equations and stores them. The last one to end (found under a lock
//!    of the job's row) reads every part, merges them in the core's fixed order, solves, and
//!    writes the table as an unsharded job does; then the job has succeeded.
//!
//! A shard whose partial is already stored (an earlier attempt got that far) does not compute
//! it again. Every stored partial is checked against its recorded SHA-256 when it is read back
//! (and the format checks its own checksum). The table bytes do not depend on the number of
//! shards (`src/l3/learn/shards.rs`).

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;

use super::queue::{Lease, finish, wake_workers};
use super::request::{JobRequest, parse_job_request};
use super::training::{on_background, publish_table, write_job_table};
use crate::l3::learn::{Classes, GramPartial, LearnError, ShardSpec, SurveyPartial, TrainingRun};
use crate::service::ServiceError;
use crate::service::state::{AppState, now_ms, sha256_hex};
use crate::service::store::{
    JobKind, JobRow, JobStage, JobStatus, NewPartial, ShardCompletion, ShardStage, StoreError,
};

/// What stops a shard.
#[derive(Debug, thiserror::Error)]
pub enum ShardError {
    #[error(transparent)]
    Learn(#[from] LearnError),
    #[error(transparent)]
    Service(#[from] ServiceError),
    #[error(transparent)]
    Store(#[from] StoreError),
    /// Stored partial sums that are missing, damaged or not of this job.
    #[error("partial sums of {stage} shard {shard}: {why}")]
    Partial {
        stage: ShardStage,
        shard: i64,
        why: String,
    },
    /// The shard's work panicked or was lost.
    #[error("{0}")]
    Task(String),
    /// A row that is not a shard of a job.
    #[error("job '{0}' is not a shard of a sharded job")]
    NotAShard(String),
}

impl ShardError {
    fn is_canceled(&self) -> bool {
        matches!(self, ShardError::Learn(LearnError::Canceled))
    }
}

/// How a shard's steps ended (when they did not fail).
enum Step {
    /// Its partial sums are stored and its end recorded.
    Done,
    /// It was the last accumulation shard and merged: the job has succeeded.
    Merged,
    /// Its job ended meanwhile (canceled, or failed in another shard).
    JobEnded,
    /// Its lease is not this replica's any more.
    LeaseLost,
}

/// What a shard works from: its job, its place in the job, the job's request.
struct Shard<'a> {
    row: &'a JobRow,
    job: &'a str,
    stage: ShardStage,
    index: i64,
    count: i64,
    req: JobRequest,
}

impl Shard<'_> {
    fn bad(&self, why: impl Into<String>) -> ShardError {
        ShardError::Partial {
            stage: self.stage,
            shard: self.index + 1,
            why: why.into(),
        }
    }
}

/// Runs a claimed shard and records how it ended: succeeded (the job too when it merged),
/// canceled, re-queued by a shutdown, or failed (which fails its job and stops the job's
/// other shards).
pub(super) async fn run_shard(state: &AppState, row: JobRow) {
    let id = row.id.clone();
    let Some(job) = row.parent_id.clone() else {
        let msg = ShardError::NotAShard(id.clone()).to_string();
        let _ = finish(state, &id, JobStatus::Failed, Some(&msg), None).await;
        return;
    };
    tracing::info!(job = %job, shard = %id, "training shard started");
    let lease = Lease::start(state, &id);
    if let Err(e) = state.store.start_sharded(&job, now_ms()).await {
        tracing::error!(job = %job, "cannot mark the job running: {e}");
    }
    let result = steps(state, &row, &job, &lease).await;
    let lease_lost = lease.end().await;
    if !matches!(result, Ok(Step::Done)) {
        // the job is over here (merged, ended, failed) or the shard stops: the prepared run
        // is not needed any more
        forget_run(state, &job);
    }
    let recorded = match result {
        _ if lease_lost => Ok(()),
        Ok(Step::Done) => Ok(()),
        Ok(Step::LeaseLost) => {
            tracing::warn!(shard = %id, "the shard's lease was lost before it ended; another attempt records it");
            Ok(())
        }
        // the merge ended the shard with its job
        Ok(Step::Merged) => Ok(()),
        Ok(Step::JobEnded) => {
            tracing::info!(job = %job, shard = %id, "training shard stopped: its job has ended");
            finish(state, &id, JobStatus::Canceled, None, None).await
        }
        Err(e) if e.is_canceled() && state.shutting_down.load(Ordering::SeqCst) => {
            tracing::info!(shard = %id, "training shard interrupted by shutdown; re-queued");
            state
                .store
                .requeue_job(&id, &state.replica_id, JobStage::InterruptedByShutdown)
                .await
                .map_err(ServiceError::from)
        }
        Err(e) if e.is_canceled() => {
            tracing::info!(job = %job, shard = %id, "training shard canceled");
            finish(state, &id, JobStatus::Canceled, None, None).await
        }
        Err(e) => {
            let msg = e.to_string();
            tracing::warn!(job = %job, shard = %id, "training shard failed: {msg}");
            let why = format!("shard {id} failed: {msg}");
            let ended = state
                .store
                .end_sharded(&job, JobStatus::Failed, Some(&why), now_ms())
                .await;
            if let Err(e) = ended {
                tracing::error!(job = %job, "cannot record the job's failure: {e}");
            }
            finish(state, &id, JobStatus::Failed, Some(&msg), None).await
        }
    };
    if let Err(e) = recorded {
        tracing::error!(shard = %id, "cannot record the shard's outcome: {e}");
    }
}

/// The training run of job `job`: the one this replica prepared last when it is that job's,
/// else prepared now (on the background pool) and kept for the job's next shard here.
async fn training_run(
    state: &AppState,
    job: &str,
    req: &JobRequest,
) -> Result<Arc<TrainingRun>, ShardError> {
    let cached = state
        .training_run
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .as_ref()
        .filter(|(id, _)| id == job)
        .map(|(_, run)| run.clone());
    if let Some(run) = cached {
        return Ok(run);
    }
    let (st, sensor, spec) = (state.clone(), req.sensor.clone(), req.spec.clone());
    let run = on_background(state, job, move || {
        TrainingRun::new(&sensor, &spec, st.iset.as_ref())
    })
    .await
    .map_err(ShardError::Task)??;
    let run = Arc::new(run);
    *state.training_run.lock().unwrap_or_else(|p| p.into_inner()) =
        Some((job.to_string(), run.clone()));
    Ok(run)
}

/// Drops the prepared run of job `job`, if it is the one kept.
fn forget_run(state: &AppState, job: &str) {
    let mut kept = state.training_run.lock().unwrap_or_else(|p| p.into_inner());
    if kept.as_ref().is_some_and(|(id, _)| id == job) {
        *kept = None;
    }
}

/// The stored partials of `stage`, every shard's, checked against their SHA-256.
async fn stored_parts(
    state: &AppState,
    shard: &Shard<'_>,
    stage: ShardStage,
    only: Option<i64>,
) -> Result<Vec<Vec<u8>>, ShardError> {
    let parts = state.store.partials(shard.job, stage, only).await?;
    let mut out = Vec::with_capacity(parts.len());
    for p in parts {
        if sha256_hex(&p.content) != p.sha256 {
            return Err(ShardError::Partial {
                stage,
                shard: p.shard_index + 1,
                why: "the stored bytes do not match their SHA-256".into(),
            });
        }
        out.push(p.content);
    }
    Ok(out)
}

/// Every part of `stage`, one per shard, in shard order.
async fn all_parts(
    state: &AppState,
    shard: &Shard<'_>,
    stage: ShardStage,
) -> Result<Vec<Vec<u8>>, ShardError> {
    let parts = stored_parts(state, shard, stage, None).await?;
    if parts.len() as i64 != shard.count {
        return Err(ShardError::Partial {
            stage,
            shard: shard.index + 1,
            why: format!(
                "{} of {} {stage} parts are stored",
                parts.len(),
                shard.count
            ),
        });
    }
    Ok(parts)
}

async fn steps(
    state: &AppState,
    row: &JobRow,
    job: &str,
    lease: &Lease,
) -> Result<Step, ShardError> {
    let stage = row
        .kind
        .shard_stage()
        .ok_or_else(|| ShardError::NotAShard(row.id.clone()))?;
    let (req, _) = parse_job_request(row.request_json.as_bytes())?;
    let shard = Shard {
        row,
        job,
        stage,
        index: row.shard_index.unwrap_or(0),
        count: row.shard_count.unwrap_or(1),
        req,
    };
    let run = training_run(state, job, &shard.req).await?;
    let spec = run
        .plan(usize::try_from(shard.count).unwrap_or(0))?
        .into_iter()
        .nth(usize::try_from(shard.index).unwrap_or(usize::MAX))
        .ok_or_else(|| shard.bad(format!("no shard {} of {}", shard.index + 1, shard.count)))?;
    let started = Instant::now();
    // an accumulation needs the run's classes, from every survey part
    let classes = if row.kind == JobKind::AccumulateShard {
        let surveys = all_parts(state, &shard, ShardStage::Survey).await?;
        let r = run.clone();
        let classes = on_background(state, &row.id, move || -> Result<Classes, ShardError> {
            let parts = surveys
                .iter()
                .map(|b| SurveyPartial::from_bytes(b))
                .collect::<Result<Vec<_>, _>>()?;
            Ok(r.classes(&parts)?)
        })
        .await
        .map_err(ShardError::Task)??;
        Some(classes)
    } else {
        None
    };
    // this shard's part: stored by an earlier attempt, else computed and stored
    let mine = stored_parts(state, &shard, stage, Some(shard.index)).await?;
    let size = match mine.into_iter().next() {
        Some(bytes) => {
            tracing::info!(shard = %row.id, "partial sums already stored by an earlier attempt");
            bytes.len()
        }
        None => compute_part(state, &shard, &run, &spec, classes.clone(), lease).await?,
    };
    let compute_ms = started.elapsed().as_millis() as i64;
    tracing::info!(
        job = %job,
        shard = %row.id,
        stage = stage.as_str(),
        batches = format!("{}..{}", spec.start, spec.end),
        seconds = format!("{:.3}", compute_ms as f64 / 1e3),
        bytes = size,
        "{stage} shard {} of {} done",
        shard.index + 1,
        shard.count
    );
    lease.ending();
    let completion = state
        .store
        .complete_shard(row, &state.replica_id, now_ms(), compute_ms)
        .await?;
    Ok(match completion {
        ShardCompletion::Done => Step::Done,
        ShardCompletion::ParentEnded => Step::JobEnded,
        ShardCompletion::LeaseLost => Step::LeaseLost,
        ShardCompletion::Last if row.kind == JobKind::SurveyShard => {
            wake_workers(state);
            Step::Done
        }
        ShardCompletion::Last => {
            let classes = classes.ok_or_else(|| shard.bad("no classes to merge with"))?;
            merge(state, &shard, &run, classes, lease).await?
        }
    })
}

/// Computes this shard's partial sums (survey, or accumulation for `classes`) on the
/// background pool and stores their bytes; returns their size.
async fn compute_part(
    state: &AppState,
    shard: &Shard<'_>,
    run: &Arc<TrainingRun>,
    spec: &ShardSpec,
    classes: Option<Classes>,
    lease: &Lease,
) -> Result<usize, ShardError> {
    let (r, spec) = (run.clone(), spec.clone());
    let (progress, cancel) = (lease.reporter(), lease.cancel_flag());
    let bytes = on_background(
        state,
        &shard.row.id,
        move || -> Result<Vec<u8>, ShardError> {
            Ok(match classes {
                None => r.survey_shard(&spec, &progress, &cancel)?.to_bytes()?,
                Some(c) => r
                    .accumulate_shard(&spec, &c, &progress, &cancel)?
                    .to_bytes()?,
            })
        },
    )
    .await
    .map_err(ShardError::Task)??;
    if lease.canceled() {
        return Err(LearnError::Canceled.into());
    }
    let sha = sha256_hex(&bytes);
    state
        .store
        .store_partial(&NewPartial {
            job_id: shard.job,
            stage: shard.stage,
            shard_index: shard.index,
            content: &bytes,
            sha256: &sha,
            replica: &state.replica_id,
            created_at: now_ms(),
        })
        .await?;
    Ok(bytes.len())
}

/// The last accumulation shard: every part read and checked, merged in the core's order,
/// solved, the table written and recorded as an unsharded job's is, the job succeeded.
async fn merge(
    state: &AppState,
    shard: &Shard<'_>,
    run: &Arc<TrainingRun>,
    classes: Classes,
    lease: &Lease,
) -> Result<Step, ShardError> {
    let started = Instant::now();
    let parts = all_parts(state, shard, ShardStage::Accumulate).await?;
    let read_s = started.elapsed().as_secs_f64();
    let job_row = state
        .store
        .job(shard.job)
        .await?
        .ok_or_else(|| shard.bad("the job is gone"))?;
    let job_started = job_row.started_at.unwrap_or(job_row.created_at);
    let (r, reproducible) = (run.clone(), shard.req.reproducible);
    let (progress, cancel) = (lease.reporter(), lease.cancel_flag());
    let st = state.clone();
    let (table, stored, merge_s) = on_background(state, &shard.row.id, move || {
        let parts = parts
            .iter()
            .map(|b| GramPartial::from_bytes(b))
            .collect::<Result<Vec<_>, _>>()?;
        let (mut table, merge_s) = r.finish_timed(classes, parts, &progress, &cancel)?;
        // the job's wall time, from its first shard's start
        table.meta.training_seconds = (now_ms() - job_started).max(0) as f64 / 1e3;
        let (table, stored) = write_job_table(&st, table, reproducible)?;
        Ok::<_, ShardError>((table, stored, merge_s))
    })
    .await
    .map_err(ShardError::Task)??;
    if lease.canceled() {
        return Err(LearnError::Canceled.into());
    }
    let still_running = state
        .store
        .job(shard.job)
        .await?
        .is_some_and(|j| j.status == JobStatus::Running);
    if !still_running {
        return Ok(Step::JobEnded);
    }
    publish_table(state, shard.job, &table, &stored).await?;
    let total_s = started.elapsed().as_secs_f64();
    let merge_ms = (total_s * 1e3) as i64;
    if !state
        .store
        .finish_sharded(
            shard.job,
            &shard.row.id,
            &stored.id,
            merge_ms,
            &state.replica_id,
            now_ms(),
        )
        .await?
    {
        return Ok(Step::JobEnded);
    }
    tracing::info!(
        job = %shard.job,
        table = %stored.id,
        seconds = format!("{total_s:.3}"),
        reading = format!("{read_s:.3}"),
        merging = format!("{merge_s:.3}"),
        "sharded training job merged and succeeded ({} shards)",
        shard.count
    );
    Ok(Step::Merged)
}
