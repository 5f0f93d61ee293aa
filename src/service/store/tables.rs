//! `l3_tables` (a table's file, checksum, metadata and health; its bytes where replicas share
//! them) and the active table (`settings`, with each table's last activation).

use super::columns::{TableStatus, column};
use super::error::{RowKind, StoreError};
use super::{Change, Store};

/// The table's name (in errors).
const TABLE: &str = "l3_tables";

/// An `l3_tables` row (without the bytes).
#[derive(Debug, Clone, PartialEq)]
pub struct TableRow {
    pub id: String,
    pub path: String,
    pub sha256: String,
    pub size_bytes: i64,
    pub kind: String,
    pub meta_json: String,
    pub job_id: Option<String>,
    pub created_at: i64,
    pub status: TableStatus,
    pub status_detail: Option<String>,
    pub last_activated_at: Option<i64>,
}

/// An `l3_tables` row as stored.
#[derive(Debug, sqlx::FromRow)]
struct StoredTableRow {
    id: String,
    path: String,
    sha256: String,
    size_bytes: i64,
    kind: String,
    meta_json: String,
    job_id: Option<String>,
    created_at: i64,
    status: String,
    status_detail: Option<String>,
    last_activated_at: Option<i64>,
}

impl TryFrom<StoredTableRow> for TableRow {
    type Error = StoreError;

    fn try_from(r: StoredTableRow) -> Result<TableRow, StoreError> {
        let status = column(TABLE, &r.id, &r.status, TableStatus::parse)?;
        Ok(TableRow {
            id: r.id,
            path: r.path,
            sha256: r.sha256,
            size_bytes: r.size_bytes,
            kind: r.kind,
            meta_json: r.meta_json,
            job_id: r.job_id,
            created_at: r.created_at,
            status,
            status_detail: r.status_detail,
            last_activated_at: r.last_activated_at,
        })
    }
}

