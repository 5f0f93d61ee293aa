//! Shared state of a running service: database, illuminant registry, the active table, the
//! fused-kernel cache, render slots, metrics and the job runner's handles.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};

use arc_swap::ArcSwapOption;
use sha2::{Digest, Sha256};
use tokio::sync::{Notify, Semaphore};

use super::ServiceError;
use super::config::ServiceConfig;
use super::metrics::Metrics;
use super::store::{IlluminantRow, Store};
use crate::l3::L3Table;
use crate::l3::correct::{IlluminantEntry, IlluminantRegistry};
use crate::pipeline::{KernelChoice, KernelKey, PipelineError, RenderPipeline};
use crate::spectral::IsetData;

/// The table renders use, with its id. Renders hold an `Arc` of it, so an activation never
/// pulls a table from under a render in flight.
#[derive(Debug)]
pub struct ActiveTable {
    pub id: String,
    pub sha256: String,
    pub table: L3Table,
}

/// Prepared renderers by table id and [`KernelKey`] (made by the kernel selection itself, so
/// the key names everything a renderer depends on besides its table).
pub type KernelCache = HashMap<(String, KernelKey), Arc<RenderPipeline>>;

/// Everything the handlers share (cheap to clone).
#[derive(Clone)]
pub struct AppState(pub Arc<Inner>);

impl std::ops::Deref for AppState {
    type Target = Inner;
    fn deref(&self) -> &Inner {
        &self.0
    }
}

/// The shared state behind [`AppState`].
pub struct Inner {
    pub config: ServiceConfig,
    pub store: Store,
    /// This replica's name in job leases: stable across restarts of the same data directory
    /// on the same host, so a restart re-queues what its previous run left running.
    pub replica_id: String,
    /// The user illuminants the registry was last built from (to notice changes other
    /// replicas made).
    pub illuminant_rows: Mutex<Vec<IlluminantRow>>,
    pub iset: Option<IsetData>,
    /// The built-in illuminants (D65, D50, A, F2, F11 and the ISET lights).
    pub default_registry: IlluminantRegistry,
    /// Built-ins plus the user's illuminants from the database.
    pub registry: Mutex<IlluminantRegistry>,
    /// Lights computed for requests (`cct:K`, `xy:x,y`, a DNG's or an estimated light): a
    /// bounded cache kept out of the public registry.
    pub computed_lights: Mutex<IlluminantRegistry>,
    /// Held by every change to the registry (PUT, DELETE) from reading it
    /// to swapping in the result, so that changes apply one after another.
    pub registry_writes: tokio::sync::Mutex<()>,
    pub active: ArcSwapOption<ActiveTable>,
    /// Prepared renderers per (table id, kernel key).
    pub kernel_cache: Mutex<KernelCache>,
    /// Tables other than the active one, loaded on demand, bounded by bytes.
    pub tables: super::table_cache::TableCache<ActiveTable>,
    /// Admission of renders: the body budget, the queue and the render slots.
    pub admission: super::admission::Admission,
    /// Execution: renders running on rayon at once (FIFO); the rest of the admitted wait.
    pub cpu_gate: Arc<Semaphore>,
    /// The render pool and the background (training, evaluation) pool.
    pub pools: super::cpu::CpuPools,
    /// Admission of evaluations (each simulates and renders a chart); excess gets 503.
    pub eval_slots: Arc<Semaphore>,
    pub metrics: Metrics,
    pub tables_dir: PathBuf,
    /// Wakes the job workers when a job is queued.
    pub job_notify: Notify,
    /// Cancel flags of the running jobs.
    pub running_jobs: Mutex<HashMap<String, Arc<AtomicBool>>>,
    /// The training run this replica prepared last, by its sharded job's id: the shards of a
    /// job that run here share it.
    pub training_run: Mutex<Option<(String, Arc<crate::l3::learn::TrainingRun>)>>,
    pub shutting_down: AtomicBool,
    pub shutdown_notify: Notify,
}

/// Largest number of cached fused-kernel sets (each is the size of a table's kernels).
const KERNEL_CACHE_ENTRIES: usize = 32;

/// Largest number of computed lights kept beyond the built-ins (then the cache starts anew).
const COMPUTED_LIGHTS: usize = 256;

impl Inner {
    /// Locks the registry (a poisoned lock is still usable: the registry has no invariants a
    /// panic could break half-way).
    pub fn registry(&self) -> std::sync::MutexGuard<'_, IlluminantRegistry> {
        self.registry.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Resolves a render's illuminant: a registered name, `cct:K`, `xy:x,y` (the CCT of that
    /// chromaticity), or a CIE standard illuminant name. Files (`csv:`) and `iset:` paths are
    /// refused over HTTP, and so is a light given by its samples (`spd:`), which training and
    /// evaluations take ([`Self::resolve_light`]).
    pub fn resolve_illuminant(&self, spec: &str) -> Result<IlluminantEntry, ServiceError> {
        let spec = spec.trim();
        if spec.to_ascii_lowercase().starts_with("spd:") && self.registry().get(spec).is_none() {
            let name = spec
                .get(4..)
                .and_then(|r| r.rsplit_once(':'))
                .map(|(n, _)| n);
            return Err(ServiceError::UnknownIlluminant(format!(
                "illuminant 'spd:{}:…': a light given by its samples is taken by training jobs and evaluations; register it (PUT /v1/illuminants/{{name}} with \"spd\") to render with it",
                name.unwrap_or_default()
            )));
        }
        self.resolve_light(spec)
    }

