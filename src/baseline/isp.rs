//! The strong conventional pipeline: demosaic (Malvar–He–Cutler on Bayer, the gradient-
//! corrected generalisation on other 2×2 CFAs, bilinear otherwise), denoise by the sensor's
//! noise model, colour matrix.

use serde::{Deserialize, Serialize};

use super::{
    BaselineError, ColourMatrix, DEFAULT_GRADIENT_GAIN, DenoiseParams, NoiseProfile, check_frame,
    check_matrix, denoise,
};
use crate::baseline::malvar::BayerLayout;
use crate::camera::Cfa;

/// A demosaicking method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DemosaicMethod {
    /// [`super::bilinear_demosaic`] (any CFA).
    Bilinear,
    /// [`super::malvar_demosaic`] (Bayer CFAs only).
    Malvar,
    /// [`super::gradient_demosaic`] (tiles up to 2×2; bilinear beyond).
    Gradient,
    /// What the ISP uses: Malvar on Bayer, gradient on other 2×2 tiles, bilinear beyond.
    Auto,
}

impl std::str::FromStr for DemosaicMethod {
    type Err = BaselineError;
    fn from_str(s: &str) -> Result<Self, BaselineError> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "bilinear" => Self::Bilinear,
            "malvar" => Self::Malvar,
            "gradient" => Self::Gradient,
            "auto" | "isp" => Self::Auto,
            _ => {
                return Err(BaselineError::InvalidParams(format!(
                    "demosaic method '{s}': expected bilinear, malvar, gradient, auto or isp"
                )));
            }
        })
    }
}

/// Demosaic `volts` with `method`; interleaved `width × height × n_channels`.
pub fn demosaic(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
    method: DemosaicMethod,
    gradient_gain: f32,
) -> Result<Vec<f32>, BaselineError> {
    match method {
        DemosaicMethod::Bilinear => super::bilinear_demosaic(volts, width, height, cfa),
        DemosaicMethod::Malvar => super::malvar_demosaic(volts, width, height, cfa),
        DemosaicMethod::Gradient => {
            super::gradient_demosaic(volts, width, height, cfa, gradient_gain)
        }
        DemosaicMethod::Auto if BayerLayout::of(cfa).is_some() => {
            super::malvar_demosaic(volts, width, height, cfa)
        }
        DemosaicMethod::Auto => super::gradient_demosaic(volts, width, height, cfa, gradient_gain),
    }
}

/// The strong conventional ISP: demosaic → denoise (when it has a noise profile) → colour
/// matrix. Output: interleaved XYZ, as [`super::render_baseline`]'s.
#[derive(Clone, Debug, PartialEq)]
pub struct Isp {
    matrix: ColourMatrix,
    noise: Option<NoiseProfile>,
    /// The demosaic ([`DemosaicMethod::Auto`] by default).
    pub demosaic: DemosaicMethod,
    /// The gradient demosaic's gain ([`DEFAULT_GRADIENT_GAIN`]).
    pub gradient_gain: f32,
    /// The denoiser's parameters.
    pub denoise: DenoiseParams,
}

impl Isp {
    /// An ISP with `matrix` (channels → XYZ) and, when given, a denoiser for `noise`.
    pub fn new(matrix: ColourMatrix, noise: Option<NoiseProfile>) -> Self {
        Self {
            matrix,
            noise,
            demosaic: DemosaicMethod::Auto,
            gradient_gain: DEFAULT_GRADIENT_GAIN,
            denoise: DenoiseParams::default(),
        }
    }

    /// The colour matrix.
    pub fn matrix(&self) -> &ColourMatrix {
        &self.matrix
    }

    /// The noise profile the denoiser uses (none: no denoising).
    pub fn noise(&self) -> Option<&NoiseProfile> {
        self.noise.as_ref()
    }

    /// The same ISP with another colour matrix (e.g. the matrix then T).
    pub fn with_matrix(&self, matrix: ColourMatrix) -> Self {
        Self {
            matrix,
            ..self.clone()
        }
    }

    /// The same ISP with another noise profile (e.g. at a frame's exposure).
    pub fn with_noise(&self, noise: Option<NoiseProfile>) -> Self {
        Self {
            noise,
            ..self.clone()
        }
    }

    /// The demosaicked and (with a profile) denoised camera channels, interleaved.
    pub fn channels(
        &self,
        volts: &[f32],
        width: usize,
        height: usize,
        cfa: &Cfa,
    ) -> Result<Vec<f32>, BaselineError> {
        check_frame(volts, width, height)?;
        if let Some(v) = volts.iter().find(|v| !v.is_finite()) {
            return Err(BaselineError::InvalidInput(format!(
                "the frame holds a non-finite value ({v})"
            )));
        }
        let dm = demosaic(volts, width, height, cfa, self.demosaic, self.gradient_gain)?;
        match &self.noise {
            Some(p) => denoise(&dm, width, height, cfa.n_channels(), p, &self.denoise),
            None => Ok(dm),
        }
    }

    /// Render a mosaic in volts to interleaved XYZ; every value is checked finite.
    pub fn render(
        &self,
        volts: &[f32],
        width: usize,
        height: usize,
        cfa: &Cfa,
    ) -> Result<Vec<f32>, BaselineError> {
        check_matrix(&self.matrix, cfa)?;
        self.matrix
            .apply(&self.channels(volts, width, height, cfa)?)
    }
}
