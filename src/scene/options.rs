//! Options shared by every scene builder.

use ndarray::Array3;

use crate::spectral::{Extrapolation, Samples, Spectrum, WavelengthGrid, cie_illuminant};

use super::{Patch, Scene, SceneError};

/// Default mean scene luminance, cd/m².
pub const DEFAULT_MEAN_LUMINANCE: f64 = 100.0;
/// Default horizontal field of view, degrees.
pub const DEFAULT_FOV_DEG: f64 = 10.0;
/// Largest scene a builder makes: bands × rows × cols values (f32).
pub const MAX_SCENE_VALUES: usize = 1 << 28;

/// The grid, illuminant, mean luminance and field of view of a scene.
#[derive(Clone, Debug)]
pub struct SceneOptions {
    pub grid: WavelengthGrid,
    /// Relative SPD of the illuminant on `grid`.
    pub illuminant: Spectrum,
    pub illuminant_name: String,
    /// Mean scene luminance, cd/m² (default 100).
    pub mean_luminance: f64,
    /// Horizontal field of view, degrees (default 10).
    pub fov_deg: f64,
}

impl SceneOptions {
    /// Options with the default luminance and field of view. The illuminant
    /// must be on `grid`.
    pub fn new(
        grid: WavelengthGrid,
        illuminant: Spectrum,
        illuminant_name: impl Into<String>,
    ) -> Result<Self, SceneError> {
        let o = Self {
            grid,
            illuminant,
            illuminant_name: illuminant_name.into(),
            mean_luminance: DEFAULT_MEAN_LUMINANCE,
            fov_deg: DEFAULT_FOV_DEG,
        };
        o.validate()?;
        Ok(o)
    }

    /// Options with an illuminant given as samples, band-averaged onto `grid`
    /// (zero outside its range).
    pub fn from_samples(
        grid: WavelengthGrid,
        illuminant: &Samples,
        illuminant_name: impl Into<String>,
    ) -> Result<Self, SceneError> {
        Self::new(
            grid,
            illuminant.resample(&grid, Extrapolation::Zero),
            illuminant_name,
        )
    }

    /// CIE D65 on `grid`, default luminance and field of view.
    pub fn d65(grid: WavelengthGrid) -> Result<Self, SceneError> {
        let d65 = cie_illuminant("D65")
            .ok_or_else(|| SceneError::Invalid("built-in D65 is missing".into()))?;
        Self::from_samples(grid, &d65, "D65")
    }

    /// The same options with another mean luminance (cd/m²).
    pub fn with_mean_luminance(mut self, cd_m2: f64) -> Self {
        self.mean_luminance = cd_m2;
        self
    }

    /// The same options with another field of view (degrees).
    pub fn with_fov(mut self, deg: f64) -> Self {
        self.fov_deg = deg;
        self
    }

    /// Check every field; builders call this first.
    pub fn validate(&self) -> Result<(), SceneError> {
        if self.grid.n == 0 {
            return Err(SceneError::Invalid("wavelength grid has no bands".into()));
        }
        if *self.illuminant.grid() != self.grid {
            return Err(SceneError::Invalid(format!(
                "illuminant '{}' is on {:?}, the scene grid is {:?}",
                self.illuminant_name,
                self.illuminant.grid(),
                self.grid
            )));
        }
        if let Some(v) = self
            .illuminant
            .values()
            .iter()
            .find(|v| !v.is_finite() || **v < 0.0)
        {
            return Err(SceneError::Invalid(format!(
                "illuminant '{}' has a negative or non-finite value ({v})",
                self.illuminant_name
            )));
        }
        if self.illuminant.max() <= 0.0 {
            return Err(SceneError::Invalid(format!(
                "illuminant '{}' is zero over the scene grid",
                self.illuminant_name
            )));
        }
        if !(self.mean_luminance.is_finite() && self.mean_luminance > 0.0) {
            return Err(SceneError::Invalid(format!(
                "mean luminance must be a positive number of cd/m², got {}",
                self.mean_luminance
            )));
        }
        if !(self.fov_deg.is_finite() && self.fov_deg > 0.0 && self.fov_deg < 180.0) {
            return Err(SceneError::Invalid(format!(
                "field of view must be within (0, 180) degrees, got {}",
                self.fov_deg
            )));
        }
        Ok(())
    }

