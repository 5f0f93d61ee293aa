//! The read endpoints end to end: health, tables, illuminants, evaluations and metrics.

use l3::service::Server;

use crate::service_support::*;

/// The synthetic raw frame's size.
const FRAME: (usize, usize) = (64, 48);

/// The server (with the tiny table active) the reads go to, and its client.
struct Reads<'a> {
    server: &'a Server,
    c: reqwest::Client,
    table_id: &'a str,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_read_endpoint_tables_illuminants_and_evaluations() {
    let data = tempfile::tempdir().unwrap();
    let (server, table_id) = server_with_table(data.path(), None).await;
    let rd = Reads {
        server: &server,
        c: client(),
        table_id: &table_id,
    };
    health_readiness_and_openapi(&rd).await;
    renders_with_region_preview_and_lights(&rd).await;
    tables(&rd).await;
    illuminants_listed_and_defined(&rd).await;
    illuminants_replaced_used_and_deleted(&rd).await;
    let v = an_evaluation_and_its_report(&rd).await;
    evaluations_at_light_levels_and_bad_ones(&rd, &v).await;
    metrics_after_all_that(&rd).await;
    server.shutdown().await.unwrap();
}

/// Health, readiness, openapi.
async fn health_readiness_and_openapi(rd: &Reads<'_>) {
    let (server, c) = (rd.server, &rd.c);
    let v = json(c.get(url(server, "/healthz")).send().await.unwrap()).await;
    assert_eq!(v["status"], "ok");
    let v = json(c.get(url(server, "/readyz")).send().await.unwrap()).await;
    assert_eq!(v["status"], "ready");
    assert_eq!(v["table_id"], rd.table_id);
    let r = c.get(url(server, "/openapi.yaml")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.text().await.unwrap(), l3::service::OPENAPI_YAML);
}

/// A render (synthetic raw frame) with region and preview; srgb16 TIFF, cct: and xy:
/// illuminants.
async fn renders_with_region_preview_and_lights(rd: &Reads<'_>) {
    let (server, c) = (rd.server, &rd.c);
    // a render (synthetic raw frame) with region and preview
    let (w, h) = FRAME;
    let r = c
        .post(url(
            server,
            &format!("/v1/render?width={w}&height={h}&region=8,8,32,16&preview=2"),
        ))
        .header("content-type", "application/octet-stream")
        .header("accept", "application/octet-stream")
        .body(gradient_raw(w, h))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["x-l3-width"], "16");
    assert_eq!(r.headers()["x-l3-height"], "8");
    assert_eq!(r.headers()["x-l3-input-pixels"], (w * h).to_string());
    assert_eq!(r.bytes().await.unwrap().len(), 16 * 8 * 12);
    // srgb16 TIFF, cct: and xy: illuminants
    for q in [
        "tiff=srgb16&illuminant=cct:3200",
        "illuminant=xy:0.4476,0.4074&white=0.5",
    ] {
        let r = c
            .post(url(server, &format!("/v1/render?width={w}&height={h}&{q}")))
            .header("content-type", "application/octet-stream")
            .header("accept", "image/tiff")
            .body(gradient_raw(w, h))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200, "{q}");
    }
}

