//! The L3 table: kernels per class plus everything needed to classify, in a
//! self-describing, checksummed safetensors file (readable from numpy; the file format
//! is in `format.rs`).

mod format;

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::classify::{ClassifyError, PatchGeometry};
use super::params::L3Params;
use crate::camera::Cfa;
use crate::spectral::WavelengthGrid;

pub use format::TABLE_FORMAT_VERSION;
pub(crate) use format::serialize_sorted;

/// The format name a table file's metadata carries.
const FORMAT_NAME: &str = "l3-table";

/// Errors of a table: a file that cannot be read as one, a table that is not usable, a
/// table that cannot be saved, and what its metadata lacks.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// A file (or bytes) that is not a valid table; `path` names where it came from.
    #[error("table file {path}: {msg}")]
    BadFile { path: String, msg: String },
    /// A table whose contents do not make a usable table (shapes, values, parameters).
    #[error("table is not usable: {0}")]
    Unusable(String),
    #[error("cannot save the table: {0}")]
    Write(#[source] Box<crate::io::IoError>),
    /// The table carries no sensor description, so no neutral can be matched through it.
    #[error("the table has no sensor description to match the frame's neutral with")]
    NoSensor,
    /// A light the table's chroma classes cannot be balanced by (a malformed neutral).
    #[error(transparent)]
    Classify(#[from] ClassifyError),
}

/// Same-illuminant (sensor under X → XYZ under X) or cross-illuminant
/// (sensor under X → XYZ under D65).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TableKind {
    #[serde(rename = "si")]
    SameIlluminant,
    #[serde(rename = "cross")]
    CrossIlluminant,
}

impl std::fmt::Display for TableKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::SameIlluminant => "si",
            Self::CrossIlluminant => "cross",
        })
    }
}

/// Everything about a table except its numbers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TableMeta {
    pub format: String,
    pub version: u32,
    pub kind: TableKind,
    /// Illuminants the training scenes were lit by.
    pub train_illuminants: Vec<String>,
    /// The chromaticity (CIE 1931 x, y) of each training light's white, in the order of
    /// `train_illuminants`: what tells a light registered later under one of those names,
    /// with other samples, from the light the table was trained under. Empty in tables
    /// written before it was recorded.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub train_white_xy: Vec<[f64; 2]>,
    /// `same` for SI tables, else the target illuminant (D65).
    pub target_illuminant: String,
    pub sensor_name: String,
    /// The full sensor design, as JSON.
    pub sensor: serde_json::Value,
    pub cfa: Cfa,
    pub grid: WavelengthGrid,
    pub params: L3Params,
    pub voltage_swing: f64,
    pub saturation_threshold: f64,
    /// Saturation cases with kernels, as channel bit masks; 0 (none) first.
    pub sat_cases: Vec<u32>,
    /// The output scale: XYZ in volts-equivalent (see `camera` docs).
    pub xyz_scale_note: String,
    pub seed: u64,
    pub created_unix_s: u64,
    pub training_seconds: f64,
    /// Free-form training summary (sample counts, timings, scene counts).
    pub summary: serde_json::Value,
}

/// Training diagnostics of one class.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClassReport {
    pub samples: u64,
    pub lambda: f64,
    /// Condition number of the covariance of the class's active regressors
    /// (1 for an intercept-only class).
    pub condition: f64,
    pub kernel_norm: f64,
    /// Level whose data filled this class when it had too few samples
    /// (−1: its own data).
    pub filled_from: i32,
    /// Output noise, volts-equivalent XYZ: the largest per-output weight norm
    /// (intercept excluded) × the sensor's per-pixel noise σ at the level.
    /// 0 in tables written before it was recorded.
    pub noise_sigma: f64,
    /// Patch pixels with non-zero variance in the class's data (saturated
    /// channels are zeroed); `None` in older tables.
    pub active: Option<u32>,
    /// Numerical rank of the active regressors' covariance.
    pub rank: Option<u32>,
}

