//! One render request, end to end: what `l3 render` and the service's `POST /v1/render` both
//! run (the evaluation and the benchmark share its kernel selection and renderer).
//!
//! A [`RenderRequest`] (input bytes with their declared format, or a decoded mosaic; the
//! light; the correction; region, preview and white; the output format) goes
//! decode → DNG levels → CFA check → light → kernels → render → encode, and comes back as a
//! [`RenderOutcome`]: the encoded bytes and what the answer reports (the light and where it
//! came from, sizes, timings, class statistics).
//!
//! - [`input`] — decoding, levels, a DNG's CFA, what the file says about the light;
//! - [`kernels`] — kernel selection, and the [`KernelKey`] a cache of prepared renderers keys on;
//! - [`options`] — white, region (`x,y,width,height`), preview downscale (1–16);
//! - [`render`] — the fast renderer (straight to 8-bit sRGB where the output allows it) and the
//!   reference renderer;
//! - [`output`] — the output formats (PNG, PPM, float XYZ or 16-bit sRGB TIFF, raw f32 XYZ) and
//!   their one encoder;
//! - [`choice`] — which table renders: the named one, the camera's, or the default;
//! - [`error`] — [`PipelineError`].
//!
//! The caller supplies a [`RenderContext`]: the table, how a light's name resolves, and where
//! prepared renderers come from (the service caches them by [`KernelKey`]).

pub mod choice;
pub mod error;
pub mod fit;
pub mod input;
pub mod kernels;
pub mod options;
pub mod output;
pub mod render;

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

pub use choice::{StoredTables, TableChoice, choose_table};
pub use error::{CfaOrigin, PipelineError};
pub use fit::{SensorMismatch, check_cfa, check_declared_cfa, design_fit};
pub use input::{CfaShift, DecodedFrame, FrameNotes, Input, Levels, Samples, cfa_phase, decode};
pub use kernels::{
    CorrectionMode, KernelChoice, KernelKey, KernelSource, Kernels, correction_for, kernels_for,
    uses_own_kernels,
};
pub use options::{
    MAX_PREVIEW, RenderOptions, check_preview, downscale, output_size, parse_region,
};
pub use output::{
    Encoded, Encoding, Image, OutputFormat, Pixels, TiffKind, UnknownTiffKind, encode,
};
pub use render::{RenderPipeline, Rendered, render_reference};

use crate::io::Limits;
use crate::l3::L3Table;
use crate::l3::correct::{IlluminantEntry, IlluminantSource};
use crate::spectral::IsetData;

/// The light a request asks for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LightChoice {
    /// An illuminant spec: a registry name, `cct:K`, `xy:x,y`…
    Named(String),
    /// The file's metadata (a sidecar's illuminant, a DNG's AsShotNeutral), else an estimate
    /// from the pixels, else D65 ([`L3Table::frame_illuminant`]).
    FromFrame,
}

/// Where the light of a render came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LightOrigin {
    /// The request named it.
    Named,
    /// The frame gave it.
    Frame(IlluminantSource),
}

/// Which renderer renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Renderer {
    /// The tiled SIMD renderer.
    #[default]
    Fast,
    /// The simple per-pixel renderer the fast one is tested against (whole frames only).
    Reference,
}

/// One render, as a caller asks for it.
pub struct RenderRequest {
    pub input: Input,
    /// DN levels over the file's.
    pub levels: Levels,
    /// The input's CFA as the request declares it (checked against the table's).
    pub cfa: Option<String>,
    pub light: LightChoice,
    pub correction: CorrectionMode,
    pub options: RenderOptions,
    pub format: OutputFormat,
    pub renderer: Renderer,
    /// Limits of the decoders.
    pub limits: Limits,
}

/// What a render needs from its caller. Its own failures (a light that does not resolve, a
/// renderer that cannot be prepared) are in its error type, which takes the pipeline's.
pub trait RenderContext {
    type Error: From<PipelineError>;

    /// The table that renders.
    fn table(&self) -> &L3Table;

    /// The ISET data over the built-in spectral data, if any.
    fn iset(&self) -> Option<&IsetData>;

    /// The light an illuminant spec names.
    fn light(&self, spec: &str) -> Result<IlluminantEntry, Self::Error>;

    /// The fast renderer prepared for `choice` (the service takes it from its cache, keyed by
    /// [`KernelChoice::key`]).
    fn renderer(&self, choice: &KernelChoice<'_>) -> Result<Arc<RenderPipeline>, Self::Error> {
        let kernels = choice.kernels(self.iset())?;
        let pipeline =
            RenderPipeline::prepare(choice.table(), &kernels).map_err(PipelineError::Kernels)?;
        Ok(Arc::new(pipeline))
    }
}

