//! Two `l3 serve` replicas on one PostgreSQL database (started by the test: initdb + pg_ctl,
//! skipped with a reason where PostgreSQL is not installed, failing under CI): a job runs
//! exactly once on either replica; kill -9 of the replica running a job and the other takes
//! it over after the lease; an activation through one replica is used by a render on the
//! other within a second; an illuminant PUT on one resolves on the other; 20 jobs submitted to
//! both at once each run exactly once; the default table is trained once per cluster, and a
//! replica caches table bytes from the database (a damaged cache file is fetched again).

#[path = "../service_support/mod.rs"]
mod service_support;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use service_support::checked_json;
use service_support::pg::PgServer;

/// The lease of the test replicas (seconds): short, so a dead replica's job returns quickly.
const LEASE_S: f64 = 2.0;

/// A running `l3 serve` replica with its captured log lines.
struct Replica {
    name: &'static str,
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

impl Replica {
    /// Starts `l3 serve` on `db` with its own data directory (its table cache) and waits
    /// until it answers /healthz. Built-in spectral data, one background thread.
    async fn start(name: &'static str, db: &str, data: &Path, config: Option<&Path>) -> Replica {
        Replica::start_with(name, db, data, config, &[]).await
    }

    /// [`Replica::start`] with more environment variables (over the ones it sets).
    async fn start_with(
        name: &'static str,
        db: &str,
        data: &Path,
        config: Option<&Path>,
        envs: &[(&str, String)],
    ) -> Replica {
        let port = free_port();
        let mut cmd = Command::new(env!("L3_BIN"));
        cmd.arg("serve");
        if let Some(c) = config {
            cmd.arg("--config").arg(c);
        }
        cmd.env("L3_BIND", format!("127.0.0.1:{port}"))
            .env("L3_DATA_DIR", data)
            .env("L3_DATABASE_URL", db)
            .env("L3_JOB_LEASE_S", LEASE_S.to_string())
            .env(
                "L3_AUTO_TRAIN",
                if config.is_some() { "true" } else { "false" },
            )
            .env("L3_BACKGROUND_THREADS", "1")
            .env("L3_RENDER_THREADS", "1")
            .env("L3_LOG_FORMAT", "text")
            .env("L3_LOG", "info,sqlx=warn")
            .env("NO_COLOR", "1")
            .env("L3_ISET_DIR", data.join("no-iset"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        for (k, v) in envs {
            cmd.env(k, v);
        }
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
        let r = Replica {
            name,
            child,
            base: format!("http://127.0.0.1:{port}"),
            log,
        };
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Ok(resp) = reqwest::get(r.url("/healthz")).await
                && resp.status() == 200
            {
                return r;
            }
            assert!(
                Instant::now() < deadline,
                "replica {name} did not start:\n{}",
                r.log_text()
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    fn log_text(&self) -> String {
        format!(
            "--- {}:\n{}",
            self.name,
            self.log.lock().unwrap().join("\n")
        )
    }

    /// Log lines containing all of `needles`.
    fn log_count(&self, needles: &[&str]) -> usize {
        self.log
            .lock()
            .unwrap()
            .iter()
            .filter(|l| needles.iter().all(|n| l.contains(n)))
            .count()
    }

    fn kill9(mut self) {
        self.child.kill().expect("SIGKILL");
        self.child.wait().expect("reap");
    }

    async fn get(&self, path: &str) -> (u16, Value) {
        let r = reqwest::get(self.url(path)).await.expect("GET");
        checked_json("GET", r).await
    }

    async fn send(&self, method: reqwest::Method, path: &str, body: &Value) -> (u16, Value) {
        let r = reqwest::Client::new()
            .request(method.clone(), self.url(path))
            .json(body)
            .send()
            .await
            .expect("request");
        checked_json(method.as_str(), r).await
    }

    async fn post(&self, path: &str, body: &Value) -> (u16, Value) {
        self.send(reqwest::Method::POST, path, body).await
    }

    /// Submits a job; returns its id.
    async fn submit(&self, body: Value) -> String {
        let (st, j) = self.post("/v1/training-jobs", &body).await;
        assert_eq!(st, 202, "{j}");
        j["id"].as_str().unwrap().to_string()
    }

    /// Polls a job until `done(job)`; panics with the logs after `secs`.
    async fn wait_job(
        &self,
        others: &[&Replica],
        id: &str,
        secs: u64,
        done: impl Fn(&Value) -> bool,
    ) -> Value {
        let deadline = Instant::now() + Duration::from_secs(secs);
        loop {
            let (_, j) = self.get(&format!("/v1/training-jobs/{id}")).await;
            if done(&j) {
                return j;
            }
            assert!(
                Instant::now() < deadline,
                "job {id} never reached the state: {j}\n{}\n{}",
                self.log_text(),
                others.iter().map(|r| r.log_text()).collect::<String>()
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    async fn ready_table(&self) -> Option<String> {
        let (s, v) = self.get("/readyz").await;
        (s == 200).then(|| v["table_id"].as_str().unwrap_or_default().to_string())
    }

    /// Renders a small frame; returns the table it used.
    async fn render_table(&self, illuminant: &str) -> (u16, String) {
        let raw: Vec<u8> = (0..64 * 64)
            .flat_map(|i| (1000 + (i % 64) as u16 * 500).to_le_bytes())
            .collect();
        let r = reqwest::Client::new()
            .post(self.url(&format!(
                "/v1/render?width=64&height=64&illuminant={illuminant}"
            )))
            .header("content-type", "application/octet-stream")
            .header("accept", "application/octet-stream")
            .body(raw)
            .send()
            .await
            .unwrap();
        let st = r.status().as_u16();
        let t = r
            .headers()
            .get("x-l3-table")
            .and_then(|v| v.to_str().ok())
            .unwrap_or_default()
            .to_string();
        (st, t)
    }
}

impl Drop for Replica {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A tiny, fast training job.
fn job_body(seed: u64, scenes: u64, activate: bool) -> Value {
    json!({
        "illuminants": ["D65"],
        "scenes": scenes,
        "scene_size": 32,
        "levels": 6,
        "seed": seed,
        "activate": activate,
    })
}

/// The PostgreSQL server and two replicas on it.
async fn cluster(test: &str) -> Option<(PgServer, tempfile::TempDir, Replica, Replica)> {
    let pg = PgServer::start(test)?;
    let data = tempfile::tempdir().unwrap();
    let a = Replica::start("A", &pg.url(), &data.path().join("a"), None).await;
    let b = Replica::start("B", &pg.url(), &data.path().join("b"), None).await;
    Some((pg, data, a, b))
}

/// How many replicas logged the start of `job`, and how often in all.
fn starts(replicas: &[&Replica], job: &str) -> usize {
    replicas
        .iter()
        .map(|r| r.log_count(&["training job started", job]))
        .sum()
}

/// Polls `check` every 5 ms until it holds; returns the time it took (panics after `secs`).
async fn within<F, Fut>(secs: f64, what: &str, mut check: F) -> Duration
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = bool>,
{
    let t0 = Instant::now();
    loop {
        if check().await {
            return t0.elapsed();
        }
        assert!(
            t0.elapsed().as_secs_f64() < secs,
            "{what}: not within {secs} s"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_runs_once_and_activation_and_illuminants_propagate() {
    let Some((_pg, _data, a, b)) =
        cluster("a_job_runs_once_and_activation_and_illuminants_propagate").await
    else {
        return;
    };
    // a job submitted to A runs exactly once, on either replica, and its activation reaches both
    let first = a.submit(job_body(1, 3, true)).await;
    let j = b
        .wait_job(&[&a], &first, 120, |j| {
            j["status"] == "succeeded" || j["status"] == "failed"
        })
        .await;
    assert_eq!(j["status"], "succeeded", "{j}");
    assert_eq!(j["attempts"], 1, "{j}");
    assert_eq!(starts(&[&a, &b], &first), 1);
    let t1 = j["table_id"].as_str().unwrap().to_string();
    for r in [&a, &b] {
        within(1.0, "the first table active on both", || async {
            r.ready_table().await.as_deref() == Some(t1.as_str())
        })
        .await;
    }
    // a second table, not activated
    let second = b.submit(job_body(2, 3, false)).await;
    let j = a
        .wait_job(&[&b], &second, 120, |j| {
            j["status"] == "succeeded" || j["status"] == "failed"
        })
        .await;
    assert_eq!(j["status"], "succeeded", "{j}");
    let t2 = j["table_id"].as_str().unwrap().to_string();
    assert_ne!(t1, t2);
    assert_eq!(b.render_table("D65").await, (200, t1.clone()));
    // activation through A is used by a render on B within a second
    let (st, v) = a
        .post(&format!("/v1/tables/{t2}/activate"), &json!({}))
        .await;
    assert_eq!(st, 200, "{v}");
    let took = within(
        1.0,
        "a render on B with the table activated through A",
        || async { b.render_table("D65").await == (200, t2.clone()) },
    )
    .await;
    println!(
        "activation through A used by a render on B after {:.1} ms",
        took.as_secs_f64() * 1e3
    );
    // an illuminant PUT on B resolves on A within a second
    let (st, v) = b
        .send(
            reqwest::Method::PUT,
            "/v1/illuminants/Studio3200",
            &json!({"cct": 3200}),
        )
        .await;
    assert_eq!(st, 201, "{v}");
    let took = within(1.0, "the illuminant put on B resolving on A", || async {
        a.render_table("Studio3200").await.0 == 200
    })
    .await;
    println!(
        "illuminant PUT on B resolved on A after {:.1} ms",
        took.as_secs_f64() * 1e3
    );
    let (st, v) = a.get("/v1/illuminants/Studio3200").await;
    assert_eq!(st, 200, "{v}");
    assert_eq!(v["user_defined"], true);
    // and its deletion through A reaches B
    let r = reqwest::Client::new()
        .delete(a.url("/v1/illuminants/Studio3200"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);
    within(1.0, "the deletion through A reaching B", || async {
        b.get("/v1/illuminants/Studio3200").await.0 == 404
    })
    .await;
    // a cancel through B stops a job A runs (or the other way round) within a second or so
    let long = a.submit(job_body(3, 400, false)).await;
    a.wait_job(&[&b], &long, 60, |j| j["status"] == "running")
        .await;
    let runner_is_a = a.log_count(&["training job started", &long]) == 1;
    let other = if runner_is_a { &b } else { &a };
    let t0 = Instant::now();
    let (st, j) = other
        .post(&format!("/v1/training-jobs/{long}/cancel"), &json!({}))
        .await;
    assert_eq!(st, 200, "{j}");
    assert_eq!(j["status"], "canceled", "{j}");
    println!(
        "a job canceled through the other replica in {:.0} ms",
        t0.elapsed().as_secs_f64() * 1e3
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill9_of_the_replica_running_a_job_and_the_other_completes_it() {
    let Some((_pg, _data, a, b)) =
        cluster("kill9_of_the_replica_running_a_job_and_the_other_completes_it").await
    else {
        return;
    };
    let id = a.submit(job_body(4, 40, false)).await;
    a.wait_job(&[&b], &id, 60, |j| j["status"] == "running")
        .await;
    let (victim, survivor) = if a.log_count(&["training job started", &id]) == 1 {
        (a, b)
    } else {
        (b, a)
    };
    println!("replica {} runs the job; kill -9", victim.name);
    victim.kill9();
    let t0 = Instant::now();
    let j = survivor
        .wait_job(&[], &id, 60, |j| {
            j["attempts"] == 2 && j["status"] == "running"
        })
        .await;
    let reclaimed = t0.elapsed();
    assert!(j["stage"].is_string());
    let j = survivor
        .wait_job(&[], &id, 120, |j| {
            j["status"] == "succeeded" || j["status"] == "failed"
        })
        .await;
    assert_eq!(j["status"], "succeeded", "{j}");
    assert_eq!(j["attempts"], 2, "{j}");
    assert_eq!(survivor.log_count(&["training job started", &id]), 1);
    println!(
        "re-claimed by replica {} {:.2} s after the kill (lease {LEASE_S} s); finished after {:.2} s",
        survivor.name,
        reclaimed.as_secs_f64(),
        t0.elapsed().as_secs_f64()
    );
    assert!(
        reclaimed.as_secs_f64() < LEASE_S + 2.0,
        "re-claimed after {reclaimed:?}"
    );
    let (_, v) = survivor.get("/v1/tables").await;
    assert_eq!(v["items"].as_array().unwrap().len(), 1, "{v}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn twenty_jobs_submitted_to_both_at_once_each_run_exactly_once() {
    let Some((_pg, _data, a, b)) =
        cluster("twenty_jobs_submitted_to_both_at_once_each_run_exactly_once").await
    else {
        return;
    };
    let (ids_a, ids_b) = tokio::join!(
        futures_util::future::join_all((0..10).map(|i| a.submit(job_body(100 + i, 1, false)))),
        futures_util::future::join_all((10..20).map(|i| b.submit(job_body(100 + i, 1, false)))),
    );
    let ids: Vec<String> = ids_a.into_iter().chain(ids_b).collect();
    let t0 = Instant::now();
    for id in &ids {
        let j = a
            .wait_job(&[&b], id, 300, |j| {
                !["queued", "running"].contains(&j["status"].as_str().unwrap_or("queued"))
            })
            .await;
        assert_eq!(j["status"], "succeeded", "{j}");
        assert_eq!(j["attempts"], 1, "{j}");
        assert_eq!(starts(&[&a, &b], id), 1, "job {id}");
    }
    let on_a = ids
        .iter()
        .filter(|id| a.log_count(&["training job started", id]) == 1)
        .count();
    println!(
        "20 jobs in {:.1} s: {on_a} on A, {} on B",
        t0.elapsed().as_secs_f64(),
        20 - on_a
    );
    let (_, v) = b.get("/v1/training-jobs?status=succeeded").await;
    assert_eq!(v["items"].as_array().unwrap().len(), 20);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_default_table_is_trained_once_per_cluster() {
    let Some(pg) = PgServer::start("the_default_table_is_trained_once_per_cluster") else {
        return;
    };
    let data = tempfile::tempdir().unwrap();
    let config = data.path().join("tiny-default.toml");
    std::fs::write(
        &config,
        "[training.default_spec]\nscenes = 2\nscene_size = 32\nlevels = 6\n",
    )
    .unwrap();
    let (url, dir_a, dir_b) = (pg.url(), data.path().join("a"), data.path().join("b"));
    let (a, b) = tokio::join!(
        Replica::start("A", &url, &dir_a, Some(&config)),
        Replica::start("B", &url, &dir_b, Some(&config)),
    );
    let (_, v) = a.get("/v1/training-jobs").await;
    let items = v["items"].as_array().unwrap();
    assert_eq!(items.len(), 1, "{v}");
    let id = items[0]["id"].as_str().unwrap().to_string();
    let j = b
        .wait_job(&[&a], &id, 120, |j| {
            j["status"] == "succeeded" || j["status"] == "failed"
        })
        .await;
    assert_eq!(j["status"], "succeeded", "{j}");
    let t = j["table_id"].as_str().unwrap().to_string();
    for r in [&a, &b] {
        within(1.0, "the default table active on both", || async {
            r.ready_table().await.as_deref() == Some(t.as_str())
        })
        .await;
    }
    // a replica joining later trains nothing
    let c = Replica::start("C", &pg.url(), &data.path().join("c"), Some(&config)).await;
    assert_eq!(c.ready_table().await.as_deref(), Some(t.as_str()));
    let (_, v) = c.get("/v1/training-jobs").await;
    assert_eq!(v["items"].as_array().unwrap().len(), 1, "{v}");
    // C read the table's bytes from the database and cached them under its id, checked
    let (_, meta) = c.get(&format!("/v1/tables/{t}")).await;
    let cached = std::fs::read(data.path().join(format!("c/tables/{t}.safetensors"))).unwrap();
    assert_eq!(
        l3::service::sha256_hex(&cached),
        meta["sha256"].as_str().unwrap()
    );
    // a damaged cache file is fetched again, not reported corrupt
    std::fs::write(
        data.path().join(format!("c/tables/{t}.safetensors")),
        b"damaged",
    )
    .unwrap();
    let r = reqwest::get(c.url(&format!("/v1/tables/{t}/download")))
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.bytes().await.unwrap().as_ref(), cached.as_slice());
    let (_, meta) = c.get(&format!("/v1/tables/{t}")).await;
    assert_eq!(meta["status"], "ok", "{meta}");
}

/// Shards of a sharded job (its `shards.items`) and the replica each ran on, checking that
/// every shard started exactly once across `replicas`.
fn shards_ran_once(job: &Value, replicas: &[&Replica]) -> Vec<(String, &'static str)> {
    let items = job["shards"]["items"].as_array().expect("shards");
    items
        .iter()
        .map(|s| {
            let id = s["id"].as_str().unwrap();
            let on: Vec<&Replica> = replicas
                .iter()
                .copied()
                .filter(|r| r.log_count(&["training shard started", &format!("shard={id}")]) > 0)
                .collect();
            let runs: usize = replicas
                .iter()
                .map(|r| r.log_count(&["training shard started", &format!("shard={id}")]))
                .sum();
            assert_eq!(runs, 1, "shard {id} started {runs} times: {job}");
            assert_eq!(s["attempts"], 1, "{job}");
            assert_eq!(s["status"], "succeeded", "{job}");
            (id.to_string(), on[0].name)
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_in_two_shards_runs_on_both_replicas_and_gives_the_one_shard_table() {
    let Some((_pg, _data, a, b)) =
        cluster("a_job_in_two_shards_runs_on_both_replicas_and_gives_the_one_shard_table").await
    else {
        return;
    };
    let mut body = job_body(9, 8, false);
    body["reproducible"] = true.into();
    body["shards"] = 2.into();
    let sharded = a.submit(body.clone()).await;
    let done = |j: &Value| j["status"] != "queued" && j["status"] != "running";
    let j = b.wait_job(&[&a], &sharded, 120, done).await;
    assert_eq!(j["status"], "succeeded", "{j}");
    assert_eq!(j["shards"]["done"], 4, "{j}");
    assert_eq!(j["shards"]["fraction"], 1.0, "{j}");
    let ran = shards_ran_once(&j, &[&a, &b]);
    println!(
        "shards: {}; merge {} ms",
        ran.iter()
            .map(|(id, r)| format!("{id} on {r}"))
            .collect::<Vec<_>>()
            .join(", "),
        j["shards"]["merge_ms"]
    );
    // the same job in one shard, on either replica
    body["shards"] = 1.into();
    let one = b.submit(body).await;
    let j1 = a.wait_job(&[&b], &one, 120, done).await;
    assert_eq!(j1["status"], "succeeded", "{j1}");
    shards_ran_once(&j1, &[&a, &b]);
    assert_eq!(j1["table_id"], j["table_id"], "{j1}\n{j}");
    let t = j["table_id"].as_str().unwrap();
    let (_, meta) = a.get(&format!("/v1/tables/{t}")).await;
    let bytes = reqwest::get(b.url(&format!("/v1/tables/{t}/download")))
        .await
        .unwrap()
        .bytes()
        .await
        .unwrap();
    assert_eq!(
        l3::service::sha256_hex(&bytes),
        meta["sha256"].as_str().unwrap()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill9_of_a_replica_running_a_shard_and_the_other_retries_it() {
    let Some((_pg, _data, a, b)) =
        cluster("kill9_of_a_replica_running_a_shard_and_the_other_retries_it").await
    else {
        return;
    };
    let mut body = job_body(10, 40, false);
    body["reproducible"] = true.into();
    body["shards"] = 2.into();
    let id = a.submit(body.clone()).await;
    let running_on_a = |j: &Value| {
        j["shards"]["items"].as_array().is_some_and(|items| {
            items.iter().any(|s| {
                s["status"] == "running" && s["stage"] == "accumulate" && {
                    let sid = s["id"].as_str().unwrap_or_default();
                    a.log_count(&["training shard started", &format!("shard={sid}")]) == 1
                }
            })
        })
    };
    let j = b.wait_job(&[&a], &id, 120, running_on_a).await;
    let victim: Vec<String> = j["shards"]["items"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["status"] == "running" && s["stage"] == "accumulate")
        .map(|s| s["id"].as_str().unwrap().to_string())
        .filter(|sid| a.log_count(&["training shard started", &format!("shard={sid}")]) == 1)
        .collect();
    println!("replica A runs {victim:?}; kill -9");
    a.kill9();
    let done = |j: &Value| j["status"] != "queued" && j["status"] != "running";
    let j = b.wait_job(&[], &id, 120, done).await;
    assert_eq!(j["status"], "succeeded", "{j}");
    for s in j["shards"]["items"].as_array().unwrap() {
        let retried = victim.iter().any(|v| s["id"] == v.as_str());
        assert_eq!(s["attempts"], if retried { 2 } else { 1 }, "{j}");
        assert_eq!(s["status"], "succeeded", "{j}");
    }
    // the same table as the job in one piece
    body.as_object_mut().unwrap().remove("shards");
    let whole = b.submit(body).await;
    let j1 = b.wait_job(&[], &whole, 120, done).await;
    assert_eq!(j1["status"], "succeeded", "{j1}");
    assert_eq!(j1["table_id"], j["table_id"]);
}

/// The figures of the README: one moderately sized job (`L3_SHARD_BENCH_SCENES`, 48 by default,
/// otherwise the default table's spec) unsharded on one replica, in 2 shards on one replica,
/// and in 2 shards on two replicas, `L3_SHARD_BENCH_ROUNDS` times (3) in turn; every replica
/// has a background pool of every core (so two replicas share them). `cargo test --test replicas -- --ignored
/// --nocapture sharding_figures`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "a measurement, about a minute or more"]
async fn sharding_figures() {
    let Some(pg) = PgServer::start("sharding_figures") else {
        return;
    };
    let env = |k: &str, d: u64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let (scenes, rounds) = (
        env("L3_SHARD_BENCH_SCENES", 48),
        env("L3_SHARD_BENCH_ROUNDS", 3),
    );
    let data = tempfile::tempdir().unwrap();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let envs = [
        ("L3_BACKGROUND_THREADS", cores.to_string()),
        ("L3_JOB_LEASE_S", "30".to_string()),
    ];
    let start = |name: &'static str| {
        let (url, dir, envs) = (pg.url(), data.path().join(name), envs.clone());
        async move { Replica::start_with(name, &url, &dir, None, &envs).await }
    };
    let body = |shards: Option<u64>| {
        let mut b = json!({ "scenes": scenes, "reproducible": true });
        if let Some(n) = shards {
            b["shards"] = n.into();
        }
        b
    };
    let a = start("a").await;
    let done = |j: &Value| j["status"] != "queued" && j["status"] != "running";
    let seconds = |j: &Value| {
        (j["finished_at_ms"].as_i64().unwrap() - j["created_at_ms"].as_i64().unwrap()) as f64 / 1e3
    };
    let mut table = None;
    let mut rows = Vec::new();
    let configs = [
        ("one piece, 1 replica", None, false),
        ("2 shards, 1 replica", Some(2), false),
        ("2 shards, 2 replicas", Some(2), true),
    ];
    for round in 0..rounds {
        // each round starts with the next configuration, so that none is always first
        for k in 0..configs.len() {
            let (what, shards, two) = configs[(k + round as usize) % configs.len()];
            let b = if two { Some(start("b").await) } else { None };
            let id = a.submit(body(shards)).await;
            let j = a.wait_job(&[], &id, 1800, done).await;
            assert_eq!(j["status"], "succeeded", "{j}");
            let t = j["table_id"].as_str().unwrap().to_string();
            assert_eq!(table.get_or_insert_with(|| t.clone()), &t, "{j}");
            let mut line = format!("round {} | {what} | {:.2} s", round + 1, seconds(&j));
            if let Some(s) = j.get("shards") {
                for it in s["items"].as_array().unwrap() {
                    let on = if it["replica"] == j["shards"]["items"][0]["replica"] {
                        "r1"
                    } else {
                        "r2"
                    };
                    line.push_str(&format!(
                        " | {} {}: {:.2} s on {on}",
                        it["stage"].as_str().unwrap(),
                        it["shard"],
                        it["compute_ms"].as_f64().unwrap() / 1e3
                    ));
                }
                line.push_str(&format!(
                    " | merge {:.2} s",
                    s["merge_ms"].as_f64().unwrap() / 1e3
                ));
            }
            println!("{line}");
            rows.push((what, seconds(&j)));
            drop(b);
        }
    }
    for what in [
        "one piece, 1 replica",
        "2 shards, 1 replica",
        "2 shards, 2 replicas",
    ] {
        let v: Vec<f64> = rows.iter().filter(|r| r.0 == what).map(|r| r.1).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let base: Vec<f64> = rows
            .iter()
            .filter(|r| r.0 == "one piece, 1 replica")
            .map(|r| r.1)
            .collect();
        let base = base.iter().sum::<f64>() / base.len() as f64;
        println!(
            "{what}: mean {mean:.2} s ({:+.1} % against one piece)",
            (mean / base - 1.0) * 100.0
        );
    }
}