    /// Whether [`Self::resolve_illuminant`] answers `spec` from what the service holds,
    /// without fitting a correction (a fit takes ~0.1 s of CPU: callers on the async runtime
    /// send the resolve to a pool when this is false).
    pub fn holds_light(&self, spec: &str) -> bool {
        let spec = spec.trim();
        self.registry().holds(spec)
            || self
                .computed_lights
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .holds(spec)
    }

    /// [`Self::resolve_illuminant`] that also takes a light given by its samples (`spd:`),
    /// whose correction is fitted each time: blocking, for the background pool.
    pub fn resolve_light(&self, spec: &str) -> Result<IlluminantEntry, ServiceError> {
        let spec = spec.trim();
        let unknown = |why: String| {
            // the core's own list of names offers files, which HTTP refuses: the registry's
            // names stand in its place
            let why = why.split(" (known:").next().unwrap_or_default();
            let names: Vec<String> = self.registry().entries().map(|e| e.name.clone()).collect();
            ServiceError::UnknownIlluminant(format!(
                "illuminant '{spec}': {why}; use a registered name ({}), cct:K or xy:x,y",
                names.join(", ")
            ))
        };
        let lower = spec.to_ascii_lowercase();
        if lower.starts_with("csv:") || lower.starts_with("iset:") {
            return Err(unknown(
                "file-based illuminant specs are not accepted over HTTP".into(),
            ));
        }
        if let Some(e) = self.registry().get(spec) {
            return Ok(e.clone());
        }
        // computed lights are cached apart: the public registry holds built-ins and the
        // user's lights only, whatever renders asked for
        let mut computed = self
            .computed_lights
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        if computed.len() > self.default_registry.len() + COMPUTED_LIGHTS {
            *computed = self.default_registry.clone();
        }
        computed
            .resolve(spec, self.iset.as_ref())
            .map_err(|e| unknown(e.to_string()))
    }

    /// The renderer for `active` under the kernel selection `choice`, cached per (table,
    /// [`KernelKey`]) when `keep` (the table is held: active, or in the table cache).
    pub fn renderer_for(
        &self,
        active: &ActiveTable,
        choice: &KernelChoice<'_>,
        keep: bool,
    ) -> Result<Arc<RenderPipeline>, ServiceError> {
        let key = (active.id.clone(), choice.key().clone());
        if keep
            && let Some(k) = self
                .kernel_cache
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .get(&key)
        {
            return Ok(k.clone());
        }
        let table_fault = |e| ServiceError::Internal(format!("table {}: {e}", active.id));
        let kernels = choice.kernels(self.iset.as_ref()).map_err(|e| match e {
            PipelineError::Kernels(e) => table_fault(e),
            e => e.into(),
        })?;
        let r = Arc::new(RenderPipeline::prepare(&active.table, &kernels).map_err(table_fault)?);
        if !keep {
            return Ok(r);
        }
        let mut cache = self.kernel_cache.lock().unwrap_or_else(|p| p.into_inner());
        if cache.len() >= KERNEL_CACHE_ENTRIES {
            cache.clear();
        }
        cache.insert(key, r.clone());
        Ok(r)
    }

    /// Drops the prepared renderers of tables evicted from the table cache (unless one is
    /// the active table, whose renderers stay).
    pub fn forget_tables(&self, ids: &[String]) {
        if ids.is_empty() {
            return;
        }
        let active = self.active.load().as_ref().map(|a| a.id.clone());
        self.kernel_cache
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .retain(|(id, _), _| !ids.contains(id) || active.as_deref() == Some(id.as_str()));
    }

    /// Drops cached kernels of an illuminant (after it was redefined or deleted).
    pub fn forget_illuminant(&self, name: &str) {
        let n = name.to_ascii_lowercase();
        self.kernel_cache
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .retain(|(_, key), _| key.light() != Some(n.as_str()));
    }
}

/// A replica id from the host name and the data directory.
pub fn replica_id(data_dir: &std::path::Path) -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|h| h.trim().to_string())
        .unwrap_or_default();
    let dir = std::fs::canonicalize(data_dir).unwrap_or_else(|_| data_dir.to_path_buf());
    let h = Sha256::digest(format!("{host}\0{}", dir.display()).as_bytes());
    let host: String = host
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || *c == '-')
        .take(32)
        .collect();
    format!("{host}-{}", hex::encode(&h[..6]))
}

/// Milliseconds since the Unix epoch.
pub fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// A new unique id with a prefix, e.g. `job_0192f3a4b5c6d7e8`.
pub fn new_id(prefix: &str) -> String {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let h = Sha256::digest(format!("{nanos}:{n}:{}", std::process::id()).as_bytes());
    format!("{prefix}_{}", hex::encode(&h[..8]))
}

/// Hex SHA-256 of bytes.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}
