//! Lifting an sRGB image to a spectral scene through a smooth reflectance
//! basis (the mean and first three principal components of the Munsell set).

use std::path::Path;

use rayon::prelude::*;

use crate::colour::{Cmfs, LINEAR_SRGB_TO_XYZ, XYZ_TO_LINEAR_SRGB, mat3_mul_vec, srgb_decode};
use crate::spectral::{
    Extrapolation, Spectrum, WavelengthGrid, cie_illuminant, munsell_reflectances,
};

use super::options::new_cube;
use super::pca::Pca;
use super::{Scene, SceneError, SceneOptions};

/// Maps sRGB colours to reflectances `clip(mean + Σ wₖ·pcₖ, 0, 1)` whose XYZ
/// under D65 matches the colour's XYZ. The sRGB white (D65 with x = 0.3127,
/// y = 0.3290) is first mapped onto the white of the spectral D65 on the
/// grid by scaling X, Y, Z (a ≤ 0.3 % correction), so RGB (1, 1, 1) asks for
/// the XYZ of a perfect white.
#[derive(Clone, Debug)]
pub struct SrgbLift {
    grid: WavelengthGrid,
    mean: Vec<f64>,
    basis: [Vec<f64>; 3],
    /// (A·B)⁻¹: XYZ offsets → basis weights.
    solve: [[f64; 3]; 3],
    /// A·mean: XYZ of the mean reflectance.
    xyz_mean: [f64; 3],
    /// Per-channel factor from sRGB-white XYZ to spectral-D65-white XYZ.
    white_scale: [f64; 3],
    /// Rows of A: reflectance → XYZ under D65 (perfect white Y = 1).
    to_xyz: [Vec<f64>; 3],
}

