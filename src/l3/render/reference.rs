//! Rendering: classify every pixel and apply its class kernel (the reference
//! renderer: simple, parallel over rows, f32).

use rayon::prelude::*;
use serde::Serialize;

use super::error::RenderError;
use crate::l3::classify::{PatchGeometry, sat_case_index};
use crate::l3::correct::{IDENTITY, IlluminantEntry};
use crate::l3::table::L3Table;

/// Counts of what the renderer did, for response headers and tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct RenderStats {
    pub pixels: u64,
    /// Pixels in a saturation case other than "none".
    pub saturated: u64,
    /// Pixels whose saturation case had no kernels and fell back.
    pub fallback: u64,
    /// Pixels classed as texture.
    pub texture: u64,
    /// Input values clamped into [0, swing].
    pub clamped: u64,
    /// Pixels the fast renderer classified with the reference code (a saturated
    /// value in the patch, a value near a class boundary, or a CFA other than 2×2).
    pub exact_path: u64,
}

impl std::ops::AddAssign for RenderStats {
    fn add_assign(&mut self, o: Self) {
        self.pixels += o.pixels;
        self.saturated += o.saturated;
        self.fallback += o.fallback;
        self.texture += o.texture;
        self.clamped += o.clamped;
        self.exact_path += o.exact_path;
    }
}

/// Kernels with a 3×3 matrix applied after them: K' = M·K for every class.
/// Rendering with fused kernels equals rendering and then applying M.
pub fn fuse_kernels(table: &L3Table, m: &[[f64; 3]; 3]) -> Vec<f32> {
    if *m == IDENTITY {
        // D65: the table as is
        return table.kernels.clone();
    }
    fuse_matrix(&table.kernels, m, table.n_features())
}

/// The kernels `table` renders with under `entry`: each class's kernel times its
/// band's correction when the entry has one per band (per level, split by chroma
/// class where the table has them), else times `entry.t`: the table's own kernels, or,
/// for a same-illuminant table under a light it was not trained on, its
/// [transfer kernels](L3Table::transfer_kernels).
pub fn fuse_entry(table: &L3Table, entry: &IlluminantEntry) -> Result<Vec<f32>, RenderError> {
    let nl = table.n_bands();
    if entry.level_corrections.len() != nl || nl == 0 {
        if table.transfers_to_light(&entry.name, entry.white_xy)
            && let Some(k) = table.transfer_kernels()?
        {
            return Ok(fuse_matrix(&k, &entry.t, table.n_features()));
        }
        return Ok(fuse_kernels(table, &entry.t));
    }
    let nf = table.n_features();
    let mut out = Vec::with_capacity(table.kernels.len());
    for (class, k) in table.kernels.chunks_exact(3 * nf).enumerate() {
        out.extend(fuse_matrix(
            k,
            &entry.level_corrections[table.class_band(class)],
            nf,
        ));
    }
    Ok(out)
}

/// `M·K` for every class's 3 output rows of `n_features` weights (f64 sums).
pub(crate) fn fuse_matrix(kernels: &[f32], m: &[[f64; 3]; 3], nf: usize) -> Vec<f32> {
    let mut out = vec![0f32; kernels.len()];
    for (src, dst) in kernels
        .chunks_exact(3 * nf)
        .zip(out.chunks_exact_mut(3 * nf))
    {
        for i in 0..3 {
            for j in 0..nf {
                let v: f64 = (0..3).map(|k| m[i][k] * f64::from(src[k * nf + j])).sum();
                dst[i * nf + j] = v as f32;
            }
        }
    }
    out
}

/// Which saturation case index a patch uses (see [`sat_case_index`]).
pub fn resolve_sat_case(table: &L3Table, mask: u32, means: &[f32]) -> (usize, bool) {
    sat_case_index(&table.meta.sat_cases, mask, means)
}

/// Render a mosaic in volts (`width × height`, row-major) to interleaved XYZ
/// with `kernels` (the table's own or fused ones), any chroma classes under
/// their reference light. Non-finite input is an error; values outside
/// [0, swing] are clamped and counted.
pub fn render_reference(
    table: &L3Table,
    kernels: &[f32],
    volts: &[f32],
    width: usize,
    height: usize,
) -> Result<(Vec<f32>, RenderStats), RenderError> {
    render_reference_under(table, kernels, None, volts, width, height)
}

