//! The service's database: SQLite (embedded, the default) or PostgreSQL (shared by replicas).
//! Every query lives here, once, by table, with typed rows (enum columns, `bool` flags); the
//! two backends run the same SQL text except where the dialects differ (claiming a job).
//! Changes other replicas must see (activation, illuminants, new jobs) are announced with
//! NOTIFY on PostgreSQL. Errors are [`StoreError`]s; what they mean over HTTP is decided once,
//! by `ServiceError` (`src/service/error.rs`).
//!
//! - `jobs.rs`: `training_jobs` rows: insert, look up, list, cancel, count;
//! - `leases.rs`: claiming a queued job under a lease, the heartbeat, ending or re-queueing it;
//! - `shards.rs`: the shard rows of a sharded job and their partial sums (`training_partials`);
//! - `tables.rs`: `l3_tables` and the active table (`settings`);
//! - `illuminants.rs`, `evaluations.rs`: their tables;
//! - `columns.rs`: the enum columns' values; `error.rs`: [`StoreError`].
//!
//! The files depend on one another in one direction: `error` ← `columns` ← `jobs` ← `leases`,
//! `shards`; every table's file uses this one's [`Store`].

use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

use sqlx::postgres::{PgListener, PgPool, PgPoolOptions};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions};

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

mod columns;
mod error;
mod evaluations;
mod illuminants;
mod jobs;
mod leases;
mod shards;
mod tables;

pub use columns::{
    EvaluationChart, EvaluationMethod, JobKind, JobStage, JobStatus, ShardStage, TableStatus,
    WORKER_KINDS,
};
pub use error::{RowKind, StoreError};
pub use evaluations::EvaluationRow;
pub use illuminants::IlluminantRow;
pub use jobs::{JobRow, NewJob};
pub use leases::{JobEnd, Progress};
pub use shards::{NewPartial, Partial, ShardCompletion};
pub use tables::{NewTable, TableRow};

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

/// The database of a service: one pool of either backend.
#[derive(Debug, Clone)]
pub enum Store {
    Sqlite(SqlitePool),
    Postgres(PgPool),
}

/// `url` with the password of its `user:password@` part, if any, shown as `***` (for
/// messages and logs).
pub fn redacted(url: &str) -> String {
    // after the scheme's `//` (also in a URL whose scheme is misspelt), else from the start
    let scheme_end = url.find("//").map_or(0, |i| i + 2);
    let rest = &url[scheme_end..];
    let authority_end = rest.find(['/', '?', '#']).unwrap_or(rest.len());
    let Some(at) = rest[..authority_end].rfind('@') else {
        return url.to_string();
    };
    match rest[..at].find(':') {
        Some(colon) => format!(
            "{}{}:***{}",
            &url[..scheme_end],
            &rest[..colon],
            &rest[at..]
        ),
        None => url.to_string(),
    }
}

/// The embedded SQLite database's file in the data directory.
pub const SQLITE_FILE: &str = "l3.sqlite";

impl Store {
    /// Connects and applies the migrations. An empty `url` is the embedded SQLite database
    /// `l3.sqlite` in `data_dir`; otherwise `sqlite://…` or `postgres://…`.
    pub async fn connect(url: &str, data_dir: &Path) -> Result<Store, StoreError> {
        let url = url.trim();
        let store = if url.is_empty() || url.starts_with("sqlite:") {
            let opts = if url.is_empty() {
                SqliteConnectOptions::new().filename(data_dir.join(SQLITE_FILE))
            } else {
                SqliteConnectOptions::from_str(url)
                    .map_err(|e| StoreError::Url(format!("database_url: {e}")))?
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
            let pool = match PgPoolOptions::new()
                .max_connections(8)
                .acquire_timeout(Duration::from_secs(10))
                .connect(url)
                .await
            {
                Ok(pool) => pool,
                Err(sqlx::Error::PoolTimedOut) => {
                    // the pool says only that it timed out: one direct attempt says why
                    use sqlx::Connection;
                    let source = match sqlx::PgConnection::connect(url).await {
                        Err(e) => e,
                        Ok(_) => sqlx::Error::PoolTimedOut,
                    };
                    return Err(StoreError::Connect {
                        url: redacted(url),
                        source,
                    });
                }
                Err(e) => return Err(e.into()),
            };
            sqlx::migrate!("./migrations/postgres").run(&pool).await?;
            Store::Postgres(pool)
        } else {
            return Err(StoreError::Url(format!(
                "database_url '{}': expected sqlite://… or postgres://…",
                redacted(url)
            )));
        };
        Ok(store)
    }

    /// Whether `url` is a database URL the service takes, checked without connecting: empty
    /// (SQLite in the data directory), `sqlite:…`, or a `postgres://` URL that parses. The
    /// error shows the URL without its password.
    pub fn check_url(url: &str) -> Result<(), StoreError> {
        let url = url.trim();
        let bad = |why: String| StoreError::Url(format!("database_url '{}': {why}", redacted(url)));
        if url.is_empty() || url.starts_with("sqlite:") {
            return SqliteConnectOptions::from_str(if url.is_empty() {
                "sqlite::memory:"
            } else {
                url
            })
            .map(|_| ())
            .map_err(|e| bad(e.to_string()));
        }
        if url.starts_with("postgres://") || url.starts_with("postgresql://") {
            return sqlx::postgres::PgConnectOptions::from_str(url)
                .map(|_| ())
                .map_err(|e| bad(redacted(&e.to_string())));
        }
        Err(bad("expected sqlite://… or postgres://…".into()))
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
    pub async fn listener(&self) -> Result<Option<PgListener>, StoreError> {
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
    pub async fn notify(&self, change: Change) -> Result<(), StoreError> {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changes_round_trip() {
        for c in [Change::ActiveTable, Change::Illuminants, Change::Jobs] {
            assert_eq!(Change::parse(c.as_str()), Some(c));
        }
        assert_eq!(Change::parse("tables"), None);
    }

    #[tokio::test]
    async fn a_url_of_no_backend_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let e = Store::connect("mysql://x", dir.path()).await.unwrap_err();
        assert!(matches!(e, StoreError::Url(_)), "{e:?}");
        assert!(e.to_string().contains("expected sqlite://"), "{e}");
    }

    #[test]
    fn urls_are_checked_without_connecting_and_shown_without_their_password() {
        for ok in [
            "",
            "sqlite://data/l3.sqlite",
            "postgres://l3:pw@db:5432/l3",
            "postgresql://db/l3",
        ] {
            Store::check_url(ok).unwrap();
        }
        for bad in [
            "mysql://u:s3cret@y/z",
            "not a url",
            "postgres//l3:s3cret@h/l3",
            "postgres://l3:s3cret@h:notaport/l3",
        ] {
            let e = Store::check_url(bad).unwrap_err().to_string();
            assert!(e.contains("database_url"), "{e}");
            assert!(!e.contains("s3cret"), "{e}");
        }
        assert_eq!(
            redacted("postgres://l3:pw@db:5432/l3"),
            "postgres://l3:***@db:5432/l3"
        );
        assert_eq!(redacted("postgres://l3@db/l3"), "postgres://l3@db/l3");
        assert_eq!(redacted("postgres://db/a@b"), "postgres://db/a@b");
    }
}
