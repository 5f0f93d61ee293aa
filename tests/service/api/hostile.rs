//! Hostile input: bad sizes, images, parameters, bodies and routes each get a clear 4xx.

use l3::service::Server;

use crate::service_support::*;

const RAW: &str = "application/octet-stream";

/// A render request of zero bytes of the given length and what refuses it: (query, content
/// type, body bytes, status, problem code, what the detail names).
type Refusal<'a> = (&'a str, Option<&'a str>, usize, u16, &'a str, &'a [&'a str]);

/// The server (64 KiB bodies, 100000 pixels at most) the hostile requests go to, and its client.
struct Hostile<'a> {
    server: &'a Server,
    c: reqwest::Client,
}

impl Hostile<'_> {
    /// A render with query `q`, content type `ctype` (none when `None`) and `body`.
    async fn render(
        &self,
        q: &str,
        ctype: Option<&str>,
        body: Vec<u8>,
    ) -> reqwest::Result<reqwest::Response> {
        let mut r = self
            .c
            .post(url(self.server, &format!("/v1/render?{q}")))
            .body(body);
        if let Some(t) = ctype {
            r = r.header("content-type", t);
        }
        r.send().await
    }

    /// Every one of `cases`, in order, is refused as it says.
    async fn refuse_all(&self, cases: &[Refusal<'_>]) {
        for &(q, ctype, n, status, code, needles) in cases {
            self.refused(q, ctype, vec![0; n], status, code, needles)
                .await;
        }
    }

    /// A render with query `q`, content type `ctype` and `body` is refused with `status` and
    /// the problem `code`, and its detail names every one of `needles`.
    async fn refused(
        &self,
        q: &str,
        ctype: Option<&str>,
        body: Vec<u8>,
        status: u16,
        code: &str,
        needles: &[&str],
    ) {
        problem_naming(
            self.render(q, ctype, body).await.unwrap(),
            status,
            code,
            needles,
        )
        .await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_input_gets_a_clear_4xx() {
    let data = tempfile::tempdir().unwrap();
    let mut cfg = test_config(data.path());
    cfg.server.max_body_bytes = 64 * 1024;
    cfg.server.max_pixels = 100_000;
    let (server, _) = server_with_table(data.path(), Some(cfg)).await;
    let h = Hostile {
        server: &server,
        c: client(),
    };
    hostile_raw_sizes(&h).await;
    hostile_images(&h).await;
    hostile_nan_in_float_input(&h).await;
    hostile_illuminants(&h).await;
    hostile_other_parameters(&h).await;
    hostile_size_types_and_negotiation(&h).await;
    hostile_job_json(&h).await;
    hostile_evaluation_and_illuminant_bodies(&h).await;
    hostile_routes_and_methods(&h).await;
    server.shutdown().await.unwrap();
}

/// Raw frames of the wrong length, size or pixel count, and bad or unknown size parameters.
async fn hostile_raw_sizes(h: &Hostile<'_>) {
    #[rustfmt::skip]
    let cases: &[Refusal] = &[
        ("width=32&height=32", Some(RAW), 1000, 400, "invalid_image", &["1000 bytes", "2048 expected"]),
        ("width=0&height=32", Some(RAW), 64, 400, "invalid_image", &["at least 1"]),
        ("width=100000&height=100000", Some(RAW), 64, 400, "invalid_image", &["at most"]),
        ("width=1000&height=1000", Some(RAW), 64, 400, "invalid_image", &["100000 pixels"]),
        ("width=-3&height=2", Some(RAW), 64, 400, "bad_request", &["width"]),
        ("", Some(RAW), 64, 400, "bad_request", &["width and height"]),
        ("width=2&height=2&bogus=1", Some(RAW), 8, 400, "bad_request", &["bogus"]),
    ];
    h.refuse_all(cases).await;
}

/// Truncated and garbage PNG / TIFF / PGM, a non-image and a size the image contradicts.
async fn hostile_images(h: &Hostile<'_>) {
    // images: truncated and garbage PNG / TIFF / PGM
    let frame =
        l3::io::RawFrame::new(32, 32, (0..1024).map(|i| (i * 50) as u16).collect()).unwrap();
    let png = l3::io::encode_png_gray16(&frame, l3::io::PngCompression::Fast).unwrap();
    let tiff = l3::io::encode_tiff_gray16(&frame).unwrap();
    let mut pgm = b"P5\n32 32\n65535\n".to_vec();
    pgm.extend(frame.data.iter().flat_map(|v| v.to_be_bytes()));
    for (ctype, good) in [
        ("image/png", &png),
        ("image/tiff", &tiff),
        ("image/x-portable-graymap", &pgm),
    ] {
        let ok = h.render("", Some(ctype), good.clone()).await.unwrap();
        assert_eq!(ok.status(), 200, "{ctype} valid input");
        let d = problem(
            h.render("", Some(ctype), good[..good.len() / 2].to_vec())
                .await
                .unwrap(),
            400,
            "invalid_image",
        )
        .await;
        assert!(!d.is_empty(), "{ctype} truncated");
        let mut garbage = good[..8.min(good.len())].to_vec();
        garbage.extend((0..500u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8));
        problem(
            h.render("", Some(ctype), garbage).await.unwrap(),
            400,
            "invalid_image",
        )
        .await;
    }
    problem_naming(
        h.render("", Some("image/png"), b"hello world, not an image".to_vec())
            .await
            .unwrap(),
        400,
        "invalid_image",
        &["unrecognised image format"],
    )
    .await;
    h.refused(
        "width=5&height=5",
        Some("image/png"),
        png.clone(),
        400,
        "invalid_image",
        &["32×32"],
    )
    .await;
}

/// A NaN in a float TIFF, named by position.
async fn hostile_nan_in_float_input(h: &Hostile<'_>) {
    // NaN in float input
    // (the encoder refuses NaN, so a marker value is patched to NaN in the encoded file)
    let mut f = vec![0.1f32; 32 * 32];
    f[37] = 0.123_456_7;
    let mut ftiff = l3::io::encode_tiff_gray_f32(32, 32, &f).unwrap();
    let marker = 0.123_456_7f32.to_le_bytes();
    let pos = ftiff
        .windows(4)
        .position(|w| w == marker)
        .expect("marker in the TIFF");
    ftiff[pos..pos + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    h.refused(
        "",
        Some("image/tiff"),
        ftiff,
        400,
        "invalid_image",
        &["finite", "x=5", "y=1"],
    )
    .await;
}

/// Unknown illuminants, a file path and an impossible chromaticity.
async fn hostile_illuminants(h: &Hostile<'_>) {
    #[rustfmt::skip]
    let cases: &[Refusal] = &[
        ("width=32&height=32&illuminant=Moonlight", Some(RAW), 2048, 400, "unknown_illuminant", &["Moonlight"]),
        ("width=32&height=32&illuminant=csv:/etc/passwd", Some(RAW), 2048, 400, "unknown_illuminant", &[]),
        ("width=32&height=32&illuminant=xy:2,3", Some(RAW), 2048, 400, "unknown_illuminant", &[]),
    ];
    h.refuse_all(cases).await;
}

/// A CFA, levels, region and preview the frame cannot have.
async fn hostile_other_parameters(h: &Hostile<'_>) {
    #[rustfmt::skip]
    let cases: &[Refusal] = &[
        ("width=32&height=32&cfa=RG/GB", Some(RAW), 2048, 422, "cfa_mismatch", &[]),
        ("width=32&height=32&white=-1", Some(RAW), 2048, 400, "bad_request", &[]),
        ("width=32&height=32&region=30,30,8,8", Some(RAW), 2048, 400, "bad_request", &[]),
        ("width=32&height=32&preview=99", Some(RAW), 2048, 400, "bad_request", &[]),
        ("width=32&height=32&black_level=70000", Some(RAW), 2048, 400, "bad_request", &[]),
        ("width=32&height=32&black_level=9&white_level=9", Some(RAW), 2048, 400, "bad_request", &["black_level"]),
        ("width=32&height=32&white_level=0", Some(RAW), 2048, 400, "bad_request", &["white_level 0"]),
    ];
    h.refuse_all(cases).await;
}

/// A body over the limit, unsupported or missing content types, an empty body and an output
/// nobody can produce.
async fn hostile_size_types_and_negotiation(h: &Hostile<'_>) {
    let (server, c) = (h.server, &h.c);
    // size, types, negotiation
    #[rustfmt::skip]
    let cases: &[Refusal] = &[
        ("width=256&height=256", Some(RAW), 256 * 256 * 2, 413, "payload_too_large", &["65536"]),
        ("width=32&height=32", Some("text/plain"), 2048, 415, "unsupported_media_type", &[]),
        ("width=32&height=32", None, 2048, 415, "unsupported_media_type", &[]),
        ("width=32&height=32", Some(RAW), 0, 400, "invalid_image", &[]),
    ];
    h.refuse_all(cases).await;
    let r = c
        .post(url(server, "/v1/render?width=32&height=32"))
        .header("content-type", RAW)
        .header("accept", "image/webp, text/html")
        .body(vec![0u8; 2048])
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["vary"], "Accept");
    let detail = problem(r, 406, "not_acceptable").await;
    assert!(detail.contains("image/jpeg"), "{detail}");
}

/// Malformed training-job JSON and a job that is not JSON.
async fn hostile_job_json(h: &Hostile<'_>) {
    let (server, c) = (h.server, &h.c);
    // malformed job JSON
    let job = |body: &'static str, ctype: &'static str| {
        c.post(url(server, "/v1/training-jobs"))
            .header("content-type", ctype)
            .body(body)
            .send()
    };
    // (body, code, what the detail names)
    #[rustfmt::skip]
    let cases: [(&str, &str, &str); 4] = [
        ("{\"levels\": ", "invalid_json", "not valid JSON"),
        ("{\"levles\": 5}", "invalid_json", "levles"),
        ("{\"levels\": 1}", "bad_request", "levels 1"),
        ("{\"illuminants\": [\"Moonlight\"]}", "unknown_illuminant", "Moonlight"),
    ];
    for (body, code, needle) in cases {
        let r = job(body, "application/json").await.unwrap();
        problem_naming(r, 400, code, &[needle]).await;
    }
    problem(
        job("{}", "text/plain").await.unwrap(),
        415,
        "unsupported_media_type",
    )
    .await;
}

/// Malformed evaluation and illuminant bodies, and a built-in illuminant's name.
async fn hostile_evaluation_and_illuminant_bodies(h: &Hostile<'_>) {
    let (server, c) = (h.server, &h.c);
    // malformed evaluation and illuminant bodies
    let r = c
        .post(url(server, "/v1/evaluations"))
        .header("content-type", "application/json")
        .body("{\"method\": 3}")
        .send()
        .await
        .unwrap();
    problem(r, 400, "invalid_json").await;
    // an array is not a request object (serde alone would read one field by field)
    let r = c
        .post(url(server, "/v1/evaluations"))
        .header("content-type", "application/json")
        .body("[null]")
        .send()
        .await
        .unwrap();
    problem(r, 400, "invalid_json").await;
    let r = c
        .post(url(server, "/v1/evaluations"))
        .json(&serde_json::json!({"method": "magic"}))
        .send()
        .await
        .unwrap();
    problem(r, 400, "bad_request").await;
    let r = c
        .put(url(server, "/v1/illuminants/Bad"))
        .json(&serde_json::json!({"matrix": [[0,0,0],[0,0,0],[0,0,0]]}))
        .send()
        .await
        .unwrap();
    problem_naming(r, 400, "bad_request", &["singular"]).await;
    let r = c
        .put(url(server, "/v1/illuminants/Bad"))
        .json(&serde_json::json!({"cct": 3000, "matrix": [[1,0,0],[0,1,0],[0,0,1]]}))
        .send()
        .await
        .unwrap();
    problem(r, 400, "bad_request").await;
    let r = c
        .put(url(server, "/v1/illuminants/Bad"))
        .json(&serde_json::json!({"spd": {"wavelengths_nm": [400], "values": [1, 2]}}))
        .send()
        .await
        .unwrap();
    problem(r, 400, "bad_request").await;
    // more samples than a job or an evaluation takes of a light
    let n = l3::spectral::MAX_INLINE_SPD_SAMPLES + 1;
    let wl: Vec<f64> = (0..n).map(|i| 300.0 + i as f64 * 0.1).collect();
    let r = c
        .put(url(server, "/v1/illuminants/Bad"))
        .json(&serde_json::json!({"spd": {"wavelengths_nm": wl, "values": vec![1.0; n]}}))
        .send()
        .await
        .unwrap();
    problem_naming(r, 400, "bad_request", &["4097 samples; at most 4096"]).await;
    // a JSON evaluation request takes no query (a ColorChecker capture's parameters are for
    // a mosaic body)
    let r = c
        .post(url(server, "/v1/evaluations?chart=colorchecker"))
        .json(&serde_json::json!({"acquisition_illuminant": "D65"}))
        .send()
        .await
        .unwrap();
    problem_naming(r, 400, "bad_request", &["chart=colorchecker", "query"]).await;
    let r = c
        .post(url(server, "/v1/evaluations"))
        .header("content-type", "text/plain")
        .body("x")
        .send()
        .await
        .unwrap();
    problem_naming(
        r,
        415,
        "unsupported_media_type",
        &["application/json", "ColorChecker"],
    )
    .await;
    // a name no light can have is the path's mistake on every method
    let long = "x".repeat(65);
    for path in [
        "/v1/illuminants/bad%20name".to_string(),
        format!("/v1/illuminants/{long}"),
    ] {
        problem_of(c.get(url(server, &path)), 400, "bad_request").await;
        problem_of(c.delete(url(server, &path)), 400, "bad_request").await;
    }
    let r = c
        .put(url(server, "/v1/illuminants/bad%20name"))
        .json(&serde_json::json!({"cct": 3000}))
        .send()
        .await
        .unwrap();
    problem(r, 400, "bad_request").await;
    let r = c
        .put(url(server, "/v1/illuminants/D65"))
        .json(&serde_json::json!({"cct": 3000}))
        .send()
        .await
        .unwrap();
    problem(r, 409, "conflict").await;
}

/// Unknown routes and methods; after all that the service is still healthy.
async fn hostile_routes_and_methods(h: &Hostile<'_>) {
    let (server, c) = (h.server, &h.c);
    // unknown routes and methods
    problem_of(c.get(url(server, "/v2/nothing")), 404, "not_found").await;
    problem_of(c.get(url(server, "/v1/render")), 405, "method_not_allowed").await;
    // the service is still healthy
    assert_eq!(
        c.get(url(server, "/healthz"))
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
}