impl ClassReport {
    /// A short explanation of an unusual class, for reports.
    pub fn note(&self) -> Option<String> {
        match (self.active, self.rank) {
            (Some(0), _) => Some(
                "intercept only: every patch pixel is saturated or constant, so the kernel \
                 returns the class's mean XYZ"
                    .into(),
            ),
            (Some(a), Some(r)) if r < a => Some(format!(
                "{r} of {a} pixel directions vary in the training data (uniform or \
                 collinear patches); the ridge sets the rest"
            )),
            _ => None,
        }
    }
}

/// A trained L3 table.
#[derive(Clone, Debug)]
pub struct L3Table {
    pub meta: TableMeta,
    /// `n_classes × 3 × n_features`, class-major.
    pub kernels: Vec<f32>,
    /// Flat/texture split per (position, level, saturation case).
    pub contrast_thresholds: Vec<f32>,
    pub reports: Vec<ClassReport>,
}

impl L3Table {
    /// The sensor design the table was trained for (stored in its metadata),
    /// checked as a design file is.
    pub fn sensor_design(&self) -> Result<crate::camera::SensorDesign, TableError> {
        if self.meta.sensor.is_null() {
            return Err(TableError::NoSensor);
        }
        let d: crate::camera::SensorDesign = serde_json::from_value(self.meta.sensor.clone())
            .map_err(|e| {
                TableError::Unusable(format!("the table's sensor description is unreadable: {e}"))
            })?;
        d.validate()
            .map_err(|e| TableError::Unusable(format!("the table's sensor: {e}")))?;
        Ok(d)
    }

    pub fn n_positions(&self) -> usize {
        self.meta.cfa.rows * self.meta.cfa.cols
    }
    pub fn n_levels(&self) -> usize {
        self.meta.params.levels.len()
    }
    /// Chroma classes per level (1 without a chroma split).
    pub fn n_chroma(&self) -> usize {
        self.meta
            .params
            .chroma
            .as_ref()
            .map_or(1, |c| c.len().max(1))
    }
    /// Classification bands: levels × chroma classes (band = level ×
    /// chroma classes + class).
    pub fn n_bands(&self) -> usize {
        self.n_levels() * self.n_chroma()
    }
    pub fn n_sat_cases(&self) -> usize {
        self.meta.sat_cases.len()
    }
    pub fn n_features(&self) -> usize {
        self.meta.params.patch_size * self.meta.params.patch_size + 1
    }
    pub fn n_classes(&self) -> usize {
        self.n_positions() * self.n_bands() * self.n_sat_cases() * 2
    }

    /// Index of the (position, band, saturation case) group.
    #[inline]
    pub fn group_index(&self, pos: usize, band: usize, sat: usize) -> usize {
        (pos * self.n_bands() + band) * self.n_sat_cases() + sat
    }

    /// Index of a class: its group, then flat (0) or texture (1).
    #[inline]
    pub fn class_index(&self, pos: usize, band: usize, sat: usize, texture: bool) -> usize {
        self.group_index(pos, band, sat) * 2 + texture as usize
    }

    /// The band of class `class` (the inverse of [`Self::class_index`] for the band).
    #[inline]
    pub fn class_band(&self, class: usize) -> usize {
        (class / (2 * self.n_sat_cases().max(1))) % self.n_bands().max(1)
    }

    /// The luminance level of class `class`.
    #[inline]
    pub fn class_level(&self, class: usize) -> usize {
        self.class_band(class) / self.n_chroma()
    }

    /// The kernel of class `class`: 3 rows of `n_features`.
    pub fn kernel(&self, class: usize) -> &[f32] {
        let n = 3 * self.n_features();
        &self.kernels[class * n..(class + 1) * n]
    }

    /// Whether the table's chroma classes balance by the light they classify
    /// under ([`super::classify::chroma`]): a split with a reference neutral.
    pub fn chroma_balances(&self) -> bool {
        self.meta
            .params
            .chroma
            .as_ref()
            .is_some_and(|c| c.len() > 1 && c.white.is_some())
    }

