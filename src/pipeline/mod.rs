//! One render pipeline, from a decoded mosaic to encoded output, shared by `l3 render`, the
//! service's `POST /v1/render` and the evaluation:
//!
//! - kernel selection for a (table, illuminant): a same-illuminant table's kernels fused
//!   with the illuminant's correction matrix (the camera-aware C by default, the paper's T
//!   on request: [`correction_for`]), a cross-illuminant table's own kernels;
//! - the options: output white, region (`x,y,width,height`), preview downscale (1–16);
//! - rendering (straight to 8-bit sRGB where the output allows it), downscaling and
//!   encoding (PNG, PPM, float XYZ or 16-bit sRGB TIFF, raw f32 XYZ).

use std::str::FromStr;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use crate::camera::Camera;
use crate::io::{
    IoError, PngCompression, encode_png_rgb8, encode_ppm_rgb8, encode_tiff_f32_rgb,
    encode_tiff_rgb16, ppm_header,
};
use crate::l3::{
    FastRenderer, Frame, IlluminantEntry, L3Error, L3Table, Mosaic, Region, RenderStats, TableKind,
    WhiteLevel, fuse_entry, xyz_to_srgb8, xyz_to_srgb16,
};
use crate::spectral::{IsetData, WavelengthGrid};
use crate::training::{TrainError, camera_corrected, noise_model, with_neutral};

/// Largest preview downscale factor.
pub const MAX_PREVIEW: usize = 16;

/// Errors of the pipeline, by kind: the options do not fit the frame, the render failed,
/// the encoding failed, or the render was canceled.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// A region or preview that is malformed or does not fit the frame.
    #[error("{0}")]
    Options(String),
    #[error(transparent)]
    Render(#[from] L3Error),
    /// The camera-aware correction could not be fitted for the table's sensor.
    #[error("camera-aware correction: {0}")]
    Correction(#[from] TrainError),
    #[error(transparent)]
    Encode(#[from] IoError),
}

/// The encoded output formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    /// 8-bit sRGB PNG.
    Png,
    /// 8-bit sRGB binary PPM (a header and the pixels).
    Ppm,
    /// Float XYZ TIFF.
    TiffXyz,
    /// 16-bit sRGB TIFF.
    TiffSrgb16,
    /// Interleaved little-endian f32 XYZ, no header.
    F32,
}

impl OutputFormat {
    /// Whether the output is display-referred (needs a white level).
    fn needs_white(self) -> bool {
        !matches!(self, OutputFormat::TiffXyz | OutputFormat::F32)
    }
}

/// How to render.
#[derive(Debug, Clone, Copy)]
pub struct RenderOptions {
    /// The Y that maps to white (display-referred outputs).
    pub white: WhiteLevel,
    /// The part of the frame to render (default: all of it).
    pub region: Option<Region>,
    /// Integer box-average downscale, 1 (none) to [`MAX_PREVIEW`].
    pub preview: usize,
    /// PNG compression.
    pub png: PngCompression,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            white: WhiteLevel::Auto,
            region: None,
            preview: 1,
            png: PngCompression::Fast,
        }
    }
}

/// A crop written `x,y,width,height`.
pub fn parse_region(s: &str) -> Result<Region, PipelineError> {
    let v: Vec<usize> = s
        .split(',')
        .map(|p| p.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            PipelineError::Options(format!(
                "region '{s}': expected x,y,width,height (non-negative integers)"
            ))
        })?;
    let [x, y, width, height] = v[..] else {
        return Err(PipelineError::Options(format!(
            "region '{s}': expected four numbers x,y,width,height"
        )));
    };
    Ok(Region {
        x,
        y,
        width,
        height,
    })
}

/// A preview factor from 1 to [`MAX_PREVIEW`].
pub fn check_preview(preview: usize) -> Result<usize, PipelineError> {
    if (1..=MAX_PREVIEW).contains(&preview) {
        Ok(preview)
    } else {
        Err(PipelineError::Options(format!(
            "preview {preview}: an integer downscale factor from 1 to {MAX_PREVIEW}"
        )))
    }
}

