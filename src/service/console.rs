//! The console: a page at `/` that drives the API from a browser (status, renders, tables and
//! sensors, training jobs, evaluations, illuminants). Plain HTML, CSS and JavaScript embedded in
//! the binary (`console/`), no build step and nothing loaded from another host: the
//! Content-Security-Policy allows only this origin (and `blob:` images, the renders and figures
//! the page fetches). The page is a GET, so it needs no bearer token; the API calls it makes
//! send the token typed into its Token field.
//!
//! Each file is answered with `Cache-Control: no-cache` and a strong ETag (its SHA-256), so a
//! browser revalidates it (304) and a new build's console is never served stale.

use std::sync::OnceLock;

use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};

use super::state::sha256_hex;

/// The console's files: (served path, content type, text).
pub const FILES: [(&str, &str, &str); 3] = [
    (
        "/",
        "text/html; charset=utf-8",
        include_str!("console/index.html"),
    ),
    (
        "/console/console.css",
        "text/css; charset=utf-8",
        include_str!("console/console.css"),
    ),
    (
        "/console/console.js",
        "text/javascript; charset=utf-8",
        include_str!("console/console.js"),
    ),
];

/// Only this origin; rendered images and figures are shown from blob URLs.
const CSP: &str = "default-src 'self'; img-src 'self' blob:; script-src 'self'; \
style-src 'self'; connect-src 'self'; object-src 'none'; base-uri 'none'; \
form-action 'none'; frame-ancestors 'none'";

/// The strong ETag of each of [`FILES`], computed once.
fn etag(index: usize) -> &'static str {
    static TAGS: OnceLock<Vec<String>> = OnceLock::new();
    let tags = TAGS.get_or_init(|| {
        FILES
            .iter()
            .map(|(_, _, text)| format!("\"{}\"", &sha256_hex(text.as_bytes())[..32]))
            .collect()
    });
    &tags[index]
}

/// Whether `If-None-Match` names `tag` (or is `*`).
fn not_modified(headers: &HeaderMap, tag: &str) -> bool {
    headers
        .get_all(header::IF_NONE_MATCH)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(|t| t.trim().trim_start_matches("W/"))
        .any(|t| t == tag || t == "*")
}

fn file(index: usize, headers: &HeaderMap) -> Response {
    let (_, ctype, text) = FILES[index];
    let tag = etag(index);
    let mut resp = if not_modified(headers, tag) {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        let mut r = text.into_response();
        r.headers_mut()
            .insert(header::CONTENT_TYPE, HeaderValue::from_static(ctype));
        r
    };
    let h = resp.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    if let Ok(v) = HeaderValue::from_str(tag) {
        h.insert(header::ETAG, v);
    }
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    if index == 0 {
        h.insert(
            header::CONTENT_SECURITY_POLICY,
            HeaderValue::from_static(CSP),
        );
        h.insert(
            header::REFERRER_POLICY,
            HeaderValue::from_static("no-referrer"),
        );
    }
    resp
}

/// `GET /`: the console's page.
pub async fn page(headers: HeaderMap) -> Response {
    file(0, &headers)
}

/// `GET /console/console.css`.
pub async fn css(headers: HeaderMap) -> Response {
    file(1, &headers)
}

/// `GET /console/console.js`.
pub async fn js(headers: HeaderMap) -> Response {
    file(2, &headers)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn etags_and_revalidation() {
        let tag = etag(2);
        assert!(tag.starts_with('"') && tag.len() == 34, "{tag}");
        assert_ne!(etag(0), etag(1));
        let mut h = HeaderMap::new();
        assert!(!not_modified(&h, tag));
        h.insert(header::IF_NONE_MATCH, HeaderValue::from_str(tag).unwrap());
        assert!(not_modified(&h, tag));
        assert_eq!(file(2, &h).status(), StatusCode::NOT_MODIFIED);
        h.insert(
            header::IF_NONE_MATCH,
            HeaderValue::from_static("\"other\", W/\"x\""),
        );
        assert!(!not_modified(&h, tag));
        let r = file(0, &h);
        assert_eq!(r.status(), StatusCode::OK);
        assert_eq!(
            r.headers()[header::CONTENT_TYPE],
            "text/html; charset=utf-8"
        );
        assert!(r.headers().contains_key(header::CONTENT_SECURITY_POLICY));
    }

    #[test]
    fn the_page_names_its_assets() {
        let page = FILES[0].2;
        for (path, _, _) in &FILES[1..] {
            assert!(page.contains(path), "index.html does not load {path}");
        }
    }
}