    /// Patch geometry for classification with this table under the light whose neutral
    /// (channel responses to white) is `light`: the chroma classes balance by it
    /// ([`PatchGeometry::under_light`]); `None`, the classes' reference light.
    pub fn geometry_under(&self, light: Option<&[f64]>) -> Result<PatchGeometry, TableError> {
        Ok(self.geometry()?.under_light(light)?.into_owned())
    }

    /// Patch geometry for classification with this table.
    /// A table whose parameters make no geometry is not usable ([`TableError::Unusable`]): its
    /// parameters are the table's, not a caller's.
    pub fn geometry(&self) -> Result<PatchGeometry, TableError> {
        let geo = PatchGeometry::new(
            self.meta.params.patch_size,
            &self.meta.cfa,
            &self.meta.params.levels,
            self.meta.saturation_threshold,
        )
        .map_err(|e| TableError::Unusable(e.to_string()))?;
        match &self.meta.params.chroma {
            Some(c) => geo
                .with_chroma(c)
                .map_err(|e| TableError::Unusable(e.to_string())),
            None => Ok(geo),
        }
    }

    /// Bytes of the kernel data (what a per-illuminant table costs).
    pub fn kernel_bytes(&self) -> usize {
        self.kernels.len() * 4 + self.contrast_thresholds.len() * 4
    }

    /// Check shapes and finiteness.
    pub fn validate(&self) -> Result<(), TableError> {
        let bad = |m: String| Err(TableError::Unusable(m));
        self.meta
            .params
            .validate()
            .map_err(|e| TableError::Unusable(e.to_string()))?;
        if self.meta.format != FORMAT_NAME {
            return bad(format!(
                "format '{}', expected '{FORMAT_NAME}'",
                self.meta.format
            ));
        }
        if self.meta.version != TABLE_FORMAT_VERSION {
            return bad(format!(
                "format version {} (this build reads version {TABLE_FORMAT_VERSION})",
                self.meta.version
            ));
        }
        let cfa = &self.meta.cfa;
        if cfa.rows == 0 || cfa.cols == 0 || cfa.pattern.len() != cfa.rows * cfa.cols {
            return bad("malformed CFA".into());
        }
        if self.meta.sat_cases.first() != Some(&0) {
            return bad("saturation cases must start with the unsaturated case".into());
        }
        if self.kernels.len() != self.n_classes() * 3 * self.n_features() {
            return bad(format!(
                "{} kernel values, expected {} classes × 3 × {}",
                self.kernels.len(),
                self.n_classes(),
                self.n_features()
            ));
        }
        if self.contrast_thresholds.len() != self.n_classes() / 2 {
            return bad("contrast threshold count does not match the classes".into());
        }
        if self.reports.len() != self.n_classes() {
            return bad("class report count does not match the classes".into());
        }
        if let Some(i) = self.kernels.iter().position(|v| !v.is_finite()) {
            return bad(format!("kernel value {i} is not finite"));
        }
        if self.contrast_thresholds.iter().any(|v| !v.is_finite()) {
            return bad("a contrast threshold is not finite".into());
        }
        if !(self.meta.voltage_swing.is_finite() && self.meta.voltage_swing > 0.0) {
            return bad("voltage swing must be positive".into());
        }
        self.geometry().map(|_| ())
    }

    /// Write atomically ([`crate::io`]'s one routine: a temporary file beside the target,
    /// fsynced, renamed, the directory fsynced), creating the directory.
    pub fn save(&self, path: &Path) -> Result<(), TableError> {
        let bytes = self.to_bytes()?;
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
        if let Some(d) = dir {
            std::fs::create_dir_all(d).map_err(|e| {
                TableError::Write(Box::new(crate::io::IoError::file("create", d, e)))
            })?;
        }
        crate::io::write_bytes_atomic(path, &bytes).map_err(|e| TableError::Write(Box::new(e)))
    }

    pub fn load(path: &Path) -> Result<Self, TableError> {
        let bytes = std::fs::read(path).map_err(|e| TableError::BadFile {
            path: path.display().to_string(),
            msg: e.to_string(),
        })?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }
}
