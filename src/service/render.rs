//! `POST /v1/render`: a raw mosaic in, an sRGB PNG or JPEG, a PPM, a TIFF or f32 XYZ out (by
//! `Accept`).
//! The handler parses the request into the core's render request ([`crate::pipeline`]), which
//! decodes, renders and encodes on rayon; the answer carries timings and class statistics in
//! headers. The result equals `l3 render` on the same input bit for bit.
//!
//! The illuminant comes from the query; without one, from a DNG's AsShotNeutral (matched to
//! a colour temperature through the table's sensor), else estimated from the frame's
//! brightest unclipped CFA tiles (matched the same way), else (a frame with too little
//! unclipped signal) D65. `x-l3-illuminant-source` says which: `query`, `metadata`,
//! `estimated` or `default`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use axum::Extension;
use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, QueryRejection};
use axum::extract::{Query, Request, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use tokio::sync::OwnedSemaphorePermit;

use super::ServiceError;
use super::accept::negotiate;
use super::config::ServerConfig;
use super::state::{ActiveTable, AppState};
use super::table_choice::table_for;
use crate::io::{JpegOptions, Limits};
use crate::l3::L3Table;
use crate::l3::correct::IlluminantEntry;
use crate::l3::render::WhiteLevel;
use crate::pipeline::{
    CorrectionMode, Encoded, Input, KernelChoice, Levels, LightChoice, LightOrigin, OutputFormat,
    PipelineError, RenderContext, RenderOptions, RenderOutcome, RenderPipeline, RenderRequest,
    Renderer, TableChoice, check_preview, parse_region,
};
use crate::spectral::IsetData;

/// Query parameters of a render.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderQuery {
    /// Frame size (required for `application/octet-stream` bodies).
    pub width: Option<usize>,
    pub height: Option<usize>,
    /// CFA of the input, e.g. `RG/WB`; must match the table's when given.
    pub cfa: Option<String>,
    /// DN levels of integer input (default: the file's own, else 0 and the container's largest value).
    pub black_level: Option<u16>,
    pub white_level: Option<u16>,
    /// Acquisition illuminant (default: from a DNG's AsShotNeutral, else D65).
    pub illuminant: Option<String>,
    /// Output white: `auto` (default) or the Y that maps to white.
    pub white: Option<String>,
    /// TIFF output: `xyz` (float, default) or `srgb16`.
    pub tiff: Option<String>,
    /// Crop of the output: `x,y,width,height`.
    pub region: Option<String>,
    /// Integer preview downscale (box average), 1–16.
    pub preview: Option<usize>,
    /// PNG compression (`fast`, `default`, `best`; default: the config's).
    pub png_compression: Option<String>,
    /// JPEG quality, 1–100 (default 90).
    pub quality: Option<String>,
    /// JPEG chroma subsampling: `420` (default), `422` or `444`.
    pub subsampling: Option<String>,
    /// The chroma stage at low light: `auto` (default), `on` or `off`.
    pub chroma_denoise: Option<String>,
    /// `camera` or `colorimetric` (default: the config's `correction`).
    pub correction: Option<String>,
    /// A stored table to render with instead of the active one (or the DNG camera's).
    pub table: Option<String>,
}

/// The request body, or a problem saying why it could not be read.
pub fn body_bytes(body: Result<Bytes, BytesRejection>, max: usize) -> Result<Bytes, ServiceError> {
    body.map_err(|e| {
        if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
            ServiceError::PayloadTooLarge(format!(
                "the request body is larger than the limit of {max} bytes"
            ))
        } else {
            ServiceError::BadRequest(format!("cannot read the request body: {}", e.body_text()))
        }
    })
}

fn content_type(headers: &HeaderMap) -> Option<String> {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .map(|v| {
            v.split(';')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_lowercase()
        })
}

/// Requires `Content-Type: application/json`.
pub fn require_json(headers: &HeaderMap) -> Result<(), ServiceError> {
    match content_type(headers).as_deref() {
        Some("application/json") => Ok(()),
        Some(other) => Err(ServiceError::UnsupportedMediaType(format!(
            "Content-Type is '{other}'; application/json is expected"
        ))),
        None => Err(ServiceError::UnsupportedMediaType(
            "Content-Type is missing; application/json is expected".into(),
        )),
    }
}

