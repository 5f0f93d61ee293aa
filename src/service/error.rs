//! The service's error type and its one mapping to `application/problem+json` (RFC 9457).

use std::path::Path;
use std::sync::Mutex;

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};

use super::store::StoreError;

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
    /// The input's CFA (from the query or the file) is not the rendering table's.
    #[error("{source_desc} CFA '{input}' does not match the table's CFA '{table}'")]
    CfaMismatch {
        /// Where the input's CFA comes from, e.g. "the query's" or "the DNG's".
        source_desc: &'static str,
        input: String,
        table: String,
    },
    /// The file's camera is a catalogue sensor no stored table was trained for.
    #[error("{0}")]
    UntrainedCamera(String),
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
    /// The listener cannot take its address (at start).
    #[error(
        "cannot listen on {addr}: {source} (is another process using it? choose another address with --bind or L3_BIND)"
    )]
    Bind {
        addr: std::net::SocketAddr,
        #[source]
        source: std::io::Error,
    },
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
            Unprocessable(_) | CfaMismatch { .. } | UntrainedCamera(_) => {
                StatusCode::UNPROCESSABLE_ENTITY
            }
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
            Config(_) | Database(_) | Bind { .. } | Internal(_) => {
                StatusCode::INTERNAL_SERVER_ERROR
            }
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
            UntrainedCamera(_) => "untrained_camera",
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
            Bind { .. } => "bind",
            Internal(_) => "internal",
        }
    }

    /// The problem document. Its detail names no directory of the server
    /// (`without_server_paths`).
    pub fn problem(&self) -> serde_json::Value {
        let status = self.status();
        serde_json::json!({
            "type": format!("https://l3.invalid/problems/{}", self.code()),
            "title": status.canonical_reason().unwrap_or("error"),
            "status": status.as_u16(),
            "code": self.code(),
            "detail": without_server_paths(&self.to_string()),
        })
    }

    /// The error of a response that did not come from a `ServiceError` (an extractor's
    /// rejection, e.g. a path that is not UTF-8), by its status, with its text as the detail.
    pub fn from_status(status: StatusCode, text: &str) -> ServiceError {
        let text = if text.trim().is_empty() {
            status.canonical_reason().unwrap_or("error").to_string()
        } else {
            text.trim().to_string()
        };
        match status {
            StatusCode::NOT_FOUND => ServiceError::NotFound(text),
            StatusCode::METHOD_NOT_ALLOWED => ServiceError::MethodNotAllowed(text),
            StatusCode::PAYLOAD_TOO_LARGE => ServiceError::PayloadTooLarge(text),
            StatusCode::UNSUPPORTED_MEDIA_TYPE => ServiceError::UnsupportedMediaType(text),
            StatusCode::UNPROCESSABLE_ENTITY => ServiceError::Unprocessable(text),
            StatusCode::NOT_ACCEPTABLE => ServiceError::NotAcceptable(text),
            StatusCode::REQUEST_TIMEOUT => ServiceError::BodyTimeout(text),
            s if s.is_client_error() => ServiceError::BadRequest(text),
            _ => ServiceError::Internal(text),
        }
    }
}

/// A response as the API answers errors: an error response that is not a problem document
/// (an extractor's plain-text rejection) becomes one, by its status. Other responses pass.
pub async fn as_problem(resp: Response) -> Response {
    let status = resp.status();
    let is_problem = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/problem+json"));
    if !(status.is_client_error() || status.is_server_error()) || is_problem {
        return resp;
    }
    let body = axum::body::to_bytes(resp.into_body(), 64 * 1024)
        .await
        .unwrap_or_default();
    ServiceError::from_status(status, &String::from_utf8_lossy(&body)).into_response()
}

