//! The typed store reads a database written by earlier versions: after the migrations, rows are
//! inserted with raw SQL holding the strings and integers the previous (untyped) store wrote
//! (every job kind, status and stage, the 0/1 flags, every table status, both evaluation
//! methods, both partial-sum stages), and the store reads them back as its enums and bools.
//! What the store writes is read back with raw SQL as the same strings and integers. A value
//! none of its column's is an error naming the row, not a panic. SQLite by default; PostgreSQL
//! with `L3_TEST_BACKEND=postgres`.

use l3::service::Store;
use l3::service::store::{
    EvaluationChart, EvaluationMethod, JobKind, JobStage, JobStatus, NewJob, ShardStage,
    StoreError, TableStatus,
};

use crate::service_support::pg;

/// A parameter of a raw statement: text or an integer, either maybe NULL.
#[derive(Debug, Clone, Copy)]
enum Param<'a> {
    Text(Option<&'a str>),
    Int(Option<i64>),
}
use Param::{Int, Text};

/// Runs one statement of raw SQL on either backend.
async fn exec(store: &Store, sql: &str, params: &[Param<'_>]) {
    macro_rules! run {
        ($p:expr) => {{
            let mut q = sqlx::query(sql);
            for v in params {
                q = match *v {
                    Text(t) => q.bind(t),
                    Int(n) => q.bind(n),
                };
            }
            q.execute($p)
                .await
                .unwrap_or_else(|e| panic!("{sql} {params:?}: {e}"));
        }};
    }
    match store {
        Store::Sqlite(p) => run!(p),
        Store::Postgres(p) => run!(p),
    }
}

/// The text and integer columns of job `id` as stored: kind, status, stage, activate,
/// cancel_requested.
async fn stored_job(store: &Store, id: &str) -> (String, String, Option<String>, i64, i64) {
    let sql =
        "SELECT kind, status, stage, activate, cancel_requested FROM training_jobs WHERE id = $1";
    match store {
        Store::Sqlite(p) => sqlx::query_as(sql).bind(id).fetch_one(p).await,
        Store::Postgres(p) => sqlx::query_as(sql).bind(id).fetch_one(p).await,
    }
    .unwrap()
}

/// A job row as the previous store wrote it: id, kind, status, stage, activate,
/// cancel_requested, parent, shard index.
type OldJob = (
    &'static str,
    &'static str,
    &'static str,
    Option<&'static str>,
    i64,
    i64,
    Option<&'static str>,
    Option<i64>,
);

/// Every kind, status and stage the previous store and the training wrote, and both flag
/// values.
const OLD_JOBS: &[OldJob] = &[
    ("job_q", "train", "queued", Some("queued"), 1, 0, None, None),
    ("job_n", "train", "queued", None, 0, 0, None, None),
    (
        "job_st",
        "train",
        "running",
        Some("starting"),
        0,
        0,
        None,
        None,
    ),
    (
        "job_sv",
        "train",
        "running",
        Some("survey"),
        0,
        0,
        None,
        None,
    ),
    (
        "job_ac",
        "train",
        "running",
        Some("accumulate"),
        0,
        1,
        None,
        None,
    ),
    (
        "job_so",
        "train",
        "running",
        Some("solve"),
        1,
        0,
        None,
        None,
    ),
    ("job_do", "train", "running", Some("done"), 1, 0, None, None),
    (
        "job_ok",
        "train",
        "succeeded",
        Some("succeeded"),
        1,
        0,
        None,
        None,
    ),
    ("job_f", "train", "failed", Some("failed"), 0, 0, None, None),
    (
        "job_c",
        "train",
        "canceled",
        Some("canceled"),
        0,
        1,
        None,
        None,
    ),
    (
        "job_rr",
        "train",
        "queued",
        Some("requeued after restart"),
        0,
        0,
        None,
        None,
    ),
    (
        "job_rl",
        "train",
        "queued",
        Some("requeued after lease expiry"),
        0,
        0,
        None,
        None,
    ),
    (
        "job_is",
        "train",
        "queued",
        Some("interrupted by shutdown"),
        0,
        0,
        None,
        None,
    ),
    (
        "job_p",
        "train_sharded",
        "running",
        Some("merge"),
        0,
        0,
        None,
        None,
    ),
    (
        "job_p-survey-1",
        "survey_shard",
        "succeeded",
        Some("succeeded"),
        0,
        0,
        Some("job_p"),
        Some(0),
    ),
    (
        "job_p-accumulate-1",
        "accumulate_shard",
        "running",
        Some("merge"),
        0,
        0,
        Some("job_p"),
        Some(0),
    ),
];

/// Inserts the old rows of every table.
async fn write_old_rows(store: &Store) {
    for (k, &(id, kind, status, stage, activate, cancel, parent, index)) in
        OLD_JOBS.iter().enumerate()
    {
        exec(
            store,
            "INSERT INTO training_jobs (id, kind, status, request_json, request_sha256, activate,
             progress, stage, created_at, cancel_requested, parent_id, shard_index, shard_count)
             VALUES ($1, $2, $3, '{}', 'sha', $4, 0.5, $5, $6, $7, $8, $9, 1)",
            &[
                Text(Some(id)),
                Text(Some(kind)),
                Text(Some(status)),
                Int(Some(activate)),
                Text(stage),
                Int(Some(100 + k as i64)),
                Int(Some(cancel)),
                Text(parent),
                Int(index),
            ],
        )
        .await;
    }
    for (id, status, detail, activated) in [
        ("tbl_ok", "ok", None, Some(50)),
        ("tbl_bad", "corrupt", Some("its SHA-256 differs"), None),
        ("tbl_gone", "missing", Some("cannot read"), None),
    ] {
        exec(
            store,
            "INSERT INTO l3_tables (id, path, sha256, size_bytes, kind, meta_json, job_id,
             created_at, status, status_detail, last_activated_at)
             VALUES ($1, $2, 'sha', 4, 'SI', '{}', 'job_ok', 10, $3, $4, $5)",
            &[
                Text(Some(id)),
                Text(Some(&format!("{id}.safetensors"))),
                Text(Some(status)),
                Text(detail),
                Int(activated),
            ],
        )
        .await;
    }
    exec(
        store,
        "INSERT INTO settings (key, value) VALUES ('active_table', 'tbl_ok')",
        &[],
    )
    .await;
    for (id, method, table, created) in [
        ("eval_l3", "l3", Some("tbl_ok"), 20),
        ("eval_base", "baseline", None, 21),
    ] {
        exec(
            store,
            "INSERT INTO evaluations (id, table_id, method, chart, acquisition_illuminant,
             mean_delta_e, request_json, report_json, created_at)
             VALUES ($1, $2, $3, 'natural100', 'Tungsten', 2.5, '{}', '{}', $4)",
            &[
                Text(Some(id)),
                Text(table),
                Text(Some(method)),
                Int(Some(created)),
            ],
        )
        .await;
    }
    exec(
        store,
        "INSERT INTO illuminants (name, definition_json, created_at) VALUES ('lamp', '{}', 1)",
        &[],
    )
    .await;
}

