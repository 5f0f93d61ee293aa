//! `POST /v1/evaluations` with a ColorChecker frame as the body: the frame rendered as
//! `POST /v1/render` renders it, the report the core gives on that render, persisted, listed
//! and drawn; what a request gets wrong is a 4xx.

use crate::service_support::*;
use l3::eval::colorchecker::{ColorCheckerOptions, Labels, Reference, evaluate_colorchecker};

/// A noise-free Macbeth frame (16 px patches, edge to edge: 96 × 64) through the paper's
/// sensor under D65, as raw little-endian u16 (0–65535 over the swing).
fn macbeth_raw() -> (Vec<u8>, usize, usize) {
    let cam = l3::test_support::paper_camera();
    let opts = l3::scene::SceneOptions::d65(l3::spectral::WavelengthGrid::default()).unwrap();
    let scene = l3::scene::macbeth(l3::spectral::IsetData::or_built_in(None), &opts, 16).unwrap();
    let cap = l3::camera::simulate(
        &cam,
        &scene,
        l3::camera::Exposure::Auto {
            target_fraction: 0.9,
        },
        &l3::camera::NoiseSwitches::none(),
        1,
    )
    .unwrap();
    let (h, w) = cap.volts.dim();
    let swing = cam.design().voltage_swing_v as f32;
    let bytes = cap
        .volts
        .iter()
        .flat_map(|v| (((v / swing).clamp(0.0, 1.0) * 65535.0).round() as u16).to_le_bytes())
        .collect();
    (bytes, w, h)
}

/// The handles the sections of the ColorChecker evaluation test share.
struct Frame<'a> {
    server: &'a l3::service::Server,
    c: &'a reqwest::Client,
    raw: &'a Vec<u8>,
    w: usize,
    h: usize,
    corners: &'a str,
    q: &'a str,
}

