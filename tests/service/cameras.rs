//! Renders with more than one table: the table a DNG's camera chooses (trained through a job
//! for a catalogue sensor, used without being activated), the one `?table=` names, the sensor
//! catalogue with its trained sensors, and the byte bound of the cache of non-active tables.

use crate::service_support::*;
use l3::camera::{Camera, catalogue};
use l3::eval::{ChartSetup, simulate_chart};
use l3::io::{DngWriteInfo, RawFrame, RawMeta, encode_dng};

/// A DNG of the Natural-100 chart under D65 through the catalogue sensor `sensor`, naming its
/// camera `unique_model` (UniqueCameraModel), written with the crate's DNG writer.
fn camera_dng(sensor: &str, unique_model: &str) -> Vec<u8> {
    let design = catalogue::find(sensor).unwrap().load(None).unwrap();
    let camera = Camera::new(&design, Default::default(), None).unwrap();
    let setup = ChartSetup {
        patch_px: 6,
        ..ChartSetup::default()
    };
    let cap = simulate_chart(&camera, "D65", None, &setup).unwrap();
    let (w, h) = (cap.width, cap.height);
    let cfa = design.cfa.to_string();
    let meta = RawMeta::new(w, h, cfa, 0, 65535, design.voltage_swing_v);
    let frame = RawFrame::from_volts(&cap.volts, w, h, &meta).unwrap();
    let info = DngWriteInfo {
        camera_model: Some(unique_model.into()),
        ..DngWriteInfo::default()
    };
    encode_dng(&frame, &meta, &info).unwrap()
}

fn gradient_raw(w: usize, h: usize) -> Vec<u8> {
    (0..w * h)
        .flat_map(|i| ((3000 + (i % w) * 30000 / w) as u16).to_le_bytes())
        .collect()
}

fn header(r: &reqwest::Response, name: &str) -> String {
    r.headers()
        .get(name)
        .map(|v| v.to_str().unwrap().to_string())
        .unwrap_or_default()
}

/// The sensor `name` of a `GET /v1/sensors` listing.
fn sensor<'a>(list: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    list["items"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == name)
        .unwrap_or_else(|| panic!("{name} not listed"))
}

/// The handles the sections of the camera-table test share.
struct CameraCase<'a> {
    server: &'a l3::service::Server,
    c: &'a reqwest::Client,
    dng: &'a Vec<u8>,
    active_id: &'a str,
}