/// Inserts stored partial sums of `stage` (bytes are bound: the backends spell BLOBs apart).
async fn write_old_partial(store: &Store, stage: &str) {
    let sql = "INSERT INTO training_partials (job_id, stage, shard_index, content, sha256,
               size_bytes, replica, created_at) VALUES ('job_p', $1, 0, $2, 'h', 4, 'r1', 7)";
    let bytes: &[u8] = b"sums";
    let stored = match store {
        Store::Sqlite(p) => sqlx::query(sql)
            .bind(stage)
            .bind(bytes)
            .execute(p)
            .await
            .map(drop),
        Store::Postgres(p) => sqlx::query(sql)
            .bind(stage)
            .bind(bytes)
            .execute(p)
            .await
            .map(drop),
    };
    stored.unwrap();
}

async fn reads_jobs(store: &Store) {
    for &(id, kind, status, stage, activate, cancel, parent, index) in OLD_JOBS {
        let row = store.existing_job(id).await.unwrap();
        assert_eq!(row.kind, JobKind::parse(kind).unwrap(), "{id}");
        assert_eq!(row.kind.as_str(), kind);
        assert_eq!(row.status.as_str(), status, "{id}");
        assert_eq!(row.stage.map(JobStage::as_str), stage, "{id}");
        assert_eq!(
            (row.activate, row.cancel_requested),
            (activate == 1, cancel == 1)
        );
        assert_eq!((row.parent_id.as_deref(), row.shard_index), (parent, index));
    }
    let q = store.existing_job("job_q").await.unwrap();
    assert_eq!(
        (q.kind, q.status, q.stage, q.activate, q.cancel_requested),
        (
            JobKind::Train,
            JobStatus::Queued,
            Some(JobStage::Queued),
            true,
            false
        )
    );
    let rl = store.existing_job("job_rl").await.unwrap();
    assert_eq!(rl.stage, Some(JobStage::RequeuedAfterLeaseExpiry));
    let c = store.existing_job("job_c").await.unwrap();
    assert!(c.cancel_requested);
    // the list and the counts are of jobs, not their shards
    let listed = store.list_jobs(None, 100).await.unwrap();
    assert_eq!(listed.len(), OLD_JOBS.len() - 2);
    let running = store
        .list_jobs(Some(JobStatus::Running), 100)
        .await
        .unwrap();
    assert_eq!(running.len(), 6);
    let mut counts = store.job_counts().await.unwrap();
    counts.sort_by_key(|(s, _)| s.as_str());
    assert_eq!(
        counts,
        [
            (JobStatus::Canceled, 1),
            (JobStatus::Failed, 1),
            (JobStatus::Queued, 5),
            (JobStatus::Running, 6),
            (JobStatus::Succeeded, 1),
        ]
    );
    let shards = store.shards("job_p").await.unwrap();
    let kinds: Vec<JobKind> = shards.iter().map(|s| s.kind).collect();
    assert_eq!(kinds, [JobKind::SurveyShard, JobKind::AccumulateShard]);
    assert_eq!(
        store.pending_activating_job().await.unwrap().as_deref(),
        Some("job_q")
    );
}

