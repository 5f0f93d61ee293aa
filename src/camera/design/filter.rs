//! The spectral curves of a sensor design: a filter, IR-cut or QE as a parametric curve, a
//! constant, a column of a CSV file, or samples given inline.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::camera::CameraError;
use crate::spectral::{Extrapolation, IsetData, Samples, Spectrum, WavelengthGrid};

/// Sub-samples per band used to band-average parametric curves.
const PARAMETRIC_SUBSAMPLES: usize = 20;

/// A spectral curve of a filter, IR-cut or photodetector QE, dimensionless in
/// [0, 1]. In TOML exactly one form is given:
///
/// ```toml
/// R = { gaussian = { center_nm = 600.0, sigma_nm = 45.0, peak = 1.0 } }
/// W = { constant = 1.0 }
/// ir_cut = { short_pass = { edge_nm = 670.0, width_nm = 10.0 } }
/// G = { csv = "sensor/colorfilters/auto/ar0132atRGBW.csv", column = "gAR0132", scale = 1.0 }
/// B = { samples = { wavelength_nm = [400.0, 450.0, 500.0], values = [0.2, 0.9, 0.1] } }
/// ```
///
/// Parametric curves are band-averaged onto the simulation grid; CSV columns
/// are resampled area-preserving with zero outside their range. A relative CSV
/// path is looked up beside the sensor TOML first (when the design is loaded
/// from a file, [`SensorDesign::with_curves_beside`]), then as a table of the
/// spectral data ([`IsetData::table`]: the ISET data directory's file, else the
/// built-in copy).
///
/// [`SensorDesign::with_curves_beside`]: crate::camera::SensorDesign::with_curves_beside
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "FilterToml", into = "FilterToml")]
pub enum FilterSpec {
    /// `peak · exp(−(λ − center)² / (2σ²))`.
    Gaussian {
        center_nm: f64,
        sigma_nm: f64,
        peak: f64,
    },
    /// The same value at every wavelength (1 = clear).
    Constant(f64),
    /// A smooth short-pass (IR-cut) edge: `1 / (1 + exp((λ − edge) / width))`,
    /// transmitting 0.5 at `edge_nm`.
    ShortPass { edge_nm: f64, width_nm: f64 },
    /// Column `column` of a `wavelength_nm,<name>…` CSV file, times `scale`
    /// (e.g. 0.01 for a QE in percent).
    Csv {
        path: String,
        column: String,
        scale: f64,
    },
    /// Samples given inline (a measured curve without a file: what a design sent over HTTP
    /// carries, [`FilterSpec::inlined`]), times `scale`.
    Samples {
        wavelength_nm: Vec<f64>,
        values: Vec<f64>,
        scale: f64,
    },
}

/// The most samples an inline curve may hold.
pub const MAX_INLINE_SAMPLES: usize = 4096;

/// How far inside the simulation grid's first or last band a measured curve (a CSV column or
/// inline samples) may start or stop, in nm, before it is noted as covering less than the
/// grid ([`CoverageNote`]).
pub const COVERAGE_SLACK_NM: f64 = 10.0;

/// A measured curve whose samples cover clearly less than the simulation grid: they start
/// more than [`COVERAGE_SLACK_NM`] after its first band or stop more than that before its
/// last. The curve is taken as zero outside its samples, as documented, but a file cut short
/// by mistake would pass unnoticed: resolving a design returns these notes for its caller to
/// show (the command line warns; the core never prints).
#[derive(Clone, Debug, PartialEq)]
pub struct CoverageNote {
    /// The curve, e.g. `'my-camera': filter 'R'`.
    pub curve: String,
    /// Where its samples are: a CSV file and column, or inline samples.
    pub source: String,
    /// The first and last wavelengths of its samples, nm.
    pub covered_nm: (f64, f64),
    /// The first and last band centres of the grid, nm.
    pub grid_nm: (f64, f64),
}

