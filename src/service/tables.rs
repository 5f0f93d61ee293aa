//! Tables: stored as `tables/<id>.safetensors` (written atomically, SHA-256 recorded), listed,
//! described, downloaded and activated (an atomic swap of the table renders use).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::Json;
use axum::body::Body;
use axum::extract::{Path as UrlPath, State};
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde_json::{Value, json};
use sqlx::Row;

use super::ServiceError;
use super::state::{ActiveTable, AppState, Inner, now_ms, sha256_hex};
use crate::l3::L3Table;

/// A table file written to disk.
#[derive(Debug, Clone)]
pub struct StoredTable {
    pub id: String,
    pub path: PathBuf,
    pub sha256: String,
    pub size_bytes: u64,
}

/// Serialises `table`, names it by its content (`tbl_` + 16 hex digits of its SHA-256) and
/// writes it atomically under `dir` (temporary file, fsync, rename). Blocking.
pub fn write_table_file(dir: &Path, table: &L3Table) -> Result<StoredTable, ServiceError> {
    write_table_file_with_pause(dir, table, 0)
}

/// [`write_table_file`] with the fault-injection pause ([`super::debug_hooks`]) between
/// the fsync of the temporary file and the rename. Blocking.
pub(super) fn write_table_file_with_pause(
    dir: &Path,
    table: &L3Table,
    pause_ms: u64,
) -> Result<StoredTable, ServiceError> {
    let bytes = table
        .to_bytes()
        .map_err(|e| ServiceError::Internal(format!("cannot serialise the table: {e}")))?;
    let sha256 = sha256_hex(&bytes);
    let id = format!("tbl_{}", &sha256[..16]);
    let path = dir.join(format!("{id}.safetensors"));
    let tmp = dir.join(format!(".{id}{TMP_SUFFIX}"));
    let werr =
        |e: std::io::Error| ServiceError::Internal(format!("cannot write {}: {e}", path.display()));
    {
        let mut f = std::fs::File::create(&tmp).map_err(werr)?;
        f.write_all(&bytes).map_err(werr)?;
        f.sync_all().map_err(werr)?;
    }
    if pause_ms > 0 {
        tracing::warn!(
            table = id,
            "fault injection: temporary table file written, pausing {pause_ms} ms before the rename"
        );
        std::thread::sleep(std::time::Duration::from_millis(pause_ms));
    }
    std::fs::rename(&tmp, &path).map_err(werr)?;
    // make the rename itself durable
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(StoredTable {
        id,
        path,
        sha256,
        size_bytes: bytes.len() as u64,
    })
}

/// Suffix of the temporary files [`write_table_file`] renames into place.
const TMP_SUFFIX: &str = ".safetensors.tmp";

/// Removes temporary table files left by a crash between write and rename (at start, before
/// any job runs); returns how many. Blocking.
pub fn remove_orphan_temp_files(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut n = 0;
    for e in entries.flatten() {
        let name = e.file_name();
        let name = name.to_string_lossy();
        if name.starts_with('.') && name.ends_with(TMP_SUFFIX) {
            match std::fs::remove_file(e.path()) {
                Ok(()) => {
                    tracing::warn!(
                        "removed {}: a table file left half-written by an interrupted run",
                        e.path().display()
                    );
                    n += 1;
                }
                Err(err) => tracing::error!("cannot remove {}: {err}", e.path().display()),
            }
        }
    }
    n
}

/// Records a stored table in the database (idempotent: the id is the content hash).
pub async fn insert_table(
    state: &Inner,
    stored: &StoredTable,
    table: &L3Table,
    job_id: Option<&str>,
) -> Result<(), ServiceError> {
    let meta = serde_json::to_string(&table.meta)
        .map_err(|e| ServiceError::Internal(format!("table metadata: {e}")))?;
    sqlx::query(
        "INSERT INTO l3_tables (id, path, sha256, size_bytes, kind, meta_json, job_id, created_at)
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8) ON CONFLICT (id) DO NOTHING",
    )
    .bind(&stored.id)
    .bind(
        stored
            .path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default(),
    )
    .bind(&stored.sha256)
    .bind(stored.size_bytes as i64)
    .bind(table.meta.kind.to_string())
    .bind(meta)
    .bind(job_id)
    .bind(now_ms())
    .execute(&state.db)
    .await?;
    Ok(())
}

async fn table_row(state: &Inner, id: &str) -> Result<sqlx::sqlite::SqliteRow, ServiceError> {
    sqlx::query("SELECT * FROM l3_tables WHERE id = $1")
        .bind(id)
        .fetch_optional(&state.db)
        .await?
        .ok_or_else(|| ServiceError::NotFound(format!("no table with id '{id}'")))
}

