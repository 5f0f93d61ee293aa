use serde::{Deserialize, Serialize};

use super::{SpectralError, WavelengthGrid};

/// What a sampled spectrum is taken to be outside its sampled range.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Extrapolation {
    /// Zero outside the samples (colour-matching functions, lights, filters).
    Zero,
    /// The first/last sample held constant (reflectances).
    Hold,
}

/// A spectrum sampled at arbitrary, strictly increasing wavelengths (a CSV
/// column, a crate table). It is read as the piecewise-linear function through
/// its samples.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Samples {
    wavelengths: Vec<f64>,
    values: Vec<f64>,
}

impl Samples {
    pub fn new(wavelengths: Vec<f64>, values: Vec<f64>) -> Result<Self, SpectralError> {
        if wavelengths.len() != values.len() {
            return Err(SpectralError::InvalidSamples(format!(
                "{} wavelengths but {} values",
                wavelengths.len(),
                values.len()
            )));
        }
        if wavelengths.len() < 2 {
            return Err(SpectralError::InvalidSamples(
                "at least two samples are needed".into(),
            ));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(SpectralError::InvalidSamples(format!(
                "value at {} nm is not finite",
                wavelengths[i]
            )));
        }
        for w in wavelengths.windows(2) {
            if !(w[0].is_finite() && w[1].is_finite() && w[1] > w[0]) {
                return Err(SpectralError::InvalidSamples(format!(
                    "wavelengths must be finite and strictly increasing ({} then {})",
                    w[0], w[1]
                )));
            }
        }
        Ok(Self {
            wavelengths,
            values,
        })
    }

    /// Samples from a built-in table whose layout is fixed and tested.
    pub(crate) fn from_trusted(wavelengths: Vec<f64>, values: Vec<f64>) -> Self {
        debug_assert_eq!(wavelengths.len(), values.len());
        Self {
            wavelengths,
            values,
        }
    }

    pub fn wavelengths(&self) -> &[f64] {
        &self.wavelengths
    }

    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Linear interpolation at `x` with the given extrapolation.
    pub fn at(&self, x: f64, ext: Extrapolation) -> f64 {
        let xs = &self.wavelengths;
        let ys = &self.values;
        let n = xs.len();
        if x < xs[0] {
            return match ext {
                Extrapolation::Zero => 0.0,
                Extrapolation::Hold => ys[0],
            };
        }
        if x > xs[n - 1] {
            return match ext {
                Extrapolation::Zero => 0.0,
                Extrapolation::Hold => ys[n - 1],
            };
        }
        let j = xs.partition_point(|&v| v <= x).clamp(1, n - 1);
        let (x0, x1, y0, y1) = (xs[j - 1], xs[j], ys[j - 1], ys[j]);
        y0 + (y1 - y0) * (x - x0) / (x1 - x0)
    }

    /// Exact integral of the piecewise-linear function over `[a, b]`.
    pub fn integrate(&self, a: f64, b: f64, ext: Extrapolation) -> f64 {
        if b <= a {
            return 0.0;
        }
        let xs = &self.wavelengths;
        let (lo, hi) = (xs[0], xs[xs.len() - 1]);
        let mut cuts = Vec::with_capacity(16);
        cuts.push(a);
        let first = xs.partition_point(|&v| v <= a);
        for &x in &xs[first..] {
            if x >= b {
                break;
            }
            cuts.push(x);
        }
        cuts.push(b);
        let (left, right) = match ext {
            Extrapolation::Zero => (0.0, 0.0),
            Extrapolation::Hold => (self.values[0], self.values[self.values.len() - 1]),
        };
        let mut sum = 0.0;
        for w in cuts.windows(2) {
            let (p, q) = (w[0], w[1]);
            let mid = 0.5 * (p + q);
            sum += if mid < lo {
                left * (q - p)
            } else if mid > hi {
                right * (q - p)
            } else {
                let fp = self.at(p.max(lo), Extrapolation::Hold);
                let fq = self.at(q.min(hi), Extrapolation::Hold);
                0.5 * (fp + fq) * (q - p)
            };
        }
        sum
    }

    /// Resample onto `grid` by averaging over each band (area-preserving):
    /// band `i` gets the mean of the function over
    /// `[λ_i − step/2, λ_i + step/2]`. Narrow emission lines keep their energy.
    pub fn resample(&self, grid: &WavelengthGrid, ext: Extrapolation) -> Spectrum {
        let h = grid.step_nm;
        let values = (0..grid.n)
            .map(|i| {
                let c = grid.wavelength(i);
                self.integrate(c - 0.5 * h, c + 0.5 * h, ext) / h
            })
            .collect();
        Spectrum {
            grid: *grid,
            values,
        }
    }