impl CoverageNote {
    /// The note for `samples` of `curve` (from `source`) on `grid`, when they cover clearly
    /// less than it.
    fn of(samples: &Samples, grid: &WavelengthGrid, curve: &str, source: String) -> Option<Self> {
        let w = samples.wavelengths();
        let (first, last) = (*w.first()?, *w.last()?);
        let (start, end) = (grid.start_nm, grid.end_nm());
        let short = first > start + COVERAGE_SLACK_NM || last < end - COVERAGE_SLACK_NM;
        short.then(|| CoverageNote {
            curve: curve.to_string(),
            source,
            covered_nm: (first, last),
            grid_nm: (start, end),
        })
    }
}

impl std::fmt::Display for CoverageNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ((a, b), (g0, g1)) = (self.covered_nm, self.grid_nm);
        write!(
            f,
            "{}: {} covers only {a}–{b} nm of the {g0}–{g1} nm simulation grid; the curve is \
             taken as zero outside {a}–{b} nm (give samples over the whole grid, with zeros \
             where the curve does not respond, if that is meant)",
            self.curve, self.source
        )
    }
}

/// Negative values down to this fraction of a curve's peak are measurement noise, taken as 0.
pub const NEGATIVE_NOISE_FRACTION: f64 = 0.01;

/// Parameters of [`FilterSpec::Samples`] as written in TOML.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SamplesToml {
    wavelength_nm: Vec<f64>,
    values: Vec<f64>,
}

/// Parameters of [`FilterSpec::Gaussian`] as written in TOML.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GaussianToml {
    center_nm: f64,
    sigma_nm: f64,
    #[serde(default = "one")]
    peak: f64,
}

/// Parameters of [`FilterSpec::ShortPass`] as written in TOML.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ShortPassToml {
    edge_nm: f64,
    width_nm: f64,
}

fn one() -> f64 {
    1.0
}

/// The TOML shape of a [`FilterSpec`]: one of the keys is set.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FilterToml {
    #[serde(skip_serializing_if = "Option::is_none")]
    gaussian: Option<GaussianToml>,
    #[serde(skip_serializing_if = "Option::is_none")]
    constant: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    short_pass: Option<ShortPassToml>,
    #[serde(skip_serializing_if = "Option::is_none")]
    csv: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    samples: Option<SamplesToml>,
    #[serde(skip_serializing_if = "Option::is_none")]
    column: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    scale: Option<f64>,
}

impl TryFrom<FilterToml> for FilterSpec {
    type Error = String;
    fn try_from(t: FilterToml) -> Result<Self, String> {
        let kinds = [
            t.gaussian.is_some(),
            t.constant.is_some(),
            t.short_pass.is_some(),
            t.csv.is_some(),
            t.samples.is_some(),
        ];
        if kinds.iter().filter(|k| **k).count() != 1 {
            return Err(
                "a filter needs exactly one of `gaussian`, `constant`, `short_pass`, `csv` or `samples`"
                    .into(),
            );
        }
        if t.csv.is_none() && t.column.is_some() {
            return Err("`column` only goes with `csv`".into());
        }
        if t.csv.is_none() && t.samples.is_none() && t.scale.is_some() {
            return Err("`scale` only goes with `csv` or `samples`".into());
        }
        Ok(if let Some(g) = t.gaussian {
            FilterSpec::Gaussian {
                center_nm: g.center_nm,
                sigma_nm: g.sigma_nm,
                peak: g.peak,
            }
        } else if let Some(v) = t.constant {
            FilterSpec::Constant(v)
        } else if let Some(s) = t.short_pass {
            FilterSpec::ShortPass {
                edge_nm: s.edge_nm,
                width_nm: s.width_nm,
            }
        } else if let Some(SamplesToml {
            wavelength_nm,
            values,
        }) = t.samples
        {
            FilterSpec::Samples {
                wavelength_nm,
                values,
                scale: t.scale.unwrap_or(1.0),
            }
        } else {
            let path = t.csv.unwrap_or_default();
            let column = t
                .column
                .ok_or_else(|| format!("csv = \"{path}\" needs `column = \"<name>\"`"))?;
            FilterSpec::Csv {
                path,
                column,
                scale: t.scale.unwrap_or(1.0),
            }
        })
    }
}

