//! Tables: stored as `tables/<id>.safetensors` (written atomically, SHA-256 recorded), listed,
//! described, downloaded and activated (an atomic swap of the table renders use). Where the
//! database keeps the table bytes (PostgreSQL, shared by replicas), the files are a local
//! cache by id and SHA-256: a file missing or damaged is fetched again from the database.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::Json;
use axum::body::Body;
use axum::extract::{Path as UrlPath, State};
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde_json::{Value, json};

use super::ServiceError;
use super::state::{ActiveTable, AppState, Inner, now_ms, sha256_hex};
use super::store::{NewTable, Store, TableRow, TableStatus};
use crate::l3::L3Table;
use crate::pipeline::StoredTables;

/// A table file written to disk.
#[derive(Debug, Clone)]
pub struct StoredTable {
    pub id: String,
    pub path: PathBuf,
    pub sha256: String,
    pub size_bytes: u64,
}

/// Serialises `table`, names it by its content (`tbl_` + 16 hex digits of its SHA-256) and
/// writes it atomically under `dir` ([`crate::io`]'s one routine: temporary file, fsync,
/// rename, fsync of the directory). Blocking.
pub fn write_table_file(dir: &Path, table: &L3Table) -> Result<StoredTable, ServiceError> {
    let bytes = table
        .to_bytes()
        .map_err(|e| ServiceError::Internal(format!("cannot serialise the table: {e}")))?;
    let sha256 = sha256_hex(&bytes);
    let id = format!("tbl_{}", &sha256[..16]);
    let path = dir.join(format!("{id}{TABLE_SUFFIX}"));
    crate::io::write_bytes_atomic_then(&path, &bytes, || {
        #[cfg(feature = "fault-injection")]
        super::fault_injection::pause_before_table_rename(&id);
    })?;
    Ok(StoredTable {
        id,
        path,
        sha256,
        size_bytes: bytes.len() as u64,
    })
}

