//! The chroma stage: a self-guided filter on the chroma of a rendered XYZ image, as wide as
//! low light needs, with its strength from the table's own output noise.
//!
//! **Why.** A class's kernel is linear over its patch (5 × 5 by default). At a tenth of the
//! exposure the noise left in its output's chroma is what separates L3 from a conventional
//! ISP, whose chroma filter averages over 9 × 9 pixels with a strength set per window
//! (docs/accuracy.md, *Against the strong ISP*; docs/research/low-light-chroma.md). The eye
//! resolves chroma far more coarsely than luminance, so chroma can be averaged over a wider
//! support than the kernels' without a visible loss, and luminance (and with it sharpness)
//! is left as the kernels made it.
//!
//! **What.** With the D65 white's ratios `kx = X/Y`, `kz = Z/Y`, the chroma planes are
//! `c₁ = X − kx·Y` and `c₂ = Z − kz·Y` (a neutral has none). Each gets the self-guided filter
//! of [`crate::baseline`]'s denoiser (the same streamed filter, radius [`RADIUS`]) with a
//! per-pixel `ε = STRENGTH · σ²_k(Y)`: `σ²_k(Y)` the variance of plane `k`'s noise at the
//! pixel's luminance. Windows whose chroma varies at the noise's level are flattened; chroma
//! steps well above it (a coloured edge, an isoluminant one too) are kept. `X` and `Z` are
//! rebuilt from the filtered planes and the untouched `Y`.
//!
//! **The noise, from the table.** The variance is the table's, not estimated from the image:
//! at each luminance level `v` (volts), the sensor's noise model
//! ([`NoiseProfile`], the table's own sensor) gives the variance `σ²(v)` of an input pixel,
//! and a flat, unsaturated class's kernel rows `x, y, z` give its output chroma's,
//! `σ²(v)·Σⱼ(xⱼ − kx·yⱼ)²` (and `z` for `c₂`), and its output luminance, `v·Σⱼ yⱼ` plus the
//! constant term. Averaged over the level's classes, that is one point of the curve
//! `σ²_k(Y)`, interpolated between levels. The kernels are the ones the frame renders with
//! (the correction folded in), so the curve is in the output's units. Dark levels' kernels
//! already average more; the curve knows it.
//!
//! **When.** The filter costs more than the render, and where the signal is high a pixel's
//! chroma noise is small against its luminance and the filter changes little.
//! [`ChromaMode::Auto`] runs it when at least [`AUTO_FRACTION`] of a sample of the frame's
//! pixels (every [`SAMPLE_STEP`]th) sit at levels whose chroma noise (σ of `c₁`, `c₂`
//! together) exceeds [`AUTO_NOISE`] of their luminance: a low-light frame. On the simulated Natural-100 chart
//! under tungsten (its white at 95 % of the swing), with each shipped sensor's tungsten
//! table, 5–30 % of the pixels are at such levels at full exposure (the stage is skipped) and
//! 58–93 % at a tenth of it (it runs). [`ChromaMode::On`] runs it on every frame, which helps
//! at full exposure too on a noisy sensor (docs/accuracy.md), at the filter's cost.
//! The radius and strength were chosen on the charts: a strength of 4 flattens more chroma
//! noise but moves patch means and smooths the dead-leaves texture's real chroma.

use std::str::FromStr;

use rayon::prelude::*;

use super::{Mosaic, RenderError};
use crate::baseline::NoiseProfile;
use crate::baseline::guided::{SelfGuided, run_side_by_side};
use crate::colour::D65_WHITE_XYZ;
use crate::l3::L3Table;

/// The filter's radius (a `9 × 9` window), as the ISP's chroma filter's.
pub const RADIUS: usize = 4;
/// `ε` as a multiple of the chroma noise's variance.
pub const STRENGTH: f32 = 2.0;
/// [`ChromaMode::Auto`]: the relative chroma noise above which a pixel's level needs the filter.
pub const AUTO_NOISE: f64 = 0.12;
/// [`ChromaMode::Auto`]: the fraction of the frame's sampled pixels that must need it.
pub const AUTO_FRACTION: f64 = 0.5;
/// Rows per parallel task (each task's filters start from its first rows' windows).
const STRIP: usize = 128;
// a strip's filters read at most 2r rows beyond it, so only its two neighbours' rows
// ([`ChromaStage::apply_in_place`])
const _: () = assert!(2 * RADIUS <= STRIP);
/// [`ChromaMode::Auto`] decides on every `SAMPLE_STEP`th value of a mosaic.
pub const SAMPLE_STEP: usize = 7;