impl CameraCase<'_> {
    /// Posts the test's DNG to `q`, asking for a TIFF.
    async fn post_dng(&self, q: &str) -> reqwest::Result<reqwest::Response> {
        self.c
            .post(url(self.server, q))
            .header("content-type", "image/x-adobe-dng")
            .header("accept", "image/tiff")
            .body(self.dng.clone())
            .send()
            .await
    }

    /// A camera of the catalogue with no table: 422 naming the sensor and the training request.
    async fn untrained_camera_is_refused(&self) {
        let (c, server) = (self.c, self.server);
        let detail = problem(
            self.post_dng("/v1/render").await.unwrap(),
            422,
            "untrained_camera",
        )
        .await;
        assert!(
            detail.contains("bayer-sony-ilce-9")
                && detail.contains(r#"POST /v1/training-jobs {"sensor":"bayer-sony-ilce-9"}"#),
            "{detail}"
        );
        let list = json(c.get(url(server, "/v1/sensors")).send().await.unwrap()).await;
        assert!(list["items"].as_array().unwrap().len() >= 55, "{list}");
        assert_eq!(sensor(&list, "bayer-sony-ilce-9")["trained"], false);
    }

    /// A job trains a table for the sensor (not activated); returns its id.
    async fn train_the_sony_table(&self) -> String {
        let (c, server) = (self.c, self.server);
        let mut body = tiny_job_json(&["D65"], 1);
        body["sensor"] = "bayer-sony-ilce-9".into();
        let r = c
            .post(url(server, "/v1/training-jobs"))
            .json(&body)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 202);
        let id = json(r).await["id"].as_str().unwrap().to_string();
        let done = wait_job(server, &id, 300.0, |j| {
            !["queued", "running"].contains(&j["status"].as_str().unwrap())
        })
        .await;
        assert_eq!(done["status"], "succeeded", "{done}");
        done["table_id"].as_str().unwrap().to_string()
    }

    /// The catalogue marks the sensor and the active table's sensor trained, no other; the
    /// sensor's design; an unknown sensor is 404.
    async fn the_catalogue_lists_the_trained_sensors(&self, sony_id: &str) {
        let (c, server, active_id) = (self.c, self.server, self.active_id);
        let list = json(c.get(url(server, "/v1/sensors")).send().await.unwrap()).await;
        let s = sensor(&list, "bayer-sony-ilce-9");
        assert_eq!(
            (&s["trained"], &s["table_id"]),
            (&true.into(), &sony_id.into())
        );
        assert_eq!(
            (&s["cfa"], &s["source"]),
            (&"RG/GB".into(), &"rawtoaces".into())
        );
        // and the active table's sensor (the tiny table is trained on rgbw-paper), no other
        let trained: Vec<_> = list["items"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["trained"] == true)
            .map(|s| (s["name"].as_str().unwrap(), s["table_id"].as_str().unwrap()))
            .collect();
        assert_eq!(
            trained,
            [("bayer-sony-ilce-9", sony_id), ("rgbw-paper", active_id)]
        );
        let one = json(
            c.get(url(server, "/v1/sensors/BAYER-SONY-ILCE-9"))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert_eq!(one["name"], "bayer-sony-ilce-9");
        assert_eq!(one["design"]["name"], "bayer-sony-ilce-9");
        assert_eq!(one["table_id"], sony_id);
        let r = c.get(url(server, "/v1/sensors/bayer-sony-ilce-10"));
        problem_of(r, 404, "not_found").await;
    }

    /// The DNG renders with the camera's table; returns the render.
    async fn the_dng_renders_with_the_cameras_table(&self, sony_id: &str) -> bytes::Bytes {
        let r = self.post_dng("/v1/render").await.unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(header(&r, "x-l3-table"), sony_id);
        assert_eq!(header(&r, "x-l3-table-choice"), "camera");
        assert_eq!(header(&r, "x-l3-sensor"), "bayer-sony-ilce-9");
        r.bytes().await.unwrap()
    }

    /// A simulated frame of the camera written by PiDNG (no table, no light named): the
    /// camera's table, and the same bytes as its raw twin rendered with that table by name.
    async fn a_pidng_frame_renders_as_its_raw_twin(&self, sony_id: &str) {
        let (c, server) = (self.c, self.server);
        let fixtures = std::path::Path::new(env!("L3_ROOT")).join("tests/fixtures/pidng");
        let pidng = std::fs::read(fixtures.join("sony_macbeth.dng")).unwrap();
        let r = c
            .post(url(server, "/v1/render"))
            .header("content-type", "image/x-adobe-dng")
            .body(pidng)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(header(&r, "x-l3-table"), sony_id);
        assert_eq!(header(&r, "x-l3-table-choice"), "camera");
        let light = header(&r, "x-l3-illuminant");
        let from_dng = r.bytes().await.unwrap();
        let twin = std::fs::read(fixtures.join("sony_macbeth.raw")).unwrap();
        let q = format!(
            "/v1/render?width=192&height=128&cfa=RG/GB&black_level=512&white_level=16383&illuminant={light}&table={sony_id}"
        );
        let r = c
            .post(url(server, &q))
            .header("content-type", "application/octet-stream")
            .body(twin)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(header(&r, "x-l3-table-choice"), "query");
        assert!(
            r.bytes().await.unwrap() == from_dng,
            "the DNG and its raw twin render apart"
        );
    }

    /// The active table stays active; the camera's table is not.
    async fn the_active_table_stays_active(&self, sony_id: &str) {
        let (c, server) = (self.c, self.server);
        let v = json(c.get(url(server, "/readyz")).send().await.unwrap()).await;
        assert_eq!(v["table_id"], self.active_id);
        let t = json(
            c.get(url(server, &format!("/v1/tables/{sony_id}")))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert_eq!(
            (&t["active"], &t["sensor_name"]),
            (&false.into(), &"bayer-sony-ilce-9".into())
        );
    }

    /// `?table=` names it: the same bytes; the active table named for the DNG: its CFA
    /// refuses; an unknown table is 404.
    async fn table_named_in_the_query(&self, sony_id: &str, by_camera: &[u8]) {
        let active_id = self.active_id;
        let r = self
            .post_dng(&format!("/v1/render?table={sony_id}"))
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(header(&r, "x-l3-table-choice"), "query");
        assert_eq!(header(&r, "x-l3-sensor"), "");
        assert!(
            r.bytes().await.unwrap() == by_camera,
            "?table= renders otherwise"
        );
        let r = self
            .post_dng(&format!("/v1/render?table={active_id}"))
            .await
            .unwrap();
        problem(r, 422, "cfa_mismatch").await;
        let r = self
            .post_dng("/v1/render?table=tbl_0000000000000000")
            .await
            .unwrap();
        let detail = problem(r, 404, "not_found").await;
        assert!(detail.contains("tbl_0000000000000000"), "{detail}");
    }

    /// A raw frame: the active table; with `?table=`, the named one. A camera the catalogue
    /// does not know: the active table, as before.
    async fn raw_frames_and_unknown_cameras(&self, sony_id: &str) {
        let (c, server, active_id) = (self.c, self.server, self.active_id);
        let raw = |q: &str| {
            c.post(url(server, &format!("/v1/render?width=32&height=32{q}")))
                .header("content-type", "application/octet-stream")
                .body(gradient_raw(32, 32))
                .send()
        };
        let r = raw("").await.unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(header(&r, "x-l3-table"), active_id);
        assert_eq!(header(&r, "x-l3-table-choice"), "active");
        let r = raw(&format!("&table={sony_id}&illuminant=D65"))
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(header(&r, "x-l3-table"), sony_id);
        assert_eq!(header(&r, "x-l3-table-choice"), "query");
        // a camera the catalogue does not know: the active table, as before
        let other = camera_dng("bayer-sony-ilce-9", "Prototype 7");
        let r = c
            .post(url(server, "/v1/render"))
            .header("content-type", "image/x-adobe-dng")
            .body(other)
            .send()
            .await
            .unwrap();
        problem(r, 422, "cfa_mismatch").await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dng_renders_with_the_table_trained_for_its_camera_without_activating_it() {
    let data = tempfile::tempdir().unwrap();
    let (server, active_id) = server_with_table(data.path(), None).await;
    let c = client();
    let dng = camera_dng("bayer-sony-ilce-9", "Sony ILCE-9");
    let case = CameraCase {
        server: &server,
        c: &c,
        dng: &dng,
        active_id: &active_id,
    };
    case.untrained_camera_is_refused().await;
    let sony_id = case.train_the_sony_table().await;
    case.the_catalogue_lists_the_trained_sensors(&sony_id).await;
    let by_camera = case.the_dng_renders_with_the_cameras_table(&sony_id).await;
    case.a_pidng_frame_renders_as_its_raw_twin(&sony_id).await;
    case.the_active_table_stays_active(&sony_id).await;
    case.table_named_in_the_query(&sony_id, &by_camera).await;
    case.raw_frames_and_unknown_cameras(&sony_id).await;
    server.shutdown().await.unwrap();
}

/// The metric `name`'s value in a /metrics text.
fn metric(text: &str, name: &str) -> u64 {
    text.lines()
        .find_map(|l| l.strip_prefix(&format!("{name} ")))
        .unwrap_or_else(|| panic!("no {name} in\n{text}"))
        .trim()
        .parse()
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_cache_of_other_tables_keeps_its_byte_bound() {
    let data = tempfile::tempdir().unwrap();
    let table = tiny_table();
    let size = std::mem::size_of_val(table.kernels.as_slice()) as u64;
    // room for two tables, not three
    let bound = 2 * size + size / 2;
    let mut cfg = test_config(data.path());
    cfg.tables.cache_bytes = bound as usize;
    let (server, active_id) = server_with_table(data.path(), Some(cfg)).await;
    let mut ids = Vec::new();
    for i in 0..3 {
        let mut t = table.clone();
        t.meta.training_seconds = 1000.0 + i as f64;
        let id = l3::service::import_table(server.state(), &t, false)
            .await
            .unwrap();
        ids.push(id);
    }
    let c = client();
    let metrics = || async {
        let r = c.get(url(&server, "/metrics")).send().await.unwrap();
        r.text().await.unwrap()
    };
    let mut held = Vec::new();
    for id in [&ids[0], &ids[1], &ids[2], &ids[0], &ids[0], &active_id] {
        let r = c
            .post(url(
                &server,
                &format!("/v1/render?width=32&height=32&illuminant=D65&table={id}"),
            ))
            .header("content-type", "application/octet-stream")
            .body(gradient_raw(32, 32))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(&header(&r, "x-l3-table"), id);
        let text = metrics().await;
        let bytes = metric(&text, "l3_table_cache_bytes");
        assert!(bytes <= bound, "{bytes} bytes held over the bound {bound}");
        assert_eq!(metric(&text, "l3_table_cache_bound_bytes"), bound);
        held.push(bytes);
    }
    let text = metrics().await;
    // 0, 1, 2 (evicts 0), 0 (evicts 1), 0 again (a hit), the active table (not cached)
    assert_eq!(
        held,
        [size, 2 * size, 2 * size, 2 * size, 2 * size, 2 * size]
    );
    assert_eq!(metric(&text, "l3_table_cache_misses_total"), 4);
    assert_eq!(metric(&text, "l3_table_cache_hits_total"), 1);
    assert_eq!(metric(&text, "l3_table_cache_evictions_total"), 2);
    server.shutdown().await.unwrap();
}
