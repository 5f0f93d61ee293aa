//! `l3 sfr`: the ISO 12233 slanted-edge SFR of an edge in any PNG, TIFF or PNM image.

use std::path::PathBuf;

use clap::Args;

use super::{CliError, write_file};
use crate::eval::slanted_edge_sfr;
use crate::io::{Limits, Transfer, decode_luminance};
use crate::pipeline::parse_region;

#[derive(Args, Debug)]
pub struct SfrArgs {
    /// The image: PNG, TIFF or PNM, grey or RGB (taken to luminance), 8 or 16 bits or float.
    #[arg(long = "in")]
    pub input: PathBuf,
    /// The region holding one straight edge, slanted 2–10° from an axis: x,y,width,height
    /// (default: the whole image).
    #[arg(long)]
    pub roi: Option<String>,
    /// How the values relate to light: `linear` (default; a linear capture or render) or
    /// `srgb` (an sRGB-encoded image, decoded first).
    #[arg(long, default_value = "linear")]
    pub transfer: String,
    /// Also write the JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(a: &SfrArgs) -> Result<(), CliError> {
    let transfer: Transfer = a.transfer.parse().map_err(CliError::Usage)?;
    let bytes = std::fs::read(&a.input).map_err(|source| CliError::File {
        path: a.input.display().to_string(),
        source,
    })?;
    let y = decode_luminance(&bytes, transfer, &Limits::default())?;
    let roi = match &a.roi {
        None => y,
        Some(s) => {
            let r = parse_region(s).map_err(|e| CliError::Usage(e.to_string()))?;
            let (h, w) = y.dim();
            if r.width == 0 || r.height == 0 || r.x + r.width > w || r.y + r.height > h {
                return Err(CliError::Usage(format!(
                    "roi {s} is not inside the {w}×{h} image"
                )));
            }
            y.slice(ndarray::s![r.y..r.y + r.height, r.x..r.x + r.width])
                .to_owned()
        }
    };
    let sfr = slanted_edge_sfr(roi.view())?;
    let json = serde_json::to_string_pretty(&sfr)?;
    if let Some(out) = &a.out {
        write_file(out, json.as_bytes())?;
    }
    println!("{json}");
    Ok(())
}
