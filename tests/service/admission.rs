//! Admission of renders against a real listener: a slow body gets 408 and holds no render
//! slot; a full queue and a wait past the limit get 503 with Retry-After; a body past the
//! body budget gets 503 before it is read; a render abandoned by its request is canceled.

use std::time::Duration;

use crate::service_support::*;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

fn gradient_raw(w: usize, h: usize) -> Vec<u8> {
    (0..w * h)
        .flat_map(|i| ((i * 97 % 60000) as u16 + 1000).to_le_bytes())
        .collect()
}

/// Opens a connection and sends a render request's head declaring `length` body bytes, then
/// `first` of them.
async fn start_upload(server: &l3::service::Server, length: usize, first: &[u8]) -> TcpStream {
    let head = "POST /v1/render?width=16&height=16";
    start_request(server, head, "application/octet-stream", length, first).await
}

/// Opens a connection and sends `head` ("POST /path") with a body of `ctype` declaring
/// `length` bytes, then `first` of them.
async fn start_request(
    server: &l3::service::Server,
    head: &str,
    ctype: &str,
    length: usize,
    first: &[u8],
) -> TcpStream {
    let mut s = TcpStream::connect(server.addr()).await.unwrap();
    let head = format!(
        "{head} HTTP/1.1\r\nhost: l3\r\ncontent-type: {ctype}\r\ncontent-length: {length}\r\n\r\n"
    );
    s.write_all(head.as_bytes()).await.unwrap();
    s.write_all(first).await.unwrap();
    s
}

/// Reads an HTTP/1.1 answer until the server closes the connection.
async fn read_answer(s: &mut TcpStream) -> String {
    let mut buf = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(30), s.read_to_end(&mut buf)).await;
    String::from_utf8_lossy(&buf).into_owned()
}

async fn render_16(server: &l3::service::Server) -> reqwest::Response {
    client()
        .post(url(server, "/v1/render?width=16&height=16"))
        .header("content-type", "application/octet-stream")
        .body(gradient_raw(16, 16))
        .send()
        .await
        .unwrap()
}