/// Why a stored table file cannot be used.
#[derive(Debug)]
pub(super) enum TableFileError {
    /// The file is gone.
    Missing(String),
    /// The file's bytes differ from the recorded checksum, or do not parse as a table.
    Corrupt(String),
    /// Any other I/O failure (permissions, …): not the file's fault.
    Io(String),
}

impl TableFileError {
    fn status(&self) -> Option<&'static str> {
        match self {
            TableFileError::Missing(_) => Some("missing"),
            TableFileError::Corrupt(_) => Some("corrupt"),
            TableFileError::Io(_) => None,
        }
    }

    fn message(&self) -> &str {
        match self {
            TableFileError::Missing(m) | TableFileError::Corrupt(m) | TableFileError::Io(m) => m,
        }
    }
}

/// Reads a table file and checks it against its recorded checksum. Blocking.
fn read_checked(path: &Path, sha256: &str) -> Result<(Vec<u8>, L3Table), TableFileError> {
    let bytes = std::fs::read(path).map_err(|e| {
        let m = format!("cannot read table file {}: {e}", path.display());
        if e.kind() == std::io::ErrorKind::NotFound {
            TableFileError::Missing(m)
        } else {
            TableFileError::Io(m)
        }
    })?;
    let actual = sha256_hex(&bytes);
    if actual != sha256 {
        return Err(TableFileError::Corrupt(format!(
            "table file {} is corrupt: its SHA-256 is {actual}, {sha256} was recorded when it was stored",
            path.display()
        )));
    }
    let table = L3Table::from_bytes(&bytes, &path.display().to_string()).map_err(|e| {
        TableFileError::Corrupt(format!("table file {} does not parse: {e}", path.display()))
    })?;
    Ok((bytes, table))
}

/// Records a table's file health (`ok`, `corrupt` or `missing`) when it changed.
async fn set_status(
    state: &Inner,
    id: &str,
    status: &str,
    detail: Option<&str>,
) -> Result<(), ServiceError> {
    sqlx::query(
        "UPDATE l3_tables SET status = $1, status_detail = $2
         WHERE id = $3 AND (status <> $1 OR status_detail IS NOT $2)",
    )
    .bind(status)
    .bind(detail)
    .bind(id)
    .execute(&state.db)
    .await?;
    Ok(())
}

/// Loads table `id` with its checksum verified. A corrupt or missing file is recorded in the
/// table's status and refused with 409 (the table cannot be used until its file is restored);
/// a file that verifies again is marked `ok` again.
pub(super) async fn load_verified(
    state: &Inner,
    id: &str,
) -> Result<(Vec<u8>, L3Table, String, String), ServiceError> {
    let row = table_row(state, id).await?;
    let file: String = row.try_get("path")?;
    let sha: String = row.try_get("sha256")?;
    let path = state.tables_dir.join(&file);
    let sha2 = sha.clone();
    let loaded = tokio::task::spawn_blocking(move || read_checked(&path, &sha2))
        .await
        .map_err(|e| ServiceError::Internal(format!("table loader: {e}")))?;
    match loaded {
        Ok((bytes, table)) => {
            set_status(state, id, "ok", None).await?;
            Ok((bytes, table, sha, file))
        }
        Err(e) => {
            if let Some(st) = e.status() {
                tracing::error!(table = id, "{}; the table is marked {st}", e.message());
                set_status(state, id, st, Some(e.message())).await?;
                Err(ServiceError::Conflict(format!(
                    "table '{id}' cannot be used: {}",
                    e.message()
                )))
            } else {
                Err(ServiceError::Internal(e.message().to_string()))
            }
        }
    }
}

/// Checks every stored table file against its checksum (at start) and records each one's
/// status; returns the ids found unusable, with the reason. Blocking reads run off the runtime.
pub async fn verify_all(state: &Inner) -> Result<Vec<(String, String)>, ServiceError> {
    let rows = sqlx::query("SELECT id, path, sha256 FROM l3_tables ORDER BY created_at, id")
        .fetch_all(&state.db)
        .await?;
    let mut bad = Vec::new();
    for r in rows {
        let id: String = r.try_get("id")?;
        let path = state.tables_dir.join(r.try_get::<String, _>("path")?);
        let sha: String = r.try_get("sha256")?;
        let checked = tokio::task::spawn_blocking(move || read_checked(&path, &sha).map(|_| ()))
            .await
            .map_err(|e| ServiceError::Internal(format!("table check: {e}")))?;
        match checked {
            Ok(()) => set_status(state, &id, "ok", None).await?,
            Err(e) => {
                if let Some(st) = e.status() {
                    tracing::error!(
                        table = id,
                        "{}; the table is marked {st} and will not be used (restore the file to use it again)",
                        e.message()
                    );
                    set_status(state, &id, st, Some(e.message())).await?;
                } else {
                    tracing::error!(table = id, "{}", e.message());
                }
                bad.push((id, e.message().to_string()));
            }
        }
    }
    Ok(bad)
}

