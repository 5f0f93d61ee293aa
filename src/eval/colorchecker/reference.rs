//! The true colours of the 24 patches, referred to D65 as the rendered image is: X-Rite's
//! published 2014 values (L\*a\*b\* under ICC D50, adapted to D65 with the Bradford transform
//! as ICC does), ISET's Macbeth reflectances under D65 (the chart `l3 simulate --scene
//! macbeth` draws), or a measured chart's values read from a CSV file ([`Measured`]: a
//! spectrophotometer's L\*a\*b\* of one's own chart, or the truth `l3 simulate` writes).

use std::sync::Arc;

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
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Reference {
    /// X-Rite's published values for charts made after November 2014.
    #[default]
    Xrite2014,
    /// ISET's Macbeth reflectances (`surfaces/reflectances/macbethChart.csv`) under D65.
    Iset,
    /// A measured chart's values, read from a CSV file ([`Measured::from_csv`]).
    Measured(Arc<Measured>),
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
    /// `xrite2014`, `iset` or `measured`.
    pub fn as_str(&self) -> &'static str {
        match self {
            Reference::Xrite2014 => "xrite2014",
            Reference::Iset => "iset",
            Reference::Measured(_) => "measured",
        }
    }

    /// How the reference is made, for the report.
    pub fn describe(&self) -> String {
        match self {
            Reference::Xrite2014 => {
                "X-Rite ColorChecker Classic, after November 2014 (X-Rite 2016): L*a*b* under ICC D50, 2° observer, adapted to D65 with the Bradford transform".into()
            }
            Reference::Iset => {
                "ISET Macbeth reflectances (surfaces/reflectances/macbethChart.csv) under CIE D65, CIE 1931 2° observer, 400–700 nm at 10 nm".into()
            }
            Reference::Measured(m) => format!("measured values from {} ({})", m.source, m.form),
        }
    }

    /// The 24 patches' true colours, row by row from dark skin.
    pub fn patches(&self, iset: Option<&IsetData>) -> Result<Vec<ReferencePatch>, EvalError> {
        match self {
            Reference::Xrite2014 => xrite2014(),
            Reference::Iset => iset_macbeth(iset),
            Reference::Measured(m) => Ok(m.patches.clone()),
        }
    }

    /// The reference a report sets beside this one (`references_delta_e`): ISET's beside
    /// X-Rite's, X-Rite's beside the others.
    pub fn counterpart(&self) -> Reference {
        match self {
            Reference::Xrite2014 => Reference::Iset,
            _ => Reference::Xrite2014,
        }
    }
}

/// A measured chart's 24 values, read from a CSV file.
#[derive(Clone, Debug, PartialEq)]
pub struct Measured {
    /// Where they came from (the file), for the report.
    pub source: String,
    /// `L*a*b*` or `XYZ`, and under which white.
    pub form: String,
    pub patches: Vec<ReferencePatch>,
}