/// Of every [`SAMPLE_STEP`]th value of `values` (from the first): how many are `noisy`,
/// and how many there are. In parallel over chunks of whole steps.
fn sample_count<T: Sync>(values: &[T], noisy: impl Fn(&T) -> bool + Sync) -> (usize, usize) {
    const CHUNK: usize = SAMPLE_STEP * 8192;
    values
        .par_chunks(CHUNK)
        .map(|c| {
            let (mut k, mut n) = (0, 0);
            for v in c.iter().step_by(SAMPLE_STEP) {
                k += usize::from(noisy(v));
                n += 1;
            }
            (k, n)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// Whether a render runs the chroma stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ChromaMode {
    /// When the frame needs it (module doc).
    #[default]
    Auto,
    /// Always (a table without a sensor has no noise model and is rendered without it).
    On,
    /// Never.
    Off,
}

/// A chroma mode that is not `auto`, `on` or `off`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("chroma denoising '{0}': expected auto, on or off")]
pub struct UnknownChromaMode(pub String);

impl FromStr for ChromaMode {
    type Err = UnknownChromaMode;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(Self::Auto),
            "on" => Ok(Self::On),
            "off" => Ok(Self::Off),
            _ => Err(UnknownChromaMode(s.to_string())),
        }
    }
}

impl std::fmt::Display for ChromaMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Auto => "auto",
            Self::On => "on",
            Self::Off => "off",
        })
    }
}

/// The chroma stage of one table under one set of kernels: the noise curve and, per level,
/// whether it needs the filter.
#[derive(Clone, Debug)]
pub struct ChromaStage {
    /// The levels' output luminance, increasing.
    y: Vec<f64>,
    /// Per level, the variance of `c₁`'s and `c₂`'s noise.
    var: [Vec<f64>; 2],
    /// The levels' edges in volts (the classification's), and whether each level needs it.
    edges: Vec<f32>,
    noisy: Vec<bool>,
    swing: f32,
    radius: usize,
    strength: f32,
}

impl ChromaStage {
    /// The stage for `table` rendering with `kernels` (its layout); `None` when the table
    /// names no sensor (no noise model) or its kernels give no usable curve.
    pub fn new(table: &L3Table, kernels: &[f32]) -> Result<Option<Self>, RenderError> {
        let Ok(design) = table.sensor_design() else {
            return Ok(None);
        };
        let nf = table.n_features();
        if kernels.len() != table.kernels.len() || nf < 2 {
            return Err(RenderError::KernelMismatch {
                got: kernels.len(),
                expected: table.kernels.len(),
            });
        }
        let noise = NoiseProfile::from_design(&design, 0.0);
        let [kx, _, kz] = D65_WHITE_XYZ;
        let levels = &table.meta.params.levels;
        let mut points = Vec::with_capacity(levels.len());
        for (l, &v) in levels.iter().enumerate() {
            let (mut y, mut s1, mut s2, mut n) = (0.0, 0.0, 0.0, 0.0);
            for pos in 0..table.n_positions() {
                for c in 0..table.n_chroma() {
                    let band = l * table.n_chroma() + c;
                    let class = table.class_index(pos, band, 0, false);
                    let k = &kernels[class * 3 * nf..(class + 1) * 3 * nf];
                    let (kxr, kyr, kzr) = (&k[..nf], &k[nf..2 * nf], &k[2 * nf..]);
                    let gy: f64 = kyr[..nf - 1].iter().map(|&w| f64::from(w)).sum();
                    y += v * gy + f64::from(kyr[nf - 1]);
                    let sq = |row: &[f32], kw: f64| -> f64 {
                        row[..nf - 1]
                            .iter()
                            .zip(&kyr[..nf - 1])
                            .map(|(&a, &b)| (f64::from(a) - kw * f64::from(b)).powi(2))
                            .sum()
                    };
                    s1 += sq(kxr, kx);
                    s2 += sq(kzr, kz);
                    n += 1.0;
                }
            }
            let var_in = noise.variance(v);
            points.push((y / n, var_in * s1 / n, var_in * s2 / n));
        }
        let usable = points
            .iter()
            .all(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite())
            && points.windows(2).all(|w| w[1].0 > w[0].0)
            && points.first().is_some_and(|p| p.0 > 0.0);
        if !usable {
            return Ok(None);
        }
        let noisy = points
            .iter()
            .map(|&(y, a, b)| (a + b).sqrt() > AUTO_NOISE * y)
            .collect();
        let edges = levels
            .windows(2)
            .map(|w| ((w[0] + w[1]) / 2.0) as f32)
            .collect();
        Ok(Some(Self {
            y: points.iter().map(|p| p.0).collect(),
            var: [
                points.iter().map(|p| p.1).collect(),
                points.iter().map(|p| p.2).collect(),
            ],
            edges,
            noisy,
            swing: table.meta.voltage_swing as f32,
            radius: RADIUS,
            strength: STRENGTH,
        }))
    }

