//! Illuminant correction: the 3×3 matrix T that maps XYZ under an
//! acquisition illuminant to XYZ under D65, from first principles (least
//! squares over surface reflectances, independent of the camera), and the
//! registry of named corrections (docs/design.md §6).

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Matrix3xX};
use serde::{Deserialize, Serialize};

use crate::colour::{Cmfs, cct_from_xy, xy};
use crate::spectral::{
    Extrapolation, IlluminantSpec, IsetData, Samples, Spectrum, WavelengthGrid, ces_reflectances,
    cie_illuminant, munsell_reflectances,
};

use super::CorrectError;

pub type Mat3 = [[f64; 3]; 3];

/// Largest magnitude of an entry of a given correction matrix. T maps XYZ to
/// XYZ, so its entries are O(1); far larger ones would overflow the f32
/// kernels they are fused into.
pub const MAX_MATRIX_ENTRY: f64 = 1e3;

pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The crate-only reflectance set for T: the Munsell matt set and the 99
/// CES samples, on `grid` (see `scene::natural_reflectances` for the
/// default, which uses natural surfaces).
pub fn default_reflectances(grid: &WavelengthGrid) -> Vec<Spectrum> {
    munsell_reflectances()
        .into_iter()
        .chain(ces_reflectances())
        .map(|(_, s)| s.resample(grid, Extrapolation::Hold))
        .collect()
}

/// T = argmin Σ‖T·xyz_X(r) − xyz_target(r)‖² over `reflectances`, each side
/// normalised so a perfect white has Y = 1. With `white_preserving`, the
/// minimum is taken subject to T mapping the perfect white exactly.
pub fn correction_matrix(
    cmfs: &Cmfs,
    reflectances: &[Spectrum],
    acquisition: &Spectrum,
    target: &Spectrum,
    white_preserving: bool,
) -> Result<Mat3, CorrectError> {
    if reflectances.len() < 3 {
        return Err(CorrectError::InvalidParams(
            "T needs at least 3 reflectances".into(),
        ));
    }
    let err =
        |e: crate::colour::ColourError| CorrectError::InvalidInput(format!("illuminant: {e}"));
    let wa = cmfs.reflectance_weights(acquisition).map_err(err)?;
    let wt = cmfs.reflectance_weights(target).map_err(err)?;
    let n = reflectances.len();
    let mut a = Matrix3xX::<f64>::zeros(n);
    let mut b = Matrix3xX::<f64>::zeros(n);
    for (j, r) in reflectances.iter().enumerate() {
        if r.grid() != &cmfs.grid {
            return Err(CorrectError::InvalidInput(
                "reflectance grid differs from the CMF grid".into(),
            ));
        }
        for k in 0..3 {
            a[(k, j)] = dot(&wa[k], r.values());
            b[(k, j)] = dot(&wt[k], r.values());
        }
    }
    let aat: Matrix3<f64> = &a * a.transpose();
    let bat: Matrix3<f64> = &b * a.transpose();
    let inv = aat.try_inverse().ok_or_else(|| {
        CorrectError::InvalidInput(
            "the illuminant makes the reflectance XYZs degenerate (T is singular)".into(),
        )
    })?;
    // least squares T·A ≈ B through the SVD of Aᵀ (conditioned as A, not as A·Aᵀ):
    // exact to rounding when both sides hold the same XYZs, even for a few nearly
    // collinear reflectances
    let svd = a.transpose().svd(true, true);
    let mut t = match svd.solve(&b.transpose(), 0.0) {
        Ok(tt) => tt.transpose(),
        Err(_) => bat * inv,
    };
    if white_preserving {
        // Constrained least squares: T·w_acq = w_target exactly (a perfect
        // white keeps its colour), the rest as close as possible.
        let wa3 = nalgebra::Vector3::from_fn(|k, _| wa[k].iter().sum::<f64>());
        let wt3 = nalgebra::Vector3::from_fn(|k, _| wt[k].iter().sum::<f64>());
        let g = inv * wa3;
        let denom = wa3.dot(&g);
        if denom > 0.0 {
            t += (wt3 - t * wa3) * g.transpose() / denom;
        }
    }
    let out: Mat3 = [0, 1, 2].map(|i| [0, 1, 2].map(|j| t[(i, j)]));
    if out.iter().flatten().any(|v| !v.is_finite()) {
        return Err(CorrectError::InvalidInput("T is not finite".into()));
    }
    if let Some(v) = out.iter().flatten().find(|v| v.abs() > MAX_MATRIX_ENTRY) {
        // a (nearly) line spectrum: every surface's XYZ is nearly collinear
        return Err(CorrectError::InvalidInput(format!(
            "the illuminant is too narrow-band for a colour correction (T has an entry {v:e}, beyond ±{MAX_MATRIX_ENTRY:e})"
        )));
    }
    Ok(out)
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// How a registry entry was made.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CorrectionSource {
    Builtin,
    Iset,
    Matrix,
    Spd,
    Cct,
}