    /// Assemble a scene from a cube made on this grid.
    pub(crate) fn scene(&self, name: &str, reflectance: Array3<f32>, patches: Vec<Patch>) -> Scene {
        Scene {
            name: name.to_string(),
            grid: self.grid,
            reflectance,
            illuminant: self.illuminant.clone(),
            illuminant_name: self.illuminant_name.clone(),
            mean_luminance: self.mean_luminance,
            fov_deg: self.fov_deg,
            patches,
        }
    }
}

/// A zero reflectance cube `(bands, rows, cols)` after checking its size.
pub(crate) fn new_cube(
    grid: &WavelengthGrid,
    rows: usize,
    cols: usize,
) -> Result<Array3<f32>, SceneError> {
    if rows == 0 || cols == 0 {
        return Err(SceneError::Invalid(format!(
            "scene size must be positive, got {rows} × {cols}"
        )));
    }
    let values = grid
        .n
        .checked_mul(rows)
        .and_then(|v| v.checked_mul(cols))
        .filter(|&v| v <= MAX_SCENE_VALUES)
        .ok_or_else(|| {
            SceneError::Invalid(format!(
                "scene of {rows} × {cols} pixels × {} bands exceeds {MAX_SCENE_VALUES} values",
                grid.n
            ))
        })?;
    debug_assert!(values > 0);
    Ok(Array3::zeros((grid.n, rows, cols)))
}

/// A reflectance put on `grid`: unchanged when already there, otherwise read
/// as piecewise linear and band-averaged with held ends. Rejects negative
/// or non-finite values.
pub(crate) fn reflectance_on_grid(
    name: &str,
    r: &Spectrum,
    grid: &WavelengthGrid,
) -> Result<Spectrum, SceneError> {
    check_reflectance(name, r.values())?;
    if r.grid() == grid {
        return Ok(r.clone());
    }
    if r.grid().n < 2 {
        return Ok(Spectrum::constant(*grid, r.values()[0]));
    }
    let s = Samples::new(r.grid().wavelengths(), r.values().to_vec())?;
    Ok(s.resample(grid, Extrapolation::Hold))
}

/// Band-average samples onto `grid` with held ends, rejecting bad values.
pub(crate) fn samples_on_grid(
    name: &str,
    s: &Samples,
    grid: &WavelengthGrid,
) -> Result<Spectrum, SceneError> {
    check_reflectance(name, s.values())?;
    Ok(s.resample(grid, Extrapolation::Hold))
}

fn check_reflectance(name: &str, v: &[f64]) -> Result<(), SceneError> {
    if v.is_empty() {
        return Err(SceneError::Invalid(format!(
            "reflectance '{name}' is empty"
        )));
    }
    if let Some(x) = v.iter().find(|x| !x.is_finite() || **x < 0.0) {
        return Err(SceneError::Invalid(format!(
            "reflectance '{name}' has a negative or non-finite value ({x})"
        )));
    }
    Ok(())
}

/// Paint a rectangle of the cube with one reflectance (clipped to the cube).
pub(crate) fn fill_rect(
    cube: &mut Array3<f32>,
    r: &Spectrum,
    row: usize,
    col: usize,
    height: usize,
    width: usize,
) {
    use ndarray::s;
    let (rows, cols) = (cube.shape()[1], cube.shape()[2]);
    let (r1, c1) = ((row + height).min(rows), (col + width).min(cols));
    if row >= r1 || col >= c1 {
        return;
    }
    for (b, &v) in r.values().iter().enumerate() {
        cube.slice_mut(s![b, row..r1, col..c1]).fill(v as f32);
    }
}
