//! Training split into shards: contiguous ranges of batches whose partial
//! sums are computed anywhere and merged into the table a single process
//! would have trained, bit for bit.
//!
//! # Why the result does not depend on the sharding
//!
//! A training run has two data passes over its batches (see `trainer.rs`):
//!
//! 1. **Survey.** Contrast histograms and sample counts of every fourth
//!    batch (batch `i` with `i % 4 == 0`). These are integers, so a sum of
//!    shard surveys is exact in any order. The classes (saturation cases
//!    and contrast thresholds) are derived from the merged survey, so every
//!    accumulation shard needs the whole survey first: survey shards, then
//!    [`merge_surveys`], then accumulation shards.
//! 2. **Accumulation.** Per-class normal equations (`[x; y]ᵀ[x; y]` and a
//!    count) in f64. Floating-point addition is not associative, so the
//!    order of the sums is fixed once for all: the batches `0..n` are the
//!    leaves of a dyadic tree (node `(lo, k)` covers batches
//!    `lo..min(lo + 2ᵏ, n)`, `lo` a multiple of `2ᵏ`; the root has
//!    `2ᵏ ≥ n`), a node's sums are its left child's plus its right child's
//!    (just the left child's when the right one starts at or beyond `n`),
//!    and a leaf is one batch accumulated sample by sample. One process
//!    evaluates the root (the two halves in parallel). A shard covering
//!    `start..end` evaluates the fewest whole nodes that tile its range
//!    (at most about 2·log₂ n) and keeps each node's sums; the merge
//!    evaluates the root again, taking those nodes as given. Every node's
//!    sums are then the same additions of the same numbers in the same
//!    order, whatever the shard boundaries, including one shard. (A plain
//!    left fold in batch order, the earlier scheme, could only be
//!    reproduced from every batch's own sums, whose volume grows with the
//!    batches; with the tree a shard hands over O(log n) nodes of at most
//!    classes × (features + 3)² f64 each. Tables trained before the tree
//!    differ from today's in the last bits.)
//!
//!    Within a batch, samples are folded in blocks of 64
//!    ([`Gram::push`]); that order depends on the batch alone.
//!
//! The single-process path ([`learn`](super::learn)) is this same code with one
//! shard covering every batch: survey it, derive the classes, accumulate
//! it, merge the one partial, solve.
//!
//! Partial sums serialise to bytes and back exactly (see
//! `partial_format.rs`), so the shards of a run can be computed on
//! different machines and merged by any of them. A partial carries the
//! caller's run key, its batch range and the shape of its sums; a merge
//! checks that its parts are of one run and tile `0..n` exactly once.

use std::collections::HashMap;
use std::ops::Range;
use std::sync::Mutex;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::LearnError;
use super::normal_eq::Gram;

/// One shard of a training run: batches `start..end` of `n_batches`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShardSpec {
    /// 0-based index of this shard and the number of shards of the run.
    pub index: usize,
    pub count: usize,
    pub start: usize,
    pub end: usize,
    pub n_batches: usize,
}

impl ShardSpec {
    pub fn batches(&self) -> Range<usize> {
        self.start..self.end
    }
}

/// Split `n_batches` batches into `n_shards` contiguous shards of nearly
/// equal size (1 ≤ `n_shards` ≤ `n_batches`).
pub fn plan_shards(n_batches: usize, n_shards: usize) -> Result<Vec<ShardSpec>, LearnError> {
    if n_shards == 0 || n_shards > n_batches {
        return Err(LearnError::InvalidParams(format!(
            "{n_shards} shards for {n_batches} batches (1 to {n_batches})"
        )));
    }
    Ok((0..n_shards)
        .map(|k| ShardSpec {
            index: k,
            count: n_shards,
            start: k * n_batches / n_shards,
            end: (k + 1) * n_batches / n_shards,
            n_batches,
        })
        .collect())
}

/// A node of the dyadic summation tree over the batches `0..n`: batches
/// `lo..min(lo + 2^log2, n)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Node {
    pub lo: usize,
    pub log2: u32,
}

impl Node {
    /// The root of the tree over `n ≥ 1` batches.
    pub fn root(n: usize) -> Node {
        Node {
            lo: 0,
            log2: n.max(1).next_power_of_two().trailing_zeros(),
        }
    }