/// One named illuminant correction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IlluminantEntry {
    pub name: String,
    /// XYZ under this illuminant → XYZ under D65.
    pub t: Mat3,
    /// Chromaticity of the illuminant's white, if known.
    pub white_xy: Option<[f64; 2]>,
    pub cct: Option<f64>,
    pub source: CorrectionSource,
    /// The light's spectrum on the registry's grid, when it is known (not for
    /// a correction given as a matrix): what a camera-aware correction is
    /// fitted on ([`camera_corrected`](super::camera_corrected)).
    #[serde(skip)]
    pub spd: Option<Spectrum>,
    /// Per table band (level, or level and chroma class), the correction a same-illuminant table's classes of that band
    /// render with, when it has been fitted per level; empty: `t` for every class.
    #[serde(skip)]
    pub level_corrections: Vec<Mat3>,
    /// A table's sensor's channel responses to white under this light, when
    /// they have been worked out for the table it renders with: what its
    /// chroma classes balance by (`l3::classify::chroma`); `None`, their
    /// reference light.
    #[serde(skip)]
    pub neutral: Option<Vec<f64>>,
}

impl IlluminantEntry {
    /// A correction given only as a matrix `t` (XYZ under the light → XYZ under D65): no
    /// spectrum, so no per-level correction and no neutral. Unchecked
    /// ([`IlluminantRegistry::insert_matrix`] checks).
    pub fn from_matrix(name: &str, t: Mat3) -> Self {
        Self {
            name: name.to_string(),
            t,
            white_xy: None,
            cct: None,
            source: CorrectionSource::Matrix,
            spd: None,
            level_corrections: Vec::new(),
            neutral: None,
        }
    }
}

/// The registry: illuminant name → T. D65 is always present (identity).
#[derive(Clone, Debug)]
pub struct IlluminantRegistry {
    grid: WavelengthGrid,
    cmfs: Cmfs,
    d65: Spectrum,
    reflectances: Vec<Spectrum>,
    white_preserving: bool,
    entries: BTreeMap<String, IlluminantEntry>,
}

impl IlluminantRegistry {
    /// An empty registry (D65 only) using `reflectances` for T.
    pub fn new(grid: WavelengthGrid, reflectances: Vec<Spectrum>) -> Result<Self, CorrectError> {
        let cmfs = Cmfs::cie1931(&grid);
        let d65 = cie_illuminant("D65")
            .ok_or_else(|| {
                CorrectError::InvalidParams("D65 missing from the built-in data".into())
            })?
            .resample(&grid, Extrapolation::Zero);
        let mut r = Self {
            grid,
            cmfs,
            d65,
            reflectances,
            white_preserving: false,
            entries: BTreeMap::new(),
        };
        let white = r.white_xy(&r.d65.clone());
        r.entries.insert(
            "D65".into(),
            IlluminantEntry {
                name: "D65".into(),
                t: IDENTITY,
                white_xy: white,
                cct: white.and_then(|w| cct_from_xy(w).ok()),
                source: CorrectionSource::Builtin,
                spd: Some(r.d65.clone()),
                level_corrections: Vec::new(),
                neutral: None,
            },
        );
        Ok(r)
    }

