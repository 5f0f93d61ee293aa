//! The router: the route list (one const, checked against openapi.yaml by a test), the
//! console, health, readiness, metrics, the OpenAPI document, and the middleware (auth, timeout, metrics,
//! tracing, request ids, body limit).

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::http::{HeaderValue, Method, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{MethodRouter, delete, get, post, put};
use serde_json::json;
use tower_http::request_id::{
    MakeRequestId, PropagateRequestIdLayer, RequestId, SetRequestIdLayer,
};
use tower_http::trace::TraceLayer;

use super::state::AppState;
use super::{ServiceError, console, evaluations, illuminants, jobs, render, sensors, tables};

/// Every served route as (method, path); openapi.yaml documents exactly these.
pub const ROUTES: &[(&str, &str)] = &[
    ("POST", "/v1/render"),
    ("POST", "/v1/training-jobs"),
    ("GET", "/v1/training-jobs"),
    ("GET", "/v1/training-jobs/{id}"),
    ("POST", "/v1/training-jobs/{id}/cancel"),
    ("GET", "/v1/tables"),
    ("GET", "/v1/tables/{id}"),
    ("GET", "/v1/tables/{id}/download"),
    ("POST", "/v1/tables/{id}/activate"),
    ("GET", "/v1/sensors"),
    ("GET", "/v1/sensors/{name}"),
    ("GET", "/v1/illuminants"),
    ("GET", "/v1/illuminants/{name}"),
    ("PUT", "/v1/illuminants/{name}"),
    ("DELETE", "/v1/illuminants/{name}"),
    ("POST", "/v1/evaluations"),
    ("GET", "/v1/evaluations"),
    ("GET", "/v1/evaluations/{id}"),
    ("GET", "/healthz"),
    ("GET", "/readyz"),
    ("GET", "/metrics"),
    ("GET", "/openapi.yaml"),
    ("GET", "/"),
    ("GET", "/console/console.css"),
    ("GET", "/console/console.js"),
];

/// The routes besides `/v1/render` whose POST or PUT reads a body ([`render::admit_body`]).
const BODY_ROUTES: &[&str] = &[
    "/v1/training-jobs",
    "/v1/illuminants/{name}",
    "/v1/evaluations",
];

/// The committed OpenAPI document, served at `/openapi.yaml`.
pub const OPENAPI_YAML: &str = include_str!("../../openapi.yaml");

/// Whether a request to `route` (the matched route's template) changes something, and so needs
/// the bearer token when one is configured: a served route other than a read or a render. A
/// method the route does not serve changes nothing: it gets its 405 whoever asks.
fn is_mutating(method: &Method, route: &str) -> bool {
    method != Method::GET
        && method != Method::HEAD
        && route != "/v1/render"
        && ROUTES
            .iter()
            .any(|&(m, r)| m == method.as_str() && r == route)
}

fn handler(method: &str, path: &str) -> Option<MethodRouter<AppState>> {
    Some(match (method, path) {
        ("POST", "/v1/render") => post(render::render),
        ("POST", "/v1/training-jobs") => post(jobs::submit),
        ("GET", "/v1/training-jobs") => get(jobs::list),
        ("GET", "/v1/training-jobs/{id}") => get(jobs::get),
        ("POST", "/v1/training-jobs/{id}/cancel") => post(jobs::cancel),
        ("GET", "/v1/tables") => get(tables::list),
        ("GET", "/v1/tables/{id}") => get(tables::get),
        ("GET", "/v1/tables/{id}/download") => get(tables::download),
        ("POST", "/v1/tables/{id}/activate") => post(tables::activate),
        ("GET", "/v1/sensors") => get(sensors::list),
        ("GET", "/v1/sensors/{name}") => get(sensors::get),
        ("GET", "/v1/illuminants") => get(illuminants::list),
        ("GET", "/v1/illuminants/{name}") => get(illuminants::get),
        ("PUT", "/v1/illuminants/{name}") => put(illuminants::put),
        ("DELETE", "/v1/illuminants/{name}") => delete(illuminants::delete),
        ("POST", "/v1/evaluations") => post(evaluations::create),
        ("GET", "/v1/evaluations") => get(evaluations::list),
        ("GET", "/v1/evaluations/{id}") => get(evaluations::get),
        ("GET", "/healthz") => get(healthz),
        ("GET", "/readyz") => get(readyz),
        ("GET", "/metrics") => get(metrics),
        ("GET", "/openapi.yaml") => get(openapi),
        ("GET", "/") => get(console::page),
        ("GET", "/console/console.css") => get(console::css),
        ("GET", "/console/console.js") => get(console::js),
        _ => return None,
    })
}

async fn healthz(State(state): State<AppState>) -> impl IntoResponse {
    axum::Json(json!({
        "status": "ok",
        "version": env!("CARGO_PKG_VERSION"),
        "backend": state.store.backend(),
    }))
}

async fn readyz(State(state): State<AppState>) -> Result<Response, ServiceError> {
    match state.active.load_full() {
        Some(a) => Ok(axum::Json(json!({ "status": "ready", "table_id": a.id })).into_response()),
        None => {
            let job = state.store.pending_activating_job().await?;
            Err(ServiceError::NotReady(match job {
                Some(j) => format!("no table is active yet; training job {j} will provide one"),
                None => {
                    "no table is active; train one (POST /v1/training-jobs) and activate it".into()
                }
            }))
        }
    }
}

/// How long a scrape waits for the database's job counts: a database that is down must not
/// take every other metric with it (nor hold the scrape for the pool's 10 s).
const SCRAPE_DATABASE_WAIT: Duration = Duration::from_secs(2);

async fn metrics(State(state): State<AppState>) -> Result<Response, ServiceError> {
    let counts = match tokio::time::timeout(SCRAPE_DATABASE_WAIT, jobs::counts(&state)).await {
        Ok(Ok(c)) => Some(c),
        Ok(Err(e)) => {
            tracing::warn!("metrics: the job counts are not available: {e}");
            None
        }
        Err(_) => {
            tracing::warn!("metrics: the database did not give the job counts within 2 s");
            None
        }
    };
    let text = state
        .metrics
        .render(&super::metrics::Scrape {
            jobs: counts.as_deref(),
            ready: state.active.load().is_some(),
            body_bytes_reserved: state.admission.reserved_bytes(),
            queue_length: state.admission.queued(),
            cache_bytes: state.tables.held_bytes(),
            cache_bound_bytes: state.tables.bound(),
        })
        .map_err(|e| ServiceError::Internal(format!("metrics exposition: {e}")))?;
    let mut r = text.into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8"),
    );
    Ok(r)
}