const IMAGE_TYPES: [&str; 8] = [
    "image/png",
    "image/tiff",
    "image/x-adobe-dng",
    "image/dng",
    "image/x-portable-graymap",
    "image/x-portable-anymap",
    "image/pgm",
    "image/x-pgm",
];

/// Sets its flag when dropped unless disarmed: a render whose request is dropped (timed
/// out, or its client gone) tells its CPU work to stop, and is counted once in
/// `l3_renders_canceled_total`, whether it was running or still waiting for its turn.
struct CancelOnDrop {
    flag: Arc<AtomicBool>,
    done: bool,
    canceled: prometheus::IntCounter,
}

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        if !self.done {
            self.flag.store(true, Ordering::Relaxed);
            self.canceled.inc();
        }
    }
}

fn into_body(e: Encoded) -> axum::body::Body {
    match e {
        Encoded::Whole(b) => axum::body::Body::from(b),
        // the pixels are sent from the render's buffer, which returns to the pool once sent
        Encoded::Framed { header, frame } => {
            let parts = [bytes::Bytes::from(header), bytes::Bytes::from_owner(frame)];
            axum::body::Body::from_stream(futures_util::stream::iter(
                parts.map(Ok::<_, std::convert::Infallible>),
            ))
        }
    }
}

/// What [`admit`] hands the handler: the body, read in full, the render slot the request
/// waited for, and how long it waited.
#[derive(Clone)]
pub struct Admitted {
    body: Bytes,
    slot: Arc<Mutex<Option<OwnedSemaphorePermit>>>,
    queue_ms: f64,
}

/// Admission of renders (see [`super::admission`]): reserve the body's memory, read the
/// body, then wait in the FIFO queue for a render slot. A refusal before or while the body
/// is read closes the connection (the rest of the body is never read).
pub async fn admit(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let adm = &state.admission;
    let counters = &state.metrics.admission;
    let (mut parts, body) = req.into_parts();
    let limit = state.config.server.max_body_bytes;
    // a declared size past the limits is refused before the body is read
    if let Err(e) = declared_size_limits(parts.uri.query(), &state.config.server) {
        return closing(e);
    }
    let (body, reservation) = match adm.take_body(body, &parts.headers, limit, counters).await {
        Ok(b) => b,
        Err(e) => return closing(e),
    };
    let queued = Instant::now();
    let slot = match adm.render_slot(counters).await {
        Ok(p) => p,
        Err(e) => return e.into_response(),
    };
    parts.extensions.insert(Admitted {
        body,
        slot: Arc::new(Mutex::new(Some(slot))),
        queue_ms: queued.elapsed().as_secs_f64() * 1e3,
    });
    let resp = next
        .run(Request::from_parts(parts, axum::body::Body::empty()))
        .await;
    drop(reservation);
    resp
}

/// The most a body other than a mosaic may hold: a training job's design with every curve
/// inlined (at most 4096 samples each) or an illuminant's samples take well under a megabyte.
pub const MAX_JSON_BODY_BYTES: usize = 8 << 20;

/// Admission of the other bodies (training jobs, illuminants, evaluations): the body budget,
/// deadline and rate of a render's body ([`super::admission`], steps 1 and 2), within
/// `max_body_bytes` for a mosaic (a ColorChecker capture) and [`MAX_JSON_BODY_BYTES`] for
/// anything else. No render slot is taken; the reservation is held until the answer.
pub async fn admit_body(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let (parts, body) = req.into_parts();
    let limit = if is_mosaic(&parts.headers) {
        state.config.server.max_body_bytes
    } else {
        MAX_JSON_BODY_BYTES
    };
    let counters = &state.metrics.admission;
    let taken = state
        .admission
        .take_body(body, &parts.headers, limit, counters);
    let (body, reservation) = match taken.await {
        Ok(b) => b,
        Err(e) => return closing(e),
    };
    let resp = next
        .run(Request::from_parts(parts, axum::body::Body::from(body)))
        .await;
    drop(reservation);
    resp
}

/// The error's answer, closing the connection: the rest of a refused body is never read.
fn closing(e: ServiceError) -> Response {
    let mut resp = e.into_response();
    resp.headers_mut()
        .insert(header::CONNECTION, HeaderValue::from_static("close"));
    resp
}

