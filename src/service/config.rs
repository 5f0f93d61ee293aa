//! Service configuration: `config/default.toml` (embedded), an optional file given with
//! `--config`, then `L3_*` environment variables, each overriding the one before.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::ServiceError;
use crate::io::PngCompression;
use crate::pipeline::{CorrectionMode, RenderOptions};

/// The embedded defaults (the committed `config/default.toml`).
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../config/default.toml");

/// The whole service configuration.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServiceConfig {
    pub server: ServerConfig,
    pub data: DataConfig,
    pub training: TrainingConfig,
    #[serde(default)]
    pub tables: TablesConfig,
}

/// `[tables]`: tables other than the active one, loaded on demand.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TablesConfig {
    /// Bytes of kernels the cache of non-active tables may hold (least recently used first
    /// out); the active table does not count.
    #[serde(default = "default_table_cache_bytes")]
    pub cache_bytes: usize,
}

impl Default for TablesConfig {
    fn default() -> Self {
        TablesConfig {
            cache_bytes: default_table_cache_bytes(),
        }
    }
}

fn default_table_cache_bytes() -> usize {
    256 << 20
}

/// `[server]`: listener, limits and authentication.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServerConfig {
    pub bind: SocketAddr,
    pub max_body_bytes: usize,
    pub max_pixels: usize,
    /// Renders past the queue at once (decoding, rendering, encoding).
    pub render_concurrency: usize,
    /// Requests that may wait for a render slot once their body is read; more get 503.
    #[serde(default = "default_render_queue_depth")]
    pub render_queue_depth: usize,
    /// Longest wait for a render slot (seconds); past it, 503 with Retry-After.
    #[serde(default = "default_render_queue_wait_s")]
    pub render_queue_wait_s: f64,
    /// Longest time a render body may take to arrive (seconds); past it, 408.
    #[serde(default = "default_body_timeout_s")]
    pub body_timeout_s: f64,
    /// Slowest average body transfer accepted (bytes/s, judged after the first two seconds;
    /// 0: none); slower bodies get 408.
    #[serde(default)]
    pub min_body_rate_bytes_s: u64,
    /// Memory all render bodies in flight may hold together (bytes); a body that would pass
    /// it gets 503 with Retry-After before it is read.
    #[serde(default = "default_body_budget_bytes")]
    pub body_budget_bytes: usize,
    /// Threads of the render pool (0: one per core).
    #[serde(default)]
    pub render_threads: usize,
    pub request_timeout_s: f64,
    /// Empty: mutating endpoints need no token.
    #[serde(default)]
    pub bearer_token: String,
    #[serde(default = "default_log_format")]
    pub log_format: String,
    /// PNG compression of render answers unless a request names one (`l3 render` has the
    /// same default, so both give the same bytes).
    #[serde(default = "default_png_compression")]
    pub png_compression: PngCompression,
    /// How the active SI table's output is taken to D65 unless a request names one:
    /// `camera` (C, fitted per level on the table's colour maps and sensor under the light) or
    /// `colorimetric` (the registry's T). `l3 render --correction` has the same default.
    #[serde(default)]
    pub correction: CorrectionMode,
}

fn default_png_compression() -> PngCompression {
    RenderOptions::default().png
}

fn default_render_queue_depth() -> usize {
    64
}

fn default_render_queue_wait_s() -> f64 {
    30.0
}

fn default_body_timeout_s() -> f64 {
    30.0
}

fn default_body_budget_bytes() -> usize {
    1 << 30
}

fn default_log_format() -> String {
    "text".into()
}

/// `[data]`: where the database and the table files live.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataConfig {
    pub dir: PathBuf,
    /// ISET data folder over the built-in spectral data; when it does not exist the built-in
    /// data alone is used.
    #[serde(default)]
    pub iset_dir: Option<PathBuf>,
    /// The database: empty for the embedded SQLite file `l3.sqlite` in `dir`, else
    /// `sqlite://…` or `postgres://…` (a PostgreSQL database replicas share).
    #[serde(default)]
    pub database_url: String,
}

/// `[training]`: the job runner and the default table.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingConfig {
    pub auto_train_default: bool,
    pub max_concurrent_jobs: usize,
    /// Threads of the pool training jobs and evaluations run on (0: half
    /// the cores, at least one).
    #[serde(default)]
    pub background_threads: usize,
    /// The scheduling priority of those threads (Linux): `idle` (the
    /// default) runs training on the cores renders leave idle.
    #[serde(default)]
    pub background_priority: super::cpu::BackgroundPriority,
    /// Seconds a replica holds a claimed job without a heartbeat; a job whose replica died
    /// goes back to the queue after this.
    #[serde(default = "default_lease_s")]
    pub job_lease_s: f64,
    /// TrainingSpec fields of the default table (validated when used).
    #[serde(default)]
    pub default_spec: toml::Table,
}