/// The ending of table files.
const TABLE_SUFFIX: &str = ".safetensors";

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
        if crate::io::is_temp_of(&name, TABLE_SUFFIX) {
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

/// Records a stored table in the database (idempotent: the id is the content hash), with its
/// bytes where the database keeps them.
pub async fn insert_table(
    state: &Inner,
    stored: &StoredTable,
    table: &L3Table,
    job_id: Option<&str>,
) -> Result<(), ServiceError> {
    let meta = serde_json::to_string(&table.meta)
        .map_err(|e| ServiceError::Internal(format!("table metadata: {e}")))?;
    let content = if state.store.keeps_table_bytes() {
        let (path, sha) = (stored.path.clone(), stored.sha256.clone());
        let read = tokio::task::spawn_blocking(move || read_checked(&path, &sha))
            .await
            .map_err(|e| ServiceError::Internal(format!("table reader: {e}")))?;
        Some(
            read.map_err(|e| ServiceError::Internal(e.message().to_string()))?
                .0,
        )
    } else {
        None
    };
    let file = stored
        .path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default();
    Ok(state
        .store
        .insert_table(&NewTable {
            id: &stored.id,
            path: file,
            sha256: &stored.sha256,
            size_bytes: stored.size_bytes as i64,
            kind: &table.meta.kind.to_string(),
            meta_json: &meta,
            job_id,
            created_at: now_ms(),
            content: content.as_deref(),
        })
        .await?)
}

/// The table `id` (404 when there is none).
async fn table_row(state: &Inner, id: &str) -> Result<TableRow, ServiceError> {
    Ok(state.store.existing_table(id).await?)
}

/// Why a stored table file cannot be used.
#[derive(Debug, thiserror::Error)]
pub(super) enum TableFileError {
    /// The file is gone.
    #[error("{0}")]
    Missing(String),
    /// The file's bytes differ from the recorded checksum, or do not parse as a table.
    #[error("{0}")]
    Corrupt(String),
    /// Any other I/O failure (permissions, …): not the file's fault.
    #[error("{0}")]
    Io(String),
}

impl TableFileError {
    fn status(&self) -> Option<TableStatus> {
        match self {
            TableFileError::Missing(_) => Some(TableStatus::Missing),
            TableFileError::Corrupt(_) => Some(TableStatus::Corrupt),
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
    let table = check_bytes(&bytes, sha256, &format!("table file {}", path.display()))?;
    Ok((bytes, table))
}

/// Checks table bytes against their recorded checksum and parses them. Blocking.
fn check_bytes(bytes: &[u8], sha256: &str, what: &str) -> Result<L3Table, TableFileError> {
    let actual = sha256_hex(bytes);
    if actual != sha256 {
        return Err(TableFileError::Corrupt(format!(
            "{what} is corrupt: its SHA-256 is {actual}, {sha256} was recorded when it was stored"
        )));
    }
    L3Table::from_bytes(bytes, what)
        .map_err(|e| TableFileError::Corrupt(format!("{what} does not parse: {e}")))
}

/// A table's bytes, checked: the local file, else (where the database keeps the bytes) the
/// database's copy, which then replaces the local file.
async fn fetch_checked(
    state: &Inner,
    row: &TableRow,
) -> Result<(Vec<u8>, L3Table), TableFileError> {
    fetch_checked_in(&state.store, &state.tables_dir, row).await
}

/// [`fetch_checked`] from `store` and the table files in `tables_dir`.
async fn fetch_checked_in(
    store: &Store,
    tables_dir: &Path,
    row: &TableRow,
) -> Result<(Vec<u8>, L3Table), TableFileError> {
    let path = tables_dir.join(&row.path);
    let sha = row.sha256.clone();
    let local = tokio::task::spawn_blocking(move || read_checked(&path, &sha))
        .await
        .map_err(|e| TableFileError::Io(format!("table loader: {e}")))?;
    let err = match local {
        Ok(v) => return Ok(v),
        Err(e) if !store.keeps_table_bytes() => return Err(e),
        Err(e) => e,
    };
    let bytes = match store.table_content(&row.id).await {
        Ok(Some(b)) => b,
        Ok(None) => return Err(err),
        Err(e) => return Err(TableFileError::Io(format!("table {}: {e}", row.id))),
    };
    let (dir, file, sha) = (
        tables_dir.to_path_buf(),
        row.path.clone(),
        row.sha256.clone(),
    );
    let what = format!("table {} in the database", row.id);
    tokio::task::spawn_blocking(move || {
        let table = check_bytes(&bytes, &sha, &what)?;
        // the local cache file, written with the one atomic routine
        if let Err(e) = crate::io::write_bytes_atomic(&dir.join(&file), &bytes) {
            tracing::warn!("cannot cache {file} in {}: {e}", dir.display());
        }
        Ok((bytes, table))
    })
    .await
    .map_err(|e| TableFileError::Io(format!("table loader: {e}")))?
}

/// Records a table's file health when it changed.
async fn set_status(
    state: &Inner,
    id: &str,
    status: TableStatus,
    detail: Option<&str>,
) -> Result<(), ServiceError> {
    Ok(state.store.set_table_status(id, status, detail).await?)
}

/// Loads table `id` with its checksum verified. A corrupt or missing file is recorded in the
/// table's status and refused with 409 (the table cannot be used until its file is restored);
/// a file that verifies again is marked `ok` again.
pub(super) async fn load_verified(
    state: &Inner,
    id: &str,
) -> Result<(Vec<u8>, L3Table, String, String), ServiceError> {
    let row = table_row(state, id).await?;
    match fetch_checked(state, &row).await {
        Ok((bytes, table)) => {
            set_status(state, id, TableStatus::Ok, None).await?;
            Ok((bytes, table, row.sha256, row.path))
        }
        Err(e) => {
            if let Some(st) = e.status() {
                tracing::error!(table = id, "{}; the table is marked {st}", e.message());
                set_status(state, id, st, Some(e.message())).await?;
                // renders by id stop too (the active table renders on from its verified copy)
                if state.tables.remove(id) {
                    state.forget_tables(&[id.to_string()]);
                }
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
    let rows = state.store.tables_oldest_first().await?;
    let mut bad = Vec::new();
    for r in rows {
        let id = r.id.clone();
        match fetch_checked(state, &r).await.map(|_| ()) {
            Ok(()) => set_status(state, &id, TableStatus::Ok, None).await?,
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

/// The good stored tables by the sensor they were trained for (`meta.sensor_name`), newest
/// first: what the table choice of a render and the sensor listing read. A table counts for a
/// catalogue sensor only when its design (`meta.sensor`) is that sensor's: a design that merely
/// took a catalogue name (before submissions refused it) cannot stand in for a camera.
pub(super) async fn stored_tables(store: &Store) -> Result<StoredTables, ServiceError> {
    #[derive(serde::Deserialize)]
    struct SensorOf {
        sensor_name: String,
        #[serde(default)]
        sensor: serde_json::Value,
    }
    let rows = store.usable_tables_newest_first().await?;
    let mut designs: std::collections::HashMap<String, Option<serde_json::Value>> =
        std::collections::HashMap::new();
    Ok(StoredTables::newest_first(rows.into_iter().filter_map(
        |(id, meta)| {
            let m: SensorOf = serde_json::from_str(&meta).ok()?;
            if let Some(entry) = crate::camera::catalogue::find(&m.sensor_name) {
                let design = designs
                    .entry(entry.name.clone())
                    .or_insert_with(|| catalogue_fingerprint(entry));
                if !design.as_ref().is_some_and(|d| same_design(d, &m.sensor)) {
                    return None;
                }
            }
            Some((m.sensor_name, id))
        },
    )))
}

/// A catalogue sensor's design as a table records it (`meta.sensor`).
fn catalogue_fingerprint(
    entry: &crate::camera::catalogue::CatalogueEntry,
) -> Option<serde_json::Value> {
    serde_json::to_value(entry.design().ok()?).ok()
}

/// Whether two designs as JSON are the same: equal but for the last bits of their numbers (a
/// number written as text and read back may differ in its last bit).
pub(in crate::service) fn same_design(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => match (x.as_f64(), y.as_f64()) {
            (Some(x), Some(y)) => x == y || (x - y).abs() <= 1e-12 * x.abs().max(y.abs()),
            _ => x == y,
        },
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(a, b)| same_design(a, b))
        }
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len()
                && x.iter()
                    .all(|(k, a)| y.get(k).is_some_and(|b| same_design(a, b)))
        }
        (a, b) => a == b,
    }
}

/// The stored table `id` of the data directory `tables_dir` and its `store`, its bytes
/// checked against the recorded SHA-256 (404 when there is none, 409 when its file is
/// corrupt or missing). Reads only.
pub(super) async fn stored_table(
    store: &Store,
    tables_dir: &Path,
    id: &str,
) -> Result<super::ServedTable, ServiceError> {
    let row = store.existing_table(id).await?;
    match fetch_checked_in(store, tables_dir, &row).await {
        Ok((_, table)) => Ok(super::ServedTable {
            id: row.id,
            path: tables_dir.join(&row.path),
            table,
            passed_over: Vec::new(),
        }),
        Err(e @ (TableFileError::Missing(_) | TableFileError::Corrupt(_))) => Err(
            ServiceError::Conflict(format!("table '{id}' cannot be used: {}", e.message())),
        ),
        Err(e) => Err(ServiceError::Internal(e.message().to_string())),
    }
}

/// The ids a start tries to make active, in order: the recorded active table, then the
/// usable ones, most recently activated first, then the newest.
pub(super) async fn activation_candidates(store: &Store) -> Result<Vec<String>, ServiceError> {
    let mut ids: Vec<String> = store.recorded_active().await?.into_iter().collect();
    for id in store.usable_tables_by_recency().await? {
        if !ids.contains(&id) {
            ids.push(id);
        }
    }
    Ok(ids)
}

/// The table a service on `store` and `tables_dir` serves once started: the first of the
/// [`activation_candidates`] whose file (or, where the database keeps them, bytes) verifies
/// against its recorded SHA-256. Nothing is recorded or changed. Returns the table, its id
/// and file, and why each candidate before it was passed over.
pub(super) async fn served_table(
    store: &Store,
    tables_dir: &Path,
) -> Result<Option<super::ServedTable>, ServiceError> {
    let mut passed_over = Vec::new();
    for id in activation_candidates(store).await? {
        let Some(row) = store.table(&id).await? else {
            passed_over.push(format!("{id}: recorded as active but not stored"));
            continue;
        };
        match fetch_checked_in(store, tables_dir, &row).await {
            Ok((_, table)) => {
                return Ok(Some(super::ServedTable {
                    path: tables_dir.join(&row.path),
                    id,
                    table,
                    passed_over,
                }));
            }
            Err(e) => passed_over.push(format!("{id}: {}", e.message())),
        }
    }
    Ok(None)
}

/// Loads table `id` (checksum verified) for activation or for renders that name it.
pub(super) async fn load_usable(state: &Inner, id: &str) -> Result<ActiveTable, ServiceError> {
    let (_, table, sha, _) = load_verified(state, id).await?;
    if table.meta.grid != *state.default_registry.grid() {
        return Err(ServiceError::Unprocessable(format!(
            "table '{id}' uses a wavelength grid other than the service's"
        )));
    }
    Ok(ActiveTable {
        id: id.to_string(),
        sha256: sha,
        table,
    })
}

/// Follows the activation recorded in the database (made through another replica): loads the
/// recorded table when it is not the one renders use. Renders in flight keep theirs.
pub async fn follow_recorded_active(state: &Inner) -> Result<(), ServiceError> {
    let Some(id) = state.store.recorded_active().await? else {
        return Ok(());
    };
    if state.active.load().as_ref().is_some_and(|a| a.id == id) {
        return Ok(());
    }
    let loaded = load_usable(state, &id).await?;
    state.active.store(Some(Arc::new(loaded)));
    tracing::info!(table = id, "table activated (through another replica)");
    Ok(())
}

/// Loads table `id` (checksum verified) and makes it the one renders use; records the choice
/// (and the activation time, so a start can fall back to the last good table) and announces
/// it to the other replicas.
pub async fn activate_table(state: &AppState, id: &str) -> Result<(), ServiceError> {
    let loaded = load_usable(state, id).await?;
    #[cfg(feature = "fault-injection")]
    if state.active.load().is_some() {
        super::fault_injection::pause_before_recording_activation(id).await;
    }
    state.store.record_activation(id, now_ms()).await?;
    state.active.store(Some(Arc::new(loaded)));
    tracing::info!(table = id, "table activated");
    Ok(())
}

/// Loads table `id` (checksum verified) and serves it as the active table without recording
/// an activation: what a start does with the table recorded as active.
pub async fn serve_table(state: &AppState, id: &str) -> Result<(), ServiceError> {
    let loaded = load_usable(state, id).await?;
    state.active.store(Some(Arc::new(loaded)));
    tracing::info!(table = id, "serving the recorded active table");
    Ok(())
}

/// The id recorded as active, if any.
pub async fn recorded_active(state: &Inner) -> Result<Option<String>, ServiceError> {
    Ok(state.store.recorded_active().await?)
}

fn row_json(state: &Inner, row: &TableRow, full: bool) -> Result<Value, ServiceError> {
    let id = &row.id;
    let meta: Value = serde_json::from_str(&row.meta_json)
        .map_err(|e| ServiceError::Internal(format!("stored metadata of {id}: {e}")))?;
    let active = state.active.load().as_ref().is_some_and(|a| a.id == *id);
    let mut v = json!({
        "id": id,
        "kind": row.kind,
        "sha256": row.sha256,
        "size_bytes": row.size_bytes,
        "job_id": row.job_id,
        "created_at_ms": row.created_at,
        "active": active,
        "status": row.status.as_str(),
        "status_detail": row.status_detail.as_deref().map(super::error::without_server_paths),
        "last_activated_at_ms": row.last_activated_at,
        "train_illuminants": meta["train_illuminants"].clone(),
        "train_white_xy": meta.get("train_white_xy").cloned().unwrap_or_else(|| json!([])),
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
    let rows = state.store.tables_newest_first().await?;
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