impl SrgbLift {
    /// The basis and solver for `grid` (at least 3 bands).
    pub fn new(grid: &WavelengthGrid) -> Result<Self, SceneError> {
        if grid.n < 3 {
            return Err(SceneError::Invalid(format!(
                "lifting sRGB to spectra needs at least 3 bands, the grid has {}",
                grid.n
            )));
        }
        let data: Vec<Vec<f64>> = munsell_reflectances()
            .iter()
            .map(|(_, s)| s.resample(grid, Extrapolation::Hold).into_values())
            .collect();
        let pca = Pca::fit(&data, 3)?;
        let d65 = cie_illuminant("D65")
            .ok_or_else(|| SceneError::Invalid("built-in D65 is missing".into()))?
            .resample(grid, Extrapolation::Zero);
        let cmfs = Cmfs::cie1931(grid);
        let to_xyz = cmfs
            .reflectance_weights(&d65)
            .map_err(|e| SceneError::Invalid(format!("D65 on the scene grid: {e}")))?;
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let mut m = [[0.0; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (k, v) in row.iter_mut().enumerate() {
                *v = dot(&to_xyz[i], &pca.components[k]);
            }
        }
        let solve = crate::colour::checked_inverse3(m).ok_or_else(|| {
            SceneError::Invalid(format!(
                "the reflectance basis is degenerate on {grid:?} (its XYZ matrix is singular)"
            ))
        })?;
        let xyz_mean = [0, 1, 2].map(|i| dot(&to_xyz[i], &pca.mean));
        let white_spec = [0, 1, 2].map(|i| to_xyz[i].iter().sum::<f64>());
        let white_srgb = mat3_mul_vec(&LINEAR_SRGB_TO_XYZ, [1.0; 3]);
        let white_scale = [0, 1, 2].map(|i| white_spec[i] / white_srgb[i]);
        let [c0, c1, c2]: [Vec<f64>; 3] = pca
            .components
            .try_into()
            .map_err(|_| SceneError::Invalid("PCA returned the wrong count".into()))?;
        Ok(Self {
            grid: *grid,
            mean: pca.mean,
            basis: [c0, c1, c2],
            solve,
            xyz_mean,
            white_scale,
            to_xyz,
        })
    }

    pub fn grid(&self) -> &WavelengthGrid {
        &self.grid
    }

    /// Basis weights for a linear-sRGB colour.
    pub fn weights(&self, linear_rgb: [f64; 3]) -> [f64; 3] {
        let xyz = mat3_mul_vec(&LINEAR_SRGB_TO_XYZ, linear_rgb);
        let t = [0, 1, 2].map(|i| xyz[i] * self.white_scale[i] - self.xyz_mean[i]);
        mat3_mul_vec(&self.solve, t)
    }

    /// The reflectance (clipped to [0, 1]) of a linear-sRGB colour, into
    /// `out` (one value per band); returns whether any band was clipped.
    pub fn reflectance_into(&self, linear_rgb: [f64; 3], out: &mut [f64]) -> bool {
        let w = self.weights(linear_rgb);
        let mut clipped = false;
        for (b, o) in out.iter_mut().enumerate().take(self.grid.n) {
            let v = self.mean[b]
                + w[0] * self.basis[0][b]
                + w[1] * self.basis[1][b]
                + w[2] * self.basis[2][b];
            clipped |= !(0.0..=1.0).contains(&v);
            *o = v.clamp(0.0, 1.0);
        }
        clipped
    }

    /// The reflectance of a linear-sRGB colour as a spectrum.
    pub fn reflectance(&self, linear_rgb: [f64; 3]) -> Spectrum {
        let mut s = Spectrum::constant(self.grid, 0.0);
        self.reflectance_into(linear_rgb, s.values_mut());
        s
    }

    /// The linear sRGB a reflectance shows under D65 (the inverse of the
    /// lift where nothing clips).
    pub fn linear_rgb_of(&self, reflectance: &[f64]) -> [f64; 3] {
        let xyz = [0, 1, 2].map(|i| {
            self.to_xyz[i]
                .iter()
                .zip(reflectance)
                .map(|(a, r)| a * r)
                .sum::<f64>()
                / self.white_scale[i]
        });
        mat3_mul_vec(&XYZ_TO_LINEAR_SRGB, xyz)
    }
}

/// Build the scene from per-pixel linear sRGB.
fn lift(
    opts: &SceneOptions,
    rows: usize,
    cols: usize,
    linear: impl Fn(usize) -> [f64; 3] + Sync,
) -> Result<Scene, SceneError> {
    opts.validate()?;
    let lift = SrgbLift::new(&opts.grid)?;
    let mut cube = new_cube(&opts.grid, rows, cols)?;
    let pixels = rows * cols;
    let mut weights = vec![[0.0f64; 3]; pixels];
    weights
        .par_chunks_mut(cols)
        .enumerate()
        .for_each(|(r, row)| {
            for (c, w) in row.iter_mut().enumerate() {
                *w = lift.weights(linear(r * cols + c));
            }
        });
    let data = cube
        .as_slice_mut()
        .ok_or_else(|| SceneError::Invalid("reflectance cube is not contiguous".into()))?;
    data.par_chunks_mut(pixels)
        .enumerate()
        .for_each(|(b, band)| {
            let (m, p0, p1, p2) = (
                lift.mean[b],
                lift.basis[0][b],
                lift.basis[1][b],
                lift.basis[2][b],
            );
            for (v, w) in band.iter_mut().zip(&weights) {
                *v = (m + w[0] * p0 + w[1] * p1 + w[2] * p2).clamp(0.0, 1.0) as f32;
            }
        });
    Ok(opts.scene("srgb-image", cube, Vec::new()))
}

/// Lift an 8-bit sRGB image to a spectral scene (see [`SrgbLift`]).
pub fn from_srgb_image(opts: &SceneOptions, img: &image::RgbImage) -> Result<Scene, SceneError> {
    let decode: [f64; 256] = std::array::from_fn(|i| srgb_decode(i as f64 / 255.0));
    let (w, h) = (img.width() as usize, img.height() as usize);
    let raw = img.as_raw();
    lift(opts, h, w, |i| {
        [
            decode[raw[3 * i] as usize],
            decode[raw[3 * i + 1] as usize],
            decode[raw[3 * i + 2] as usize],
        ]
    })
}

/// Lift encoded sRGB values in [0, 1] (row-major RGB triplets, values
/// clamped) to a spectral scene.
pub fn from_srgb_pixels(
    opts: &SceneOptions,
    rows: usize,
    cols: usize,
    encoded_rgb: &[f32],
) -> Result<Scene, SceneError> {
    let n = rows
        .checked_mul(cols)
        .and_then(|p| p.checked_mul(3))
        .ok_or_else(|| SceneError::Invalid(format!("image size {rows} × {cols} overflows")))?;
    if encoded_rgb.len() != n {
        return Err(SceneError::Invalid(format!(
            "{rows} × {cols} RGB image needs {n} values, got {}",
            encoded_rgb.len()
        )));
    }
    let dec = |v: f32| {
        let v = if v.is_nan() {
            0.0
        } else {
            (v as f64).clamp(0.0, 1.0)
        };
        srgb_decode(v)
    };
    lift(opts, rows, cols, |i| {
        [
            dec(encoded_rgb[3 * i]),
            dec(encoded_rgb[3 * i + 1]),
            dec(encoded_rgb[3 * i + 2]),
        ]
    })
}

/// Read an sRGB PNG or TIFF (8 or 16 bit, grey or colour; alpha ignored) and
/// lift it to a spectral scene named after the file.
pub fn from_srgb_file(opts: &SceneOptions, path: &Path) -> Result<Scene, SceneError> {
    let err = |msg: String| SceneError::Image {
        path: path.display().to_string(),
        msg,
    };
    let img = image::ImageReader::open(path)
        .map_err(|e| err(e.to_string()))?
        .with_guessed_format()
        .map_err(|e| err(e.to_string()))?
        .decode()
        .map_err(|e| err(e.to_string()))?;
    let rgb = img.to_rgb32f();
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let mut scene = from_srgb_pixels(opts, h, w, rgb.as_raw())?;
    scene.name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "srgb-image".into());
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn white_lifts_to_a_near_perfect_white_and_round_trips() {
        let lift = SrgbLift::new(&WavelengthGrid::default()).unwrap();
        let mut r = vec![0.0; 31];
        lift.reflectance_into([0.2, 0.3, 0.1], &mut r);
        let back = lift.linear_rgb_of(&r);
        for (a, b) in back.iter().zip([0.2, 0.3, 0.1]) {
            assert!((a - b).abs() < 1e-9, "{back:?}");
        }
        let grid1 = WavelengthGrid::new(500.0, 510.0, 10.0).unwrap();
        assert!(SrgbLift::new(&grid1).is_err());
    }
}
