//! Service configuration in layers, each over the one before: `config/default.toml`
//! (embedded), an optional file given with `--config`, the `L3_*` environment variables, then
//! `l3 serve`'s flags (`--bind`, `--data-dir`, `--iset-dir`).
//!
//! The layers are merged by `figment` (dictionaries merged key by key, a later layer's value
//! over an earlier one's) and extracted into [`ServiceConfig`] through serde, so a bad value or
//! an unknown key names its key and its layer (the file's path, the variables, the command
//! line). Each layer is handed to figment as values already read, not through its own `Toml`
//! and `Env` providers, for two reasons:
//! - figment's `Env` parses every value as TOML-like data, so `L3_BEARER_TOKEN=123456` or
//!   `L3_DATA_DIR=2024` arrives as an integer and fails to deserialize into the string it is
//!   (figment issues #42 and #70); and the variables here are named for people
//!   (`L3_AUTO_TRAIN`, not `L3_TRAINING__AUTO_TRAIN_DEFAULT`), so a table maps each to its key
//!   anyway, and each is checked with a message that names the variable
//!   (`L3_MAX_PIXELS="lots" is not a valid number`).
//! - figment's `Toml` provider needs its own `toml` crate version; the files are parsed by the
//!   `toml` this crate already uses, which keeps its error messages with line and column.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use figment::value::{Dict, Map, Value};
use figment::{Figment, Metadata, Profile, Provider};
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

fn bad(msg: String) -> ServiceError {
    ServiceError::Config(msg)
}

/// What `l3 serve`'s flags set, over every other layer.
#[derive(Clone, Debug, Default)]
pub struct ConfigFlags {
    /// `--bind`
    pub bind: Option<SocketAddr>,
    /// `--data-dir`
    pub data_dir: Option<PathBuf>,
    /// `--iset-dir` (a flag of every command)
    pub iset_dir: Option<PathBuf>,
}

/// How an `L3_*` variable's text becomes a value.
#[derive(Clone, Copy)]
enum EnvKind {
    Text,
    Uint,
    Float,
    Bool,
    Addr,
    Png,
    Correction,
    Priority,
}

/// The `L3_*` variables: name, key in the configuration, kind.
const ENV_KEYS: [(&str, &str, EnvKind); 24] = [
    ("L3_BIND", "server.bind", EnvKind::Addr),
    ("L3_DATA_DIR", "data.dir", EnvKind::Text),
    ("L3_DATABASE_URL", "data.database_url", EnvKind::Text),
    ("L3_JOB_LEASE_S", "training.job_lease_s", EnvKind::Float),
    ("L3_ISET_DIR", "data.iset_dir", EnvKind::Text),
    ("L3_MAX_BODY_BYTES", "server.max_body_bytes", EnvKind::Uint),
    ("L3_MAX_PIXELS", "server.max_pixels", EnvKind::Uint),
    (
        "L3_RENDER_CONCURRENCY",
        "server.render_concurrency",
        EnvKind::Uint,
    ),
    (
        "L3_RENDER_QUEUE_DEPTH",
        "server.render_queue_depth",
        EnvKind::Uint,
    ),
    (
        "L3_RENDER_QUEUE_WAIT_S",
        "server.render_queue_wait_s",
        EnvKind::Float,
    ),
    ("L3_BODY_TIMEOUT_S", "server.body_timeout_s", EnvKind::Float),
    (
        "L3_MIN_BODY_RATE_BYTES_S",
        "server.min_body_rate_bytes_s",
        EnvKind::Uint,
    ),
    (
        "L3_BODY_BUDGET_BYTES",
        "server.body_budget_bytes",
        EnvKind::Uint,
    ),
    ("L3_RENDER_THREADS", "server.render_threads", EnvKind::Uint),
    (
        "L3_BACKGROUND_THREADS",
        "training.background_threads",
        EnvKind::Uint,
    ),
    (
        "L3_BACKGROUND_PRIORITY",
        "training.background_priority",
        EnvKind::Priority,
    ),
    (
        "L3_REQUEST_TIMEOUT_S",
        "server.request_timeout_s",
        EnvKind::Float,
    ),
    ("L3_BEARER_TOKEN", "server.bearer_token", EnvKind::Text),
    ("L3_LOG_FORMAT", "server.log_format", EnvKind::Text),
    ("L3_PNG_COMPRESSION", "server.png_compression", EnvKind::Png),
    ("L3_CORRECTION", "server.correction", EnvKind::Correction),
    (
        "L3_AUTO_TRAIN",
        "training.auto_train_default",
        EnvKind::Bool,
    ),
    (
        "L3_MAX_CONCURRENT_JOBS",
        "training.max_concurrent_jobs",
        EnvKind::Uint,
    ),
    ("L3_TABLE_CACHE_BYTES", "tables.cache_bytes", EnvKind::Uint),
];

