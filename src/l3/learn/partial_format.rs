//! The bytes of a shard's partial sums ([`SurveyPartial`], [`GramPartial`]):
//! a safetensors file, exact to the bit (integers and f64 stored
//! little-endian as computed), checksummed, validated before use.
//!
//! Header metadata (`__metadata__`, keys sorted):
//! - `l3-partial`: JSON of the [`Header`]: `format` = `"l3-partial-sums"`,
//!   `version` ([`PARTIAL_FORMAT_VERSION`]), `stage` (`survey` or
//!   `accumulate`), `run_key`, `n_batches`, the shard's `start..end`, and
//!   the sizes of its stage;
//! - `sha256`: hex SHA-256 of that JSON followed by every tensor's name,
//!   byte length (u64 LE) and bytes, in name order.
//!
//! Tensors of a survey: `count` (U64, one per (position, level, mask)
//! cell), `hist_cells` (U32, the cells with a histogram, increasing) and
//! `hist` (U64, `[cells, bins]`).
//!
//! Tensors of an accumulation, for node `i` of the shard's tiling (in
//! batch order, exactly [`super::shards::cover`] of its range):
//! `nodeIIIII.classes` (U32, the classes with samples, increasing),
//! `nodeIIIII.counts` (U64, their sample counts) and `nodeIIIII.sums` (F64,
//! `[classes, dim, dim]`, `dim = n_features + 3`, row-major
//! `[x; y]ᵀ[x; y]`).
//!
//! Every size in the header is bounded and checked against the tensors'
//! shapes, which safetensors checks against the bytes, before anything is
//! allocated from it.

use std::collections::HashMap;
use std::ops::Range;

use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::LearnError;
use super::normal_eq::Gram;
use super::shards::{ClassSums, GramPartial, Node, SurveyPartial, SurveyShape, cover};
use crate::l3::table::serialize_sorted;

pub const PARTIAL_FORMAT_VERSION: u32 = 1;
const FORMAT_NAME: &str = "l3-partial-sums";
const HEADER_KEY: &str = "l3-partial";

