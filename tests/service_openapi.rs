//! openapi.yaml and the router agree: every served route is documented and every documented
//! route is served.

use std::collections::BTreeSet;

#[test]
fn openapi_documents_exactly_the_served_routes() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/openapi.yaml"))
        .expect("read openapi.yaml");
    assert_eq!(
        text,
        l3::service::OPENAPI_YAML,
        "the served document is the committed file"
    );
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
