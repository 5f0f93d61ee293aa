//! What a client cannot make the service do: read the server's files through a training job,
//! stand in for a catalogue camera's table, see the server's directories in problems, or grow
//! the illuminant registry with renders. And what it can: registered lights in training and
//! evaluations, a lowercase `bearer` scheme, `Accept` type wildcards.

use serde_json::{Value, json};

use crate::service_support::*;

/// A tiny job body with `extra` fields over it.
pub(super) fn job(extra: Value) -> Value {
    let mut body = json!({"scenes": 4, "scene_size": 32, "levels": 4, "patch_size": 3,
        "chroma_classes": 1, "illuminants": ["D65"]});
    for (k, v) in extra.as_object().into_iter().flatten() {
        body[k] = v.clone();
    }
    body
}

/// Gaussian RGB filters for a Bayer design object.
fn gaussian_bayer(name: &str) -> Value {
    let g = |c: f64, s: f64| json!({"gaussian": {"center_nm": c, "sigma_nm": s, "peak": 1.0}});
    json!({"name": name, "cfa": "RG/GB",
        "filters": {"R": g(600.0, 45.0), "G": g(530.0, 40.0), "B": g(445.0, 30.0)}})
}

async fn job_count(server: &l3::service::Server) -> usize {
    let v = json(
        client()
            .get(url(server, "/v1/training-jobs"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    v["items"].as_array().map_or(0, Vec::len)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn training_jobs_read_no_file_of_the_server_and_take_no_camera_name() {
    let data = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(data.path(), None).await;
    let c = client();
    let secret = data.path().join("secret.csv");
    std::fs::write(&secret, "wavelength,value\n400,TOPSECRET\n").unwrap();
    let secret = secret.display().to_string();
    let post = |body: Value| c.post(url(&server, "/v1/training-jobs")).json(&body);
    for light in [format!("csv:{secret}"), "iset:Tungsten".into()] {
        let d = problem_of(
            post(job(json!({"illuminants": [light]}))),
            400,
            "unknown_illuminant",
        )
        .await;
        assert!(d.contains("not accepted over HTTP"), "{d}");
        assert!(!d.contains("TOPSECRET"), "{d}");
    }
    for path in [
        secret.as_str(),
        "../../secret.csv",
        "cameras/../../../secret.csv",
    ] {
        let mut design = gaussian_bayer("evil");
        design["filters"]["R"] = json!({"csv": path, "column": "value"});
        let d = problem_of(post(job(json!({"sensor": design}))), 400, "bad_request").await;
        assert!(
            d.contains("not accepted over HTTP") && d.contains("samples"),
            "{d}"
        );
    }
    // a measured curve given inline reads no file and is taken
    let mut design = gaussian_bayer("my-inline");
    design["filters"]["R"] = json!({"samples": {"wavelength_nm": [400.0, 550.0, 600.0, 700.0],
        "values": [0.01, 0.1, 0.9, 0.5]}});
    let r = post(job(json!({"sensor": design}))).send().await.unwrap();
    assert_eq!(r.status(), 202);
    let mut bad = gaussian_bayer("my-inline");
    bad["filters"]["R"] = json!({"samples": {"wavelength_nm": [400.0, 300.0],
        "values": [0.5, 0.5]}});
    let d = problem_of(post(job(json!({"sensor": bad}))), 400, "bad_request").await;
    assert!(d.contains("increasing"), "{d}");
    // curves that cannot train are refused at submission, as the CLI refuses them at load:
    // a curve in percent, one sampled in µm, a table the spectral data lacks
    for (curve, needle) in [
        (
            json!({"samples": {"wavelength_nm": [400.0, 700.0], "values": [50.0, 50.0]}}),
            "percent",
        ),
        (
            json!({"samples": {"wavelength_nm": [0.4, 0.7], "values": [0.5, 0.5]}}),
            "no response",
        ),
        (json!({"csv": "cam.csv", "column": "R"}), "cam.csv"),
    ] {
        let mut bad = gaussian_bayer("my-inline");
        bad["filters"]["R"] = curve;
        let d = problem_of(post(job(json!({"sensor": bad}))), 400, "bad_request").await;
        assert!(d.contains(needle), "{needle}: {d}");
    }
    // a design object named like a catalogue camera, but not that camera
    let d = problem_of(
        post(job(json!({"sensor": gaussian_bayer("BAYER-SONY-ILCE-9")}))),
        400,
        "bad_request",
    )
    .await;
    assert!(d.contains("\"sensor\": \"bayer-sony-ilce-9\""), "{d}");
    assert_eq!(
        job_count(&server).await,
        1,
        "only the inline design's job is created"
    );
    // the catalogue's own design (its curves a table of the spectral data) is that sensor
    let sensor = json(
        c.get(url(&server, "/v1/sensors/bayer-sony-ilce-9"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    let r = post(job(json!({"sensor": sensor["design"].clone()})))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    server.shutdown().await.unwrap();
}

/// A table counts for a catalogue camera only when its design is the catalogue's: a table
/// whose design merely took the name (stored before submissions refused it) does not.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_a_table_of_the_catalogue_design_serves_a_camera() {
    let data = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(data.path(), None).await;
    let c = client();
    let name = "bayer-sony-ilce-9";
    let trained = || async {
        let v = json(
            c.get(url(&server, &format!("/v1/sensors/{name}")))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert_eq!(v["trained"], v["table_id"].is_string(), "{v}");
        v["table_id"].as_str().map(str::to_string)
    };
    let mut impostor = tiny_table().clone();
    impostor.meta.sensor_name = name.into();
    impostor.meta.seed = 11;
    l3::service::import_table(server.state(), &impostor, false)
        .await
        .unwrap();
    assert_eq!(trained().await, None);
    let design = l3::camera::catalogue::find(name).unwrap().design().unwrap();
    let mut real = impostor.clone();
    real.meta.sensor = serde_json::to_value(&design).unwrap();
    real.meta.seed = 12;
    let id = l3::service::import_table(server.state(), &real, false)
        .await
        .unwrap();
    assert_eq!(trained().await, Some(id));
    server.shutdown().await.unwrap();
}

/// Registered lights with a spectrum train and evaluate; a matrix-only one is a 422 saying
/// why; an unknown name a 400 listing what is taken (the user's lights, no files).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn registered_lights_in_training_and_evaluations() {
    let data = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(data.path(), None).await;
    let c = client();
    for (name, def) in [
        ("myl", json!({"cct": 3200})),
        (
            "mat1",
            json!({"matrix": [[0.6, 0.2, 0.3], [-0.3, 1.25, 0.15], [0.08, -0.12, 2.5]]}),
        ),
    ] {
        let r = c
            .put(url(&server, &format!("/v1/illuminants/{name}")))
            .json(&def)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 201);
    }
    let eval = |light: &str| {
        c.post(url(&server, "/v1/evaluations"))
            .json(&json!({"acquisition_illuminant": light, "patch_px": 8}))
    };
    let r = eval("myl").send().await.unwrap();
    assert_eq!(r.status(), 201, "{}", r.text().await.unwrap());
    let d = problem_of(eval("mat1"), 422, "unprocessable").await;
    assert!(d.contains("matrix"), "{d}");
    let d = problem_of(eval("nope"), 400, "unknown_illuminant").await;
    assert!(
        d.contains("myl") && !d.contains("csv:") && !d.contains("mat1"),
        "{d}"
    );
    let r = c
        .post(url(&server, "/v1/training-jobs"))
        .json(&job(json!({"illuminants": ["myl"]})))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let v = json(r).await;
    assert_eq!(v["request"]["illuminants"], json!(["cct:3200"]));
    let done = wait_job(&server, v["id"].as_str().unwrap(), 120.0, |j| {
        j["status"] != "queued" && j["status"] != "running"
    })
    .await;
    assert_eq!(done["status"], "succeeded", "{done}");
    // a finished job links to its table, and has nothing to cancel
    let table = done["table_id"].as_str().unwrap();
    assert_eq!(done["links"]["table"], format!("/v1/tables/{table}"));
    assert!(done["links"].get("cancel").is_none(), "{done}");
    let r = c
        .post(url(&server, "/v1/training-jobs"))
        .json(&job(json!({"illuminants": ["mat1"]})))
        .send()
        .await
        .unwrap();
    problem(r, 422, "unprocessable").await;
    server.shutdown().await.unwrap();
}

/// Renders with computed lights leave the registry as it was; the correction header says
/// what was applied.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn renders_leave_the_registry_alone_and_report_the_applied_correction() {
    let data = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(data.path(), None).await;
    let c = client();
    let count = || async {
        let v = json(c.get(url(&server, "/v1/illuminants")).send().await.unwrap()).await;
        v["items"].as_array().unwrap().len()
    };
    let before = count().await;
    let render = |query: String| {
        c.post(url(
            &server,
            &format!("/v1/render?width=16&height=16&{query}"),
        ))
        .header("content-type", "application/octet-stream")
        .body(gradient_raw(16, 16))
    };
    for light in ["cct:5001", "cct:5002", "xy:0.3,0.4"] {
        let r = render(format!("illuminant={light}")).send().await.unwrap();
        assert_eq!(r.status(), 200);
    }
    let r = render(String::new()).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(count().await, before);
    problem_of(
        c.get(url(&server, "/v1/illuminants/cct:5001")),
        404,
        "not_found",
    )
    .await;
    let r = c
        .put(url(&server, "/v1/illuminants/mat1"))
        .json(&json!({"matrix": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    for (query, applied) in [
        ("illuminant=mat1&correction=camera", "colorimetric"),
        ("illuminant=A&correction=camera", "camera"),
        ("illuminant=A&correction=colorimetric", "colorimetric"),
    ] {
        let r = render(query.into()).send().await.unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(r.headers()["x-l3-correction"], applied, "{query}");
    }
    server.shutdown().await.unwrap();
}

/// A lowercase `bearer` scheme, `Accept: application/*`, a path that is not UTF-8, and a
/// corrupt table's 409 that names no directory of the server.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn protocol_details() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.bearer_token = "s3cret".into();
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    let c = client();
    let r = c
        .put(url(&server, "/v1/illuminants/warm"))
        .header("authorization", "bearer s3cret")
        .json(&json!({"cct": 3000}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let r = c
        .post(url(&server, "/v1/render?width=16&height=16"))
        .header("content-type", "application/octet-stream")
        .header("accept", "application/*")
        .body(gradient_raw(16, 16))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "application/octet-stream");
    problem_of(
        c.get(url(&server, "/v1/illuminants/%FF")),
        400,
        "bad_request",
    )
    .await;
    let render = |query: &str| {
        c.post(url(
            &server,
            &format!("/v1/render?width=16&height=16&{query}"),
        ))
        .header("content-type", "application/octet-stream")
        .body(gradient_raw(16, 16))
    };
    // a malformed CFA (no rectangular tile, a channel the table's sensor does not have, a
    // single channel) is the query's mistake; the table's channels otherwise arranged, a
    // mismatch
    for (cfa, needle) in [
        ("RG/G", "rectangular"),
        ("XX/YY", "X, Y are not channels of the table's sensor"),
        ("RG/BY", "Y is not a channel"),
        ("R", "one channel"),
    ] {
        let d = problem_of(render(&format!("cfa={cfa}")), 400, "bad_request").await;
        assert!(
            d.starts_with(&format!("cfa '{cfa}': ")) && d.contains(needle),
            "{d}"
        );
    }
    for cfa in ["RG/GB", "BW/GR"] {
        problem_of(render(&format!("cfa={cfa}")), 422, "cfa_mismatch").await;
    }
    let r = render("cfa=rg/wb").send().await.unwrap();
    assert_eq!(r.status(), 200, "the table's own CFA, however cased");
    let d = problem_of(render("correction=foo"), 400, "bad_request").await;
    assert!(
        d.ends_with("expected camera or colorimetric (also written t)"),
        "{d}"
    );
    // a table file corrupted on disk: 409, its detail without the data directory
    let mut other = tiny_table().clone();
    other.meta.seed = 13;
    let id = l3::service::import_table(server.state(), &other, false)
        .await
        .unwrap();
    corrupt_stored_table(data.path(), &id).await;
    let d = problem_of(
        c.get(url(&server, &format!("/v1/tables/{id}/download"))),
        409,
        "conflict",
    )
    .await;
    let dir = data.path().display().to_string();
    assert!(!d.contains(&dir) && d.contains(&id), "{d}");
    server.shutdown().await.unwrap();
}

/// Overwrites table `id`'s stored bytes: its file, and on PostgreSQL (where replicas read the
/// bytes from the database) its `content` column too.
async fn corrupt_stored_table(data: &std::path::Path, id: &str) {
    let file = data.join("tables").join(format!("{id}.safetensors"));
    std::fs::write(&file, b"not a table").unwrap();
    if let Some(url) = pg::test_database_url(data) {
        let store = l3::service::Store::connect(&url, data).await.unwrap();
        let l3::service::Store::Postgres(pool) = &store else {
            panic!("{url} is not PostgreSQL")
        };
        let done = sqlx::query("UPDATE l3_tables SET content = $1 WHERE id = $2")
            .bind(&b"not a table"[..])
            .bind(id)
            .execute(pool)
            .await
            .unwrap();
        assert_eq!(done.rows_affected(), 1);
    }
}

/// A restart serves the recorded active table without stamping a new activation time.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restart_is_not_an_activation() {
    let data = tempfile::tempdir().unwrap();
    let (server, id) = server_with_table(data.path(), None).await;
    let stamp = |server: &l3::service::Server| {
        let u = url(server, &format!("/v1/tables/{id}"));
        async move { json(client().get(u).send().await.unwrap()).await["last_activated_at_ms"].clone() }
    };
    let before = stamp(&server).await;
    assert!(before.is_i64(), "{before}");
    server.shutdown().await.unwrap();
    tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    let v = json(client().get(url(&server, "/readyz")).send().await.unwrap()).await;
    assert_eq!(v["table_id"], id.as_str());
    assert_eq!(stamp(&server).await, before);
    server.shutdown().await.unwrap();
}

/// A query size past the pixel limit is refused before the body is read: the answer comes
/// while the declared 200 MB body has barely started.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_oversized_query_is_refused_before_the_body() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let data = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(data.path(), None).await;
    let mut s = tokio::net::TcpStream::connect(server.addr()).await.unwrap();
    let head = "POST /v1/render?width=20000&height=9999 HTTP/1.1\r\nHost: x\r\n\
        Content-Type: application/octet-stream\r\nContent-Length: 200000000\r\n\r\n";
    s.write_all(head.as_bytes()).await.unwrap();
    s.write_all(&[0u8; 1024]).await.unwrap();
    let mut answer = vec![0u8; 4096];
    let n = tokio::time::timeout(std::time::Duration::from_secs(10), s.read(&mut answer))
        .await
        .expect("an answer before the body")
        .unwrap();
    let text = String::from_utf8_lossy(&answer[..n]);
    assert!(text.starts_with("HTTP/1.1 400"), "{text}");
    assert!(
        text.contains("application/problem+json") && text.contains("pixels"),
        "{text}"
    );
    server.shutdown().await.unwrap();
}
