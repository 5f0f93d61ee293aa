//! The true colours of the 24 patches, referred to D65 as the rendered image is: X-Rite's
//! published 2014 values (L\*a\*b\* under ICC D50, adapted to D65 with the Bradford transform
//! as ICC does), or ISET's Macbeth reflectances under D65 (the chart `l3 simulate --scene
//! macbeth` draws).

use serde::{Deserialize, Serialize};

use crate::colour::{
    Cmfs, D65_WHITE_XYZ, Lab, Xyz, checked_inverse3, lab_to_xyz, mat3_mul_vec, xy_to_xyz,
    xyz_to_lab,
};
use crate::eval::EvalError;
use crate::scene::{SceneOptions, macbeth};
use crate::spectral::{Extrapolation, IsetData, WavelengthGrid, cie_illuminant};

/// X-Rite's values, compiled in (`config/ref/`, with provenance and licence in its README).
const XRITE2014_CSV: &str = include_str!("../../../config/ref/colorchecker24_xrite2014_d50.csv");

/// The ICC D50 white's chromaticity, which the published L\*a\*b\* are relative to.
pub const ICC_D50_XY: [f64; 2] = [0.345703, 0.358539];

/// The Bradford cone-response matrix.
const BRADFORD: [[f64; 3]; 3] = [
    [0.8951, 0.2664, -0.1614],
    [-0.7502, 1.7135, 0.0367],
    [0.0389, -0.0685, 1.0296],
];

/// Which true colours a ColorChecker evaluation compares with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reference {
    /// X-Rite's published values for charts made after November 2014.
    #[default]
    Xrite2014,
    /// ISET's Macbeth reflectances (`surfaces/reflectances/macbethChart.csv`) under D65.
    Iset,
}

impl std::str::FromStr for Reference {
    type Err = EvalError;
    fn from_str(s: &str) -> Result<Self, EvalError> {
        match s.to_ascii_lowercase().as_str() {
            "xrite2014" => Ok(Reference::Xrite2014),
            "iset" => Ok(Reference::Iset),
            _ => Err(EvalError::Invalid(format!(
                "reference '{s}': expected xrite2014 or iset"
            ))),
        }
    }
}

impl Reference {
    pub fn as_str(self) -> &'static str {
        match self {
            Reference::Xrite2014 => "xrite2014",
            Reference::Iset => "iset",
        }
    }

    /// How the reference is made, for the report.
    pub fn describe(self) -> &'static str {
        match self {
            Reference::Xrite2014 => {
                "X-Rite ColorChecker Classic, after November 2014 (X-Rite 2016): L*a*b* under ICC D50, 2° observer, adapted to D65 with the Bradford transform"
            }
            Reference::Iset => {
                "ISET Macbeth reflectances (surfaces/reflectances/macbethChart.csv) under CIE D65, CIE 1931 2° observer, 400–700 nm at 10 nm"
            }
        }
    }

    /// The 24 patches' true colours, row by row from dark skin.
    pub fn patches(self, iset: Option<&IsetData>) -> Result<Vec<ReferencePatch>, EvalError> {
        match self {
            Reference::Xrite2014 => xrite2014(),
            Reference::Iset => iset_macbeth(iset),
        }
    }
}

/// One patch's true colour under D65: XYZ with a perfect white at Y = 1, and its CIELAB
/// relative to the D65 white.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferencePatch {
    pub name: String,
    pub xyz: Xyz,
    pub lab: Lab,
}

/// The Bradford chromatic adaptation from white `from` to white `to` (XYZ, any scale).
pub fn bradford(from: Xyz, to: Xyz) -> Result<[[f64; 3]; 3], EvalError> {
    let inv = checked_inverse3(BRADFORD)
        .ok_or_else(|| EvalError::Invalid("the Bradford matrix is singular".into()))?;
    let (a, b) = (mat3_mul_vec(&BRADFORD, from), mat3_mul_vec(&BRADFORD, to));
    let gain: [f64; 3] = std::array::from_fn(|i| b[i] / a[i]);
    let mut scaled = BRADFORD;
    for (row, g) in scaled.iter_mut().zip(gain) {
        row.iter_mut().for_each(|v| *v *= g);
    }
    Ok(std::array::from_fn(|i| {
        std::array::from_fn(|j| (0..3).map(|k| inv[i][k] * scaled[k][j]).sum())
    }))
}

