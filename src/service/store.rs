//! The service's database: SQLite (embedded, the default) or PostgreSQL (shared by replicas).
//! Every query lives here, once, with typed rows; the two backends run the same SQL text
//! except where the dialects differ (claiming a job). Changes other replicas must see
//! (activation, illuminants, new jobs) are announced with NOTIFY on PostgreSQL.

use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

use sqlx::postgres::{PgListener, PgPool, PgPoolOptions};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions};

use super::ServiceError;

/// The NOTIFY channel replicas listen on.
pub const CHANGES_CHANNEL: &str = "l3_changes";

/// What a NOTIFY on [`CHANGES_CHANNEL`] announces (its payload).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Change {
    /// The active table was switched.
    ActiveTable,
    /// A user illuminant was created, replaced or deleted.
    Illuminants,
    /// A job was queued.
    Jobs,
}

impl Change {
    pub fn as_str(self) -> &'static str {
        match self {
            Change::ActiveTable => "active_table",
            Change::Illuminants => "illuminants",
            Change::Jobs => "jobs",
        }
    }

    pub fn parse(s: &str) -> Option<Change> {
        [Change::ActiveTable, Change::Illuminants, Change::Jobs]
            .into_iter()
            .find(|c| c.as_str() == s)
    }
}

/// A training job's state (the `status` column, checked by the schema).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JobStatus {
    Queued,
    Running,
    Succeeded,
    Failed,
    Canceled,
}

impl JobStatus {
    /// Every state, in lifecycle order.
    pub const ALL: [JobStatus; 5] = [
        JobStatus::Queued,
        JobStatus::Running,
        JobStatus::Succeeded,
        JobStatus::Failed,
        JobStatus::Canceled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            JobStatus::Queued => "queued",
            JobStatus::Running => "running",
            JobStatus::Succeeded => "succeeded",
            JobStatus::Failed => "failed",
            JobStatus::Canceled => "canceled",
        }
    }
}

impl std::fmt::Display for JobStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for JobStatus {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        JobStatus::ALL
            .into_iter()
            .find(|j| j.as_str() == s)
            .ok_or_else(|| format!("unknown job status '{s}'"))
    }
}

impl TryFrom<String> for JobStatus {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

/// The kind of a job row. Workers claim the kinds they run ([`WORKER_KINDS`]).
///
/// A training job trained in one piece.
pub const JOB_KIND_TRAIN: &str = "train";
/// A training job split into shards: its shard rows are claimed, never the job itself.
pub const JOB_KIND_SHARDED: &str = "train_sharded";
/// The survey of one shard's batches (stage 1 of a sharded job).
pub const JOB_KIND_SURVEY_SHARD: &str = "survey_shard";
/// The normal equations of one shard's batches (stage 2); the last one to end also merges.
pub const JOB_KIND_ACCUMULATE_SHARD: &str = "accumulate_shard";
/// The kinds a job worker claims.
pub const WORKER_KINDS: &[&str] = &[
    JOB_KIND_TRAIN,
    JOB_KIND_SURVEY_SHARD,
    JOB_KIND_ACCUMULATE_SHARD,
];

/// The stage of a shard kind, as the partial sums are filed (`survey` or `accumulate`).
pub fn shard_stage(kind: &str) -> Option<&'static str> {
    match kind {
        JOB_KIND_SURVEY_SHARD => Some("survey"),
        JOB_KIND_ACCUMULATE_SHARD => Some("accumulate"),
        _ => None,
    }
}

/// The id of shard `index` (0-based) of `kind` of job `parent`: `<parent>-survey-1`, … (fixed,
/// so that a stage's rows are inserted once however often it is tried).
pub fn shard_id(parent: &str, kind: &str, index: i64) -> String {
    format!(
        "{parent}-{}-{}",
        shard_stage(kind).unwrap_or(kind),
        index + 1
    )
}

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

/// A `training_jobs` row.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct JobRow {
    pub id: String,
    pub kind: String,
    #[sqlx(try_from = "String")]
    pub status: JobStatus,
    pub request_json: String,
    pub idempotency_key: Option<String>,
    pub request_sha256: String,
    pub activate: i64,
    pub progress: f64,
    pub stage: Option<String>,
    pub error: Option<String>,
    pub table_id: Option<String>,
    pub attempts: i64,
    pub created_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
    pub lease_owner: Option<String>,
    pub lease_expires_at: Option<i64>,
    pub cancel_requested: i64,
    /// The job a shard belongs to.
    pub parent_id: Option<String>,
    pub shard_index: Option<i64>,
    /// A shard's and a sharded job's number of shards.
    pub shard_count: Option<i64>,
    pub compute_ms: Option<i64>,
    pub merge_ms: Option<i64>,
    pub finished_by: Option<String>,
}

