//! `training_jobs`: a job's row, inserting it (a sharded job with its survey shards), looking
//! it up, listing, cancelling a queued one, counting by state.

use super::columns::{JobKind, JobStage, JobStatus, column, flag, flag_value};
use super::error::{RowKind, StoreError};
use super::{Change, Store};

/// The table's name (in errors).
const TABLE: &str = "training_jobs";

/// A `training_jobs` row.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRow {
    pub id: String,
    pub kind: JobKind,
    pub status: JobStatus,
    pub request_json: String,
    pub idempotency_key: Option<String>,
    pub request_sha256: String,
    pub activate: bool,
    pub progress: f64,
    pub stage: Option<JobStage>,
    pub error: Option<String>,
    pub table_id: Option<String>,
    pub attempts: i64,
    pub created_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
    pub lease_owner: Option<String>,
    pub lease_expires_at: Option<i64>,
    pub cancel_requested: bool,
    /// The job a shard belongs to.
    pub parent_id: Option<String>,
    pub shard_index: Option<i64>,
    /// A shard's and a sharded job's number of shards.
    pub shard_count: Option<i64>,
    pub compute_ms: Option<i64>,
    pub merge_ms: Option<i64>,
    pub finished_by: Option<String>,
}

/// A `training_jobs` row as stored (text and integer columns).
#[derive(Debug, sqlx::FromRow)]
pub(super) struct StoredJobRow {
    id: String,
    kind: String,
    status: String,
    request_json: String,
    idempotency_key: Option<String>,
    request_sha256: String,
    activate: i64,
    progress: f64,
    stage: Option<String>,
    error: Option<String>,
    table_id: Option<String>,
    attempts: i64,
    created_at: i64,
    started_at: Option<i64>,
    finished_at: Option<i64>,
    lease_owner: Option<String>,
    lease_expires_at: Option<i64>,
    cancel_requested: i64,
    parent_id: Option<String>,
    shard_index: Option<i64>,
    shard_count: Option<i64>,
    compute_ms: Option<i64>,
    merge_ms: Option<i64>,
    finished_by: Option<String>,
}

impl TryFrom<StoredJobRow> for JobRow {
    type Error = StoreError;

    fn try_from(r: StoredJobRow) -> Result<JobRow, StoreError> {
        let kind = column(TABLE, &r.id, &r.kind, JobKind::parse)?;
        let status = column(TABLE, &r.id, &r.status, JobStatus::parse)?;
        let stage = r
            .stage
            .as_deref()
            .map(|s| column(TABLE, &r.id, s, JobStage::parse))
            .transpose()?;
        Ok(JobRow {
            id: r.id,
            kind,
            status,
            request_json: r.request_json,
            idempotency_key: r.idempotency_key,
            request_sha256: r.request_sha256,
            activate: flag(r.activate),
            progress: r.progress,
            stage,
            error: r.error,
            table_id: r.table_id,
            attempts: r.attempts,
            created_at: r.created_at,
            started_at: r.started_at,
            finished_at: r.finished_at,
            lease_owner: r.lease_owner,
            lease_expires_at: r.lease_expires_at,
            cancel_requested: flag(r.cancel_requested),
            parent_id: r.parent_id,
            shard_index: r.shard_index,
            shard_count: r.shard_count,
            compute_ms: r.compute_ms,
            merge_ms: r.merge_ms,
            finished_by: r.finished_by,
        })
    }
}

/// The typed row of a stored one, if any.
pub(super) fn job_row(r: Option<StoredJobRow>) -> Result<Option<JobRow>, StoreError> {
    r.map(JobRow::try_from).transpose()
}

/// The typed rows of stored ones.
pub(super) fn job_rows(rows: Vec<StoredJobRow>) -> Result<Vec<JobRow>, StoreError> {
    rows.into_iter().map(JobRow::try_from).collect()
}

