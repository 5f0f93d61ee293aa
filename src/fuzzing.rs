//! Fuzz target bodies, shared by the cargo-fuzz targets in `fuzz/` and by
//! `tests/fuzz_regressions.rs` (which replays saved crashers under `cargo test`).
//! Compiled only with the `test-support` feature (the fuzz crate and the crate's own
//! tests turn it on; a release build of the library has no such module).
//!
//! Each body takes arbitrary bytes, runs one input decoder and what the
//! service does with a decoded value next, and checks the invariants the
//! decoder promises. Invalid input must come back as an error; a body panics
//! only when an invariant breaks (a panic inside the library, a NaN pixel, a
//! non-finite correction matrix), which is what the fuzzer reports.

use std::sync::OnceLock;

use crate::camera::Cfa;
use crate::io::{
    DecodedMosaic, DngWriteInfo, Limits, MosaicFormat, RawMeta, decode_dng,
    decode_mosaic_with_info, decode_raw_u16_le, detect_format, encode_dng,
};
use crate::l3::L3Table;
use crate::l3::correct::IlluminantRegistry;
use crate::l3::render::{WhiteLevel, render_reference, white_y, xyz_to_srgb8};
use crate::service::{IlluminantDefinition, RenderQuery, apply_illuminant, parse_job_request};
use crate::spectral::{Extrapolation, WavelengthGrid, ces_reflectances};
use crate::test_support::tiny_table;

/// Names of the fuzz targets, as directories under `tests/fuzz_regressions/`
/// and binaries under `fuzz/fuzz_targets/`.
pub const FUZZ_TARGETS: [&str; 6] = [
    "raw_query",
    "mosaic_decode",
    "dng_decode",
    "table_file",
    "training_json",
    "illuminant_upload",
];

/// Run the body of fuzz target `name` on `data`; `false` if there is no such target.
pub fn run_target(name: &str, data: &[u8]) -> bool {
    match name {
        "raw_query" => fuzz_raw_query(data),
        "mosaic_decode" => fuzz_mosaic_decode(data),
        "dng_decode" => fuzz_dng_decode(data),
        "table_file" => fuzz_table_file(data),
        "training_json" => fuzz_training_json(data),
        "illuminant_upload" => fuzz_illuminant_upload(data),
        _ => return false,
    }
    true
}

/// Decoders are given these limits: big enough for every size class, small
/// enough that one input cannot make the fuzzer allocate gigabytes.
const FUZZ_LIMITS: Limits = Limits {
    max_pixels: 1 << 22,
    max_dim: 1 << 14,
};

/// Frames up to this many pixels are also rendered.
const RENDER_MAX_PIXELS: usize = 4096;

/// Render `volts` with the tiny table when the frame is small, and check the
/// output is finite and encodes.
fn render_small(volts: &[f32], w: usize, h: usize, white: WhiteLevel) {
    if w.saturating_mul(h) > RENDER_MAX_PIXELS {
        return;
    }
    let t = tiny_table();
    match render_reference(t, &t.kernels, volts, w, h) {
        Ok((xyz, stats)) => {
            assert_eq!(xyz.len(), w * h * 3);
            assert_eq!(stats.pixels as usize, w * h);
            if let Some(i) = xyz.iter().position(|v| !v.is_finite()) {
                panic!("rendered pixel {} of a {w}×{h} frame is {}", i / 3, xyz[i]);
            }
            let wy = white_y(&xyz, w, h, white);
            assert!(wy.is_finite() && wy > 0.0, "white Y {wy}");
            // the fast renderer agrees with the reference on whatever the fuzzer sends
            if let Ok(fast) = crate::l3::render::FastRenderer::new(t, &t.kernels) {
                let got = fast.render_xyz(crate::l3::render::Mosaic::Volts(volts), w, h, None);
                let Ok((got, _)) = got else {
                    panic!("the fast renderer refused a frame the reference rendered")
                };
                let d = got
                    .iter()
                    .zip(&xyz)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0f32, f32::max);
                assert!(d <= 1e-4, "fast and reference renderers differ by {d}");
            }
            assert_eq!(xyz_to_srgb8(&xyz, wy).len(), w * h * 3);
        }
        Err(e) => {
            // only non-finite volts are refused (the decoders never produce them)
            assert!(
                volts.iter().any(|v| !v.is_finite()),
                "finite frame refused: {e}"
            );
        }
    }
}