    /// The defaults: D65, D50, A, F2, F11, and ISET's measured Tungsten and
    /// Fluorescent (from `iset`; `None`: the built-in data).
    pub fn with_defaults(
        grid: WavelengthGrid,
        iset: Option<&IsetData>,
    ) -> Result<Self, CorrectError> {
        let refl = crate::scene::natural_reflectances(&grid, iset)
            .map_err(|e| CorrectError::InvalidInput(e.to_string()))?
            .into_iter()
            .map(|(_, s)| s)
            .collect();
        let mut r = Self::new(grid, refl)?;
        for name in ["D50", "A", "F2", "F11"] {
            let spd = cie_illuminant(name).ok_or_else(|| {
                CorrectError::InvalidParams(format!("{name} missing from built-in data"))
            })?;
            r.insert_spd(name, &spd, CorrectionSource::Builtin)?;
        }
        let data = IsetData::or_built_in(iset);
        for name in ["Tungsten", "Fluorescent"] {
            r.insert_spd(name, &data.light(name)?, CorrectionSource::Iset)?;
        }
        Ok(r)
    }

    pub fn grid(&self) -> &WavelengthGrid {
        &self.grid
    }

    fn white_xy(&self, spd: &Spectrum) -> Option<[f64; 2]> {
        self.cmfs.white(spd).ok().map(xy)
    }

    fn key(name: &str) -> String {
        name.trim().to_ascii_lowercase()
    }

    /// Look up by name, case-insensitively.
    pub fn get(&self, name: &str) -> Option<&IlluminantEntry> {
        let k = Self::key(name);
        self.entries.values().find(|e| Self::key(&e.name) == k)
    }

