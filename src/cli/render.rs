use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use clap::Args;

use super::{Cli, CliError, iset, write_file};
use crate::io::{
    DecodedMosaic, Limits, PngCompression, encode_png_rgb8, encode_ppm_rgb8, encode_tiff_f32_rgb,
    encode_tiff_rgb16, read_mosaic,
};
use crate::l3::{
    IlluminantRegistry, L3Table, Mosaic, RenderStats, TableKind, WhiteLevel,
    render_reference_under, white_y, xyz_to_srgb8, xyz_to_srgb16,
};
use crate::pipeline::{
    CorrectionMode, OutputFormat, PipelineError, RenderOptions, RenderPipeline, check_preview,
    correction_for, kernels_for, parse_region,
};
use crate::service::{ServiceConfig, ServiceError};

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The L3 table (safetensors). Default: the active table of the service's data
    /// directory (`--data-dir`), as recorded in its database.
    #[arg(long)]
    pub table: Option<PathBuf>,
    /// The service's data directory, whose active table renders when `--table` is not given
    /// (default: the service's, `L3_DATA_DIR` or ./data; its database: `L3_DATABASE_URL`, else
    /// the directory's l3.sqlite).
    #[arg(long, value_name = "DIR")]
    pub data_dir: Option<PathBuf>,
    /// Acquisition illuminant: a registry name (D65, D50, A, F2, F11, Tungsten,
    /// Fluorescent), cct:K, xy:x,y (a chromaticity), or any illuminant spec. Default: the sidecar's `illuminant`, else
    /// a DNG's AsShotNeutral (matched to a colour temperature through the table's sensor),
    /// else D65.
    #[arg(long)]
    pub illuminant: Option<String>,
    /// Input mosaic: .raw (+ .json sidecar), DNG, 16-bit PNG, TIFF or PGM.
    #[arg(long = "in")]
    pub input: PathBuf,
    /// Output: .png (sRGB 8-bit), .ppm (sRGB 8-bit, uncompressed), .tiff (float XYZ), .raw (f32 XYZ).
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
    /// How an SI table's output is taken to D65: `camera` (C, fitted on the table's
    /// colour map and sensor under the light; the service's default too) or
    /// `colorimetric` (the paper's T).
    #[arg(long, default_value = "camera")]
    pub correction: CorrectionMode,
}

/// A mosaic in volts with what its file says about the capture.
pub struct MosaicInput {
    pub volts: Vec<f32>,
    pub width: usize,
    pub height: usize,
    /// The CFA a DNG declares (sidecars are not checked).
    pub dng_cfa: Option<String>,
    /// The sidecar's `illuminant`.
    pub illuminant: Option<String>,
    /// A DNG's AsShotNeutral per channel.
    pub neutral: Option<Vec<(String, f64)>>,
}

impl MosaicInput {
    /// A DNG whose CFA is not `table`'s is refused, naming both.
    pub fn check_dng_cfa(&self, table: &L3Table, path: &std::path::Path) -> Result<(), CliError> {
        let table_cfa = table.meta.cfa.to_string();
        match &self.dng_cfa {
            Some(cfa) if !cfa.eq_ignore_ascii_case(&table_cfa) => Err(CliError::Usage(format!(
                "{}: the DNG's CFA '{cfa}' does not match the table's CFA '{table_cfa}'",
                path.display()
            ))),
            _ => Ok(()),
        }
    }

    /// The light to render this frame under, and where it came from: `named` (the
    /// `--illuminant` flag), else the file's metadata, else an estimate from the pixels
    /// ([`L3Table::frame_illuminant`]).
    pub fn light(
        &self,
        table: &L3Table,
        named: Option<&str>,
        iset: Option<&crate::spectral::IsetData>,
    ) -> Result<(String, &'static str), CliError> {
        if let Some(s) = named {
            return Ok((s.to_string(), "--illuminant"));
        }
        let metadata = crate::l3::FrameMetadata {
            illuminant: self.illuminant.as_deref(),
            neutral: self.neutral.as_deref(),
        };
        let (spec, source) = table.frame_illuminant(
            metadata,
            &crate::l3::Mosaic::Volts(&self.volts),
            self.width,
            self.height,
            iset,
        )?;
        Ok((spec, source.describe()))
    }
}