/// Raw little-endian u16 body plus render query parameters, as the service's
/// `application/octet-stream` render path takes them.
///
/// Input layout: if the first byte is `b'?'`, a query string up to the first
/// `b'\n'` (parsed as the service's [`RenderQuery`]) and then the body; otherwise a binary
/// header `width u8, height u8, black u16 LE, white u16 LE` and then the body.
pub fn fuzz_raw_query(data: &[u8]) {
    let (q, body) = if data.first() == Some(&b'?') {
        let end = data.iter().position(|&b| b == b'\n').unwrap_or(data.len());
        let text = String::from_utf8_lossy(&data[1..end]);
        let uri: axum::http::Uri = match format!("/v1/render?{text}").parse() {
            Ok(u) => u,
            Err(_) => return,
        };
        let q = match axum::extract::Query::<RenderQuery>::try_from_uri(&uri) {
            Ok(q) => q.0,
            Err(_) => return,
        };
        (q, &data[(end + 1).min(data.len())..])
    } else {
        if data.len() < 6 {
            return;
        }
        let q = RenderQuery {
            width: Some(usize::from(data[0])),
            height: Some(usize::from(data[1])),
            black_level: Some(u16::from_le_bytes([data[2], data[3]])),
            white_level: Some(u16::from_le_bytes([data[4], data[5]])),
            ..RenderQuery::default()
        };
        (q, &data[6..])
    };
    let white = match q.white.as_deref().map(str::parse::<WhiteLevel>) {
        None => WhiteLevel::Auto,
        Some(Ok(w)) => w,
        Some(Err(_)) => return,
    };
    let (Some(w), Some(h)) = (q.width, q.height) else {
        return;
    };
    let frame = match decode_raw_u16_le(body, w, h, &FUZZ_LIMITS) {
        Ok(f) => f,
        Err(e) => {
            assert!(!e.to_string().is_empty());
            return;
        }
    };
    assert_eq!(frame.data.len(), w * h);
    assert_eq!(body.len(), w * h * 2);
    let swing = tiny_table().meta.voltage_swing;
    let meta = RawMeta::new(
        w,
        h,
        "",
        q.black_level.unwrap_or(0),
        q.white_level.unwrap_or(u16::MAX),
        swing,
    );
    let volts = match frame.to_volts(&meta) {
        Ok(v) => v,
        Err(e) => {
            // only bad levels are refused
            assert!(meta.black_level >= meta.white_level, "to_volts: {e}");
            return;
        }
    };
    assert!(
        volts
            .iter()
            .all(|v| v.is_finite() && (0.0..=swing as f32).contains(v)),
        "to_volts left the [0, swing] range"
    );
    render_small(&volts, w, h, white);
}

/// PNG / TIFF / PGM mosaic bytes through the format-detecting decoder.
pub fn fuzz_mosaic_decode(data: &[u8]) {
    let (m, info) = match decode_mosaic_with_info(data, &FUZZ_LIMITS) {
        Ok(v) => v,
        Err(e) => {
            assert!(!e.to_string().is_empty());
            return;
        }
    };
    let (w, h) = m.dims();
    assert!(
        FUZZ_LIMITS.check(w, h).is_ok(),
        "decoded {w}×{h} beyond limits"
    );
    let volts = match m {
        DecodedMosaic::U16(frame) => {
            assert_eq!(frame.data.len(), w * h);
            let white = info.max_value.unwrap_or(u16::MAX).max(1);
            if let Some(mx) = info.max_value {
                assert!(
                    frame.data.iter().all(|&v| v <= mx),
                    "a sample exceeds the container's maximum {mx}"
                );
            }
            let meta = RawMeta::new(w, h, "RG/WB", 0, white, 1.8);
            match frame.to_volts(&meta) {
                Ok(v) => v,
                Err(e) => panic!("to_volts of a decoded mosaic: {e}"),
            }
        }
        DecodedMosaic::F32 { data, .. } => {
            assert_eq!(data.len(), w * h);
            assert!(data.iter().all(|v| v.is_finite()), "non-finite f32 decoded");
            data
        }
    };
    render_small(&volts, w, h, WhiteLevel::Auto);
}

