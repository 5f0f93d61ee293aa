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
    let bytes = table
        .to_bytes()
        .map_err(|e| ServiceError::Internal(format!("cannot serialise the table: {e}")))?;
    let sha256 = sha256_hex(&bytes);
    let id = format!("tbl_{}", &sha256[..16]);
    let path = dir.join(format!("{id}.safetensors"));
    let tmp = dir.join(format!(".{id}.safetensors.tmp"));
    let werr =
        |e: std::io::Error| ServiceError::Internal(format!("cannot write {}: {e}", path.display()));
    {
        let mut f = std::fs::File::create(&tmp).map_err(werr)?;
        f.write_all(&bytes).map_err(werr)?;
        f.sync_all().map_err(werr)?;
    }
    std::fs::rename(&tmp, &path).map_err(werr)?;
    Ok(StoredTable {
        id,
        path,
        sha256,
        size_bytes: bytes.len() as u64,
    })
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

/// Reads a table file and checks it against its recorded checksum. Blocking.
fn read_checked(path: &Path, sha256: &str) -> Result<(Vec<u8>, L3Table), ServiceError> {
    let bytes = std::fs::read(path).map_err(|e| {
        ServiceError::Internal(format!("cannot read table file {}: {e}", path.display()))
    })?;
    let actual = sha256_hex(&bytes);
    if actual != sha256 {
        return Err(ServiceError::Internal(format!(
            "table file {} is corrupt: SHA-256 {actual}, {sha256} recorded",
            path.display()
        )));
    }
    let table = L3Table::from_bytes(&bytes, &path.display().to_string())
        .map_err(|e| ServiceError::Internal(e.to_string()))?;
    Ok((bytes, table))
}

/// Loads table `id` (checksum verified) and makes it the one renders use; records the choice.
pub async fn activate_table(state: &AppState, id: &str) -> Result<(), ServiceError> {
    let row = table_row(state, id).await?;
    let file: String = row.try_get("path")?;
    let sha: String = row.try_get("sha256")?;
    let path = state.tables_dir.join(file);
    let sha2 = sha.clone();
    let (_, table) = tokio::task::spawn_blocking(move || read_checked(&path, &sha2))
        .await
        .map_err(|e| ServiceError::Internal(format!("table loader: {e}")))??;
    if table.meta.grid != *state.default_registry.grid() {
        return Err(ServiceError::Unprocessable(format!(
            "table '{id}' uses a wavelength grid other than the service's"
        )));
    }
    sqlx::query(
        "INSERT INTO settings (key, value) VALUES ('active_table', $1)
         ON CONFLICT (key) DO UPDATE SET value = excluded.value",
    )
    .bind(id)
    .execute(&state.db)
    .await?;
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
    let row = table_row(&state, &id).await?;
    let file: String = row.try_get("path")?;
    let sha: String = row.try_get("sha256")?;
    let path = state.tables_dir.join(&file);
    let sha2 = sha.clone();
    let (bytes, _) = tokio::task::spawn_blocking(move || read_checked(&path, &sha2))
        .await
        .map_err(|e| ServiceError::Internal(format!("table reader: {e}")))??;
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
