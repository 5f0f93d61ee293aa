//! A sharded job's shard rows (`training_jobs` rows with a parent) and their partial sums
//! (`training_partials`): starting and ending the job with its shards, storing and reading the
//! parts, and a shard's end under a lock of its job's row (so that exactly one shard of a
//! stage finds itself last, on either backend).

use super::columns::{JobKind, JobStage, JobStatus, ShardStage, flag_value};
use super::error::StoreError;
use super::jobs::{JobRow, NewShards, StoredJobRow, insert_shards, job_rows};
use super::{Change, Store};

/// How ending a shard's step went ([`Store::complete_shard`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShardCompletion {
    /// The shard ended succeeded; other shards of its stage are still to end.
    Done,
    /// The last shard of its stage: after the survey the accumulation shards are queued (and
    /// this one ended); after the accumulation this one merges, still under its lease.
    Last,
    /// The job of the shard ended meanwhile (canceled or failed): nothing was recorded.
    ParentEnded,
    /// The shard's lease is not its runner's any more: nothing was recorded.
    LeaseLost,
}

/// A shard's partial sums to store.
#[derive(Debug, Clone)]
pub struct NewPartial<'a> {
    /// The sharded job.
    pub job_id: &'a str,
    pub stage: ShardStage,
    pub shard_index: i64,
    pub content: &'a [u8],
    pub sha256: &'a str,
    pub replica: &'a str,
    pub created_at: i64,
}

/// Stored partial sums of one shard.
#[derive(Debug, Clone, PartialEq, sqlx::FromRow)]
pub struct Partial {
    /// 0-based.
    pub shard_index: i64,
    pub content: Vec<u8>,
    /// The SHA-256 recorded when they were stored.
    pub sha256: String,
}

/// In the transaction `$tx` of [`Store::complete_shard`]: locks the row of the shard's job
/// (every shard of the job ends one after the other) and returns from the function when the
/// job is not running or the shard's lease is not `$owner`'s; else evaluates to whether the
/// shard is the last of its stage to end.
macro_rules! lock_for_shard_end {
    ($tx:ident, $parent:expr, $shard:expr, $owner:expr) => {{
        let running = JobStatus::Running.as_str();
        let status: Option<String> = sqlx::query_scalar(
            "UPDATE training_jobs SET stage = stage WHERE id = $1 RETURNING status",
        )
        .bind($parent)
        .fetch_optional(&mut *$tx)
        .await?;
        if status.as_deref() != Some(running) {
            return Ok(ShardCompletion::ParentEnded);
        }
        let mine: i64 = sqlx::query_scalar(
            "SELECT COUNT(*) FROM training_jobs WHERE id = $1 AND lease_owner = $2 AND status = $3",
        )
        .bind(&$shard.id)
        .bind($owner)
        .bind(running)
        .fetch_one(&mut *$tx)
        .await?;
        if mine == 0 {
            return Ok(ShardCompletion::LeaseLost);
        }
        let others: i64 = sqlx::query_scalar(
            "SELECT COUNT(*) FROM training_jobs
             WHERE parent_id = $1 AND kind = $2 AND id <> $3 AND status <> $4",
        )
        .bind($parent)
        .bind($shard.kind.as_str())
        .bind(&$shard.id)
        .bind(JobStatus::Succeeded.as_str())
        .fetch_one(&mut *$tx)
        .await?;
        others == 0
    }};
}

impl Store {
    /// The shard rows of job `parent`, survey shards first, by index.
    pub async fn shards(&self, parent: &str) -> Result<Vec<JobRow>, StoreError> {
        job_rows(on_pool!(self, p => sqlx::query_as::<_, StoredJobRow>(
            "SELECT * FROM training_jobs WHERE parent_id = $1
             ORDER BY CASE WHEN kind = $2 THEN 0 ELSE 1 END, shard_index",
        )
        .bind(parent)
        .bind(JobKind::SurveyShard.as_str())
        .fetch_all(p)
        .await?))
    }