impl From<FilterSpec> for FilterToml {
    fn from(f: FilterSpec) -> Self {
        match f {
            FilterSpec::Gaussian {
                center_nm,
                sigma_nm,
                peak,
            } => FilterToml {
                gaussian: Some(GaussianToml {
                    center_nm,
                    sigma_nm,
                    peak,
                }),
                ..Default::default()
            },
            FilterSpec::Constant(v) => FilterToml {
                constant: Some(v),
                ..Default::default()
            },
            FilterSpec::ShortPass { edge_nm, width_nm } => FilterToml {
                short_pass: Some(ShortPassToml { edge_nm, width_nm }),
                ..Default::default()
            },
            FilterSpec::Csv {
                path,
                column,
                scale,
            } => FilterToml {
                csv: Some(path),
                column: Some(column),
                scale: (scale != 1.0).then_some(scale),
                ..Default::default()
            },
            FilterSpec::Samples {
                wavelength_nm,
                values,
                scale,
            } => FilterToml {
                samples: Some(SamplesToml {
                    wavelength_nm,
                    values,
                }),
                scale: (scale != 1.0).then_some(scale),
                ..Default::default()
            },
        }
    }
}

impl FilterSpec {
    /// Check the parameters (not the CSV file); `what` names the curve in errors.
    pub(super) fn validate(&self, what: &str) -> Result<(), CameraError> {
        let bad = |msg: String| Err(CameraError::InvalidDesign(format!("{what}: {msg}")));
        match self {
            FilterSpec::Gaussian {
                center_nm,
                sigma_nm,
                peak,
            } => {
                if !(center_nm.is_finite() && (100.0..=3000.0).contains(center_nm)) {
                    return bad(format!(
                        "center_nm = {center_nm} must be within 100–3000 nm"
                    ));
                }
                if !(sigma_nm.is_finite() && *sigma_nm > 0.0 && *sigma_nm <= 2000.0) {
                    return bad(format!("sigma_nm = {sigma_nm} must be within (0, 2000] nm"));
                }
                if !(peak.is_finite() && (0.0..=1.0).contains(peak)) {
                    return bad(format!("peak = {peak} must be within [0, 1]"));
                }
            }
            FilterSpec::Constant(v) => {
                if !(v.is_finite() && (0.0..=1.0).contains(v)) {
                    return bad(format!("constant = {v} must be within [0, 1]"));
                }
            }
            FilterSpec::ShortPass { edge_nm, width_nm } => {
                if !(edge_nm.is_finite() && (100.0..=3000.0).contains(edge_nm)) {
                    return bad(format!("edge_nm = {edge_nm} must be within 100–3000 nm"));
                }
                if !(width_nm.is_finite() && *width_nm > 0.0 && *width_nm <= 500.0) {
                    return bad(format!("width_nm = {width_nm} must be within (0, 500] nm"));
                }
            }
            FilterSpec::Csv {
                path,
                column,
                scale,
            } => {
                if path.trim().is_empty() {
                    return bad("csv path is empty".into());
                }
                if column.trim().is_empty() {
                    return bad("csv column is empty".into());
                }
                if !(scale.is_finite() && *scale > 0.0 && *scale <= 100.0) {
                    return bad(format!("scale = {scale} must be within (0, 100]"));
                }
            }
            FilterSpec::Samples {
                wavelength_nm,
                values,
                scale,
            } => {
                if wavelength_nm.len() > MAX_INLINE_SAMPLES {
                    return bad(format!(
                        "{} samples; at most {MAX_INLINE_SAMPLES} are taken",
                        wavelength_nm.len()
                    ));
                }
                if !(scale.is_finite() && *scale > 0.0 && *scale <= 100.0) {
                    return bad(format!("scale = {scale} must be within (0, 100]"));
                }
                if let Err(e) = Samples::new(wavelength_nm.clone(), values.clone()) {
                    return bad(format!("samples: {e}"));
                }
            }
        }
        Ok(())
    }