/// Checks the query's `width` and `height`, when both are whole numbers, against the pixel
/// limits (the decode checks them again, with everything else about the query).
fn declared_size_limits(query: Option<&str>, server: &ServerConfig) -> Result<(), ServiceError> {
    let value = |key: &str| {
        query?
            .split('&')
            .filter_map(|kv| kv.split_once('='))
            .find(|(k, _)| *k == key)
            .and_then(|(_, v)| v.parse::<usize>().ok())
    };
    if let (Some(width), Some(height)) = (value("width"), value("height")) {
        let limits = Limits {
            max_pixels: server.max_pixels,
            ..Limits::default()
        };
        limits.check(width, height)?;
    }
    Ok(())
}

/// A render against the chosen table (the active one unless the request or its DNG's camera
/// chose another: [`super::table_choice`]): lights from the service's registry (no files
/// over HTTP), prepared renderers from its cache while the table is held.
#[derive(Clone)]
pub(super) struct ServiceRender {
    pub(super) state: AppState,
    pub(super) active: Arc<ActiveTable>,
    pub(super) keep_renderers: bool,
}

impl RenderContext for ServiceRender {
    type Error = ServiceError;

    fn table(&self) -> &L3Table {
        &self.active.table
    }

    fn iset(&self) -> Option<&IsetData> {
        self.state.iset.as_ref()
    }

    fn light(&self, spec: &str) -> Result<IlluminantEntry, ServiceError> {
        self.state.resolve_illuminant(spec)
    }

    fn renderer(&self, choice: &KernelChoice<'_>) -> Result<Arc<RenderPipeline>, ServiceError> {
        self.state
            .renderer_for(&self.active, choice, self.keep_renderers)
    }
}

/// Whether the request's Content-Type is one of a mosaic (raw or an image file).
pub(super) fn is_mosaic(headers: &HeaderMap) -> bool {
    content_type(headers)
        .is_some_and(|t| t == "application/octet-stream" || IMAGE_TYPES.contains(&t.as_str()))
}

/// Whether a body of the request's Content-Type is a raw mosaic (else an image file).
fn is_raw(headers: &HeaderMap) -> Result<bool, ServiceError> {
    let ctype = content_type(headers).ok_or_else(|| {
        ServiceError::UnsupportedMediaType(
            "Content-Type is missing; send application/octet-stream (raw little-endian u16 with width and height) or image/png, image/tiff, image/x-adobe-dng, image/x-portable-graymap".into(),
        )
    })?;
    match ctype.as_str() {
        "application/octet-stream" => Ok(true),
        t if IMAGE_TYPES.contains(&t) => Ok(false),
        other => Err(ServiceError::UnsupportedMediaType(format!(
            "Content-Type '{other}' is not a mosaic; send application/octet-stream (raw little-endian u16) or image/png, image/tiff, image/x-adobe-dng, image/x-portable-graymap"
        ))),
    }
}

/// The output the query asks for, checked in this order: `white`, `tiff` (over the
/// negotiated `format`), `region`, `preview`, `png_compression`, `quality`, `subsampling`
/// (each checked whatever the format).
fn output_of(
    q: &RenderQuery,
    format: OutputFormat,
    server: &ServerConfig,
) -> Result<(OutputFormat, RenderOptions), ServiceError> {
    let white: WhiteLevel = match &q.white {
        None => WhiteLevel::Auto,
        Some(s) => s
            .parse()
            .map_err(|e: crate::l3::render::RenderError| ServiceError::BadRequest(e.to_string()))?,
    };
    let format = match q.tiff.as_deref() {
        None => format,
        Some(t) => format.with_tiff(
            t.parse()
                .map_err(|e| ServiceError::BadRequest(format!("tiff {e}")))?,
        ),
    };
    let options = RenderOptions {
        white,
        region: q.region.as_deref().map(parse_region).transpose()?,
        preview: check_preview(q.preview.unwrap_or(1))?,
        png: parse_query(q.png_compression.as_deref())?.unwrap_or(server.png_compression),
        jpeg: JpegOptions {
            quality: parse_query(q.quality.as_deref())?.unwrap_or_default(),
            subsampling: parse_query(q.subsampling.as_deref())?.unwrap_or_default(),
        },
        chroma: parse_query(q.chroma_denoise.as_deref())?.unwrap_or_default(),
    };
    Ok((format, options))
}

