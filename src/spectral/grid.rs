use serde::{Deserialize, Serialize};

use super::SpectralError;

/// A uniform wavelength grid: band `i` is centred on `start_nm + i * step_nm`
/// and spans `step_nm` (half a step either side of its centre).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WavelengthGrid {
    pub start_nm: f64,
    pub step_nm: f64,
    pub n: usize,
}

impl Default for WavelengthGrid {
    /// 400–700 nm at 10 nm: 31 bands (docs/design.md §3).
    fn default() -> Self {
        Self {
            start_nm: 400.0,
            step_nm: 10.0,
            n: 31,
        }
    }
}

impl WavelengthGrid {
    /// A grid from `start_nm` to `end_nm` inclusive at `step_nm`.
    pub fn new(start_nm: f64, end_nm: f64, step_nm: f64) -> Result<Self, SpectralError> {
        if !(start_nm.is_finite() && end_nm.is_finite() && step_nm.is_finite()) {
            return Err(SpectralError::InvalidGrid("non-finite bound".into()));
        }
        if step_nm <= 0.0 || end_nm < start_nm || start_nm <= 0.0 {
            return Err(SpectralError::InvalidGrid(format!(
                "start {start_nm} nm, end {end_nm} nm, step {step_nm} nm"
            )));
        }
        let span = (end_nm - start_nm) / step_nm;
        let n = span.round() as usize + 1;
        if (span - span.round()).abs() > 1e-6 {
            return Err(SpectralError::InvalidGrid(format!(
                "({end_nm} - {start_nm}) is not a multiple of the step {step_nm}"
            )));
        }
        if n > 100_000 {
            return Err(SpectralError::InvalidGrid(format!("{n} bands is too many")));
        }
        Ok(Self {
            start_nm,
            step_nm,
            n,
        })
    }

    pub fn len(&self) -> usize {
        self.n
    }

    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Centre wavelength of band `i`, in nm.
    pub fn wavelength(&self, i: usize) -> f64 {
        self.start_nm + i as f64 * self.step_nm
    }

    pub fn end_nm(&self) -> f64 {
        self.wavelength(self.n.saturating_sub(1))
    }

    pub fn wavelengths(&self) -> Vec<f64> {
        (0..self.n).map(|i| self.wavelength(i)).collect()
    }
}
