//! S-CIELAB of a rendering method on a dead-leaves texture of the natural reflectances,
//! captured through the full camera model, against the texture's ideal image.
//!
//! The scene: [`crate::scene::dead_leaves`] of the natural reflectances (the set every colour
//! fit is made on; occluding discs of radii 2 px to a quarter of the side, a fixed layout,
//! [`TEXTURE_LAYOUT_SEED`]) under a strip of the chart's white
//! ([`crate::scene::add_white_strip`]), which sets the auto-exposure as the chart's white
//! patch does and is the reference both images are normalised by: each is divided by the mean
//! Y of its own white strip's interior, as the chart evaluation divides by its white patch's.
//! The S-CIELAB ([`super::scielab`], CIEDE2000, default viewing condition and filters) is taken
//! over the texture below the strip (less [`super::edge::ROI_MARGIN`] rows), and its mean is
//! the score.

use super::workflow::{ChartSetup, capture_scene, ideal_d65_image};
use super::{EvalError, ScielabOptions, patch_means, scielab};
use crate::camera::Camera;
use crate::scene::{
    DeadLeavesParams, Patch, SceneOptions, WHITE_PATCH, add_white_strip, dead_leaves,
    natural_reflectances,
};
use crate::spectral::{IlluminantSpec, IsetData, Spectrum};

/// The seed of the texture's layout (the capture's noise takes the set-up's seed).
pub const TEXTURE_LAYOUT_SEED: u64 = 12;
/// The smallest side of the texture, pixels.
pub const MIN_TEXTURE_SIZE: usize = 32;

/// The texture captured once under one acquisition light, with its ideal image.
#[derive(Clone, Debug)]
pub struct TextureCapture {
    /// The scene's patches (the white strip).
    pub patches: Vec<Patch>,
    /// The acquisition illuminant's resolved name.
    pub acquisition: String,
    /// The raw mosaic in volts, row-major `width × height`.
    pub volts: Vec<f32>,
    pub width: usize,
    pub height: usize,
    pub exposure_s: f64,
    /// The noise-free XYZ of the optical image relit by D65 (interleaved).
    pub ideal_image: Vec<f32>,
    /// Rows of the white strip at the top.
    pub white_rows: usize,
}

/// Simulate a `size × size` texture under `acquisition` as `setup` says (noise, seed,
/// exposure factor, mean luminance), with its ideal image.
pub fn simulate_texture(
    camera: &Camera,
    acquisition: &str,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
    size: usize,
) -> Result<TextureCapture, EvalError> {
    if size < MIN_TEXTURE_SIZE {
        return Err(EvalError::Invalid(format!(
            "a texture of {size} px: at least {MIN_TEXTURE_SIZE}"
        )));
    }
    let named = IlluminantSpec::parse(acquisition)?.resolve(iset)?;
    let grid = *camera.grid();
    let opts = SceneOptions::from_samples(grid, &named.spd, named.name.clone())?
        .with_mean_luminance(setup.mean_luminance);
    let set: Vec<Spectrum> = natural_reflectances(&grid, iset)?
        .into_iter()
        .map(|(_, s)| s)
        .collect();
    let params = DeadLeavesParams::new(size, size, TEXTURE_LAYOUT_SEED);
    let mut scene = dead_leaves(&opts, &set, &params)?;
    let white_rows = (size / 8).max(6);
    add_white_strip(&mut scene, white_rows)?;
    let cap = capture_scene(camera, &scene, setup)?;
    let (height, width) = cap.volts.dim();
    let ideal_image = ideal_d65_image(camera, &scene)?;
    Ok(TextureCapture {
        patches: scene.patches,
        acquisition: named.name,
        volts: cap.volts.into_raw_vec_and_offset().0,
        width,
        height,
        exposure_s: cap.exposure_s,
        ideal_image,
        white_rows,
    })
}

impl TextureCapture {
    /// The mean S-CIELAB ΔE2000 of a rendered XYZ image (interleaved, `width × height × 3`)
    /// against the ideal image, both normalised by their white strip, over the texture.
    pub fn score(&self, rendered_xyz: &[f32]) -> Result<f64, EvalError> {
        let n = self.width * self.height * 3;
        if rendered_xyz.len() != n || self.ideal_image.len() != n {
            return Err(EvalError::Invalid(format!(
                "the texture render has {} values; {}×{}×3 expected",
                rendered_xyz.len(),
                self.width,
                self.height
            )));
        }
        let y_ideal = self.white_y(&self.ideal_image)?;
        let y_render = self.white_y(rendered_xyz)?;
        let first = (self.white_rows + super::edge::ROI_MARGIN) * self.width * 3;
        let rows = self
            .height
            .saturating_sub(self.white_rows + super::edge::ROI_MARGIN);
        let a: Vec<f64> = self.ideal_image[first..]
            .iter()
            .map(|&v| f64::from(v) / y_ideal)
            .collect();
        let b: Vec<f64> = rendered_xyz[first..]
            .iter()
            .map(|&v| f64::from(v) / y_render)
            .collect();
        let s = scielab(&a, &b, self.width, rows, &ScielabOptions::default(), false)?;
        Ok(s.stats.mean)
    }

    /// The mean Y over the white strip's interior.
    fn white_y(&self, xyz: &[f32]) -> Result<f64, EvalError> {
        let white = self
            .patches
            .iter()
            .find(|p| p.name == WHITE_PATCH)
            .ok_or_else(|| EvalError::Invalid("the texture has no white strip".into()))?;
        let y = patch_means(std::slice::from_ref(white), xyz, self.width)[0][1];
        if !(y.is_finite() && y > 0.0) {
            return Err(EvalError::Invalid(format!(
                "the texture's white strip has no signal (Y {y})"
            )));
        }
        Ok(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ideal_image_scores_zero_and_a_blur_or_a_cast_does_not() {
        let camera = crate::test_support::paper_camera();
        let setup = ChartSetup {
            noise: false,
            ..ChartSetup::default()
        };
        let cap = simulate_texture(&camera, "Tungsten", None, &setup, 48).unwrap();
        assert_eq!((cap.width, cap.height), (48, 48));
        assert!(cap.score(&cap.ideal_image).unwrap() < 1e-9);
        // a brighter copy of the ideal image is the same after normalisation
        let brighter: Vec<f32> = cap.ideal_image.iter().map(|v| v * 3.0).collect();
        assert!(cap.score(&brighter).unwrap() < 1e-6);
        // a colour cast is an error
        let cast: Vec<f32> = cap
            .ideal_image
            .chunks(3)
            .flat_map(|v| [v[0] * 1.1, v[1], v[2] * 0.8])
            .collect();
        assert!(cap.score(&cast).unwrap() > 1.0);
        assert!(cap.score(&cast[3..]).is_err());
        assert!(simulate_texture(&camera, "D65", None, &setup, 8).is_err());
    }
}