/// A new job to insert.
#[derive(Debug, Clone)]
pub struct NewJob<'a> {
    pub id: &'a str,
    /// [`JOB_KIND_TRAIN`] or [`JOB_KIND_SHARDED`] (then [`Store::insert_job`] also queues the
    /// survey shards).
    pub kind: &'a str,
    /// Shards of a sharded job.
    pub shard_count: Option<i64>,
    pub request_json: &'a str,
    pub idempotency_key: Option<&'a str>,
    pub request_sha256: &'a str,
    pub activate: bool,
    pub created_at: i64,
}

/// A shard's partial sums to store.
#[derive(Debug, Clone)]
pub struct NewPartial<'a> {
    /// The sharded job.
    pub job_id: &'a str,
    /// `survey` or `accumulate`.
    pub stage: &'a str,
    pub shard_index: i64,
    pub content: &'a [u8],
    pub sha256: &'a str,
    pub replica: &'a str,
    pub created_at: i64,
}

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

/// An `l3_tables` row (without the bytes).
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct TableRow {
    pub id: String,
    pub path: String,
    pub sha256: String,
    pub size_bytes: i64,
    pub kind: String,
    pub meta_json: String,
    pub job_id: Option<String>,
    pub created_at: i64,
    pub status: String,
    pub status_detail: Option<String>,
    pub last_activated_at: Option<i64>,
}

macro_rules! table_columns {
    () => {
        "id, path, sha256, size_bytes, kind, meta_json, job_id, created_at, status, status_detail, last_activated_at"
    };
}

/// A table to record.
#[derive(Debug, Clone)]
pub struct NewTable<'a> {
    pub id: &'a str,
    pub path: &'a str,
    pub sha256: &'a str,
    pub size_bytes: i64,
    pub kind: &'a str,
    pub meta_json: &'a str,
    pub job_id: Option<&'a str>,
    pub created_at: i64,
    /// The file's bytes, kept in the database where replicas share it.
    pub content: Option<&'a [u8]>,
}

/// An `illuminants` row.
#[derive(Debug, Clone, PartialEq, sqlx::FromRow)]
pub struct IlluminantRow {
    pub name: String,
    pub definition_json: String,
}

/// An `evaluations` row.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct EvaluationRow {
    pub id: String,
    pub table_id: Option<String>,
    pub method: String,
    pub chart: String,
    pub acquisition_illuminant: String,
    pub mean_delta_e: f64,
    pub request_json: String,
    pub report_json: String,
    pub created_at: i64,
}

/// The database of a service: one pool of either backend.
#[derive(Debug, Clone)]
pub enum Store {
    Sqlite(SqlitePool),
    Postgres(PgPool),
}

/// Runs `$body` with `$p` bound to the pool, whichever the backend: the same code (and SQL)
/// for both.
macro_rules! on_pool {
    ($store:expr, $p:ident => $body:expr) => {
        match $store {
            Store::Sqlite($p) => $body,
            Store::Postgres($p) => $body,
        }
    };
}

/// The rows of a stage's shards, queued together.
struct NewShards<'a> {
    parent: &'a str,
    kind: &'a str,
    count: i64,
    request_json: &'a str,
    request_sha256: &'a str,
    /// The job's creation time: shards are claimed in the order of their jobs.
    created_at: i64,
}