async fn openapi() -> Response {
    let mut r = OPENAPI_YAML.into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/yaml"),
    );
    r
}

async fn not_found(req: Request) -> ServiceError {
    ServiceError::NotFound(format!(
        "no route for {} {}",
        req.method(),
        req.uri().path()
    ))
}

async fn method_not_allowed(req: Request) -> ServiceError {
    ServiceError::MethodNotAllowed(format!(
        "method {} is not allowed on {}",
        req.method(),
        req.uri().path()
    ))
}

/// Bearer token check, request timeout and metrics around every request.
async fn guard(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let started = Instant::now();
    let method = req.method().clone();
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_string())
        .unwrap_or_else(|| "unmatched".into());
    let token = &state.config.server.bearer_token;
    let resp = if !token.is_empty() && is_mutating(&method, &route) {
        let ok = req
            .headers()
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(bearer_credentials)
            .is_some_and(|t| constant_time_eq(t.as_bytes(), token.as_bytes()));
        if ok {
            None
        } else {
            Some(
                ServiceError::Unauthorized(
                    "this endpoint needs Authorization: Bearer <token>".into(),
                )
                .into_response(),
            )
        }
    } else {
        None
    };
    let resp = match resp {
        Some(r) => r,
        None => {
            let limit = Duration::from_secs_f64(state.config.server.request_timeout_s);
            match tokio::time::timeout(limit, next.run(req)).await {
                Ok(r) => r,
                Err(_) => ServiceError::Timeout(format!(
                    "the request took longer than the {} s limit",
                    state.config.server.request_timeout_s
                ))
                .into_response(),
            }
        }
    };
    // an extractor's plain-text rejection (e.g. a path that is not UTF-8) as a problem
    let resp = super::error::as_problem(resp).await;
    state.metrics.observe(
        method.as_str(),
        &route,
        resp.status().as_u16(),
        started.elapsed().as_secs_f64(),
    );
    resp
}

