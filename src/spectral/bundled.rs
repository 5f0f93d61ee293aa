//! Spectral data compiled into the binary (`config/spectra/`, with provenance
//! and licences in its README): the ISETCam tables the defaults need (the
//! measured Tungsten and Fluorescent lights, the Vrhel reflectance sets behind
//! Natural-100 and the training and correction sets, the Macbeth chart) and
//! the filter curves of the shipped sensor designs. Paths are those of the
//! ISET data directory, which overrides these copies file by file
//! ([`super::IsetData`]).

use super::{SpectralError, SpectralTable};

/// `(path, contents)` of each file under `config/spectra/`.
macro_rules! bundled_files {
    ($($path:literal),* $(,)?) => {
        [$(($path, include_str!(concat!("../../config/spectra/", $path)))),*]
    };
}

/// `(path relative to the spectral data root, contents)`.
const FILES: [(&str, &str); 18] = bundled_files![
    "lights/Tungsten.csv",
    "lights/Fluorescent.csv",
    "surfaces/reflectances/Food_Vhrel.csv",
    "surfaces/reflectances/Clothes_Vhrel.csv",
    "surfaces/reflectances/Nature_Vhrel.csv",
    "surfaces/reflectances/Hair_Vhrel.csv",
    "surfaces/reflectances/skin/Caucasian_Vhrel.csv",
    "surfaces/reflectances/skin/AfricanAmerican_Vhrel.csv",
    "surfaces/reflectances/skin/Asian_Vhrel.csv",
    "surfaces/reflectances/skin/EastIndian_Vhrel.csv",
    "surfaces/reflectances/DupontPaintChip_Vhrel.csv",
    "surfaces/reflectances/Objects_Vhrel.csv",
    "surfaces/reflectances/MunsellSamples_Vhrel.csv",
    "surfaces/reflectances/macbethChart.csv",
    "sensor/colorfilters/RGBW.csv",
    "sensor/colorfilters/auto/ar0132atRGBW.csv",
    "cameras/nikon_d5100_npl.csv",
    "cameras/canon_eos_5d_mark_ii_rawtoaces.csv",
];

/// The built-in table at `rel` (a path relative to the spectral data root,
/// `/`-separated), if one is bundled.
pub fn bundled_table(rel: &str) -> Option<Result<SpectralTable, SpectralError>> {
    let rel = rel.trim_start_matches("./");
    FILES
        .iter()
        .find(|(p, _)| *p == rel)
        .map(|(p, text)| SpectralTable::parse(&format!("built-in:{p}"), text))
}

/// Paths of every bundled table.
pub fn bundled_paths() -> impl Iterator<Item = &'static str> {
    FILES.iter().map(|(p, _)| *p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bundled_table_parses() {
        for p in bundled_paths() {
            let t = bundled_table(p).unwrap().unwrap();
            let all = t.all().unwrap();
            assert!(!all.is_empty(), "{p}");
            if p.starts_with("sensor/") || p.starts_with("cameras/") {
                assert!((3..=4).contains(&all.len()), "{p}");
            }
        }
        assert!(bundled_table("nope.csv").is_none());
        assert!(bundled_table("./lights/Tungsten.csv").is_some());
    }
}