/// Bounds on the sizes a header may state (far above any real run: 10 000
/// batches, 20 levels × 4 positions × 5 saturation cases × 2 = 800 classes,
/// 26 features). What a small file may make the reader allocate: at most
/// 2·24 nodes × `MAX_CLASSES` empty class slots.
const MAX_BATCHES: usize = 1 << 24;
const MAX_CELLS: usize = 1 << 20;
const MAX_BINS: usize = 1 << 12;
const MAX_FEATURES: usize = 1 << 10;
const MAX_CLASSES: usize = 1 << 17;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
enum Stage {
    Survey,
    Accumulate,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    format: String,
    version: u32,
    stage: Stage,
    run_key: String,
    n_batches: usize,
    start: usize,
    end: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    survey: Option<SurveyShape>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    accumulate: Option<AccumulateShape>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct AccumulateShape {
    n_features: usize,
    n_classes: usize,
    classes_digest: String,
    /// `(lo, log2)` of every node, in batch order.
    nodes: Vec<(usize, u32)>,
}

fn bad(msg: impl Into<String>) -> LearnError {
    LearnError::PartialSums(msg.into())
}

fn checksum(header: &str, tensors: &[(String, Vec<u8>)]) -> String {
    let mut h = Sha256::new();
    h.update(header.as_bytes());
    let mut sorted: Vec<&(String, Vec<u8>)> = tensors.iter().collect();
    sorted.sort_by(|a, b| a.0.cmp(&b.0));
    for (name, data) in sorted {
        h.update(name.as_bytes());
        h.update((data.len() as u64).to_le_bytes());
        h.update(data);
    }
    hex::encode(h.finalize())
}

fn write(
    header: &Header,
    tensors: Vec<(String, Dtype, Vec<usize>, Vec<u8>)>,
) -> Result<Vec<u8>, LearnError> {
    let json = serde_json::to_string(header).map_err(|e| bad(format!("header: {e}")))?;
    let plain: Vec<(String, Vec<u8>)> = tensors
        .iter()
        .map(|(n, _, _, d)| (n.clone(), d.clone()))
        .collect();
    let mut info = HashMap::new();
    info.insert("sha256".to_string(), checksum(&json, &plain));
    info.insert(HEADER_KEY.to_string(), json);
    let views = tensors
        .iter()
        .map(|(name, dt, shape, data)| {
            TensorView::new(*dt, shape.clone(), data)
                .map(|v| (name.clone(), v))
                .map_err(|e| bad(format!("tensor {name}: {e}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    serialize_sorted(views, info).map_err(bad)
}

/// Parse, checksum and version-check a partial's bytes.
fn read(bytes: &[u8], stage: Stage) -> Result<(Header, SafeTensors<'_>), LearnError> {
    let st = SafeTensors::deserialize(bytes)
        .map_err(|e| bad(format!("not a valid safetensors file ({e})")))?;
    let (_, md) =
        SafeTensors::read_metadata(bytes).map_err(|e| bad(format!("unreadable header ({e})")))?;
    let info = md
        .metadata()
        .as_ref()
        .ok_or_else(|| bad("no header metadata"))?;
    let json = info
        .get(HEADER_KEY)
        .ok_or_else(|| bad("no l3-partial header"))?;
    let stored = info.get("sha256").ok_or_else(|| bad("no checksum"))?;
    let mut names = st.names();
    names.sort();
    let tensors = names
        .iter()
        .map(|n| {
            st.tensor(n)
                .map(|t| (n.to_string(), t.data().to_vec()))
                .map_err(|e| bad(format!("tensor {n}: {e}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    if checksum(json, &tensors) != *stored {
        return Err(bad("checksum mismatch: the partial sums are corrupt"));
    }
    let header: Header =
        serde_json::from_str(json).map_err(|e| bad(format!("bad header ({e})")))?;
    if header.format != FORMAT_NAME || header.version != PARTIAL_FORMAT_VERSION {
        return Err(bad(format!(
            "format {} version {} (expected {FORMAT_NAME} {PARTIAL_FORMAT_VERSION})",
            header.format, header.version
        )));
    }
    if header.stage != stage {
        return Err(bad(format!(
            "{:?} sums where {stage:?} sums were expected",
            header.stage
        )));
    }
    if header.n_batches == 0
        || header.n_batches > MAX_BATCHES
        || header.start >= header.end
        || header.end > header.n_batches
    {
        return Err(bad(format!(
            "batches {}..{} of {}",
            header.start, header.end, header.n_batches
        )));
    }
    Ok((header, st))
}

/// The bytes of tensor `name`, which must have type `dtype` and `shape`.
fn tensor<'a>(
    st: &'a SafeTensors<'a>,
    name: &str,
    dtype: Dtype,
    shape: &[usize],
) -> Result<&'a [u8], LearnError> {
    let t = st
        .tensor(name)
        .map_err(|_| bad(format!("tensor {name} missing")))?;
    if t.dtype() != dtype || t.shape() != shape {
        return Err(bad(format!(
            "tensor {name}: {:?} {:?}, expected {dtype:?} {shape:?}",
            t.dtype(),
            t.shape()
        )));
    }
    Ok(t.data())
}

fn u64s(b: &[u8]) -> Vec<u64> {
    b.chunks_exact(8)
        .map(|c| u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
        .collect()
}

fn u32s(b: &[u8]) -> Vec<u32> {
    b.chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn f64s(b: &[u8]) -> Vec<f64> {
    b.chunks_exact(8)
        .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
        .collect()
}

fn le_bytes<const N: usize, T: Copy>(v: &[T], f: impl Fn(T) -> [u8; N]) -> Vec<u8> {
    v.iter().flat_map(|&x| f(x)).collect()
}

/// Indices strictly increasing and below `n`.
fn increasing_below(idx: &[u32], n: usize) -> bool {
    idx.windows(2).all(|w| w[0] < w[1]) && idx.last().is_none_or(|&l| (l as usize) < n)
}

fn range_of(h: &Header) -> Range<usize> {
    h.start..h.end
}

impl SurveyPartial {
    /// The partial's bytes (format in the `partial_format` module's docs).
    pub fn to_bytes(&self) -> Result<Vec<u8>, LearnError> {
        let cells: Vec<u32> = (0..self.hist.len())
            .filter(|&k| !self.hist[k].is_empty())
            .map(|k| k as u32)
            .collect();
        let bins = self.shape.bins;
        if self.count.len() != self.shape.n_cells()
            || self.hist.len() != self.shape.n_cells()
            || cells.iter().any(|&k| self.hist[k as usize].len() != bins)
        {
            return Err(bad("survey sizes disagree with its shape"));
        }
        let hist: Vec<u64> = cells
            .iter()
            .flat_map(|&k| self.hist[k as usize].iter().copied())
            .collect();
        let header = Header {
            format: FORMAT_NAME.into(),
            version: PARTIAL_FORMAT_VERSION,
            stage: Stage::Survey,
            run_key: self.run_key.clone(),
            n_batches: self.n_batches,
            start: self.batches.start,
            end: self.batches.end,
            survey: Some(self.shape),
            accumulate: None,
        };
        write(
            &header,
            vec![
                (
                    "count".into(),
                    Dtype::U64,
                    vec![self.count.len()],
                    le_bytes(&self.count, u64::to_le_bytes),
                ),
                (
                    "hist".into(),
                    Dtype::U64,
                    vec![cells.len(), bins],
                    le_bytes(&hist, u64::to_le_bytes),
                ),
                (
                    "hist_cells".into(),
                    Dtype::U32,
                    vec![cells.len()],
                    le_bytes(&cells, u32::to_le_bytes),
                ),
            ],
        )
    }

    /// Read a survey partial from its bytes, checking everything.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, LearnError> {
        let (h, st) = read(bytes, Stage::Survey)?;
        let shape = h.survey.ok_or_else(|| bad("survey sizes missing"))?;
        let cells = shape
            .n_positions
            .checked_mul(shape.n_levels)
            .and_then(|v| v.checked_mul(shape.n_masks))
            .filter(|&c| c > 0 && c <= MAX_CELLS)
            .ok_or_else(|| bad("survey cell count out of range"))?;
        if shape.bins == 0 || shape.bins > MAX_BINS || h.accumulate.is_some() || st.len() != 3 {
            return Err(bad("survey sizes out of range"));
        }
        let count = u64s(tensor(&st, "count", Dtype::U64, &[cells])?);
        let n_hist = st
            .tensor("hist_cells")
            .map_err(|_| bad("tensor hist_cells missing"))?
            .shape()
            .first()
            .copied()
            .unwrap_or(0);
        let keys = u32s(tensor(&st, "hist_cells", Dtype::U32, &[n_hist])?);
        if !increasing_below(&keys, cells) {
            return Err(bad("histogram cells not increasing or out of range"));
        }
        let flat = u64s(tensor(&st, "hist", Dtype::U64, &[n_hist, shape.bins])?);
        let mut hist = vec![Vec::new(); cells];
        for (&k, row) in keys.iter().zip(flat.chunks_exact(shape.bins)) {
            hist[k as usize] = row.to_vec();
        }
        Ok(SurveyPartial {
            run_key: h.run_key.clone(),
            n_batches: h.n_batches,
            batches: range_of(&h),
            shape,
            hist,
            count,
        })
    }
}

impl GramPartial {
    /// The partial's bytes (format in the `partial_format` module's docs).
    pub fn to_bytes(&self) -> Result<Vec<u8>, LearnError> {
        let dim = self.n_features + 3;
        let mut tensors = Vec::new();
        for (i, (_, sums)) in self.nodes.iter().enumerate() {
            let mut classes = Vec::new();
            let mut counts = Vec::new();
            let mut flat = Vec::new();
            for (c, g) in sums.iter().enumerate() {
                if let Some(g) = g {
                    let (m, n) = g
                        .flushed_sums()
                        .ok_or_else(|| bad(format!("class {c} has unfolded samples")))?;
                    if m.len() != dim * dim {
                        return Err(bad(format!("class {c}: {} sums", m.len())));
                    }
                    classes.push(c as u32);
                    counts.push(n);
                    flat.extend_from_slice(&le_bytes(m, f64::to_le_bytes));
                }
            }
            let k = classes.len();
            tensors.push((
                format!("node{i:05}.classes"),
                Dtype::U32,
                vec![k],
                le_bytes(&classes, u32::to_le_bytes),
            ));
            tensors.push((
                format!("node{i:05}.counts"),
                Dtype::U64,
                vec![k],
                le_bytes(&counts, u64::to_le_bytes),
            ));
            tensors.push((
                format!("node{i:05}.sums"),
                Dtype::F64,
                vec![k, dim, dim],
                flat,
            ));
        }
        let header = Header {
            format: FORMAT_NAME.into(),
            version: PARTIAL_FORMAT_VERSION,
            stage: Stage::Accumulate,
            run_key: self.run_key.clone(),
            n_batches: self.n_batches,
            start: self.batches.start,
            end: self.batches.end,
            survey: None,
            accumulate: Some(AccumulateShape {
                n_features: self.n_features,
                n_classes: self.n_classes,
                classes_digest: self.classes_digest.clone(),
                nodes: self.nodes.iter().map(|(n, _)| (n.lo, n.log2)).collect(),
            }),
        };
        write(&header, tensors)
    }

    /// Read an accumulation partial from its bytes, checking everything.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, LearnError> {
        let (h, st) = read(bytes, Stage::Accumulate)?;
        let a = h
            .accumulate
            .as_ref()
            .ok_or_else(|| bad("accumulation sizes missing"))?;
        let (nf, nc) = (a.n_features, a.n_classes);
        if nf == 0 || nf > MAX_FEATURES || nc == 0 || nc > MAX_CLASSES || h.survey.is_some() {
            return Err(bad(format!("{nf} features, {nc} classes")));
        }
        let n = h.n_batches;
        let expected = cover(range_of(&h), n);
        let given: Vec<Node> = a
            .nodes
            .iter()
            .map(|&(lo, log2)| Node { lo, log2 })
            .collect();
        if given != expected {
            return Err(bad(format!(
                "nodes {given:?} do not tile batches {}..{}",
                h.start, h.end
            )));
        }
        if st.len() != 3 * given.len() {
            return Err(bad(format!(
                "{} tensors for {} nodes",
                st.len(),
                given.len()
            )));
        }
        let dim = nf + 3;
        let mut nodes = Vec::with_capacity(given.len());
        for (i, &node) in given.iter().enumerate() {
            let name = format!("node{i:05}.classes");
            let k = st
                .tensor(&name)
                .map_err(|_| bad(format!("tensor {name} missing")))?
                .shape()
                .first()
                .copied()
                .unwrap_or(0);
            let classes = u32s(tensor(&st, &name, Dtype::U32, &[k])?);
            if !increasing_below(&classes, nc) {
                return Err(bad(format!("{name}: not increasing or out of range")));
            }
            let counts = u64s(tensor(
                &st,
                &format!("node{i:05}.counts"),
                Dtype::U64,
                &[k],
            )?);
            let flat = tensor(&st, &format!("node{i:05}.sums"), Dtype::F64, &[k, dim, dim])?;
            let mut sums: ClassSums = (0..nc).map(|_| None).collect();
            for ((&c, &count), m) in classes
                .iter()
                .zip(&counts)
                .zip(flat.chunks_exact(dim * dim * 8))
            {
                sums[c as usize] = Some(Box::new(Gram::from_sums(nf, f64s(m), count)?));
            }
            nodes.push((node, sums));
        }
        Ok(GramPartial {
            run_key: h.run_key.clone(),
            n_batches: n,
            batches: range_of(&h),
            n_features: nf,
            n_classes: nc,
            classes_digest: a.classes_digest.clone(),
            nodes,
        })
    }
}