    /// Whether a frame with mosaic `mosaic` needs the filter under `mode`: under
    /// [`ChromaMode::Auto`], decided on every [`SAMPLE_STEP`]th value of the mosaic, in volts
    /// (`swing` the renderer's; each clamped to the table's swing).
    ///
    /// The decision comes before the render and used to walk the sample in one thread, a
    /// binary search per value: 4–5 % of a served 2 MP render's CPU, all of it on the
    /// request's path. Now a DN mosaic's values are looked up in a table of the 65 536
    /// codes' answers, built in one sweep (volts do not decrease with the code), and volts
    /// are searched for in parallel. The counts, so the decision, are the same.
    pub fn runs_on(&self, mode: ChromaMode, mosaic: &Mosaic<'_>, swing: f32) -> bool {
        let (noisy, n) = match (mode, *mosaic) {
            (ChromaMode::On, _) => return true,
            (ChromaMode::Off, _) => return false,
            (ChromaMode::Auto, Mosaic::Volts(v)) => sample_count(v, |&x| self.noisy_at(x)),
            (ChromaMode::Auto, Mosaic::Dn { data, black, white }) => {
                let k = swing / f32::from(white.saturating_sub(black).max(1));
                let codes = self.code_answers(black, k);
                sample_count(data, |&d| codes[usize::from(d)])
            }
        };
        n > 0 && noisy as f64 >= AUTO_FRACTION * n as f64
    }

    /// Whether a mosaic value of `v` volts sits at a level that needs the filter.
    fn noisy_at(&self, v: f32) -> bool {
        let l = self
            .edges
            .partition_point(|&e| e < v.clamp(0.0, self.swing));
        self.noisy.get(l).copied().unwrap_or(false)
    }

    /// [`Self::noisy_at`] of every DN code's volts (`(code − black) · k`), in one sweep.
    fn code_answers(&self, black: u16, k: f32) -> Vec<bool> {
        let mut l = 0;
        (0..=u16::MAX)
            .map(|d| {
                let v = (f32::from(d.saturating_sub(black)) * k).clamp(0.0, self.swing);
                while l < self.edges.len() && self.edges[l] < v {
                    l += 1;
                }
                self.noisy.get(l).copied().unwrap_or(false)
            })
            .collect()
    }

    /// The variance of plane `k`'s noise at luminance `y`, linear between levels, the
    /// segment searched for from `hint` (the previous pixel's, updated): along a row the
    /// luminance moves a level or less from pixel to pixel, so a step or two replaces a
    /// binary search. The segment is the one `partition_point`
    /// finds (the levels' luminances increase strictly; a NaN `y` gives the first).
    fn variance_near(&self, k: usize, y: f64, hint: &mut usize) -> f64 {
        let (ys, var) = (&self.y, &self.var[k]);
        let mut i = (*hint).min(ys.len());
        while i < ys.len() && ys[i] < y {
            i += 1;
        }
        while i > 0 && ys[i - 1].partial_cmp(&y) != Some(std::cmp::Ordering::Less) {
            i -= 1;
        }
        *hint = i;
        if i == 0 {
            return var[0];
        }
        if i >= ys.len() {
            return var[ys.len() - 1];
        }
        let t = (y - ys[i - 1]) / (ys[i] - ys[i - 1]);
        var[i - 1] + t * (var[i] - var[i - 1])
    }

    /// Filter the chroma of an interleaved `width × height` XYZ image (module doc); `Y` is
    /// kept. Errors on a buffer of the wrong size or a non-finite result. This is
    /// [`Self::apply_in_place`] on a copy.
    pub fn apply(&self, xyz: &[f32], width: usize, height: usize) -> Result<Vec<f32>, RenderError> {
        let mut out = xyz.to_vec();
        self.apply_in_place(&mut out, width, height)?;
        Ok(out)
    }