/// A new job to insert.
#[derive(Debug, Clone)]
pub struct NewJob<'a> {
    pub id: &'a str,
    /// [`JobKind::Train`] or [`JobKind::Sharded`] (then [`Store::insert_job`] also queues
    /// the survey shards).
    pub kind: JobKind,
    /// Shards of a sharded job.
    pub shard_count: Option<i64>,
    pub request_json: &'a str,
    pub idempotency_key: Option<&'a str>,
    pub request_sha256: &'a str,
    pub activate: bool,
    pub created_at: i64,
}

/// The rows of a stage's shards, queued together ([`insert_shards`]).
pub(super) struct NewShards<'a> {
    pub parent: &'a str,
    pub kind: JobKind,
    pub count: i64,
    pub request_json: &'a str,
    pub request_sha256: &'a str,
    /// The job's creation time: shards are claimed in the order of their jobs.
    pub created_at: i64,
}

impl NewShards<'_> {
    /// The id of shard `index` (0-based): `<parent>-survey-1`, … (fixed, so that a stage's
    /// rows are inserted once however often it is tried).
    pub fn id(&self, index: i64) -> String {
        let stage = self
            .kind
            .shard_stage()
            .map_or(self.kind.as_str(), |s| s.as_str());
        format!("{}-{stage}-{}", self.parent, index + 1)
    }
}

/// Inserts the rows of a [`NewShards`] in the transaction `$tx` (either backend; a row already
/// there is left alone).
macro_rules! insert_shards {
    ($tx:ident, $s:expr) => {
        for k in 0..$s.count {
            sqlx::query(
                "INSERT INTO training_jobs (id, kind, status, request_json, request_sha256, activate,
                 progress, stage, created_at, parent_id, shard_index, shard_count)
                 VALUES ($1, $2, $3, $4, $5, 0, 0, $3, $6, $7, $8, $9) ON CONFLICT DO NOTHING",
            )
            .bind($s.id(k))
            .bind($s.kind.as_str())
            .bind(JobStatus::Queued.as_str())
            .bind($s.request_json)
            .bind($s.request_sha256)
            .bind($s.created_at)
            .bind($s.parent)
            .bind(k)
            .bind($s.count)
            .execute(&mut *$tx)
            .await?;
        }
    };
}
pub(super) use insert_shards;

impl Store {
    /// Inserts a queued job; false when its idempotency key is already taken. A sharded job's
    /// survey shards are queued with it, in one transaction.
    pub async fn insert_job(&self, j: &NewJob<'_>) -> Result<bool, StoreError> {
        let queued = JobStatus::Queued.as_str();
        let n = on_pool!(self, p => {
            let mut tx = p.begin().await?;
            let n = sqlx::query(
                "INSERT INTO training_jobs (id, kind, status, request_json, idempotency_key, request_sha256, activate, progress, stage, created_at, shard_count)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, 0, $3, $8, $9) ON CONFLICT DO NOTHING",
            )
            .bind(j.id)
            .bind(j.kind.as_str())
            .bind(queued)
            .bind(j.request_json)
            .bind(j.idempotency_key)
            .bind(j.request_sha256)
            .bind(flag_value(j.activate))
            .bind(j.created_at)
            .bind(j.shard_count)
            .execute(&mut *tx)
            .await?
            .rows_affected();
            if n == 1 && j.kind == JobKind::Sharded {
                let shards = NewShards {
                    parent: j.id,
                    kind: JobKind::SurveyShard,
                    count: j.shard_count.unwrap_or(1),
                    request_json: j.request_json,
                    request_sha256: j.request_sha256,
                    created_at: j.created_at,
                };
                insert_shards!(tx, shards);
            }
            tx.commit().await?;
            n
        });
        if n == 1 {
            self.notify(Change::Jobs).await?;
        }
        Ok(n == 1)
    }

    /// The job `id`, if any.
    pub async fn job(&self, id: &str) -> Result<Option<JobRow>, StoreError> {
        job_row(on_pool!(self, p => sqlx::query_as::<_, StoredJobRow>(
            "SELECT * FROM training_jobs WHERE id = $1",
        )
        .bind(id)
        .fetch_optional(p)
        .await?))
    }