/// The table list, one table, its download and activation; an unknown table.
async fn tables(rd: &Reads<'_>) {
    let (server, c, table_id) = (rd.server, &rd.c, rd.table_id);
    let v = json(c.get(url(server, "/v1/tables")).send().await.unwrap()).await;
    assert_eq!(v["active_table_id"], table_id);
    assert_eq!(v["items"][0]["id"], table_id);
    assert_eq!(v["items"][0]["active"], true);
    let v = json(
        c.get(url(server, &format!("/v1/tables/{table_id}")))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(v["kind"], "si");
    assert!(
        v["meta"].is_object() && !v["training_report"].is_null(),
        "{v}"
    );
    let sha = v["sha256"].as_str().unwrap().to_string();
    let r = c
        .get(url(server, &format!("/v1/tables/{table_id}/download")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["x-content-sha256"], sha.as_str());
    let bytes = r.bytes().await.unwrap();
    assert_eq!(l3::service::sha256_hex(&bytes), sha);
    assert!(l3::l3::L3Table::from_bytes(&bytes, "download").is_ok());
    let r = c
        .post(url(server, &format!("/v1/tables/{table_id}/activate")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    problem_of(c.get(url(server, "/v1/tables/tbl_nope")), 404, "not_found").await;
    problem_of(
        c.post(url(server, "/v1/tables/tbl_nope/activate")),
        404,
        "not_found",
    )
    .await;
}

/// The built-in illuminants, and new ones defined by matrix, CCT and SPD.
async fn illuminants_listed_and_defined(rd: &Reads<'_>) {
    let (server, c) = (rd.server, &rd.c);
    let v = json(c.get(url(server, "/v1/illuminants")).send().await.unwrap()).await;
    let names: Vec<&str> = v["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    for n in ["D65", "D50", "A", "F2", "F11"] {
        assert!(names.contains(&n), "{n} missing from {names:?}");
    }
    let v = json(
        c.get(url(server, "/v1/illuminants/d65"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(
        v["matrix"],
        serde_json::json!([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    );
    let defs = [
        (
            "Studio",
            serde_json::json!({"matrix": [[1.1, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.8]]}),
            "matrix",
        ),
        ("Warm", serde_json::json!({"cct": 2800}), "cct"),
        (
            "Flat",
            serde_json::json!({"spd": {"wavelengths_nm": [380, 780], "values": [1.0, 1.0]}}),
            "spd",
        ),
    ];
    for (name, body, source) in &defs {
        let r = c
            .put(url(server, &format!("/v1/illuminants/{name}")))
            .json(body)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 201, "{name}");
        let v = json(r).await;
        assert_eq!(v["source"], *source);
        assert_eq!(v["user_defined"], true);
    }
}

/// Replace → 200; use in a render; built-in and unknown illuminants cannot be deleted, a user's
/// can.
async fn illuminants_replaced_used_and_deleted(rd: &Reads<'_>) {
    let (server, c) = (rd.server, &rd.c);
    let (w, h) = FRAME;
    let r = c
        .put(url(server, "/v1/illuminants/Warm"))
        .json(&serde_json::json!({"cct": 3000}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(json(r).await["cct"], 3000.0);
    let r = c
        .post(url(
            server,
            &format!("/v1/render?width={w}&height={h}&illuminant=Studio"),
        ))
        .header("content-type", "application/octet-stream")
        .body(gradient_raw(w, h))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["x-l3-illuminant"], "Studio");
    problem_of(
        c.delete(url(server, "/v1/illuminants/D65")),
        409,
        "conflict",
    )
    .await;
    problem_of(c.delete(url(server, "/v1/illuminants/A")), 409, "conflict").await;
    problem_of(
        c.delete(url(server, "/v1/illuminants/Nope")),
        404,
        "not_found",
    )
    .await;
    problem_of(c.get(url(server, "/v1/illuminants/Nope")), 404, "not_found").await;
    let r = c
        .delete(url(server, "/v1/illuminants/Flat"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);
    problem_of(c.get(url(server, "/v1/illuminants/Flat")), 404, "not_found").await;
}

/// An evaluation: its fields, its report's and the list's. The evaluation.
async fn an_evaluation_and_its_report(rd: &Reads<'_>) -> serde_json::Value {
    let (server, c) = (rd.server, &rd.c);
    let r = c
        .post(url(server, "/v1/evaluations"))
        .json(&serde_json::json!({"acquisition_illuminant": "Tungsten", "patch_px": 8, "noise": false}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let v = json(r).await;
    for f in [
        "id",
        "table_id",
        "method",
        "chart",
        "acquisition_illuminant",
        "mean_delta_e",
        "created_at_ms",
        "request",
        "report",
        "links",
    ] {
        assert!(v.get(f).is_some(), "evaluation field {f} missing");
    }
    for f in [
        "schema",
        "chart",
        "acquisition_illuminant",
        "method",
        "summary",
        "per_pixel",
        "per_category",
        "white_patch",
        "patches",
        "context",
    ] {
        assert!(v["report"].get(f).is_some(), "report field {f} missing");
    }
    for f in ["n", "mean", "std", "median", "p90", "max"] {
        assert!(v["report"]["summary"][f].is_number(), "summary.{f}");
    }
    for f in ["n", "mean", "p90"] {
        assert!(v["report"]["per_pixel"][f].is_number(), "per_pixel.{f}");
    }
    // a simulated chart's report carries the render's S-CIELAB and the spatial metrics
    for f in [
        "s_cielab_mean",
        "mtf50",
        "mtf_at_half_nyquist",
        "ideal_mtf50",
        "false_colour",
        "s_cielab_texture",
    ] {
        let x = v["report"][f].as_f64();
        assert!(
            x.is_some_and(f64::is_finite),
            "report.{f}: {:?}",
            v["report"][f]
        );
    }
    assert_eq!(v["report"]["schema"], "l3.delta_e.v1");
    assert_eq!(v["table_id"], rd.table_id);
    let mean = v["mean_delta_e"].as_f64().unwrap();
    assert!(
        mean.is_finite() && mean > 0.0 && mean < 50.0,
        "mean ΔE {mean}"
    );
    let got = json(c.get(url(server, &loc)).send().await.unwrap()).await;
    assert_eq!(got["report"], v["report"]);
    let list = json(c.get(url(server, "/v1/evaluations")).send().await.unwrap()).await;
    assert_eq!(list["items"][0]["id"], v["id"]);
    assert!(list["items"][0]["report"].get("patches").is_none());
    v
}

/// Light level: a tenth of the exposure is noisier per pixel than `v`; bad light levels and an
/// unknown evaluation.
async fn evaluations_at_light_levels_and_bad_ones(rd: &Reads<'_>, v: &serde_json::Value) {
    let (server, c) = (rd.server, &rd.c);
    let dim = c
        .post(url(server, "/v1/evaluations"))
        .json(&serde_json::json!({"acquisition_illuminant": "Tungsten", "patch_px": 8, "exposure_factor": 0.1}))
        .send()
        .await
        .unwrap();
    assert_eq!(dim.status(), 201);
    let dim = json(dim).await;
    assert_eq!(dim["report"]["context"]["setup"]["exposure_factor"], 0.1);
    assert!(
        dim["report"]["per_pixel"]["mean"].as_f64().unwrap()
            > v["report"]["per_pixel"]["mean"].as_f64().unwrap()
    );
    for bad in [
        serde_json::json!({"exposure_factor": 1.5}),
        serde_json::json!({"exposure_factor": 0}),
        serde_json::json!({"scene_luminance": -3}),
        serde_json::json!({"exposure_factor": 0.5, "scene_luminance": 10}),
    ] {
        problem_of(
            c.post(url(server, "/v1/evaluations")).json(&bad),
            400,
            "bad_request",
        )
        .await;
    }
    problem_of(
        c.get(url(server, "/v1/evaluations/eval_nope")),
        404,
        "not_found",
    )
    .await;
}

/// Metrics after all that.
async fn metrics_after_all_that(rd: &Reads<'_>) {
    let (server, c) = (rd.server, &rd.c);
    let text = c
        .get(url(server, "/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(
        text.contains(
            "l3_http_requests_total{method=\"POST\",route=\"/v1/render\",status=\"200\"}"
        ),
        "{text}"
    );
    assert!(text.contains("l3_http_request_duration_seconds_bucket{method=\"GET\",route=\"/v1/tables\",status=\"200\",le=\"+Inf\"} 1"));
    assert!(text.contains("l3_rendered_megapixels_total"));
    assert!(text.contains("l3_training_jobs{state=\"queued\"} 0"));
    assert!(text.contains("l3_ready 1"));
}