    pub fn entries(&self) -> impl Iterator<Item = &IlluminantEntry> {
        self.entries.values()
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// A name a light may be registered under: 1–64 characters of letters, digits, `-`, `_`,
    /// `.` and `:`.
    pub fn check_name(name: &str) -> Result<(), CorrectError> {
        let ok = !name.is_empty()
            && name.len() <= 64
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_.:".contains(c));
        if ok {
            Ok(())
        } else {
            Err(CorrectError::InvalidInput(format!(
                "illuminant name '{name}': 1–64 characters of A–Z, a–z, 0–9, '-', '_', '.', ':'"
            )))
        }
    }

    fn put(&mut self, e: IlluminantEntry) -> Result<&IlluminantEntry, CorrectError> {
        Self::check_name(&e.name)?;
        if Self::key(&e.name) == "d65" {
            return Err(CorrectError::InvalidInput(
                "D65 is the target and cannot be replaced".into(),
            ));
        }
        let existing = self
            .entries
            .keys()
            .find(|k| Self::key(k) == Self::key(&e.name))
            .cloned();
        if let Some(k) = existing {
            self.entries.remove(&k);
        }
        // (any entry under the name was removed just above)
        Ok(self.entries.entry(e.name.clone()).or_insert(e))
    }

    /// The correction T to D65 of an SPD on the registry's grid, as an entry
    /// registered from it would carry.
    pub fn correction_for(&self, spd: &Spectrum) -> Result<Mat3, CorrectError> {
        correction_matrix(
            &self.cmfs,
            &self.reflectances,
            spd,
            &self.d65,
            self.white_preserving,
        )
    }

    /// The correction entry of an SPD already on the registry's grid.
    fn entry_for(
        &self,
        name: &str,
        spd: &Spectrum,
        cct: Option<f64>,
        source: CorrectionSource,
    ) -> Result<IlluminantEntry, CorrectError> {
        if spd.values().iter().any(|v| *v < 0.0) {
            return Err(CorrectError::InvalidInput(format!(
                "SPD of '{name}' has negative values"
            )));
        }
        let t = self.correction_for(spd)?;
        let white = self.white_xy(spd);
        Ok(IlluminantEntry {
            name: name.to_string(),
            t,
            white_xy: white,
            cct: cct.or_else(|| white.and_then(|w| cct_from_xy(w).ok())),
            source,
            spd: Some(spd.clone()),
            level_corrections: Vec::new(),
            neutral: None,
        })
    }

    /// Register an illuminant from its SPD (any sampling; resampled here).
    pub fn insert_spd(
        &mut self,
        name: &str,
        spd: &Samples,
        source: CorrectionSource,
    ) -> Result<&IlluminantEntry, CorrectError> {
        let s = spd.resample(&self.grid, Extrapolation::Zero);
        let e = self.entry_for(name, &s, None, source)?;
        self.put(e)
    }

    /// Register a given matrix.
    pub fn insert_matrix(&mut self, name: &str, t: Mat3) -> Result<&IlluminantEntry, CorrectError> {
        if t.iter().flatten().any(|v| !v.is_finite()) {
            return Err(CorrectError::InvalidInput(
                "matrix has non-finite entries".into(),
            ));
        }
        if let Some(v) = t.iter().flatten().find(|v| v.abs() > MAX_MATRIX_ENTRY) {
            // fused into f32 kernels, such a matrix overflows to Inf/NaN pixels
            return Err(CorrectError::InvalidInput(format!(
                "matrix entry {v:e} is beyond ±{MAX_MATRIX_ENTRY:e}: not an XYZ → XYZ correction"
            )));
        }
        let m = Matrix3::from_fn(|i, j| t[i][j]);
        if m.determinant().abs() < 1e-9 {
            return Err(CorrectError::InvalidInput("matrix is singular".into()));
        }
        self.put(IlluminantEntry::from_matrix(name, t))
    }

    /// Register a blackbody (below 4000 K) or CIE daylight (from 4000 K) by CCT.
    pub fn insert_cct(&mut self, name: &str, cct: f64) -> Result<&IlluminantEntry, CorrectError> {
        let spd = IlluminantSpec::Cct(cct).resolve(None)?.spd;
        let s = spd.resample(&self.grid, Extrapolation::Zero);
        let e = self.entry_for(name, &s, Some(cct), CorrectionSource::Cct)?;
        self.put(e)
    }

    /// Remove an entry (never D65). Returns whether it existed.
    pub fn remove(&mut self, name: &str) -> Result<bool, CorrectError> {
        if Self::key(name) == "d65" {
            return Err(CorrectError::InvalidInput("D65 cannot be deleted".into()));
        }
        let k = self
            .entries
            .keys()
            .find(|k| Self::key(k) == Self::key(name))
            .cloned();
        Ok(k.and_then(|k| self.entries.remove(&k)).is_some())
    }

    /// Whether [`Self::resolve`] would answer `spec` from what is already held, without
    /// fitting a correction: a held name, or a `cct:K` or `xy:x,y` whose colour temperature
    /// is held. Cheap, for a caller deciding where the resolve may run.
    pub fn holds(&self, spec: &str) -> bool {
        if self.get(spec).is_some() {
            return true;
        }
        let cct = match xy_spec_cct(spec) {
            Ok(Some(k)) => Some(k),
            Ok(None) => match IlluminantSpec::parse(spec) {
                Ok(IlluminantSpec::Cct(k)) => Some(k),
                _ => None,
            },
            Err(_) => None,
        };
        cct.is_some_and(|k| self.get(&format!("cct:{}", k.round())).is_some())
    }

    /// Resolve a request's illuminant: a registered name, or `cct:K`
    /// (computed and cached as `cct:K`), or `xy:x,y` (the illuminant of that
    /// chromaticity's CCT, see [`xy_spec_cct`]), or any other spec that resolves to
    /// an SPD: a CIE name or an ISET light, computed and cached; a CSV or a light given by its
    /// samples, computed each time.
    pub fn resolve(
        &mut self,
        spec: &str,
        iset: Option<&IsetData>,
    ) -> Result<IlluminantEntry, CorrectError> {
        if let Some(e) = self.get(spec) {
            return Ok(e.clone());
        }
        if let Some(cct) = xy_spec_cct(spec)? {
            // corrected as the illuminant of that CCT (blackbody below 4000 K, daylight above)
            return self.resolve(&format!("cct:{}", cct.round()), iset);
        }
        let parsed = IlluminantSpec::parse(spec)?;
        match &parsed {
            IlluminantSpec::Cct(k) => {
                // computed at the kelvin it is cached under, so that what a request gets does
                // not depend on which nearby temperature was asked for first
                let k = k.round();
                let name = format!("cct:{k}");
                if let Some(e) = self.get(&name) {
                    return Ok(e.clone());
                }
                Ok(self.insert_cct(&name, k)?.clone())
            }
            IlluminantSpec::Csv { .. } => {
                // never cache arbitrary files under their path
                let spd = parsed.resolve(iset)?.spd;
                let s = spd.resample(&self.grid, Extrapolation::Zero);
                self.entry_for(&parsed.to_string(), &s, None, CorrectionSource::Spd)
            }
            IlluminantSpec::Samples { name, samples } => {
                // by the light's name, as a table trained under it records it; never cached
                // under that name, which in the registry may be another light's
                let s = samples.resample(&self.grid, Extrapolation::Zero);
                self.entry_for(name, &s, None, CorrectionSource::Spd)
            }
            _ => {
                let named = parsed.resolve(iset)?;
                let src = if matches!(parsed, IlluminantSpec::Iset(_)) {
                    CorrectionSource::Iset
                } else {
                    CorrectionSource::Builtin
                };
                Ok(self.insert_spd(&named.name, &named.spd, src)?.clone())
            }
        }
    }
}

/// The correlated colour temperature of an `xy:x,y` illuminant spec (`None` when `spec` is
/// not one): a chromaticity inside the spectrum locus triangle whose CCT lies in
/// 1000–25000 K.
pub fn xy_spec_cct(spec: &str) -> Result<Option<f64>, CorrectError> {
    let spec = spec.trim();
    let Some(rest) = spec
        .get(..3)
        .filter(|p| p.eq_ignore_ascii_case("xy:"))
        .map(|_| &spec[3..])
    else {
        return Ok(None);
    };
    let bad = |why: String| CorrectError::InvalidInput(format!("illuminant '{spec}': {why}"));
    let parts: Vec<f64> = rest
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad("expected xy:x,y with two numbers".into()))?;
    let [x, y] = parts[..] else {
        return Err(bad("expected xy:x,y with two numbers".into()));
    };
    if !(x > 0.0 && y > 0.0 && x + y < 1.0) {
        return Err(bad(format!(
            "chromaticity ({x}, {y}) is not inside the spectrum locus triangle"
        )));
    }
    let cct =
        cct_from_xy([x, y]).map_err(|e| bad(format!("no correlated colour temperature: {e}")))?;
    if !(1000.0..=25_000.0).contains(&cct) {
        return Err(bad(format!("its CCT {cct:.0} K is outside 1000–25000 K")));
    }
    Ok(Some(cct))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xy_specs_resolve_to_the_cct_of_their_chromaticity() {
        assert_eq!(xy_spec_cct("D65").unwrap(), None);
        let k = xy_spec_cct("xy:0.4476,0.4074").unwrap().unwrap();
        assert!((k - 2856.0).abs() < 5.0, "{k}");
        assert!(xy_spec_cct("XY: 0.3127, 0.3290").unwrap().is_some());
        assert!(xy_spec_cct("xy:0.9,0.9").is_err());
        assert!(xy_spec_cct("xy:1,2,3").is_err());
        assert!(xy_spec_cct("xy:ä").is_err());
    }