    /// The curve on `grid` (band averages), checked to lie in [0, 1].
    /// `iset` holds relative CSV paths (`None`: the built-in data).
    pub fn resolve(
        &self,
        grid: &WavelengthGrid,
        iset: Option<&IsetData>,
        what: &str,
    ) -> Result<Spectrum, CameraError> {
        Ok(self.resolve_noted(grid, iset, what)?.0)
    }

    /// [`Self::resolve`], with a note when the curve's samples cover clearly less than
    /// `grid` ([`CoverageNote`]; only a CSV column or inline samples can).
    pub fn resolve_noted(
        &self,
        grid: &WavelengthGrid,
        iset: Option<&IsetData>,
        what: &str,
    ) -> Result<(Spectrum, Option<CoverageNote>), CameraError> {
        self.validate(what)?;
        let mut note = None;
        let mut source = String::new();
        let spectrum = match self {
            FilterSpec::Gaussian {
                center_nm,
                sigma_nm,
                peak,
            } => band_average(grid, |l| {
                peak * (-0.5 * ((l - center_nm) / sigma_nm).powi(2)).exp()
            }),
            FilterSpec::Constant(v) => Spectrum::constant(*grid, *v),
            FilterSpec::ShortPass { edge_nm, width_nm } => {
                band_average(grid, |l| 1.0 / (1.0 + ((l - edge_nm) / width_nm).exp()))
            }
            FilterSpec::Csv {
                path,
                column,
                scale,
            } => {
                let samples = csv_samples(path, column, iset, what)?;
                source = format!(" ({path}, column '{column}')");
                note =
                    CoverageNote::of(&samples, grid, what, format!("{path} (column '{column}')"));
                samples.resample(grid, Extrapolation::Zero).scaled(*scale)
            }
            FilterSpec::Samples {
                wavelength_nm,
                values,
                scale,
            } => {
                let samples = Samples::new(wavelength_nm.clone(), values.clone())?;
                note = CoverageNote::of(&samples, grid, what, "its inline samples".into());
                samples.resample(grid, Extrapolation::Zero).scaled(*scale)
            }
        };
        // measurement noise leaves small negatives in a curve's tails: they are zero
        let peak = spectrum.max().max(0.0);
        let floor = -NEGATIVE_NOISE_FRACTION * peak;
        let mut values = spectrum.values().to_vec();
        for (i, v) in values.iter_mut().enumerate() {
            let band = grid.wavelength(i);
            if !v.is_finite() || *v > 1.0 + 1e-9 {
                return Err(CameraError::InvalidDesign(format!(
                    "{what}{source}: value {v} (averaged over the band at {band} nm) is outside \
                     [0, 1] (a transmittance or quantum efficiency; use `scale` for data in \
                     percent)"
                )));
            }
            if *v < -1e-12 && *v < floor {
                return Err(CameraError::InvalidDesign(format!(
                    "{what}{source}: value {v} (averaged over the band at {band} nm) is \
                     negative beyond measurement noise ({:.0} % of the peak {peak})",
                    NEGATIVE_NOISE_FRACTION * 100.0
                )));
            }
            *v = v.max(0.0);
        }
        Ok((Spectrum::new(*grid, values)?, note))
    }
}

