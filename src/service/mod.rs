//! The render service over HTTP (docs/design.md §8): render, training jobs, tables, illuminants,
//! ΔE evaluations, health, metrics and the OpenAPI document. It depends on the numeric core;
//! the core knows nothing of it. CPU work runs on rayon, never on the async runtime's threads.

mod accept;
mod admission;
mod colorchecker;
mod config;
mod console;
mod cpu;
pub(crate) mod error;
mod evaluations;
#[cfg(feature = "fault-injection")]
pub mod fault_injection;
mod illuminants;
mod jobs;
mod metrics;
mod render;
mod routes;
mod sensors;
mod state;
pub mod store;
mod sync;
mod table_cache;
mod table_choice;
mod tables;

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use arc_swap::ArcSwapOption;
use tokio::sync::{Notify, Semaphore};

pub use admission::Admission;
pub use config::{
    ConfigFlags, DEFAULT_CONFIG_TOML, DataConfig, ServerConfig, ServiceConfig, TablesConfig,
    TrainingConfig,
};
pub use error::ServiceError;
// what the fuzz bodies (`crate::fuzzing`, test support only) run as the service does
pub use accept::negotiate;
#[cfg(feature = "test-support")]
pub(crate) use illuminants::{IlluminantDefinition, apply as apply_illuminant};
#[cfg(feature = "test-support")]
pub(crate) use jobs::parse_job_request;
#[cfg(feature = "test-support")]
pub(crate) use render::RenderQuery;
pub use routes::{OPENAPI_YAML, ROUTES};
pub use state::{ActiveTable, AppState, Inner, sha256_hex};
pub use store::{JobStatus, Store};
pub use tables::{StoredTable, write_table_file};

use crate::l3::L3Table;
use crate::l3::correct::IlluminantRegistry;
use crate::l3::learn::TrainingSpec;
use crate::spectral::{IsetData, WavelengthGrid};

/// Evaluations running at once; more get 503 with Retry-After.
const EVALUATION_SLOTS: usize = 2;

/// A running server: its address, and a handle to stop it.
pub struct Server {
    addr: SocketAddr,
    state: AppState,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<Result<(), ServiceError>>,
    workers: Vec<tokio::task::JoinHandle<()>>,
}

impl Server {
    /// The bound address (useful with port 0).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The shared state (for tests and embedding).
    pub fn state(&self) -> &AppState {
        &self.state
    }

    /// Graceful shutdown: stop accepting, let in-flight requests finish, interrupt the running
    /// training jobs (they are re-queued and resume at the next start).
    pub async fn shutdown(mut self) -> Result<(), ServiceError> {
        begin_shutdown(&self.state);
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        for w in self.workers.drain(..) {
            let _ = w.await;
        }
        self.task
            .await
            .map_err(|e| ServiceError::Internal(format!("server task: {e}")))?
    }

    /// Runs until the server stops (after `begin_shutdown` or a signal given to `start_with`).
    pub async fn wait(mut self) -> Result<(), ServiceError> {
        let r = (&mut self.task)
            .await
            .map_err(|e| ServiceError::Internal(format!("server task: {e}")))?;
        begin_shutdown(&self.state);
        for w in self.workers.drain(..) {
            let _ = w.await;
        }
        r
    }
}

fn begin_shutdown(state: &AppState) {
    state.shutting_down.store(true, Ordering::SeqCst);
    state.shutdown_notify.notify_waiters();
    for f in state
        .running_jobs
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .values()
    {
        f.store(true, Ordering::SeqCst);
    }
}

/// The default table's training spec: the config's `[training.default_spec]` fields over the
/// TrainingSpec defaults, with the SI ensemble D65 + Tungsten + Fluorescent when no illuminants
/// are given, and a new spec's defaults ([`crate::l3::learn::new_spec_defaults`]: chroma
/// classes, the texture classes' colour maps) for the fields it does not name.
pub fn default_training_spec(cfg: &ServiceConfig) -> Result<TrainingSpec, ServiceError> {
    let mut t = cfg.training.default_spec.clone();
    if !t.contains_key("illuminants") {
        let ills: Vec<toml::Value> = ["D65", "Tungsten", "Fluorescent"]
            .iter()
            .map(|s| toml::Value::String(s.to_string()))
            .collect();
        t.insert("illuminants".into(), toml::Value::Array(ills));
    }
    for (key, value) in crate::l3::learn::new_spec_defaults() {
        if !t.contains_key(key) {
            let v = toml::Value::try_from(value)
                .map_err(|e| ServiceError::Internal(format!("default {key}: {e}")))?;
            t.insert(key.into(), v);
        }
    }
    let spec: TrainingSpec = toml::Value::Table(t)
        .try_into()
        .map_err(|e| ServiceError::Config(format!("[training.default_spec]: {e}")))?;
    spec.validate()
        .map_err(|e| ServiceError::Config(format!("[training.default_spec]: {e}")))?;
    Ok(spec)
}