/// A query parameter parsed by its type's `FromStr`; a bad value is 400 with the parser's words.
fn parse_query<T>(v: Option<&str>) -> Result<Option<T>, ServiceError>
where
    T: std::str::FromStr,
    T::Err: std::fmt::Display,
{
    v.map(str::parse)
        .transpose()
        .map_err(|e: T::Err| ServiceError::BadRequest(e.to_string()))
}

/// The render a request asks for, its parts checked in this order: the Content-Type, a
/// body, the output ([`output_of`]), `correction`, the size of a raw body. `format` is the
/// negotiated one.
pub(super) fn render_request(
    q: RenderQuery,
    headers: &HeaderMap,
    body: Bytes,
    format: OutputFormat,
    server: &ServerConfig,
) -> Result<RenderRequest, ServiceError> {
    let raw = is_raw(headers)?;
    if body.is_empty() {
        return Err(ServiceError::InvalidImage(
            "the request body is empty".into(),
        ));
    }
    let (format, options) = output_of(&q, format, server)?;
    let correction = match q.correction.as_deref() {
        None => server.correction,
        Some(s) => s.parse::<CorrectionMode>()?,
    };
    if let Some(cfa) = &q.cfa {
        // a malformed CFA is the query's mistake, not a mismatch with the table
        crate::camera::Cfa::parse(cfa.trim())
            .map_err(|e| ServiceError::BadRequest(format!("cfa '{cfa}': {e}")))?;
    }
    let input = match (raw, q.width, q.height) {
        (true, Some(width), Some(height)) => Input::RawU16 {
            bytes: body,
            width,
            height,
        },
        (true, ..) => {
            return Err(ServiceError::BadRequest(
                "a raw application/octet-stream body needs the width and height query parameters"
                    .into(),
            ));
        }
        (false, width, height) => Input::Image {
            bytes: body,
            width,
            height,
        },
    };
    Ok(RenderRequest {
        input,
        levels: Levels {
            black: q.black_level,
            white: q.white_level,
        },
        cfa: q.cfa,
        light: q
            .illuminant
            .map_or(LightChoice::FromFrame, LightChoice::Named),
        correction,
        options,
        format,
        renderer: Renderer::Fast,
        limits: Limits {
            max_pixels: server.max_pixels,
            ..Limits::default()
        },
    })
}

/// `POST /v1/render`
pub async fn render(
    State(state): State<AppState>,
    Extension(admitted): Extension<Admitted>,
    headers: HeaderMap,
    query: Result<Query<RenderQuery>, QueryRejection>,
) -> Result<Response, ServiceError> {
    let Query(mut q) = query.map_err(|e| ServiceError::BadRequest(e.body_text()))?;
    let format = negotiate(headers.get(header::ACCEPT).and_then(|v| v.to_str().ok()))?;
    let named = q.table.take();
    let request = render_request(q, &headers, admitted.body, format, &state.config.server)?;
    let format = request.format;
    let chosen = table_for(&state, named.as_deref(), &request.input).await?;
    let table = (chosen.table.id.clone(), chosen.choice);
    let ctx = ServiceRender {
        state: state.clone(),
        active: chosen.table,
        keep_renderers: chosen.keep_renderers,
    };
    // the query's CFA and a named illuminant are checked before the body is decoded; a light
    // whose correction is not held yet is fitted on the render pool, not on this thread
    let prepared = match &request.light {
        LightChoice::Named(spec) if !state.holds_light(spec) => {
            let c = ctx.clone();
            super::cpu::run(&state.pools.render, "the render's light", move || {
                request.prepare(&c)
            })
            .await??
        }
        _ => request.prepare(&ctx)?,
    };
    let permit = admitted
        .slot
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .take()
        .ok_or_else(|| ServiceError::Internal("render slot missing".into()))?;
    // renders execute in arrival order, a few at a time (each one is parallel inside), so
    // latency under load grows evenly instead of in a long tail
    let cancel = Arc::new(AtomicBool::new(false));
    let mut cancel_on_drop = CancelOnDrop {
        flag: cancel.clone(),
        done: false,
        canceled: state.metrics.admission.renders_canceled.clone(),
    };
    let queued = Instant::now();
    let gate = state
        .cpu_gate
        .clone()
        .acquire_owned()
        .await
        .map_err(|_| ServiceError::Internal("the render gate is closed".into()))?;
    let queue_ms = admitted.queue_ms + queued.elapsed().as_secs_f64() * 1e3;
    #[cfg(feature = "fault-injection")]
    let inject_panic = super::fault_injection::render_panic_requested(&headers);
    let r = super::cpu::run(&state.pools.render, "the render", move || {
        let result = if cancel.load(Ordering::Relaxed) {
            // abandoned while it waited for a thread
            Err(PipelineError::Render(crate::l3::render::RenderError::RenderCanceled).into())
        } else {
            #[cfg(feature = "fault-injection")]
            if inject_panic {
                panic!("injected fault: {}", super::fault_injection::RENDER_PANIC);
            }
            prepared.run(&ctx, &cancel)
        };
        // free the slots before answering, so a client's next request finds them free
        drop(gate);
        drop(permit);
        result
    })
    .await;
    cancel_on_drop.done = true;
    let out = r??;
    state
        .metrics
        .rendered((out.input_width * out.input_height) as u64);
    Ok(respond(out, format, table, queue_ms))
}