    /// The batches this node covers in a run of `n` batches.
    pub fn batches(self, n: usize) -> Range<usize> {
        let span = 1usize.checked_shl(self.log2).unwrap_or(usize::MAX);
        self.lo.min(n)..self.lo.saturating_add(span).min(n)
    }

    fn children(self) -> (Node, Node) {
        let log2 = self.log2.saturating_sub(1);
        let left = Node { lo: self.lo, log2 };
        let right = Node {
            lo: self.lo + (1usize << log2),
            log2,
        };
        (left, right)
    }

    /// Whether this is a node of the tree over `n` batches.
    pub fn is_valid(self, n: usize) -> bool {
        self.log2 <= Node::root(n).log2
            && self.lo < n
            && self.lo.is_multiple_of(1usize << self.log2)
    }
}

/// The fewest whole tree nodes tiling `range` (a sub-range of `0..n`), in
/// batch order.
pub fn cover(range: Range<usize>, n: usize) -> Vec<Node> {
    fn walk(node: Node, range: &Range<usize>, n: usize, out: &mut Vec<Node>) {
        let b = node.batches(n);
        if b.is_empty() || b.end <= range.start || b.start >= range.end {
            return;
        }
        if range.start <= b.start && b.end <= range.end {
            out.push(node);
            return;
        }
        let (l, r) = node.children();
        walk(l, range, n, out);
        walk(r, range, n, out);
    }
    let mut out = Vec::new();
    if n > 0 && range.start < range.end {
        walk(Node::root(n), &range, n, &mut out);
    }
    out
}

/// The sums of `node`: `get(node)` when it gives them (a computed leaf, a
/// stored node), else the sum of its children's, the two evaluated in
/// parallel. A leaf `get` does not give is missing.
pub(crate) fn tree_sum<T: Send>(
    node: Node,
    n: usize,
    get: &(dyn Fn(Node) -> Result<Option<T>, LearnError> + Sync),
    add: &(dyn Fn(T, T) -> T + Sync),
) -> Result<T, LearnError> {
    if let Some(v) = get(node)? {
        return Ok(v);
    }
    if node.log2 == 0 {
        return Err(LearnError::PartialSums(format!(
            "no shard has the sums of batch {}",
            node.lo
        )));
    }
    let (l, r) = node.children();
    if r.lo >= n {
        return tree_sum(l, n, get, add);
    }
    let (a, b) = rayon::join(|| tree_sum(l, n, get, add), || tree_sum(r, n, get, add));
    Ok(add(a?, b?))
}

/// Sizes every partial of a run shares, checked when parts are merged.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SurveyShape {
    pub n_positions: usize,
    pub n_levels: usize,
    pub n_masks: usize,
    pub bins: usize,
}

impl SurveyShape {
    pub fn n_cells(&self) -> usize {
        self.n_positions * self.n_levels * self.n_masks
    }
}

/// Survey statistics of the surveyed batches in `batches`: per (position,
/// level, saturation mask) a contrast histogram (empty when no sample
/// fell there) and a sample count.
#[derive(Clone, Debug, PartialEq)]
pub struct SurveyPartial {
    pub run_key: String,
    pub n_batches: usize,
    pub batches: Range<usize>,
    pub shape: SurveyShape,
    pub hist: Vec<Vec<u64>>,
    pub count: Vec<u64>,
}

impl SurveyPartial {
    pub(crate) fn empty(
        run_key: &str,
        n_batches: usize,
        batches: Range<usize>,
        shape: SurveyShape,
    ) -> Self {
        Self {
            run_key: run_key.to_string(),
            n_batches,
            batches,
            hist: vec![Vec::new(); shape.n_cells()],
            count: vec![0; shape.n_cells()],
            shape,
        }
    }

    /// Whether the histograms and counts have the sizes `shape` says.
    fn sizes_agree(&self) -> bool {
        let cells = self.shape.n_cells();
        self.hist.len() == cells
            && self.count.len() == cells
            && self
                .hist
                .iter()
                .all(|h| h.is_empty() || h.len() == self.shape.bins)
    }