/// The ISET data directory over the built-in spectral data: the config's, else a located one;
/// `None`: the built-in data alone. A configured directory that cannot be read is logged and
/// the service starts on the built-in data (the tests pin the built-in data so).
fn locate_iset(cfg: &ServiceConfig) -> Option<IsetData> {
    if let Some(d) = &cfg.data.iset_dir {
        match IsetData::at(d) {
            Ok(i) => return Some(i),
            Err(e) => {
                tracing::warn!("ISET data at {}: {e}; using the built-in data", d.display());
                return None;
            }
        }
    }
    IsetData::locate()
}

/// Starts the service: data dir, database and migrations, illuminants, the active table (or
/// the default table's training job, once per database), job workers, the follower of changes
/// made through other replicas, and the HTTP listener. `signal` ends the
/// server gracefully when it completes (in addition to [`Server::shutdown`]).
pub async fn start_with(
    cfg: ServiceConfig,
    signal: impl std::future::Future<Output = ()> + Send + 'static,
) -> Result<Server, ServiceError> {
    // the address first: a start that cannot listen changes nothing in the data directory
    // or the database (connections made before the router runs wait in the backlog)
    let listener = tokio::net::TcpListener::bind(cfg.server.bind)
        .await
        .map_err(|source| ServiceError::Bind {
            addr: cfg.server.bind,
            source,
        })?;
    let (state, default_spec) = open_state(&cfg).await?;
    illuminants::load_registry(&state).await?;
    let requeued = jobs::requeue_interrupted(&state).await?;
    if requeued > 0 {
        tracing::info!("{requeued} interrupted training job(s) re-queued");
    }
    activate_stored_table(&state).await?;
    if state.active.load().is_none() && cfg.training.auto_train_default {
        queue_default_table(&state, &default_spec).await?;
    }
    let mut workers: Vec<_> = (0..cfg.training.max_concurrent_jobs)
        .map(|_| tokio::spawn(jobs::worker(state.clone())))
        .collect();
    workers.push(tokio::spawn(sync::follower(state.clone())));
    let addr = listener
        .local_addr()
        .map_err(|e| ServiceError::Internal(format!("local address: {e}")))?;
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let task = serve(listener, state.clone(), async move {
        tokio::select! {
            _ = rx => {}
            _ = signal => {}
        }
    });
    tracing::info!("l3 service listening on http://{addr}");
    Ok(Server {
        addr,
        state,
        shutdown: Some(tx),
        task,
        workers,
    })
}

