//! Spectral data compiled into the binary (`config/spectra/`, with provenance
//! and licences in its README): the ISETCam tables the defaults need (the
//! measured Tungsten and Fluorescent lights, the Vrhel reflectance sets behind
//! Natural-100 and the training and correction sets, the Macbeth chart) and
//! the filter curves of the shipped sensor designs and of the 49 catalogue cameras. Paths are those of the
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
const FILES: &[(&str, &str)] = &bundled_files![
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
    // the 49 cameras of the sensor catalogue (crate::camera::catalogue)
    "cameras/rawtoaces/arashi_vision_insta360_x5.csv",
    "cameras/rawtoaces/arri_d21.csv",
    "cameras/rawtoaces/canon_digital_rebel_xti.csv",
    "cameras/rawtoaces/canon_eos-1d_x_mark_ii.csv",
    "cameras/rawtoaces/canon_eos-1ds_mark_ii.csv",
    "cameras/rawtoaces/canon_eos-1ds_mark_iii.csv",
    "cameras/rawtoaces/canon_eos_100d.csv",
    "cameras/rawtoaces/canon_eos_200d.csv",
    "cameras/rawtoaces/canon_eos_200d_ii.csv",
    "cameras/rawtoaces/canon_eos_5d.csv",
    "cameras/rawtoaces/canon_eos_5d_mark_ii.csv",
    "cameras/rawtoaces/canon_eos_5d_mark_iii.csv",
    "cameras/rawtoaces/canon_eos_5d_mark_iv.csv",
    "cameras/rawtoaces/canon_eos_5ds.csv",
    "cameras/rawtoaces/canon_eos_600d.csv",
    "cameras/rawtoaces/canon_eos_m.csv",
    "cameras/rawtoaces/canon_eos_r.csv",
    "cameras/rawtoaces/canon_eos_r10.csv",
    "cameras/rawtoaces/canon_eos_r5.csv",
    "cameras/rawtoaces/canon_eos_r5m2.csv",
    "cameras/rawtoaces/canon_eos_r6.csv",
    "cameras/rawtoaces/canon_eos_r6m2.csv",
    "cameras/rawtoaces/canon_eos_rp.csv",
    "cameras/rawtoaces/canon_powershot_s90.csv",
    "cameras/rawtoaces/fujifilm_gfx_100.csv",
    "cameras/rawtoaces/fujifilm_x-t4.csv",
    "cameras/rawtoaces/hasselblad_l2d-20c.csv",
    "cameras/rawtoaces/nikon_d200.csv",
    "cameras/rawtoaces/nikon_d3300.csv",
    "cameras/rawtoaces/nikon_d5100.csv",
    "cameras/rawtoaces/nikon_d5300.csv",
    "cameras/rawtoaces/nikon_d70.csv",
    "cameras/rawtoaces/nikon_d700.csv",
    "cameras/rawtoaces/nikon_d7000.csv",
    "cameras/rawtoaces/nikon_d800e.csv",
    "cameras/rawtoaces/nikon_d810.csv",
    "cameras/rawtoaces/nikon_d850.csv",
    "cameras/rawtoaces/nikon_z_f.csv",
    "cameras/rawtoaces/panasonic_dc-gx9.csv",
    "cameras/rawtoaces/sony_dsc-rx100m4.csv",
    "cameras/rawtoaces/sony_ilce-6400.csv",
    "cameras/rawtoaces/sony_ilce-7cm2.csv",
    "cameras/rawtoaces/sony_ilce-7m4.csv",
    "cameras/rawtoaces/sony_ilce-7rm2.csv",
    "cameras/rawtoaces/sony_ilce-7rm3.csv",
    "cameras/rawtoaces/sony_ilce-7rm4.csv",
    "cameras/rawtoaces/sony_ilce-7sm2.csv",
    "cameras/rawtoaces/sony_ilce-7sm3.csv",
    "cameras/rawtoaces/sony_ilce-9.csv",
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