/// The output size of a `width × height` frame under `opts`, or why the options do not fit.
pub fn output_size(
    width: usize,
    height: usize,
    opts: &RenderOptions,
) -> Result<(usize, usize), PipelineError> {
    let preview = check_preview(opts.preview)?;
    let (ow, oh) = match opts.region {
        None => (width, height),
        Some(r) => {
            let inside = r.width > 0
                && r.height > 0
                && r.x.checked_add(r.width).is_some_and(|e| e <= width)
                && r.y.checked_add(r.height).is_some_and(|e| e <= height);
            if !inside {
                return Err(PipelineError::Options(format!(
                    "region {},{},{}×{} is empty or not inside the {width}×{height} frame",
                    r.x, r.y, r.width, r.height
                )));
            }
            (r.width, r.height)
        }
    };
    if ow / preview == 0 || oh / preview == 0 {
        return Err(PipelineError::Options(format!(
            "preview {preview} leaves nothing of a {ow}×{oh} image"
        )));
    }
    Ok((ow / preview, oh / preview))
}

/// Box-average downscale by `k` (partial edge blocks dropped).
pub fn downscale(xyz: &[f32], w: usize, h: usize, k: usize) -> (Vec<f32>, usize, usize) {
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
                    for (c, a) in acc.iter_mut().enumerate() {
                        *a += f64::from(xyz[p + c]);
                    }
                }
            }
            for (c, a) in acc.iter().enumerate() {
                out[(oy * ow + ox) * 3 + c] = (a / n) as f32;
            }
        }
    }
    (out, ow, oh)
}

/// Whether `table` renders with its own kernels under every illuminant (cross-illuminant
/// tables output D65 already); otherwise its kernels are fused with the illuminant's
/// correction.
pub fn uses_own_kernels(table: &L3Table) -> bool {
    table.meta.kind == TableKind::CrossIlluminant
}

/// How a same-illuminant table's output is taken from the acquisition light to D65.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum CorrectionMode {
    /// The registry's T: XYZ under the light → XYZ under D65, from colorimetry alone (the
    /// paper's method).
    #[serde(alias = "t")]
    Colorimetric,
    /// C, fitted per level on the table's own colour maps and its sensor's response under the light
    /// (`crate::l3::camera_correction`), wherever the light's spectrum is known; T for a
    /// correction given only as a matrix.
    #[default]
    Camera,
}

impl CorrectionMode {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Colorimetric => "colorimetric",
            Self::Camera => "camera",
        }
    }
}

impl FromStr for CorrectionMode {
    type Err = PipelineError;
    fn from_str(s: &str) -> Result<Self, PipelineError> {
        match s.to_ascii_lowercase().as_str() {
            "camera" => Ok(Self::Camera),
            "colorimetric" | "t" => Ok(Self::Colorimetric),
            _ => Err(PipelineError::Options(format!(
                "correction '{s}': expected camera or colorimetric (t)"
            ))),
        }
    }
}

/// The correction `table` renders with under `entry` in `mode`: `entry` itself, or, for a
/// same-illuminant table with a sensor description in [`CorrectionMode::Camera`] under a
/// light whose spectrum is known, `entry` with C in place of T (fitted on the table's sensor, built-in curves or
/// `iset`'s). For a table whose chroma classes balance by the light, the entry also gets the
/// sensor's neutral under a light whose spectrum is known ([`IlluminantEntry::neutral`]).
pub fn correction_for(
    table: &L3Table,
    entry: &IlluminantEntry,
    mode: CorrectionMode,
    iset: Option<&IsetData>,
) -> Result<IlluminantEntry, PipelineError> {
    let known = entry.spd.is_some();
    let camera_aware = known && mode == CorrectionMode::Camera && !uses_own_kernels(table);
    let balances = known && table.chroma_balances();
    if !camera_aware && !balances {
        return Ok(entry.clone());
    }
    let design = match table.sensor_design() {
        Ok(d) => d,
        // a table with no sensor description has nothing to fit C on: T
        Err(L3Error::NoSensor) => return Ok(entry.clone()),
        Err(e) => return Err(e.into()),
    };
    let camera = Camera::new(&design, WavelengthGrid::default(), iset).map_err(TrainError::from)?;
    if camera_aware {
        Ok(camera_corrected(
            &camera,
            &table.level_colour_maps(&noise_model(&design))?,
            entry,
            iset,
        )?)
    } else {
        Ok(with_neutral(&camera, entry)?)
    }
}