/// The published values: `name` and `L,a,b` of each row, under ICC D50 → XYZ → Bradford to
/// D65 → CIELAB relative to D65.
pub fn xrite2014() -> Result<Vec<ReferencePatch>, EvalError> {
    let bad = |why: String| EvalError::Invalid(format!("the built-in X-Rite values: {why}"));
    let mut lines = XRITE2014_CSV.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .ok_or_else(|| bad(format!("no column {name}")))
    };
    let (name_c, l_c, a_c, b_c) = (col("patch_name")?, col("L")?, col("a")?, col("b")?);
    let d50 = xy_to_xyz(ICC_D50_XY);
    let cat = bradford(d50, D65_WHITE_XYZ)?;
    let patches = lines
        .filter(|l| !l.trim().is_empty())
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            let num = |c: usize| {
                f.get(c)
                    .and_then(|v| v.trim().parse::<f64>().ok())
                    .ok_or_else(|| bad(format!("row '{line}'")))
            };
            let lab50 = [num(l_c)?, num(a_c)?, num(b_c)?];
            let xyz = mat3_mul_vec(&cat, lab_to_xyz(lab50, d50));
            Ok(ReferencePatch {
                name: f.get(name_c).copied().unwrap_or("").to_string(),
                xyz,
                lab: xyz_to_lab(xyz, D65_WHITE_XYZ),
            })
        })
        .collect::<Result<Vec<_>, EvalError>>()?;
    if patches.len() != 24 {
        return Err(bad(format!("{} patches, 24 expected", patches.len())));
    }
    Ok(patches)
}

/// ISET's Macbeth reflectances (the chart the simulator draws, built in or `iset`'s) under
/// D65, named as X-Rite names them.
pub fn iset_macbeth(iset: Option<&IsetData>) -> Result<Vec<ReferencePatch>, EvalError> {
    let grid = WavelengthGrid::default();
    let chart = macbeth(IsetData::or_built_in(iset), &SceneOptions::d65(grid)?, 1)?;
    let d65 = cie_illuminant("D65")
        .ok_or_else(|| EvalError::Invalid("D65 missing from the built-in data".into()))?
        .resample(&grid, Extrapolation::Zero);
    let cmfs = Cmfs::cie1931(&grid);
    let names = xrite2014()?;
    chart
        .patches
        .iter()
        .zip(names)
        .map(|(p, named)| {
            let xyz = cmfs.reflectance_xyz(&p.reflectance, &d65)?;
            Ok(ReferencePatch {
                name: named.name,
                xyz,
                lab: xyz_to_lab(xyz, D65_WHITE_XYZ),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::ciede2000;

    #[test]
    fn bradford_takes_d50_white_to_d65_white() {
        let d50 = xy_to_xyz(ICC_D50_XY);
        let m = bradford(d50, D65_WHITE_XYZ).unwrap();
        let w = mat3_mul_vec(&m, d50);
        for (a, b) in w.iter().zip(D65_WHITE_XYZ) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
        // the D50 → D65 Bradford matrix as usually published (Lindbloom), made with
        // D50 = (0.96422, 1, 0.82521): within the whites' own difference
        let want = [
            [0.9555766, -0.0230393, 0.0631636],
            [-0.0282895, 1.0099416, 0.0210077],
            [0.0122982, -0.0204830, 1.3299098],
        ];
        for (r, w) in m.iter().zip(want) {
            for (a, b) in r.iter().zip(w) {
                assert!((a - b).abs() < 1e-3, "{m:?}");
            }
        }
    }

    #[test]
    fn the_published_values_parse_and_adapt() {
        let p = xrite2014().unwrap();
        assert_eq!(p.len(), 24);
        assert_eq!(p[0].name, "dark skin");
        assert_eq!(p[23].name, "black 2 (1.5 D)");
        // a neutral stays neutral and keeps its lightness through the adaptation
        let white = &p[18];
        assert!((white.lab[0] - 95.19).abs() < 0.05, "{:?}", white.lab);
        assert!((white.xyz[1] - 0.8807).abs() < 1e-3);
        let n5 = &p[21];
        assert!(
            n5.lab[1].abs() < 0.5 && n5.lab[2].abs() < 0.5,
            "{:?}",
            n5.lab
        );
    }

    /// ISET's reflectances and X-Rite's values are the same chart, measured apart: every
    /// patch within a few ΔE2000, the order the same.
    #[test]
    fn the_two_references_are_the_same_chart() {
        let (x, i) = (xrite2014().unwrap(), iset_macbeth(None).unwrap());
        assert_eq!(i.len(), 24);
        let de: Vec<f64> = x
            .iter()
            .zip(&i)
            .map(|(a, b)| ciede2000(a.lab, b.lab))
            .collect();
        assert!(de.iter().all(|d| *d < 8.0), "{de:?}");
        assert!(de.iter().sum::<f64>() / 24.0 < 4.0, "{de:?}");
    }
}
