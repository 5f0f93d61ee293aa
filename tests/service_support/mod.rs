//! Shared helpers of the service integration tests: a tiny trained table, a server on
//! 127.0.0.1:0 with a temporary data directory, and an HTTP client.
#![allow(dead_code)]

use std::path::Path;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use l3::camera::SensorDesign;
use l3::l3::L3Table;
use l3::l3::learn::{TrainingSpec, train_table};
use l3::service::{Server, ServiceConfig};

/// A small, quick training spec.
pub fn tiny_spec(illuminants: &[&str]) -> TrainingSpec {
    TrainingSpec {
        illuminants: illuminants.iter().map(|s| s.to_string()).collect(),
        scenes: 4,
        scene_size: 48,
        levels: 10,
        ..TrainingSpec::default()
    }
}

/// The tiny table JSON body for a training job.
pub fn tiny_job_json(illuminants: &[&str], seed: u64) -> serde_json::Value {
    serde_json::json!({
        "illuminants": illuminants,
        "scenes": 4,
        "scene_size": 48,
        "levels": 10,
        "seed": seed,
    })
}

/// A tiny SI table on D65 and Tungsten (trained once per test binary, on the built-in
/// spectral data).
pub fn tiny_table() -> &'static L3Table {
    static T: OnceLock<L3Table> = OnceLock::new();
    T.get_or_init(|| {
        train_table(
            &SensorDesign::paper_default(),
            &tiny_spec(&["D65", "Tungsten"]),
            None,
            &|_, _| {},
            &AtomicBool::new(false),
        )
        .expect("train tiny table")
    })
}

/// A config for tests: port 0, the given data dir, no auto-training, and the ISET data the
/// service would locate from the repository's root (`../shared/data/iset`, or `$L3_ISET_DIR`):
/// the tests run in tests/, where its own lookup would not find it.
pub fn test_config(data: &Path) -> ServiceConfig {
    let mut c = ServiceConfig::load_with_env(None, &[]).expect("default config");
    let beside_the_repository = Path::new(concat!(env!("L3_ROOT"), "/../shared/data/iset"));
    if std::env::var_os(l3::spectral::ISET_DIR_ENV).is_none() && beside_the_repository.is_dir() {
        c.data.iset_dir = Some(beside_the_repository.to_path_buf());
    }
    c.server.bind = "127.0.0.1:0".parse().unwrap();
    c.data.dir = data.to_path_buf();
    c.training.auto_train_default = false;
    if let Some(db) = pg::test_database_url(data) {
        c.data.database_url = db;
    }
    c
}

/// A started server with the tiny table imported and active.
pub async fn server_with_table(data: &Path, cfg: Option<ServiceConfig>) -> (Server, String) {
    let cfg = cfg.unwrap_or_else(|| test_config(data));
    let server = l3::service::start(cfg).await.expect("start server");
    let table = tiny_table().clone();
    let id = l3::service::import_table(server.state(), &table, true)
        .await
        .expect("import table");
    (server, id)
}

/// A simple synthetic raw u16 frame (a gradient), little-endian bytes.
pub fn gradient_raw(w: usize, h: usize) -> Vec<u8> {
    (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w, i / w);
            let v = (2000 + (x * 40000 / w) + (y * 10000 / h)) as u16;
            v.to_le_bytes()
        })
        .collect()
}

pub fn url(server: &Server, path: &str) -> String {
    format!("http://{}{}", server.addr(), path)
}

pub fn client() -> reqwest::Client {
    reqwest::Client::new()
}

/// The status and body of an answer to `method` (`None`: not known), the body checked against
/// openapi.yaml's schema for its route, status and content type ([`openapi::check_response`]).
async fn checked_body(method: Option<&str>, resp: reqwest::Response) -> (u16, Vec<u8>) {
    let path = resp.url().path().to_string();
    let status = resp.status().as_u16();
    let ctype = resp
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_string();
    let bytes = resp.bytes().await.expect("body").to_vec();
    openapi::assert_response(method, &path, status, &ctype, &bytes);
    (status, bytes)
}

/// Parses a JSON body, first checked against openapi.yaml.
pub async fn json(resp: reqwest::Response) -> serde_json::Value {
    let (_, bytes) = checked_body(None, resp).await;
    serde_json::from_slice(&bytes)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&bytes)))
}

/// The status and JSON body (`Null` when the body is not JSON) of an answer to `method`, the
/// body first checked against openapi.yaml.
pub async fn checked_json(method: &str, resp: reqwest::Response) -> (u16, serde_json::Value) {
    let (status, bytes) = checked_body(Some(method), resp).await;
    (
        status,
        serde_json::from_slice(&bytes).unwrap_or(serde_json::Value::Null),
    )
}

/// Asserts a problem+json answer with `status` and `code`, and returns its detail.
pub async fn problem(resp: reqwest::Response, status: u16, code: &str) -> String {
    assert_eq!(resp.status().as_u16(), status, "status");
    assert_eq!(
        resp.headers()["content-type"],
        "application/problem+json",
        "content type"
    );
    let v = json(resp).await;
    assert_eq!(v["code"], code, "{v}");
    assert_eq!(v["status"], status);
    let d = v["detail"].as_str().unwrap_or_default().to_string();
    assert!(!d.is_empty());
    d
}

/// [`problem`] of the answer to `request`.
pub async fn problem_of(request: reqwest::RequestBuilder, status: u16, code: &str) -> String {
    problem(request.send().await.unwrap(), status, code).await
}

/// [`problem`], and its detail names every one of `needles`.
pub async fn problem_naming(resp: reqwest::Response, status: u16, code: &str, needles: &[&str]) {
    let d = problem(resp, status, code).await;
    assert!(needles.iter().all(|n| d.contains(n)), "{d}");
}

/// Polls a job until `done(job)` or the timeout (seconds); returns the last job JSON.
pub async fn wait_job(
    server: &Server,
    id: &str,
    secs: f64,
    done: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let c = client();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs_f64(secs);
    loop {
        let j = json(
            c.get(url(server, &format!("/v1/training-jobs/{id}")))
                .send()
                .await
                .unwrap(),
        )
        .await;
        if done(&j) || std::time::Instant::now() > deadline {
            return j;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
}
pub mod openapi;
pub mod pg;
