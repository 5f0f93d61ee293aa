//! `POST /v1/render`: a raw mosaic in, an sRGB PNG, a TIFF or f32 XYZ out (by `Accept`).
//! Decoding, rendering and encoding run on rayon; the answer carries timings and class
//! statistics in headers. The result equals `l3 render` on the same input bit for bit.
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
use super::state::AppState;
use crate::io::{
    DecodedMosaic, Limits, UnknownPngCompression, decode_mosaic_with_meta, decode_raw_u16_le,
};
use crate::l3::{FrameMetadata, Mosaic, WhiteLevel};
use crate::pipeline::{
    CorrectionMode, Encoded, OutputFormat as PipelineFormat, PipelineError, RenderOptions,
    check_preview, parse_region,
};

/// Query parameters of a render.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderQuery {
    /// Frame size (required for `application/octet-stream` bodies).
    pub width: Option<usize>,
    pub height: Option<usize>,
    /// CFA of the input, e.g. `RG/WB`; must match the table's when given.
    pub cfa: Option<String>,
    /// DN levels of integer input (default: a DNG's own, else 0 and 65535).
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
    /// `camera` or `colorimetric` (default: the config's `correction`).
    pub correction: Option<String>,
}

/// Output formats a client can ask for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    Png,
    /// Binary PPM: 8-bit sRGB, uncompressed (encoding is a header and a copy).
    Ppm,
    Tiff,
    F32,
}

impl OutputFormat {
    fn content_type(self) -> &'static str {
        match self {
            OutputFormat::Png => "image/png",
            OutputFormat::Ppm => "image/x-portable-pixmap",
            OutputFormat::Tiff => "image/tiff",
            OutputFormat::F32 => "application/octet-stream",
        }
    }
}

