//! The skips of docs/design.md §9, each timed with and without it on a frame where
//! it applies and on one where it does not, with the output difference.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::BenchError;
use super::stats::time_median;
use crate::io::{
    JpegOptions, PngCompression, encode_jpeg_rgb8, encode_png_rgb8, encode_ppm_rgb8,
    encode_tiff_f32_rgb,
};
use crate::l3::L3Table;
use crate::l3::correct::{IDENTITY, Mat3};
use crate::l3::render::{
    FastOptions, FastRenderer, Frame, Mosaic, Region, WhiteLevel, fuse_kernels, xyz_to_srgb8,
};

/// One skip measured on one frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SkipResult {
    pub skip: String,
    pub case: String,
    /// Whether the skip can save work in this case.
    pub applies: bool,
    /// Median ms with the skip and without it.
    pub with_ms: f64,
    pub without_ms: f64,
    /// without / with.
    pub speedup: f64,
    /// Largest output difference: |ΔXYZ| for XYZ outputs, sRGB codes for 8-bit ones.
    pub max_diff: f64,
    pub diff_unit: String,
}

/// One output encoding of the rendered frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EncoderResult {
    pub encoding: String,
    pub median_ms: f64,
    pub bytes: usize,
}

/// What the skips are measured with.
pub struct SkipInputs<'a> {
    pub table: &'a L3Table,
    /// A non-identity correction (tungsten's T).
    pub t: Mat3,
    pub frame: &'a [f32],
    pub width: usize,
    pub height: usize,
    pub runs: usize,
}

fn max_abs(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| f64::from((x - y).abs())).fold(
        if a.len() == b.len() {
            0.0
        } else {
            f64::INFINITY
        },
        f64::max,
    )
}

fn max_code(a: &[u8], b: &[u8]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| f64::from(x.abs_diff(*y)))
        .fold(
            if a.len() == b.len() {
                0.0
            } else {
                f64::INFINITY
            },
            f64::max,
        )
}

/// Apply a 3×3 matrix to interleaved XYZ (the pass a pipeline without fusion makes).
fn apply_matrix(xyz: &mut [f32], m: &Mat3) {
    let m = m.map(|r| r.map(|v| v as f32));
    xyz.par_chunks_mut(3 * 4096).for_each(|c| {
        for p in c.chunks_exact_mut(3) {
            let v = [p[0], p[1], p[2]];
            for i in 0..3 {
                p[i] = m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2];
            }
        }
    });
}

/// A skip and the case it is measured on.
struct Case<'a> {
    skip: &'a str,
    case: &'a str,
    /// Whether the skip can save work in this case.
    applies: bool,
}

impl Case<'_> {
    /// The result: median ms with and without the skip, and the largest output difference
    /// in `unit`.
    fn result(&self, with: f64, without: f64, diff: f64, unit: &str) -> SkipResult {
        SkipResult {
            skip: self.skip.into(),
            case: self.case.into(),
            applies: self.applies,
            with_ms: with,
            without_ms: without,
            speedup: without / with,
            max_diff: diff,
            diff_unit: unit.into(),
        }
    }
}

const XYZ_UNIT: &str = "|ΔXYZ|";

/// Measure every skip. `progress(message)` reports each step.
pub fn run_skips(
    inp: &SkipInputs<'_>,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<(Vec<SkipResult>, Vec<EncoderResult>), BenchError> {
    let mut out = Vec::new();
    // 1. the illuminant correction fused into the kernels (or skipped for D65)
    progress("skips: fused / identity correction");
    fused_correction(inp, &mut out)?;
    // 2. saturation tests only in tiles that reach the threshold
    progress("skips: saturation tests only where a value clips");
    let on = saturation_tests(inp, &mut out)?;
    // 3. contrast only where a level's flat and texture kernels differ
    progress("skips: contrast only where flat and texture kernels differ");
    equal_contrast_kernels(inp, &mut out)?;
    // 4. only the requested region
    progress("skips: only the requested region");
    region(inp, &on, &mut out)?;
    // 5. only the requested output: 8-bit sRGB straight from fused kernels
    progress("skips: sRGB without an XYZ image");
    let rgb = srgb_output(inp, &on, &mut out)?;
    // 6. encoders of the rendered frame
    progress("encoders");
    let enc = encoders(inp, &on, &rgb)?;
    Ok((out, enc))
}

