//! `l3 eval --scielab IDEAL RENDERED`: S-CIELAB ([`crate::eval::scielab`]) between two float
//! XYZ TIFFs (D65, white Y = 1), printed and written as JSON, optionally with the ΔE map.

use std::path::{Path, PathBuf};

use super::{CliError, write_file};
use crate::eval::{Border, DeltaEFormula, FilterSet, ScielabOptions, ViewingCondition, scielab};
use crate::io::{Limits, read_tiff_f32_rgb, write_tiff_gray_f32};

/// What `l3 eval --scielab` was asked (its flags).
pub struct ScielabArgs<'a> {
    pub ideal: &'a Path,
    pub rendered: &'a Path,
    pub samples_per_degree: Option<f64>,
    pub delta_e: DeltaEFormula,
    pub filters: FilterSet,
    pub border: Border,
    pub map: Option<&'a PathBuf>,
    pub out: &'a Path,
}

impl ScielabArgs<'_> {
    fn options(&self) -> ScielabOptions {
        let mut o = ScielabOptions {
            formula: self.delta_e,
            filters: self.filters,
            border: self.border,
            ..ScielabOptions::default()
        };
        if let Some(spd) = self.samples_per_degree {
            o.viewing = ViewingCondition {
                samples_per_degree: spd,
            };
        }
        o
    }
}

pub fn run(a: &ScielabArgs) -> Result<(), CliError> {
    let opts = a.options();
    let limits = Limits::default();
    let (w, h, ideal) = read_tiff_f32_rgb(a.ideal, &limits)?;
    let (w2, h2, rendered) = read_tiff_f32_rgb(a.rendered, &limits)?;
    if (w, h) != (w2, h2) {
        return Err(CliError::Usage(format!(
            "{} is {w}×{h} but {} is {w2}×{h2}",
            a.ideal.display(),
            a.rendered.display()
        )));
    }
    let mut s = scielab(&ideal, &rendered, w, h, &opts, a.map.is_some())
        .map_err(|e| CliError::Usage(e.to_string()))?;
    // the per-pixel map goes to its TIFF only, not into the printed and written JSON
    if let (Some(path), Some(map)) = (a.map, s.map.take()) {
        let map: Vec<f32> = map.iter().map(|&v| v as f32).collect();
        write_tiff_gray_f32(path, w, h, &map)?;
    }
    let json = serde_json::to_string_pretty(&s)?;
    let out = if a.out.extension().is_some() {
        a.out.to_path_buf()
    } else {
        a.out.join("scielab.json")
    };
    write_file(&out, json.as_bytes())?;
    println!("{json}");
    Ok(())
}
