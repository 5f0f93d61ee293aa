//! Job leases: a replica claims the oldest queued job under a lease it renews with a
//! heartbeat (which records progress and brings back a cancel request), and ends the job or
//! puts it back in the queue. Jobs whose lease expired, and those a restarted replica had left
//! running, go back to the queue.

use super::Store;
use super::columns::{JobKind, JobStage, JobStatus, flag};
use super::error::StoreError;
use super::jobs::{JobRow, StoredJobRow, job_row};

/// How a running job ends.
#[derive(Debug, Clone)]
pub struct JobEnd<'a> {
    pub status: JobStatus,
    pub error: Option<&'a str>,
    pub table_id: Option<&'a str>,
    pub finished_at: i64,
    /// A shard's own work, milliseconds.
    pub compute_ms: Option<i64>,
}

/// The progress a heartbeat records: the fraction done, and the stage when it is one the
/// service knows (else the stage recorded is left as it is).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    pub stage: Option<JobStage>,
    pub fraction: f64,
}

impl Store {
    /// Claims the oldest queued job of one of `kinds` for `owner` under a lease until
    /// `lease_until`: `SELECT … FOR UPDATE SKIP LOCKED` on PostgreSQL, one atomic UPDATE on
    /// SQLite (a single writer). Shards carry their job's creation time, so they come in the
    /// order of their jobs, by index within one.
    pub async fn claim_job(
        &self,
        kinds: &[JobKind],
        owner: &str,
        now: i64,
        lease_until: i64,
    ) -> Result<Option<JobRow>, StoreError> {
        let kinds_sql = (0..kinds.len().max(1))
            .map(|i| format!("${}", i + 7))
            .collect::<Vec<_>>()
            .join(", ");
        let sql = match self {
            Store::Postgres(_) => format!(
                "UPDATE training_jobs SET status = $1, stage = $6, progress = 0,
                 attempts = attempts + 1, started_at = $2, lease_owner = $3,
                 lease_expires_at = $4, heartbeat_at = $2
                 WHERE id = (SELECT id FROM training_jobs WHERE status = $5 AND kind IN ({kinds_sql})
                             ORDER BY created_at, COALESCE(shard_index, 0), id
                             LIMIT 1 FOR UPDATE SKIP LOCKED)
                 RETURNING *"
            ),
            Store::Sqlite(_) => format!(
                "UPDATE training_jobs SET status = $1, stage = $6, progress = 0,
                 attempts = attempts + 1, started_at = $2, lease_owner = $3,
                 lease_expires_at = $4, heartbeat_at = $2
                 WHERE status = $5 AND id = (SELECT id FROM training_jobs
                                             WHERE status = $5 AND kind IN ({kinds_sql})
                                             ORDER BY created_at, COALESCE(shard_index, 0), id
                                             LIMIT 1)
                 RETURNING *"
            ),
        };
        let row = on_pool!(self, p => {
            let mut q = sqlx::query_as::<_, StoredJobRow>(&sql)
                .bind(JobStatus::Running.as_str())
                .bind(now)
                .bind(owner)
                .bind(lease_until)
                .bind(JobStatus::Queued.as_str())
                .bind(JobStage::Starting.as_str());
            if kinds.is_empty() {
                q = q.bind("");
            }
            for k in kinds {
                q = q.bind(k.as_str());
            }
            q.fetch_optional(p).await?
        });
        job_row(row)
    }

    /// Extends `owner`'s lease on a running job and records its progress; returns whether a
    /// cancel was requested, or `None` when the lease is no longer `owner`'s (it expired and
    /// the job went back to the queue, or it was canceled while queued).
    pub async fn heartbeat(
        &self,
        id: &str,
        owner: &str,
        now: i64,
        lease_until: i64,
        progress: Option<Progress>,
    ) -> Result<Option<bool>, StoreError> {
        let stage = progress.and_then(|p| p.stage).map(JobStage::as_str);
        let frac = progress.map(|p| p.fraction);
        let r: Option<i64> = on_pool!(self, p => sqlx::query_scalar(
            "UPDATE training_jobs SET lease_expires_at = $1, heartbeat_at = $2,
             stage = COALESCE($3, stage), progress = COALESCE($4, progress)
             WHERE id = $5 AND lease_owner = $6 AND status = $7
             RETURNING cancel_requested",
        )
        .bind(lease_until)
        .bind(now)
        .bind(stage)
        .bind(frac)
        .bind(id)
        .bind(owner)
        .bind(JobStatus::Running.as_str())
        .fetch_optional(p)
        .await?);
        Ok(r.map(flag))
    }