    #[test]
    fn holds_what_resolve_answers_without_a_fit() {
        let mut r = IlluminantRegistry::with_defaults(WavelengthGrid::default(), None).unwrap();
        assert!(r.holds("D65") && r.holds("tungsten"));
        for spec in [
            "cct:4321",
            "xy:0.3721,0.3751",
            "csv:x.csv",
            "nonesuch",
            "xy:0.9,0.9",
        ] {
            assert!(!r.holds(spec), "{spec}");
        }
        r.resolve("cct:4321.2", None).unwrap();
        assert!(r.holds("cct:4321") && r.holds("cct:4320.9"));
        // that chromaticity's colour temperature rounds to another kelvin
        let k = xy_spec_cct("xy:0.3721,0.3751").unwrap().unwrap().round();
        assert!(!r.holds("xy:0.3721,0.3751"));
        r.resolve("xy:0.3721,0.3751", None).unwrap();
        assert!(r.holds("xy:0.3721,0.3751") && r.holds(&format!("cct:{k}")));
    }

    /// `cct:K` is the light of the nearest kelvin, whichever request computed it first (at
    /// 4000 K the light switches from Planck's to daylight).
    #[test]
    fn cct_is_computed_at_the_kelvin_it_is_cached_under() {
        let g = WavelengthGrid::default();
        for (first, then) in [("cct:3999.5", "cct:4000"), ("cct:1500.4", "cct:1500")] {
            let mut warm = IlluminantRegistry::with_defaults(g, None).unwrap();
            warm.resolve(first, None).unwrap();
            let mut cold = IlluminantRegistry::with_defaults(g, None).unwrap();
            assert_eq!(
                warm.resolve(then, None).unwrap().t,
                cold.resolve(then, None).unwrap().t,
                "{first} then {then}"
            );
            assert_eq!(
                cold.resolve(first, None).unwrap().t,
                warm.resolve(first, None).unwrap().t
            );
        }
    }

