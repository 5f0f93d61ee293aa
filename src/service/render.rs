//! `POST /v1/render`: a raw mosaic in, an sRGB PNG, a TIFF or f32 XYZ out (by `Accept`).
//! Decoding, rendering and encoding run on rayon; the answer carries timings and class
//! statistics in headers. The result equals `l3 render` on the same input bit for bit.
//!
//! The illuminant comes from the query; without one, from a DNG's AsShotNeutral (matched to
//! a colour temperature through the table's sensor), else estimated from the frame's
//! brightest unclipped CFA tiles (matched the same way), else (a frame with too little
//! unclipped signal) D65. `x-l3-illuminant-source` says which: `query`, `metadata`,
//! `estimated` or `default`.

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
    DecodedMosaic, Limits, PngCompression, decode_mosaic_with_meta, decode_raw_u16_le,
    encode_png_rgb8, encode_ppm_rgb8, encode_tiff_f32_rgb, encode_tiff_rgb16, ppm_header,
};
use crate::l3::{FrameMetadata, Mosaic, Region, WhiteLevel, xyz_to_srgb8, xyz_to_srgb16};

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

/// A crop `x,y,width,height`.
fn parse_region(s: &str, w: usize, h: usize) -> Result<(usize, usize, usize, usize), ServiceError> {
    let v: Vec<usize> = s
        .split(',')
        .map(|p| p.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            ServiceError::BadRequest(format!(
                "region '{s}': expected x,y,width,height (non-negative integers)"
            ))
        })?;
    let [x, y, rw, rh] = v[..] else {
        return Err(ServiceError::BadRequest(format!(
            "region '{s}': expected four numbers x,y,width,height"
        )));
    };
    if rw == 0 || rh == 0 || x.saturating_add(rw) > w || y.saturating_add(rh) > h {
        return Err(ServiceError::BadRequest(format!(
            "region {x},{y},{rw}×{rh} is empty or not inside the {w}×{h} frame"
        )));
    }
    Ok((x, y, rw, rh))
}

/// Box-average downscale by `k` (partial edge blocks dropped).
fn downscale(xyz: &[f32], w: usize, h: usize, k: usize) -> (Vec<f32>, usize, usize) {
    let (ow, oh) = (w / k, h / k);
    let mut out = vec![0f32; ow * oh * 3];
    let n = (k * k) as f64;
    for oy in 0..oh {
        for ox in 0..ow {
            let mut acc = [0f64; 3];
            for dy in 0..k {
                let row = (oy * k + dy) * w;
                for dx in 0..k {
                    let p = (row + ox * k + dx) * 3;
                    for c in 0..3 {
                        acc[c] += f64::from(xyz[p + c]);
                    }
                }
            }
            for c in 0..3 {
                out[(oy * ow + ox) * 3 + c] = (acc[c] / n) as f32;
            }
        }
    }
    (out, ow, oh)
}

/// A decoded mosaic as the renderer takes it.
enum Input {
    Dn(Vec<u16>),
    Volts(Vec<f32>),
}

/// What the renderer produced.
enum Rendered8 {
    Srgb(crate::l3::Frame),
    Xyz(Vec<f32>),
}

/// An encoded answer: one buffer, or a header followed by the rendered frame itself (PPM:
/// the pixels are sent from the render's buffer, which returns to the pool once sent).
enum Encoded {
    Whole(Vec<u8>),
    Framed {
        header: Vec<u8>,
        frame: crate::l3::Frame,
    },
}

impl Encoded {
    fn len(&self) -> usize {
        match self {
            Encoded::Whole(b) => b.len(),
            Encoded::Framed { header, frame } => header.len() + frame.len(),
        }
    }

    fn into_body(self) -> axum::body::Body {
        match self {
            Encoded::Whole(b) => axum::body::Body::from(b),
            Encoded::Framed { header, frame } => {
                let parts = [bytes::Bytes::from(header), bytes::Bytes::from_owner(frame)];
                axum::body::Body::from_stream(futures_util::stream::iter(
                    parts.map(Ok::<_, std::convert::Infallible>),
                ))
            }
        }
    }
}

struct Rendered {
    illuminant: String,
    illuminant_source: &'static str,
    bytes: Encoded,
    width: usize,
    height: usize,
    in_width: usize,
    in_height: usize,
    stats: crate::l3::RenderStats,
    decode_ms: f64,
    render_ms: f64,
    encode_ms: f64,
}

