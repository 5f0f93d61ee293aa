//! Named reflectance sets: what training and the illuminant correction use.

use super::{SceneError, natural100_samples};
use crate::spectral::{
    Extrapolation, IsetData, Spectrum, WavelengthGrid, ces_reflectances, munsell_reflectances,
};

const VRHEL_OBJECTS: &str = "surfaces/reflectances/Objects_Vhrel.csv";
const VRHEL_DUPONT: &str = "surfaces/reflectances/DupontPaintChip_Vhrel.csv";
const VRHEL_MUNSELL: &str = "surfaces/reflectances/MunsellSamples_Vhrel.csv";

/// Vrhel sets from the ISET data, minus the Natural-100 chart's samples.
fn vrhel_without_chart(
    grid: &WavelengthGrid,
    iset: &IsetData,
    files: &[&str],
) -> Result<Vec<(String, Spectrum)>, SceneError> {
    let excluded: Vec<String> = natural100_samples(iset)?
        .into_iter()
        .map(|s| s.name)
        .collect();
    let mut out = Vec::new();
    for file in files {
        for (name, s) in iset.table(file)?.all()? {
            if !excluded.contains(&name) {
                out.push((name, s.resample(grid, Extrapolation::Hold)));
            }
        }
    }
    Ok(out)
}

fn crate_sets(grid: &WavelengthGrid, munsell: bool) -> Vec<(String, Spectrum)> {
    let m = if munsell {
        munsell_reflectances()
    } else {
        Vec::new()
    };
    m.into_iter()
        .chain(ces_reflectances())
        .map(|(n, s)| (n, s.resample(grid, Extrapolation::Hold)))
        .collect()
}

/// The training reflectances: the Munsell matt set and the 99 CES from the
/// crate, plus ISET's Vrhel objects, DuPont paints and Munsell samples
/// (`iset` `None`: the built-in copies) — never the 100 samples of the
/// Natural-100 evaluation chart.
pub fn training_reflectances(
    grid: &WavelengthGrid,
    iset: Option<&IsetData>,
) -> Result<Vec<(String, Spectrum)>, SceneError> {
    let mut out = crate_sets(grid, true);
    out.extend(vrhel_without_chart(
        grid,
        IsetData::or_built_in(iset),
        &[VRHEL_OBJECTS, VRHEL_DUPONT, VRHEL_MUNSELL],
    )?);
    Ok(out)
}

/// The natural reflectances, the set every colour fit is made on: Vrhel's
/// objects and DuPont paints (minus the Natural-100 chart's samples) with
/// the 99 CES (`iset` `None`: the built-in copies). The illuminant
/// correction T, the camera-aware correction C, the trainer's colour maps,
/// the matching linear maps and the baseline's colour matrix are all fitted
/// on it; the training *scenes* keep the wider [`training_reflectances`].
/// The Munsell set over-weights saturated colours that natural scenes
/// rarely hold. Measured on the Natural-100 chart under ISET's tungsten: T
/// alone costs 1.30 ΔE2000 with this set against 1.72 with Munsell + CES;
/// with the colour maps' CIEDE2000 weights, a cross-illuminant table on ISET's
/// RGBW gives 2.86 on one capture against 3.55 when its maps were fitted on
/// the training reflectances (16 captures; `docs/research/colour-map-loss.md`).
pub fn natural_reflectances(
    grid: &WavelengthGrid,
    iset: Option<&IsetData>,
) -> Result<Vec<(String, Spectrum)>, SceneError> {
    let mut out = crate_sets(grid, false);
    out.extend(vrhel_without_chart(
        grid,
        IsetData::or_built_in(iset),
        &[VRHEL_OBJECTS, VRHEL_DUPONT],
    )?);
    Ok(out)
}