/// Chooses the output from an `Accept` header (q-values honoured; none or `*/*` → PNG).
pub fn negotiate(accept: Option<&str>) -> Result<OutputFormat, ServiceError> {
    let Some(accept) = accept.map(str::trim).filter(|a| !a.is_empty()) else {
        return Ok(OutputFormat::Png);
    };
    super::accept::preferred(accept, |media| match media {
        "image/png" | "image/*" | "*/*" => Some(OutputFormat::Png),
        "image/x-portable-pixmap" => Some(OutputFormat::Ppm),
        "image/tiff" => Some(OutputFormat::Tiff),
        "application/octet-stream" => Some(OutputFormat::F32),
        _ => None,
    })
    .ok_or_else(|| {
        ServiceError::NotAcceptable(format!(
            "Accept '{accept}' allows none of image/png, image/x-portable-pixmap, image/tiff, application/octet-stream"
        ))
    })
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

/// A decoded mosaic as the renderer takes it.
enum Input {
    Dn(Vec<u16>),
    Volts(Vec<f32>),
}

/// The answer of the CPU part of a render.
struct Rendered {
    illuminant: String,
    illuminant_source: &'static str,
    out: crate::pipeline::Rendered,
    in_width: usize,
    in_height: usize,
    decode_ms: f64,
}

/// Sets its flag when dropped unless disarmed: a render whose request is dropped (timed
/// out, or its client gone) tells its CPU work to stop.
struct CancelOnDrop(Arc<AtomicBool>, bool);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        if !self.1 {
            self.0.store(true, Ordering::Relaxed);
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
    let declared = super::admission::content_length(&parts.headers);
    let close = |e: ServiceError| {
        let mut resp = e.into_response();
        resp.headers_mut()
            .insert(header::CONNECTION, HeaderValue::from_static("close"));
        resp
    };
    let mut reservation = match adm.reserve(declared.unwrap_or(0), counters) {
        Ok(r) => r,
        Err(e) => return close(e),
    };
    let body = match adm
        .read_body(body, declared, &mut reservation, counters)
        .await
    {
        Ok(b) => b,
        Err(e) => return close(e),
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

/// `POST /v1/render`
pub async fn render(
    State(state): State<AppState>,
    Extension(admitted): Extension<Admitted>,
    headers: HeaderMap,
    query: Result<Query<RenderQuery>, QueryRejection>,
) -> Result<Response, ServiceError> {
    let Query(q) = query.map_err(|e| ServiceError::BadRequest(e.body_text()))?;
    let body = admitted.body;
    let format = negotiate(headers.get(header::ACCEPT).and_then(|v| v.to_str().ok()))?;
    let ctype = content_type(&headers).ok_or_else(|| {
        ServiceError::UnsupportedMediaType(
            "Content-Type is missing; send application/octet-stream (raw little-endian u16 with width and height) or image/png, image/tiff, image/x-adobe-dng, image/x-portable-graymap".into(),
        )
    })?;
    let raw = match ctype.as_str() {
        "application/octet-stream" => true,
        t if IMAGE_TYPES.contains(&t) => false,
        other => {
            return Err(ServiceError::UnsupportedMediaType(format!(
                "Content-Type '{other}' is not a mosaic; send application/octet-stream (raw little-endian u16) or image/png, image/tiff, image/x-adobe-dng, image/x-portable-graymap"
            )));
        }
    };
    if body.is_empty() {
        return Err(ServiceError::InvalidImage(
            "the request body is empty".into(),
        ));
    }
    let white: WhiteLevel = match &q.white {
        None => WhiteLevel::Auto,
        Some(s) => s
            .parse()
            .map_err(|e: crate::l3::L3Error| ServiceError::BadRequest(e.to_string()))?,
    };
    let pipeline_format = match (format, q.tiff.as_deref()) {
        (OutputFormat::Png, _) => PipelineFormat::Png,
        (OutputFormat::Ppm, _) => PipelineFormat::Ppm,
        (OutputFormat::F32, _) => PipelineFormat::F32,
        (OutputFormat::Tiff, None | Some("xyz")) => PipelineFormat::TiffXyz,
        (OutputFormat::Tiff, Some("srgb16")) => PipelineFormat::TiffSrgb16,
        (OutputFormat::Tiff, Some(other)) => {
            return Err(ServiceError::BadRequest(format!(
                "tiff '{other}': expected xyz or srgb16"
            )));
        }
    };
    if let Some(t) = q.tiff.as_deref()
        && !["xyz", "srgb16"].contains(&t)
    {
        return Err(ServiceError::BadRequest(format!(
            "tiff '{t}': expected xyz or srgb16"
        )));
    }
    let opts = RenderOptions {
        white,
        region: q.region.as_deref().map(parse_region).transpose()?,
        preview: check_preview(q.preview.unwrap_or(1))?,
        png: match q.png_compression.as_deref() {
            None => state.config.server.png_compression,
            Some(s) => s
                .parse()
                .map_err(|e: UnknownPngCompression| ServiceError::BadRequest(e.to_string()))?,
        },
    };
    let correction = match q.correction.as_deref() {
        None => state.config.server.correction,
        Some(s) => s.parse::<CorrectionMode>()?,
    };
    if raw && (q.width.is_none() || q.height.is_none()) {
        return Err(ServiceError::BadRequest(
            "a raw application/octet-stream body needs the width and height query parameters"
                .into(),
        ));
    }
    let active = state.active.load_full().ok_or_else(|| {
        ServiceError::NotReady(
            "no table is active yet (the default table may still be training; see /readyz)".into(),
        )
    })?;
    let table_cfa = active.table.meta.cfa.to_string();
    if let Some(cfa) = &q.cfa
        && !cfa.trim().eq_ignore_ascii_case(&table_cfa)
    {
        return Err(ServiceError::CfaMismatch {
            source_desc: "the query's",
            input: cfa.clone(),
            table: table_cfa,
        });
    }
    // a named illuminant is checked before the body is decoded
    let query_entry = q
        .illuminant
        .as_deref()
        .map(|s| state.resolve_illuminant(s))
        .transpose()?;
    let permit = admitted
        .slot
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .take()
        .ok_or_else(|| ServiceError::Internal("render slot missing".into()))?;
    // renders execute in arrival order, a few at a time (each one is parallel inside), so
    // latency under load grows evenly instead of in a long tail
    let queued = Instant::now();
    let gate = state
        .cpu_gate
        .clone()
        .acquire_owned()
        .await
        .map_err(|_| ServiceError::Internal("the render gate is closed".into()))?;
    let queue_ms = admitted.queue_ms + queued.elapsed().as_secs_f64() * 1e3;
    let limits = Limits {
        max_pixels: state.config.server.max_pixels,
        ..Limits::default()
    };
    let st = state.clone();
    let table_id = active.id.clone();
    let cancel = Arc::new(AtomicBool::new(false));
    let mut cancel_on_drop = CancelOnDrop(cancel.clone(), false);
    #[cfg(feature = "fault-injection")]
    let inject_panic = super::fault_injection::render_panic_requested(&headers);
    let r = super::cpu::run(&state.pools.render, "the render", move || {
        let run = || -> Result<Rendered, ServiceError> {
            if cancel.load(Ordering::Relaxed) {
                // abandoned while it waited for a thread
                return Err(PipelineError::Render(crate::l3::L3Error::RenderCanceled).into());
            }
            #[cfg(feature = "fault-injection")]
            if inject_panic {
                panic!("injected fault: {}", super::fault_injection::RENDER_PANIC);
            }
            let t0 = Instant::now();
            let mut black = q.black_level.unwrap_or(0);
            let mut white_dn = q.white_level.unwrap_or(65535);
            let bad_levels = |black: u16, white_dn: u16| {
                ServiceError::InvalidImage(format!(
                    "white_level {white_dn} must exceed black_level {black}"
                ))
            };
            if white_dn <= black {
                return Err(bad_levels(black, white_dn));
            }
            let mut neutral = None;
            // integer input stays u16: the renderer converts it tile by tile
            let (input, w, h) = if raw {
                let (w, h) = (q.width.unwrap_or(0), q.height.unwrap_or(0));
                let f = decode_raw_u16_le(&body, w, h, &limits)?;
                (Input::Dn(f.data), f.width, f.height)
            } else {
                let loaded = decode_mosaic_with_meta(&body, &limits)?;
                if let (Some(meta), Some(dng)) = (&loaded.meta, &loaded.dng) {
                    if !meta.cfa.eq_ignore_ascii_case(&table_cfa) {
                        return Err(ServiceError::CfaMismatch {
                            source_desc: "the DNG's",
                            input: meta.cfa.clone(),
                            table: table_cfa.clone(),
                        });
                    }
                    // the file's levels unless the query gives others
                    black = q.black_level.unwrap_or(meta.black_level);
                    white_dn = q.white_level.unwrap_or(meta.white_level);
                    neutral = dng.neutral();
                }
                let m = loaded.mosaic;
                let (mw, mh) = m.dims();
                if q.width.is_some_and(|w| w != mw) || q.height.is_some_and(|h| h != mh) {
                    return Err(ServiceError::InvalidImage(format!(
                        "the image is {mw}×{mh} but the query says {}×{}",
                        q.width.map_or("?".into(), |v| v.to_string()),
                        q.height.map_or("?".into(), |v| v.to_string())
                    )));
                }
                match m {
                    DecodedMosaic::U16(f) => (Input::Dn(f.data), f.width, f.height),
                    DecodedMosaic::F32 {
                        width,
                        height,
                        data,
                    } => (Input::Volts(data), width, height),
                }
            };
            if white_dn <= black {
                return Err(bad_levels(black, white_dn));
            }
            let mosaic = match &input {
                Input::Dn(d) => Mosaic::Dn {
                    data: d,
                    black,
                    white: white_dn,
                },
                Input::Volts(v) => Mosaic::Volts(v),
            };
            let (entry, source) = match query_entry {
                Some(e) => (e, "query"),
                None => {
                    let metadata = FrameMetadata {
                        illuminant: None,
                        neutral: neutral.as_deref(),
                    };
                    let (spec, source) = active
                        .table
                        .frame_illuminant(metadata, &mosaic, w, h, st.iset.as_ref())
                        .map_err(|e| {
                            ServiceError::from_l3(e, |m| {
                                ServiceError::Unprocessable(format!(
                                    "the illuminant cannot be taken from the DNG's AsShotNeutral ({m}); name one with illuminant="
                                ))
                            })
                        })?;
                    (st.resolve_illuminant(&spec)?, source.name())
                }
            };
            let decode_ms = t0.elapsed().as_secs_f64() * 1e3;
            let pipeline = st.renderer_for(&active, &entry, correction)?;
            let out = pipeline.render(mosaic, w, h, pipeline_format, &opts, &cancel)?;
            Ok(Rendered {
                illuminant: entry.name.clone(),
                illuminant_source: source,
                out,
                in_width: w,
                in_height: h,
                decode_ms,
            })
        };
        let result = run();
        if cancel.load(Ordering::Relaxed) {
            st.metrics
                .admission
                .renders_canceled
                .fetch_add(1, Ordering::Relaxed);
        }
        // free the slots before answering, so a client's next request finds them free
        drop(gate);
        drop(permit);
        result
    })
    .await;
    cancel_on_drop.1 = true;
    let r = r??;
    state.metrics.rendered((r.in_width * r.in_height) as u64);
    let length = r.out.output.len();
    let out = r.out;
    let mut resp = into_body(out.output).into_response();
    let h = resp.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(format.content_type()),
    );
    h.insert(header::VARY, HeaderValue::from_static("Accept"));
    // (a PPM body is a stream of two parts: its length is still known)
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(length));
    let mut put = |name: &'static str, v: String| {
        if let Ok(v) = HeaderValue::from_str(&v) {
            h.insert(HeaderName::from_static(name), v);
        }
    };
    put("x-l3-table", table_id);
    put("x-l3-illuminant", r.illuminant.clone());
    put("x-l3-illuminant-source", r.illuminant_source.to_string());
    put("x-l3-correction", correction.as_str().to_string());
    put("x-l3-width", out.width.to_string());
    put("x-l3-height", out.height.to_string());
    put("x-l3-input-pixels", (r.in_width * r.in_height).to_string());
    put("x-l3-queue-ms", format!("{queue_ms:.3}"));
    put("x-l3-decode-ms", format!("{:.3}", r.decode_ms));
    put("x-l3-render-ms", format!("{:.3}", out.render_ms));
    put("x-l3-encode-ms", format!("{:.3}", out.encode_ms));
    put("x-l3-saturated-pixels", out.stats.saturated.to_string());
    put("x-l3-texture-pixels", out.stats.texture.to_string());
    put("x-l3-fallback-pixels", out.stats.fallback.to_string());
    put("x-l3-clamped-pixels", out.stats.clamped.to_string());
    put("x-l3-exact-path-pixels", out.stats.exact_path.to_string());
    put(
        "server-timing",
        format!(
            "queue;dur={queue_ms:.3}, decode;dur={:.3}, render;dur={:.3}, encode;dur={:.3}",
            r.decode_ms, out.render_ms, out.encode_ms
        ),
    );
    Ok(resp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accept_negotiation() {
        assert_eq!(negotiate(None).unwrap(), OutputFormat::Png);
        assert_eq!(negotiate(Some("*/*")).unwrap(), OutputFormat::Png);
        assert_eq!(negotiate(Some("image/tiff")).unwrap(), OutputFormat::Tiff);
        assert_eq!(
            negotiate(Some("image/x-portable-pixmap, image/png;q=0.9")).unwrap(),
            OutputFormat::Ppm
        );
        assert_eq!(
            negotiate(Some("image/png;q=0.5, application/octet-stream")).unwrap(),
            OutputFormat::F32
        );
        assert_eq!(
            negotiate(Some("text/html, image/tiff;q=0.1")).unwrap(),
            OutputFormat::Tiff
        );
        assert_eq!(negotiate(Some("text/html")).unwrap_err().status(), 406);
    }
}
