//! `l3 render`: a mosaic file through the core's render request ([`crate::pipeline`]) to an
//! image file.

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use clap::Args;

use super::sensors::{block_on, data_config};
use super::{Cli, CliError, iset, write_file};
use crate::io::{
    JpegOptions, JpegQuality, Limits, LoadedMosaic, PngCompression, Subsampling, read_mosaic,
};
use crate::l3::L3Table;
use crate::l3::correct::{IlluminantEntry, IlluminantRegistry};
use crate::l3::render::{ChromaMode, WhiteLevel};
use crate::l3::table::TableKind;
use crate::pipeline::{
    CorrectionMode, DecodedFrame, FrameNotes, Input, Levels, LightChoice, LightOrigin,
    OutputFormat, PipelineError, RenderContext, RenderOptions, RenderOutcome, RenderRequest,
    Renderer, StoredTables, TableChoice, check_preview, choose_table, decode, parse_region,
};
use crate::spectral::IsetData;

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The L3 table (safetensors). Default: the active table of the service's data
    /// directory (`--data-dir`), as recorded in its database.
    #[arg(long)]
    pub table: Option<PathBuf>,
    /// The service's data directory, whose tables render when `--table` is not given: the one
    /// `--table-id` names, else the newest trained for the catalogue sensor of a DNG's camera
    /// (UniqueCameraModel, else Make and Model), else the active table (default: the service's
    /// directory, `L3_DATA_DIR` or ./data; its database: `L3_DATABASE_URL`, else the
    /// directory's l3.sqlite).
    #[arg(long, value_name = "DIR")]
    pub data_dir: Option<PathBuf>,
    /// A stored table of the data directory to render with, by id (as `?table=` does).
    #[arg(long, value_name = "ID", conflicts_with = "table")]
    pub table_id: Option<String>,
    /// Acquisition illuminant: a registry name (D65, D50, A, F2, F11, Tungsten,
    /// Fluorescent), cct:K, xy:x,y (a chromaticity), or any illuminant spec. Default: the
    /// sidecar's `illuminant`, else a DNG's AsShotNeutral (matched to a colour temperature
    /// through the table's sensor) or AsShotWhiteXY (as xy:x,y), else an estimate from the
    /// frame's pixels, else (too little unclipped signal to estimate) D65.
    #[arg(long)]
    pub illuminant: Option<String>,
    /// Input mosaic: .raw (+ .json sidecar), DNG, 16-bit PNG, TIFF or PGM.
    #[arg(long = "in")]
    pub input: PathBuf,
    /// Output: .png (sRGB 8-bit), .jpg/.jpeg (sRGB 8-bit, ICC-tagged), .ppm (sRGB 8-bit,
    /// uncompressed), .tiff (float XYZ), .raw (f32 XYZ).
    #[arg(long)]
    pub out: PathBuf,
    /// `auto` or the Y that maps to white.
    #[arg(long, default_value = "auto")]
    pub white_level: String,
    /// For .tiff output: `xyz` (float) or `srgb16`.
    #[arg(long, default_value = "xyz")]
    pub tiff: String,
    /// Render only this crop of the frame: `x,y,width,height` (fast renderer).
    #[arg(long)]
    pub region: Option<String>,
    /// Integer box-average downscale of the output, 1–16 (fast renderer).
    #[arg(long, default_value_t = 1)]
    pub preview: usize,
    /// `fast` (tiled, SIMD) or `reference` (the simple per-pixel renderer the fast one is
    /// tested against). Both put every pixel in the same class.
    #[arg(long, default_value = "fast")]
    pub renderer: String,
    /// PNG compression: `fast`, `default` or `best`. The service's default (config
    /// `png_compression`) is the same, so both write the same PNG bytes.
    #[arg(long, default_value_t = RenderOptions::default().png)]
    pub png_compression: PngCompression,
    /// JPEG quality, 1–100 (for .jpg; the service's `quality` has the same default).
    #[arg(long, default_value_t = JpegQuality::default())]
    pub quality: JpegQuality,
    /// JPEG chroma subsampling: `420`, `422` or `444` (for .jpg; as the service's
    /// `subsampling`).
    #[arg(long, default_value_t = Subsampling::default())]
    pub subsampling: Subsampling,
    /// How an SI table's output is taken to D65: `camera` (C, fitted on the table's
    /// colour map and sensor under the light; the service's default too) or
    /// `colorimetric` (the paper's T).
    #[arg(long, default_value = "camera")]
    pub correction: CorrectionMode,
    /// The chroma stage at low light: `auto` (when the frame's chroma noise needs it), `on`
    /// or `off` (as the service's `chroma_denoise`; docs/accuracy.md).
    #[arg(long, default_value_t = ChromaMode::default())]
    pub chroma_denoise: ChromaMode,
    /// Largest frame read (width × height, stored pixels of a DNG); the default takes every
    /// catalogue camera (the largest, the Fujifilm GFX 100, stores 102 MP).
    #[arg(long, value_name = "PIXELS", default_value_t = Limits::default().max_pixels)]
    pub max_pixels: usize,
}