/// The server's directories (data, tables, spectral data) that client-facing text must not
/// show, longest first.
static SERVER_DIRS: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Registers a directory of the server whose absolute path client-facing text must not show
/// (both as given and canonical).
pub fn hide_server_dir(dir: &Path) {
    let mut dirs = SERVER_DIRS.lock().unwrap_or_else(|p| p.into_inner());
    let canonical = std::fs::canonicalize(dir).ok();
    for d in [Some(dir.to_path_buf()), canonical].into_iter().flatten() {
        let abs = if d.is_absolute() {
            d
        } else {
            match std::env::current_dir() {
                Ok(cwd) => cwd.join(d),
                Err(_) => continue,
            }
        };
        for text in [abs.display().to_string(), d_display(&abs)] {
            let text = text.trim_end_matches('/').to_string();
            if text.len() > 1 && !dirs.contains(&text) {
                dirs.push(text);
            }
        }
    }
    dirs.sort_by_key(|d| std::cmp::Reverse(d.len()));
}

fn d_display(p: &Path) -> String {
    p.components()
        .collect::<std::path::PathBuf>()
        .display()
        .to_string()
}

/// `text` without the server's directories: a path inside one is shown relative to it, the
/// directory itself as "the server's data directory". Client-facing details and job errors
/// go through it; the log keeps the paths.
pub fn without_server_paths(text: &str) -> String {
    let dirs = SERVER_DIRS.lock().unwrap_or_else(|p| p.into_inner());
    let mut out = text.to_string();
    for d in dirs.iter() {
        out = hide_dir(&out, d);
    }
    out
}