    /// Ends `owner`'s running job; false when it is not `owner`'s any more.
    pub async fn finish_job(
        &self,
        id: &str,
        owner: &str,
        end: &JobEnd<'_>,
    ) -> Result<bool, StoreError> {
        let progress = if end.status == JobStatus::Succeeded {
            1.0
        } else {
            -1.0
        };
        let n = on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET status = $1, stage = $1, error = $2, table_id = $3,
             progress = CASE WHEN $4 >= 0 THEN $4 ELSE progress END, finished_at = $5,
             lease_owner = NULL, lease_expires_at = NULL, finished_by = $7,
             compute_ms = COALESCE($9, compute_ms)
             WHERE id = $6 AND lease_owner = $7 AND status = $8",
        )
        .bind(end.status.as_str())
        .bind(end.error)
        .bind(end.table_id)
        .bind(progress)
        .bind(end.finished_at)
        .bind(id)
        .bind(owner)
        .bind(JobStatus::Running.as_str())
        .bind(end.compute_ms)
        .execute(p)
        .await?
        .rows_affected());
        Ok(n == 1)
    }

    /// Puts `owner`'s running job back in the queue (interrupted by a shutdown).
    pub async fn requeue_job(
        &self,
        id: &str,
        owner: &str,
        stage: JobStage,
    ) -> Result<(), StoreError> {
        on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET status = $1, stage = $2, progress = 0,
             lease_owner = NULL, lease_expires_at = NULL
             WHERE id = $3 AND lease_owner = $4 AND status = $5",
        )
        .bind(JobStatus::Queued.as_str())
        .bind(stage.as_str())
        .bind(id)
        .bind(owner)
        .bind(JobStatus::Running.as_str())
        .execute(p)
        .await?
        .rows_affected());
        Ok(())
    }

    /// Re-queues the jobs left running by this replica's previous run (a crash or restart),
    /// and training jobs running without an owner (recorded before leases existed; a running
    /// sharded job has no owner, its shards do).
    pub async fn requeue_owned(&self, owner: &str) -> Result<u64, StoreError> {
        Ok(on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET status = $1, stage = $5, progress = 0,
             lease_owner = NULL, lease_expires_at = NULL
             WHERE status = $2 AND (lease_owner = $3 OR (lease_owner IS NULL AND kind = $4))",
        )
        .bind(JobStatus::Queued.as_str())
        .bind(JobStatus::Running.as_str())
        .bind(owner)
        .bind(JobKind::Train.as_str())
        .bind(JobStage::RequeuedAfterRestart.as_str())
        .execute(p)
        .await?
        .rows_affected()))
    }

    /// Jobs whose lease expired (their replica died) go back to the queue, or end canceled
    /// when a cancel was requested; returns how many.
    pub async fn requeue_expired(&self, now: i64) -> Result<u64, StoreError> {
        Ok(on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET
               status = CASE WHEN cancel_requested <> 0 THEN $1 ELSE $2 END,
               stage = CASE WHEN cancel_requested <> 0 THEN $1 ELSE $5 END,
               finished_at = CASE WHEN cancel_requested <> 0 THEN $3 ELSE NULL END,
               progress = 0, lease_owner = NULL, lease_expires_at = NULL
             WHERE status = $4 AND lease_expires_at < $3",
        )
        .bind(JobStatus::Canceled.as_str())
        .bind(JobStatus::Queued.as_str())
        .bind(now)
        .bind(JobStatus::Running.as_str())
        .bind(JobStage::RequeuedAfterLeaseExpiry.as_str())
        .execute(p)
        .await?
        .rows_affected()))
    }
}

#[cfg(test)]
mod tests {
    use super::super::NewJob;
    use super::*;

