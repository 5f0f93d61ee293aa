//! The service's error type and its one mapping to `application/problem+json` (RFC 9457).

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};

/// Everything a request (or the service's start) can fail with. Each variant has a stable
/// machine-readable `code` and an HTTP status; the message says exactly what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// A malformed request: query parameters, headers or body fields.
    #[error("{0}")]
    BadRequest(String),
    /// A body that is not a usable image/mosaic (size, format, values).
    #[error("{0}")]
    InvalidImage(String),
    /// A body that is not valid JSON for the endpoint.
    #[error("{0}")]
    InvalidJson(String),
    /// An illuminant that is neither registered nor a `cct:K` / `xy:x,y` spec.
    #[error("{0}")]
    UnknownIlluminant(String),
    /// An input the request's parameters make inconsistent.
    #[error("{0}")]
    Unprocessable(String),
    /// The input's CFA (from the query or the file) is not the active table's.
    #[error("{source_desc} CFA '{input}' does not match the active table's CFA '{table}'")]
    CfaMismatch {
        /// Where the input's CFA comes from, e.g. "the query's" or "the DNG's".
        source_desc: &'static str,
        input: String,
        table: String,
    },
    #[error("{0}")]
    NotFound(String),
    #[error("{0}")]
    Conflict(String),
    #[error("{0}")]
    PayloadTooLarge(String),
    #[error("{0}")]
    UnsupportedMediaType(String),
    #[error("{0}")]
    NotAcceptable(String),
    #[error("{0}")]
    MethodNotAllowed(String),
    #[error("{0}")]
    Unauthorized(String),
    /// Too many renders at once; retry after the given seconds.
    #[error("{msg}")]
    Overloaded { msg: String, retry_after_s: u64 },
    /// No active table yet (the default table is still training).
    #[error("{0}")]
    NotReady(String),
    #[error("{0}")]
    Timeout(String),
    /// The request body did not arrive in time (too slow, or stalled).
    #[error("{0}")]
    BodyTimeout(String),
    /// Configuration errors (at start).
    #[error("configuration: {0}")]
    Config(String),
    /// Database errors.
    #[error("database: {0}")]
    Database(String),
    /// Anything else that is the server's fault.
    #[error("{0}")]
    Internal(String),
}

