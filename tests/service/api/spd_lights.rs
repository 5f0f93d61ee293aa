//! Lights registered from SPD samples train and evaluate: a job's stored request carries the
//! samples under the light's name (so it trains what was registered at submission, on any
//! replica, whatever happens to the name since), and its table says it was trained under
//! that light.

use serde_json::{Value, json};

use super::trust::job;
use crate::service_support::*;

/// Samples of a light: 380–780 nm every 10 nm, a blue peak at `blue` nm over a broad
/// phosphor hump.
fn led(blue: f64) -> (Vec<f64>, Vec<f64>) {
    let wl: Vec<f64> = (0..=40).map(|i| 380.0 + 10.0 * f64::from(i)).collect();
    let power = wl
        .iter()
        .map(|w| {
            let bump = |c: f64, s: f64| (-((w - c) / s).powi(2)).exp();
            0.02 + bump(blue, 12.0) + 0.8 * bump(590.0, 70.0)
        })
        .collect();
    (wl, power)
}

/// The light as a job's stored request holds it.
fn inline(name: &str, (wl, power): &(Vec<f64>, Vec<f64>)) -> String {
    l3::spectral::IlluminantSpec::samples(name, wl.clone(), power.clone())
        .unwrap()
        .to_string()
}

async fn register(server: &l3::service::Server, name: &str, light: &(Vec<f64>, Vec<f64>)) -> u16 {
    let (wl, power) = light;
    client()
        .put(url(server, &format!("/v1/illuminants/{name}")))
        .json(&json!({"spd": {"wavelengths_nm": wl, "values": power}}))
        .send()
        .await
        .unwrap()
        .status()
        .as_u16()
}

async fn submit(server: &l3::service::Server, body: &Value) -> Value {
    let r = client()
        .post(url(server, "/v1/training-jobs"))
        .json(body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    json(r).await
}

/// A queued job keeps the samples it was submitted with when the name is registered anew;
/// it trains to a table recorded as trained under the light, which evaluates under it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_light_registered_from_samples_trains_and_evaluates() {
    let data = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(data.path(), None).await;
    let c = client();
    let first = led(450.0);
    assert_eq!(register(&server, "warm-led", &first).await, 201);
    // a long job holds the one job slot, so the next waits in the queue
    let long = submit(&server, &job(json!({"scenes": 2000, "scene_size": 96}))).await;
    let long = long["id"].as_str().unwrap().to_string();
    let queued = submit(
        &server,
        &job(json!({"illuminants": ["Warm-LED"], "seed": 3})),
    )
    .await;
    let stored = json!([inline("warm-led", &first)]);
    assert_eq!(queued["request"]["illuminants"], stored);
    let id = queued["id"].as_str().unwrap().to_string();
    // the name registered anew: the queued job's request is unchanged
    assert_eq!(register(&server, "warm-led", &led(470.0)).await, 200);
    let j = json(
        c.get(url(&server, &format!("/v1/training-jobs/{id}")))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(j["status"], "queued", "{j}");
    assert_eq!(j["request"]["illuminants"], stored);
    let r = c
        .post(url(&server, &format!("/v1/training-jobs/{long}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let done = wait_job(&server, &id, 120.0, |j| {
        !["queued", "running"].contains(&j["status"].as_str().unwrap())
    })
    .await;
    assert_eq!(done["status"], "succeeded", "{done}");
    // the table names the light, and its training report keeps the samples it was lit by
    let table = done["table_id"].as_str().unwrap();
    let t = json(
        c.get(url(&server, &format!("/v1/tables/{table}")))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(t["train_illuminants"], json!(["warm-led"]), "{t}");
    assert_eq!(t["training_report"]["spec"]["illuminants"], stored);
    // the stored request, sent again, trains the same light
    let again = submit(&server, &done["request"]).await;
    assert_eq!(again["request"]["illuminants"], stored);
    let again = again["id"].as_str().unwrap();
    let r = c
        .post(url(&server, &format!("/v1/training-jobs/{again}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    // an evaluation under the light (now the second samples), with the new table and with
    // the active one
    for table_id in [json!(table), Value::Null] {
        let r = c
            .post(url(&server, "/v1/evaluations"))
            .json(&json!({"acquisition_illuminant": "warm-led", "patch_px": 8,
                "table_id": table_id}))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 201);
        let v = json(r).await;
        assert_eq!(v["report"]["acquisition_illuminant"], "warm-led", "{v}");
        assert!(v["mean_delta_e"].as_f64().unwrap().is_finite());
    }
    server.shutdown().await.unwrap();
}

/// The inline form is taken as given by training and evaluations (it is what stored requests
/// hold), checked like registered samples; renders take the registered name only. A light
/// given as a matrix stays a 422; unknown names list the lights with samples.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_inline_form_is_checked_and_renders_take_the_name() {
    let data = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(data.path(), None).await;
    let c = client();
    let light = led(450.0);
    assert_eq!(register(&server, "led1", &light).await, 201);
    let given = inline("my-lamp", &light);
    let eval = |light: &str| {
        c.post(url(&server, "/v1/evaluations"))
            .json(&json!({"acquisition_illuminant": light, "patch_px": 8}))
    };
    let r = eval(&given).send().await.unwrap();
    assert_eq!(r.status(), 201);
    assert_eq!(json(r).await["report"]["acquisition_illuminant"], "my-lamp");
    let v = submit(
        &server,
        &job(json!({"illuminants": [given.clone(), "D65"]})),
    )
    .await;
    assert_eq!(v["request"]["illuminants"], json!([given, "D65"]));
    for (bad, needle) in [
        ("spd:x:400=1,500=-1", "negative"),
        ("spd:x:500=1,400=1", "increasing"),
        ("spd:x", "expected spd:NAME"),
    ] {
        let d = problem_of(eval(bad), 400, "bad_request").await;
        assert!(d.contains(needle), "{bad}: {d}");
        let r = c
            .post(url(&server, "/v1/training-jobs"))
            .json(&job(json!({"illuminants": [bad]})))
            .send()
            .await
            .unwrap();
        problem(r, 400, "bad_request").await;
    }
    // names with the prefix are refused, as cct: and the others are
    let r = c
        .put(url(&server, "/v1/illuminants/spd:x"))
        .json(&json!({"cct": 3000}))
        .send()
        .await
        .unwrap();
    problem(r, 400, "bad_request").await;
    let d = problem_of(eval("nope"), 400, "unknown_illuminant").await;
    assert!(d.contains("led1") && d.contains("spd"), "{d}");
    // renders: the registered name, not the inline form
    let render = |light: &str| {
        c.post(url(&server, "/v1/render"))
            .query(&[("width", "16"), ("height", "16"), ("illuminant", light)])
            .header("content-type", "application/octet-stream")
            .body(gradient_raw(16, 16))
    };
    let r = render("led1").send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["x-l3-illuminant"], "led1");
    let d = problem_of(render(&given), 400, "unknown_illuminant").await;
    assert!(d.contains("spd:my-lamp:…") && d.contains("PUT"), "{d}");
    assert!(d.len() < 400, "the detail does not repeat the samples: {d}");
    server.shutdown().await.unwrap();
}