    #[tokio::test]
    async fn sqlite_store_claims_leases_and_requeues() {
        let dir = tempfile::tempdir().unwrap();
        let s = Store::connect("", dir.path()).await.unwrap();
        let job = |id: &'static str, key: Option<&'static str>| NewJob {
            id,
            kind: JobKind::Train,
            shard_count: None,
            request_json: "{}",
            idempotency_key: key,
            request_sha256: "x",
            activate: false,
            created_at: 1,
        };
        let train = &[JobKind::Train];
        assert!(s.insert_job(&job("a", Some("k"))).await.unwrap());
        assert!(!s.insert_job(&job("b", Some("k"))).await.unwrap());
        let c = s.claim_job(train, "r1", 10, 20).await.unwrap().unwrap();
        assert_eq!(
            (c.id.as_str(), c.status, c.attempts, c.stage),
            ("a", JobStatus::Running, 1, Some(JobStage::Starting))
        );
        assert!(s.claim_job(train, "r2", 10, 20).await.unwrap().is_none());
        assert_eq!(s.heartbeat("a", "r2", 11, 30, None).await.unwrap(), None);
        let solving = Progress {
            stage: Some(JobStage::Solve),
            fraction: 0.5,
        };
        assert_eq!(
            s.heartbeat("a", "r1", 11, 30, Some(solving)).await.unwrap(),
            Some(false)
        );
        // a stage the service does not know leaves the stage recorded, not the fraction
        let unknown = Progress {
            stage: None,
            fraction: 0.75,
        };
        s.heartbeat("a", "r1", 11, 30, Some(unknown)).await.unwrap();
        let row = s.existing_job("a").await.unwrap();
        assert_eq!((row.stage, row.progress), (Some(JobStage::Solve), 0.75));
        assert_eq!(s.requeue_expired(25).await.unwrap(), 0);
        assert!(s.request_cancel("a").await.unwrap());
        assert_eq!(
            s.heartbeat("a", "r1", 12, 30, None).await.unwrap(),
            Some(true)
        );
        // the lease expires with the cancel requested: canceled, not re-queued
        assert_eq!(s.requeue_expired(31).await.unwrap(), 1);
        assert_eq!(
            s.existing_job("a").await.unwrap().status,
            JobStatus::Canceled
        );
        assert_eq!(s.heartbeat("a", "r1", 32, 40, None).await.unwrap(), None);
        // a canceled once-job is queued again, a queued one is left alone
        assert_eq!(
            s.queue_once(&job("c", Some("k"))).await.unwrap(),
            Some("a".into())
        );
        assert_eq!(s.queue_once(&job("d", Some("k"))).await.unwrap(), None);
        let c = s.claim_job(train, "r2", 40, 50).await.unwrap().unwrap();
        assert_eq!((c.attempts, c.cancel_requested), (2, false));
        assert_eq!(s.requeue_expired(51).await.unwrap(), 1);
        let row = s.existing_job("a").await.unwrap();
        assert_eq!(
            (row.status, row.stage),
            (JobStatus::Queued, Some(JobStage::RequeuedAfterLeaseExpiry))
        );
        s.close().await;
    }

    #[tokio::test]
    async fn jobs_end_or_go_back_to_the_queue_by_their_owner() {
        let dir = tempfile::tempdir().unwrap();
        let s = Store::connect("", dir.path()).await.unwrap();
        for id in ["a", "b"] {
            let j = NewJob {
                id,
                kind: JobKind::Train,
                shard_count: None,
                request_json: "{}",
                idempotency_key: None,
                request_sha256: "x",
                activate: false,
                created_at: 1,
            };
            assert!(s.insert_job(&j).await.unwrap());
        }
        let a = s
            .claim_job(&[JobKind::Train], "r1", 1, 100)
            .await
            .unwrap()
            .unwrap();
        let b = s
            .claim_job(&[JobKind::Train], "r1", 1, 100)
            .await
            .unwrap()
            .unwrap();
        let end = JobEnd {
            status: JobStatus::Succeeded,
            error: None,
            table_id: Some("tbl"),
            finished_at: 5,
            compute_ms: None,
        };
        assert!(!s.finish_job(&a.id, "r2", &end).await.unwrap());
        assert!(s.finish_job(&a.id, "r1", &end).await.unwrap());
        let a = s.existing_job(&a.id).await.unwrap();
        assert_eq!(
            (a.status, a.stage, a.progress, a.finished_by.as_deref()),
            (
                JobStatus::Succeeded,
                Some(JobStage::Succeeded),
                1.0,
                Some("r1")
            )
        );
        s.requeue_job(&b.id, "r1", JobStage::InterruptedByShutdown)
            .await
            .unwrap();
        let b = s.existing_job(&b.id).await.unwrap();
        assert_eq!(
            (b.status, b.stage, b.lease_owner),
            (
                JobStatus::Queued,
                Some(JobStage::InterruptedByShutdown),
                None
            )
        );
        s.claim_job(&[JobKind::Train], "r1", 6, 100)
            .await
            .unwrap()
            .unwrap();
        assert_eq!(s.requeue_owned("r1").await.unwrap(), 1);
        let b = s.existing_job(&b.id).await.unwrap();
        assert_eq!(b.stage, Some(JobStage::RequeuedAfterRestart));
        s.close().await;
    }
}
