//! A camera's response to white under a light, and the colour temperature whose white
//! response best matches a recorded neutral (a DNG's AsShotNeutral).
//!
//! A raw file's neutral is the camera's channel responses to a white surface under the scene
//! light, up to scale. Under Planckian (below 4000 K) and CIE daylight (from 4000 K) lights,
//! exactly as `cct:K` defines them, the camera's own white responses trace a curve; the match
//! is the point on it closest to the neutral in log ratios (scale removed).

use super::{Camera, CameraError};
use crate::spectral::{Extrapolation, IlluminantSpec, Samples, Spectrum};

/// The colour temperatures searched, in kelvin.
pub const NEUTRAL_CCT_RANGE: (f64, f64) = (2000.0, 12000.0);

/// The colour temperature matching a neutral.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeutralMatch {
    /// Kelvin, rounded to a whole number, within [`NEUTRAL_CCT_RANGE`].
    pub cct: f64,
    /// Root-mean-square difference of the log channel ratios at that temperature (0 when the
    /// neutral lies on the curve).
    pub rms_log_error: f64,
}

impl NeutralMatch {
    /// The illuminant spec to correct with: `cct:K`.
    pub fn spec(&self) -> String {
        format!("cct:{}", self.cct)
    }
}

impl Camera {
    /// Noise-free responses of every channel (CFA channel order) to a perfect white diffuser
    /// under `illuminant`, in volts per unit radiance scale and exposure.
    pub fn white_response(&self, illuminant: &Samples) -> Result<Vec<f64>, CameraError> {
        let white = Spectrum::constant(*self.grid(), 1.0);
        self.surface_response(&white, illuminant)
    }

    /// Noise-free responses of every channel to `surface` (on the camera's grid) under
    /// `illuminant`.
    pub fn surface_response(
        &self,
        surface: &Spectrum,
        illuminant: &Samples,
    ) -> Result<Vec<f64>, CameraError> {
        let spd = illuminant.resample(self.grid(), Extrapolation::Zero);
        Ok(self.reflectance_response(surface, &spd)?.0)
    }

    /// [`white_response`](Self::white_response) divided by its largest value: what a DNG
    /// records as AsShotNeutral (per channel name).
    pub fn white_neutral(&self, illuminant: &Samples) -> Result<Vec<(String, f64)>, CameraError> {
        let r = self.white_response(illuminant)?;
        let max = r.iter().copied().fold(0.0, f64::max);
        if !(max.is_finite() && max > 0.0) {
            return Err(CameraError::InvalidArgument(
                "the camera does not respond to white under this light".into(),
            ));
        }
        Ok(self
            .cfa()
            .channel_names
            .iter()
            .cloned()
            .zip(r.iter().map(|v| v / max))
            .collect())
    }

    /// The colour temperature (2000–12000 K, Planckian below 4000 K and daylight above, as
    /// `cct:K`) under which this camera's white response best matches `neutral`: the least
    /// squares fit of the log channel ratios, scale removed. `neutral` gives a positive value
    /// for every channel of the camera, by name (case-insensitive); other names are ignored.
    pub fn cct_from_neutral(&self, neutral: &[(String, f64)]) -> Result<NeutralMatch, CameraError> {
        self.cct_from_surface(neutral, &Spectrum::constant(*self.grid(), 1.0))
    }