/// Loads table `id` (checksum verified) and makes it the one renders use; records the choice
/// (and the activation time, so a start can fall back to the last good table).
pub async fn activate_table(state: &AppState, id: &str) -> Result<(), ServiceError> {
    let (_, table, sha, _) = load_verified(state, id).await?;
    if table.meta.grid != *state.default_registry.grid() {
        return Err(ServiceError::Unprocessable(format!(
            "table '{id}' uses a wavelength grid other than the service's"
        )));
    }
    let pause = super::debug_hooks::activation_pause_ms();
    if pause > 0 && state.active.load().is_some() {
        tracing::warn!(
            table = id,
            "fault injection: table verified, pausing {pause} ms before recording it as active"
        );
        tokio::time::sleep(std::time::Duration::from_millis(pause)).await;
    }
    let mut tx = state.db.begin().await?;
    sqlx::query(
        "INSERT INTO settings (key, value) VALUES ('active_table', $1)
         ON CONFLICT (key) DO UPDATE SET value = excluded.value",
    )
    .bind(id)
    .execute(&mut *tx)
    .await?;
    sqlx::query("UPDATE l3_tables SET last_activated_at = $1 WHERE id = $2")
        .bind(now_ms())
        .bind(id)
        .execute(&mut *tx)
        .await?;
    tx.commit().await?;
    state.active.store(Some(Arc::new(ActiveTable {
        id: id.to_string(),
        sha256: sha,
        table,
    })));
    tracing::info!(table = id, "table activated");
    Ok(())
}

/// The id recorded as active, if any.
pub async fn recorded_active(state: &Inner) -> Result<Option<String>, ServiceError> {
    Ok(
        sqlx::query("SELECT value FROM settings WHERE key = 'active_table'")
            .fetch_optional(&state.db)
            .await?
            .map(|r| r.try_get::<String, _>("value"))
            .transpose()?,
    )
}

fn row_json(
    state: &Inner,
    row: &sqlx::sqlite::SqliteRow,
    full: bool,
) -> Result<Value, ServiceError> {
    let id: String = row.try_get("id")?;
    let meta: Value = serde_json::from_str(&row.try_get::<String, _>("meta_json")?)
        .map_err(|e| ServiceError::Internal(format!("stored metadata of {id}: {e}")))?;
    let active = state.active.load().as_ref().is_some_and(|a| a.id == id);
    let mut v = json!({
        "id": id,
        "kind": row.try_get::<String, _>("kind")?,
        "sha256": row.try_get::<String, _>("sha256")?,
        "size_bytes": row.try_get::<i64, _>("size_bytes")?,
        "job_id": row.try_get::<Option<String>, _>("job_id")?,
        "created_at_ms": row.try_get::<i64, _>("created_at")?,
        "active": active,
        "status": row.try_get::<String, _>("status")?,
        "status_detail": row.try_get::<Option<String>, _>("status_detail")?,
        "last_activated_at_ms": row.try_get::<Option<i64>, _>("last_activated_at")?,
        "train_illuminants": meta["train_illuminants"].clone(),
        "sensor_name": meta["sensor_name"].clone(),
        "training_seconds": meta["training_seconds"].clone(),
        "links": {
            "self": format!("/v1/tables/{id}"),
            "download": format!("/v1/tables/{id}/download"),
            "activate": format!("/v1/tables/{id}/activate"),
        },
    });
    if full {
        v["training_report"] = meta["summary"].clone();
        v["meta"] = meta;
    }
    Ok(v)
}

/// `GET /v1/tables`
pub async fn list(State(state): State<AppState>) -> Result<Json<Value>, ServiceError> {
    let rows = sqlx::query("SELECT * FROM l3_tables ORDER BY created_at DESC, id")
        .fetch_all(&state.db)
        .await?;
    let items = rows
        .iter()
        .map(|r| row_json(&state, r, false))
        .collect::<Result<Vec<_>, _>>()?;
    let active = state.active.load().as_ref().map(|a| a.id.clone());
    Ok(Json(json!({ "items": items, "active_table_id": active })))
}

/// `GET /v1/tables/{id}`
pub async fn get(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    let row = table_row(&state, &id).await?;
    Ok(Json(row_json(&state, &row, true)?))
}

/// `GET /v1/tables/{id}/download`
pub async fn download(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Response, ServiceError> {
    let (bytes, _, sha, file) = load_verified(&state, &id).await?;
    let mut resp = Body::from(bytes).into_response();
    let h = resp.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/octet-stream"),
    );
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{file}\"")) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    if let Ok(v) = HeaderValue::from_str(&sha) {
        h.insert("x-content-sha256", v);
    }
    Ok(resp)
}

/// `POST /v1/tables/{id}/activate`
pub async fn activate(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    activate_table(&state, &id).await?;
    let row = table_row(&state, &id).await?;
    Ok(Json(row_json(&state, &row, false)?))
}