/// Encodes a rendered image as a whole buffer (every format but a PPM of an sRGB frame).
fn encode(
    format: OutputFormat,
    out: Rendered8,
    ow: usize,
    oh: usize,
    wy: f64,
    tiff_srgb16: bool,
) -> Result<Vec<u8>, ServiceError> {
    Ok(match (format, out) {
        (OutputFormat::Png, Rendered8::Srgb(rgb)) => {
            encode_png_rgb8(ow, oh, &rgb, PngCompression::Fast)?
        }
        (OutputFormat::Png, Rendered8::Xyz(xyz)) => {
            encode_png_rgb8(ow, oh, &xyz_to_srgb8(&xyz, wy), PngCompression::Fast)?
        }
        (OutputFormat::Ppm, Rendered8::Srgb(rgb)) => encode_ppm_rgb8(ow, oh, &rgb)?,
        (OutputFormat::Ppm, Rendered8::Xyz(xyz)) => {
            encode_ppm_rgb8(ow, oh, &xyz_to_srgb8(&xyz, wy))?
        }
        (OutputFormat::Tiff, Rendered8::Xyz(xyz)) if tiff_srgb16 => {
            encode_tiff_rgb16(ow, oh, &xyz_to_srgb16(&xyz, wy))?
        }
        (OutputFormat::Tiff, Rendered8::Xyz(xyz)) => encode_tiff_f32_rgb(ow, oh, &xyz)?,
        (OutputFormat::F32, Rendered8::Xyz(xyz)) => {
            let mut b = crate::buffers::with_capacity(xyz.len() * 4);
            b.extend(xyz.iter().flat_map(|v| v.to_le_bytes()));
            b
        }
        _ => {
            return Err(ServiceError::Internal(
                "render output does not match the format".into(),
            ));
        }
    })
}

/// A render slot taken by [`admit`] before the body is read.
#[derive(Clone)]
pub struct RenderSlot(Arc<Mutex<Option<OwnedSemaphorePermit>>>);

/// Admission of renders: takes a slot before the body is read, or answers 503 with
/// Retry-After at once (an overloaded service decodes no bodies; it discards what the client
/// already sends, so the client can read the 503 and keep its connection).
pub async fn admit(State(state): State<AppState>, mut req: Request, next: Next) -> Response {
    match state.render_slots.clone().try_acquire_owned() {
        Ok(p) => {
            req.extensions_mut()
                .insert(RenderSlot(Arc::new(Mutex::new(Some(p)))));
            next.run(req).await
        }
        Err(_) => {
            let keep_alive = discard_body(req, state.config.server.max_body_bytes).await;
            let mut resp = ServiceError::Overloaded {
                msg: format!(
                    "{} renders are already running; retry shortly",
                    state.config.server.render_concurrency
                ),
                retry_after_s: 1,
            }
            .into_response();
            if !keep_alive {
                resp.headers_mut()
                    .insert(header::CONNECTION, HeaderValue::from_static("close"));
            }
            resp
        }
    }
}

/// Largest body an overloaded render reads and throws away before its 503.
const DISCARD_LIMIT: usize = 64 << 20;

/// Reads and drops a refused request's body (up to [`DISCARD_LIMIT`], within 10 s) so that a
/// client still sending it sees the answer instead of a broken pipe. Without this, answering
/// before the body is read makes the server close the connection mid-upload. A client that
/// sent `Expect: 100-continue` has not sent the body yet: nothing is read. Returns whether
/// the connection can be kept.
async fn discard_body(req: Request, max_body_bytes: usize) -> bool {
    use axum::body::HttpBody;
    if req
        .headers()
        .get(header::EXPECT)
        .is_some_and(|v| v.as_bytes().eq_ignore_ascii_case(b"100-continue"))
    {
        return true;
    }
    let limit = DISCARD_LIMIT.min(max_body_bytes);
    let mut body = req.into_body();
    let drain = async {
        let mut seen = 0usize;
        loop {
            match std::future::poll_fn(|cx| std::pin::Pin::new(&mut body).poll_frame(cx)).await {
                None => return true,
                Some(Err(_)) => return false,
                Some(Ok(frame)) => {
                    seen += frame.data_ref().map_or(0, |d| d.len());
                    if seen > limit {
                        return false;
                    }
                }
            }
        }
    };
    tokio::time::timeout(std::time::Duration::from_secs(10), drain)
        .await
        .unwrap_or(false)
}