/// Inserts the rows of [`NewShards`] in the transaction `$tx` (either backend; a row already
/// there is left alone).
macro_rules! insert_shards {
    ($tx:ident, $s:expr) => {
        for k in 0..$s.count {
            sqlx::query(
                "INSERT INTO training_jobs (id, kind, status, request_json, request_sha256, activate,
                 progress, stage, created_at, parent_id, shard_index, shard_count)
                 VALUES ($1, $2, $3, $4, $5, 0, 0, $3, $6, $7, $8, $9) ON CONFLICT DO NOTHING",
            )
            .bind(shard_id($s.parent, $s.kind, k))
            .bind($s.kind)
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

/// The embedded SQLite database's file in the data directory.
pub const SQLITE_FILE: &str = "l3.sqlite";

impl Store {
    /// Connects and applies the migrations. An empty `url` is the embedded SQLite database
    /// `l3.sqlite` in `data_dir`; otherwise `sqlite://…` or `postgres://…`.
    pub async fn connect(url: &str, data_dir: &Path) -> Result<Store, ServiceError> {
        let url = url.trim();
        let store = if url.is_empty() || url.starts_with("sqlite:") {
            let opts = if url.is_empty() {
                SqliteConnectOptions::new().filename(data_dir.join(SQLITE_FILE))
            } else {
                SqliteConnectOptions::from_str(url)
                    .map_err(|e| ServiceError::Config(format!("database_url: {e}")))?
            };
            let opts = opts
                .create_if_missing(true)
                .journal_mode(SqliteJournalMode::Wal)
                .busy_timeout(Duration::from_secs(10));
            let pool = SqlitePoolOptions::new()
                .max_connections(8)
                .connect_with(opts)
                .await?;
            sqlx::migrate!("./migrations/sqlite").run(&pool).await?;
            Store::Sqlite(pool)
        } else if url.starts_with("postgres://") || url.starts_with("postgresql://") {
            let pool = PgPoolOptions::new()
                .max_connections(8)
                .acquire_timeout(Duration::from_secs(10))
                .connect(url)
                .await?;
            sqlx::migrate!("./migrations/postgres").run(&pool).await?;
            Store::Postgres(pool)
        } else {
            return Err(ServiceError::Config(format!(
                "database_url '{url}': expected sqlite://… or postgres://…"
            )));
        };
        Ok(store)
    }

    /// The backend's name, for logs.
    pub fn backend(&self) -> &'static str {
        match self {
            Store::Sqlite(_) => "sqlite",
            Store::Postgres(_) => "postgres",
        }
    }

    /// Whether table bytes are kept in the database (PostgreSQL: replicas on other machines
    /// read them from there). With SQLite the table files are the store.
    pub fn keeps_table_bytes(&self) -> bool {
        matches!(self, Store::Postgres(_))
    }

    /// A listener on [`CHANGES_CHANNEL`] (PostgreSQL only: an embedded database has no other
    /// replicas).
    pub async fn listener(&self) -> Result<Option<PgListener>, ServiceError> {
        match self {
            Store::Sqlite(_) => Ok(None),
            Store::Postgres(pool) => {
                let mut l = PgListener::connect_with(pool).await?;
                l.listen(CHANGES_CHANNEL).await?;
                Ok(Some(l))
            }
        }
    }

    /// Announces a change to the other replicas (nothing to do on SQLite).
    pub async fn notify(&self, change: Change) -> Result<(), ServiceError> {
        if let Store::Postgres(pool) = self {
            sqlx::query("SELECT pg_notify($1, $2)")
                .bind(CHANGES_CHANNEL)
                .bind(change.as_str())
                .execute(pool)
                .await?;
        }
        Ok(())
    }

    pub async fn close(&self) {
        on_pool!(self, p => p.close().await)
    }

    // ---- jobs ----

    /// Inserts a queued job; false when its idempotency key is already taken. A sharded job's
    /// survey shards are queued with it, in one transaction.
    pub async fn insert_job(&self, j: &NewJob<'_>) -> Result<bool, ServiceError> {
        let queued = JobStatus::Queued.as_str();
        let n = on_pool!(self, p => {
            let mut tx = p.begin().await?;
            let n = sqlx::query(
                "INSERT INTO training_jobs (id, kind, status, request_json, idempotency_key, request_sha256, activate, progress, stage, created_at, shard_count)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, 0, $3, $8, $9) ON CONFLICT DO NOTHING",
            )
            .bind(j.id)
            .bind(j.kind)
            .bind(queued)
            .bind(j.request_json)
            .bind(j.idempotency_key)
            .bind(j.request_sha256)
            .bind(i64::from(j.activate))
            .bind(j.created_at)
            .bind(j.shard_count)
            .execute(&mut *tx)
            .await?
            .rows_affected();
            if n == 1 && j.kind == JOB_KIND_SHARDED {
                let shards = NewShards {
                    parent: j.id,
                    kind: JOB_KIND_SURVEY_SHARD,
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

    pub async fn job(&self, id: &str) -> Result<Option<JobRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, JobRow>(
            "SELECT * FROM training_jobs WHERE id = $1",
        )
        .bind(id)
        .fetch_optional(p)
        .await?))
    }

    pub async fn job_by_key(&self, key: &str) -> Result<Option<JobRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, JobRow>(
            "SELECT * FROM training_jobs WHERE idempotency_key = $1",
        )
        .bind(key)
        .fetch_optional(p)
        .await?))
    }

    /// The newest jobs first, optionally of one state.
    pub async fn list_jobs(
        &self,
        status: Option<JobStatus>,
        limit: i64,
    ) -> Result<Vec<JobRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, JobRow>(
            "SELECT * FROM training_jobs WHERE ($1 IS NULL OR status = $1) AND parent_id IS NULL
             ORDER BY created_at DESC, id LIMIT $2",
        )
        .bind(status.map(JobStatus::as_str))
        .bind(limit)
        .fetch_all(p)
        .await?))
    }

    /// Cancels a queued job; false if it was not queued (any more).
    pub async fn cancel_queued(&self, id: &str, now: i64) -> Result<bool, ServiceError> {
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
    pub async fn request_cancel(&self, id: &str) -> Result<bool, ServiceError> {
        let n = on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET cancel_requested = 1 WHERE id = $1 AND status = $2",
        )
        .bind(id)
        .bind(JobStatus::Running.as_str())
        .execute(p)
        .await?
        .rows_affected());
        Ok(n == 1)
    }

    /// Claims the oldest queued job of one of `kinds` for `owner` under a lease until
    /// `lease_until`: `SELECT … FOR UPDATE SKIP LOCKED` on PostgreSQL, one atomic UPDATE on
    /// SQLite (a single writer). Shards carry their job's creation time, so they come in the
    /// order of their jobs, by index within one.
    pub async fn claim_job(
        &self,
        kinds: &[&str],
        owner: &str,
        now: i64,
        lease_until: i64,
    ) -> Result<Option<JobRow>, ServiceError> {
        let kinds_sql = (0..kinds.len().max(1))
            .map(|i| format!("${}", i + 6))
            .collect::<Vec<_>>()
            .join(", ");
        let sql = match self {
            Store::Postgres(_) => format!(
                "UPDATE training_jobs SET status = $1, stage = 'starting', progress = 0,
                 attempts = attempts + 1, started_at = $2, lease_owner = $3,
                 lease_expires_at = $4, heartbeat_at = $2
                 WHERE id = (SELECT id FROM training_jobs WHERE status = $5 AND kind IN ({kinds_sql})
                             ORDER BY created_at, COALESCE(shard_index, 0), id
                             LIMIT 1 FOR UPDATE SKIP LOCKED)
                 RETURNING *"
            ),
            Store::Sqlite(_) => format!(
                "UPDATE training_jobs SET status = $1, stage = 'starting', progress = 0,
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
            let mut q = sqlx::query_as::<_, JobRow>(&sql)
                .bind(JobStatus::Running.as_str())
                .bind(now)
                .bind(owner)
                .bind(lease_until)
                .bind(JobStatus::Queued.as_str());
            if kinds.is_empty() {
                q = q.bind("");
            }
            for k in kinds {
                q = q.bind(*k);
            }
            q.fetch_optional(p).await?
        });
        Ok(row)
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
        progress: Option<(&str, f64)>,
    ) -> Result<Option<bool>, ServiceError> {
        let (stage, frac) = progress.unzip();
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
        Ok(r.map(|c| c != 0))
    }

    /// Ends `owner`'s running job; false when it is not `owner`'s any more.
    pub async fn finish_job(
        &self,
        id: &str,
        owner: &str,
        end: &JobEnd<'_>,
    ) -> Result<bool, ServiceError> {
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
        stage: &str,
    ) -> Result<(), ServiceError> {
        on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET status = $1, stage = $2, progress = 0,
             lease_owner = NULL, lease_expires_at = NULL
             WHERE id = $3 AND lease_owner = $4 AND status = $5",
        )
        .bind(JobStatus::Queued.as_str())
        .bind(stage)
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
    pub async fn requeue_owned(&self, owner: &str) -> Result<u64, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET status = $1, stage = 'requeued after restart', progress = 0,
             lease_owner = NULL, lease_expires_at = NULL
             WHERE status = $2 AND (lease_owner = $3 OR (lease_owner IS NULL AND kind = $4))",
        )
        .bind(JobStatus::Queued.as_str())
        .bind(JobStatus::Running.as_str())
        .bind(owner)
        .bind(JOB_KIND_TRAIN)
        .execute(p)
        .await?
        .rows_affected()))
    }

    /// Jobs whose lease expired (their replica died) go back to the queue, or end canceled
    /// when a cancel was requested; returns how many.
    pub async fn requeue_expired(&self, now: i64) -> Result<u64, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET
               status = CASE WHEN cancel_requested <> 0 THEN $1 ELSE $2 END,
               stage = CASE WHEN cancel_requested <> 0 THEN $1 ELSE 'requeued after lease expiry' END,
               finished_at = CASE WHEN cancel_requested <> 0 THEN $3 ELSE NULL END,
               progress = 0, lease_owner = NULL, lease_expires_at = NULL
             WHERE status = $4 AND lease_expires_at < $3",
        )
        .bind(JobStatus::Canceled.as_str())
        .bind(JobStatus::Queued.as_str())
        .bind(now)
        .bind(JobStatus::Running.as_str())
        .execute(p)
        .await?
        .rows_affected()))
    }

    /// Queues a job under `key` once per database: inserted when the key is new, re-queued
    /// when its earlier run failed or was canceled, else left alone. Returns its id when it
    /// was (re-)queued.
    pub async fn queue_once(&self, j: &NewJob<'_>) -> Result<Option<String>, ServiceError> {
        if self.insert_job(j).await? {
            return Ok(Some(j.id.to_string()));
        }
        let Some(key) = j.idempotency_key else {
            return Ok(None);
        };
        let id: Option<String> = on_pool!(self, p => sqlx::query_scalar(
            "UPDATE training_jobs SET status = $1, stage = $1, progress = 0, error = NULL,
             cancel_requested = 0, finished_at = NULL, started_at = NULL
             WHERE idempotency_key = $2 AND status IN ($3, $4) RETURNING id",
        )
        .bind(JobStatus::Queued.as_str())
        .bind(key)
        .bind(JobStatus::Failed.as_str())
        .bind(JobStatus::Canceled.as_str())
        .fetch_optional(p)
        .await?);
        if id.is_some() {
            self.notify(Change::Jobs).await?;
        }
        Ok(id)
    }

    /// The oldest queued or running job that will activate its table.
    pub async fn pending_activating_job(&self) -> Result<Option<String>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_scalar(
            "SELECT id FROM training_jobs WHERE status IN ($1, $2) AND activate = 1
             ORDER BY created_at, id LIMIT 1",
        )
        .bind(JobStatus::Queued.as_str())
        .bind(JobStatus::Running.as_str())
        .fetch_optional(p)
        .await?))
    }

    /// Job counts by state (jobs, not their shards).
    pub async fn job_counts(&self) -> Result<Vec<(String, i64)>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, (String, i64)>(
            "SELECT status, COUNT(*) FROM training_jobs WHERE parent_id IS NULL GROUP BY status",
        )
        .fetch_all(p)
        .await?))
    }

    // ---- shards ----

    /// The shard rows of job `parent`, survey shards first, by index.
    pub async fn shards(&self, parent: &str) -> Result<Vec<JobRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, JobRow>(
            "SELECT * FROM training_jobs WHERE parent_id = $1
             ORDER BY CASE WHEN kind = $2 THEN 0 ELSE 1 END, shard_index",
        )
        .bind(parent)
        .bind(JOB_KIND_SURVEY_SHARD)
        .fetch_all(p)
        .await?))
    }

    /// Marks a queued sharded job running when its first shard starts (the time it started).
    pub async fn start_sharded(&self, parent: &str, now: i64) -> Result<(), ServiceError> {
        on_pool!(self, p => sqlx::query(
            "UPDATE training_jobs SET status = $1, stage = 'survey', started_at = $2,
             attempts = attempts + 1
             WHERE id = $3 AND status = $4",
        )
        .bind(JobStatus::Running.as_str())
        .bind(now)
        .bind(parent)
        .bind(JobStatus::Queued.as_str())
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
    ) -> Result<Option<Vec<String>>, ServiceError> {
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
                "UPDATE training_jobs SET cancel_requested = 1 WHERE parent_id = $1 AND status = $2
                 RETURNING id",
            )
            .bind(parent)
            .bind(running)
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
    pub async fn store_partial(&self, part: &NewPartial<'_>) -> Result<(), ServiceError> {
        on_pool!(self, p => sqlx::query(
            "INSERT INTO training_partials (job_id, stage, shard_index, content, sha256, size_bytes, replica, created_at)
             SELECT $1, $2, $3, $4, $5, $6, $7, $8
             WHERE EXISTS (SELECT 1 FROM training_jobs WHERE id = $1 AND status IN ($9, $10))
             ON CONFLICT DO NOTHING",
        )
        .bind(part.job_id)
        .bind(part.stage)
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

    /// The stored partial sums of `stage` of job `parent` as (shard index, bytes, recorded
    /// SHA-256), by index; `only` picks one shard.
    pub async fn partials(
        &self,
        parent: &str,
        stage: &str,
        only: Option<i64>,
    ) -> Result<Vec<(i64, Vec<u8>, String)>, ServiceError> {
        Ok(
            on_pool!(self, p => sqlx::query_as::<_, (i64, Vec<u8>, String)>(
            "SELECT shard_index, content, sha256 FROM training_partials
             WHERE job_id = $1 AND stage = $2 AND ($3 IS NULL OR shard_index = $3)
             ORDER BY shard_index",
        )
        .bind(parent)
        .bind(stage)
        .bind(only)
        .fetch_all(p)
        .await?),
        )
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
    ) -> Result<ShardCompletion, ServiceError> {
        let Some(parent) = shard.parent_id.as_deref() else {
            return Ok(ShardCompletion::ParentEnded);
        };
        let (running, succeeded) = (JobStatus::Running.as_str(), JobStatus::Succeeded.as_str());
        let done = on_pool!(self, p => {
            let mut tx = p.begin().await?;
            // the lock: every shard of the job ends one after the other
            let status: Option<String> = sqlx::query_scalar(
                "UPDATE training_jobs SET stage = stage WHERE id = $1 RETURNING status",
            )
            .bind(parent)
            .fetch_optional(&mut *tx)
            .await?;
            if status.as_deref() != Some(running) {
                return Ok(ShardCompletion::ParentEnded);
            }
            let mine: i64 = sqlx::query_scalar(
                "SELECT COUNT(*) FROM training_jobs WHERE id = $1 AND lease_owner = $2 AND status = $3",
            )
            .bind(&shard.id)
            .bind(owner)
            .bind(running)
            .fetch_one(&mut *tx)
            .await?;
            if mine == 0 {
                return Ok(ShardCompletion::LeaseLost);
            }
            let others: i64 = sqlx::query_scalar(
                "SELECT COUNT(*) FROM training_jobs
                 WHERE parent_id = $1 AND kind = $2 AND id <> $3 AND status <> $4",
            )
            .bind(parent)
            .bind(&shard.kind)
            .bind(&shard.id)
            .bind(succeeded)
            .fetch_one(&mut *tx)
            .await?;
            let last = others == 0;
            if last && shard.kind == JOB_KIND_ACCUMULATE_SHARD {
                sqlx::query("UPDATE training_jobs SET stage = 'merge' WHERE id = $1 OR id = $2")
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
            if last && shard.kind == JOB_KIND_SURVEY_SHARD {
                let next = NewShards {
                    parent,
                    kind: JOB_KIND_ACCUMULATE_SHARD,
                    count: shard.shard_count.unwrap_or(1),
                    request_json: &shard.request_json,
                    request_sha256: &shard.request_sha256,
                    created_at: shard.created_at,
                };
                insert_shards!(tx, next);
                sqlx::query("UPDATE training_jobs SET stage = 'accumulate' WHERE id = $1")
                    .bind(parent)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await?;
            if last { ShardCompletion::Last } else { ShardCompletion::Done }
        });
        if done == ShardCompletion::Last && shard.kind == JOB_KIND_SURVEY_SHARD {
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
    ) -> Result<bool, ServiceError> {
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

    // ---- tables ----

    /// Records a table (idempotent: the id is the content hash).
    pub async fn insert_table(&self, t: &NewTable<'_>) -> Result<(), ServiceError> {
        on_pool!(self, p => sqlx::query(
            "INSERT INTO l3_tables (id, path, sha256, size_bytes, kind, meta_json, job_id, created_at, content)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) ON CONFLICT (id) DO NOTHING",
        )
        .bind(t.id)
        .bind(t.path)
        .bind(t.sha256)
        .bind(t.size_bytes)
        .bind(t.kind)
        .bind(t.meta_json)
        .bind(t.job_id)
        .bind(t.created_at)
        .bind(t.content)
        .execute(p)
        .await?
        .rows_affected());
        Ok(())
    }

    pub async fn table(&self, id: &str) -> Result<Option<TableRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, TableRow>(
            concat!("SELECT ", table_columns!(), " FROM l3_tables WHERE id = $1"),
        )
        .bind(id)
        .fetch_optional(p)
        .await?))
    }

    /// All tables, oldest first.
    pub async fn tables_oldest_first(&self) -> Result<Vec<TableRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, TableRow>(
            concat!("SELECT ", table_columns!(), " FROM l3_tables ORDER BY created_at, id"),
        )
        .fetch_all(p)
        .await?))
    }

    /// All tables, newest first.
    pub async fn tables_newest_first(&self) -> Result<Vec<TableRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, TableRow>(
            concat!("SELECT ", table_columns!(), " FROM l3_tables ORDER BY created_at DESC, id"),
        )
        .fetch_all(p)
        .await?))
    }

    /// The bytes of a table kept in the database, if any.
    pub async fn table_content(&self, id: &str) -> Result<Option<Vec<u8>>, ServiceError> {
        let r: Option<Option<Vec<u8>>> = on_pool!(self, p => sqlx::query_scalar(
            "SELECT content FROM l3_tables WHERE id = $1",
        )
        .bind(id)
        .fetch_optional(p)
        .await?);
        Ok(r.flatten())
    }

    /// Records a table's file health (`ok`, `corrupt` or `missing`) when it changed.
    pub async fn set_table_status(
        &self,
        id: &str,
        status: &str,
        detail: Option<&str>,
    ) -> Result<(), ServiceError> {
        on_pool!(self, p => sqlx::query(
            "UPDATE l3_tables SET status = $1, status_detail = $2
             WHERE id = $3 AND (status <> $1 OR status_detail IS DISTINCT FROM $2)",
        )
        .bind(status)
        .bind(detail)
        .bind(id)
        .execute(p)
        .await?
        .rows_affected());
        Ok(())
    }

    /// Records `id` as the active table (and when), and tells the other replicas.
    pub async fn record_activation(&self, id: &str, now: i64) -> Result<(), ServiceError> {
        on_pool!(self, p => {
            let mut tx = p.begin().await?;
            sqlx::query(
                "INSERT INTO settings (key, value) VALUES ('active_table', $1)
                 ON CONFLICT (key) DO UPDATE SET value = excluded.value",
            )
            .bind(id)
            .execute(&mut *tx)
            .await?;
            sqlx::query("UPDATE l3_tables SET last_activated_at = $1 WHERE id = $2")
                .bind(now)
                .bind(id)
                .execute(&mut *tx)
                .await?;
            tx.commit().await?;
        });
        self.notify(Change::ActiveTable).await
    }

    /// The id recorded as active, if any.
    pub async fn recorded_active(&self) -> Result<Option<String>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_scalar(
            "SELECT value FROM settings WHERE key = 'active_table'",
        )
        .fetch_optional(p)
        .await?))
    }

    /// Healthy tables, most recently activated first, then the newest.
    pub async fn usable_tables_by_recency(&self) -> Result<Vec<String>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_scalar(
            "SELECT id FROM l3_tables WHERE status = 'ok'
             ORDER BY (last_activated_at IS NULL), last_activated_at DESC, created_at DESC, id",
        )
        .fetch_all(p)
        .await?))
    }

    // ---- illuminants ----

    /// The user illuminants, in creation order.
    pub async fn illuminants(&self) -> Result<Vec<IlluminantRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, IlluminantRow>(
            "SELECT name, definition_json FROM illuminants ORDER BY created_at, name",
        )
        .fetch_all(p)
        .await?))
    }

    /// Creates or replaces a user illuminant, and tells the other replicas.
    pub async fn upsert_illuminant(
        &self,
        name: &str,
        definition_json: &str,
        now: i64,
    ) -> Result<(), ServiceError> {
        on_pool!(self, p => sqlx::query(
            "INSERT INTO illuminants (name, definition_json, created_at) VALUES ($1, $2, $3)
             ON CONFLICT (name) DO UPDATE SET definition_json = excluded.definition_json",
        )
        .bind(name)
        .bind(definition_json)
        .bind(now)
        .execute(p)
        .await?
        .rows_affected());
        self.notify(Change::Illuminants).await
    }

    /// Deletes a user illuminant, and tells the other replicas.
    pub async fn delete_illuminant(&self, name: &str) -> Result<(), ServiceError> {
        on_pool!(self, p => sqlx::query("DELETE FROM illuminants WHERE name = $1")
            .bind(name)
            .execute(p)
            .await?
            .rows_affected());
        self.notify(Change::Illuminants).await
    }

    // ---- evaluations ----

    pub async fn insert_evaluation(&self, e: &EvaluationRow) -> Result<(), ServiceError> {
        on_pool!(self, p => sqlx::query(
            "INSERT INTO evaluations (id, table_id, method, chart, acquisition_illuminant, mean_delta_e, request_json, report_json, created_at)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)",
        )
        .bind(&e.id)
        .bind(&e.table_id)
        .bind(&e.method)
        .bind(&e.chart)
        .bind(&e.acquisition_illuminant)
        .bind(e.mean_delta_e)
        .bind(&e.request_json)
        .bind(&e.report_json)
        .bind(e.created_at)
        .execute(p)
        .await?
        .rows_affected());
        Ok(())
    }

    pub async fn evaluation(&self, id: &str) -> Result<Option<EvaluationRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, EvaluationRow>(
            "SELECT * FROM evaluations WHERE id = $1",
        )
        .bind(id)
        .fetch_optional(p)
        .await?))
    }

    /// The newest evaluations first (at most 1000).
    pub async fn evaluations(&self) -> Result<Vec<EvaluationRow>, ServiceError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, EvaluationRow>(
            "SELECT * FROM evaluations ORDER BY created_at DESC, id LIMIT 1000",
        )
        .fetch_all(p)
        .await?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn job_status_round_trips() {
        for s in JobStatus::ALL {
            assert_eq!(s.as_str().parse::<JobStatus>(), Ok(s));
        }
        assert!("done".parse::<JobStatus>().is_err());
        for c in [Change::ActiveTable, Change::Illuminants, Change::Jobs] {
            assert_eq!(Change::parse(c.as_str()), Some(c));
        }
    }

    #[tokio::test]
    async fn sqlite_store_claims_leases_and_requeues() {
        let dir = tempfile::tempdir().unwrap();
        let s = Store::connect("", dir.path()).await.unwrap();
        let job = |id: &'static str, key: Option<&'static str>| NewJob {
            id,
            kind: JOB_KIND_TRAIN,
            shard_count: None,
            request_json: "{}",
            idempotency_key: key,
            request_sha256: "x",
            activate: false,
            created_at: 1,
        };
        assert!(s.insert_job(&job("a", Some("k"))).await.unwrap());
        assert!(!s.insert_job(&job("b", Some("k"))).await.unwrap());
        let c = s
            .claim_job(&[JOB_KIND_TRAIN], "r1", 10, 20)
            .await
            .unwrap()
            .unwrap();
        assert_eq!(
            (c.id.as_str(), c.status, c.attempts),
            ("a", JobStatus::Running, 1)
        );
        assert!(
            s.claim_job(&[JOB_KIND_TRAIN], "r2", 10, 20)
                .await
                .unwrap()
                .is_none()
        );
        assert_eq!(s.heartbeat("a", "r2", 11, 30, None).await.unwrap(), None);
        assert_eq!(
            s.heartbeat("a", "r1", 11, 30, None).await.unwrap(),
            Some(false)
        );
        assert_eq!(s.requeue_expired(25).await.unwrap(), 0);
        assert!(s.request_cancel("a").await.unwrap());
        assert_eq!(
            s.heartbeat("a", "r1", 12, 30, None).await.unwrap(),
            Some(true)
        );
        // the lease expires with the cancel requested: canceled, not re-queued
        assert_eq!(s.requeue_expired(31).await.unwrap(), 1);
        assert_eq!(
            s.job("a").await.unwrap().unwrap().status,
            JobStatus::Canceled
        );
        assert_eq!(s.heartbeat("a", "r1", 32, 40, None).await.unwrap(), None);
        // a canceled once-job is queued again, a queued one is left alone
        assert_eq!(
            s.queue_once(&job("c", Some("k"))).await.unwrap(),
            Some("a".into())
        );
        assert_eq!(s.queue_once(&job("d", Some("k"))).await.unwrap(), None);
        let c = s
            .claim_job(&[JOB_KIND_TRAIN], "r2", 40, 50)
            .await
            .unwrap()
            .unwrap();
        assert_eq!((c.attempts, c.cancel_requested), (2, 0));
        assert_eq!(s.requeue_expired(51).await.unwrap(), 1);
        assert_eq!(s.job("a").await.unwrap().unwrap().status, JobStatus::Queued);
        s.close().await;
    }

    #[tokio::test]
    async fn sqlite_store_runs_shards_and_finds_the_last_one_once() {
        let dir = tempfile::tempdir().unwrap();
        let s = Store::connect("", dir.path()).await.unwrap();
        let parent = NewJob {
            id: "p",
            kind: JOB_KIND_SHARDED,
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
        // the accumulation shards are queued once the survey is complete
        let c = s.claim_job(kinds, "r1", 13, 100).await.unwrap().unwrap();
        let d = s.claim_job(kinds, "r2", 13, 100).await.unwrap().unwrap();
        assert_eq!(c.id, "p-accumulate-1");
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
            s.job("p").await.unwrap().unwrap(),
            s.job(&c.id).await.unwrap().unwrap(),
        );
        assert_eq!(
            (pj.stage.as_deref(), cj.status),
            (Some("merge"), JobStatus::Running)
        );
        let part = NewPartial {
            job_id: "p",
            stage: "accumulate",
            shard_index: 0,
            content: b"sums",
            sha256: "h",
            replica: "r1",
            created_at: 15,
        };
        s.store_partial(&part).await.unwrap();
        s.store_partial(&part).await.unwrap();
        assert_eq!(s.partials("p", "accumulate", None).await.unwrap().len(), 1);
        assert!(
            s.finish_sharded("p", &c.id, "tbl", 3, "r1", 16)
                .await
                .unwrap()
        );
        assert_eq!(
            s.job(&c.id).await.unwrap().unwrap().status,
            JobStatus::Succeeded
        );
        assert!(
            s.partials("p", "accumulate", None)
                .await
                .unwrap()
                .is_empty()
        );
        assert_eq!(s.shards("p").await.unwrap().len(), 4);
        // a job canceled while queued takes its shards with it
        let q = NewJob { id: "q", ..parent };
        assert!(s.insert_job(&q).await.unwrap());
        let e = s.claim_job(kinds, "r1", 20, 100).await.unwrap().unwrap();
        let stopping = s
            .end_sharded("q", JobStatus::Canceled, None, 21)
            .await
            .unwrap()
            .unwrap();
        assert_eq!(stopping, vec![e.id.clone()]);
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
        s.close().await;
    }
}