/// The state of a starting service: its data directory's `tables/`, the database (migrated),
/// the spectral data, the built-in illuminants and the CPU pools; and the default table's
/// training spec.
async fn open_state(cfg: &ServiceConfig) -> Result<(AppState, TrainingSpec), ServiceError> {
    let data = cfg.data.dir.clone();
    let tables_dir = data.join("tables");
    std::fs::create_dir_all(&tables_dir).map_err(|e| {
        ServiceError::Config(format!("cannot create {}: {e}", tables_dir.display()))
    })?;
    let store = Store::connect(&cfg.data.database_url, &data).await?;
    let replica_id = state::replica_id(&data);
    tracing::info!(
        backend = store.backend(),
        replica = replica_id,
        "database ready"
    );
    let iset = locate_iset(cfg);
    // problem details and job errors name no directory of the server (the log does)
    error::hide_server_dir(&data);
    if let Some(d) = iset.as_ref().and_then(IsetData::dir) {
        error::hide_server_dir(d);
    }
    match iset.as_ref().and_then(IsetData::dir) {
        Some(d) => tracing::info!(
            "spectral data: the ISET directory {} over the built-in data",
            d.display()
        ),
        None => tracing::info!("spectral data: built in (no ISET data directory)"),
    }
    let grid = WavelengthGrid::default();
    let defaults = IlluminantRegistry::with_defaults(grid, iset.as_ref())
        .map_err(|e| ServiceError::Internal(format!("default illuminants: {e}")))?;
    let default_spec = default_training_spec(cfg)?;
    let pools = cpu::CpuPools::new(
        cfg.server.render_threads,
        cfg.training.background_threads,
        cfg.training.background_priority,
    )?;
    let tables = table_cache::TableCache::new(cfg.tables.cache_bytes);
    let metrics = metrics::Metrics::new(&tables.counters)
        .map_err(|e| ServiceError::Internal(format!("metrics registry: {e}")))?;
    let state = AppState(Arc::new(Inner {
        admission: admission::Admission::new(&cfg.server),
        cpu_gate: Arc::new(Semaphore::new(
            (pools.render.current_num_threads() / 2).max(1),
        )),
        pools,
        eval_slots: Arc::new(Semaphore::new(EVALUATION_SLOTS)),
        config: cfg.clone(),
        store,
        replica_id,
        illuminant_rows: Mutex::new(Vec::new()),
        iset,
        registry: Mutex::new(defaults.clone()),
        computed_lights: Mutex::new(defaults.clone()),
        registry_writes: tokio::sync::Mutex::new(()),
        default_registry: defaults,
        active: ArcSwapOption::empty(),
        kernel_cache: Mutex::new(HashMap::new()),
        tables,
        metrics,
        tables_dir,
        job_notify: Notify::new(),
        running_jobs: Mutex::new(HashMap::new()),
        training_run: Mutex::new(None),
        shutting_down: AtomicBool::new(false),
        shutdown_notify: Notify::new(),
    }));
    Ok((state, default_spec))
}

/// Checks the stored table files and activates the table a start serves: the recorded one,
/// else the last good one (most recently activated, then the newest stored), skipping files
/// found corrupt or missing. Half-written temporary files are removed first.
async fn activate_stored_table(state: &AppState) -> Result<(), ServiceError> {
    let dir = state.tables_dir.clone();
    tokio::task::spawn_blocking(move || tables::remove_orphan_temp_files(&dir))
        .await
        .map_err(|e| ServiceError::Internal(format!("table directory scan: {e}")))?;
    let unusable = tables::verify_all(state).await?;
    let recorded = tables::recorded_active(state).await?;
    for id in tables::activation_candidates(&state.store).await? {
        if unusable.iter().any(|(b, _)| *b == id) {
            continue;
        }
        // the recorded table is served again, not activated anew (its activation time stays)
        let served = if recorded.as_deref() == Some(id.as_str()) {
            tables::serve_table(state, &id).await
        } else {
            tables::activate_table(state, &id).await
        };
        match served {
            Ok(()) => break,
            Err(e) => tracing::error!(table = id, "cannot activate: {e}"),
        }
    }
    if let Some(r) = &recorded
        && let Some((_, why)) = unusable.iter().find(|(b, _)| b == r)
    {
        match state.active.load().as_ref() {
            Some(a) => tracing::error!(
                "the recorded active table {r} is unusable ({why}); serving the last good table {} instead",
                a.id
            ),
            None => tracing::error!(
                "the recorded active table {r} is unusable ({why}) and no other stored table is usable"
            ),
        }
    }
    Ok(())
}

/// Queues the training of the default table (`spec`, activated when done) unless a job that
/// will activate a table is already queued or running: once per database, so that replicas
/// starting together queue one job.
async fn queue_default_table(state: &AppState, spec: &TrainingSpec) -> Result<(), ServiceError> {
    if state.store.pending_activating_job().await?.is_some() {
        return Ok(());
    }
    let mut v = serde_json::to_value(spec)
        .map_err(|e| ServiceError::Internal(format!("default spec: {e}")))?;
    v["activate"] = serde_json::Value::Bool(true);
    if let Some(id) = jobs::enqueue_default(state, &v).await? {
        tracing::info!(
            job = id,
            "no table yet: training the default table ({}); /readyz is 503 until it is active",
            spec.illuminants.join("+")
        );
    }
    Ok(())
}