    /// Point-sample onto `grid` (only for comparison with band averaging).
    pub fn point_sample(&self, grid: &WavelengthGrid, ext: Extrapolation) -> Spectrum {
        Spectrum {
            grid: *grid,
            values: grid
                .wavelengths()
                .iter()
                .map(|&w| self.at(w, ext))
                .collect(),
        }
    }
}

/// A spectrum on a uniform [`WavelengthGrid`]: one value per band.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Spectrum {
    grid: WavelengthGrid,
    values: Vec<f64>,
}

impl Spectrum {
    pub fn new(grid: WavelengthGrid, values: Vec<f64>) -> Result<Self, SpectralError> {
        if values.len() != grid.n {
            return Err(SpectralError::LengthMismatch {
                expected: grid.n,
                got: values.len(),
            });
        }
        Ok(Self { grid, values })
    }

    pub fn from_fn(grid: WavelengthGrid, f: impl Fn(f64) -> f64) -> Self {
        let values = (0..grid.n).map(|i| f(grid.wavelength(i))).collect();
        Self { grid, values }
    }

    pub fn constant(grid: WavelengthGrid, v: f64) -> Self {
        Self {
            grid,
            values: vec![v; grid.n],
        }
    }

    pub fn grid(&self) -> &WavelengthGrid {
        &self.grid
    }

    pub fn values(&self) -> &[f64] {
        &self.values
    }

    pub fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }

    pub fn into_values(self) -> Vec<f64> {
        self.values
    }

    pub fn scaled(&self, k: f64) -> Self {
        Self {
            grid: self.grid,
            values: self.values.iter().map(|v| v * k).collect(),
        }
    }

    /// Band-wise product (e.g. reflectance × illuminant). Panics never: grids
    /// must match, which the caller guarantees by resampling onto one grid.
    pub fn product(&self, other: &Spectrum) -> Result<Self, SpectralError> {
        self.check_grid(other)?;
        Ok(Self {
            grid: self.grid,
            values: self
                .values
                .iter()
                .zip(&other.values)
                .map(|(a, b)| a * b)
                .collect(),
        })
    }

    /// Σ aᵢ bᵢ Δλ: the integral of the product over the grid.
    pub fn integral_of_product(&self, other: &Spectrum) -> Result<f64, SpectralError> {
        self.check_grid(other)?;
        Ok(self
            .values
            .iter()
            .zip(&other.values)
            .map(|(a, b)| a * b)
            .sum::<f64>()
            * self.grid.step_nm)
    }

    pub fn max(&self) -> f64 {
        self.values
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    }

    pub fn is_finite(&self) -> bool {
        self.values.iter().all(|v| v.is_finite())
    }

    fn check_grid(&self, other: &Spectrum) -> Result<(), SpectralError> {
        if self.grid != other.grid {
            return Err(SpectralError::GridMismatch(self.grid, other.grid));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_average_preserves_area_of_a_narrow_line() {
        // A 2 nm wide triangle line of area 1 at 546 nm.
        let s = Samples::new(
            vec![400.0, 545.0, 546.0, 547.0, 700.0],
            vec![0.0, 0.0, 1.0, 0.0, 0.0],
        )
        .unwrap();
        let g = WavelengthGrid::default();
        let r = s.resample(&g, Extrapolation::Zero);
        let area: f64 = r.values().iter().sum::<f64>() * g.step_nm;
        assert!((area - 1.0).abs() < 1e-12, "area {area}");
        // Point sampling at 540/550 misses it entirely.
        let p = s.point_sample(&g, Extrapolation::Zero);
        assert_eq!(p.values().iter().sum::<f64>(), 0.0);
    }

    #[test]
    fn linear_function_resamples_exactly() {
        let s = Samples::new(vec![380.0, 780.0], vec![0.0, 400.0]).unwrap();
        let g = WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
        let r = s.resample(&g, Extrapolation::Zero);
        for (i, v) in r.values().iter().enumerate() {
            assert!((v - (g.wavelength(i) - 380.0)).abs() < 1e-9);
        }
    }

    #[test]
    fn hold_extrapolation_and_errors() {
        let s = Samples::new(vec![410.0, 690.0], vec![0.5, 0.5]).unwrap();
        let r = s.resample(&WavelengthGrid::default(), Extrapolation::Hold);
        assert!(r.values().iter().all(|v| (v - 0.5).abs() < 1e-12));
        assert!(Samples::new(vec![400.0, 400.0], vec![1.0, 1.0]).is_err());
        assert!(Samples::new(vec![400.0, 410.0], vec![1.0, f64::NAN]).is_err());
        assert!(WavelengthGrid::new(400.0, 705.0, 10.0).is_err());
        assert_eq!(WavelengthGrid::new(400.0, 700.0, 10.0).unwrap().n, 31);
    }
}