impl Measured {
    /// Reads a CSV of the 24 patches in the chart's order (or numbered by an `index` column,
    /// 1–24), with a header row; lines starting with `#` are comments. Either
    /// - `L`, `a`, `b`: CIELAB under ICC D50 (as X-Rite publishes and spectrophotometers
    ///   report), or under the white given per row by `illuminant_x` and `illuminant_y`;
    ///   adapted to D65 with Bradford;
    /// - or `X`, `Y`, `Z`: XYZ under D65, a perfect white at Y = 1.
    ///
    /// A `patch_name` (or `name`) column names the patches; without it X-Rite's names are
    /// used. `source` names the file in errors and in the report.
    pub fn from_csv(text: &str, source: &str) -> Result<Measured, EvalError> {
        let (form, patches) = parse_reference_csv(text, source)?;
        Ok(Measured {
            source: source.to_string(),
            form,
            patches,
        })
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
    parse_reference_csv(XRITE2014_CSV, "the built-in X-Rite values").map(|(_, p)| p)
}

/// A reference CSV ([`Measured::from_csv`], XYZ under D65) of a simulated chart's truth:
/// `ideal` is the XYZ per patch as the chart evaluation takes it (the optical image relit by
/// D65, so the lens's blur and flare are in it), scaled as the chart evaluation scales it:
/// the white patch at Y = 1. Scoring a capture against it is scoring it as the chart
/// evaluation does; against `iset`, as a real capture is scored (docs/accuracy.md).
pub fn simulated_truth_csv(ideal: &[Xyz]) -> Result<String, EvalError> {
    if ideal.len() != 24 {
        return Err(EvalError::Invalid(format!(
            "{} patches, a ColorChecker has 24",
            ideal.len()
        )));
    }
    let scale = 1.0 / ideal[super::WHITE_PATCH][1];
    if !(scale.is_finite() && scale > 0.0) {
        return Err(EvalError::Invalid("the white patch has no signal".into()));
    }
    let mut csv = String::from(
        "# the simulated chart's truth: its optical image relit by D65 (lens blur and flare \
         included), per patch interior, white patch at Y = 1 as the chart evaluation scales it; XYZ under D65\n\
         index,patch_name,X,Y,Z\n",
    );
    for (k, v) in ideal.iter().enumerate() {
        let [x, y, z] = v.map(|c| c * scale);
        csv += &format!("{},{},{x:.8},{y:.8},{z:.8}\n", k + 1, NAMES[k]);
    }
    Ok(csv)
}

/// The default patch names (X-Rite's, row by row from dark skin).
const NAMES: [&str; 24] = [
    "dark skin",
    "light skin",
    "blue sky",
    "foliage",
    "blue flower",
    "bluish green",
    "orange",
    "purplish blue",
    "moderate red",
    "purple",
    "yellow green",
    "orange yellow",
    "blue",
    "green",
    "red",
    "yellow",
    "magenta",
    "cyan",
    "white 9.5 (.05 D)",
    "neutral 8 (.23 D)",
    "neutral 6.5 (.44 D)",
    "neutral 5 (.70 D)",
    "neutral 3.5 (1.05 D)",
    "black 2 (1.5 D)",
];

/// The values a reference CSV holds ([`Measured::from_csv`]), with its form.
fn parse_reference_csv(
    text: &str,
    source: &str,
) -> Result<(String, Vec<ReferencePatch>), EvalError> {
    let bad = |why: String| EvalError::Invalid(format!("{source}: {why}"));
    let mut lines = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'));
    let header: Vec<String> = lines
        .next()
        .ok_or_else(|| bad("no header row".into()))?
        .split(',')
        .map(|h| h.trim().trim_matches('"').to_string())
        .collect();
    let find = |name: &str| header.iter().position(|h| h == name);
    let name_c = find("patch_name").or_else(|| find("name"));
    let index_c = find("index");
    let white_c = find("illuminant_x").zip(find("illuminant_y"));
    let (form, cols) = match (
        find("L"),
        find("a"),
        find("b"),
        find("X"),
        find("Y"),
        find("Z"),
    ) {
        (Some(l), Some(a), Some(b), _, _, _) => ("lab", [l, a, b]),
        (_, _, _, Some(x), Some(y), Some(z)) => ("xyz", [x, y, z]),
        _ => {
            return Err(bad(format!(
                "columns {header:?}: expected L, a, b (CIELAB, D50) or X, Y, Z (D65, white Y = 1)"
            )));
        }
    };
    let d50 = xy_to_xyz(ICC_D50_XY);
    let mut slots: Vec<Option<ReferencePatch>> = vec![None; 24];
    let mut whites = std::collections::BTreeSet::new();
    for (row, line) in lines.enumerate() {
        let f: Vec<&str> = line
            .split(',')
            .map(|v| v.trim().trim_matches('"'))
            .collect();
        let num = |c: usize| {
            f.get(c)
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| bad(format!("row '{line}': column {} is not a number", c + 1)))
        };
        let k = match index_c {
            Some(c) => {
                let i = num(c)?;
                if i.fract() != 0.0 || !(1.0..=24.0).contains(&i) {
                    return Err(bad(format!("row '{line}': index {i} is not 1–24")));
                }
                i as usize - 1
            }
            None => row,
        };
        if k >= 24 || slots[k].is_some() {
            return Err(bad(format!(
                "row '{line}': patch {} is given twice or is beyond 24",
                k + 1
            )));
        }
        let v = [num(cols[0])?, num(cols[1])?, num(cols[2])?];
        let xyz = if form == "lab" {
            let white = match white_c {
                Some((x, y)) => xy_to_xyz([num(x)?, num(y)?]),
                None => d50,
            };
            whites.insert(format!("{:.6},{:.6}", white[0], white[2]));
            mat3_mul_vec(&bradford(white, D65_WHITE_XYZ)?, lab_to_xyz(v, white))
        } else {
            v
        };
        let name = name_c
            .and_then(|c| f.get(c))
            .filter(|n| !n.is_empty())
            .map_or_else(|| NAMES[k].to_string(), |n| n.to_string());
        slots[k] = Some(ReferencePatch {
            name,
            xyz,
            lab: xyz_to_lab(xyz, D65_WHITE_XYZ),
        });
    }
    let given = slots.iter().filter(|s| s.is_some()).count();
    let patches: Vec<ReferencePatch> = slots.into_iter().flatten().collect();
    if given != 24 {
        return Err(bad(format!("{given} patches, 24 expected")));
    }
    let form = match (form, whites.len()) {
        ("xyz", _) => "XYZ under D65".to_string(),
        (_, 1) if white_c.is_none() => "L*a*b* under ICC D50, adapted to D65 with Bradford".into(),
        _ => "L*a*b* under the file's whites, adapted to D65 with Bradford".into(),
    };
    Ok((form, patches))
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
    chart
        .patches
        .iter()
        .zip(NAMES)
        .map(|(p, name)| {
            let xyz = cmfs.reflectance_xyz(&p.reflectance, &d65)?;
            Ok(ReferencePatch {
                name: name.to_string(),
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

    /// A measured chart as L*a*b* (D50, X-Rite's own file) reads as the built-in values; as
    /// XYZ under D65, numbered out of order, it reads as given; bad files are named errors.
    #[test]
    fn measured_values_read_from_csv() {
        let m = Measured::from_csv(XRITE2014_CSV, "x.csv").unwrap();
        assert_eq!(m.patches, xrite2014().unwrap());
        let iset = iset_macbeth(None).unwrap();
        let mut csv = String::from("# ISET's chart as XYZ\nindex,X,Y,Z\n");
        for (k, p) in iset.iter().enumerate().rev() {
            csv += &format!("{},{},{},{}\n", k + 1, p.xyz[0], p.xyz[1], p.xyz[2]);
        }
        let m = Measured::from_csv(&csv, "sim.csv").unwrap();
        for (a, b) in m.patches.iter().zip(&iset) {
            assert_eq!(a.name, b.name);
            assert!(ciede2000(a.lab, b.lab) < 1e-9);
        }
        let r = Reference::Measured(Arc::new(m));
        assert_eq!(r.as_str(), "measured");
        assert!(r.describe().contains("sim.csv"), "{}", r.describe());
        for bad in [
            "X,Y\n1,2\n",
            "L,a,b\n50,0,0\n",
            "L,a,b\n50,zero,0\n",
            "index,X,Y,Z\n25,0.1,0.1,0.1\n",
        ] {
            let e = Measured::from_csv(bad, "bad.csv").unwrap_err().to_string();
            assert!(e.contains("bad.csv"), "{e}");
        }
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