    /// Add another survey's counts (integers: exact in any order); both
    /// have [`SurveyPartial::sizes_agree`] and one shape.
    pub(crate) fn add_counts(&mut self, other: &SurveyPartial) {
        for (k, h) in other.hist.iter().enumerate() {
            if h.is_empty() {
                continue;
            }
            if self.hist[k].is_empty() {
                self.hist[k] = h.clone();
            } else {
                for (x, y) in self.hist[k].iter_mut().zip(h) {
                    *x = x.saturating_add(*y);
                }
            }
        }
        // saturating: a crafted partial cannot overflow (real counts are far below 2⁶⁴)
        for (x, y) in self.count.iter_mut().zip(&other.count) {
            *x = x.saturating_add(*y);
        }
    }
}

/// Check that `ranges` (with their origins) tile `0..n` exactly once, and
/// return the order that sorts them by start.
fn check_tiling(ranges: &[Range<usize>], n: usize) -> Result<Vec<usize>, LearnError> {
    let mut order: Vec<usize> = (0..ranges.len()).collect();
    order.sort_by_key(|&i| (ranges[i].start, ranges[i].end));
    let mut next = 0;
    for &i in &order {
        let r = &ranges[i];
        if r.start != next || r.end <= r.start {
            return Err(LearnError::PartialSums(format!(
                "shards do not tile batches 0..{n}: batches {next}.. expected, {}..{} given",
                r.start, r.end
            )));
        }
        next = r.end;
    }
    if next != n {
        return Err(LearnError::PartialSums(format!(
            "shards cover batches 0..{next} of 0..{n}"
        )));
    }
    Ok(order)
}

/// Merge the survey shards of one run into the survey of all its batches.
pub fn merge_surveys(parts: &[SurveyPartial]) -> Result<SurveyPartial, LearnError> {
    let first = parts
        .first()
        .ok_or_else(|| LearnError::PartialSums("no survey shards".into()))?;
    for p in parts {
        if p.run_key != first.run_key
            || p.n_batches != first.n_batches
            || p.shape != first.shape
            || !p.sizes_agree()
        {
            return Err(LearnError::PartialSums(format!(
                "survey of batches {}..{} is of another run or shape",
                p.batches.start, p.batches.end
            )));
        }
    }
    let ranges: Vec<Range<usize>> = parts.iter().map(|p| p.batches.clone()).collect();
    let order = check_tiling(&ranges, first.n_batches)?;
    let mut all = SurveyPartial::empty(
        &first.run_key,
        first.n_batches,
        0..first.n_batches,
        first.shape,
    );
    for i in order {
        all.add_counts(&parts[i]);
    }
    Ok(all)
}

/// Per-class sums of one tree node: `None` for a class no sample reached.
pub type ClassSums = Vec<Option<Box<Gram>>>;

/// Add `b`'s class sums to `a`'s (the one addition of the tree).
pub(crate) fn add_class_sums(mut a: ClassSums, b: ClassSums) -> ClassSums {
    for (x, y) in a.iter_mut().zip(b) {
        match (x.as_mut(), y) {
            (Some(g), Some(h)) => g.merge_owned(*h),
            (None, Some(h)) => *x = Some(h),
            _ => {}
        }
    }
    a
}

/// The classes of a run: the saturation cases that get kernels and the
/// contrast threshold of every (position, level, case).
#[derive(Clone, Debug, PartialEq)]
pub struct Classes {
    pub sat_cases: Vec<u32>,
    /// Per (position, level, case).
    pub thresholds: Vec<f32>,
}

impl Classes {
    pub fn n_sat(&self) -> usize {
        self.sat_cases.len()
    }

    /// SHA-256 (hex) of the cases and the thresholds' bits: partial sums
    /// accumulated for other classes cannot be merged.
    pub fn digest(&self) -> String {
        let mut h = Sha256::new();
        h.update((self.sat_cases.len() as u64).to_le_bytes());
        for c in &self.sat_cases {
            h.update(c.to_le_bytes());
        }
        for t in &self.thresholds {
            h.update(t.to_bits().to_le_bytes());
        }
        hex::encode(h.finalize())
    }
}