fn table_rows(rows: Vec<StoredTableRow>) -> Result<Vec<TableRow>, StoreError> {
    rows.into_iter().map(TableRow::try_from).collect()
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

impl Store {
    /// Records a table (idempotent: the id is the content hash).
    pub async fn insert_table(&self, t: &NewTable<'_>) -> Result<(), StoreError> {
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

    /// The table `id`, if any.
    pub async fn table(&self, id: &str) -> Result<Option<TableRow>, StoreError> {
        let row = on_pool!(self, p => sqlx::query_as::<_, StoredTableRow>(
            concat!("SELECT ", table_columns!(), " FROM l3_tables WHERE id = $1"),
        )
        .bind(id)
        .fetch_optional(p)
        .await?);
        row.map(TableRow::try_from).transpose()
    }

    /// The table `id`; [`StoreError::NotFound`] when there is none.
    pub async fn existing_table(&self, id: &str) -> Result<TableRow, StoreError> {
        self.table(id).await?.ok_or_else(|| StoreError::NotFound {
            kind: RowKind::Table,
            id: id.to_string(),
        })
    }

    /// All tables, oldest first.
    pub async fn tables_oldest_first(&self) -> Result<Vec<TableRow>, StoreError> {
        table_rows(on_pool!(self, p => sqlx::query_as::<_, StoredTableRow>(
            concat!("SELECT ", table_columns!(), " FROM l3_tables ORDER BY created_at, id"),
        )
        .fetch_all(p)
        .await?))
    }

    /// All tables, newest first.
    pub async fn tables_newest_first(&self) -> Result<Vec<TableRow>, StoreError> {
        table_rows(on_pool!(self, p => sqlx::query_as::<_, StoredTableRow>(
            concat!("SELECT ", table_columns!(), " FROM l3_tables ORDER BY created_at DESC, id"),
        )
        .fetch_all(p)
        .await?))
    }

    /// The bytes of a table kept in the database, if any.
    pub async fn table_content(&self, id: &str) -> Result<Option<Vec<u8>>, StoreError> {
        let r: Option<Option<Vec<u8>>> = on_pool!(self, p => sqlx::query_scalar(
            "SELECT content FROM l3_tables WHERE id = $1",
        )
        .bind(id)
        .fetch_optional(p)
        .await?);
        Ok(r.flatten())
    }

    /// Records a table's file health when it changed.
    pub async fn set_table_status(
        &self,
        id: &str,
        status: TableStatus,
        detail: Option<&str>,
    ) -> Result<(), StoreError> {
        on_pool!(self, p => sqlx::query(
            "UPDATE l3_tables SET status = $1, status_detail = $2
             WHERE id = $3 AND (status <> $1 OR status_detail IS DISTINCT FROM $2)",
        )
        .bind(status.as_str())
        .bind(detail)
        .bind(id)
        .execute(p)
        .await?
        .rows_affected());
        Ok(())
    }

    /// Records `id` as the active table (and when), and tells the other replicas.
    pub async fn record_activation(&self, id: &str, now: i64) -> Result<(), StoreError> {
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
    pub async fn recorded_active(&self) -> Result<Option<String>, StoreError> {
        Ok(on_pool!(self, p => sqlx::query_scalar(
            "SELECT value FROM settings WHERE key = 'active_table'",
        )
        .fetch_optional(p)
        .await?))
    }

    /// Healthy tables' ids and metadata (JSON), newest first.
    pub async fn usable_tables_newest_first(&self) -> Result<Vec<(String, String)>, StoreError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, (String, String)>(
            "SELECT id, meta_json FROM l3_tables WHERE status = $1 ORDER BY created_at DESC, id",
        )
        .bind(TableStatus::Ok.as_str())
        .fetch_all(p)
        .await?))
    }

    /// Healthy tables, most recently activated first, then the newest.
    pub async fn usable_tables_by_recency(&self) -> Result<Vec<String>, StoreError> {
        Ok(on_pool!(self, p => sqlx::query_scalar(
            "SELECT id FROM l3_tables WHERE status = $1
             ORDER BY (last_activated_at IS NULL), last_activated_at DESC, created_at DESC, id",
        )
        .bind(TableStatus::Ok.as_str())
        .fetch_all(p)
        .await?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn new_table(id: &str) -> NewTable<'_> {
        NewTable {
            id,
            path: "t.safetensors",
            sha256: "h",
            size_bytes: 4,
            kind: "SI",
            meta_json: "{}",
            job_id: None,
            created_at: 1,
            content: None,
        }
    }

    #[tokio::test]
    async fn tables_record_their_health_and_the_active_one() {
        let dir = tempfile::tempdir().unwrap();
        let s = Store::connect("", dir.path()).await.unwrap();
        s.insert_table(&new_table("a")).await.unwrap();
        s.insert_table(&NewTable {
            created_at: 2,
            ..new_table("b")
        })
        .await
        .unwrap();
        assert_eq!(s.existing_table("a").await.unwrap().status, TableStatus::Ok);
        let e = s.existing_table("c").await.unwrap_err();
        assert_eq!(e.to_string(), "no table with id 'c'");
        s.set_table_status("b", TableStatus::Corrupt, Some("bad"))
            .await
            .unwrap();
        let b = s.existing_table("b").await.unwrap();
        assert_eq!(
            (b.status, b.status_detail.as_deref()),
            (TableStatus::Corrupt, Some("bad"))
        );
        assert_eq!(s.usable_tables_by_recency().await.unwrap(), vec!["a"]);
        assert_eq!(s.recorded_active().await.unwrap(), None);
        s.record_activation("a", 7).await.unwrap();
        assert_eq!(s.recorded_active().await.unwrap().as_deref(), Some("a"));
        assert_eq!(
            s.existing_table("a").await.unwrap().last_activated_at,
            Some(7)
        );
        let ids: Vec<String> = s
            .tables_newest_first()
            .await
            .unwrap()
            .into_iter()
            .map(|t| t.id)
            .collect();
        assert_eq!(ids, ["b", "a"]);
        assert_eq!(s.table_content("a").await.unwrap(), None);
        s.close().await;
    }
}
