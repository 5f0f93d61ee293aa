//! openapi.yaml and the service agree: every served route is documented and every documented
//! route is served, and the response check every service test runs its JSON answers through
//! (`service_support::openapi`) fails on bodies that break the document.

use std::collections::BTreeSet;

use crate::service_support::openapi::{check_response, route_template};
use serde_json::json;

#[test]
fn openapi_documents_exactly_the_served_routes() {
    let text = std::fs::read_to_string(concat!(env!("L3_ROOT"), "/openapi.yaml"))
        .expect("read openapi.yaml");
    let doc: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text).expect("openapi.yaml parses");
    assert!(doc["openapi"].as_str().unwrap().starts_with("3."));
    let paths = doc["paths"].as_mapping().expect("paths");
    let mut documented = BTreeSet::new();
    for (path, item) in paths {
        let path = path.as_str().unwrap();
        for (method, _) in item.as_mapping().unwrap() {
            let m = method.as_str().unwrap();
            if ["get", "put", "post", "delete", "patch", "head", "options"].contains(&m) {
                documented.insert((m.to_ascii_uppercase(), path.to_string()));
            }
        }
    }
    let served: BTreeSet<(String, String)> = l3::service::ROUTES
        .iter()
        .map(|(m, p)| (m.to_string(), p.to_string()))
        .collect();
    let undocumented: Vec<_> = served.difference(&documented).collect();
    let unserved: Vec<_> = documented.difference(&served).collect();
    assert!(
        undocumented.is_empty(),
        "served but not documented: {undocumented:?}"
    );
    assert!(
        unserved.is_empty(),
        "documented but not served: {unserved:?}"
    );
    // every $ref points at a defined component
    let comps = &doc["components"];
    for r in text.match_indices("$ref: \"#/components/") {
        let rest = &text[r.0 + "$ref: \"#/components/".len()..];
        let target = &rest[..rest.find('"').unwrap()];
        let (kind, name) = target.split_once('/').unwrap();
        assert!(
            !comps[kind][name].is_null(),
            "dangling $ref #/components/{target}"
        );
    }
}

/// The check fails where the document says otherwise: a missing required field, a wrong type,
/// a value outside an enum, a status the route does not document, an unknown problem code.
#[test]
fn the_response_check_fails_on_bodies_that_break_the_document() {
    let ok_job = json!({
        "id": "job_1", "status": "queued", "progress": 0.0, "stage": null, "error": null,
        "table_id": null, "activate": false, "attempts": 0, "idempotency_key": null,
        "request": {}, "created_at_ms": 1, "started_at_ms": null, "finished_at_ms": null,
        "timings": { "queued_ms": 0, "running_ms": null }, "links": {}
    });
    let check = |method, path, status, ctype, body: &serde_json::Value| {
        check_response(
            Some(method),
            path,
            status,
            ctype,
            body.to_string().as_bytes(),
        )
    };
    let job_path = "/v1/training-jobs/job_1";
    assert_eq!(route_template(job_path), Some("/v1/training-jobs/{id}"));
    assert_eq!(
        route_template("/v1/training-jobs/job_1/cancel"),
        Some("/v1/training-jobs/{id}/cancel")
    );
    check("GET", job_path, 200, "application/json", &ok_job).unwrap();

    let mut missing = ok_job.clone();
    missing.as_object_mut().unwrap().remove("attempts");
    let e = check("GET", job_path, 200, "application/json", &missing).unwrap_err();
    assert!(e.contains("attempts"), "{e}");

    let mut wrong_type = ok_job.clone();
    wrong_type["progress"] = json!("half");
    let e = check("GET", job_path, 200, "application/json", &wrong_type).unwrap_err();
    assert!(e.contains("/progress"), "{e}");

    let mut not_in_enum = ok_job.clone();
    not_in_enum["status"] = json!("paused");
    assert!(check("GET", job_path, 200, "application/json", &not_in_enum).is_err());

    // a status the route does not document
    let e = check("GET", job_path, 418, "application/json", &ok_job).unwrap_err();
    assert!(e.contains("no 418"), "{e}");

    // problem documents: a code the document does not list, a missing detail
    let problem = json!({
        "type": "https://l3.invalid/problems/not_found", "title": "Not Found",
        "status": 404, "code": "not_found", "detail": "no training job with id 'x'"
    });
    let ptype = "application/problem+json";
    check("GET", job_path, 404, ptype, &problem).unwrap();
    let mut unknown_code = problem.clone();
    unknown_code["code"] = json!("teapot");
    assert!(check("GET", job_path, 404, ptype, &unknown_code).is_err());
    let mut no_detail = problem.clone();
    no_detail.as_object_mut().unwrap().remove("detail");
    assert!(check("GET", job_path, 404, ptype, &no_detail).is_err());
    // a path the document does not have is held to the problem schema
    check("GET", "/nowhere", 404, ptype, &problem).unwrap();
    assert!(check("GET", "/nowhere", 404, ptype, &json!({"oops": 1})).is_err());

    // with the method unknown, one of the route's methods must document the answer
    let list = json!({ "items": [ok_job] });
    check_response(
        None,
        "/v1/training-jobs",
        200,
        "application/json",
        list.to_string().as_bytes(),
    )
    .unwrap();
    assert!(
        check_response(
            None,
            "/v1/training-jobs",
            200,
            "application/json",
            json!({ "items": 3 }).to_string().as_bytes(),
        )
        .is_err()
    );
    // a body that is not JSON under a JSON content type
    assert!(check_response(Some("GET"), job_path, 200, "application/json", b"not json").is_err());
}
