//! Limits and guards: backpressure (503), the bearer token, /readyz, an injected panic, 504.

use super::decode_png;
use crate::service_support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_render_queued_past_the_longest_wait_gets_503_with_retry_after_and_mutations_need_the_token()
 {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.render_concurrency = 2;
    cfg.server.render_queue_wait_s = 0.3;
    cfg.server.bearer_token = "s3cret".into();
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    let c = client();
    // hold both render slots: a render waits in the queue, then gives up
    let slots = server.state().admission.render_slots.clone();
    let held = slots.clone().try_acquire_many_owned(2).unwrap();
    let r = c
        .post(url(&server, "/v1/render?width=16&height=16"))
        .header("content-type", "application/octet-stream")
        .body(gradient_raw(16, 16))
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["retry-after"], "1");
    problem(r, 503, "overloaded").await;
    drop(held);
    let r = c
        .post(url(&server, "/v1/render?width=16&height=16"))
        .header("content-type", "application/octet-stream")
        .body(gradient_raw(16, 16))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200, "render needs no token");
    // mutations need the bearer token; reads do not
    let body = tiny_job_json(&["D65"], 1);
    let r = c
        .post(url(&server, "/v1/training-jobs"))
        .json(&body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["www-authenticate"], "Bearer");
    problem(r, 401, "unauthorized").await;
    let r = c
        .post(url(&server, "/v1/training-jobs"))
        .bearer_auth("wrong")
        .json(&body)
        .send()
        .await
        .unwrap();
    problem(r, 401, "unauthorized").await;
    let r = c
        .put(url(&server, "/v1/illuminants/X"))
        .json(&serde_json::json!({"cct": 3000}))
        .send()
        .await
        .unwrap();
    problem(r, 401, "unauthorized").await;
    assert_eq!(
        c.get(url(&server, "/v1/tables"))
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
    // a method a route does not serve is 405 with or without the token
    let r = c.delete(url(&server, "/v1/tables")).send().await.unwrap();
    problem(r, 405, "method_not_allowed").await;
    let r = c
        .post(url(&server, "/v1/training-jobs"))
        .bearer_auth("s3cret")
        .json(&body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let id = json(r).await["id"].as_str().unwrap().to_string();
    let r = c
        .post(url(&server, &format!("/v1/training-jobs/{id}/cancel")))
        .bearer_auth("s3cret")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn readyz_is_503_until_a_table_is_active() {
    let data = tempfile::tempdir().unwrap();
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    let c = client();
    let r = c.get(url(&server, "/readyz")).send().await.unwrap();
    assert!(r.headers().contains_key("retry-after"));
    problem(r, 503, "not_ready").await;
    let r = c
        .post(url(&server, "/v1/render?width=16&height=16"))
        .header("content-type", "application/octet-stream")
        .body(gradient_raw(16, 16))
        .send()
        .await
        .unwrap();
    problem(r, 503, "not_ready").await;
    let text = c
        .get(url(&server, "/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(text.contains("l3_ready 0"));
    server.shutdown().await.unwrap();
    // a restart picks the stored table and the user's illuminants up again
    let (server, id) = server_with_table(data.path(), None).await;
    let r = c
        .put(url(&server, "/v1/illuminants/Stage"))
        .json(&serde_json::json!({"cct": 3300}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    server.shutdown().await.unwrap();
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    let v = json(c.get(url(&server, "/readyz")).send().await.unwrap()).await;
    assert_eq!(v["table_id"], id.as_str());
    let v = json(
        c.get(url(&server, "/v1/illuminants/stage"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(v["cct"], 3300.0);
    assert_eq!(v["user_defined"], true);
    server.shutdown().await.unwrap();
}

/// A panic inside a render (injected through the `fault-injection` feature, which only the
/// crate's own tests enable) is a 500 `internal` answer; its render slot is given back and
/// the next render succeeds.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_injected_panic_inside_a_render_is_a_500_and_the_next_render_succeeds() {
    let data = tempfile::tempdir().unwrap();
    let cfg = test_config(data.path());
    let slots = cfg.server.render_concurrency;
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    let c = client();
    let (w, h) = (64, 48);
    let post = |fault: Option<&'static str>| {
        let mut r = c
            .post(url(&server, &format!("/v1/render?width={w}&height={h}")))
            .header("content-type", "application/octet-stream")
            .body(gradient_raw(w, h));
        if let Some(f) = fault {
            r = r.header(l3::service::fault_injection::FAULT_HEADER, f);
        }
        r.send()
    };
    // more panics than there are render slots: each must give its slot back
    for _ in 0..slots + 2 {
        let r = post(Some(l3::service::fault_injection::RENDER_PANIC))
            .await
            .unwrap();
        assert!(r.headers().contains_key("x-request-id"));
        let detail = problem(r, 500, "internal").await;
        assert!(detail.contains("render"), "{detail}");
    }
    // an unknown fault name is no fault
    let r = post(Some("nothing")).await.unwrap();
    assert_eq!(r.status(), 200);
    let r = post(None).await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "image/png");
    let img = decode_png(&r.bytes().await.unwrap());
    assert_eq!(img.dimensions(), (w as u32, h as u32));
    let r = c.get(url(&server, "/healthz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_request_over_the_time_limit_gets_504() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.request_timeout_s = 0.02;
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    // a full-size chart evaluation takes far longer than 20 ms
    let r = client()
        .post(url(&server, "/v1/evaluations"))
        .json(&serde_json::json!({"acquisition_illuminant": "A", "patch_px": 64}))
        .send()
        .await
        .unwrap();
    problem_naming(r, 504, "request_timeout", &["0.02 s"]).await;
    // the evaluation its request gave up on still ends, and is stored for GET to find
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    loop {
        let list: serde_json::Value = client()
            .get(url(&server, "/v1/evaluations"))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        let items = list["items"].as_array().cloned().unwrap_or_default();
        if let Some(e) = items.first() {
            assert_eq!(items.len(), 1, "{list}");
            assert_eq!(e["acquisition_illuminant"], "A", "{e}");
            break;
        }
        assert!(std::time::Instant::now() < deadline, "never stored: {list}");
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    server.shutdown().await.unwrap();
}
