//! The L3 table: kernels per class plus everything needed to classify, in a
//! self-describing, checksummed safetensors file (readable from numpy).

use std::collections::HashMap;
use std::path::Path;

use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::{L3Error, L3Params, PatchGeometry};
use crate::camera::Cfa;
use crate::spectral::WavelengthGrid;

pub const TABLE_FORMAT_VERSION: u32 = 1;
const FORMAT_NAME: &str = "l3-table";

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
    /// The report of a solved class with `n_features` regressors (the last
    /// the constant) at a level with per-pixel noise `sigma` volts.
    pub fn new(
        samples: u64,
        filled_from: i32,
        sol: &super::ClassSolution,
        n_features: usize,
        sigma: f64,
    ) -> Self {
        let gain = sol
            .kernel
            .chunks(n_features.max(1))
            .map(|row| {
                row[..row.len().saturating_sub(1)]
                    .iter()
                    .map(|v| v * v)
                    .sum::<f64>()
                    .sqrt()
            })
            .fold(0.0, f64::max);
        Self {
            samples,
            lambda: sol.lambda,
            condition: sol.condition,
            kernel_norm: sol.kernel.iter().map(|v| v * v).sum::<f64>().sqrt(),
            filled_from,
            noise_sigma: gain * sigma,
            active: Some(sol.active as u32),
            rank: Some(sol.rank as u32),
        }
    }

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
    pub fn sensor_design(&self) -> Result<crate::camera::SensorDesign, L3Error> {
        if self.meta.sensor.is_null() {
            return Err(L3Error::NoSensor);
        }
        let d: crate::camera::SensorDesign = serde_json::from_value(self.meta.sensor.clone())
            .map_err(|e| {
                L3Error::Table(format!("the table's sensor description is unreadable: {e}"))
            })?;
        d.validate()
            .map_err(|e| L3Error::Table(format!("the table's sensor: {e}")))?;
        Ok(d)
    }

    /// The colour temperature whose white response, through the table's sensor, best matches
    /// a raw file's neutral (e.g. a DNG's AsShotNeutral, per channel name): see
    /// [`Camera::cct_from_neutral`](crate::camera::Camera::cct_from_neutral). The sensor's
    /// curves are read through `iset` (the built-in data when `None`).
    pub fn illuminant_from_neutral(
        &self,
        neutral: &[(String, f64)],
        iset: Option<&crate::spectral::IsetData>,
    ) -> Result<crate::camera::NeutralMatch, L3Error> {
        let design = self.sensor_design()?;
        let camera = crate::camera::Camera::new(&design, self.meta.grid, iset)
            .map_err(|e| L3Error::Table(format!("the table's sensor: {e}")))?;
        camera
            .cct_from_neutral(neutral)
            .map_err(|e| L3Error::Neutral(e.to_string()))
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
    /// under ([`super::chroma`]): a split with a reference neutral.
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
    pub fn geometry_under(&self, light: Option<&[f64]>) -> Result<PatchGeometry, L3Error> {
        Ok(self.geometry()?.under_light(light)?.into_owned())
    }

    /// Patch geometry for classification with this table.
    /// A table whose parameters make no geometry is not usable ([`L3Error::Table`]): its
    /// parameters are the table's, not a caller's.
    pub fn geometry(&self) -> Result<PatchGeometry, L3Error> {
        let geo = PatchGeometry::new(
            self.meta.params.patch_size,
            &self.meta.cfa,
            &self.meta.params.levels,
            self.meta.saturation_threshold,
        )
        .map_err(|e| L3Error::Table(e.to_string()))?;
        match &self.meta.params.chroma {
            Some(c) => geo
                .with_chroma(c)
                .map_err(|e| L3Error::Table(e.to_string())),
            None => Ok(geo),
        }
    }

    /// Bytes of the kernel data (what a per-illuminant table costs).
    pub fn kernel_bytes(&self) -> usize {
        self.kernels.len() * 4 + self.contrast_thresholds.len() * 4
    }

    /// Check shapes and finiteness.
    pub fn validate(&self) -> Result<(), L3Error> {
        let bad = |m: String| Err(L3Error::Table(m));
        self.meta
            .params
            .validate()
            .map_err(|e| L3Error::Table(e.to_string()))?;
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

    /// Serialize to safetensors bytes with a SHA-256 checksum in the header.
    pub fn to_bytes(&self) -> Result<Vec<u8>, L3Error> {
        self.validate()?;
        let n_pos = self.n_positions();
        let (nl, ns, nf) = (self.n_bands(), self.n_sat_cases(), self.n_features());
        let nc = self.n_classes();
        let meta_json = serde_json::to_string(&self.meta)
            .map_err(|e| L3Error::Table(format!("metadata: {e}")))?;
        let kernels = f32_bytes(&self.kernels);
        let thresholds = f32_bytes(&self.contrast_thresholds);
        let r = &self.reports;
        let samples: Vec<f64> = r.iter().map(|c| c.samples as f64).collect();
        let lambda: Vec<f64> = r.iter().map(|c| c.lambda).collect();
        let cond: Vec<f64> = r.iter().map(|c| c.condition.min(f64::MAX)).collect();
        let norm: Vec<f64> = r.iter().map(|c| c.kernel_norm).collect();
        let filled: Vec<f64> = r.iter().map(|c| c.filled_from as f64).collect();
        let sigma: Vec<f64> = r.iter().map(|c| c.noise_sigma).collect();
        let opt = |v: Option<u32>| v.map(f64::from).unwrap_or(-1.0);
        let active: Vec<f64> = r.iter().map(|c| opt(c.active)).collect();
        let rank: Vec<f64> = r.iter().map(|c| opt(c.rank)).collect();
        let tensors: Vec<(&str, Dtype, Vec<usize>, Vec<u8>)> = vec![
            ("kernels", Dtype::F32, vec![nc, 3, nf], kernels),
            (
                "contrast_thresholds",
                Dtype::F32,
                vec![n_pos, nl, ns],
                thresholds,
            ),
            ("class_samples", Dtype::F64, vec![nc], f64_bytes(&samples)),
            ("class_lambda", Dtype::F64, vec![nc], f64_bytes(&lambda)),
            ("class_condition", Dtype::F64, vec![nc], f64_bytes(&cond)),
            ("class_kernel_norm", Dtype::F64, vec![nc], f64_bytes(&norm)),
            (
                "class_filled_from",
                Dtype::F64,
                vec![nc],
                f64_bytes(&filled),
            ),
            ("class_noise_sigma", Dtype::F64, vec![nc], f64_bytes(&sigma)),
            ("class_active", Dtype::F64, vec![nc], f64_bytes(&active)),
            ("class_rank", Dtype::F64, vec![nc], f64_bytes(&rank)),
        ];
        let digest = checksum(&meta_json, tensors.iter().map(|t| (t.0, &t.3[..])));
        let mut info = HashMap::new();
        info.insert("l3".to_string(), meta_json);
        info.insert("sha256".to_string(), digest);
        let views = tensors
            .iter()
            .map(|(name, dt, shape, data)| {
                TensorView::new(*dt, shape.clone(), data)
                    .map(|v| (name.to_string(), v))
                    .map_err(|e| L3Error::Table(format!("tensor {name}: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        serialize_sorted(views, info).map_err(L3Error::Table)
    }

    /// Parse and verify a table file's bytes. `origin` names it in errors.
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, L3Error> {
        let bad = |m: String| L3Error::BadTable {
            path: origin.to_string(),
            msg: m,
        };
        let st = SafeTensors::deserialize(bytes)
            .map_err(|e| bad(format!("not a valid safetensors file ({e})")))?;
        let (_, md) = SafeTensors::read_metadata(bytes)
            .map_err(|e| bad(format!("unreadable header ({e})")))?;
        let info = md
            .metadata()
            .as_ref()
            .ok_or_else(|| bad("no l3 metadata in the header".into()))?;
        let meta_json = info
            .get("l3")
            .ok_or_else(|| bad("no l3 metadata in the header".into()))?;
        let stored_sum = info
            .get("sha256")
            .ok_or_else(|| bad("no checksum in the header".into()))?;
        let names = [
            "kernels",
            "contrast_thresholds",
            "class_samples",
            "class_lambda",
            "class_condition",
            "class_kernel_norm",
            "class_filled_from",
        ];
        // written since the reports gained noise and rank; optional on load
        let optional = ["class_noise_sigma", "class_active", "class_rank"];
        let mut views = Vec::new();
        for n in names {
            let v = st
                .tensor(n)
                .map_err(|_| bad(format!("tensor '{n}' is missing")))?;
            views.push(v);
        }
        let present: Vec<&str> = optional
            .into_iter()
            .filter(|n| st.tensor(n).is_ok())
            .collect();
        if !(present.is_empty() || present.len() == optional.len()) {
            return Err(bad("class report columns are incomplete".into()));
        }
        let names: Vec<&str> = names.into_iter().chain(present.iter().copied()).collect();
        for n in &present {
            let v = st
                .tensor(n)
                .map_err(|_| bad(format!("tensor '{n}' is missing")))?;
            views.push(v);
        }
        let sum = checksum(
            meta_json,
            names.iter().zip(&views).map(|(n, v)| (*n, v.data())),
        );
        if &sum != stored_sum {
            return Err(bad("checksum mismatch: the file is corrupt".into()));
        }
        let meta: TableMeta =
            serde_json::from_str(meta_json).map_err(|e| bad(format!("metadata: {e}")))?;
        let f32s = |v: &TensorView| -> Result<Vec<f32>, L3Error> {
            if v.dtype() != Dtype::F32 {
                return Err(bad("expected f32 data".into()));
            }
            Ok(v.data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect())
        };
        let f64s = |v: &TensorView| -> Result<Vec<f64>, L3Error> {
            if v.dtype() != Dtype::F64 {
                return Err(bad("expected f64 data".into()));
            }
            Ok(v.data()
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect())
        };
        let kernels = f32s(&views[0])?;
        let contrast_thresholds = f32s(&views[1])?;
        let cols: Vec<Vec<f64>> = views[2..].iter().map(&f64s).collect::<Result<_, _>>()?;
        let nc = cols[0].len();
        if cols.iter().any(|c| c.len() != nc) {
            return Err(bad("class report columns differ in length".into()));
        }
        let reports = (0..nc)
            .map(|i| ClassReport {
                samples: cols[0][i] as u64,
                lambda: cols[1][i],
                condition: cols[2][i],
                kernel_norm: cols[3][i],
                filled_from: cols[4][i] as i32,
                noise_sigma: cols.get(5).map(|c| c[i]).unwrap_or(0.0),
                active: cols
                    .get(6)
                    .and_then(|c| (c[i] >= 0.0).then_some(c[i] as u32)),
                rank: cols
                    .get(7)
                    .and_then(|c| (c[i] >= 0.0).then_some(c[i] as u32)),
            })
            .collect();
        let t = L3Table {
            meta,
            kernels,
            contrast_thresholds,
            reports,
        };
        t.validate().map_err(|e| bad(e.to_string()))?;
        Ok(t)
    }

    /// Write atomically ([`crate::io`]'s one routine: a temporary file beside the target,
    /// fsynced, renamed, the directory fsynced), creating the directory.
    pub fn save(&self, path: &Path) -> Result<(), L3Error> {
        let bytes = self.to_bytes()?;
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
        if let Some(d) = dir {
            std::fs::create_dir_all(d)
                .map_err(|e| L3Error::Write(Box::new(crate::io::IoError::file("create", d, e))))?;
        }
        crate::io::write_bytes_atomic(path, &bytes).map_err(|e| L3Error::Write(Box::new(e)))
    }

    pub fn load(path: &Path) -> Result<Self, L3Error> {
        let bytes = std::fs::read(path).map_err(|e| L3Error::BadTable {
            path: path.display().to_string(),
            msg: e.to_string(),
        })?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }
}

/// `safetensors::serialize` with the header's keys in sorted order: the
/// header metadata is a `HashMap`, whose order varies from run to run, and
/// equal contents must give equal bytes.
pub(crate) fn serialize_sorted(
    views: Vec<(String, TensorView<'_>)>,
    info: HashMap<String, String>,
) -> Result<Vec<u8>, String> {
    let raw = safetensors::serialize(views, Some(info)).map_err(|e| e.to_string())?;
    let n = raw
        .get(..8)
        .and_then(|b| b.try_into().ok())
        .map(u64::from_le_bytes)
        .and_then(|n| usize::try_from(n).ok())
        .filter(|&n| raw.len() >= 8 + n)
        .ok_or("safetensors header length")?;
    // serde_json's maps are sorted by key (no `preserve_order`)
    let header: serde_json::Value =
        serde_json::from_slice(&raw[8..8 + n]).map_err(|e| e.to_string())?;
    let mut h = serde_json::to_vec(&header).map_err(|e| e.to_string())?;
    h.resize(h.len().next_multiple_of(8), b' ');
    let mut out = Vec::with_capacity(8 + h.len() + raw.len() - 8 - n);
    out.extend_from_slice(&(h.len() as u64).to_le_bytes());
    out.extend_from_slice(&h);
    out.extend_from_slice(&raw[8 + n..]);
    Ok(out)
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn f64_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn checksum<'a>(meta: &str, parts: impl Iterator<Item = (&'a str, &'a [u8])>) -> String {
    let mut h = Sha256::new();
    h.update(meta.as_bytes());
    for (name, data) in parts {
        h.update(name.as_bytes());
        h.update((data.len() as u64).to_le_bytes());
        h.update(data);
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}
