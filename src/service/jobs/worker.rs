//! The job worker: returns the jobs of dead replicas to the queue, claims the oldest queued
//! job (or shard) this replica can run, runs it, repeats until shutdown.

use std::sync::atomic::Ordering;
use std::time::Duration;

use super::queue::lease_until;
use super::{sharded, training};
use crate::service::state::{AppState, now_ms};
use crate::service::store::{JobKind, WORKER_KINDS};

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
            Ok(Some(job)) if job.kind == JobKind::Train => {
                training::run_job(&state, &job.id, &job.request_json).await
            }
            Ok(Some(job)) => sharded::run_shard(&state, job).await,
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