    /// Marks a queued sharded job running when its first shard starts (the time it started).
    pub async fn start_sharded(&self, parent: &str, now: i64) -> Result<(), StoreError> {
        on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET status = $1, stage = $5, started_at = $2,
             attempts = attempts + 1
             WHERE id = $3 AND status = $4",
        )
        .bind(JobStatus::Running.as_str())
        .bind(now)
        .bind(parent)
        .bind(JobStatus::Queued.as_str())
        .bind(JobStage::Survey.as_str())
        .execute(p)
        .await?
        .rows_affected());
        Ok(())
    }

    /// Ends a queued or running sharded job as `status` (canceled or failed, with `error`):
    /// its queued shards end canceled, its running shards are asked to stop (their ids are
    /// returned), its partial sums are deleted. `None` when the job had ended already.
    pub async fn end_sharded(
        &self,
        parent: &str,
        status: JobStatus,
        error: Option<&str>,
        now: i64,
    ) -> Result<Option<Vec<String>>, StoreError> {
        let (queued, running, canceled) = (
            JobStatus::Queued.as_str(),
            JobStatus::Running.as_str(),
            JobStatus::Canceled.as_str(),
        );
        on_pool!(self, p => {
            let mut tx = p.begin().await?;
            let n = sqlx::query(
                "UPDATE training_jobs SET status = $1, stage = $1, error = $2, finished_at = $3
                 WHERE id = $4 AND status IN ($5, $6)",
            )
            .bind(status.as_str())
            .bind(error)
            .bind(now)
            .bind(parent)
            .bind(queued)
            .bind(running)
            .execute(&mut *tx)
            .await?
            .rows_affected();
            if n == 0 {
                return Ok(None);
            }
            sqlx::query(
                "UPDATE training_jobs SET status = $1, stage = $1, finished_at = $2
                 WHERE parent_id = $3 AND status = $4",
            )
            .bind(canceled)
            .bind(now)
            .bind(parent)
            .bind(queued)
            .execute(&mut *tx)
            .await?;
            let stopping: Vec<String> = sqlx::query_scalar(
                "UPDATE training_jobs SET cancel_requested = $3 WHERE parent_id = $1 AND status = $2
                 RETURNING id",
            )
            .bind(parent)
            .bind(running)
            .bind(flag_value(true))
            .fetch_all(&mut *tx)
            .await?;
            sqlx::query("DELETE FROM training_partials WHERE job_id = $1")
                .bind(parent)
                .execute(&mut *tx)
                .await?;
            tx.commit().await?;
            Ok(Some(stopping))
        })
    }

    /// Stores a shard's partial sums (bytes and SHA-256) while its job is queued or running;
    /// a part already stored (the same bytes: a shard retried after its lease expired) is left
    /// alone.
    pub async fn store_partial(&self, part: &NewPartial<'_>) -> Result<(), StoreError> {
        on_pool!(self, p => sqlx::query(
            "INSERT INTO training_partials (job_id, stage, shard_index, content, sha256, size_bytes, replica, created_at)
             SELECT $1, $2, $3, $4, $5, $6, $7, $8
             WHERE EXISTS (SELECT 1 FROM training_jobs WHERE id = $1 AND status IN ($9, $10))
             ON CONFLICT DO NOTHING",
        )
        .bind(part.job_id)
        .bind(part.stage.as_str())
        .bind(part.shard_index)
        .bind(part.content)
        .bind(part.sha256)
        .bind(part.content.len() as i64)
        .bind(part.replica)
        .bind(part.created_at)
        .bind(JobStatus::Queued.as_str())
        .bind(JobStatus::Running.as_str())
        .execute(p)
        .await?
        .rows_affected());
        Ok(())
    }

    /// The stored partial sums of `stage` of job `parent`, by index; `only` picks one shard.
    pub async fn partials(
        &self,
        parent: &str,
        stage: ShardStage,
        only: Option<i64>,
    ) -> Result<Vec<Partial>, StoreError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, Partial>(
            "SELECT shard_index, content, sha256 FROM training_partials
             WHERE job_id = $1 AND stage = $2 AND ($3 IS NULL OR shard_index = $3)
             ORDER BY shard_index",
        )
        .bind(parent)
        .bind(stage.as_str())
        .bind(only)
        .fetch_all(p)
        .await?))
    }

    /// Records the end of `owner`'s shard `shard`, whose partial sums are stored, under a lock
    /// of its job's row (so that exactly one shard of a stage finds itself last, on either
    /// backend). After the survey the last shard queues the accumulation shards; the last
    /// accumulation shard stays running (it merges) and the job's stage becomes `merge`.
    pub async fn complete_shard(
        &self,
        shard: &JobRow,
        owner: &str,
        now: i64,
        compute_ms: i64,
    ) -> Result<ShardCompletion, StoreError> {
        let Some(parent) = shard.parent_id.as_deref() else {
            return Ok(ShardCompletion::ParentEnded);
        };
        let succeeded = JobStatus::Succeeded.as_str();
        let done = on_pool!(self, p => {
            let mut tx = p.begin().await?;
            let last = lock_for_shard_end!(tx, parent, shard, owner);
            if last && shard.kind == JobKind::AccumulateShard {
                sqlx::query("UPDATE training_jobs SET stage = $1 WHERE id = $2 OR id = $3")
                    .bind(JobStage::Merge.as_str())
                    .bind(parent)
                    .bind(&shard.id)
                    .execute(&mut *tx)
                    .await?;
                sqlx::query("UPDATE training_jobs SET compute_ms = $1 WHERE id = $2")
                    .bind(compute_ms)
                    .bind(&shard.id)
                    .execute(&mut *tx)
                    .await?;
            } else {
                sqlx::query(
                    "UPDATE training_jobs SET status = $1, stage = $1, progress = 1, finished_at = $2,
                     compute_ms = $3, finished_by = $4, lease_owner = NULL, lease_expires_at = NULL
                     WHERE id = $5",
                )
                .bind(succeeded)
                .bind(now)
                .bind(compute_ms)
                .bind(owner)
                .bind(&shard.id)
                .execute(&mut *tx)
                .await?;
            }
            if last && shard.kind == JobKind::SurveyShard {
                let next = NewShards {
                    parent,
                    kind: JobKind::AccumulateShard,
                    count: shard.shard_count.unwrap_or(1),
                    request_json: &shard.request_json,
                    request_sha256: &shard.request_sha256,
                    created_at: shard.created_at,
                };
                insert_shards!(tx, next);
                sqlx::query("UPDATE training_jobs SET stage = $1 WHERE id = $2")
                    .bind(JobStage::Accumulate.as_str())
                    .bind(parent)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await?;
            if last { ShardCompletion::Last } else { ShardCompletion::Done }
        });
        if done == ShardCompletion::Last && shard.kind == JobKind::SurveyShard {
            self.notify(Change::Jobs).await?;
        }
        Ok(done)
    }

    /// Ends a running sharded job succeeded with its table and merge time, together with its
    /// last shard (`by`'s, which merged), and deletes its partial sums; false when the job had
    /// ended meanwhile (canceled).
    pub async fn finish_sharded(
        &self,
        parent: &str,
        shard: &str,
        table_id: &str,
        merge_ms: i64,
        by: &str,
        now: i64,
    ) -> Result<bool, StoreError> {
        on_pool!(self, p => {
            let mut tx = p.begin().await?;
            let n = sqlx::query(
                "UPDATE training_jobs SET status = $1, stage = $1, progress = 1, table_id = $2,
                 merge_ms = $3, finished_by = $4, finished_at = $5
                 WHERE id = $6 AND status = $7",
            )
            .bind(JobStatus::Succeeded.as_str())
            .bind(table_id)
            .bind(merge_ms)
            .bind(by)
            .bind(now)
            .bind(parent)
            .bind(JobStatus::Running.as_str())
            .execute(&mut *tx)
            .await?
            .rows_affected();
            if n == 1 {
                sqlx::query(
                    "UPDATE training_jobs SET status = $1, stage = $1, progress = 1, finished_at = $2,
                     finished_by = $3, lease_owner = NULL, lease_expires_at = NULL
                     WHERE id = $4 AND lease_owner = $3 AND status = $5",
                )
                .bind(JobStatus::Succeeded.as_str())
                .bind(now)
                .bind(by)
                .bind(shard)
                .bind(JobStatus::Running.as_str())
                .execute(&mut *tx)
                .await?;
            }
            sqlx::query("DELETE FROM training_partials WHERE job_id = $1")
                .bind(parent)
                .execute(&mut *tx)
                .await?;
            tx.commit().await?;
            Ok(n == 1)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::{NewJob, WORKER_KINDS};
    use super::*;

    #[tokio::test]
    async fn sqlite_store_runs_shards_and_finds_the_last_one_once() {
        let dir = tempfile::tempdir().unwrap();
        let s = Store::connect("", dir.path()).await.unwrap();
        let parent = NewJob {
            id: "p",
            kind: JobKind::Sharded,
            shard_count: Some(2),
            request_json: "{}",
            idempotency_key: None,
            request_sha256: "x",
            activate: false,
            created_at: 1,
        };
        assert!(s.insert_job(&parent).await.unwrap());
        // the job itself is never claimed; its survey shards are, in order
        let kinds = WORKER_KINDS;
        let a = s.claim_job(kinds, "r1", 10, 100).await.unwrap().unwrap();
        let b = s.claim_job(kinds, "r2", 10, 100).await.unwrap().unwrap();
        assert_eq!((a.id.as_str(), b.id.as_str()), ("p-survey-1", "p-survey-2"));
        assert_eq!(a.kind, JobKind::SurveyShard);
        assert!(s.claim_job(kinds, "r1", 10, 100).await.unwrap().is_none());
        s.start_sharded("p", 10).await.unwrap();
        assert_eq!(s.list_jobs(None, 10).await.unwrap().len(), 1);
        // a shard whose lease is not its runner's records nothing
        assert_eq!(
            s.complete_shard(&a, "r2", 11, 5).await.unwrap(),
            ShardCompletion::LeaseLost
        );
        assert_eq!(
            s.complete_shard(&a, "r1", 11, 5).await.unwrap(),
            ShardCompletion::Done
        );
        assert_eq!(
            s.complete_shard(&b, "r2", 12, 6).await.unwrap(),
            ShardCompletion::Last
        );
        assert_eq!(
            s.existing_job("p").await.unwrap().stage,
            Some(JobStage::Accumulate)
        );
        accumulate_and_merge(&s, &parent).await;
        s.close().await;
    }

    /// The accumulation of job `p` (its survey done): the last shard merges.
    async fn accumulate_and_merge(s: &Store, parent: &NewJob<'_>) {
        let kinds = WORKER_KINDS;
        // the accumulation shards are queued once the survey is complete
        let c = s.claim_job(kinds, "r1", 13, 100).await.unwrap().unwrap();
        let d = s.claim_job(kinds, "r2", 13, 100).await.unwrap().unwrap();
        assert_eq!(
            (c.id.as_str(), c.kind),
            ("p-accumulate-1", JobKind::AccumulateShard)
        );
        assert_eq!(
            s.complete_shard(&d, "r2", 14, 7).await.unwrap(),
            ShardCompletion::Done
        );
        assert_eq!(
            s.complete_shard(&c, "r1", 15, 8).await.unwrap(),
            ShardCompletion::Last
        );
        // the last one is still running (it merges); the job's stage says so
        let (pj, cj) = (
            s.existing_job("p").await.unwrap(),
            s.existing_job(&c.id).await.unwrap(),
        );
        assert_eq!(
            (pj.stage, cj.status),
            (Some(JobStage::Merge), JobStatus::Running)
        );
        let part = NewPartial {
            job_id: "p",
            stage: ShardStage::Accumulate,
            shard_index: 0,
            content: b"sums",
            sha256: "h",
            replica: "r1",
            created_at: 15,
        };
        s.store_partial(&part).await.unwrap();
        s.store_partial(&part).await.unwrap();
        let parts = s.partials("p", ShardStage::Accumulate, None).await.unwrap();
        assert_eq!(
            parts,
            vec![Partial {
                shard_index: 0,
                content: b"sums".to_vec(),
                sha256: "h".into()
            }]
        );
        assert!(
            s.partials("p", ShardStage::Survey, None)
                .await
                .unwrap()
                .is_empty()
        );
        assert!(
            s.finish_sharded("p", &c.id, "tbl", 3, "r1", 16)
                .await
                .unwrap()
        );
        assert_eq!(
            s.existing_job(&c.id).await.unwrap().status,
            JobStatus::Succeeded
        );
        assert!(
            s.partials("p", ShardStage::Accumulate, None)
                .await
                .unwrap()
                .is_empty()
        );
        assert_eq!(s.shards("p").await.unwrap().len(), 4);
        cancel_with_shards(s, parent).await;
    }

    /// A job canceled while its shards run takes them with it.
    async fn cancel_with_shards(s: &Store, parent: &NewJob<'_>) {
        let kinds = WORKER_KINDS;
        let q = NewJob {
            id: "q",
            ..parent.clone()
        };
        assert!(s.insert_job(&q).await.unwrap());
        let e = s.claim_job(kinds, "r1", 20, 100).await.unwrap().unwrap();
        let stopping = s
            .end_sharded("q", JobStatus::Canceled, None, 21)
            .await
            .unwrap()
            .unwrap();
        assert_eq!(stopping, vec![e.id.clone()]);
        assert!(s.existing_job(&e.id).await.unwrap().cancel_requested);
        assert!(s.claim_job(kinds, "r1", 22, 100).await.unwrap().is_none());
        assert_eq!(
            s.complete_shard(&e, "r1", 23, 1).await.unwrap(),
            ShardCompletion::ParentEnded
        );
        assert!(
            s.end_sharded("q", JobStatus::Canceled, None, 24)
                .await
                .unwrap()
                .is_none()
        );
    }
}