/// Waits (up to 30 s) until `cond` holds.
async fn eventually<F, Fut>(what: &str, cond: F)
where
    F: Fn() -> Fut,
    Fut: std::future::Future<Output = bool>,
{
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while !cond().await {
        assert!(std::time::Instant::now() < deadline, "never: {what}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

async fn metric(server: &l3::service::Server, name: &str) -> f64 {
    let text = client()
        .get(url(server, "/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    text.lines()
        .find_map(|l| l.strip_prefix(&format!("{name} ")))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no metric {name} in\n{text}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slow_body_gets_408_and_holds_no_render_slot() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.render_concurrency = 1;
    cfg.server.body_timeout_s = 2.0;
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    // a body of 512 bytes that stops after 10
    let mut slow = start_upload(&server, 512, &[0; 10]).await;
    // the one render slot is free for everyone else meanwhile
    for _ in 0..3 {
        let r = render_16(&server).await;
        assert_eq!(r.status(), 200);
    }
    let answer = read_answer(&mut slow).await;
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    assert!(answer.contains("application/problem+json"), "{answer}");
    assert!(answer.contains("\"code\":\"body_timeout\""), "{answer}");
    assert_eq!(metric(&server, "l3_render_body_timeouts_total").await, 1.0);
    assert_eq!(render_16(&server).await.status(), 200);
    server.shutdown().await.unwrap();
}

/// The other bodies (a training job, an illuminant, an evaluation's JSON or mosaic) are read
/// under the same rules: a JSON body past its own limit gets 413 before it is sent, a slow
/// one 408, and a mosaic evaluation's body counts against the body budget while it is read.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn job_illuminant_and_evaluation_bodies_are_admitted_as_render_bodies() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.body_timeout_s = 2.0;
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    let json = "application/json";
    let heads = [
        "POST /v1/training-jobs",
        "PUT /v1/illuminants/mine",
        "POST /v1/evaluations",
    ];
    for head in heads {
        let mut s = start_request(&server, head, json, 9 << 20, &[]).await;
        let answer = read_answer(&mut s).await;
        assert!(answer.starts_with("HTTP/1.1 413"), "{head}: {answer}");
        assert!(
            answer.contains("limit of 8388608 bytes"),
            "{head}: {answer}"
        );
    }
    for head in heads {
        let mut s = start_request(&server, head, json, 1000, b"{").await;
        let answer = read_answer(&mut s).await;
        assert!(answer.starts_with("HTTP/1.1 408"), "{head}: {answer}");
        assert!(
            answer.contains("\"code\":\"body_timeout\""),
            "{head}: {answer}"
        );
    }
    assert_eq!(metric(&server, "l3_render_body_timeouts_total").await, 3.0);
    // a ColorChecker frame may be as large as a render's, and is reserved while it is read
    let head = "POST /v1/evaluations?chart=colorchecker&corners=0,0,99,0,99,99,0,99&width=2000&height=2000";
    let frame = start_request(
        &server,
        head,
        "application/octet-stream",
        8_000_000,
        &[0; 64],
    )
    .await;
    eventually("the frame's body is reserved", || async {
        metric(&server, "l3_render_body_bytes_reserved").await >= 8_000_000.0
    })
    .await;
    drop(frame);
    eventually("the reservation returns", || async {
        metric(&server, "l3_render_body_bytes_reserved").await == 0.0
    })
    .await;
    // and a small, prompt body is read as before
    let r = client()
        .put(url(&server, "/v1/illuminants/mine"))
        .header("content-type", json)
        .body(r#"{"cct": 4000}"#)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_queue_and_a_long_wait_get_503_with_retry_after() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.render_concurrency = 1;
    cfg.server.render_queue_depth = 1;
    cfg.server.render_queue_wait_s = 1.0;
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    // every render slot taken
    let held = server
        .state()
        .admission
        .render_slots
        .clone()
        .try_acquire_owned()
        .unwrap();
    let waiting = {
        let url = url(&server, "/v1/render?width=16&height=16");
        tokio::spawn(async move {
            client()
                .post(url)
                .header("content-type", "application/octet-stream")
                .body(gradient_raw(16, 16))
                .send()
                .await
                .unwrap()
        })
    };
    eventually("a request queues", || async {
        server.state().admission.queued() == 1
    })
    .await;
    // the queue (depth 1) is full: refused at once
    let r = render_16(&server).await;
    assert_eq!(r.headers()["retry-after"], "1");
    problem_naming(r, 503, "overloaded", &["waiting"]).await;
    // the one in the queue gives up after the longest wait
    let r = waiting.await.unwrap();
    assert_eq!(r.headers()["retry-after"], "1");
    problem_naming(r, 503, "overloaded", &["within"]).await;
    assert_eq!(server.state().admission.queued(), 0);
    assert_eq!(metric(&server, "l3_render_queue_refusals_total").await, 2.0);
    drop(held);
    assert_eq!(render_16(&server).await.status(), 200);
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn past_the_body_budget_a_body_gets_503_before_it_is_read() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.max_body_bytes = 4096;
    cfg.server.body_budget_bytes = 4096;
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    // one upload holds the whole budget while it trickles
    let first = start_upload(&server, 4096, &[0; 100]).await;
    eventually("the first body is reserved", || async {
        metric(&server, "l3_render_body_bytes_reserved").await >= 4096.0
    })
    .await;
    // a second one is answered without sending a byte of its body
    let mut second = start_upload(&server, 2048, &[]).await;
    let answer = read_answer(&mut second).await;
    assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
    assert!(
        answer.to_ascii_lowercase().contains("retry-after: 1"),
        "{answer}"
    );
    assert!(answer.contains("\"code\":\"overloaded\""), "{answer}");
    assert_eq!(
        metric(&server, "l3_render_budget_refusals_total").await,
        1.0
    );
    // the first one's client leaves: its reservation returns
    drop(first);
    eventually("the reservation returns", || async {
        metric(&server, "l3_render_body_bytes_reserved").await == 0.0
    })
    .await;
    assert_eq!(render_16(&server).await.status(), 200);
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_render_abandoned_by_its_request_is_canceled() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.request_timeout_s = 0.5;
    cfg.server.render_threads = 1;
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    // the render pool's one thread is busy until released
    let (release, wait) = std::sync::mpsc::channel::<()>();
    server.state().pools.render.spawn(move || {
        let _ = wait.recv();
    });
    // three renders at once: one waits for the pool's thread, two for their turn at the CPU
    let (a, b, c) = tokio::join!(render_16(&server), render_16(&server), render_16(&server));
    for r in [a, b, c] {
        problem(r, 504, "request_timeout").await;
    }
    release.send(()).unwrap();
    // the renders, abandoned where they waited, stop without rendering; each counts once
    eventually("the renders are canceled", || async {
        metric(&server, "l3_renders_canceled_total").await == 3.0
    })
    .await;
    assert_eq!(metric(&server, "l3_renders_total").await, 0.0);
    assert_eq!(render_16(&server).await.status(), 200);
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_render_whose_client_leaves_is_canceled() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.render_threads = 1;
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    let (release, wait) = std::sync::mpsc::channel::<()>();
    server.state().pools.render.spawn(move || {
        let _ = wait.recv();
    });
    // a whole request, which passes the gate and waits for the busy render pool
    let body = gradient_raw(16, 16);
    let client_gone = start_upload(&server, body.len(), &body).await;
    eventually("the render waits for the pool", || async {
        server.state().cpu_gate.available_permits() == 0
    })
    .await;
    drop(client_gone);
    // the server notices the closed connection and drops the request (its body reservation
    // returns with it); only then does the pool come free
    eventually("the request is dropped", || async {
        metric(&server, "l3_render_body_bytes_reserved").await == 0.0
    })
    .await;
    release.send(()).unwrap();
    eventually("the render is canceled", || async {
        metric(&server, "l3_renders_canceled_total").await == 1.0
    })
    .await;
    assert_eq!(render_16(&server).await.status(), 200);
    server.shutdown().await.unwrap();
}
