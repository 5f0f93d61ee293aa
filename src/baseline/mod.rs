//! The conventional pipelines L3 is compared with.
//!
//! - The **baseline** ([`render_baseline`]): bilinear demosaicking ([`bilinear_demosaic`])
//!   followed by a least-squares colour matrix ([`ColourMatrix`]: channels → XYZ), and T;
//!   [`render_baseline_fused`] is the same render in one parallel, vectorised pass.
//! - A **strong ISP** ([`Isp`]): Malvar–He–Cutler demosaicking on Bayer CFAs
//!   ([`malvar_demosaic`]), its generalisation to other 2×2 CFAs such as RGBW
//!   ([`gradient_demosaic`]), a luma/chroma denoiser whose strength comes from the sensor's
//!   noise model at the frame's exposure ([`NoiseProfile`], [`denoise`]), then the colour
//!   matrix. It is the rival an imaging engineer would accept as fair: every step is a
//!   published, widely used one, tuned on the same charts L3 is judged on.

mod bilinear;
mod denoise;
mod fast;
pub(crate) mod guided;
mod isp;
mod malvar;
mod matrix;
mod rgbw;

pub use bilinear::bilinear_demosaic;
pub use denoise::{DenoiseParams, NoiseProfile, denoise};
pub use fast::{render_baseline_fused, render_baseline_fused_srgb8};
pub use isp::{DemosaicMethod, Isp, demosaic};
pub use malvar::{BayerLayout, malvar_demosaic};
pub use matrix::ColourMatrix;
pub use rgbw::{DEFAULT_GRADIENT_GAIN, gradient_demosaic};

use crate::camera::Cfa;
use crate::l3::classify::mirror;

/// Errors of the conventional pipelines: a colour matrix that cannot be fitted, a frame they
/// cannot render.
#[derive(Debug, thiserror::Error)]
pub enum BaselineError {
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// A colour matrix fit whose normal equations are singular.
    #[error("table is not usable: {0}")]
    Singular(String),
}

/// Render with the baseline: bilinear demosaic, then XYZ = M · channels.
pub fn render_baseline(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
    m: &ColourMatrix,
) -> Result<Vec<f32>, BaselineError> {
    check_matrix(m, cfa)?;
    m.apply(&bilinear_demosaic(volts, width, height, cfa)?)
}

/// The matrix fits the CFA's channels.
fn check_matrix(m: &ColourMatrix, cfa: &Cfa) -> Result<(), BaselineError> {
    let nc = cfa.n_channels();
    if m.n_channels != nc {
        return Err(BaselineError::InvalidInput(format!(
            "colour matrix has {} channels, the CFA {nc}",
            m.n_channels
        )));
    }
    Ok(())
}

/// The frame's size matches its values.
fn check_frame(volts: &[f32], width: usize, height: usize) -> Result<(), BaselineError> {
    if width == 0 || height == 0 || Some(volts.len()) != width.checked_mul(height) {
        return Err(BaselineError::InvalidInput(format!(
            "{} values for a {width}×{height} frame",
            volts.len()
        )));
    }
    Ok(())
}

/// The taps the 5×5 demosaics read around a pixel: the pixel, its horizontal and vertical
/// neighbours at distances 1 and 2, and its four diagonal neighbours.
#[derive(Clone, Copy)]
struct Taps {
    x: f32,
    /// Left, right, up, down at distance 1.
    l1: f32,
    r1: f32,
    u1: f32,
    d1: f32,
    /// The same at distance 2.
    l2: f32,
    r2: f32,
    u2: f32,
    d2: f32,
    /// Up-left, up-right, down-left, down-right.
    ul: f32,
    ur: f32,
    dl: f32,
    dr: f32,
}

/// A row's neighbourhood in a frame, the frame mirrored about its edges (as [`mirror`]
/// does): rows `r−2 ..= r+2`, read without copying the frame.
struct Window5<'a> {
    rows: [&'a [f32]; 5],
}

impl<'a> Window5<'a> {
    fn new(volts: &'a [f32], width: usize, height: usize, r: usize) -> Self {
        Self {
            rows: std::array::from_fn(|k| {
                let rr = mirror(r as isize + k as isize - 2, height);
                &volts[rr * width..(rr + 1) * width]
            }),
        }
    }

    /// The taps around column `c` (columns mirrored at the sides).
    #[inline(always)]
    fn taps(&self, c: usize) -> Taps {
        let [u2, u1, m0, d1, d2] = self.rows;
        let w = m0.len();
        let [a, b, j, d, e] = if c >= 2 && c + 2 < w {
            [c - 2, c - 1, c, c + 1, c + 2]
        } else {
            std::array::from_fn(|k| mirror(c as isize + k as isize - 2, w))
        };
        Taps {
            x: m0[j],
            l1: m0[b],
            r1: m0[d],
            u1: u1[j],
            d1: d1[j],
            l2: m0[a],
            r2: m0[e],
            u2: u2[j],
            d2: d2[j],
            ul: u1[b],
            ur: u1[d],
            dl: d1[b],
            dr: d1[d],
        }
    }
}

#[cfg(test)]
mod tests;