/// DNG bytes through the DNG reader: a decoded frame is within the limits, its CFA and
/// levels make valid sidecar metadata, the format detector calls it a DNG, small frames
/// render, and writing it back as DNG reads back the same mosaic.
pub fn fuzz_dng_decode(data: &[u8]) {
    let d = match decode_dng(data, &FUZZ_LIMITS) {
        Ok(d) => d,
        Err(e) => {
            assert!(!e.to_string().is_empty());
            return;
        }
    };
    let (w, h) = (d.frame.width, d.frame.height);
    assert!(
        FUZZ_LIMITS.check(w, h).is_ok(),
        "decoded {w}×{h} beyond limits"
    );
    assert_eq!(d.frame.data.len(), w * h);
    assert_eq!(detect_format(data), Some(MosaicFormat::Dng));
    assert!(
        d.black_level < d.white_level,
        "levels {} ≥ {}",
        d.black_level,
        d.white_level
    );
    if let Err(e) = Cfa::parse(&d.cfa) {
        panic!("the DNG's CFA {:?} does not parse: {e}", d.cfa);
    }
    if let Some(n) = d.info.neutral() {
        assert_eq!(n.len(), d.info.plane_colors.len());
        assert!(
            n.iter().all(|(_, v)| v.is_finite() && *v > 0.0),
            "neutral {n:?}"
        );
    }
    let meta = d.raw_meta(1.8);
    if let Err(e) = meta.validate() {
        panic!("a decoded DNG's sidecar fields are invalid: {e}");
    }
    let volts = match d.frame.to_volts(&meta) {
        Ok(v) => v,
        Err(e) => panic!("to_volts of a decoded DNG: {e}"),
    };
    render_small(&volts, w, h, WhiteLevel::Auto);
    if w * h <= 16 * RENDER_MAX_PIXELS {
        let bytes = match encode_dng(&d.frame, &meta, &DngWriteInfo::default()) {
            Ok(b) => b,
            Err(e) => panic!("a decoded DNG does not encode: {e}"),
        };
        match decode_dng(&bytes, &FUZZ_LIMITS) {
            Ok(back) => {
                assert_eq!(
                    back.frame, d.frame,
                    "the DNG written back reads differently"
                );
                assert_eq!(
                    (back.black_level, back.white_level),
                    (d.black_level, d.white_level)
                );
                assert_eq!(back.cfa, d.cfa);
            }
            Err(e) => panic!("a written DNG does not read back: {e}"),
        }
    }
}

/// The tensors a table file holds, in checksum order.
const TABLE_TENSORS: [&str; 7] = [
    "kernels",
    "contrast_thresholds",
    "class_samples",
    "class_lambda",
    "class_condition",
    "class_kernel_norm",
    "class_filled_from",
];

/// Re-sign a safetensors file as a table file: recompute the `sha256` header
/// entry over its `l3` metadata and tables tensors, so that a mutated header
/// or tensor reaches the table's validation instead of stopping at the
/// checksum (anyone can compute a SHA-256: the checksum guards against
/// corruption, not against a hostile file). `None` if the bytes are not a
/// safetensors file with `l3` metadata and all seven tensors.
pub fn resign_table(bytes: &[u8]) -> Option<Vec<u8>> {
    use safetensors::SafeTensors;
    use sha2::{Digest, Sha256};
    let st = SafeTensors::deserialize(bytes).ok()?;
    let (_, md) = SafeTensors::read_metadata(bytes).ok()?;
    let mut info = md.metadata().clone()?;
    let meta = info.get("l3")?.clone();
    let mut views = Vec::new();
    for n in TABLE_TENSORS {
        views.push((n.to_string(), st.tensor(n).ok()?));
    }
    let mut h = Sha256::new();
    h.update(meta.as_bytes());
    for (name, v) in &views {
        h.update(name.as_bytes());
        h.update((v.data().len() as u64).to_le_bytes());
        h.update(v.data());
    }
    let digest: String = h.finalize().iter().map(|b| format!("{b:02x}")).collect();
    info.insert("sha256".into(), digest);
    safetensors::serialize(views, Some(info)).ok()
}