impl ServiceError {
    /// The HTTP status.
    pub fn status(&self) -> StatusCode {
        use ServiceError::*;
        match self {
            BadRequest(_) | InvalidImage(_) | InvalidJson(_) | UnknownIlluminant(_) => {
                StatusCode::BAD_REQUEST
            }
            Unprocessable(_) | CfaMismatch { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            NotFound(_) => StatusCode::NOT_FOUND,
            Conflict(_) => StatusCode::CONFLICT,
            PayloadTooLarge(_) => StatusCode::PAYLOAD_TOO_LARGE,
            UnsupportedMediaType(_) => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            NotAcceptable(_) => StatusCode::NOT_ACCEPTABLE,
            MethodNotAllowed(_) => StatusCode::METHOD_NOT_ALLOWED,
            Unauthorized(_) => StatusCode::UNAUTHORIZED,
            Overloaded { .. } | NotReady(_) => StatusCode::SERVICE_UNAVAILABLE,
            Timeout(_) => StatusCode::GATEWAY_TIMEOUT,
            BodyTimeout(_) => StatusCode::REQUEST_TIMEOUT,
            Config(_) | Database(_) | Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    /// The stable machine-readable code.
    pub fn code(&self) -> &'static str {
        use ServiceError::*;
        match self {
            BadRequest(_) => "bad_request",
            InvalidImage(_) => "invalid_image",
            InvalidJson(_) => "invalid_json",
            UnknownIlluminant(_) => "unknown_illuminant",
            Unprocessable(_) => "unprocessable",
            CfaMismatch { .. } => "cfa_mismatch",
            NotFound(_) => "not_found",
            Conflict(_) => "conflict",
            PayloadTooLarge(_) => "payload_too_large",
            UnsupportedMediaType(_) => "unsupported_media_type",
            NotAcceptable(_) => "not_acceptable",
            MethodNotAllowed(_) => "method_not_allowed",
            Unauthorized(_) => "unauthorized",
            Overloaded { .. } => "overloaded",
            NotReady(_) => "not_ready",
            Timeout(_) => "request_timeout",
            BodyTimeout(_) => "body_timeout",
            Config(_) => "config",
            Database(_) => "database",
            Internal(_) => "internal",
        }
    }

    /// The problem document.
    pub fn problem(&self) -> serde_json::Value {
        let status = self.status();
        serde_json::json!({
            "type": format!("https://l3.invalid/problems/{}", self.code()),
            "title": status.canonical_reason().unwrap_or("error"),
            "status": status.as_u16(),
            "code": self.code(),
            "detail": self.to_string(),
        })
    }
}

impl IntoResponse for ServiceError {
    fn into_response(self) -> Response {
        let status = self.status();
        if status == StatusCode::INTERNAL_SERVER_ERROR {
            tracing::error!(code = self.code(), "{self}");
        } else if status.is_server_error() {
            tracing::debug!(code = self.code(), "{self}");
        }
        let body = serde_json::to_vec(&self.problem()).unwrap_or_default();
        let mut resp = (status, body).into_response();
        resp.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        if let ServiceError::Overloaded { retry_after_s, .. } = &self
            && let Ok(v) = HeaderValue::from_str(&retry_after_s.to_string())
        {
            resp.headers_mut().insert(header::RETRY_AFTER, v);
        }
        if let ServiceError::BodyTimeout(_) = &self {
            // the rest of the body is not read: the connection cannot be reused
            resp.headers_mut()
                .insert(header::CONNECTION, HeaderValue::from_static("close"));
        }
        if let ServiceError::NotReady(_) = &self {
            resp.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
        }
        if let ServiceError::Unauthorized(_) = &self {
            resp.headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        resp
    }
}

impl From<sqlx::Error> for ServiceError {
    fn from(e: sqlx::Error) -> Self {
        ServiceError::Database(e.to_string())
    }
}

impl From<sqlx::migrate::MigrateError> for ServiceError {
    fn from(e: sqlx::migrate::MigrateError) -> Self {
        ServiceError::Database(format!("migration failed: {e}"))
    }
}

impl From<crate::io::IoError> for ServiceError {
    fn from(e: crate::io::IoError) -> Self {
        use crate::io::IoError::*;
        match e {
            File { .. } | Encode { .. } => ServiceError::Internal(e.to_string()),
            Length { .. }
            | ZeroDimension { .. }
            | DimensionTooLarge { .. }
            | TooManyPixels { .. }
            | UnknownFormat { .. }
            | PixelLayout { .. }
            | Png(_)
            | Tiff(_)
            | Dng(_)
            | Pgm(_)
            | NonFinite { .. }
            | Sidecar { .. }
            | InvalidMeta(_) => ServiceError::InvalidImage(e.to_string()),
        }
    }
}

impl From<crate::render_pipeline::PipelineError> for ServiceError {
    fn from(e: crate::render_pipeline::PipelineError) -> Self {
        use crate::l3::L3Error;
        use crate::render_pipeline::PipelineError;
        match e {
            PipelineError::Options(m) => ServiceError::BadRequest(m),
            PipelineError::Correction(e) => ServiceError::Internal(e.to_string()),
            PipelineError::Encode(e) => e.into(),
            PipelineError::Render(e) => match e {
                L3Error::InvalidInput(_) | L3Error::InvalidParams(_) => {
                    ServiceError::InvalidImage(e.to_string())
                }
                // nobody waits for the answer of a canceled render any more
                L3Error::RenderCanceled => {
                    ServiceError::Timeout("the render was abandoned by its request".into())
                }
                other => ServiceError::Internal(other.to_string()),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn problem_json_has_code_and_detail() {
        let e = ServiceError::InvalidImage("body has 1000 bytes".into());
        let p = e.problem();
        assert_eq!(p["status"], 400);
        assert_eq!(p["code"], "invalid_image");
        assert_eq!(p["detail"], "body has 1000 bytes");
        let r = ServiceError::Overloaded {
            msg: "busy".into(),
            retry_after_s: 2,
        }
        .into_response();
        assert_eq!(r.status(), StatusCode::SERVICE_UNAVAILABLE);
        assert_eq!(r.headers()[header::RETRY_AFTER], "2");
        assert_eq!(
            r.headers()[header::CONTENT_TYPE],
            "application/problem+json"
        );
    }
}