    /// [`Self::apply`] over the image itself: no second frame. A 110 MP render through the
    /// stage held two float XYZ frames of 1.3 GB each; it now holds one, and a copy of the
    /// rows on either side of each strip's edges (`4r` rows per `STRIP`).
    ///
    /// Strips run in parallel, each over its own rows. A strip's filters read each input row
    /// once, in order, and emit an output row only after reading the rows `2r` below it
    /// (`run_side_by_side`), so within a strip a row is read before it is overwritten. Only
    /// its neighbours' edge rows could change under it; those are read from the copy taken
    /// before any strip starts. The result is the out-of-place filter's, bit for bit. On an
    /// error (a non-finite result) the image is left part-filtered.
    pub fn apply_in_place(
        &self,
        xyz: &mut [f32],
        width: usize,
        height: usize,
    ) -> Result<(), RenderError> {
        if xyz.len() != width * height * 3 {
            return Err(RenderError::InvalidInput(format!(
                "{} values for a {width}×{height} XYZ image",
                xyz.len()
            )));
        }
        if width == 0 || height == 0 {
            return Ok(());
        }
        let [kx, _, kz] = D65_WHITE_XYZ.map(|v| v as f32);
        let white = [kx, kz];
        let row = width * 3;
        // the rows within 2r of each strip edge, before any strip writes (the filters read
        // input rows up to 2r beyond their strip)
        let reach = 2 * self.radius;
        let edges: Vec<EdgeRows> = (STRIP..height)
            .step_by(STRIP)
            .map(|b| {
                let first = b.saturating_sub(reach);
                let end = (b + reach).min(height);
                EdgeRows {
                    first,
                    rows: xyz[first * row..end * row].to_vec(),
                }
            })
            .collect();
        let finite = xyz.par_chunks_mut(STRIP * row).enumerate().map_init(
            || {
                [
                    SelfGuided::new(height, self.radius),
                    SelfGuided::new(height, self.radius),
                ]
            },
            |filters, (strip, o)| {
                let y0 = strip * STRIP;
                let y1 = y0 + o.len() / row;
                let own = std::cell::Cell::from_mut(o).as_slice_of_cells();
                // row t as it was before filtering: this strip's own, else its neighbour's copy
                let load = |t: usize, dst: &mut Vec<f32>| {
                    dst.clear();
                    if (y0..y1).contains(&t) {
                        let at = (t - y0) * row;
                        dst.extend(own[at..at + row].iter().map(std::cell::Cell::get));
                    } else {
                        let e = &edges[if t < y0 { strip - 1 } else { strip }];
                        let at = (t - e.first) * row;
                        dst.extend_from_slice(&e.rows[at..at + row]);
                    }
                };
                let (mut input_row, mut eps_row) = (Vec::new(), Vec::new());
                run_side_by_side(
                    filters,
                    width,
                    y0..y1,
                    |k, t, plane| {
                        load(t, &mut input_row);
                        for (p, px) in plane.iter_mut().zip(input_row.chunks_exact(3)) {
                            *p = px[2 * k] - white[k] * px[1];
                        }
                    },
                    |k, s, _, e| {
                        load(s, &mut eps_row);
                        let mut hint = 0;
                        for (e, px) in e.iter_mut().zip(eps_row.chunks_exact(3)) {
                            let var = self.variance_near(k, f64::from(px[1]), &mut hint);
                            *e = (self.strength * var as f32).max(f32::MIN_POSITIVE);
                        }
                    },
                    |k, y, filtered| {
                        let at = (y - y0) * row;
                        for (px, &c) in own[at..at + row].chunks_exact(3).zip(filtered) {
                            px[2 * k].set(c + white[k] * px[1].get());
                        }
                    },
                );
                own.iter().all(|v| v.get().is_finite())
            },
        );
        // (a reduce, not `all`: every strip is filtered)
        if !finite.reduce(|| true, |a, b| a && b) {
            return Err(RenderError::InvalidInput(
                "the chroma stage produced a value that is not finite".into(),
            ));
        }
        Ok(())
    }
}

/// Rows `first..` of an image as they were before the chroma stage wrote any: the rows about
/// one edge between two strips ([`ChromaStage::apply_in_place`]).
struct EdgeRows {
    first: usize,
    rows: Vec<f32>,
}

#[cfg(test)]
mod tests;