    /// The job `id`; [`StoreError::NotFound`] when there is none.
    pub async fn existing_job(&self, id: &str) -> Result<JobRow, StoreError> {
        self.job(id).await?.ok_or_else(|| StoreError::NotFound {
            kind: RowKind::Job,
            id: id.to_string(),
        })
    }

    /// The job queued under idempotency key `key`, when it was queued for the same request
    /// (its `request_sha256`); `None` when no job has the key, [`StoreError::KeyConflict`]
    /// when the key's job is another request's.
    pub async fn job_for_key(
        &self,
        key: &str,
        request_sha256: &str,
    ) -> Result<Option<JobRow>, StoreError> {
        let row = job_row(on_pool!(self, p => sqlx::query_as::<_, StoredJobRow>(
            "SELECT * FROM training_jobs WHERE idempotency_key = $1",
        )
        .bind(key)
        .fetch_optional(p)
        .await?))?;
        match row {
            Some(r) if r.request_sha256 != request_sha256 => Err(StoreError::KeyConflict {
                key: key.to_string(),
            }),
            r => Ok(r),
        }
    }

    /// The newest jobs first, optionally of one state.
    pub async fn list_jobs(
        &self,
        status: Option<JobStatus>,
        limit: i64,
    ) -> Result<Vec<JobRow>, StoreError> {
        job_rows(on_pool!(self, p => sqlx::query_as::<_, StoredJobRow>(
            "SELECT * FROM training_jobs WHERE ($1 IS NULL OR status = $1) AND parent_id IS NULL
             ORDER BY created_at DESC, id LIMIT $2",
        )
        .bind(status.map(JobStatus::as_str))
        .bind(limit)
        .fetch_all(p)
        .await?))
    }

