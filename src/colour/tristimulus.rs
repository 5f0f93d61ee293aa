//! Tristimulus integration with the CIE 1931 2° observer.

use crate::spectral::{Extrapolation, Spectrum, WavelengthGrid, cie1931_cmfs};

use super::{ColourError, Xyz};

/// Colour-matching functions on a wavelength grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Cmfs {
    pub grid: WavelengthGrid,
    pub xbar: Spectrum,
    pub ybar: Spectrum,
    pub zbar: Spectrum,
}

impl Cmfs {
    /// The CIE 1931 2° observer band-averaged (area-preserving) onto `grid`,
    /// zero outside the tabulated 380–780 nm.
    pub fn cie1931(grid: &WavelengthGrid) -> Cmfs {
        let [x, y, z] = cie1931_cmfs();
        Cmfs {
            grid: *grid,
            xbar: x.resample(grid, Extrapolation::Zero),
            ybar: y.resample(grid, Extrapolation::Zero),
            zbar: z.resample(grid, Extrapolation::Zero),
        }
    }

    /// X, Y, Z = Σ cmf·spd·Δλ (no normalisation).
    pub fn tristimulus(&self, spd: &Spectrum) -> Result<Xyz, ColourError> {
        Ok([
            self.xbar.integral_of_product(spd)?,
            self.ybar.integral_of_product(spd)?,
            self.zbar.integral_of_product(spd)?,
        ])
    }

    /// The white point of an illuminant, normalised to Y = 1.
    pub fn white(&self, illuminant: &Spectrum) -> Result<Xyz, ColourError> {
        let w = self.tristimulus(illuminant)?;
        let y = luminance_norm(w[1])?;
        Ok(w.map(|v| v / y))
    }

    /// XYZ of a surface under an illuminant, normalised so that a perfect
    /// white (reflectance 1) has Y = 1.
    pub fn reflectance_xyz(
        &self,
        reflectance: &Spectrum,
        illuminant: &Spectrum,
    ) -> Result<Xyz, ColourError> {
        let y = luminance_norm(self.ybar.integral_of_product(illuminant)?)?;
        let lit = reflectance.product(illuminant)?;
        Ok(self.tristimulus(&lit)?.map(|v| v / y))
    }

    /// The per-band weights `cmf·illuminant·Δλ / Y_white` that turn a
    /// reflectance on this grid into XYZ (perfect white Y = 1) with one dot
    /// product per channel; for hot loops over many reflectances.
    pub fn reflectance_weights(&self, illuminant: &Spectrum) -> Result<[Vec<f64>; 3], ColourError> {
        let y = luminance_norm(self.ybar.integral_of_product(illuminant)?)?;
        let h = self.grid.step_nm;
        let w = |c: &Spectrum| -> Result<Vec<f64>, ColourError> {
            Ok(c.product(illuminant)?
                .values()
                .iter()
                .map(|v| v * h / y)
                .collect())
        };
        Ok([w(&self.xbar)?, w(&self.ybar)?, w(&self.zbar)?])
    }
}

fn luminance_norm(y: f64) -> Result<f64, ColourError> {
    if !y.is_finite() {
        return Err(ColourError::NonFinite("illuminant luminance"));
    }
    if y <= 0.0 {
        return Err(ColourError::ZeroLuminance(y));
    }
    Ok(y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_energy_white_is_one_third() {
        let g = WavelengthGrid::new(380.0, 780.0, 5.0).unwrap();
        let c = Cmfs::cie1931(&g);
        let w = c.white(&Spectrum::constant(g, 1.0)).unwrap();
        let s = w[0] + w[1] + w[2];
        assert!((w[0] / s - 1.0 / 3.0).abs() < 1e-3, "{w:?}");
        assert!((w[1] / s - 1.0 / 3.0).abs() < 1e-3, "{w:?}");
    }

    #[test]
    fn perfect_white_has_y_one_and_errors_are_clear() {
        let g = WavelengthGrid::default();
        let c = Cmfs::cie1931(&g);
        let ill = Spectrum::from_fn(g, |l| l / 500.0);
        let xyz = c
            .reflectance_xyz(&Spectrum::constant(g, 1.0), &ill)
            .unwrap();
        assert!((xyz[1] - 1.0).abs() < 1e-12);
        let w = c.reflectance_weights(&ill).unwrap();
        let grey = Spectrum::constant(g, 0.5);
        let dot: f64 = w[1].iter().zip(grey.values()).map(|(a, b)| a * b).sum();
        assert!((dot - 0.5).abs() < 1e-12);
        assert!(matches!(
            c.white(&Spectrum::constant(g, 0.0)),
            Err(ColourError::ZeroLuminance(_))
        ));
        let other = WavelengthGrid::new(400.0, 700.0, 5.0).unwrap();
        assert!(c.white(&Spectrum::constant(other, 1.0)).is_err());
    }
}