/// The XYZ kernels `table` renders with under `entry`.
pub fn kernels_for(table: &L3Table, entry: &IlluminantEntry) -> Result<Vec<f32>, L3Error> {
    if uses_own_kernels(table) {
        Ok(table.kernels.clone())
    } else {
        fuse_entry(table, entry)
    }
}

/// An encoded output: one buffer, or a PPM header followed by the rendered frame itself (so
/// a server can send the pixels from the render's buffer).
pub enum Encoded {
    Whole(Vec<u8>),
    Framed { header: Vec<u8>, frame: Frame },
}

impl Encoded {
    pub fn len(&self) -> usize {
        match self {
            Encoded::Whole(b) => b.len(),
            Encoded::Framed { header, frame } => header.len() + frame.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The output as one buffer.
    pub fn into_vec(self) -> Vec<u8> {
        match self {
            Encoded::Whole(b) => b,
            Encoded::Framed { mut header, frame } => {
                header.extend_from_slice(&frame);
                header
            }
        }
    }
}

/// The output of [`RenderPipeline::render`].
pub struct Rendered {
    pub output: Encoded,
    /// Output size (after region and preview).
    pub width: usize,
    pub height: usize,
    pub stats: RenderStats,
    /// The Y mapped to white (1 for scene-referred outputs).
    pub white_y: f64,
    pub render_ms: f64,
    pub encode_ms: f64,
}

/// A table prepared to render under one illuminant.
pub struct RenderPipeline {
    renderer: FastRenderer,
}

/// What the renderer produced, before encoding.
enum Pixels {
    Srgb8(Frame),
    Xyz(Vec<f32>),
}

impl RenderPipeline {
    /// Prepares `table` for `entry` (kernel selection: [`kernels_for`]).
    pub fn new(table: &L3Table, entry: &IlluminantEntry) -> Result<Self, L3Error> {
        Ok(Self {
            renderer: FastRenderer::under_light(
                table,
                &kernels_for(table, entry)?,
                entry.neutral.as_deref(),
            )?,
        })
    }

    /// Prepares `table` with explicit XYZ kernels.
    pub fn with_kernels(table: &L3Table, kernels: &[f32]) -> Result<Self, L3Error> {
        Ok(Self {
            renderer: FastRenderer::new(table, kernels)?,
        })
    }

    /// The fast renderer behind the pipeline.
    pub fn renderer(&self) -> &FastRenderer {
        &self.renderer
    }

    /// The fast renderer behind the pipeline, taken out of it.
    pub fn into_renderer(self) -> FastRenderer {
        self.renderer
    }

    /// Renders `mosaic` (`width × height`) to `format` under `opts`. Stops between bands of
    /// rows once `cancel` is set ([`L3Error::RenderCanceled`]).
    pub fn render(
        &self,
        mosaic: Mosaic<'_>,
        width: usize,
        height: usize,
        format: OutputFormat,
        opts: &RenderOptions,
        cancel: &AtomicBool,
    ) -> Result<Rendered, PipelineError> {
        let (ow, oh) = output_size(width, height, opts)?;
        let r = &self.renderer;
        let t0 = Instant::now();
        // only what the output needs: 8-bit sRGB straight from the kernels for a PNG or PPM
        // at full size, XYZ otherwise; only the region's pixels
        let srgb8 = matches!(format, OutputFormat::Png | OutputFormat::Ppm);
        let (pixels, stats, wy) = if srgb8 && opts.preview == 1 {
            let (rgb, wy, stats) =
                r.render_srgb8_until(mosaic, width, height, opts.region, opts.white, cancel)?;
            (Pixels::Srgb8(rgb), stats, wy)
        } else {
            let (xyz, stats) = r.render_xyz_until(mosaic, width, height, opts.region, cancel)?;
            let wy = if format.needs_white() {
                r.white_y(mosaic, width, height, opts.white)?
            } else {
                1.0
            };
            let xyz = if opts.preview > 1 {
                let (rw, rh) = opts.region.map_or((width, height), |g| (g.width, g.height));
                downscale(&xyz, rw, rh, opts.preview).0
            } else {
                xyz
            };
            (Pixels::Xyz(xyz), stats, wy)
        };
        let t1 = Instant::now();
        let output = encode(format, pixels, ow, oh, wy, opts.png)?;
        let t2 = Instant::now();
        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
        Ok(Rendered {
            output,
            width: ow,
            height: oh,
            stats,
            white_y: wy,
            render_ms: ms(t0, t1),
            encode_ms: ms(t1, t2),
        })
    }
}

fn encode(
    format: OutputFormat,
    pixels: Pixels,
    w: usize,
    h: usize,
    wy: f64,
    png: PngCompression,
) -> Result<Encoded, PipelineError> {
    use OutputFormat::*;
    Ok(match pixels {
        // 8-bit pixels are rendered for PNG and PPM only
        Pixels::Srgb8(frame) if format == Ppm => Encoded::Framed {
            header: ppm_header(w, h)?,
            frame,
        },
        Pixels::Srgb8(rgb) => Encoded::Whole(encode_png_rgb8(w, h, &rgb, png)?),
        Pixels::Xyz(xyz) => Encoded::Whole(match format {
            Png => encode_png_rgb8(w, h, &xyz_to_srgb8(&xyz, wy), png)?,
            Ppm => encode_ppm_rgb8(w, h, &xyz_to_srgb8(&xyz, wy))?,
            TiffSrgb16 => encode_tiff_rgb16(w, h, &xyz_to_srgb16(&xyz, wy))?,
            TiffXyz => encode_tiff_f32_rgb(w, h, &xyz)?,
            F32 => {
                let mut b = crate::buffers::with_capacity(xyz.len() * 4);
                b.extend(xyz.iter().flat_map(|v| v.to_le_bytes()));
                b
            }
        }),
    })
}

impl FromStr for OutputFormat {
    type Err = PipelineError;

    /// `png`, `ppm`, `tiff` (float XYZ), `tiff-srgb16` or `f32`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "png" => OutputFormat::Png,
            "ppm" => OutputFormat::Ppm,
            "tiff" | "tif" => OutputFormat::TiffXyz,
            "tiff-srgb16" => OutputFormat::TiffSrgb16,
            "f32" | "raw" => OutputFormat::F32,
            other => {
                return Err(PipelineError::Options(format!(
                    "output format '{other}': png, ppm, tiff, tiff-srgb16 or f32"
                )));
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn region_and_preview() {
        let opts = |region: &str, preview| RenderOptions {
            region: Some(parse_region(region).unwrap()),
            preview,
            ..RenderOptions::default()
        };
        assert_eq!(output_size(4, 4, &opts("0,0,2,2", 1)).unwrap(), (2, 2));
        assert!(output_size(4, 4, &opts("3,0,2,2", 1)).is_err());
        assert!(output_size(4, 4, &opts("0,0,0,2", 1)).is_err());
        assert!(output_size(4, 4, &opts("0,0,2,2", 4)).is_err());
        assert!(parse_region("a,b").is_err());
        assert!(parse_region("1,2,3").is_err());
        assert!(check_preview(0).is_err() && check_preview(17).is_err());
        let xyz: Vec<f32> = (0..4 * 2 * 3).map(|v| v as f32).collect();
        let (d, w, h) = downscale(&xyz, 4, 2, 2);
        assert_eq!((w, h), (2, 1));
        // mean of pixels 0,1,4,5 channel 0: (0+3+12+15)/4
        assert_eq!(d[0], 7.5);
    }
}