/// The token of an `Authorization: Bearer <token>` header value; the scheme is
/// case-insensitive (RFC 9110 §11.1), and spaces around the token are ignored.
fn bearer_credentials(value: &str) -> Option<&str> {
    let (scheme, token) = value.trim_start().split_once([' ', '\t'])?;
    scheme
        .eq_ignore_ascii_case("bearer")
        .then_some(token.trim())
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[derive(Clone, Default)]
struct Counter(std::sync::Arc<AtomicU64>);

impl MakeRequestId for Counter {
    fn make_request_id<B>(&mut self, _req: &axum::http::Request<B>) -> Option<RequestId> {
        let n = self.0.fetch_add(1, Ordering::Relaxed);
        HeaderValue::from_str(&format!("req-{n}"))
            .ok()
            .map(RequestId::new)
    }
}

/// The application router with all middleware.
pub fn router(state: AppState) -> Router {
    let mut r: Router<AppState> = Router::new();
    for (m, p) in ROUTES {
        if let Some(mut h) = handler(m, p) {
            if *p == "/v1/render" {
                // the body is read, then the request queues for a render slot
                h = h.route_layer(middleware::from_fn_with_state(state.clone(), render::admit));
            } else if matches!(*m, "POST" | "PUT") && BODY_ROUTES.contains(p) {
                // the body is read within the same budget and deadline
                h = h.route_layer(middleware::from_fn_with_state(
                    state.clone(),
                    render::admit_body,
                ));
            }
            r = r.route(p, h);
        } else {
            tracing::error!("route {m} {p} has no handler");
        }
    }
    let body_limit = state.config.server.max_body_bytes;
    r.fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .route_layer(middleware::from_fn_with_state(state.clone(), guard))
        .layer(DefaultBodyLimit::max(body_limit))
        // 5xx are logged by ServiceError (500 at ERROR); overload 503s would flood the log
        .layer(TraceLayer::new_for_http().on_failure(()))
        .layer(PropagateRequestIdLayer::x_request_id())
        .layer(SetRequestIdLayer::x_request_id(Counter::default()))
        .with_state(state)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_route_has_a_handler() {
        for (m, p) in ROUTES {
            assert!(handler(m, p).is_some(), "{m} {p}");
        }
    }

    #[test]
    fn mutating_routes() {
        assert!(is_mutating(&Method::POST, "/v1/training-jobs"));
        assert!(is_mutating(&Method::DELETE, "/v1/illuminants/{name}"));
        assert!(is_mutating(&Method::POST, "/v1/tables/{id}/activate"));
        assert!(!is_mutating(&Method::POST, "/v1/render"));
        assert!(!is_mutating(&Method::GET, "/v1/tables"));
        // methods a route does not serve are answered 405, token or not
        assert!(!is_mutating(&Method::DELETE, "/v1/tables"));
        assert!(!is_mutating(&Method::OPTIONS, "/healthz"));
        assert!(!is_mutating(&Method::POST, "unmatched"));
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        for (header, token) in [
            ("Bearer s3cret", Some("s3cret")),
            ("bearer s3cret", Some("s3cret")),
            ("BEARER  s3cret ", Some("s3cret")),
            ("Basic s3cret", None),
            ("Bearers3cret", None),
        ] {
            assert_eq!(bearer_credentials(header), token, "{header}");
        }
    }
}
