//! Spectral scenes: a reflectance cube lit by one illuminant, at a given mean
//! luminance and field of view, plus the labelled regions (chart patches)
//! that evaluation reads back.

use ndarray::Array3;
use serde::{Deserialize, Serialize};

use crate::spectral::{Spectrum, WavelengthGrid};

/// Errors of scene building.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(transparent)]
    Spectral(#[from] crate::spectral::SpectralError),
    #[error("invalid scene: {0}")]
    Invalid(String),
    #[error("cannot read image {path}: {msg}")]
    Image { path: String, msg: String },
}

/// A labelled rectangular region of a scene (a chart patch).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Patch {
    pub name: String,
    /// Category (e.g. `Food`, `grey`), empty when not applicable.
    pub category: String,
    pub row: usize,
    pub col: usize,
    pub height: usize,
    pub width: usize,
    /// The patch's reflectance on the scene grid.
    pub reflectance: Spectrum,
}

/// A spectral scene. Radiance at a pixel is
/// `reflectance[b, r, c] × illuminant[b] × radiance_scale`, in W/(sr·m²·nm).
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub grid: WavelengthGrid,
    /// Reflectance factors, shape `(bands, rows, cols)`.
    pub reflectance: Array3<f32>,
    /// Relative SPD of the illuminant on `grid`.
    pub illuminant: Spectrum,
    pub illuminant_name: String,
    /// Mean scene luminance in cd/m².
    pub mean_luminance: f64,
    /// Horizontal field of view in degrees.
    pub fov_deg: f64,
    /// Labelled regions, if the scene is a chart.
    pub patches: Vec<Patch>,
}

impl Scene {
    pub fn rows(&self) -> usize {
        self.reflectance.shape()[1]
    }

    pub fn cols(&self) -> usize {
        self.reflectance.shape()[2]
    }

    pub fn bands(&self) -> usize {
        self.reflectance.shape()[0]
    }
}