/// Table file bytes (safetensors with the l3 header and checksum), as given
/// and re-signed ([`resign_table`]).
pub fn fuzz_table_file(data: &[u8]) {
    check_table_bytes(data);
    if let Some(resigned) = resign_table(data) {
        check_table_bytes(&resigned);
    }
}

fn check_table_bytes(data: &[u8]) {
    let t = match L3Table::from_bytes(data, "fuzz") {
        Ok(t) => t,
        Err(e) => {
            assert!(!e.to_string().is_empty());
            return;
        }
    };
    assert!(t.validate().is_ok());
    // a loaded table saves and loads back to the same numbers
    let bytes = match t.to_bytes() {
        Ok(b) => b,
        Err(e) => panic!("a loaded table does not serialise: {e}"),
    };
    match L3Table::from_bytes(&bytes, "fuzz round trip") {
        Ok(back) => assert_eq!(back.kernels, t.kernels),
        Err(e) => panic!("a re-serialised table does not load: {e}"),
    }
    // and classifies a small frame without panicking
    if t.n_classes() <= 1 << 16 {
        let frame: Vec<f32> = (0..64)
            .map(|i| (i as f32 / 64.0) * t.meta.voltage_swing as f32)
            .collect();
        let _ = render_reference(&t, &t.kernels, &frame, 8, 8);
    }
}

/// A training job's JSON body (the [`TrainingSpec`](crate::l3::learn::TrainingSpec)
/// fields plus `sensor` and `activate`), parsed and validated as the service does,
/// then turned into L3 parameters. Nothing is trained.
pub fn fuzz_training_json(data: &[u8]) {
    let req = match parse_job_request(data) {
        Ok((req, _)) => req,
        Err(e) => {
            assert!(!e.to_string().is_empty());
            return;
        }
    };
    assert!(req.spec.validate().is_ok());
    assert!(req.sensor.validate().is_ok());
    match req.spec.params(req.sensor.voltage_swing_v) {
        Ok(p) => {
            assert!(p.validate().is_ok());
            assert_eq!(p.levels.len(), req.spec.levels);
        }
        Err(e) => assert!(!e.to_string().is_empty()),
    }
}

/// A small registry (CES reflectances only) cloned for every upload.
fn fuzz_registry() -> &'static IlluminantRegistry {
    static R: OnceLock<Result<IlluminantRegistry, String>> = OnceLock::new();
    let r = R.get_or_init(|| {
        let grid = WavelengthGrid::default();
        let refl = ces_reflectances()
            .into_iter()
            .map(|(_, s)| s.resample(&grid, Extrapolation::Hold))
            .collect();
        IlluminantRegistry::new(grid, refl).map_err(|e| e.to_string())
    });
    match r {
        Ok(r) => r,
        Err(e) => panic!("the fuzz registry does not build: {e}"),
    }
}

/// An illuminant upload: a name up to the first `b'\n'`, then the JSON body
/// ([`IlluminantDefinition`]: a matrix, an SPD or a CCT), applied to a registry
/// as the service's `PUT /v1/illuminants/{name}` does ([`apply_illuminant`]).
pub fn fuzz_illuminant_upload(data: &[u8]) {
    let end = data.iter().position(|&b| b == b'\n').unwrap_or(0);
    let name = String::from_utf8_lossy(&data[..end]).into_owned();
    let body = &data[(end + 1).min(data.len())..];
    let def: IlluminantDefinition = match serde_json::from_slice(body) {
        Ok(d) => d,
        Err(_) => return,
    };
    let mut reg = fuzz_registry().clone();
    match apply_illuminant(&mut reg, &name, &def) {
        Ok(entry) => {
            assert!(
                entry.t.iter().flatten().all(|v| v.is_finite()),
                "non-finite T {:?}",
                entry.t
            );
            let got = reg.get(&name).map(|e| e.t);
            assert_eq!(
                got,
                Some(entry.t),
                "the entry is not retrievable by its name"
            );
            // fusing T into kernels keeps them finite (what rendering uses)
            let t = tiny_table();
            let fused = crate::l3::render::fuse_kernels(t, &entry.t);
            assert!(
                fused.iter().all(|v| v.is_finite()),
                "T {:?} makes fused kernels non-finite",
                entry.t
            );
        }
        Err(e) => assert!(!e.to_string().is_empty()),
    }
}