/// The correction fused into the kernels against a separate 3×3 pass, under tungsten and
/// under D65.
fn fused_correction(inp: &SkipInputs<'_>, out: &mut Vec<SkipResult>) -> Result<(), BenchError> {
    let (w, h, runs) = (inp.width, inp.height, inp.runs);
    let table = inp.table;
    let frame = Mosaic::Volts(inp.frame);
    for (case, t, applies) in [
        ("Tungsten (T ≠ I): T fused into the kernels", inp.t, true),
        (
            "D65 (T = I): the table's kernels as they are",
            IDENTITY,
            true,
        ),
    ] {
        let fused = FastRenderer::new(table, &fuse_kernels(table, &t))?;
        let plain = FastRenderer::new(table, &table.kernels)?;
        let (with, a) = time_median(runs, || Ok(fused.render_xyz(frame, w, h, None)?.0))?;
        let (without, b) = time_median(runs, || {
            let mut x = plain.render_xyz(frame, w, h, None)?.0;
            apply_matrix(&mut x, &t);
            Ok(x)
        })?;
        let c = Case {
            skip: "correction fused into the kernels (vs a separate 3×3 pass)",
            case,
            applies,
        };
        out.push(c.result(with, without, max_abs(&a, &b), XYZ_UNIT));
    }
    Ok(())
}

/// Saturation tests only in tiles that reach the threshold, on a dim and a bright frame;
/// the renderer with every skip on (fused kernels), which the later steps use.
fn saturation_tests(
    inp: &SkipInputs<'_>,
    out: &mut Vec<SkipResult>,
) -> Result<FastRenderer, BenchError> {
    let (w, h, runs) = (inp.width, inp.height, inp.runs);
    let table = inp.table;
    let renderer = |opts: FastOptions, kernels: &[f32]| -> Result<FastRenderer, BenchError> {
        let mut r = FastRenderer::new(table, kernels)?;
        r.options = opts;
        Ok(r)
    };
    let kernels = fuse_kernels(table, &inp.t);
    let swing = table.meta.voltage_swing as f32;
    let dim: Vec<f32> = inp.frame.iter().map(|v| v * 0.5).collect();
    let bright: Vec<f32> = inp.frame.iter().map(|v| (v * 4.0).min(swing)).collect();
    let on = renderer(FastOptions::default(), &kernels)?;
    let sat_off = renderer(
        FastOptions {
            skip_unsaturated_tiles: false,
            ..FastOptions::default()
        },
        &kernels,
    )?;
    for (case, v, applies) in [
        ("frame at half exposure: no value clips", &dim, true),
        (
            "frame at 4× exposure: clipped values in most tiles",
            &bright,
            false,
        ),
    ] {
        let m = Mosaic::Volts(v);
        let (with, a) = time_median(runs, || Ok(on.render_xyz(m, w, h, None)?.0))?;
        let (without, b) = time_median(runs, || Ok(sat_off.render_xyz(m, w, h, None)?.0))?;
        let c = Case {
            skip: "saturation tests only in tiles that reach the threshold",
            case,
            applies,
        };
        out.push(c.result(with, without, max_abs(&a, &b), XYZ_UNIT));
    }
    Ok(on)
}

/// Contrast only where a level's flat and texture kernels differ: the trained table, and
/// the same table with its texture kernels set equal to the flat ones.
fn equal_contrast_kernels(
    inp: &SkipInputs<'_>,
    out: &mut Vec<SkipResult>,
) -> Result<(), BenchError> {
    let (w, h, runs) = (inp.width, inp.height, inp.runs);
    let table = inp.table;
    let frame = Mosaic::Volts(inp.frame);
    let mut merged = table.clone();
    let nf3 = 3 * table.n_features();
    for g in 0..table.n_classes() / 2 {
        let (flat, tex) = merged.kernels.split_at_mut((2 * g + 1) * nf3);
        tex[..nf3].copy_from_slice(&flat[2 * g * nf3..]);
    }
    for (case, t, applies) in [
        (
            "the trained table: flat and texture kernels differ",
            table,
            false,
        ),
        (
            "the same table with texture kernels set equal to flat ones",
            &merged,
            true,
        ),
    ] {
        let k = fuse_kernels(t, &inp.t);
        let mut on = FastRenderer::new(t, &k)?;
        on.options = FastOptions::default();
        let mut off = FastRenderer::new(t, &k)?;
        off.options.skip_equal_contrast_kernels = false;
        let (with, a) = time_median(runs, || Ok(on.render_xyz(frame, w, h, None)?.0))?;
        let (without, b) = time_median(runs, || Ok(off.render_xyz(frame, w, h, None)?.0))?;
        let c = Case {
            skip: "contrast only where flat and texture kernels differ",
            case,
            applies,
        };
        out.push(c.result(with, without, max_abs(&a, &b), XYZ_UNIT));
    }
    Ok(())
}