/// A failure of `l3 render`: the pipeline's (shown with the input's path where it is about
/// the input) or the command's own.
enum Failure {
    Pipeline(PipelineError),
    Cli(CliError),
}

impl From<PipelineError> for Failure {
    fn from(e: PipelineError) -> Self {
        Failure::Pipeline(e)
    }
}

/// The CLI's error for a pipeline error about the input file `path`.
pub(crate) fn input_error(e: PipelineError, path: &Path) -> CliError {
    match e {
        PipelineError::CfaMismatch { .. } => CliError::Usage(format!("{}: {e}", path.display())),
        e => e.into(),
    }
}

/// `l3 render`'s side of a render: its table, lights from a registry of the built-in
/// illuminants (which takes files and ISET lights too), renderers prepared afresh.
struct CliRender<'a> {
    table: &'a L3Table,
    iset: Option<&'a IsetData>,
    registry: RefCell<IlluminantRegistry>,
}

impl RenderContext for CliRender<'_> {
    type Error = Failure;

    fn table(&self) -> &L3Table {
        self.table
    }

    fn iset(&self) -> Option<&IsetData> {
        self.iset
    }

    /// The light `spec` names; a cross-illuminant table not trained under it is warned of.
    fn light(&self, spec: &str) -> Result<IlluminantEntry, Failure> {
        let entry = self
            .registry
            .borrow_mut()
            .resolve(spec, self.iset)
            .map_err(|e| Failure::Cli(e.into()))?;
        let table = self.table;
        if table.meta.kind == TableKind::CrossIlluminant
            && !table.trained_under_light(&entry.name, entry.white_xy)
        {
            eprintln!(
                "warning: cross-illuminant table trained for {} used for {}",
                table.meta.train_illuminants.join("+"),
                entry.name
            );
        }
        Ok(entry)
    }
}

/// Where a light came from, as `l3 render` and `l3 eval --frame` say it.
pub(crate) fn light_source(origin: LightOrigin) -> &'static str {
    match origin {
        LightOrigin::Named => "--illuminant",
        LightOrigin::Frame(source) => source.describe(),
    }
}

/// The mosaic file `path` decoded for `table` (a DNG's CFA checked), with the light
/// to render it under: `named`, else the file's metadata, else an estimate from its pixels.
pub(crate) fn frame_and_light(
    path: &Path,
    table: &L3Table,
    named: Option<&str>,
    iset: Option<&IsetData>,
) -> Result<(DecodedFrame, String, &'static str), CliError> {
    let limits = Limits::default();
    let input = Input::Decoded(Box::new(read_mosaic(path, &limits)?));
    let frame =
        decode(input, Levels::default(), table, &limits).map_err(|e| input_error(e, path))?;
    warn_of(&frame.notes, path);
    let (spec, origin) = match named {
        Some(s) => (s.to_string(), LightOrigin::Named),
        None => {
            let (spec, source) = frame.light(table, iset)?;
            (spec, LightOrigin::Frame(source))
        }
    };
    Ok((frame, spec, light_source(origin)))
}

