//! `GET /v1/evaluations/{id}` with `Accept: image/svg+xml` answers the report's figure; JSON
//! stays the default.

use crate::service_support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn evaluation_figure_is_served_as_svg() {
    let data = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(data.path(), None).await;
    let c = client();
    let r = c
        .post(url(&server, "/v1/evaluations"))
        .json(&serde_json::json!({"acquisition_illuminant": "Tungsten", "patch_px": 8, "noise": false}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let created = json(r).await;

    // the figure
    let r = c
        .get(url(&server, &loc))
        .header("accept", "image/svg+xml")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "image/svg+xml");
    assert_eq!(r.headers()["vary"], "Accept");
    let svg = r.text().await.unwrap();
    assert!(svg.starts_with("<?xml"), "{}", &svg[..svg.len().min(200)]);
    assert!(svg.contains("<svg xmlns=\"http://www.w3.org/2000/svg\""));
    assert!(svg.trim_end().ends_with("</svg>"));
    for title in [
        "a. ΔE2000 distribution",
        "b. Chromaticity (CIE 1931 xy)",
        "c. Lightness L*: estimated vs true",
        "d. Worst patches",
    ] {
        assert!(svg.contains(title), "panel title {title:?} missing");
    }
    assert_eq!(svg.matches("class=\"swatch-pair\"").count(), 12);
    let method = created["report"]["method"].as_str().unwrap();
    assert!(svg.contains(&method.replace('&', "&amp;").replace('<', "&lt;")));
    // preferred by q-value, and image/* also picks the figure
    let r = c
        .get(url(&server, &loc))
        .header("accept", "application/json;q=0.5, image/*")
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["content-type"], "image/svg+xml");

    // JSON stays the default and the answer to application/json
    for accept in [None, Some("application/json"), Some("*/*")] {
        let mut req = c.get(url(&server, &loc));
        if let Some(a) = accept {
            req = req.header("accept", a);
        }
        let r = req.send().await.unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(
            r.headers()["content-type"],
            "application/json",
            "{accept:?}"
        );
        let got = json(r).await;
        assert_eq!(got["report"], created["report"]);
    }

    // errors stay problem+json
    problem_of(
        c.get(url(&server, "/v1/evaluations/eval_nope"))
            .header("accept", "image/svg+xml"),
        404,
        "not_found",
    )
    .await;
    server.shutdown().await.unwrap();
}