async fn reads_tables_evaluations_and_partials(store: &Store) {
    let tables = store.tables_oldest_first().await.unwrap();
    let statuses: Vec<(&str, TableStatus)> =
        tables.iter().map(|t| (t.id.as_str(), t.status)).collect();
    assert_eq!(
        statuses,
        [
            ("tbl_bad", TableStatus::Corrupt),
            ("tbl_gone", TableStatus::Missing),
            ("tbl_ok", TableStatus::Ok),
        ]
    );
    let ok = store.existing_table("tbl_ok").await.unwrap();
    assert_eq!((ok.last_activated_at, ok.status_detail), (Some(50), None));
    assert_eq!(store.usable_tables_by_recency().await.unwrap(), ["tbl_ok"]);
    assert_eq!(
        store.recorded_active().await.unwrap().as_deref(),
        Some("tbl_ok")
    );
    let evals = store.evaluations().await.unwrap();
    let read: Vec<(&str, EvaluationMethod, EvaluationChart, Option<&str>)> = evals
        .iter()
        .map(|e| (e.id.as_str(), e.method, e.chart, e.table_id.as_deref()))
        .collect();
    assert_eq!(
        read,
        [
            (
                "eval_base",
                EvaluationMethod::Baseline,
                EvaluationChart::Natural100,
                None
            ),
            (
                "eval_l3",
                EvaluationMethod::L3,
                EvaluationChart::Natural100,
                Some("tbl_ok")
            ),
        ]
    );
    for stage in ShardStage::ALL {
        let parts = store.partials("job_p", stage, None).await.unwrap();
        assert_eq!(parts.len(), 1, "{stage}");
        assert_eq!(
            (parts[0].content.as_slice(), parts[0].sha256.as_str()),
            (&b"sums"[..], "h")
        );
    }
    assert_eq!(store.illuminants().await.unwrap()[0].name, "lamp");
}

/// What the typed store writes is stored as the strings and integers the previous one wrote.
async fn writes_the_old_values(store: &Store) {
    let job = NewJob {
        id: "job_new",
        kind: JobKind::Train,
        shard_count: None,
        request_json: "{}",
        idempotency_key: None,
        request_sha256: "sha",
        activate: true,
        created_at: 1,
    };
    assert!(store.insert_job(&job).await.unwrap());
    assert_eq!(
        stored_job(store, "job_new").await,
        ("train".into(), "queued".into(), Some("queued".into()), 1, 0)
    );
    let claimed = store
        .claim_job(&[JobKind::Train], "r1", 0, i64::MAX)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(claimed.id, "job_new");
    assert!(store.request_cancel("job_new").await.unwrap());
    assert_eq!(
        stored_job(store, "job_new").await,
        (
            "train".into(),
            "running".into(),
            Some("starting".into()),
            1,
            1
        )
    );
    store
        .set_table_status("tbl_ok", TableStatus::Missing, Some("gone"))
        .await
        .unwrap();
    let sql = "SELECT status FROM l3_tables WHERE id = 'tbl_ok'";
    let status: String = match store {
        Store::Sqlite(p) => sqlx::query_scalar(sql).fetch_one(p).await,
        Store::Postgres(p) => sqlx::query_scalar(sql).fetch_one(p).await,
    }
    .unwrap();
    assert_eq!(status, "missing");
}

/// A stored value none of its column's is an error naming the row and the value.
async fn a_bad_value_is_an_error(store: &Store) {
    exec(
        store,
        "UPDATE training_jobs SET stage = 'thinking' WHERE id = $1",
        &[Text(Some("job_f"))],
    )
    .await;
    let e = store.existing_job("job_f").await.unwrap_err();
    assert!(
        matches!(&e, StoreError::CorruptRow { table: "training_jobs", id, column: "stage", value, .. }
            if id == "job_f" && value == "thinking"),
        "{e:?}"
    );
    assert!(store.list_jobs(None, 100).await.is_err());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_typed_store_reads_and_writes_what_the_previous_store_wrote() {
    let data = tempfile::tempdir().unwrap();
    let url = pg::test_database_url(data.path()).unwrap_or_default();
    let store = Store::connect(&url, data.path()).await.unwrap();
    eprintln!("backend: {}", store.backend());
    write_old_rows(&store).await;
    write_old_partial(&store, "survey").await;
    write_old_partial(&store, "accumulate").await;
    reads_jobs(&store).await;
    reads_tables_evaluations_and_partials(&store).await;
    writes_the_old_values(&store).await;
    a_bad_value_is_an_error(&store).await;
    store.close().await;
}
