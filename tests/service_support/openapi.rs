//! Response bodies checked against `openapi.yaml`: a JSON body must match the schema the
//! document gives for its route template, method and status (and content type), with the
//! `jsonschema` crate. The document is OpenAPI 3.1, whose schemas are JSON Schema 2020-12;
//! a schema's `$ref`s to `#/components/…` resolve because the components are put beside it,
//! and a response that is a `$ref` to `#/components/responses/…` is followed first.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use serde_json::Value;

/// Statuses any route may answer, by the document's description.
const ANY_ROUTE: [u16; 3] = [405, 500, 504];

/// The document, as JSON.
fn document() -> &'static Value {
    static DOC: OnceLock<Value> = OnceLock::new();
    DOC.get_or_init(|| {
        let path = concat!(env!("L3_ROOT"), "/openapi.yaml");
        let text = std::fs::read_to_string(path).expect("read openapi.yaml");
        let yaml: serde_yaml_ng::Value =
            serde_yaml_ng::from_str(&text).expect("openapi.yaml parses");
        let doc = serde_json::to_value(yaml).expect("openapi.yaml as JSON");
        assert!(
            doc["openapi"]
                .as_str()
                .is_some_and(|v| v.starts_with("3.1")),
            "the checks read schemas as JSON Schema 2020-12, which is OpenAPI 3.1's dialect"
        );
        doc
    })
}

/// The route templates of the document (`/v1/tables/{id}`, …).
fn templates(doc: &Value) -> Vec<&str> {
    doc["paths"]
        .as_object()
        .map(|m| m.keys().map(String::as_str).collect())
        .unwrap_or_default()
}

/// The template a concrete path is served by: the one whose segments match, literal segments
/// preferred over parameters. `None` for a path the document does not have.
pub fn route_template(path: &str) -> Option<&'static str> {
    let path = path.split(['?', '#']).next().unwrap_or(path);
    let segs: Vec<&str> = path.split('/').collect();
    templates(document())
        .into_iter()
        .filter_map(|t| {
            let ts: Vec<&str> = t.split('/').collect();
            if ts.len() != segs.len() {
                return None;
            }
            let mut literal = 0;
            for (a, b) in ts.iter().zip(&segs) {
                if a.starts_with('{') && a.ends_with('}') {
                    if b.is_empty() {
                        return None;
                    }
                } else if a == b {
                    literal += 1;
                } else {
                    return None;
                }
            }
            Some((literal, t))
        })
        .max_by_key(|(literal, _)| *literal)
        .map(|(_, t)| t)
}

/// Follows a local `$ref` (`#/…`) of the document.
fn resolve<'a>(doc: &'a Value, v: &'a Value) -> Result<&'a Value, String> {
    match v.get("$ref").and_then(Value::as_str) {
        None => Ok(v),
        Some(r) => {
            let pointer = r
                .strip_prefix('#')
                .ok_or_else(|| format!("$ref {r} is not local"))?;
            doc.pointer(pointer)
                .ok_or_else(|| format!("dangling $ref {r}"))
        }
    }
}

/// A validator for `schema` with the document's components beside it.
fn validator(doc: &Value, schema: &Value) -> Result<Arc<jsonschema::Validator>, String> {
    static CACHE: OnceLock<Mutex<HashMap<String, Arc<jsonschema::Validator>>>> = OnceLock::new();
    let key = schema.to_string();
    let cache = CACHE.get_or_init(Default::default);
    if let Some(v) = cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
        return Ok(v.clone());
    }
    let mut full = match schema {
        Value::Object(m) => m.clone(),
        other => return Err(format!("a schema that is not an object: {other}")),
    };
    full.insert("components".into(), doc["components"].clone());
    let v = jsonschema::draft202012::options()
        .build(&Value::Object(full))
        .map_err(|e| format!("the schema does not compile: {e}"))?;
    let v = Arc::new(v);
    cache
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .insert(key, v.clone());
    Ok(v)
}

/// The media type without parameters, lower case.
fn media_type(content_type: &str) -> String {
    content_type
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase()
}