/// The input mosaic in volts: integer frames are scaled by their sidecar's (or DNG's)
/// black/white levels (default 0/65535) to the table's swing; float frames are taken as
/// volts. With what the file says about the capture.
pub fn load_mosaic(path: &Path, swing: f64) -> Result<MosaicInput, CliError> {
    let loaded = read_mosaic(path, &Limits::default())?;
    let neutral = loaded.dng.as_ref().and_then(|d| d.neutral());
    let dng_cfa = match (&loaded.dng, &loaded.meta) {
        (Some(_), Some(m)) => Some(m.cfa.clone()),
        _ => None,
    };
    let illuminant = match &loaded.dng {
        None => loaded.meta.as_ref().and_then(|m| m.illuminant.clone()),
        Some(_) => None,
    };
    let (volts, width, height) = match loaded.mosaic {
        DecodedMosaic::U16(frame) => {
            let meta = match loaded.meta {
                Some(m) => m,
                None => crate::io::RawMeta::new(frame.width, frame.height, "", 0, 65535, swing),
            };
            let mut m = meta;
            m.voltage_swing = swing;
            (frame.to_volts(&m)?, frame.width, frame.height)
        }
        DecodedMosaic::F32 {
            width,
            height,
            data,
        } => (data, width, height),
    };
    Ok(MosaicInput {
        volts,
        width,
        height,
        dng_cfa,
        illuminant,
        neutral,
    })
}

pub fn run(cli: &Cli, a: &RenderArgs) -> Result<(), CliError> {
    let iset = iset(&cli.iset_dir)?;
    let (table_path, table) = table_of(a)?;
    let white: WhiteLevel = a.white_level.parse()?;
    let input = load_mosaic(&a.input, table.meta.voltage_swing)?;
    input.check_dng_cfa(&table, &a.input)?;
    let (spec, source) = input.light(&table, a.illuminant.as_deref(), iset.as_ref())?;
    let (volts, w, h) = (input.volts, input.width, input.height);
    let mut registry = IlluminantRegistry::with_defaults(table.meta.grid, iset.as_ref())?;
    let entry = correction_for(
        &table,
        &registry.resolve(&spec, iset.as_ref())?,
        a.correction,
        iset.as_ref(),
    )?;
    let illuminant = format!("{} (from {source})", entry.name);
    if table.meta.kind == TableKind::CrossIlluminant && !table.trained_under(&entry.name) {
        eprintln!(
            "warning: cross-illuminant table trained for {} used for {}",
            table.meta.train_illuminants.join("+"),
            entry.name
        );
    }
    let ext = a
        .out
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let format = match ext.as_str() {
        "png" => OutputFormat::Png,
        "ppm" => OutputFormat::Ppm,
        "tif" | "tiff" => match a.tiff.as_str() {
            "xyz" => OutputFormat::TiffXyz,
            "srgb16" => OutputFormat::TiffSrgb16,
            other => {
                return Err(CliError::Usage(format!(
                    "--tiff '{other}': expected xyz or srgb16"
                )));
            }
        },
        "raw" | "bin" | "f32" => OutputFormat::F32,
        _ => {
            return Err(CliError::Usage(format!(
                "--out {}: use .png, .ppm, .tiff or .raw",
                a.out.display()
            )));
        }
    };
    let usage = |e: PipelineError| CliError::Usage(e.to_string());
    let opts = RenderOptions {
        white,
        region: a
            .region
            .as_deref()
            .map(parse_region)
            .transpose()
            .map_err(usage)?,
        preview: check_preview(a.preview).map_err(usage)?,
        png: a.png_compression,
    };
    let started = std::time::Instant::now();
    let frame = Mosaic::Volts(&volts);
    let (bytes, ow, oh, stats) = match a.renderer.as_str() {
        "fast" => {
            let pipeline = RenderPipeline::new(&table, &entry)?;
            let r = pipeline.render(frame, w, h, format, &opts, &AtomicBool::new(false))?;
            (r.output.into_vec(), r.width, r.height, r.stats)
        }
        "reference" => {
            if opts.region.is_some() || opts.preview != 1 {
                return Err(CliError::Usage(
                    "--region and --preview need the fast renderer".into(),
                ));
            }
            let (xyz, stats) = render_reference_under(
                &table,
                &kernels_for(&table, &entry)?,
                entry.neutral.as_deref(),
                &volts,
                w,
                h,
            )?;
            let wy = || white_y(&xyz, w, h, white);
            let bytes = match format {
                OutputFormat::Png => encode_png_rgb8(w, h, &xyz_to_srgb8(&xyz, wy()), opts.png)?,
                OutputFormat::Ppm => encode_ppm_rgb8(w, h, &xyz_to_srgb8(&xyz, wy()))?,
                OutputFormat::TiffXyz => encode_tiff_f32_rgb(w, h, &xyz)?,
                OutputFormat::TiffSrgb16 => encode_tiff_rgb16(w, h, &xyz_to_srgb16(&xyz, wy()))?,
                OutputFormat::F32 => xyz.iter().flat_map(|v| v.to_le_bytes()).collect(),
            };
            (bytes, w, h, stats)
        }
        other => {
            return Err(CliError::Usage(format!(
                "--renderer '{other}': expected fast or reference"
            )));
        }
    };
    let ms = started.elapsed().as_secs_f64() * 1e3;
    write_file(&a.out, &bytes)?;
    report(a, &table_path, &illuminant, ow, oh, ms, &stats);
    Ok(())
}