/// [`render_reference`] with the chroma classes balanced by `light`, the
/// neutral (channel responses to white) of the light the mosaic is taken
/// under; `None`, the classes' reference light.
pub fn render_reference_under(
    table: &L3Table,
    kernels: &[f32],
    light: Option<&[f64]>,
    volts: &[f32],
    width: usize,
    height: usize,
) -> Result<(Vec<f32>, RenderStats), RenderError> {
    if width == 0 || height == 0 {
        return Err(RenderError::InvalidInput(format!(
            "frame is {width}×{height}"
        )));
    }
    if volts.len() != width * height {
        return Err(RenderError::InvalidInput(format!(
            "{} values for a {width}×{height} frame ({} expected)",
            volts.len(),
            width * height
        )));
    }
    if kernels.len() != table.kernels.len() {
        return Err(RenderError::KernelMismatch {
            got: kernels.len(),
            expected: table.kernels.len(),
        });
    }
    if let Some(i) = volts.iter().position(|v| !v.is_finite()) {
        return Err(RenderError::InvalidInput(format!(
            "input value at row {}, column {} is not finite",
            i / width,
            i % width
        )));
    }
    let swing = table.meta.voltage_swing as f32;
    let mut clamped = 0u64;
    let input: Vec<f32> = volts
        .iter()
        .map(|&v| {
            if (0.0..=swing).contains(&v) {
                v
            } else {
                clamped += 1;
                v.clamp(0.0, swing)
            }
        })
        .collect();
    let geo = table.geometry_under(light)?;
    let frame = RowSource {
        table,
        geo: &geo,
        kernels,
        img: &input,
        width,
        height,
    };
    let mut out = vec![0f32; width * height * 3];
    let stats = out
        .par_chunks_mut(width * 3)
        .enumerate()
        .map(|(r, row)| render_row(&frame, r, row))
        .reduce(RenderStats::default, |mut a, b| {
            a += b;
            a
        });
    let mut stats = stats;
    stats.clamped = clamped;
    Ok((out, stats))
}

/// Dot product with 8 independent partial sums (vectorises; a plain
/// `iter().sum()` of f32 must keep its sequential order and cannot).
#[inline]
pub(crate) fn dot(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let mut acc = [0f32; 8];
    let full = n / 8 * 8;
    for (ca, cb) in a[..full].chunks_exact(8).zip(b[..full].chunks_exact(8)) {
        for l in 0..8 {
            acc[l] += ca[l] * cb[l];
        }
    }
    let mut s = (acc[0] + acc[4]) + (acc[1] + acc[5]) + (acc[2] + acc[6]) + (acc[3] + acc[7]);
    for i in full..n {
        s += a[i] * b[i];
    }
    s
}

/// What every row of a reference render reads: the table, its geometry under the light,
/// the kernels and the clamped input frame (`width × height` volts).
struct RowSource<'a> {
    table: &'a L3Table,
    geo: &'a PatchGeometry,
    kernels: &'a [f32],
    img: &'a [f32],
    width: usize,
    height: usize,
}

/// Render row `r` of `src` into `row` (interleaved XYZ).
fn render_row(src: &RowSource, r: usize, row: &mut [f32]) -> RenderStats {
    let RowSource {
        table,
        geo,
        kernels,
        img,
        width,
        height,
    } = *src;
    let nf = geo.n_features();
    let np = nf - 1;
    let mut patch = vec![0f32; np];
    let mut feat = vec![0f32; nf];
    let mut st = RenderStats::default();
    let sat_on = table.meta.params.saturation_classes;
    let contrast_on = table.meta.params.contrast_classes;
    for c in 0..width {
        geo.gather(img, width, height, r, c, &mut patch);
        let pos = geo.position(r, c);
        let s = geo.stats(&patch, pos);
        let band = geo.band_of(s.luminance, &s.channel_means);
        let (sat, fell_back) = if sat_on && s.sat_mask != 0 {
            resolve_sat_case(table, s.sat_mask, &s.channel_means)
        } else {
            (0, false)
        };
        let group = table.group_index(pos, band, sat);
        let texture = contrast_on && s.contrast > table.contrast_thresholds[group];
        let class = group * 2 + texture as usize;
        geo.features(&patch, pos, table.meta.sat_cases[sat], &mut feat);
        let k = &kernels[class * 3 * nf..(class + 1) * 3 * nf];
        for i in 0..3 {
            row[c * 3 + i] = dot(&k[i * nf..(i + 1) * nf], &feat);
        }
        st.pixels += 1;
        st.saturated += (sat != 0) as u64;
        st.fallback += fell_back as u64;
        st.texture += texture as u64;
    }
    st
}
