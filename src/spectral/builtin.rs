//! Built-in spectral data, carried by the `colorimetry` crate (CIE 1931 2°
//! observer, CIE illuminants, the 99 CIE 224 colour evaluation samples, the
//! Munsell matt set), plus Planck and CIE daylight computed by CCT.

use colorimetry::illuminant::{CieIlluminant, Illuminant};
use colorimetry::observer::Observer;
use colorimetry::traits::{Filter, Light};

use super::{Samples, SpectralError};

/// The crate tables span 380–780 nm at 1 nm.
fn crate_grid() -> Vec<f64> {
    (380..=780).map(|w| w as f64).collect()
}

/// The crate's tables are 401 finite values on 380..=780 nm (checked by the
/// tests below), so they need no validation.
fn from_crate(values: &[f64]) -> Samples {
    Samples::from_trusted(crate_grid(), values.to_vec())
}

/// The CIE 1931 2° colour-matching functions x̄, ȳ, z̄ (energy basis), 380–780 nm.
pub fn cie1931_cmfs() -> [Samples; 3] {
    let obs = Observer::Cie1931;
    let mut cols = [Vec::new(), Vec::new(), Vec::new()];
    for w in 380..=780usize {
        let xyz = obs
            .xyz_at_wavelength(w)
            .map(|x| x.to_array())
            .unwrap_or([0.0; 3]);
        for k in 0..3 {
            cols[k].push(xyz[k]);
        }
    }
    cols.map(|c| from_crate(c.as_slice()))
}

/// Names accepted by [`cie_illuminant`].
pub const CIE_ILLUMINANT_NAMES: &[&str] = &[
    "D65", "D50", "E", "A", "F1", "F2", "F3", "F4", "F5", "F6", "F7", "F8", "F9", "F10", "F11",
    "F12",
];

/// A CIE standard illuminant by name (case-insensitive): D65, D50, E, A, F1–F12.
pub fn cie_illuminant(name: &str) -> Option<Samples> {
    let upper = name.to_ascii_uppercase();
    let ill = match upper.as_str() {
        "D65" => CieIlluminant::D65,
        "D50" => CieIlluminant::D50,
        "E" => CieIlluminant::E,
        "A" => CieIlluminant::A,
        "F1" => CieIlluminant::F1,
        "F2" => CieIlluminant::F2,
        "F3" => CieIlluminant::F3,
        "F4" => CieIlluminant::F4,
        "F5" => CieIlluminant::F5,
        "F6" => CieIlluminant::F6,
        "F7" => CieIlluminant::F7,
        "F8" => CieIlluminant::F8,
        "F9" => CieIlluminant::F9,
        "F10" => CieIlluminant::F10,
        "F11" => CieIlluminant::F11,
        "F12" => CieIlluminant::F12,
        _ => return None,
    };
    Some(from_crate(ill.spectrum().as_array()))
}

/// Planck's law, spectral radiance of a blackbody at `cct` kelvin, relative
/// (normalised to 1 at 560 nm), sampled at 1 nm over 380–780 nm.
pub fn planck(cct: f64) -> Result<Samples, SpectralError> {
    if !(cct.is_finite() && (500.0..=100_000.0).contains(&cct)) {
        return Err(SpectralError::InvalidIlluminantSpec(
            format!("cct:{cct}"),
            "colour temperature must be within 500–100000 K".into(),
        ));
    }
    const C2: f64 = 1.438_776_877e-2; // m·K
    let b = |nm: f64| {
        let l = nm * 1e-9;
        1.0 / (l.powi(5) * ((C2 / (l * cct)).exp_m1()))
    };
    let norm = b(560.0);
    let values = crate_grid().iter().map(|&w| b(w) / norm).collect();
    Samples::new(crate_grid(), values)
}

/// CIE daylight (D series) at `cct` kelvin, 4000–25000 K, 380–780 nm at 1 nm.
pub fn cie_daylight(cct: f64) -> Result<Samples, SpectralError> {
    let ill = Illuminant::d_illuminant(cct)
        .map_err(|e| SpectralError::InvalidIlluminantSpec(format!("cct:{cct}"), e.to_string()))?;
    Ok(from_crate(ill.spectrum().as_array()))
}

/// The 99 CIE 224:2017 colour evaluation samples (reflectance), named `CES01`…`CES99`.
pub fn ces_reflectances() -> Vec<(String, Samples)> {
    colorimetry::colorant::CES
        .iter()
        .enumerate()
        .map(|(i, c)| {
            (
                format!("CES{:02}", i + 1),
                from_crate(c.spectrum().as_array()),
            )
        })
        .collect()
}

/// The Munsell matt set (1269 samples, reflectance), named by Munsell notation.
pub fn munsell_reflectances() -> Vec<(String, Samples)> {
    use colorimetry::colorant::{Munsell, MunsellCollection};
    (0..MunsellCollection::len())
        .map(|i| {
            let m = Munsell::new(i);
            (m.key().to_string(), from_crate(m.spectrum().as_array()))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sets_have_their_sizes() {
        assert_eq!(ces_reflectances().len(), 99);
        assert_eq!(munsell_reflectances().len(), 1269);
        for n in CIE_ILLUMINANT_NAMES {
            assert!(cie_illuminant(n).is_some(), "{n}");
        }
        assert!(cie_illuminant("Z9").is_none());
    }

    #[test]
    fn planck_peak_follows_wien() {
        // Wien: λmax = 2.8978e-3 / T; at 5000 K, 579.6 nm.
        let p = planck(5000.0).unwrap();
        let (i, _) = p
            .values()
            .iter()
            .enumerate()
            .fold((0, f64::MIN), |a, (i, &v)| if v > a.1 { (i, v) } else { a });
        assert!((p.wavelengths()[i] - 579.6).abs() <= 1.0);
        assert!(planck(-3.0).is_err());
        assert!(cie_daylight(3000.0).is_err());
        assert!(cie_daylight(6504.0).is_ok());
    }
}
