//! Spectral data compiled into the binary: the filter curves of the shipped
//! sensor designs (`config/spectra/`, with their provenance and licences in
//! its README), so every shipped sensor loads without the ISET data folder.

use super::{SpectralError, SpectralTable};

/// `(path relative to the spectral data root, contents)`.
const FILES: [(&str, &str); 4] = [
    (
        "sensor/colorfilters/RGBW.csv",
        include_str!("../../config/spectra/sensor/colorfilters/RGBW.csv"),
    ),
    (
        "sensor/colorfilters/auto/ar0132atRGBW.csv",
        include_str!("../../config/spectra/sensor/colorfilters/auto/ar0132atRGBW.csv"),
    ),
    (
        "cameras/nikon_d5100_npl.csv",
        include_str!("../../config/spectra/cameras/nikon_d5100_npl.csv"),
    ),
    (
        "cameras/canon_eos_5d_mark_ii_rawtoaces.csv",
        include_str!("../../config/spectra/cameras/canon_eos_5d_mark_ii_rawtoaces.csv"),
    ),
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
    fn every_bundled_table_parses_with_three_or_four_channels() {
        for p in bundled_paths() {
            let t = bundled_table(p).unwrap().unwrap();
            let all = t.all().unwrap();
            assert!((3..=4).contains(&all.len()), "{p}");
        }
        assert!(bundled_table("nope.csv").is_none());
    }
}