    /// As [`cct_from_neutral`](Self::cct_from_neutral), for channel responses to `surface`
    /// (on the camera's grid) rather than to white: e.g. a scene's mean, matched against the
    /// mean of natural surfaces.
    pub fn cct_from_surface(
        &self,
        neutral: &[(String, f64)],
        surface: &Spectrum,
    ) -> Result<NeutralMatch, CameraError> {
        let names = &self.cfa().channel_names;
        let mut log_n = Vec::with_capacity(names.len());
        for name in names {
            let v = neutral
                .iter()
                .find(|(n, _)| n.eq_ignore_ascii_case(name))
                .map(|(_, v)| *v)
                .ok_or_else(|| {
                    CameraError::InvalidArgument(format!(
                        "the neutral has no value for the camera's channel {name} (it gives {})",
                        neutral
                            .iter()
                            .map(|(n, _)| n.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
            if !(v.is_finite() && v > 0.0) {
                return Err(CameraError::InvalidArgument(format!(
                    "the neutral's {name} value is {v}; positive values are expected"
                )));
            }
            log_n.push(v.ln());
        }
        let cost = |mired: f64| -> Result<f64, CameraError> {
            let spd = IlluminantSpec::Cct(1e6 / mired).resolve(None)?.spd;
            let r = self.surface_response(surface, &spd)?;
            let d: Vec<f64> = log_n
                .iter()
                .zip(&r)
                .map(|(n, r)| n - r.max(f64::MIN_POSITIVE).ln())
                .collect();
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            Ok((d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt())
        };
        // a scan in mireds (even steps of perceived colour), then a golden-section refinement
        let (lo, hi) = (1e6 / NEUTRAL_CCT_RANGE.1, 1e6 / NEUTRAL_CCT_RANGE.0);
        let step = 2.0;
        let n = ((hi - lo) / step).ceil() as usize;
        let mut best = (f64::INFINITY, lo);
        for i in 0..=n {
            let m = (lo + step * i as f64).min(hi);
            let c = cost(m)?;
            if c < best.0 {
                best = (c, m);
            }
        }
        let (mut a, mut b) = ((best.1 - step).max(lo), (best.1 + step).min(hi));
        let g = (5f64.sqrt() - 1.0) / 2.0;
        let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
        let (mut f1, mut f2) = (cost(x1)?, cost(x2)?);
        for _ in 0..30 {
            if f1 < f2 {
                b = x2;
                (x2, f2) = (x1, f1);
                x1 = b - g * (b - a);
                f1 = cost(x1)?;
            } else {
                a = x1;
                (x1, f1) = (x2, f2);
                x2 = a + g * (b - a);
                f2 = cost(x2)?;
            }
        }
        let m = if f1.min(f2) < best.0 {
            (a + b) / 2.0
        } else {
            best.1
        };
        let cct = (1e6 / m)
            .round()
            .clamp(NEUTRAL_CCT_RANGE.0, NEUTRAL_CCT_RANGE.1);
        Ok(NeutralMatch {
            cct,
            rms_log_error: cost(1e6 / cct)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::SensorDesign;
    use crate::spectral::WavelengthGrid;

    fn camera(design: SensorDesign) -> Camera {
        Camera::new(&design, WavelengthGrid::default(), None).unwrap()
    }

    fn light(spec: &str) -> Samples {
        IlluminantSpec::parse(spec)
            .unwrap()
            .resolve(None)
            .unwrap()
            .spd
    }

    #[test]
    fn smooth_lights_come_back_at_their_temperature() {
        let cam = camera(SensorDesign::paper_default());
        for k in [2000.0, 2856.0, 3200.0, 4500.0, 6504.0, 9000.0, 12000.0] {
            let n = cam.white_neutral(&light(&format!("cct:{k}"))).unwrap();
            let m = cam.cct_from_neutral(&n).unwrap();
            assert!((m.cct - k).abs() <= 2.0, "{k} K came back as {} K", m.cct);
            assert!(m.rms_log_error < 1e-3, "{k} K: {}", m.rms_log_error);
            assert_eq!(m.spec(), format!("cct:{}", m.cct));
        }
    }

    #[test]
    fn standard_lights_match_nearby_temperatures() {
        let cam = camera(SensorDesign::paper_default());
        // CIE A is a 2856 K blackbody; D50 and D65 are daylights of 5003 and 6504 K
        for (spec, k, tol) in [
            ("A", 2856.0, 5.0),
            ("D50", 5003.0, 60.0),
            ("D65", 6504.0, 80.0),
        ] {
            let m = cam
                .cct_from_neutral(&cam.white_neutral(&light(spec)).unwrap())
                .unwrap();
            eprintln!("{spec}: {} K (rms log error {:.4})", m.cct, m.rms_log_error);
            assert!((m.cct - k).abs() <= tol, "{spec}: {} K", m.cct);
        }
        let m = cam
            .cct_from_neutral(&cam.white_neutral(&light("Tungsten")).unwrap())
            .unwrap();
        eprintln!(
            "Tungsten: {} K (rms log error {:.4})",
            m.cct, m.rms_log_error
        );
        assert!((2400.0..3400.0).contains(&m.cct), "Tungsten: {} K", m.cct);
    }

    #[test]
    fn neutrals_missing_channels_are_refused() {
        let cam = camera(SensorDesign::paper_default());
        let e = cam
            .cct_from_neutral(&[("R".into(), 1.0), ("G".into(), 1.0), ("B".into(), 1.0)])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no value for the camera's channel W") && e.contains("R, G, B"),
            "{e}"
        );
        let e = cam
            .cct_from_neutral(&[
                ("r".into(), 1.0),
                ("g".into(), 0.0),
                ("b".into(), 1.0),
                ("w".into(), 1.0),
            ])
            .unwrap_err()
            .to_string();
        assert!(e.contains("G value is 0"), "{e}");
    }
}