/// The answer of a render: the output with its media type, and what the render reports in
/// `x-l3-*` headers and `Server-Timing`.
fn respond(
    out: RenderOutcome,
    format: OutputFormat,
    (table_id, choice): (String, TableChoice),
    queue_ms: f64,
) -> Response {
    let r = out.rendered;
    let length = r.output.len();
    let mut resp = into_body(r.output).into_response();
    let h = resp.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(format.media_type()),
    );
    h.insert(header::VARY, HeaderValue::from_static("Accept"));
    // (a PPM body is a stream of two parts: its length is still known)
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(length));
    let mut put = |name: &'static str, v: String| {
        if let Ok(v) = HeaderValue::from_str(&v) {
            h.insert(HeaderName::from_static(name), v);
        }
    };
    let source = match out.light_origin {
        LightOrigin::Named => "query",
        LightOrigin::Frame(source) => source.name(),
    };
    put("x-l3-table", table_id);
    put("x-l3-table-choice", choice.as_str().to_string());
    if let Some(sensor) = choice.sensor() {
        put("x-l3-sensor", sensor.to_string());
    }
    put("x-l3-illuminant", out.light);
    put("x-l3-illuminant-source", source.to_string());
    if !out.notes.skipped_opcodes.is_empty() {
        put(
            "x-l3-dng-skipped-opcodes",
            out.notes.skipped_opcodes.join(", "),
        );
    }
    if let Some(shift) = &out.notes.cfa_shift {
        put(
            "x-l3-dng-cfa-shift",
            format!(
                "rows={}; cols={}; from={}",
                shift.rows, shift.cols, shift.from
            ),
        );
    }
    // what was applied (a matrix-only light keeps its T whatever the request's mode; a
    // cross-illuminant table applies none)
    put(
        "x-l3-correction",
        out.correction
            .map_or("none", CorrectionMode::as_str)
            .to_string(),
    );
    put("x-l3-width", r.width.to_string());
    put("x-l3-height", r.height.to_string());
    let input_pixels = out.input_width * out.input_height;
    put("x-l3-input-pixels", input_pixels.to_string());
    put("x-l3-queue-ms", format!("{queue_ms:.3}"));
    put("x-l3-decode-ms", format!("{:.3}", out.decode_ms));
    put("x-l3-render-ms", format!("{:.3}", r.render_ms));
    put("x-l3-encode-ms", format!("{:.3}", r.encode_ms));
    put("x-l3-saturated-pixels", r.stats.saturated.to_string());
    put("x-l3-texture-pixels", r.stats.texture.to_string());
    put("x-l3-fallback-pixels", r.stats.fallback.to_string());
    put("x-l3-clamped-pixels", r.stats.clamped.to_string());
    put("x-l3-exact-path-pixels", r.stats.exact_path.to_string());
    put(
        "server-timing",
        format!(
            "queue;dur={queue_ms:.3}, decode;dur={:.3}, render;dur={:.3}, encode;dur={:.3}",
            out.decode_ms, r.render_ms, r.encode_ms
        ),
    );
    resp
}