/// `text` with the directory `dir` hidden where it stands as a whole path component.
fn hide_dir(text: &str, dir: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find(dir) {
        let after = &rest[i + dir.len()..];
        out.push_str(&rest[..i]);
        match after.chars().next() {
            Some('/') => rest = &after[1..],
            Some(c) if c.is_alphanumeric() || "-_.~".contains(c) => {
                out.push_str(dir);
                rest = after;
            }
            _ => {
                out.push_str("the server's data directory");
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

impl IntoResponse for ServiceError {
    fn into_response(self) -> Response {
        let status = self.status();
        let problem = self.problem();
        if status == StatusCode::INTERNAL_SERVER_ERROR {
            tracing::error!(code = self.code(), "{self}");
        } else if status.is_server_error() {
            tracing::debug!(code = self.code(), "{self}");
        } else if problem["detail"].as_str() != Some(self.to_string().as_str()) {
            // the client's detail hides the server's paths: the log keeps them
            tracing::info!(code = self.code(), "{self}");
        }
        let body = serde_json::to_vec(&problem).unwrap_or_default();
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
        if let ServiceError::NotAcceptable(_) = &self {
            // the answer depends on Accept, as a 200's would
            resp.headers_mut()
                .insert(header::VARY, HeaderValue::from_static("Accept"));
        }
        resp
    }
}

/// The one mapping of the store's errors to HTTP: a row not found is 404, a taken idempotency
/// key 409, a value none of a column's values (given by a request) 400; the database failing,
/// a stored row the service cannot read, or its URL 500.
impl From<StoreError> for ServiceError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::NotFound { .. } => ServiceError::NotFound(e.to_string()),
            StoreError::KeyConflict { .. } => ServiceError::Conflict(e.to_string()),
            StoreError::UnknownValue { .. } => ServiceError::BadRequest(e.to_string()),
            StoreError::CorruptRow { .. } => ServiceError::Database(e.to_string()),
            StoreError::Url(m) => ServiceError::Config(m),
            StoreError::Connect { url, source } => {
                ServiceError::Database(format!("cannot connect to {url}: {source}"))
            }
            StoreError::Migration(e) => ServiceError::Database(format!("migration failed: {e}")),
            StoreError::Database(e) => ServiceError::Database(e.to_string()),
        }
    }
}

impl From<crate::io::IoError> for ServiceError {
    fn from(e: crate::io::IoError) -> Self {
        if e.is_input() {
            ServiceError::InvalidImage(e.to_string())
        } else {
            ServiceError::Internal(e.to_string())
        }
    }
}

impl From<crate::pipeline::PipelineError> for ServiceError {
    /// A render request's error, by kind: what the query or the body got wrong is a 4xx
    /// (`bad_request`, `invalid_image`, `cfa_mismatch`, `unprocessable` for a light the frame
    /// does not give), an abandoned render a timeout, the table's or the server's faults a
    /// 500 `internal`.
    fn from(e: crate::pipeline::PipelineError) -> Self {
        use crate::pipeline::{CfaOrigin, PipelineError::*, error::show};
        match e {
            Options(m) => ServiceError::BadRequest(m),
            WholeFrameOnly => ServiceError::BadRequest(e.to_string()),
            CfaMismatch {
                origin,
                input,
                table,
            } => ServiceError::CfaMismatch {
                source_desc: match origin {
                    CfaOrigin::Declared => "the query's",
                    CfaOrigin::Dng => "the DNG's",
                    CfaOrigin::Sidecar => "the sidecar's",
                    CfaOrigin::Sensor => "the sensor's",
                },
                input,
                table,
            },
            CfaShiftTooSmall { .. } => ServiceError::InvalidImage(e.to_string()),
            Levels { black, white } => ServiceError::InvalidImage(format!(
                "white_level {white} must exceed black_level {black}"
            )),
            GivenLevels { black, white } => ServiceError::BadRequest(format!(
                "white_level {white} must exceed black_level {black} (0 and 65535 when not given)"
            )),
            SizeMismatch {
                image: (w, h),
                declared: (dw, dh),
            } => ServiceError::InvalidImage(format!(
                "the image is {w}×{h} but the query says {}×{}",
                show(dw),
                show(dh)
            )),
            Decode(e) | Encode(e) => e.into(),
            FrameLight(e) => ServiceError::from_l3(e, |m| {
                ServiceError::Unprocessable(format!(
                    "the illuminant cannot be taken from the DNG's AsShotNeutral ({m}); name one with illuminant="
                ))
            }),
            Correction(e) => ServiceError::Internal(e.to_string()),
            Kernels(e) => ServiceError::Internal(e.to_string()),
            Render(e) => ServiceError::from_l3(e, ServiceError::InvalidImage),
            UntrainedCamera { ref sensors, .. } => {
                let sensor = sensors.first().map_or("", String::as_str);
                ServiceError::UntrainedCamera(format!(
                    "{e}; train one with POST /v1/training-jobs {{\"sensor\":\"{sensor}\"}} (GET /v1/sensors/{sensor} describes it), or name a table with ?table=ID"
                ))
            }
        }
    }
}

impl ServiceError {
    /// An L3 core error, by variant: what the request got wrong becomes `input(message)`
    /// (the caller picks the 4xx that fits where the input came from: a body, a query, a
    /// table the request named), a render abandoned by its request a timeout, and the rest
    /// (the table, the server) a 500 `internal`.
    pub fn from_l3(e: impl CoreFault, input: impl FnOnce(String) -> ServiceError) -> ServiceError {
        // nobody waits for the answer of a canceled render any more
        if e.is_abandoned() {
            return ServiceError::Timeout("the render was abandoned by its request".into());
        }
        let is_input = e.is_input();
        by_fault(e, is_input, input)
    }

    /// An evaluation error, by variant (see [`ServiceError::from_l3`]).
    pub fn from_eval(
        e: crate::eval::EvalError,
        input: impl FnOnce(String) -> ServiceError,
    ) -> ServiceError {
        use crate::eval::EvalError::*;
        use crate::scene::SceneError;
        let is_input = match &e {
            Invalid(_) | Scene(SceneError::Invalid(_)) => true,
            Spectral(s) | Scene(SceneError::Spectral(s)) => spectral_input_fault(s),
            Colour(c) => colour_input_fault(c),
            // the camera-aware correction of a table that cannot be fitted: the table's fault
            Scene(SceneError::Image { .. }) | Learn(_) => false,
            // the evaluation's own edge, not the request's
            Sfr(_) | NoSignal(_) => false,
            Table(e) => e.is_input(),
            Correct(e) => e.is_input(),
            Render(e) => e.is_input(),
            Baseline(e) => e.is_input(),
            Params(e) => e.is_input(),
            Classify(e) => e.is_input(),
        };
        match e {
            Table(e) => ServiceError::from_l3(e, input),
            Correct(e) => ServiceError::from_l3(e, input),
            Render(e) => ServiceError::from_l3(e, input),
            Baseline(e) => ServiceError::from_l3(e, input),
            Params(e) => ServiceError::from_l3(e, input),
            Classify(e) => ServiceError::from_l3(e, input),
            e => by_fault(e, is_input, input),
        }
    }

    /// A camera error (building the camera of a table's or a request's sensor), by variant.
    pub fn from_camera(
        e: crate::camera::CameraError,
        input: impl FnOnce(String) -> ServiceError,
    ) -> ServiceError {
        use crate::camera::CameraError::*;
        let is_input = match &e {
            Spectral(s) => spectral_input_fault(s),
            InvalidDesign(_)
            | Json(_)
            | InvalidCfa(_)
            | InvalidArgument(_)
            | GridMismatch { .. } => true,
            Toml { .. } | Io { .. } => false,
        };
        by_fault(e, is_input, input)
    }
}

/// An L3 core error sorted by whose fault it is, for [`ServiceError::from_l3`]: the
/// request's (its input, its parameters, a light it named), or the table's or the server's.
pub trait CoreFault: std::fmt::Display {
    /// Whether the request got it wrong.
    fn is_input(&self) -> bool;
    /// Whether the request abandoned the work (a canceled render).
    fn is_abandoned(&self) -> bool {
        false
    }
}

impl CoreFault for crate::l3::classify::ClassifyError {
    fn is_input(&self) -> bool {
        // invalid parameters or an invalid input (a light's neutral)
        true
    }
}

impl CoreFault for crate::l3::params::ParamsError {
    fn is_input(&self) -> bool {
        true
    }
}

impl CoreFault for crate::l3::table::TableError {
    fn is_input(&self) -> bool {
        use crate::l3::table::TableError::*;
        match self {
            NoSensor => true,
            Classify(e) => e.is_input(),
            BadFile { .. } | Unusable(_) | Write(_) => false,
        }
    }
}

impl CoreFault for crate::l3::correct::CorrectError {
    fn is_input(&self) -> bool {
        use crate::l3::correct::CorrectError::*;
        match self {
            InvalidParams(_) | InvalidInput(_) | Neutral(_) => true,
            Table(e) => e.is_input(),
            Spectral(s) => spectral_input_fault(s),
            Samples(_) | Fit(_) | Camera(_) => false,
        }
    }
}

impl CoreFault for crate::l3::render::RenderError {
    fn is_input(&self) -> bool {
        use crate::l3::render::RenderError::*;
        match self {
            InvalidInput(_) => true,
            Prepare(e) => e.is_input(),
            Table(_) | RenderCanceled | KernelMismatch { .. } | OutputBuffer { .. } => false,
        }
    }

    fn is_abandoned(&self) -> bool {
        matches!(self, crate::l3::render::RenderError::RenderCanceled)
    }
}

impl CoreFault for crate::baseline::BaselineError {
    fn is_input(&self) -> bool {
        use crate::baseline::BaselineError::*;
        match self {
            InvalidParams(_) | InvalidInput(_) => true,
            Singular(_) => false,
        }
    }
}

/// `input(message)` for the request's faults, a 500 `internal` for the server's.
fn by_fault(
    e: impl std::fmt::Display,
    is_input: bool,
    input: impl FnOnce(String) -> ServiceError,
) -> ServiceError {
    if is_input {
        input(e.to_string())
    } else {
        ServiceError::Internal(e.to_string())
    }
}

/// Whether a spectral error is about data a request named or gave (an unknown light, bad
/// samples) rather than the server's own data files.
fn spectral_input_fault(e: &crate::spectral::SpectralError) -> bool {
    use crate::spectral::SpectralError::*;
    match e {
        InvalidGrid(_)
        | LengthMismatch { .. }
        | InvalidSamples(_)
        | GridMismatch(..)
        | UnknownIlluminant(..)
        | InvalidIlluminantSpec(..)
        | NoSuchTable { .. } => true,
        Io { .. } | Csv { .. } | NoSuchColumn { .. } | IsetDataMissing(_) => false,
    }
}

/// Whether a colour error comes from what a request gave (a light, a temperature).
fn colour_input_fault(e: &crate::colour::ColourError) -> bool {
    use crate::colour::ColourError::*;
    match e {
        Spectral(s) => spectral_input_fault(s),
        ZeroLuminance(_) | CctOutOfRange { .. } | TemperatureOutOfRange(..) => true,
        NonFinite(_) => false,
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

    #[test]
    fn server_paths_are_hidden() {
        let d = "/srv/l3/data";
        assert_eq!(
            hide_dir(
                "table file /srv/l3/data/tables/tbl_1.safetensors is corrupt",
                d
            ),
            "table file tables/tbl_1.safetensors is corrupt"
        );
        assert_eq!(
            hide_dir("cannot create /srv/l3/data: denied", d),
            "cannot create the server's data directory: denied"
        );
        assert_eq!(hide_dir("/srv/l3/database", d), "/srv/l3/database");
    }

    /// Render errors map by their kind: the input's faults to 4xx, the table's or the
    /// server's to 500 `internal` (not every render error is `invalid_image`).
    #[test]
    fn render_errors_map_by_kind() {
        use crate::l3::render::RenderError;
        use crate::l3::table::TableError;
        use crate::pipeline::PipelineError;
        let code = |e: RenderError| ServiceError::from(PipelineError::Render(e));
        let e = code(RenderError::InvalidInput(
            "input value at row 0 is not finite".into(),
        ));
        assert_eq!((e.status().as_u16(), e.code()), (400, "invalid_image"));
        for internal in [
            RenderError::KernelMismatch {
                got: 1,
                expected: 2,
            },
            RenderError::OutputBuffer {
                got: 1,
                need: 3,
                width: 1,
                height: 1,
            },
            RenderError::Table("a kernel weight is not finite".into()),
        ] {
            let e = code(internal);
            assert_eq!((e.status().as_u16(), e.code()), (500, "internal"), "{e}");
        }
        let e = code(RenderError::RenderCanceled);
        assert_eq!(e.code(), "request_timeout");
        let e = ServiceError::from(PipelineError::Options("preview 17".into()));
        assert_eq!(e.code(), "bad_request");
        // levels the query gives are the query's fault; the file's, the image's
        let (black, white) = (9, 9);
        let e = ServiceError::from(PipelineError::GivenLevels { black, white });
        assert_eq!(e.code(), "bad_request");
        let e = ServiceError::from(PipelineError::Levels { black, white });
        assert_eq!(e.code(), "invalid_image");
        // the caller chooses the 4xx of an input fault
        let e = ServiceError::from_l3(TableError::NoSensor, ServiceError::Unprocessable);
        assert_eq!((e.status().as_u16(), e.code()), (422, "unprocessable"));
        let e = ServiceError::from_l3(
            TableError::Unusable("metadata".into()),
            ServiceError::Unprocessable,
        );
        assert_eq!(e.code(), "internal");
    }

    /// The store's errors map to HTTP here, once, with the store's message.
    #[test]
    fn store_errors_map_by_kind() {
        use crate::service::store::{RowKind, StoreError};
        let cases = [
            (
                StoreError::NotFound {
                    kind: RowKind::Table,
                    id: "t".into(),
                },
                404,
                "not_found",
                "no table with id 't'".to_string(),
            ),
            (
                StoreError::KeyConflict { key: "k".into() },
                409,
                "conflict",
                "Idempotency-Key 'k' was already used with a different request body".into(),
            ),
            (
                StoreError::UnknownValue {
                    column: "status",
                    value: "x".into(),
                    expected: "queued, running".into(),
                },
                400,
                "bad_request",
                "status 'x': one of queued, running".into(),
            ),
            (
                StoreError::CorruptRow {
                    table: "training_jobs",
                    id: "j".into(),
                    column: "stage",
                    value: "x".into(),
                    expected: "queued".into(),
                },
                500,
                "database",
                "database: training_jobs row 'j': stage 'x' is none of queued".into(),
            ),
            (
                StoreError::Url("database_url 'x': expected sqlite://… or postgres://…".into()),
                500,
                "config",
                "configuration: database_url 'x': expected sqlite://… or postgres://…".into(),
            ),
            (
                StoreError::Database(sqlx::Error::PoolTimedOut),
                500,
                "database",
                format!("database: {}", sqlx::Error::PoolTimedOut),
            ),
        ];
        for (e, status, code, message) in cases {
            let e = ServiceError::from(e);
            assert_eq!(
                (e.status().as_u16(), e.code(), e.to_string()),
                (status, code, message)
            );
        }
    }
}