impl FilterSpec {
    /// The curve with a CSV column replaced by its samples, read as [`Self::resolve`] reads
    /// them (absolute: that file; relative: a table of the spectral data), so that the design
    /// needs no file: what a design sent to the service must be. Other forms are kept.
    pub fn inlined(&self, iset: Option<&IsetData>, what: &str) -> Result<Self, CameraError> {
        let FilterSpec::Csv {
            path,
            column,
            scale,
        } = self
        else {
            return Ok(self.clone());
        };
        let samples = csv_samples(path, column, iset, what)?;
        let (w, v) = (samples.wavelengths(), samples.values());
        // the samples the default grid's bands reach, and one beyond either end, so that the
        // curve resolves exactly as its file does
        let (lo, hi) = {
            let g = WavelengthGrid::default();
            (g.start_nm - g.step_nm, g.end_nm() + g.step_nm)
        };
        let first = w.partition_point(|&x| x < lo).saturating_sub(1);
        let last = (w.partition_point(|&x| x <= hi) + 1).min(w.len());
        // a curve off the grid stays whole, for the error that names its range
        let (first, last) = if last - first < 2 {
            (0, w.len())
        } else {
            (first, last)
        };
        if last - first > MAX_INLINE_SAMPLES {
            return Err(CameraError::InvalidDesign(format!(
                "{what}: {} has {} samples between {} and {} nm; a design inlined for the \
                 service takes at most {MAX_INLINE_SAMPLES} per curve (resample the file, to \
                 1 nm say)",
                path,
                last - first,
                w[first],
                w[last - 1]
            )));
        }
        Ok(FilterSpec::Samples {
            wavelength_nm: w[first..last].to_vec(),
            values: v[first..last].to_vec(),
            scale: *scale,
        })
    }
}

impl FilterSpec {
    /// The curve as a table records it: a CSV column that only this machine's files give (an
    /// absolute path, or a table of `iset` that the built-in data lacks or holds otherwise)
    /// replaced by its samples ([`Self::inlined`]), so that the table renders and evaluates
    /// wherever it is copied and whatever becomes of the file; a column of the built-in data
    /// keeps its name. A curve that cannot be inlined (too many samples) keeps its path.
    pub fn portable(&self, iset: Option<&IsetData>, what: &str) -> Self {
        let FilterSpec::Csv { path, column, .. } = self else {
            return self.clone();
        };
        let built_in = || csv_samples(path, column, None, what).ok();
        let same = |a: &Samples, b: &Samples| {
            a.wavelengths() == b.wavelengths() && a.values() == b.values()
        };
        let keep = !Path::new(path).is_absolute()
            && match (built_in(), iset) {
                (None, _) => false,
                (Some(_), None) => true,
                (Some(b), Some(_)) => {
                    csv_samples(path, column, iset, what).is_ok_and(|theirs| same(&b, &theirs))
                }
            };
        if keep {
            return self.clone();
        }
        self.inlined(iset, what).unwrap_or_else(|_| self.clone())
    }
}

/// Column `column` of the CSV file `path`: absolute, that file; relative, a table of the
/// spectral data.
fn csv_samples(
    path: &str,
    column: &str,
    iset: Option<&IsetData>,
    what: &str,
) -> Result<Samples, CameraError> {
    let p = Path::new(path);
    let table = if p.is_absolute() {
        crate::spectral::load_csv(p)
    } else {
        IsetData::or_built_in(iset).table(path)
    }
    .map_err(|e| CameraError::InvalidDesign(format!("{what}: {e}")))?;
    table
        .samples(column)
        .map_err(|e| CameraError::InvalidDesign(format!("{what}: {e}")))
}

/// Band average of a smooth function: midpoint rule with
/// [`PARAMETRIC_SUBSAMPLES`] points per band.
fn band_average(grid: &WavelengthGrid, f: impl Fn(f64) -> f64) -> Spectrum {
    let n = PARAMETRIC_SUBSAMPLES;
    let h = grid.step_nm;
    Spectrum::from_fn(*grid, |c| {
        (0..n)
            .map(|j| f(c - 0.5 * h + (j as f64 + 0.5) * h / n as f64))
            .sum::<f64>()
            / n as f64
    })
}
