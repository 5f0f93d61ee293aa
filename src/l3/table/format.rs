//! The table file: a safetensors file whose header carries the table's metadata as JSON
//! (`l3`) and a SHA-256 checksum (`sha256`) over the metadata and every tensor, so that a
//! damaged file is refused rather than rendered with.

use std::collections::HashMap;

use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};
use sha2::{Digest, Sha256};

use super::{ClassReport, L3Table, TableError, TableMeta};

pub const TABLE_FORMAT_VERSION: u32 = 1;

impl L3Table {
    /// Serialize to safetensors bytes with a SHA-256 checksum in the header.
    pub fn to_bytes(&self) -> Result<Vec<u8>, TableError> {
        self.validate()?;
        let n_pos = self.n_positions();
        let (nl, ns, nf) = (self.n_bands(), self.n_sat_cases(), self.n_features());
        let nc = self.n_classes();
        let meta_json = serde_json::to_string(&self.meta)
            .map_err(|e| TableError::Unusable(format!("metadata: {e}")))?;
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
                    .map_err(|e| TableError::Unusable(format!("tensor {name}: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        serialize_sorted(views, info).map_err(TableError::Unusable)
    }

    /// Parse and verify a table file's bytes. `origin` names it in errors.
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, TableError> {
        let bad = |m: String| TableError::BadFile {
            path: origin.to_string(),
            msg: m,
        };
        let st = SafeTensors::deserialize(bytes)
            .map_err(|e| bad(format!("not a valid safetensors file ({e})")))?;
        let (meta_json, views) = checked_tensors(bytes, &st).map_err(bad)?;
        let meta: TableMeta =
            serde_json::from_str(&meta_json).map_err(|e| bad(format!("metadata: {e}")))?;
        let kernels = f32s(&views[0]).map_err(bad)?;
        let contrast_thresholds = f32s(&views[1]).map_err(bad)?;
        let cols: Vec<Vec<f64>> = views[2..]
            .iter()
            .map(f64s)
            .collect::<Result<_, _>>()
            .map_err(bad)?;
        let reports = reports_from_columns(&cols).map_err(bad)?;
        let t = L3Table {
            meta,
            kernels,
            contrast_thresholds,
            reports,
        };
        t.validate().map_err(|e| bad(e.to_string()))?;
        Ok(t)
    }
}

/// The tensors a table file must hold, in checksum order.
const REQUIRED: [&str; 7] = [
    "kernels",
    "contrast_thresholds",
    "class_samples",
    "class_lambda",
    "class_condition",
    "class_kernel_norm",
    "class_filled_from",
];

/// Class report columns written since the reports gained noise and rank; optional on load,
/// but all or none.
const OPTIONAL: [&str; 3] = ["class_noise_sigma", "class_active", "class_rank"];

/// The header's `l3` metadata and the file's tensors in checksum order ([`REQUIRED`], then
/// [`OPTIONAL`] when present), once the header's checksum matches them.
fn checked_tensors<'a>(
    bytes: &[u8],
    st: &SafeTensors<'a>,
) -> Result<(String, Vec<TensorView<'a>>), String> {
    let (_, md) =
        SafeTensors::read_metadata(bytes).map_err(|e| format!("unreadable header ({e})"))?;
    let info = md
        .metadata()
        .as_ref()
        .ok_or("no l3 metadata in the header")?;
    let meta_json = info.get("l3").ok_or("no l3 metadata in the header")?;
    let stored_sum = info.get("sha256").ok_or("no checksum in the header")?;
    let mut views = Vec::new();
    for n in REQUIRED {
        let v = st
            .tensor(n)
            .map_err(|_| format!("tensor '{n}' is missing"))?;
        views.push(v);
    }
    let present: Vec<&str> = OPTIONAL
        .into_iter()
        .filter(|n| st.tensor(n).is_ok())
        .collect();
    if !(present.is_empty() || present.len() == OPTIONAL.len()) {
        return Err("class report columns are incomplete".into());
    }
    let names: Vec<&str> = REQUIRED
        .into_iter()
        .chain(present.iter().copied())
        .collect();
    for n in &present {
        let v = st
            .tensor(n)
            .map_err(|_| format!("tensor '{n}' is missing"))?;
        views.push(v);
    }
    let sum = checksum(
        meta_json,
        names.iter().zip(&views).map(|(n, v)| (*n, v.data())),
    );
    if &sum != stored_sum {
        return Err("checksum mismatch: the file is corrupt".into());
    }
    Ok((meta_json.clone(), views))
}

fn f32s(v: &TensorView) -> Result<Vec<f32>, String> {
    if v.dtype() != Dtype::F32 {
        return Err("expected f32 data".into());
    }
    Ok(v.data()
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

fn f64s(v: &TensorView) -> Result<Vec<f64>, String> {
    if v.dtype() != Dtype::F64 {
        return Err("expected f64 data".into());
    }
    Ok(v.data()
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
        .collect())
}

/// The class reports from their columns (the [`REQUIRED`] ones from `class_samples` on,
/// then the [`OPTIONAL`] ones when present).
fn reports_from_columns(cols: &[Vec<f64>]) -> Result<Vec<ClassReport>, String> {
    let nc = cols[0].len();
    if cols.iter().any(|c| c.len() != nc) {
        return Err("class report columns differ in length".into());
    }
    Ok((0..nc)
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
        .collect())
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
