//! The camera's colour matrix in the DNG sense: XYZ under a light → the camera's channel
//! responses (ColorMatrix1), fitted by least squares over surface reflectances, so that a
//! DNG written from a simulation tells other raw readers how its channels relate to colour.

use nalgebra::{Matrix3, Vector3};

use super::{Camera, CameraError};
use crate::spectral::{Extrapolation, Samples, Spectrum};

impl Camera {
    /// Per channel (CFA channel order), the row `m` with `response ≈ m · XYZ` over
    /// `reflectances` under `illuminant`; XYZ normalised so the perfect white has Y = 1, and
    /// the matrix scaled so that the white's largest channel is 1 (the DNG convention).
    pub fn xyz_to_camera_matrix(
        &self,
        illuminant: &Samples,
        reflectances: &[Spectrum],
    ) -> Result<Vec<[f64; 3]>, CameraError> {
        if reflectances.len() < 3 {
            return Err(CameraError::InvalidArgument(
                "a colour matrix needs at least 3 reflectances".into(),
            ));
        }
        let spd = illuminant.resample(self.grid(), Extrapolation::Zero);
        let white = Spectrum::constant(*self.grid(), 1.0);
        let (_, wx) = self.reflectance_response(&white, &spd)?;
        if !(wx[1].is_finite() && wx[1] > 0.0) {
            return Err(CameraError::InvalidArgument(
                "the light has no luminance".into(),
            ));
        }
        let nc = self.cfa().n_channels();
        let mut xtx = Matrix3::<f64>::zeros();
        let mut xtc = vec![Vector3::<f64>::zeros(); nc];
        for r in reflectances {
            let (c, x) = self.reflectance_response(r, &spd)?;
            let x = Vector3::from_fn(|k, _| x[k] / wx[1]);
            xtx += x * x.transpose();
            for (acc, v) in xtc.iter_mut().zip(&c) {
                *acc += x * *v;
            }
        }
        let inv = xtx.try_inverse().ok_or_else(|| {
            CameraError::InvalidArgument("the reflectances' XYZs are degenerate".into())
        })?;
        let rows: Vec<Vector3<f64>> = xtc.iter().map(|v| inv * v).collect();
        let w = Vector3::from_fn(|k, _| wx[k] / wx[1]);
        let max = rows.iter().map(|m| m.dot(&w)).fold(0.0, f64::max);
        if !(max.is_finite() && max > 0.0) {
            return Err(CameraError::InvalidArgument(
                "the camera does not respond to white under this light".into(),
            ));
        }
        Ok(rows
            .iter()
            .map(|m| [m[0] / max, m[1] / max, m[2] / max])
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::SensorDesign;
    use crate::spectral::{WavelengthGrid, ces_reflectances, cie_illuminant};

    #[test]
    fn the_matrix_maps_white_to_a_largest_channel_of_one_and_predicts_responses() {
        let grid = WavelengthGrid::default();
        let cam = Camera::new(&SensorDesign::paper_default(), grid, None).unwrap();
        let refl: Vec<Spectrum> = ces_reflectances()
            .into_iter()
            .map(|(_, s)| s.resample(&grid, Extrapolation::Hold))
            .collect();
        let d65 = cie_illuminant("D65").unwrap();
        let m = cam.xyz_to_camera_matrix(&d65, &refl).unwrap();
        assert_eq!(m.len(), cam.cfa().n_channels());
        let spd = d65.resample(&grid, Extrapolation::Zero);
        let (wc, wx) = cam
            .reflectance_response(&Spectrum::constant(grid, 1.0), &spd)
            .unwrap();
        let w = [wx[0] / wx[1], 1.0, wx[2] / wx[1]];
        let pred: Vec<f64> = m
            .iter()
            .map(|r| r[0] * w[0] + r[1] * w[1] + r[2] * w[2])
            .collect();
        let max = pred.iter().copied().fold(0.0, f64::max);
        assert!((max - 1.0).abs() < 1e-12, "{pred:?}");
        // the predicted white has the camera's white's channel ratios (near-colorimetric
        // filters: within a few per cent)
        let wmax = wc.iter().copied().fold(0.0, f64::max);
        for (p, c) in pred.iter().zip(&wc) {
            assert!((p - c / wmax).abs() < 0.05, "{pred:?} vs {wc:?}");
        }
        assert!(cam.xyz_to_camera_matrix(&d65, &refl[..2]).is_err());
    }
}
