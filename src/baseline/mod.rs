//! The conventional pipelines L3 is compared with.
//!
//! - The **baseline** ([`render_baseline`]): bilinear demosaicking ([`bilinear_demosaic`])
//!   followed by a least-squares colour matrix ([`ColourMatrix`]: channels → XYZ), and T.
//! - A **strong ISP** ([`Isp`]): Malvar–He–Cutler demosaicking on Bayer CFAs
//!   ([`malvar_demosaic`]), its generalisation to other 2×2 CFAs such as RGBW
//!   ([`gradient_demosaic`]), a luma/chroma denoiser whose strength comes from the sensor's
//!   noise model at the frame's exposure ([`NoiseProfile`], [`denoise`]), then the colour
//!   matrix. It is the rival an imaging engineer would accept as fair: every step is a
//!   published, widely used one, tuned on the same charts L3 is judged on.

mod bilinear;
mod denoise;
mod guided;
mod isp;
mod malvar;
mod matrix;
mod rgbw;

pub use bilinear::bilinear_demosaic;
pub use denoise::{DenoiseParams, NoiseProfile, denoise};
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

/// The frame with a border of `pad` pixels mirrored about its edges (as
/// [`mirror`] does), row-major, `(width + 2·pad) × (height + 2·pad)`: the 5×5 demosaics
/// read it without a bounds test per tap.
fn pad_mirrored(volts: &[f32], width: usize, height: usize, pad: usize) -> Vec<f32> {
    let pw = width + 2 * pad;
    let mut out = vec![0f32; pw * (height + 2 * pad)];
    for (pr, row) in out.chunks_exact_mut(pw).enumerate() {
        let r = mirror(pr as isize - pad as isize, height);
        let src = &volts[r * width..(r + 1) * width];
        row[pad..pad + width].copy_from_slice(src);
        for p in 0..pad {
            row[p] = src[mirror(p as isize - pad as isize, width)];
            row[pad + width + p] = src[mirror((width + p) as isize, width)];
        }
    }
    out
}

#[cfg(test)]
mod tests;