/// Checks `body` (an answer with `status` and `content_type` to `method` on `path`) against
/// the schema the document gives for it. With `method` unknown, the route's methods that
/// document `status` are tried and the body must match one of them. A path the document does
/// not have is held to the problem schema (the router's 404). Bodies that are not JSON
/// (`application/json`, `application/problem+json`) are not checked.
pub fn check_response(
    method: Option<&str>,
    path: &str,
    status: u16,
    content_type: &str,
    body: &[u8],
) -> Result<(), String> {
    let doc = document();
    let media = media_type(content_type);
    if media != "application/json" && media != "application/problem+json" {
        return Ok(());
    }
    let value: Value = serde_json::from_slice(body).map_err(|e| {
        format!(
            "{status} {media} body of {path} is not JSON ({e}): {}",
            String::from_utf8_lossy(body)
        )
    })?;
    let Some(template) = route_template(path) else {
        let schema = json_schema_of(doc, &doc["components"]["responses"]["Problem"], &media)?;
        return validate(doc, schema, &value).map_err(|e| format!("{status} on {path}: {e}"));
    };
    let item = &doc["paths"][template];
    // the statuses the document's description gives every route (405 to a method a route does
    // not serve, 500, 504 past the request timeout) are problems wherever no operation lists them
    if ANY_ROUTE.contains(&status)
        && !["get", "put", "post", "delete", "patch"].iter().any(|m| {
            item.get(*m)
                .is_some_and(|op| op["responses"].get(status.to_string()).is_some())
        })
    {
        let schema = json_schema_of(doc, &doc["components"]["responses"]["Problem"], &media)?;
        return validate(doc, schema, &value).map_err(|e| format!("{status} on {path}: {e}"));
    }
    let methods: Vec<String> = match method {
        Some(m) => vec![m.to_ascii_lowercase()],
        None => ["get", "put", "post", "delete", "patch"]
            .iter()
            .filter(|m| item.get(**m).is_some())
            .map(|m| m.to_string())
            .collect(),
    };
    let mut tried = Vec::new();
    for m in &methods {
        let Some(op) = item.get(m.as_str()) else {
            tried.push(format!("{} {template} is not documented", m.to_uppercase()));
            continue;
        };
        let Some(resp) = op["responses"].get(status.to_string()) else {
            tried.push(format!(
                "{} {template} documents no {status} answer",
                m.to_uppercase()
            ));
            continue;
        };
        let checked = resolve(doc, resp)
            .and_then(|r| json_schema_of(doc, r, &media))
            .and_then(|schema| validate(doc, schema, &value));
        match checked {
            Ok(()) => return Ok(()),
            Err(e) => tried.push(format!("{} {template} {status}: {e}", m.to_uppercase())),
        }
    }
    Err(format!(
        "the {status} {media} answer of {path} breaks openapi.yaml:\n  {}\nbody: {value}",
        tried.join("\n  ")
    ))
}

/// The schema of a response's `media` content.
fn json_schema_of<'a>(doc: &'a Value, resp: &'a Value, media: &str) -> Result<&'a Value, String> {
    let resp = resolve(doc, resp)?;
    resp.get("content")
        .and_then(|c| c.get(media))
        .and_then(|c| c.get("schema"))
        .ok_or_else(|| format!("no {media} content documented"))
}

fn validate(doc: &Value, schema: &Value, value: &Value) -> Result<(), String> {
    let v = validator(doc, schema)?;
    let errors: Vec<String> = v
        .iter_errors(value)
        .map(|e| format!("at '{}': {e}", e.instance_path()))
        .collect();
    if errors.is_empty() {
        Ok(())
    } else {
        Err(errors.join("; "))
    }
}

/// [`check_response`], panicking with what is wrong.
pub fn assert_response(
    method: Option<&str>,
    path: &str,
    status: u16,
    content_type: &str,
    body: &[u8],
) {
    if let Err(e) = check_response(method, path, status, content_type, body) {
        panic!("{e}");
    }
}