/// The normal equations of the batches `batches` of a run, as the sums of
/// the tree nodes tiling that range.
#[derive(Clone, Debug)]
pub struct GramPartial {
    pub run_key: String,
    pub n_batches: usize,
    pub batches: Range<usize>,
    /// Regressors per class (patch pixels and the constant).
    pub n_features: usize,
    pub n_classes: usize,
    /// [`Classes::digest`] of the classes accumulated.
    pub classes_digest: String,
    /// The nodes tiling `batches` in order, each with its class sums, every
    /// sample folded in ([`Gram::flushed_sums`] is `Some`).
    pub nodes: Vec<(Node, ClassSums)>,
}

/// Merge the accumulation shards of one run, accumulated for `classes`:
/// the class sums of every batch, added exactly as one process adds them.
/// Each class without samples gets an empty accumulator.
pub fn merge_partials(classes: &Classes, parts: Vec<GramPartial>) -> Result<Vec<Gram>, LearnError> {
    let first = parts
        .first()
        .ok_or_else(|| LearnError::PartialSums("no accumulation shards".into()))?;
    let (key, n, nf, nc) = (
        first.run_key.clone(),
        first.n_batches,
        first.n_features,
        first.n_classes,
    );
    let digest = classes.digest();
    for p in &parts {
        if p.run_key != key
            || p.n_batches != n
            || p.n_features != nf
            || p.n_classes != nc
            || p.classes_digest != digest
        {
            return Err(LearnError::PartialSums(format!(
                "sums of batches {}..{} are of another run or other classes",
                p.batches.start, p.batches.end
            )));
        }
    }
    let ranges: Vec<Range<usize>> = parts.iter().map(|p| p.batches.clone()).collect();
    check_tiling(&ranges, n)?;
    let mut stored = HashMap::new();
    for p in parts {
        for (node, sums) in p.nodes {
            let b = node.batches(n);
            if !node.is_valid(n) || b.start < p.batches.start || b.end > p.batches.end {
                return Err(LearnError::PartialSums(format!(
                    "node {node:?} is not in shard {}..{}",
                    p.batches.start, p.batches.end
                )));
            }
            let bad_size = sums.iter().flatten().any(|g| g.n_features() != nf);
            if bad_size || sums.len() != nc || stored.insert(node, sums).is_some() {
                return Err(LearnError::PartialSums(format!(
                    "node {node:?}: wrong class count or size, or given twice"
                )));
            }
        }
    }
    let stored = Mutex::new(stored);
    let get = |node: Node| -> Result<Option<ClassSums>, LearnError> {
        Ok(stored
            .lock()
            .map_err(|_| LearnError::PartialSums("merge state poisoned".into()))?
            .remove(&node))
    };
    let sums = tree_sum(Node::root(n), n, &get, &add_class_sums)?;
    let left = stored
        .into_inner()
        .map_err(|_| LearnError::PartialSums("merge state poisoned".into()))?;
    if !left.is_empty() {
        return Err(LearnError::PartialSums(format!(
            "{} nodes overlap others",
            left.len()
        )));
    }
    Ok(sums
        .into_iter()
        .map(|g| g.map(|b| *b).unwrap_or_else(|| Gram::new(nf)))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covers_tile_their_range_with_whole_nodes() {
        for n in 1..40 {
            for s in 0..n {
                for e in s + 1..=n {
                    let nodes = cover(s..e, n);
                    let mut next = s;
                    for node in &nodes {
                        assert!(node.is_valid(n));
                        let b = node.batches(n);
                        assert_eq!(b.start, next, "n {n} range {s}..{e}");
                        next = b.end;
                    }
                    assert_eq!(next, e);
                    assert!(nodes.len() <= 2 * (Node::root(n).log2 as usize + 1));
                }
            }
            assert_eq!(cover(0..n, n), vec![Node::root(n)]);
        }
    }

    #[test]
    fn shard_plans_tile_the_batches() {
        let plan = plan_shards(10, 3).unwrap();
        let r: Vec<_> = plan.iter().map(|s| s.batches()).collect();
        assert_eq!(r, vec![0..3, 3..6, 6..10]);
        assert!(plan_shards(3, 4).is_err());
        assert!(plan_shards(3, 0).is_err());
        assert!(check_tiling(&[0..3, 4..10], 10).is_err());
        assert!(check_tiling(&[0..5, 3..10], 10).is_err());
        assert!(check_tiling(&[3..10, 0..3], 10).is_ok());
    }
}