/// `--table`, else the active table of the service's data directory (the one a service
/// started there renders with: [`crate::service::served_table`]); with none, an error that
/// says how to get or choose one.
fn table_of(a: &RenderArgs) -> Result<(PathBuf, L3Table), CliError> {
    if let Some(t) = &a.table {
        return Ok((t.clone(), L3Table::load(t)?));
    }
    let mut cfg = ServiceConfig::load(None).map_err(|e| CliError::Usage(e.to_string()))?;
    if let Some(d) = &a.data_dir {
        cfg.data.dir = d.clone();
    }
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| ServiceError::Internal(format!("cannot start the async runtime: {e}")))?;
    let served = rt.block_on(crate::service::served_table(&cfg))?;
    let dir = cfg.data.dir.display();
    let Some(served) = served else {
        return Err(CliError::Usage(format!(
            "no --table given and the data directory {dir} has no active table; pass --table FILE: \
             train one with `l3 train --out FILE`, or start `l3 serve --data-dir {dir}` (it trains \
             a default table), or activate a stored one (POST /v1/tables/{{id}}/activate)"
        )));
    };
    for why in &served.passed_over {
        eprintln!("warning: the data directory's table {why}; passed over");
    }
    eprintln!("table: {} (active in {dir})", served.id);
    Ok((served.path, served.table))
}

fn report(
    a: &RenderArgs,
    table: &Path,
    illuminant: &str,
    w: usize,
    h: usize,
    ms: f64,
    stats: &RenderStats,
) {
    println!(
        "rendered {w}×{h} with {} under {illuminant} ({} renderer) in {ms:.1} ms ({:.1} Mpix/s): {} saturated, {} texture pixels, {} classified by the reference code; wrote {}",
        table.display(),
        a.renderer,
        (w * h) as f64 / ms / 1e3,
        stats.saturated,
        stats.texture,
        stats.exact_path,
        a.out.display()
    );
}