/// The value of `L3_*` variable `key` (of `kind`), checked with a message naming it.
fn env_value(key: &str, value: &str, kind: EnvKind) -> Result<Value, ServiceError> {
    fn num<T: std::str::FromStr>(key: &str, v: &str) -> Result<T, ServiceError> {
        v.trim()
            .parse()
            .map_err(|_| bad(format!("{key}={v:?} is not a valid number")))
    }
    Ok(match kind {
        EnvKind::Text => Value::from(value),
        EnvKind::Uint => Value::from(num::<u64>(key, value)?),
        EnvKind::Float => Value::from(num::<f64>(key, value)?),
        EnvKind::Bool => Value::from(match value.trim() {
            "1" | "true" | "yes" => true,
            "0" | "false" | "no" => false,
            _ => return Err(bad(format!("{key}={value:?}: expected true or false"))),
        }),
        EnvKind::Addr => {
            let a: SocketAddr = value.parse().map_err(|_| {
                bad(format!(
                    "{key}={value:?} is not an address like 127.0.0.1:8080"
                ))
            })?;
            Value::from(a.to_string())
        }
        EnvKind::Png => {
            let _: PngCompression = value.parse().map_err(|e| bad(format!("{key}: {e}")))?;
            Value::from(value)
        }
        EnvKind::Correction => {
            let c: CorrectionMode = value.parse().map_err(|e| bad(format!("{key}: {e}")))?;
            Value::serialize(c).map_err(|e| bad(format!("{key}: {e}")))?
        }
        EnvKind::Priority => {
            let _: super::cpu::BackgroundPriority = value.trim().parse().map_err(bad)?;
            Value::from(value.trim())
        }
    })
}

/// One layer of the configuration: a dictionary of values and the name errors give it.
struct Layer {
    name: String,
    values: Dict,
}

impl Layer {
    fn new(name: impl Into<String>) -> Self {
        Layer {
            name: name.into(),
            values: Dict::new(),
        }
    }

    /// Sets `path` (dotted, e.g. `server.bind`) to `value`.
    fn set(&mut self, path: &str, value: Value) {
        let mut dict = &mut self.values;
        let mut keys = path.split('.').peekable();
        while let Some(k) = keys.next() {
            if keys.peek().is_none() {
                dict.insert(k.to_string(), value);
                return;
            }
            let entry = dict
                .entry(k.to_string())
                .or_insert_with(|| Value::from(Dict::new()));
            if !matches!(entry, Value::Dict(..)) {
                *entry = Value::from(Dict::new());
            }
            let Value::Dict(_, d) = entry else { return };
            dict = d;
        }
    }

    /// A layer from a TOML document.
    fn toml(name: impl Into<String>, table: toml::Table) -> Result<Self, ServiceError> {
        let name = name.into();
        let values = Value::serialize(&table)
            .ok()
            .and_then(|v| v.into_dict())
            .ok_or_else(|| bad(format!("{name}: not a table")))?;
        Ok(Layer { name, values })
    }
}

impl Provider for Layer {
    fn metadata(&self) -> Metadata {
        // keys named as in the file ("server.bind"), without figment's profile
        Metadata::named(self.name.clone()).interpolater(|_, keys| keys.join("."))
    }

    fn data(&self) -> Result<Map<Profile, Dict>, figment::Error> {
        Ok(Profile::Default.collect(self.values.clone()))
    }
}

impl ServiceConfig {
    /// Defaults, then `file` if given, then the process environment.
    pub fn load(file: Option<&Path>) -> Result<Self, ServiceError> {
        Self::load_layers(file, &Self::process_env(), &ConfigFlags::default())
    }

    /// The process's `L3_*` variables (those with a name and value in Unicode).
    pub fn process_env() -> Vec<(String, String)> {
        std::env::vars_os()
            .filter_map(|(k, v)| Some((k.into_string().ok()?, v.into_string().ok()?)))
            .filter(|(k, _)| k.starts_with("L3_"))
            .collect()
    }