/// Only the requested region against rendering all of the frame, then cropping.
fn region(
    inp: &SkipInputs<'_>,
    on: &FastRenderer,
    out: &mut Vec<SkipResult>,
) -> Result<(), BenchError> {
    let (w, h, runs) = (inp.width, inp.height, inp.runs);
    let frame = Mosaic::Volts(inp.frame);
    let side = 1024.min(w).min(h);
    for (case, reg, applies) in [
        (
            format!("a {side}×{side} region"),
            Region {
                x: (w - side) / 2,
                y: (h - side) / 2,
                width: side,
                height: side,
            },
            true,
        ),
        (
            "the whole frame as the region".to_string(),
            Region {
                x: 0,
                y: 0,
                width: w,
                height: h,
            },
            false,
        ),
    ] {
        let (with, a) = time_median(runs, || Ok(on.render_xyz(frame, w, h, Some(reg))?.0))?;
        let (without, b) = time_median(runs, || {
            let all = on.render_xyz(frame, w, h, None)?.0;
            let mut c = Vec::with_capacity(reg.width * reg.height * 3);
            for r in reg.y..reg.y + reg.height {
                c.extend_from_slice(&all[(r * w + reg.x) * 3..(r * w + reg.x + reg.width) * 3]);
            }
            Ok(c)
        })?;
        let c = Case {
            skip: "only the requested region (vs render all, then crop)",
            case: &case,
            applies,
        };
        out.push(c.result(with, without, max_abs(&a, &b), XYZ_UNIT));
    }
    Ok(())
}

/// 8-bit sRGB straight from the kernels against an XYZ image then sRGB, and an XYZ request
/// (nothing to skip); the sRGB frame.
fn srgb_output(
    inp: &SkipInputs<'_>,
    on: &FastRenderer,
    out: &mut Vec<SkipResult>,
) -> Result<Frame, BenchError> {
    let (w, h, runs) = (inp.width, inp.height, inp.runs);
    let frame = Mosaic::Volts(inp.frame);
    let skip = "8-bit sRGB straight from the kernels (vs XYZ image, then sRGB)";
    let white = WhiteLevel::Auto;
    let (with, a) = time_median(runs, || Ok(on.render_srgb8(frame, w, h, None, white)?.0))?;
    let (without, b) = time_median(runs, || {
        let xyz = on.render_xyz(frame, w, h, None)?.0;
        let wy = on.white_y(frame, w, h, white)?;
        Ok(xyz_to_srgb8(&xyz, wy))
    })?;
    let c = Case {
        skip,
        case: "PNG request (sRGB 8-bit, auto white)",
        applies: true,
    };
    out.push(c.result(with, without, max_code(&a, &b), "sRGB codes"));
    let (with, _) = time_median(runs, || Ok(on.render_xyz(frame, w, h, None)?.0))?;
    let c = Case {
        skip,
        case: "XYZ request: nothing to skip (the same render)",
        applies: false,
    };
    out.push(c.result(with, with, 0.0, XYZ_UNIT));
    Ok(a)
}

/// Each output encoding of the rendered frame (`rgb`: its sRGB).
fn encoders(
    inp: &SkipInputs<'_>,
    on: &FastRenderer,
    rgb: &[u8],
) -> Result<Vec<EncoderResult>, BenchError> {
    let (w, h, runs) = (inp.width, inp.height, inp.runs);
    let frame = Mosaic::Volts(inp.frame);
    let xyz = on.render_xyz(frame, w, h, None)?.0;
    let mut enc = Vec::new();
    for (name, c) in [
        ("PNG fast (bands on all cores)", PngCompression::Fast),
        ("PNG default", PngCompression::Default),
    ] {
        let (ms, bytes) = time_median(runs, || {
            encode_png_rgb8(w, h, rgb, c).map_err(|e| BenchError::Invalid(e.to_string()))
        })?;
        enc.push(EncoderResult {
            encoding: name.into(),
            median_ms: ms,
            bytes: bytes.len(),
        });
    }
    let (ms, bytes) = time_median(runs, || {
        encode_jpeg_rgb8(w, h, rgb, JpegOptions::default())
            .map_err(|e| BenchError::Invalid(e.to_string()))
    })?;
    enc.push(EncoderResult {
        encoding: "JPEG quality 90, 4:2:0".into(),
        median_ms: ms,
        bytes: bytes.len(),
    });
    // (the service sends a PPM's header and then the rendered frame itself, without this copy)
    let (ms, bytes) = time_median(runs, || {
        encode_ppm_rgb8(w, h, rgb).map_err(|e| BenchError::Invalid(e.to_string()))
    })?;
    enc.push(EncoderResult {
        encoding: "PPM sRGB 8-bit (header + copy)".into(),
        median_ms: ms,
        bytes: bytes.len(),
    });
    let (ms, bytes) = time_median(runs, || {
        encode_tiff_f32_rgb(w, h, &xyz).map_err(|e| BenchError::Invalid(e.to_string()))
    })?;
    enc.push(EncoderResult {
        encoding: "TIFF float XYZ".into(),
        median_ms: ms,
        bytes: bytes.len(),
    });
    let (ms, bytes) = time_median(runs, || {
        Ok(xyz
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>())
    })?;
    enc.push(EncoderResult {
        encoding: "raw f32 XYZ".into(),
        median_ms: ms,
        bytes: bytes.len(),
    });
    Ok(enc)
}
