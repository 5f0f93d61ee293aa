//! Crash safety of the real `l3 serve` process: kill -9 during a training job, while a table is
//! being stored, and while the active table is being switched; restart and check that no job
//! and no table is lost or corrupted. Then a table file corrupted on disk: the service says so
//! at start and stays up on the last good table.
//!
//! The windows are hit deterministically with the debug hook
//! `L3_DEBUG_PAUSE_ACTIVATION_MS`, which makes the service pause (and log) just before the
//! rename of a new table file and just before recording a table switch.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::service_support::checked_json;
use serde_json::{Value, json};

/// A running `l3 serve` child with its captured log lines.
struct Service {
    child: Child,
    base: String,
    log: Arc<Mutex<Vec<String>>>,
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

impl Service {
    /// Starts `l3 serve` on `data` (auto-training off) and waits until it answers /healthz.
    /// The service gets no ISET data directory: it runs on the built-in spectral data.
    async fn start(data: &Path, pause_ms: u64) -> Service {
        let port = free_port();
        let mut cmd = Command::new(env!("L3_BIN"));
        cmd.arg("serve")
            .env("L3_BIND", format!("127.0.0.1:{port}"))
            .env("L3_DATA_DIR", data)
            .env("L3_AUTO_TRAIN", "false")
            .env("L3_LOG_FORMAT", "text")
            .env("L3_LOG", "info,sqlx=warn")
            .env("NO_COLOR", "1")
            .env("L3_DEBUG_PAUSE_ACTIVATION_MS", pause_ms.to_string())
            .env("L3_ISET_DIR", data.join("no-iset"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().expect("spawn l3 serve");
        let log = Arc::new(Mutex::new(Vec::new()));
        for pipe in [
            Box::new(child.stdout.take().unwrap()) as Box<dyn std::io::Read + Send>,
            Box::new(child.stderr.take().unwrap()) as Box<dyn std::io::Read + Send>,
        ] {
            let log = log.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(pipe).lines().map_while(Result::ok) {
                    log.lock().unwrap().push(line);
                }
            });
        }
        let s = Service {
            child,
            base: format!("http://127.0.0.1:{port}"),
            log,
        };
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Ok(r) = reqwest::get(s.url("/healthz")).await
                && r.status() == 200
            {
                return s;
            }
            assert!(
                Instant::now() < deadline,
                "the service did not start:\n{}",
                s.log_text()
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    fn log_text(&self) -> String {
        self.log.lock().unwrap().join("\n")
    }

    fn log_count(&self, needle: &str) -> usize {
        self.log
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.contains(needle))
            .count()
    }

    /// Waits until `needle` has appeared `n` times in the log.
    async fn wait_log(&self, needle: &str, n: usize, secs: u64) {
        let deadline = Instant::now() + Duration::from_secs(secs);
        while self.log_count(needle) < n {
            assert!(
                Instant::now() < deadline,
                "no log line {needle:?} (×{n}):\n{}",
                self.log_text()
            );
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// kill -9.
    fn kill9(mut self) {
        self.child.kill().expect("SIGKILL");
        self.child.wait().expect("reap");
    }

    async fn get(&self, path: &str) -> (u16, Value) {
        let r = reqwest::get(self.url(path)).await.expect("GET");
        checked_json("GET", r).await
    }

    async fn post(&self, path: &str, body: &Value) -> (u16, Value) {
        let r = reqwest::Client::new()
            .post(self.url(path))
            .json(body)
            .send()
            .await
            .expect("POST");
        checked_json("POST", r).await
    }

    /// Polls a job until `done(job)`; panics with the log after `secs`.
    async fn wait_job(&self, id: &str, secs: u64, done: impl Fn(&Value) -> bool) -> Value {
        let deadline = Instant::now() + Duration::from_secs(secs);
        loop {
            let (_, j) = self.get(&format!("/v1/training-jobs/{id}")).await;
            if done(&j) {
                return j;
            }
            assert!(
                Instant::now() < deadline,
                "job {id} never reached the state: {j}\n{}",
                self.log_text()
            );
            tokio::time::sleep(Duration::from_millis(15)).await;
        }
    }

    async fn ready_table(&self) -> Option<String> {
        let (s, v) = self.get("/readyz").await;
        (s == 200).then(|| v["table_id"].as_str().unwrap().to_string())
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn job_body(seed: u64, scenes: u64, activate: bool) -> Value {
    json!({
        "illuminants": ["D65", "A"],
        "scenes": scenes,
        "scene_size": 48,
        "levels": 10,
        "seed": seed,
        "activate": activate,
    })
}

fn temp_files(tables: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(tables)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.to_string_lossy().ends_with(".tmp"))
        .collect()
}

/// Every table's file exists and matches its recorded SHA-256 and id; returns the ids.
async fn check_tables_agree(s: &Service, tables: &Path) -> Vec<String> {
    let (st, list) = s.get("/v1/tables").await;
    assert_eq!(st, 200);
    let mut ids = Vec::new();
    for t in list["items"].as_array().unwrap() {
        let id = t["id"].as_str().unwrap();
        assert_eq!(t["status"], "ok", "{t}");
        let bytes = std::fs::read(tables.join(format!("{id}.safetensors"))).unwrap();
        let sha = l3::service::sha256_hex(&bytes);
        assert_eq!(t["sha256"], sha.as_str(), "{id}");
        assert_eq!(id, format!("tbl_{}", &sha[..16]));
        let r = reqwest::get(s.url(&format!("/v1/tables/{id}/download")))
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(r.bytes().await.unwrap().as_ref(), bytes.as_slice());
        ids.push(id.to_string());
    }
    ids
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill9_during_a_training_job_then_the_restart_finishes_it() {
    let data = tempfile::tempdir().unwrap();
    let s = Service::start(data.path(), 0).await;
    let (st, job) = s.post("/v1/training-jobs", &job_body(3, 12, true)).await;
    assert_eq!(st, 202, "{job}");
    let id = job["id"].as_str().unwrap().to_string();
    let running = s
        .wait_job(&id, 60, |j| {
            j["status"] != "queued"
                && (j["status"] != "running" || j["progress"].as_f64().unwrap() > 0.0)
        })
        .await;
    assert_eq!(running["status"], "running", "finished before the kill");
    assert!(running["progress"].as_f64().unwrap() > 0.0);
    s.kill9();

    let s = Service::start(data.path(), 0).await;
    s.wait_log("interrupted training job(s) re-queued", 1, 10)
        .await;
    let (_, list) = s.get("/v1/training-jobs").await;
    assert_eq!(list["items"].as_array().unwrap().len(), 1, "{list}");
    let done = s
        .wait_job(&id, 120, |j| {
            j["status"] != "queued" && j["status"] != "running"
        })
        .await;
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(done["attempts"], 2, "{done}");
    assert_eq!(done["request"]["seed"], 3);
    let table = done["table_id"].as_str().unwrap();
    assert_eq!(s.ready_table().await.as_deref(), Some(table));
    let ids = check_tables_agree(&s, &data.path().join("tables")).await;
    assert_eq!(ids, [table]);
    assert!(temp_files(&data.path().join("tables")).is_empty());
}

/// The debug pause before the rename of a table file and before the switch to it (runs 2, 3).
const PAUSE_MS: u64 = 4000;
/// The log line of the pause before the rename.
const BEFORE_RENAME: &str = "pausing 4000 ms before the rename";
/// The log line of the pause before the switch is recorded.
const BEFORE_SWITCH: &str = "pausing 4000 ms before recording it as active";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill9_while_storing_and_switching_tables_then_a_corrupt_table_file() {
    let data = tempfile::tempdir().unwrap();
    let tables = data.path().join("tables");
    let a = run1_table_a_trained_and_active(data.path()).await;
    let b_job = run2_killed_before_the_rename(data.path(), &tables, &a).await;
    run3_killed_before_the_switch(data.path(), &tables, &a).await;
    let b = run4_job_b_runs_again(data.path(), &tables, &a, &b_job).await;
    run5_a_corrupt_active_table_file(data.path(), &tables, &a, &b).await;
}

/// Run 1: table A trained and active; returns A.
async fn run1_table_a_trained_and_active(data: &Path) -> String {
    let s = Service::start(data, 0).await;
    let (_, job) = s.post("/v1/training-jobs", &job_body(1, 4, true)).await;
    let a_job = job["id"].as_str().unwrap().to_string();
    let done = s
        .wait_job(&a_job, 120, |j| {
            j["status"] == "succeeded" || j["status"] == "failed"
        })
        .await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let a = done["table_id"].as_str().unwrap().to_string();
    assert_eq!(s.ready_table().await.as_deref(), Some(a.as_str()));
    s.kill9();
    a
}

/// Run 2: job B (activate) killed after its temporary file is written, before the rename;
/// returns B's job id.
async fn run2_killed_before_the_rename(data: &Path, tables: &Path, a: &str) -> String {
    let s = Service::start(data, PAUSE_MS).await;
    assert_eq!(s.ready_table().await.as_deref(), Some(a));
    let (_, job) = s.post("/v1/training-jobs", &job_body(2, 4, true)).await;
    let b_job = job["id"].as_str().unwrap().to_string();
    s.wait_log(BEFORE_RENAME, 1, 120).await;
    assert_eq!(
        temp_files(tables).len(),
        1,
        "the window holds a temporary file"
    );
    s.kill9();
    b_job
}

/// Run 3: the temporary file is cleaned at start, A still serves, B runs again and is killed
/// after its file is stored and verified, before the switch to it is recorded.
async fn run3_killed_before_the_switch(data: &Path, tables: &Path, a: &str) {
    let s = Service::start(data, PAUSE_MS).await;
    assert!(
        temp_files(tables).is_empty(),
        "orphan temporary file remains"
    );
    s.wait_log("left half-written", 1, 10).await;
    assert_eq!(s.ready_table().await.as_deref(), Some(a));
    s.wait_log(BEFORE_SWITCH, 1, 120).await;
    let (_, list) = s.get("/v1/tables").await;
    assert_eq!(list["items"].as_array().unwrap().len(), 2, "{list}");
    s.kill9();
}

/// Run 4: A is still the active table (the switch was never recorded); every file agrees with
/// the database; job B is not lost: it runs a third time and activates B, which it returns.
async fn run4_job_b_runs_again(data: &Path, tables: &Path, a: &str, b_job: &str) -> String {
    let s = Service::start(data, 0).await;
    assert_eq!(s.ready_table().await.as_deref(), Some(a));
    let ids = check_tables_agree(&s, tables).await;
    assert_eq!(ids.len(), 2);
    let done = s
        .wait_job(b_job, 120, |j| {
            j["status"] == "succeeded" || j["status"] == "failed"
        })
        .await;
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(done["attempts"], 3, "{done}");
    let b = done["table_id"].as_str().unwrap().to_string();
    assert_ne!(a, b);
    assert_eq!(s.ready_table().await.as_deref(), Some(b.as_str()));
    // the interrupted attempt's table stays stored (a table records its training time, so the
    // re-run's file is a new table); all of them agree with their files
    let ids = check_tables_agree(&s, tables).await;
    assert!(ids.contains(&a.to_string()) && ids.contains(&b), "{ids:?}");
    let (_, jobs) = s.get("/v1/training-jobs").await;
    assert_eq!(jobs["items"].as_array().unwrap().len(), 2);
    s.kill9();
    b
}

/// Run 5: the active table's file is corrupted on disk: a clear message at start, the service
/// stays up on the last good table (A), refuses B; restoring the file makes B usable again.
async fn run5_a_corrupt_active_table_file(data: &Path, tables: &Path, a: &str, b: &str) {
    let b_path = tables.join(format!("{b}.safetensors"));
    let mut bytes = std::fs::read(&b_path).unwrap();
    let mid = bytes.len() / 2;
    for x in &mut bytes[mid..mid + 16] {
        *x ^= 0xA5;
    }
    std::fs::write(&b_path, &bytes).unwrap();
    let s = Service::start(data, 0).await;
    b_is_reported_corrupt(&s, a, b).await;
    the_corrupt_table_is_refused(&s, a, b).await;
    // restoring the file makes the table usable again
    for x in &mut bytes[mid..mid + 16] {
        *x ^= 0xA5;
    }
    std::fs::write(&b_path, &bytes).unwrap();
    let (st, t) = s
        .post(&format!("/v1/tables/{b}/activate"), &json!({}))
        .await;
    assert_eq!(st, 200, "{t}");
    assert_eq!(t["status"], "ok");
    assert_eq!(s.ready_table().await.as_deref(), Some(b));
    s.kill9();
}

/// A serves, the start logs that the active table B is unusable, and /v1/tables reports B as
/// corrupt.
async fn b_is_reported_corrupt(s: &Service, a: &str, b: &str) {
    assert_eq!(s.ready_table().await.as_deref(), Some(a));
    s.wait_log(&format!("the recorded active table {b} is unusable"), 1, 10)
        .await;
    assert!(s.log_count("is corrupt") >= 1);
    let (_, list) = s.get("/v1/tables").await;
    assert_eq!(list["active_table_id"], a);
    for t in list["items"].as_array().unwrap() {
        if t["id"] == b {
            assert_eq!(t["status"], "corrupt", "{t}");
            assert!(t["status_detail"].as_str().unwrap().contains("SHA-256"));
        } else {
            assert_eq!(t["status"], "ok", "{t}");
            assert_eq!(t["active"], t["id"] == a);
        }
    }
}

/// The corrupt table is refused (409), never served; renders still work on A.
async fn the_corrupt_table_is_refused(s: &Service, a: &str, b: &str) {
    let (st, p) = s
        .post(&format!("/v1/tables/{b}/activate"), &json!({}))
        .await;
    assert_eq!(st, 409, "{p}");
    assert_eq!(p["code"], "conflict");
    let r = reqwest::get(s.url(&format!("/v1/tables/{b}/download")))
        .await
        .unwrap();
    assert_eq!(r.status(), 409);
    let raw: Vec<u8> = (0..64 * 64)
        .flat_map(|i| (1000u16 + i as u16).to_le_bytes())
        .collect();
    let r = reqwest::Client::new()
        .post(s.url("/v1/render?width=64&height=64"))
        .header("content-type", "application/octet-stream")
        .header("accept", "application/octet-stream")
        .body(raw)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["x-l3-table"], a);
}