    /// [`load`](Self::load) with an explicit environment (for tests).
    pub fn load_with_env(
        file: Option<&Path>,
        env: &[(String, String)],
    ) -> Result<Self, ServiceError> {
        Self::load_layers(file, env, &ConfigFlags::default())
    }

    /// Every layer, each over the one before: the embedded defaults, `file`, the `L3_*`
    /// variables of `env`, then `flags`.
    pub fn load_layers(
        file: Option<&Path>,
        env: &[(String, String)],
        flags: &ConfigFlags,
    ) -> Result<Self, ServiceError> {
        let defaults: toml::Table = DEFAULT_CONFIG_TOML
            .parse()
            .map_err(|e| bad(format!("embedded config/default.toml: {e}")))?;
        let mut figment = Figment::from(Layer::toml("config/default.toml", defaults)?);
        if let Some(path) = file {
            let text = std::fs::read_to_string(path)
                .map_err(|e| bad(format!("cannot read {}: {e}", path.display())))?;
            let over: toml::Table = text
                .parse()
                .map_err(|e| bad(format!("{}: {e}", path.display())))?;
            figment = figment.merge(Layer::toml(path.display().to_string(), over)?);
        }
        let mut vars = Layer::new("the L3_* environment variables");
        for (k, v) in env {
            if let Some((_, path, kind)) = ENV_KEYS.iter().find(|(name, ..)| name == k) {
                vars.set(path, env_value(k, v, *kind)?);
            }
        }
        let mut flag_layer = Layer::new("the command line");
        let path_value = |p: &Path| Value::from(p.to_string_lossy().into_owned());
        if let Some(bind) = flags.bind {
            flag_layer.set("server.bind", Value::from(bind.to_string()));
        }
        if let Some(d) = &flags.data_dir {
            flag_layer.set("data.dir", path_value(d));
        }
        if let Some(d) = &flags.iset_dir {
            flag_layer.set("data.iset_dir", path_value(d));
        }
        let cfg: ServiceConfig = figment
            .merge(vars)
            .merge(flag_layer)
            .extract()
            .map_err(|e| bad(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
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
        super::store::Store::check_url(&self.data.database_url).map_err(|e| bad(e.to_string()))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    /// Defaults, then a file over them, the variables over the file, the flags over the
    /// variables: each layer wins over the one below and keeps what it does not set.
    #[test]
    fn each_layer_overrides_the_one_below() {
        let none = ConfigFlags::default();
        let c = ServiceConfig::load_layers(None, &[], &none).unwrap();
        assert_eq!(c.server.bind.to_string(), "127.0.0.1:8080");
        assert_eq!(c.server.max_pixels, 110_000_000);
        assert_eq!(c.server.render_concurrency, 4);
        assert_eq!(c.data.dir, PathBuf::from("./data"));
        assert!(c.training.auto_train_default);
        assert_eq!(c.server.png_compression, RenderOptions::default().png);
        assert_eq!(c.tables.cache_bytes, 268435456);
        assert_eq!(c.training.default_spec["levels"].as_integer(), Some(20));

        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("c.toml");
        std::fs::write(
            &f,
            "[server]\nbind = \"127.0.0.2:8001\"\nmax_pixels = 1000\n[data]\ndir = \"/file\"\n\
             [training.default_spec]\nlevels = 3\n",
        )
        .unwrap();
        let c = ServiceConfig::load_layers(Some(&f), &[], &none).unwrap();
        assert_eq!(c.server.bind.to_string(), "127.0.0.2:8001");
        assert_eq!(c.server.max_pixels, 1000);
        assert_eq!(c.data.dir, PathBuf::from("/file"));
        // kept from the defaults, in the same tables
        assert_eq!(c.server.render_concurrency, 4);
        assert_eq!(c.training.default_spec["levels"].as_integer(), Some(3));
        assert_eq!(c.training.default_spec["patch_size"].as_integer(), Some(5));

        let vars = env(&[
            ("L3_BIND", "127.0.0.3:8002"),
            ("L3_DATA_DIR", "/env"),
            ("L3_AUTO_TRAIN", "false"),
            ("L3_PNG_COMPRESSION", "best"),
            ("L3_TABLE_CACHE_BYTES", "1000"),
            ("HOME", "/elsewhere"),
        ]);
        let c = ServiceConfig::load_layers(Some(&f), &vars, &none).unwrap();
        assert_eq!(c.server.bind.to_string(), "127.0.0.3:8002");
        assert_eq!(c.data.dir, PathBuf::from("/env"));
        assert!(!c.training.auto_train_default);
        assert_eq!(c.server.png_compression, PngCompression::Best);
        assert_eq!(c.tables.cache_bytes, 1000);
        // kept from the file
        assert_eq!(c.server.max_pixels, 1000);

        let flags = ConfigFlags {
            bind: Some("127.0.0.4:8003".parse().unwrap()),
            data_dir: Some(PathBuf::from("/flag")),
            iset_dir: Some(PathBuf::from("/iset")),
        };
        let c = ServiceConfig::load_layers(Some(&f), &vars, &flags).unwrap();
        assert_eq!(c.server.bind.to_string(), "127.0.0.4:8003");
        assert_eq!(c.data.dir, PathBuf::from("/flag"));
        assert_eq!(c.data.iset_dir, Some(PathBuf::from("/iset")));
        // kept from the variables and the file
        assert!(!c.training.auto_train_default);
        assert_eq!(c.server.max_pixels, 1000);
    }

    /// Variables are text: a numeric token stays the string it is; names map to their keys.
    #[test]
    fn variables_keep_their_text() {
        let vars = env(&[
            ("L3_BEARER_TOKEN", "123456"),
            ("L3_DATABASE_URL", "postgres://l3@db:5432/l3"),
            ("L3_LOG_FORMAT", "json"),
            ("L3_CORRECTION", "t"),
            ("L3_AUTO_TRAIN", " yes "),
            ("L3_JOB_LEASE_S", "5"),
            ("L3_BACKGROUND_PRIORITY", "low"),
        ]);
        let c = ServiceConfig::load_with_env(None, &vars).unwrap();
        assert_eq!(c.server.bearer_token, "123456");
        assert_eq!(c.data.database_url, "postgres://l3@db:5432/l3");
        assert_eq!(c.server.log_format, "json");
        assert_eq!(c.server.correction, CorrectionMode::Colorimetric);
        assert!(c.training.auto_train_default);
        assert_eq!(c.training.job_lease_s, 5.0);
        assert_eq!(
            c.training.background_priority,
            super::super::cpu::BackgroundPriority::Low
        );
    }

    #[test]
    fn bad_values_are_clear_errors() {
        let e = |vars: &[(&str, &str)]| {
            ServiceConfig::load_with_env(None, &env(vars))
                .unwrap_err()
                .to_string()
        };
        assert!(
            e(&[("L3_MAX_PIXELS", "lots")])
                .contains("L3_MAX_PIXELS=\"lots\" is not a valid number")
        );
        assert!(
            e(&[("L3_BIND", "localhost")])
                .contains("L3_BIND=\"localhost\" is not an address like 127.0.0.1:8080")
        );
        assert!(
            e(&[("L3_AUTO_TRAIN", "maybe")])
                .contains("L3_AUTO_TRAIN=\"maybe\": expected true or false")
        );
        assert!(e(&[("L3_PNG_COMPRESSION", "max")]).contains("L3_PNG_COMPRESSION"));
        assert!(e(&[("L3_JOB_LEASE_S", "0.1")]).contains("job_lease_s 0.1 (0.5 to 3600 seconds)"));
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("c.toml");
        std::fs::write(&f, "[server]\nbogus = 1\n").unwrap();
        let msg = ServiceConfig::load_with_env(Some(&f), &[])
            .unwrap_err()
            .to_string();
        assert!(msg.contains("bogus") && msg.contains("c.toml"), "{msg}");
        std::fs::write(&f, "[server]\nmax_pixels = \"many\"\n").unwrap();
        let msg = ServiceConfig::load_with_env(Some(&f), &[])
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("server.max_pixels") && msg.contains("c.toml"),
            "{msg}"
        );
        std::fs::write(&f, "[server\n").unwrap();
        let msg = ServiceConfig::load_with_env(Some(&f), &[])
            .unwrap_err()
            .to_string();
        assert!(msg.contains("c.toml") && msg.contains("line 1"), "{msg}");
        let missing = dir.path().join("none.toml");
        let msg = ServiceConfig::load_with_env(Some(&missing), &[])
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("cannot read") && msg.contains("none.toml"),
            "{msg}"
        );
    }
}