    #[test]
    fn d65_is_identity_and_a_is_plausible() {
        let g = WavelengthGrid::default();
        let mut r = IlluminantRegistry::with_defaults(g, None).unwrap();
        assert_eq!(r.get("d65").unwrap().t, IDENTITY);
        // T computed for D65 from spectra is the identity too
        let d65 = cie_illuminant("D65").unwrap();
        r.insert_spd("D65copy", &d65, CorrectionSource::Spd)
            .unwrap();
        let t = r.get("D65copy").unwrap().t;
        for i in 0..3 {
            for j in 0..3 {
                assert!((t[i][j] - IDENTITY[i][j]).abs() < 1e-9);
            }
        }
        // A's white maps close to D65's white
        let a = r.get("A").unwrap().clone();
        let cmfs = Cmfs::cie1931(&g);
        let wa = cmfs
            .white(
                &cie_illuminant("A")
                    .unwrap()
                    .resample(&g, Extrapolation::Zero),
            )
            .unwrap();
        let mapped = crate::colour::mat3_mul_vec(&a.t, wa);
        let d = crate::colour::D65_WHITE_XYZ;
        for k in 0..3 {
            assert!((mapped[k] - d[k]).abs() < 0.02, "{mapped:?}");
        }
        assert!((a.cct.unwrap() - 2856.0).abs() < 30.0);
        assert!(r.get("F11").is_some() && r.get("f2").is_some());
    }

    #[test]
    fn registry_edits() {
        let g = WavelengthGrid::default();
        let mut r = IlluminantRegistry::new(g, default_reflectances(&g)).unwrap();
        assert!(r.remove("D65").is_err());
        assert!(r.insert_matrix("bad", [[0.0; 3]; 3]).is_err());
        assert!(r.insert_matrix("bad name!", IDENTITY).is_err());
        // huge finite entries would overflow fused f32 kernels (fuzz crasher)
        let mut huge = IDENTITY;
        huge[2][0] = 2.2e73;
        let e = r.insert_matrix("huge", huge).unwrap_err().to_string();
        assert!(e.contains("beyond"), "{e}");
        huge[2][0] = -999.0;
        assert!(r.insert_matrix("large", huge).is_ok());
        assert!(r.insert_matrix("D65", IDENTITY).is_err());
        r.insert_matrix("m1", [[1.1, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.9]])
            .unwrap();
        assert!(r.get("M1").is_some());
        let e = r.resolve("cct:3200", None).unwrap();
        assert_eq!(e.name, "cct:3200");
        assert!(r.get("cct:3200").is_some());
        assert!(r.resolve("nonsense", None).is_err());
        assert!(r.remove("m1").unwrap());
        assert!(!r.remove("m1").unwrap());
    }

    #[test]
    fn an_inline_light_resolves_under_its_name_and_is_not_cached() {
        let g = WavelengthGrid::default();
        let mut r = IlluminantRegistry::new(g, default_reflectances(&g)).unwrap();
        let a = cie_illuminant("A").unwrap();
        let spec = IlluminantSpec::samples("lamp", a.wavelengths().to_vec(), a.values().to_vec())
            .unwrap()
            .to_string();
        let n = r.entries().count();
        let e = r.resolve(&spec, None).unwrap();
        assert_eq!((e.name.as_str(), e.source), ("lamp", CorrectionSource::Spd));
        assert_eq!(r.entries().count(), n, "nothing is cached");
        assert!(r.get("lamp").is_none());
        // the same T as the light registered from those samples
        let registered = r.insert_spd("A2", &a, CorrectionSource::Spd).unwrap().t;
        assert_eq!(e.t, registered);
    }
}