    /// Cancels a queued job; false if it was not queued (any more).
    pub async fn cancel_queued(&self, id: &str, now: i64) -> Result<bool, StoreError> {
        let n = on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET status = $1, stage = $1, finished_at = $2
             WHERE id = $3 AND status = $4",
        )
        .bind(JobStatus::Canceled.as_str())
        .bind(now)
        .bind(id)
        .bind(JobStatus::Queued.as_str())
        .execute(p)
        .await?
        .rows_affected());
        Ok(n == 1)
    }

    /// Asks whichever replica runs the job to stop it (seen at its next heartbeat).
    pub async fn request_cancel(&self, id: &str) -> Result<bool, StoreError> {
        let n = on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET cancel_requested = $1 WHERE id = $2 AND status = $3",
        )
        .bind(flag_value(true))
        .bind(id)
        .bind(JobStatus::Running.as_str())
        .execute(p)
        .await?
        .rows_affected());
        Ok(n == 1)
    }

    /// Queues a job under `key` once per database: inserted when the key is new, re-queued
    /// when its earlier run failed or was canceled, else left alone. Returns its id when it
    /// was (re-)queued.
    pub async fn queue_once(&self, j: &NewJob<'_>) -> Result<Option<String>, StoreError> {
        if self.insert_job(j).await? {
            return Ok(Some(j.id.to_string()));
        }
        let Some(key) = j.idempotency_key else {
            return Ok(None);
        };
        let id: Option<String> = on_pool!(self, p => sqlx::query_scalar(
            "UPDATE training_jobs SET status = $1, stage = $1, progress = 0, error = NULL,
             cancel_requested = $5, finished_at = NULL, started_at = NULL
             WHERE idempotency_key = $2 AND status IN ($3, $4) RETURNING id",
        )
        .bind(JobStatus::Queued.as_str())
        .bind(key)
        .bind(JobStatus::Failed.as_str())
        .bind(JobStatus::Canceled.as_str())
        .bind(flag_value(false))
        .fetch_optional(p)
        .await?);
        if id.is_some() {
            self.notify(Change::Jobs).await?;
        }
        Ok(id)
    }

    /// The oldest queued or running job that will activate its table.
    pub async fn pending_activating_job(&self) -> Result<Option<String>, StoreError> {
        Ok(on_pool!(self, p => sqlx::query_scalar(
            "SELECT id FROM training_jobs WHERE status IN ($1, $2) AND activate = $3
             ORDER BY created_at, id LIMIT 1",
        )
        .bind(JobStatus::Queued.as_str())
        .bind(JobStatus::Running.as_str())
        .bind(flag_value(true))
        .fetch_optional(p)
        .await?))
    }

    /// Job counts by state (jobs, not their shards).
    pub async fn job_counts(&self) -> Result<Vec<(JobStatus, i64)>, StoreError> {
        let rows = on_pool!(self, p => sqlx::query_as::<_, (String, i64)>(
            "SELECT status, COUNT(*) FROM training_jobs WHERE parent_id IS NULL GROUP BY status",
        )
        .fetch_all(p)
        .await?);
        rows.into_iter()
            .map(|(s, n)| Ok((column(TABLE, "(count)", &s, JobStatus::parse)?, n)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn train_job<'a>(id: &'a str, key: Option<&'a str>) -> NewJob<'a> {
        NewJob {
            id,
            kind: JobKind::Train,
            shard_count: None,
            request_json: "{}",
            idempotency_key: key,
            request_sha256: "x",
            activate: false,
            created_at: 1,
        }
    }

    #[test]
    fn shard_ids_name_the_stage_and_count_from_one() {
        let s = NewShards {
            parent: "job_1",
            kind: JobKind::AccumulateShard,
            count: 2,
            request_json: "{}",
            request_sha256: "x",
            created_at: 1,
        };
        assert_eq!(
            (s.id(0), s.id(1)),
            ("job_1-accumulate-1".into(), "job_1-accumulate-2".into())
        );
    }

    #[tokio::test]
    async fn jobs_are_inserted_once_per_key_and_found_by_it() {
        let dir = tempfile::tempdir().unwrap();
        let s = Store::connect("", dir.path()).await.unwrap();
        let mut a = train_job("a", Some("k"));
        a.activate = true;
        assert!(s.insert_job(&a).await.unwrap());
        assert!(!s.insert_job(&train_job("b", Some("k"))).await.unwrap());
        let row = s.existing_job("a").await.unwrap();
        assert_eq!(
            (
                row.kind,
                row.status,
                row.stage,
                row.activate,
                row.cancel_requested
            ),
            (
                JobKind::Train,
                JobStatus::Queued,
                Some(JobStage::Queued),
                true,
                false
            )
        );
        assert_eq!(s.job_for_key("k", "x").await.unwrap().unwrap().id, "a");
        assert!(s.job_for_key("other", "x").await.unwrap().is_none());
        let e = s.job_for_key("k", "y").await.unwrap_err();
        assert!(matches!(e, StoreError::KeyConflict { .. }), "{e:?}");
        let e = s.existing_job("nope").await.unwrap_err();
        assert_eq!(e.to_string(), "no training job with id 'nope'");
        assert_eq!(
            s.pending_activating_job().await.unwrap().as_deref(),
            Some("a")
        );
        assert_eq!(s.job_counts().await.unwrap(), vec![(JobStatus::Queued, 1)]);
        assert!(s.cancel_queued("a", 5).await.unwrap());
        assert!(!s.cancel_queued("a", 6).await.unwrap());
        let row = s.existing_job("a").await.unwrap();
        assert_eq!(
            (row.status, row.stage),
            (JobStatus::Canceled, Some(JobStage::Canceled))
        );
        assert_eq!(
            s.list_jobs(Some(JobStatus::Canceled), 10)
                .await
                .unwrap()
                .len(),
            1
        );
        assert!(
            s.list_jobs(Some(JobStatus::Queued), 10)
                .await
                .unwrap()
                .is_empty()
        );
        s.close().await;
    }
}