impl Frame<'_> {
    /// Posts `body` as `ctype` to `q`.
    async fn post(
        &self,
        q: String,
        ctype: &'static str,
        body: Vec<u8>,
    ) -> reqwest::Result<reqwest::Response> {
        self.c
            .post(url(self.server, &q))
            .header("content-type", ctype)
            .body(body)
            .send()
            .await
    }

    /// The frame evaluated: 201, its location and the evaluation.
    async fn evaluate(&self, table_id: &str) -> (String, serde_json::Value) {
        let (raw, corners, q) = (self.raw, self.corners, self.q);
        let r = self
            .post(q.to_string(), "application/octet-stream", raw.clone())
            .await
            .unwrap();
        assert_eq!(r.status(), 201);
        let loc = r.headers()["location"].to_str().unwrap().to_string();
        let (_, created) = checked_json("POST", r).await;
        assert_eq!(created["chart"], "colorchecker");
        assert_eq!(created["method"], "l3");
        assert_eq!(created["table_id"], table_id);
        assert_eq!(created["acquisition_illuminant"], "D65");
        assert_eq!(created["request"]["corners"], corners);
        assert_eq!(created["request"]["frame_bytes"], raw.len());
        let report = &created["report"];
        assert_eq!(report["schema"], "l3.colorchecker.v1");
        assert_eq!(report["reference"], "iset");
        assert_eq!(report["context"]["illuminant_source"], "query");
        assert_eq!(report["patches"].as_array().unwrap().len(), 24);
        assert_eq!(created["mean_delta_e"], report["summary"]["mean"]);
        (loc, created)
    }

    /// The same frame through `POST /v1/render` to float XYZ, scored by the core: the same
    /// report.
    async fn the_core_scores_the_render_alike(&self, report: &serde_json::Value) {
        let (c, server, w, h) = (self.c, self.server, self.w, self.h);
        let r = c
            .post(url(
                server,
                &format!("/v1/render?illuminant=D65&width={w}&height={h}"),
            ))
            .header("content-type", "application/octet-stream")
            .header("accept", "application/octet-stream")
            .body(self.raw.clone())
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        let xyz: Vec<f32> = r
            .bytes()
            .await
            .unwrap()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let opts = ColorCheckerOptions {
            corners: self.corners.parse().unwrap(),
            gap: 0.0,
            reference: Reference::Iset,
        };
        let labels = Labels {
            method: "",
            illuminant: "D65",
            context: serde_json::Value::Null,
        };
        let core = evaluate_colorchecker(&xyz, w, h, &opts, None, labels).unwrap();
        for (p, want) in report["patches"]
            .as_array()
            .unwrap()
            .iter()
            .zip(&core.patches)
        {
            let got = p["delta_e"].as_f64().unwrap();
            assert!((got - want.delta_e).abs() < 1e-9, "{p} against {want:?}");
        }
    }

    /// The figure, the evaluation and the list.
    async fn figure_evaluation_and_list(&self, loc: &str, created: &serde_json::Value) {
        let (c, server) = (self.c, self.server);
        let r = c
            .get(url(server, loc))
            .header("accept", "image/svg+xml")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(r.headers()["content-type"], "image/svg+xml");
        let svg = r.text().await.unwrap();
        assert!(svg.starts_with("<?xml") && svg.trim_end().ends_with("</svg>"));
        assert_eq!(svg.matches("class=\"cc-patch\"").count(), 24);
        assert!(svg.contains("b. ΔE2000 per patch"));
        let got = json(c.get(url(server, loc)).send().await.unwrap()).await;
        assert_eq!(got["report"], created["report"]);
        let list = json(c.get(url(server, "/v1/evaluations")).send().await.unwrap()).await;
        let item = &list["items"][0];
        assert_eq!(item["chart"], "colorchecker");
        assert!(item["report"].get("patches").is_none());
    }

    /// What a request gets wrong: a 4xx saying what.
    async fn what_a_request_gets_wrong(&self) {
        let (w, h, corners, q) = (self.w, self.h, self.corners, self.q);
        let bad = [
            // no corners
            (
                format!("/v1/evaluations?chart=colorchecker&width={w}&height={h}"),
                400,
                "corners",
            ),
            // counter-clockwise
            (
                q.replace(corners, &format!("0,0,0,{h},{w},{h},{w},0")),
                400,
                "counter-clockwise",
            ),
            // a frame body for a simulated chart
            (
                q.replace("chart=colorchecker", "chart=natural100"),
                400,
                "chart=colorchecker",
            ),
            (
                q.replace("reference=iset", "reference=pantone"),
                400,
                "xrite2014 or iset",
            ),
            (q.replace("gap=0", "gap=2"), 400, "gap"),
            // a chart larger than the frame
            (
                q.replace(corners, &format!("0,0,{0},0,{0},{1},0,{1}", 3 * w, 3 * h)),
                422,
                "outside",
            ),
        ];
        for (q, status, says) in bad {
            let r = self
                .post(q.clone(), "application/octet-stream", self.raw.clone())
                .await
                .unwrap();
            let code = if status == 400 {
                "bad_request"
            } else {
                "unprocessable"
            };
            let detail = problem(r, status, code).await;
            assert!(detail.contains(says), "{q}: {detail}");
        }
    }

    /// A JSON body cannot carry a ColorChecker capture.
    async fn a_json_body_is_refused(&self) {
        let r = self
            .c
            .post(url(self.server, "/v1/evaluations"))
            .json(&serde_json::json!({"chart": "colorchecker"}))
            .send()
            .await
            .unwrap();
        let detail = problem(r, 400, "bad_request").await;
        assert!(detail.contains("frame as the body"), "{detail}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn colorchecker_evaluation_of_a_frame() {
    let data = tempfile::tempdir().unwrap();
    let (server, table_id) = server_with_table(data.path(), None).await;
    let c = client();
    let (raw, w, h) = macbeth_raw();
    let corners = format!("0,0,{w},0,{w},{h},0,{h}");
    let q = format!(
        "/v1/evaluations?chart=colorchecker&corners={corners}&gap=0&reference=iset&illuminant=D65&width={w}&height={h}"
    );
    let frame = Frame {
        server: &server,
        c: &c,
        raw: &raw,
        w,
        h,
        corners: &corners,
        q: &q,
    };
    let (loc, created) = frame.evaluate(&table_id).await;
    frame
        .the_core_scores_the_render_alike(&created["report"])
        .await;
    frame.figure_evaluation_and_list(&loc, &created).await;
    frame.what_a_request_gets_wrong().await;
    frame.a_json_body_is_refused().await;
    server.shutdown().await.unwrap();
}
