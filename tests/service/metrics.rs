//! `/metrics` through a real listener after a render, read by a Prometheus text-format parser
//! (`prometheus-parse`, as a scraper would): every series dashboards use is there with its
//! type, labels and buckets.

use prometheus_parse::{Sample, Scrape, Value};

use crate::service_support::*;

/// The sample named `name` whose labels include `labels`.
fn sample<'a>(scrape: &'a Scrape, name: &str, labels: &[(&str, &str)]) -> &'a Sample {
    scrape
        .samples
        .iter()
        .find(|s| s.metric == name && labels.iter().all(|(k, v)| s.labels.get(k) == Some(*v)))
        .unwrap_or_else(|| {
            panic!(
                "no {name} {labels:?} among {} samples",
                scrape.samples.len()
            )
        })
}

fn counter(scrape: &Scrape, name: &str, labels: &[(&str, &str)]) -> f64 {
    match sample(scrape, name, labels).value {
        Value::Counter(v) => v,
        ref v => panic!("{name} is no counter: {v:?}"),
    }
}

fn gauge(scrape: &Scrape, name: &str, labels: &[(&str, &str)]) -> f64 {
    match sample(scrape, name, labels).value {
        Value::Gauge(v) => v,
        ref v => panic!("{name} is no gauge: {v:?}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_exposition_parses_with_every_series() {
    let data = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(data.path(), None).await;
    let c = client();
    let r = c
        .post(url(&server, "/v1/render?width=32&height=24&illuminant=D65"))
        .header("content-type", "application/octet-stream")
        .body(gradient_raw(32, 24))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let r = c.get(url(&server, "/metrics")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let ctype = r.headers()["content-type"].to_str().unwrap().to_string();
    assert!(ctype.starts_with("text/plain; version=0.0.4"), "{ctype}");
    let text = r.text().await.unwrap();
    let scrape = Scrape::parse(text.lines().map(|l| Ok(l.to_string()))).unwrap();

    let render = [
        ("method", "POST"),
        ("route", "/v1/render"),
        ("status", "200"),
    ];
    assert_eq!(counter(&scrape, "l3_http_requests_total", &render), 1.0);
    let Value::Histogram(buckets) =
        &sample(&scrape, "l3_http_request_duration_seconds", &render).value
    else {
        panic!("l3_http_request_duration_seconds is no histogram");
    };
    let bounds: Vec<f64> = buckets.iter().map(|b| b.less_than).collect();
    // the buckets dashboards were built on
    let expected = [
        0.001,
        0.0025,
        0.005,
        0.01,
        0.025,
        0.05,
        0.1,
        0.25,
        0.5,
        1.0,
        2.5,
        5.0,
        10.0,
        30.0,
        f64::INFINITY,
    ];
    assert_eq!(bounds, expected);
    assert_eq!(buckets.last().unwrap().count, 1.0);
    assert_eq!(counter(&scrape, "l3_renders_total", &[]), 1.0);
    let mpx = counter(&scrape, "l3_rendered_megapixels_total", &[]);
    assert!((mpx - 32.0 * 24.0 / 1e6).abs() < 1e-12, "{mpx}");
    for name in [
        "l3_render_body_timeouts_total",
        "l3_render_budget_refusals_total",
        "l3_render_queue_refusals_total",
        "l3_renders_canceled_total",
        "l3_table_cache_hits_total",
        "l3_table_cache_misses_total",
        "l3_table_cache_evictions_total",
    ] {
        assert_eq!(counter(&scrape, name, &[]), 0.0, "{name}");
    }
    assert_eq!(gauge(&scrape, "l3_ready", &[]), 1.0);
    for state in ["queued", "running", "succeeded", "failed", "canceled"] {
        assert_eq!(gauge(&scrape, "l3_training_jobs", &[("state", state)]), 0.0);
    }
    // the render's body budget is back and nothing waits
    assert_eq!(gauge(&scrape, "l3_render_body_bytes_reserved", &[]), 0.0);
    assert_eq!(gauge(&scrape, "l3_render_queue_length", &[]), 0.0);
    assert_eq!(gauge(&scrape, "l3_table_cache_bytes", &[]), 0.0);
    assert_eq!(
        gauge(&scrape, "l3_table_cache_bound_bytes", &[]),
        server.state().config.tables.cache_bytes as f64
    );
    // every family has its help text
    for name in [
        "l3_http_requests_total",
        "l3_http_request_duration_seconds",
        "l3_training_jobs",
        "l3_ready",
    ] {
        assert!(scrape.docs.contains_key(name), "no HELP for {name}");
    }
    server.shutdown().await.unwrap();
}