/// Serves the routes on `listener` until `stop` completes (or the server is shut down), then
/// begins the shutdown.
fn serve(
    listener: tokio::net::TcpListener,
    state: AppState,
    stop: impl std::future::Future<Output = ()> + Send + 'static,
) -> tokio::task::JoinHandle<Result<(), ServiceError>> {
    let app = routes::router(state.clone());
    tokio::spawn(async move {
        axum::serve(listener, app)
            .with_graceful_shutdown(async move {
                stop.await;
                begin_shutdown(&state);
            })
            .await
            .map_err(|e| ServiceError::Internal(format!("server: {e}")))
    })
}

/// [`start_with`] without an external signal.
pub async fn start(cfg: ServiceConfig) -> Result<Server, ServiceError> {
    start_with(cfg, std::future::pending()).await
}

/// The table a service on a data directory serves (see [`served_table`]).
#[derive(Debug)]
pub struct ServedTable {
    pub id: String,
    /// Its file in the data directory's `tables/`.
    pub path: std::path::PathBuf,
    pub table: L3Table,
    /// The candidates passed over before it (a recorded active table whose file is corrupt
    /// or missing, …), each with the reason.
    pub passed_over: Vec<String>,
}

/// The table the service on `cfg`'s data directory and database renders with (what `l3
/// render` uses without `--table`): the recorded active table, else, as a start falls back,
/// the last good one, its file checked against its recorded SHA-256. Reads only; `None` when
/// the data directory has no database (a service never ran there) or no usable table.
pub async fn served_table(cfg: &ServiceConfig) -> Result<Option<ServedTable>, ServiceError> {
    let Some(store) = existing_store(cfg).await? else {
        return Ok(None);
    };
    let served = tables::served_table(&store, &cfg.data.dir.join("tables")).await;
    store.close().await;
    served
}

/// Opens the store of `cfg`'s data directory for reading, `None` when it has no database (a
/// service never ran there).
async fn existing_store(cfg: &ServiceConfig) -> Result<Option<Store>, ServiceError> {
    let url = cfg.data.database_url.trim();
    if url.is_empty() && !cfg.data.dir.join(store::SQLITE_FILE).is_file() {
        return Ok(None);
    }
    Ok(Some(Store::connect(url, &cfg.data.dir).await?))
}

/// The good stored tables of `cfg`'s data directory by the sensor they were trained for,
/// newest first (none without a database): what `l3 sensors` and `l3 render`'s table choice
/// read, as the service's do.
pub async fn stored_tables_in(
    cfg: &ServiceConfig,
) -> Result<crate::pipeline::StoredTables, ServiceError> {
    let Some(store) = existing_store(cfg).await? else {
        return Ok(Default::default());
    };
    let stored = tables::stored_tables(&store).await;
    store.close().await;
    stored
}

/// The stored table `id` of `cfg`'s data directory, its file checked against its recorded
/// SHA-256 (what a render naming it uses). Reads only.
pub async fn stored_table_in(cfg: &ServiceConfig, id: &str) -> Result<ServedTable, ServiceError> {
    let Some(store) = existing_store(cfg).await? else {
        return Err(ServiceError::NotFound(format!(
            "no table with id '{id}': the data directory {} has no database",
            cfg.data.dir.display()
        )));
    };
    let t = tables::stored_table(&store, &cfg.data.dir.join("tables"), id).await;
    store.close().await;
    t
}

/// Stores a table in the service (file written atomically, checksum recorded) and optionally
/// activates it; returns its id. Used to seed a data directory and by tests.
pub async fn import_table(
    state: &AppState,
    table: &L3Table,
    activate: bool,
) -> Result<String, ServiceError> {
    table
        .validate()
        .map_err(|e| ServiceError::Unprocessable(e.to_string()))?;
    let dir = state.tables_dir.clone();
    let t = table.clone();
    let stored = tokio::task::spawn_blocking(move || write_table_file(&dir, &t))
        .await
        .map_err(|e| ServiceError::Internal(format!("table writer: {e}")))??;
    tables::insert_table(state, &stored, table, None).await?;
    if activate {
        tables::activate_table(state, &stored.id).await?;
    }
    Ok(stored.id)
}