/// The render `a` asks for of `loaded`: the output format by the file's extension (and
/// `--tiff`), white, region, preview, PNG compression, renderer, light and correction.
fn render_request(
    a: &RenderArgs,
    white: WhiteLevel,
    loaded: LoadedMosaic,
) -> Result<RenderRequest, CliError> {
    let ext = a.out.extension().and_then(|e| e.to_str()).unwrap_or("");
    let format = match OutputFormat::from_extension(ext) {
        Some(OutputFormat::Tiff(_)) => OutputFormat::Tiff(
            a.tiff
                .parse()
                .map_err(|e| CliError::Usage(format!("--tiff {e}")))?,
        ),
        Some(format) => format,
        None => {
            return Err(CliError::Usage(format!(
                "--out {}: use .png, .jpg, .ppm, .tiff or .raw",
                a.out.display()
            )));
        }
    };
    let usage = |e: PipelineError| CliError::Usage(e.to_string());
    let options = RenderOptions {
        white,
        region: a
            .region
            .as_deref()
            .map(parse_region)
            .transpose()
            .map_err(usage)?,
        preview: check_preview(a.preview).map_err(usage)?,
        png: a.png_compression,
        jpeg: JpegOptions {
            quality: a.quality,
            subsampling: a.subsampling,
        },
        chroma: a.chroma_denoise,
    };
    let renderer = match a.renderer.as_str() {
        "fast" => Renderer::Fast,
        "reference" => Renderer::Reference,
        other => {
            return Err(CliError::Usage(format!(
                "--renderer '{other}': expected fast or reference"
            )));
        }
    };
    Ok(RenderRequest {
        input: Input::Decoded(Box::new(loaded)),
        levels: Levels::default(),
        cfa: None,
        light: a
            .illuminant
            .clone()
            .map_or(LightChoice::FromFrame, LightChoice::Named),
        correction: a.correction,
        options,
        format,
        renderer,
        limits: Limits::with_max_pixels(a.max_pixels),
    })
}

pub fn run(cli: &Cli, a: &RenderArgs) -> Result<(), CliError> {
    let iset = iset(&cli.iset_dir)?;
    // a table file is read before the input, a data directory's table chosen after it
    let given = match &a.table {
        Some(t) => Some((t.clone(), L3Table::load(t)?)),
        None => None,
    };
    let white: WhiteLevel = a.white_level.parse().map_err(CliError::argument)?;
    let loaded = read_mosaic(&a.input, &Limits::with_max_pixels(a.max_pixels))?;
    let request = render_request(a, white, loaded)?;
    let (table_path, table) = match given {
        Some(t) => t,
        None => table_of(a, &request.input)?,
    };
    let out = run_request(request, &table, iset.as_ref(), &a.input)?;
    let summary = summary(a, &table_path, &out);
    write_file(&a.out, &out.rendered.output.into_vec())?;
    println!("{summary}");
    Ok(())
}

/// `warning:` lines for what a render of `input` left undone or moved, and for a frame that
/// names another sensor than the table's.
pub(crate) fn warn_of(notes: &FrameNotes, input: &Path) {
    if !notes.skipped_opcodes.is_empty() {
        eprintln!(
            "warning: {}: DNG opcodes not applied: {}",
            input.display(),
            notes.skipped_opcodes.join(", ")
        );
    }
    if let Some(shift) = &notes.cfa_shift {
        eprintln!("warning: {}: {}", input.display(), shift.describe());
    }
    if let Some(m) = &notes.sensor_mismatch {
        eprintln!("warning: {}: {m}", input.display());
    }
}

/// Runs `request` with `table`, lights from a registry of the built-in illuminants (and
/// `iset`'s); errors about the input name `input`, and what the frame's notes report
/// ([`warn_of`]) is printed as warnings.
fn run_request(
    request: RenderRequest,
    table: &L3Table,
    iset: Option<&IsetData>,
    input: &Path,
) -> Result<RenderOutcome, CliError> {
    let ctx = CliRender {
        table,
        iset,
        registry: RefCell::new(IlluminantRegistry::with_defaults(table.meta.grid, iset)?),
    };
    // the cheap checks first: there the context's only errors are the named light's
    // (`--illuminant`'s), later they are the light the frame gives
    let prepared = request.prepare(&ctx).map_err(|f| match f {
        Failure::Pipeline(e) => input_error(e, input),
        Failure::Cli(e) => CliError::argument(e),
    })?;
    let out = prepared
        .run(&ctx, &AtomicBool::new(false))
        .map_err(|f| match f {
            Failure::Pipeline(e) => input_error(e, input),
            Failure::Cli(e) => e,
        })?;
    warn_of(&out.notes, input);
    Ok(out)
}

