//! Training jobs over HTTP: submit (idempotent) → running with progress → succeeded →
//! activated → used for a render; cancel; restart with a queued and a running job.

use crate::service_support::*;

fn gradient_raw(w: usize, h: usize) -> Vec<u8> {
    (0..w * h)
        .flat_map(|i| ((3000 + (i % w) * 30000 / w) as u16).to_le_bytes())
        .collect()
}

/// The server and client the sections of a job test share.
struct Jobs<'a> {
    server: &'a l3::service::Server,
    c: &'a reqwest::Client,
}

impl Jobs<'_> {
    /// Submits `body` with an idempotency key: 202; the same key and body → the same job;
    /// another body → 409. Returns the job's id.
    async fn submit_idempotently(&self, body: &serde_json::Value) -> String {
        let (c, server) = (self.c, self.server);
        let r = c
            .post(url(server, "/v1/training-jobs"))
            .header("idempotency-key", "k-1")
            .json(body)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 202);
        let loc = r.headers()["location"].to_str().unwrap().to_string();
        let job = json(r).await;
        let id = job["id"].as_str().unwrap().to_string();
        assert_eq!(loc, format!("/v1/training-jobs/{id}"));
        assert!(["queued", "running"].contains(&job["status"].as_str().unwrap()));
        // the same key and body → the same job; another body → 409
        let r = c
            .post(url(server, "/v1/training-jobs"))
            .header("idempotency-key", "k-1")
            .json(body)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(json(r).await["id"], id.as_str());
        let mut other = body.clone();
        other["seed"] = 6.into();
        let r = c
            .post(url(server, "/v1/training-jobs"))
            .header("idempotency-key", "k-1")
            .json(&other)
            .send()
            .await
            .unwrap();
        problem(r, 409, "conflict").await;
        id
    }

    /// Observes the job running with progress, then succeeded; returns its table's id.
    async fn runs_with_progress_and_succeeds(&self, id: &str) -> String {
        let server = self.server;
        let running = wait_job(server, id, 60.0, |j| {
            j["status"] != "queued"
                && (j["status"] != "running" || j["progress"].as_f64().unwrap() > 0.0)
        })
        .await;
        assert_eq!(running["status"], "running", "{running}");
        let p = running["progress"].as_f64().unwrap();
        assert!(p > 0.0 && p <= 1.0, "{running}");
        assert!(running["stage"].is_string());
        let done = wait_job(server, id, 120.0, |j| j["status"] != "running").await;
        assert_eq!(done["status"], "succeeded", "{done}");
        assert_eq!(done["progress"], 1.0);
        assert_eq!(done["attempts"], 1);
        assert!(done["timings"]["running_ms"].as_i64().unwrap() >= 0);
        done["table_id"].as_str().unwrap().to_string()
    }

    /// The job's table is activated and used for a render.
    async fn activated_and_used_for_a_render(&self, id: &str, table_id: &str) {
        let (c, server) = (self.c, self.server);
        let v = json(c.get(url(server, "/readyz")).send().await.unwrap()).await;
        assert_eq!(v["table_id"], table_id);
        let t = json(
            c.get(url(server, &format!("/v1/tables/{table_id}")))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert_eq!(t["job_id"], id);
        assert_eq!(t["train_illuminants"], serde_json::json!(["D65", "A"]));
        let r = c
            .post(url(server, "/v1/render?width=32&height=32&illuminant=A"))
            .header("content-type", "application/octet-stream")
            .body(gradient_raw(32, 32))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(r.headers()["x-l3-table"], table_id);
    }

    /// Listing and filtering the jobs, the job metric, and a finished job cannot be canceled.
    async fn listed_counted_and_not_cancelable(&self, id: &str) {
        let (c, server) = (self.c, self.server);
        let v = json(
            c.get(url(server, "/v1/training-jobs?status=succeeded"))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert_eq!(v["items"].as_array().unwrap().len(), 1);
        let v = json(
            c.get(url(server, "/v1/training-jobs?status=queued"))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert!(v["items"].as_array().unwrap().is_empty());
        problem_of(
            c.get(url(server, "/v1/training-jobs?status=lost")),
            400,
            "bad_request",
        )
        .await;
        problem_of(
            c.get(url(server, "/v1/training-jobs/job_nope")),
            404,
            "not_found",
        )
        .await;
        let text = c
            .get(url(server, "/metrics"))
            .send()
            .await
            .unwrap()
            .text()
            .await
            .unwrap();
        assert!(
            text.contains("l3_training_jobs{state=\"succeeded\"} 1"),
            "{text}"
        );
        // a finished job cannot be canceled
        problem_of(
            c.post(url(server, &format!("/v1/training-jobs/{id}/cancel"))),
            409,
            "conflict",
        )
        .await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn job_runs_with_progress_succeeds_activates_and_renders() {
    let data = tempfile::tempdir().unwrap();
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    let c = client();
    let jobs = Jobs {
        server: &server,
        c: &c,
    };
    let mut body = tiny_job_json(&["D65", "A"], 5);
    body["scenes"] = 8.into();
    body["activate"] = true.into();
    let id = jobs.submit_idempotently(&body).await;
    let table_id = jobs.runs_with_progress_and_succeeds(&id).await;
    jobs.activated_and_used_for_a_render(&id, &table_id).await;
    jobs.listed_counted_and_not_cancelable(&id).await;
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn running_and_queued_jobs_are_canceled() {
    let data = tempfile::tempdir().unwrap();
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    let c = client();
    // a long job and one queued behind it
    let mut long = tiny_job_json(&["D65"], 1);
    long["scenes"] = 2000.into();
    long["scene_size"] = 96.into();
    let a = json(
        c.post(url(&server, "/v1/training-jobs"))
            .json(&long)
            .send()
            .await
            .unwrap(),
    )
    .await;
    let b = json(
        c.post(url(&server, "/v1/training-jobs"))
            .json(&tiny_job_json(&["D65"], 2))
            .send()
            .await
            .unwrap(),
    )
    .await;
    let (a, b) = (
        a["id"].as_str().unwrap().to_string(),
        b["id"].as_str().unwrap().to_string(),
    );
    let ja = wait_job(&server, &a, 30.0, |j| j["status"] == "running").await;
    assert_eq!(ja["status"], "running");
    // the queued one is canceled at once
    let jb = json(
        c.post(url(&server, &format!("/v1/training-jobs/{b}/cancel")))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(jb["status"], "canceled");
    // the running one within a second or so
    let t0 = std::time::Instant::now();
    let ja = json(
        c.post(url(&server, &format!("/v1/training-jobs/{a}/cancel")))
            .send()
            .await
            .unwrap(),
    )
    .await;
    let waited = t0.elapsed().as_secs_f64();
    assert_eq!(ja["status"], "canceled", "after {waited:.2} s: {ja}");
    println!("running job canceled in {waited:.3} s");
    assert!(ja["table_id"].is_null());
    let v = json(
        c.get(url(&server, "/v1/training-jobs?status=canceled"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(v["items"].as_array().unwrap().len(), 2);
    let v = json(c.get(url(&server, "/v1/tables")).send().await.unwrap()).await;
    assert!(v["items"].as_array().unwrap().is_empty());
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restart_resumes_a_running_and_a_queued_job() {
    let data = tempfile::tempdir().unwrap();
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    let c = client();
    let mut first = tiny_job_json(&["D65"], 11);
    first["scenes"] = 40.into();
    let a = json(
        c.post(url(&server, "/v1/training-jobs"))
            .json(&first)
            .send()
            .await
            .unwrap(),
    )
    .await;
    let b = json(
        c.post(url(&server, "/v1/training-jobs"))
            .json(&tiny_job_json(&["D65"], 12))
            .send()
            .await
            .unwrap(),
    )
    .await;
    let (a, b) = (
        a["id"].as_str().unwrap().to_string(),
        b["id"].as_str().unwrap().to_string(),
    );
    let ja = wait_job(&server, &a, 30.0, |j| j["status"] == "running").await;
    assert_eq!(ja["status"], "running");
    let jb = json(
        c.get(url(&server, &format!("/v1/training-jobs/{b}")))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(jb["status"], "queued");
    server.shutdown().await.unwrap();
    // simulate a crash in the middle of job a: the database says it is still running
    {
        let cfg = test_config(data.path());
        let store = l3::service::Store::connect(&cfg.data.database_url, data.path())
            .await
            .unwrap();
        let job = store.job(&a).await.unwrap().unwrap();
        assert_eq!(
            job.status,
            l3::service::JobStatus::Queued,
            "a graceful shutdown re-queues the running job"
        );
        const CRASHED: &str = "UPDATE training_jobs SET status = 'running' WHERE id = $1";
        match &store {
            l3::service::Store::Sqlite(p) => {
                sqlx::query(CRASHED).bind(&a).execute(p).await.unwrap();
            }
            l3::service::Store::Postgres(p) => {
                sqlx::query(CRASHED).bind(&a).execute(p).await.unwrap();
            }
        }
        store.close().await;
    }
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    for id in [&a, &b] {
        let j = wait_job(&server, id, 120.0, |j| {
            !["queued", "running"].contains(&j["status"].as_str().unwrap())
        })
        .await;
        assert_eq!(j["status"], "succeeded", "{j}");
        assert!(j["table_id"].is_string());
    }
    let ja = json(
        c.get(url(&server, &format!("/v1/training-jobs/{a}")))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(ja["attempts"], 2, "{ja}");
    let v = json(c.get(url(&server, "/v1/tables")).send().await.unwrap()).await;
    assert_eq!(v["items"].as_array().unwrap().len(), 2);
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn first_start_trains_and_activates_the_default_table() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.training.auto_train_default = true;
    // keep the default table tiny for the test
    for (k, v) in [("scenes", 4), ("scene_size", 48), ("levels", 10)] {
        cfg.training
            .default_spec
            .insert(k.into(), toml::Value::Integer(v));
    }
    let server = l3::service::start(cfg.clone()).await.unwrap();
    let c = client();
    let r = c.get(url(&server, "/readyz")).send().await.unwrap();
    let status = r.status().as_u16();
    if status == 503 {
        problem_naming(r, 503, "not_ready", &["training job"]).await;
    }
    let jobs = json(
        c.get(url(&server, "/v1/training-jobs"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    let id = jobs["items"][0]["id"].as_str().unwrap().to_string();
    assert_eq!(
        jobs["items"][0]["request"]["illuminants"],
        serde_json::json!(["D65", "Tungsten", "Fluorescent"])
    );
    let j = wait_job(&server, &id, 120.0, |j| {
        j["status"] == "succeeded" || j["status"] == "failed"
    })
    .await;
    assert_eq!(j["status"], "succeeded", "{j}");
    let v = json(c.get(url(&server, "/readyz")).send().await.unwrap()).await;
    assert_eq!(v["table_id"], j["table_id"]);
    server.shutdown().await.unwrap();
    // the next start finds the table and trains nothing
    let server = l3::service::start(cfg).await.unwrap();
    let jobs = json(
        c.get(url(&server, "/v1/training-jobs"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(jobs["items"].as_array().unwrap().len(), 1);
    assert_eq!(
        c.get(url(&server, "/readyz"))
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
    server.shutdown().await.unwrap();
}

/// Submits a job body; returns (status, job JSON).
async fn submit(
    server: &l3::service::Server,
    body: &serde_json::Value,
) -> (u16, serde_json::Value) {
    let r = client()
        .post(url(server, "/v1/training-jobs"))
        .json(body)
        .send()
        .await
        .unwrap();
    let st = r.status().as_u16();
    (st, json(r).await)
}

impl Jobs<'_> {
    /// A shard count out of range: a clear 400.
    async fn shards_out_of_range_are_refused(&self, body: &serde_json::Value) {
        for (n, needle) in [(0, "shards 0: 1 to 4"), (5, "shards 5: 1 to 4")] {
            let mut b = body.clone();
            b["shards"] = n.into();
            let r = self
                .c
                .post(url(self.server, "/v1/training-jobs"))
                .json(&b)
                .send()
                .await
                .unwrap();
            let d = problem(r, 400, "bad_request").await;
            assert!(d.contains(needle), "{d}");
        }
    }

    /// Submits the job in one piece, in 1 shard and in 3; returns the jobs' ids.
    async fn submit_in_one_piece_and_sharded(&self, body: &serde_json::Value) -> Vec<String> {
        let mut ids = Vec::new();
        for shards in [None, Some(1), Some(3)] {
            let mut b = body.clone();
            if let Some(n) = shards {
                b["shards"] = n.into();
            }
            let (st, j) = submit(self.server, &b).await;
            assert_eq!(st, 202, "{j}");
            if let Some(n) = shards {
                assert_eq!(j["shards"]["count"], n, "{j}");
                assert_eq!(j["shards"]["total"], 2 * n, "{j}");
                assert!(j["shards"]["fraction"].as_f64().unwrap() < 1.0, "{j}");
            } else {
                assert!(j.get("shards").is_none(), "{j}");
            }
            ids.push(j["id"].as_str().unwrap().to_string());
        }
        ids
    }

    /// Waits for every job to succeed, checking a sharded one's shards; returns the tables.
    async fn wait_for_the_tables(&self, ids: &[String]) -> Vec<String> {
        let mut tables = Vec::new();
        for id in ids {
            let j = wait_job(self.server, id, 120.0, |j| {
                !["queued", "running"].contains(&j["status"].as_str().unwrap())
            })
            .await;
            assert_eq!(j["status"], "succeeded", "{j}");
            assert_eq!(j["progress"], 1.0, "{j}");
            tables.push(j["table_id"].as_str().unwrap().to_string());
            if let Some(s) = j.get("shards") {
                self.check_the_shards(id, &j, s).await;
            }
        }
        tables
    }

    /// A finished sharded job `j`'s shards `s`: all done, each named with its stage, and one
    /// names its job and is canceled through it.
    async fn check_the_shards(&self, id: &str, j: &serde_json::Value, s: &serde_json::Value) {
        let (c, server) = (self.c, self.server);
        let n = s["count"].as_i64().unwrap();
        assert_eq!(s["done"], 2 * n, "{j}");
        assert_eq!(s["fraction"], 1.0, "{j}");
        assert!(s["merge_ms"].as_i64().unwrap() >= 0, "{j}");
        let items = s["items"].as_array().unwrap();
        assert_eq!(items.len() as i64, 2 * n, "{j}");
        for (k, it) in items.iter().enumerate() {
            let stage = if (k as i64) < n {
                "survey"
            } else {
                "accumulate"
            };
            assert_eq!(it["stage"], stage, "{j}");
            assert_eq!(it["shard"], k as i64 % n + 1, "{j}");
            assert_eq!(it["status"], "succeeded", "{j}");
            assert_eq!(it["attempts"], 1, "{j}");
            assert!(it["compute_ms"].as_i64().unwrap() >= 0, "{j}");
            assert!(it["replica"].is_string(), "{j}");
        }
        // a shard names its job and is canceled through it
        let sid = items[0]["id"].as_str().unwrap();
        let sj = json(
            c.get(url(server, &format!("/v1/training-jobs/{sid}")))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert_eq!(sj["parent_id"], id, "{sj}");
        let r = c
            .post(url(server, &format!("/v1/training-jobs/{sid}/cancel")))
            .send()
            .await
            .unwrap();
        problem(r, 409, "conflict").await;
    }

    /// The table's bytes (named by their SHA-256) are the same in one piece, 1 shard, 3
    /// shards; the list has the jobs, not their shards.
    async fn the_same_table_bytes(&self, tables: &[String]) {
        let (c, server) = (self.c, self.server);
        assert_eq!(tables[1], tables[0]);
        assert_eq!(tables[2], tables[0]);
        let t = json(
            c.get(url(server, &format!("/v1/tables/{}", tables[0])))
                .send()
                .await
                .unwrap(),
        )
        .await;
        let bytes = c
            .get(url(server, &format!("/v1/tables/{}/download", tables[0])))
            .send()
            .await
            .unwrap()
            .bytes()
            .await
            .unwrap();
        assert_eq!(
            l3::service::sha256_hex(&bytes),
            t["sha256"].as_str().unwrap()
        );
        // the list has the jobs, not their shards
        let v = json(
            c.get(url(server, "/v1/training-jobs"))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert_eq!(v["items"].as_array().unwrap().len(), 3, "{v}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sharded_job_gives_the_unsharded_table_bytes() {
    let data = tempfile::tempdir().unwrap();
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    let c = client();
    let jobs = Jobs {
        server: &server,
        c: &c,
    };
    let mut body = tiny_job_json(&["D65"], 21);
    body["reproducible"] = true.into();
    jobs.shards_out_of_range_are_refused(&body).await;
    let ids = jobs.submit_in_one_piece_and_sharded(&body).await;
    let tables = jobs.wait_for_the_tables(&ids).await;
    jobs.the_same_table_bytes(&tables).await;
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sharded_job_is_canceled_with_its_shards() {
    let data = tempfile::tempdir().unwrap();
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    let c = client();
    let mut long = tiny_job_json(&["D65"], 3);
    long["scenes"] = 2000.into();
    long["scene_size"] = 96.into();
    long["shards"] = 2.into();
    let (st, j) = submit(&server, &long).await;
    assert_eq!(st, 202, "{j}");
    let id = j["id"].as_str().unwrap().to_string();
    let j = wait_job(&server, &id, 30.0, |j| {
        j["status"] == "running"
            && j["shards"]["items"]
                .as_array()
                .is_some_and(|i| i.iter().any(|s| s["status"] == "running"))
    })
    .await;
    assert_eq!(j["status"], "running", "{j}");
    let t0 = std::time::Instant::now();
    let j = json(
        c.post(url(&server, &format!("/v1/training-jobs/{id}/cancel")))
            .send()
            .await
            .unwrap(),
    )
    .await;
    let waited = t0.elapsed().as_secs_f64();
    assert_eq!(j["status"], "canceled", "{j}");
    println!("sharded job canceled in {waited:.3} s");
    for s in j["shards"]["items"].as_array().unwrap() {
        assert_eq!(s["status"], "canceled", "after {waited:.2} s: {j}");
    }
    // canceled again: 409
    let r = c
        .post(url(&server, &format!("/v1/training-jobs/{id}/cancel")))
        .send()
        .await
        .unwrap();
    problem(r, 409, "conflict").await;
    let v = json(c.get(url(&server, "/v1/tables")).send().await.unwrap()).await;
    assert!(v["items"].as_array().unwrap().is_empty());
    server.shutdown().await.unwrap();
}
