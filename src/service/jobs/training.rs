//! Running a training job trained in one piece: the training on the background pool under the
//! job's lease, the table written (atomically) and recorded, activated when the job asked for
//! it; and what sharded training shares with it (the background pool, writing and publishing
//! a job's table).

use std::sync::atomic::Ordering;

use super::queue::{Lease, finish};
use super::request::parse_job_request;
use crate::service::ServiceError;
use crate::service::state::AppState;
use crate::service::store::{JobStage, JobStatus};
use crate::service::tables::{StoredTable, activate_table, insert_table, write_table_file};

use crate::l3::L3Table;
use crate::l3::learn::LearnError;
use crate::l3::learn::train_table;

/// Runs `work` on the background pool and waits for it without blocking the runtime; a panic
/// (logged) or a lost task is an `Err` with what to record.
pub(super) async fn on_background<T, F>(state: &AppState, job: &str, work: F) -> Result<T, String>
where
    T: Send + 'static,
    F: FnOnce() -> T + Send + 'static,
{
    let (tx, rx) = tokio::sync::oneshot::channel();
    let job = job.to_string();
    crate::service::cpu::spawn_catching(&state.pools.background, work, move |r| {
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

pub(super) async fn run_job(state: &AppState, id: &str, request: &str) {
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
                .requeue_job(id, &state.replica_id, JobStage::InterruptedByShutdown)
                .await
                .map_err(ServiceError::from)
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
    Ok(state.store.existing_job(id).await?.activate)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;
    use std::sync::Mutex;
    use std::sync::atomic::AtomicBool;

    use super::*;

    /// Every stage the training reports is one a job records (a stage it does not know would
    /// leave the job's stage as it was).
    #[test]
    fn the_training_reports_stages_a_job_records() {
        let body = br#"{"illuminants":["D65"],"scenes":4,"scene_size":48,"levels":10}"#;
        let (req, _) = parse_job_request(body).unwrap();
        let stages = Mutex::new(BTreeSet::new());
        let progress = |stage: &str, _: f64| {
            stages.lock().unwrap().insert(stage.to_string());
        };
        train_table(
            &req.sensor,
            &req.spec,
            None,
            &progress,
            &AtomicBool::new(false),
        )
        .unwrap();
        let stages = stages.into_inner().unwrap();
        assert!(!stages.is_empty());
        for s in &stages {
            assert!(JobStage::parse(s).is_ok(), "{s} of {stages:?}");
        }
    }
}