/// The mosaic file `path` rendered as `l3 render --table … --out frame.raw` renders it: float
/// XYZ referred to D65, under the light `named` (else the file's metadata, else an estimate,
/// else D65) with `correction`.
pub(crate) fn render_file_xyz(
    table: &L3Table,
    path: &Path,
    named: Option<&str>,
    correction: CorrectionMode,
    iset: Option<&IsetData>,
) -> Result<RenderOutcome, CliError> {
    let loaded = read_mosaic(path, &Limits::default())?;
    let request = RenderRequest {
        input: Input::Decoded(Box::new(loaded)),
        levels: Levels::default(),
        cfa: None,
        light: named.map_or(LightChoice::FromFrame, |s| LightChoice::Named(s.into())),
        correction,
        options: RenderOptions::default(),
        format: OutputFormat::F32,
        renderer: Renderer::Fast,
        limits: Limits::default(),
    };
    run_request(request, table, iset, path)
}

/// Without `--table`: a table of the service's data directory chosen as the service chooses
/// ([`choose_table`]): `--table-id`, else the newest good table trained for the catalogue
/// sensor of the DNG's camera, else the active table (the one a service started there renders
/// with: [`crate::service::served_table`]). With none, an error that says how to get or
/// choose one.
fn table_of(a: &RenderArgs, input: &Input) -> Result<(PathBuf, L3Table), CliError> {
    let cfg = data_config(&a.data_dir)?;
    let camera = if a.table_id.is_none() {
        input.camera()
    } else {
        None
    };
    let stored = match &camera {
        Some(_) => block_on(crate::service::stored_tables_in(&cfg))??,
        None => StoredTables::default(),
    };
    let choice = choose_table(a.table_id.as_deref(), camera.as_ref(), &stored)
        .map_err(|e| input_error(e, &a.input))?;
    let dir = cfg.data.dir.display();
    let served = match choice.table_id() {
        Some(id) => block_on(crate::service::stored_table_in(&cfg, id))??,
        None => block_on(crate::service::served_table(&cfg))??.ok_or_else(|| {
            CliError::NoTable(format!(
                "no --table given and the data directory {dir} has no active table; pass --table FILE: \
                 train one with `l3 train --out FILE`, or start `l3 serve --data-dir {dir}` (it trains \
                 a default table), or activate a stored one (POST /v1/tables/{{id}}/activate)"
            ))
        })?,
    };
    for why in &served.passed_over {
        eprintln!("warning: the data directory's table {why}; passed over");
    }
    let why = match &choice {
        TableChoice::Active => format!("active in {dir}"),
        TableChoice::Named(_) => format!("--table-id, in {dir}"),
        TableChoice::Camera { sensor, camera, .. } => format!(
            "in {dir}, trained for {sensor}, the sensor of the file's camera {} {}",
            camera.make, camera.model
        ),
    };
    eprintln!("table: {} ({why})", served.id);
    Ok((served.path, served.table))
}

/// What `l3 render` says of a render: sizes, table, light, time (kernels, render and
/// encoding), class counts, the file written.
fn summary(a: &RenderArgs, table: &Path, out: &RenderOutcome) -> String {
    let r = &out.rendered;
    let (w, h) = (r.width, r.height);
    let ms = out.kernels_ms + r.render_ms + r.encode_ms;
    format!(
        "rendered {w}×{h} with {} under {} (from {}) ({} renderer) in {ms:.1} ms ({:.1} Mpix/s): {} saturated, {} texture pixels, {} classified by the reference code; wrote {}",
        table.display(),
        out.light,
        light_source(out.light_origin),
        a.renderer,
        (w * h) as f64 / ms / 1e3,
        r.stats.saturated,
        r.stats.texture,
        r.stats.exact_path,
        a.out.display()
    )
}