/// `POST /v1/render`
pub async fn render(
    State(state): State<AppState>,
    Extension(permit): Extension<RenderSlot>,
    headers: HeaderMap,
    query: Result<Query<RenderQuery>, QueryRejection>,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ServiceError> {
    let Query(q) = query.map_err(|e| ServiceError::BadRequest(e.body_text()))?;
    let body = body_bytes(body, state.config.server.max_body_bytes)?;
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
    let tiff_srgb16 = match q.tiff.as_deref() {
        None | Some("xyz") => false,
        Some("srgb16") => true,
        Some(other) => {
            return Err(ServiceError::BadRequest(format!(
                "tiff '{other}': expected xyz or srgb16"
            )));
        }
    };
    let preview = q.preview.unwrap_or(1);
    if !(1..=16).contains(&preview) {
        return Err(ServiceError::BadRequest(format!(
            "preview {preview}: an integer downscale factor from 1 to 16"
        )));
    }
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
    let permit = permit
        .0
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
    let queue_ms = queued.elapsed().as_secs_f64() * 1e3;
    let limits = Limits {
        max_pixels: state.config.server.max_pixels,
        ..Limits::default()
    };
    let st = state.clone();
    let table_id = active.id.clone();
    let r = super::cpu::run(&state.pools.render, "the render", move || {
        let run = || -> Result<Rendered, ServiceError> {
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
                            ServiceError::Unprocessable(format!(
                                "the illuminant cannot be taken from the DNG's AsShotNeutral ({e}); name one with illuminant="
                            ))
                        })?;
                    (st.resolve_illuminant(&spec)?, source.name())
                }
            };
            let region = q
                .region
                .as_deref()
                .map(|s| parse_region(s, w, h))
                .transpose()?
                .map(|(x, y, width, height)| Region {
                    x,
                    y,
                    width,
                    height,
                });
            let (ow, oh) = region.map_or((w, h), |r| (r.width, r.height));
            if preview > 1 && (ow / preview == 0 || oh / preview == 0) {
                return Err(ServiceError::BadRequest(format!(
                    "preview {preview} leaves nothing of a {ow}×{oh} image"
                )));
            }
            let t1 = Instant::now();
            let renderer = st.renderer_for(&active, &entry)?;
            let bad = |e: crate::l3::L3Error| ServiceError::InvalidImage(e.to_string());
            // only what the answer needs: 8-bit sRGB straight from the kernels for a PNG,
            // XYZ otherwise; only the region's pixels
            let srgb8 = matches!(format, OutputFormat::Png | OutputFormat::Ppm);
            let (out, stats, wy) = if srgb8 && preview == 1 {
                let (rgb, wy, stats) = renderer
                    .render_srgb8(mosaic, w, h, region, white)
                    .map_err(bad)?;
                (Rendered8::Srgb(rgb), stats, wy)
            } else {
                let (xyz, stats) = renderer.render_xyz(mosaic, w, h, region).map_err(bad)?;
                let wy = match format {
                    OutputFormat::F32 => 1.0,
                    OutputFormat::Tiff if !tiff_srgb16 => 1.0,
                    _ => renderer.white_y(mosaic, w, h, white).map_err(bad)?,
                };
                (Rendered8::Xyz(xyz), stats, wy)
            };
            let t2 = Instant::now();
            let (out, ow, oh) = match out {
                Rendered8::Xyz(xyz) if preview > 1 => {
                    let (d, dw, dh) = downscale(&xyz, ow, oh, preview);
                    (Rendered8::Xyz(d), dw, dh)
                }
                other => (other, ow, oh),
            };
            let bytes = match (format, out) {
                (OutputFormat::Ppm, Rendered8::Srgb(frame)) => Encoded::Framed {
                    header: ppm_header(ow, oh)?,
                    frame,
                },
                (format, out) => Encoded::Whole(encode(format, out, ow, oh, wy, tiff_srgb16)?),
            };
            let t3 = Instant::now();
            let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
            Ok(Rendered {
                illuminant: entry.name.clone(),
                illuminant_source: source,
                bytes,
                width: ow,
                height: oh,
                in_width: w,
                in_height: h,
                stats,
                decode_ms: ms(t0, t1),
                render_ms: ms(t1, t2),
                encode_ms: ms(t2, t3),
            })
        };
        let result = run();
        // free the slots before answering, so a client's next request finds them free
        drop(gate);
        drop(permit);
        result
    })
    .await??;
    state.metrics.rendered((r.in_width * r.in_height) as u64);
    let length = r.bytes.len();
    let mut resp = r.bytes.into_body().into_response();
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
    put("x-l3-width", r.width.to_string());
    put("x-l3-height", r.height.to_string());
    put("x-l3-input-pixels", (r.in_width * r.in_height).to_string());
    put("x-l3-queue-ms", format!("{queue_ms:.3}"));
    put("x-l3-decode-ms", format!("{:.3}", r.decode_ms));
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
            r.decode_ms, r.render_ms, r.encode_ms
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

    #[test]
    fn region_and_preview() {
        assert!(parse_region("0,0,2,2", 4, 4).is_ok());
        assert!(parse_region("3,0,2,2", 4, 4).is_err());
        assert!(parse_region("0,0,0,2", 4, 4).is_err());
        assert!(parse_region("a,b", 4, 4).is_err());
        let xyz: Vec<f32> = (0..4 * 2 * 3).map(|v| v as f32).collect();
        let (d, w, h) = downscale(&xyz, 4, 2, 2);
        assert_eq!((w, h), (2, 1));
        // mean of pixels 0,1,4,5 channel 0: (0+3+12+15)/4
        assert_eq!(d[0], 7.5);
    }
}