/// A render and what its answer reports.
pub struct RenderOutcome {
    /// The encoded output, its size, class statistics, white, render and encode times.
    pub rendered: Rendered,
    /// The light's name.
    pub light: String,
    pub light_origin: LightOrigin,
    /// The correction applied: the request's mode, except that a light given only as a
    /// matrix (no spectrum, so no camera-aware C) is corrected colorimetrically (its T);
    /// `None` for a cross-illuminant table, whose own kernels render to D65 under any light.
    pub correction: Option<CorrectionMode>,
    /// The input frame's size.
    pub input_width: usize,
    pub input_height: usize,
    /// Decoding, levels and the light.
    pub decode_ms: f64,
    /// The kernels: the correction fitted, fused, the renderer prepared (or found cached).
    pub kernels_ms: f64,
    /// DNG opcodes left unapplied, a crop moved to the table's CFA phase.
    pub notes: FrameNotes,
}

/// A request whose cheap checks passed: [`RenderRequest::prepare`].
pub struct Prepared {
    request: RenderRequest,
    named: Option<IlluminantEntry>,
}

impl RenderRequest {
    /// The checks that need no decoding, in order: the declared CFA against the table's, the
    /// named light resolved, a reference render asked for the whole frame.
    pub fn prepare<C: RenderContext>(self, ctx: &C) -> Result<Prepared, C::Error> {
        if let Some(cfa) = &self.cfa {
            check_declared_cfa(cfa, &ctx.table().meta.cfa)?;
        }
        let named = match &self.light {
            LightChoice::Named(spec) => Some(ctx.light(spec)?),
            LightChoice::FromFrame => None,
        };
        if self.renderer == Renderer::Reference && !self.options.whole_frame() {
            return Err(PipelineError::WholeFrameOnly.into());
        }
        Ok(Prepared {
            request: self,
            named,
        })
    }

    /// [`Self::prepare`], then [`Prepared::run`].
    pub fn run<C: RenderContext>(
        self,
        ctx: &C,
        cancel: &AtomicBool,
    ) -> Result<RenderOutcome, C::Error> {
        self.prepare(ctx)?.run(ctx, cancel)
    }
}

fn ms(from: Instant, to: Instant) -> f64 {
    (to - from).as_secs_f64() * 1e3
}

impl Prepared {
    /// Decodes, takes the light, prepares the kernels, renders and encodes. The fast renderer
    /// stops between bands of rows once `cancel` is set.
    pub fn run<C: RenderContext>(
        self,
        ctx: &C,
        cancel: &AtomicBool,
    ) -> Result<RenderOutcome, C::Error> {
        let Prepared { request: r, named } = self;
        let table = ctx.table();
        let t0 = Instant::now();
        let frame = decode(r.input, r.levels, table, &r.limits)?;
        let (entry, light_origin) = match named {
            Some(entry) => (entry, LightOrigin::Named),
            None => {
                let (spec, source) = frame.light(table, ctx.iset())?;
                (ctx.light(&spec)?, LightOrigin::Frame(source))
            }
        };
        let (width, height) = (frame.width, frame.height);
        let notes = frame.notes.clone();
        let t1 = Instant::now();
        let choice = KernelChoice::new(table, &entry, r.correction);
        let correction = match r.correction {
            _ if uses_own_kernels(table) => None,
            CorrectionMode::Camera if entry.spd.is_none() => Some(CorrectionMode::Colorimetric),
            mode => Some(mode),
        };
        let (rendered, t2) = match r.renderer {
            Renderer::Fast => {
                let pipeline = ctx.renderer(&choice)?;
                let t2 = Instant::now();
                let mosaic = frame.mosaic();
                let out = pipeline.render(mosaic, width, height, r.format, &r.options, cancel)?;
                (out, t2)
            }
            Renderer::Reference => {
                let kernels = choice.kernels(ctx.iset())?;
                let t2 = Instant::now();
                let volts = frame.into_volts(table.meta.voltage_swing)?;
                let size = (width, height);
                let out = render_reference(table, &kernels, &volts, size, r.format, &r.options)?;
                (out, t2)
            }
        };
        Ok(RenderOutcome {
            rendered,
            light: entry.name,
            light_origin,
            correction,
            input_width: width,
            input_height: height,
            decode_ms: ms(t0, t1),
            kernels_ms: ms(t1, t2),
            notes,
        })
    }
}
