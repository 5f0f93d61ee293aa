//! Spectral scenes: a reflectance cube lit by one illuminant, at a given mean
//! luminance and field of view, plus the labelled regions (chart patches)
//! that evaluation reads back.

mod chart;
mod dead_leaves;
mod image_lift;
mod kind;
mod kmeans;
mod natural100;
mod options;
mod pca;
mod sets;
mod simple;
mod slanted_edge;

pub use chart::{
    CHART_SURROUND, GREY_CATEGORY, GREY_STRIP_STEPS, MACBETH_CSV, grey_strip_levels, macbeth,
    reflectance_chart,
};
pub use dead_leaves::{DeadLeavesParams, dead_leaves, dead_leaves_labels};
pub use image_lift::{SrgbLift, from_srgb_file, from_srgb_image, from_srgb_pixels};
pub use kind::{DEFAULT_TEXTURE_SIZE, MACBETH_PATCH_PX, SceneKind, ScenesKind};
pub use natural100::{
    ChartSample, NATURAL100_CATEGORIES, NATURAL100_COLS, NATURAL100_COMPONENTS,
    NATURAL100_PATCH_PX, NATURAL100_SEED, Natural100Category, ces_chart, ces_samples,
    natural100_chart, natural100_samples, natural100_samples_seeded,
};
pub use options::{DEFAULT_FOV_DEG, DEFAULT_MEAN_LUMINANCE, MAX_SCENE_VALUES, SceneOptions};
pub use sets::{natural_reflectances, training_reflectances};
pub use simple::{grey_ramp, uniform};
pub use slanted_edge::{
    BRIGHT_PATCH, DARK_PATCH, EDGE_ANGLE_DEG, EDGE_BRIGHT, EDGE_DARK, EDGE_SIZE, MIN_EDGE_SIZE,
    SlantedEdgeParams, WHITE_PATCH, WHITE_REFERENCE, add_white_strip, slanted_edge,
};

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

    /// The same scene on a grid `k` times finer: every pixel becomes a
    /// `k × k` block of equal reflectance (patches scale with it).
    pub fn upsampled(&self, k: usize) -> Scene {
        let k = k.max(1);
        let (bands, rows, cols) = self.reflectance.dim();
        let reflectance = Array3::from_shape_fn((bands, rows * k, cols * k), |(b, r, c)| {
            self.reflectance[[b, r / k, c / k]]
        });
        Scene {
            reflectance,
            patches: self
                .patches
                .iter()
                .map(|p| Patch {
                    row: p.row * k,
                    col: p.col * k,
                    height: p.height * k,
                    width: p.width * k,
                    ..p.clone()
                })
                .collect(),
            name: self.name.clone(),
            grid: self.grid,
            illuminant: self.illuminant.clone(),
            illuminant_name: self.illuminant_name.clone(),
            mean_luminance: self.mean_luminance,
            fov_deg: self.fov_deg,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectral::cie_illuminant;

    #[test]
    fn upsampling_replicates_pixels_and_scales_patches() {
        let grid = WavelengthGrid::default();
        let scene = Scene {
            name: "s".into(),
            grid,
            reflectance: Array3::from_shape_fn((grid.n, 2, 3), |(b, r, c)| {
                (b + 10 * r + 100 * c) as f32
            }),
            illuminant: cie_illuminant("D65")
                .unwrap()
                .resample(&grid, crate::spectral::Extrapolation::Zero),
            illuminant_name: "D65".into(),
            mean_luminance: 100.0,
            fov_deg: 10.0,
            patches: vec![Patch {
                name: "p".into(),
                category: String::new(),
                row: 1,
                col: 2,
                height: 1,
                width: 1,
                reflectance: Spectrum::constant(grid, 0.5),
            }],
        };
        let up = scene.upsampled(3);
        assert_eq!(up.reflectance.dim(), (grid.n, 6, 9));
        for ((b, r, c), v) in up.reflectance.indexed_iter() {
            assert_eq!(*v, scene.reflectance[[b, r / 3, c / 3]]);
        }
        let p = &up.patches[0];
        assert_eq!((p.row, p.col, p.height, p.width), (3, 6, 3, 3));
        assert_eq!(scene.upsampled(1).reflectance, scene.reflectance);
    }
}