fn default_lease_s() -> f64 {
    30.0
}

fn merge(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

fn bad(msg: String) -> ServiceError {
    ServiceError::Config(msg)
}

impl ServiceConfig {
    /// Defaults, then `file` if given, then the process environment.
    pub fn load(file: Option<&Path>) -> Result<Self, ServiceError> {
        let env: Vec<(String, String)> = std::env::vars().collect();
        Self::load_with_env(file, &env)
    }

    /// [`load`](Self::load) with an explicit environment (for tests).
    pub fn load_with_env(
        file: Option<&Path>,
        env: &[(String, String)],
    ) -> Result<Self, ServiceError> {
        let mut base: toml::Table = DEFAULT_CONFIG_TOML
            .parse()
            .map_err(|e| bad(format!("embedded config/default.toml: {e}")))?;
        if let Some(path) = file {
            let text = std::fs::read_to_string(path)
                .map_err(|e| bad(format!("cannot read {}: {e}", path.display())))?;
            let over: toml::Table = text
                .parse()
                .map_err(|e| bad(format!("{}: {e}", path.display())))?;
            merge(&mut base, over);
        }
        let mut cfg: ServiceConfig = toml::Value::Table(base)
            .try_into()
            .map_err(|e| bad(format!("configuration: {e}")))?;
        for (k, v) in env {
            cfg.apply_env(k, v)?;
        }
        cfg.validate()?;
        Ok(cfg)
    }

    fn apply_env(&mut self, key: &str, value: &str) -> Result<(), ServiceError> {
        fn num<T: std::str::FromStr>(key: &str, v: &str) -> Result<T, ServiceError> {
            v.trim()
                .parse()
                .map_err(|_| bad(format!("{key}={v:?} is not a valid number")))
        }
        match key {
            "L3_BIND" => {
                self.server.bind = value.parse().map_err(|_| {
                    bad(format!(
                        "L3_BIND={value:?} is not an address like 127.0.0.1:8080"
                    ))
                })?
            }
            "L3_DATA_DIR" => self.data.dir = PathBuf::from(value),
            "L3_DATABASE_URL" => self.data.database_url = value.to_string(),
            "L3_JOB_LEASE_S" => self.training.job_lease_s = num(key, value)?,
            "L3_ISET_DIR" => self.data.iset_dir = Some(PathBuf::from(value)),
            "L3_MAX_BODY_BYTES" => self.server.max_body_bytes = num(key, value)?,
            "L3_MAX_PIXELS" => self.server.max_pixels = num(key, value)?,
            "L3_RENDER_CONCURRENCY" => self.server.render_concurrency = num(key, value)?,
            "L3_RENDER_QUEUE_DEPTH" => self.server.render_queue_depth = num(key, value)?,
            "L3_RENDER_QUEUE_WAIT_S" => self.server.render_queue_wait_s = num(key, value)?,
            "L3_BODY_TIMEOUT_S" => self.server.body_timeout_s = num(key, value)?,
            "L3_MIN_BODY_RATE_BYTES_S" => self.server.min_body_rate_bytes_s = num(key, value)?,
            "L3_BODY_BUDGET_BYTES" => self.server.body_budget_bytes = num(key, value)?,
            "L3_RENDER_THREADS" => self.server.render_threads = num(key, value)?,
            "L3_BACKGROUND_THREADS" => self.training.background_threads = num(key, value)?,
            "L3_BACKGROUND_PRIORITY" => {
                self.training.background_priority = value.trim().parse().map_err(bad)?
            }
            "L3_REQUEST_TIMEOUT_S" => self.server.request_timeout_s = num(key, value)?,
            "L3_BEARER_TOKEN" => self.server.bearer_token = value.to_string(),
            "L3_LOG_FORMAT" => self.server.log_format = value.to_string(),
            "L3_PNG_COMPRESSION" => {
                self.server.png_compression = value
                    .parse()
                    .map_err(|e| bad(format!("L3_PNG_COMPRESSION: {e}")))?
            }
            "L3_CORRECTION" => {
                self.server.correction = value
                    .parse()
                    .map_err(|e| bad(format!("L3_CORRECTION: {e}")))?
            }
            "L3_AUTO_TRAIN" => {
                self.training.auto_train_default = match value.trim() {
                    "1" | "true" | "yes" => true,
                    "0" | "false" | "no" => false,
                    _ => {
                        return Err(bad(format!(
                            "L3_AUTO_TRAIN={value:?}: expected true or false"
                        )));
                    }
                }
            }
            "L3_MAX_CONCURRENT_JOBS" => self.training.max_concurrent_jobs = num(key, value)?,
            "L3_TABLE_CACHE_BYTES" => self.tables.cache_bytes = num(key, value)?,
            _ => {}
        }
        Ok(())
    }

    /// Checks ranges that would make the service unusable.
    pub fn validate(&self) -> Result<(), ServiceError> {
        let s = &self.server;
        if s.max_body_bytes < 1024 {
            return Err(bad(format!(
                "max_body_bytes {} (at least 1024)",
                s.max_body_bytes
            )));
        }
        if s.max_pixels == 0 {
            return Err(bad("max_pixels must be at least 1".into()));
        }
        if s.render_concurrency == 0 {
            return Err(bad("render_concurrency must be at least 1".into()));
        }
        if !(s.render_queue_wait_s.is_finite() && s.render_queue_wait_s >= 0.0) {
            return Err(bad(format!(
                "render_queue_wait_s {} (a non-negative number of seconds)",
                s.render_queue_wait_s
            )));
        }
        if !(s.body_timeout_s.is_finite() && s.body_timeout_s > 0.0) {
            return Err(bad(format!(
                "body_timeout_s {} (a positive number of seconds)",
                s.body_timeout_s
            )));
        }
        if s.body_budget_bytes < s.max_body_bytes {
            return Err(bad(format!(
                "body_budget_bytes {} is below max_body_bytes {}: the largest body could never be read",
                s.body_budget_bytes, s.max_body_bytes
            )));
        }
        if !(s.request_timeout_s.is_finite() && s.request_timeout_s > 0.0) {
            return Err(bad(format!(
                "request_timeout_s {} (a positive number of seconds)",
                s.request_timeout_s
            )));
        }
        if !["text", "json"].contains(&s.log_format.as_str()) {
            return Err(bad(format!("log_format {:?}: text or json", s.log_format)));
        }
        let lease = self.training.job_lease_s;
        if !(lease.is_finite() && (0.5..=3600.0).contains(&lease)) {
            return Err(bad(format!("job_lease_s {lease} (0.5 to 3600 seconds)")));
        }
        if self.training.max_concurrent_jobs == 0 {
            return Err(bad("max_concurrent_jobs must be at least 1".into()));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_file_and_env_layer() {
        let c = ServiceConfig::load_with_env(None, &[]).unwrap();
        assert_eq!(c.server.bind.to_string(), "127.0.0.1:8080");
        assert_eq!(c.data.dir, PathBuf::from("./data"));
        assert!(c.training.auto_train_default);
        assert_eq!(c.server.png_compression, RenderOptions::default().png);
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("c.toml");
        std::fs::write(&f, "[server]\nmax_pixels = 1000\n[data]\ndir = \"/x\"\n").unwrap();
        let env = vec![
            ("L3_BIND".to_string(), "0.0.0.0:9000".to_string()),
            ("L3_AUTO_TRAIN".to_string(), "false".to_string()),
            ("L3_PNG_COMPRESSION".to_string(), "best".to_string()),
            ("L3_TABLE_CACHE_BYTES".to_string(), "1000".to_string()),
        ];
        let c = ServiceConfig::load_with_env(Some(&f), &env).unwrap();
        assert_eq!(c.server.max_pixels, 1000);
        assert_eq!(c.server.render_concurrency, 4);
        assert_eq!(c.data.dir, PathBuf::from("/x"));
        assert_eq!(c.server.bind.to_string(), "0.0.0.0:9000");
        assert!(!c.training.auto_train_default);
        assert_eq!(c.server.png_compression, PngCompression::Best);
        assert_eq!(c.tables.cache_bytes, 1000);
        let c = ServiceConfig::load_with_env(None, &[]).unwrap();
        assert_eq!(c.tables.cache_bytes, 268435456);
    }

    #[test]
    fn bad_values_are_clear_errors() {
        let env = vec![("L3_MAX_PIXELS".to_string(), "lots".to_string())];
        let e = ServiceConfig::load_with_env(None, &env).unwrap_err();
        assert!(e.to_string().contains("L3_MAX_PIXELS"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("c.toml");
        std::fs::write(&f, "[server]\nbogus = 1\n").unwrap();
        let e = ServiceConfig::load_with_env(Some(&f), &[]).unwrap_err();
        assert!(e.to_string().contains("bogus"), "{e}");
    }
}
