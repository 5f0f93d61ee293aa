//! Rendering a mosaic to encoded output: the fast renderer (straight to 8-bit sRGB where the
//! output allows it, a region, a preview downscale) and the reference renderer, both through
//! the one encoder.

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use super::error::PipelineError;
use super::kernels::{Kernels, kernels_for};
use super::options::{RenderOptions, downscale, output_size};
use super::output::{Encoded, Image, OutputFormat, Pixels, encode};
use crate::l3::L3Table;
use crate::l3::correct::IlluminantEntry;
use crate::l3::render::{ChromaMode, ChromaStage, RenderError};
use crate::l3::render::{FastRenderer, Mosaic, RenderStats, render_reference_under, white_y};

/// The output of a render.
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

/// A table prepared to render under one illuminant: the fast renderer and the chroma stage
/// ([`ChromaStage`]; `None` for a table that names no sensor).
pub struct RenderPipeline {
    renderer: FastRenderer,
    chroma: Option<ChromaStage>,
}

fn ms(a: Instant, b: Instant) -> f64 {
    (b - a).as_secs_f64() * 1e3
}

impl RenderPipeline {
    /// Prepares `table` for `entry` (kernel selection: [`kernels_for`]).
    pub fn new(table: &L3Table, entry: &IlluminantEntry) -> Result<Self, RenderError> {
        let kernels = Kernels {
            xyz: kernels_for(table, entry)?,
            neutral: entry.neutral.clone(),
        };
        Self::prepare(table, &kernels)
    }

    /// Prepares `table` with chosen kernels ([`super::kernels::KernelChoice::kernels`]).
    pub fn prepare(table: &L3Table, kernels: &Kernels) -> Result<Self, RenderError> {
        Ok(Self {
            renderer: FastRenderer::under_light(table, &kernels.xyz, kernels.neutral.as_deref())?,
            chroma: ChromaStage::new(table, &kernels.xyz)?,
        })
    }

    /// Prepares `table` with explicit XYZ kernels.
    pub fn with_kernels(table: &L3Table, kernels: &[f32]) -> Result<Self, RenderError> {
        Ok(Self {
            renderer: FastRenderer::new(table, kernels)?,
            chroma: ChromaStage::new(table, kernels)?,
        })
    }

    /// The chroma stage, when this frame runs it under `mode`.
    fn chroma_for(&self, mode: ChromaMode, mosaic: &Mosaic<'_>) -> Option<&ChromaStage> {
        self.chroma
            .as_ref()
            .filter(|c| c.runs_on(mode, mosaic, self.renderer.voltage_swing()))
    }

    /// Renders `mosaic` (`width × height`, or its `region`) to XYZ, then the chroma stage
    /// when the frame runs it under `mode`: what every XYZ render of a pipeline goes
    /// through (the service, `l3 render`, the evaluations).
    pub fn render_xyz(
        &self,
        mosaic: Mosaic<'_>,
        width: usize,
        height: usize,
        region: Option<crate::l3::render::Region>,
        mode: ChromaMode,
        cancel: &AtomicBool,
    ) -> Result<(Vec<f32>, RenderStats), RenderError> {
        let stage = self.chroma_for(mode, &mosaic);
        let (mut xyz, stats) = self
            .renderer
            .render_xyz_until(mosaic, width, height, region, cancel)?;
        if let Some(c) = stage {
            let (rw, rh) = region.map_or((width, height), |g| (g.width, g.height));
            c.apply_in_place(&mut xyz, rw, rh)?;
        }
        Ok((xyz, stats))
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
    /// rows once `cancel` is set ([`RenderError::RenderCanceled`]).
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
        // at full size when the chroma stage does not run, XYZ otherwise; only the region's
        // pixels
        let chroma = self.chroma_for(opts.chroma, &mosaic).is_some();
        let (pixels, stats, wy) = if format.is_srgb8() && opts.preview == 1 && !chroma {
            let (rgb, wy, stats) =
                r.render_srgb8_until(mosaic, width, height, opts.region, opts.white, cancel)?;
            (Pixels::Srgb8(rgb), stats, wy)
        } else {
            let mode = if chroma {
                ChromaMode::On
            } else {
                ChromaMode::Off
            };
            let (xyz, stats) = self.render_xyz(mosaic, width, height, opts.region, mode, cancel)?;
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
        let image = Image {
            pixels,
            width: ow,
            height: oh,
            white_y: wy,
        };
        let output = encode(format, image, opts.encoding()).map_err(PipelineError::Encode)?;
        Ok(Rendered {
            output,
            width: ow,
            height: oh,
            stats,
            white_y: wy,
            render_ms: ms(t0, t1),
            encode_ms: ms(t1, Instant::now()),
        })
    }
}

/// Renders `volts` (`width × height`) with the reference renderer, the whole frame
/// ([`PipelineError::WholeFrameOnly`] for a region or preview), to `format`.
pub fn render_reference(
    table: &L3Table,
    kernels: &Kernels,
    volts: &[f32],
    (width, height): (usize, usize),
    format: OutputFormat,
    opts: &RenderOptions,
) -> Result<Rendered, PipelineError> {
    if !opts.whole_frame() {
        return Err(PipelineError::WholeFrameOnly);
    }
    let t0 = Instant::now();
    let (mut xyz, stats) = render_reference_under(
        table,
        &kernels.xyz,
        kernels.neutral.as_deref(),
        volts,
        width,
        height,
    )?;
    let stage = ChromaStage::new(table, &kernels.xyz)?;
    let swing = table.meta.voltage_swing as f32;
    if let Some(c) = stage.filter(|c| c.runs_on(opts.chroma, &Mosaic::Volts(volts), swing)) {
        c.apply_in_place(&mut xyz, width, height)?;
    }
    let wy = if format.needs_white() {
        white_y(&xyz, width, height, opts.white)
    } else {
        1.0
    };
    let t1 = Instant::now();
    let image = Image {
        pixels: Pixels::Xyz(xyz),
        width,
        height,
        white_y: wy,
    };
    let output = encode(format, image, opts.encoding()).map_err(PipelineError::Encode)?;
    Ok(Rendered {
        output,
        width,
        height,
        stats,
        white_y: wy,
        render_ms: ms(t0, t1),
        encode_ms: ms(t1, Instant::now()),
    })
}
