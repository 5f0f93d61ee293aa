//! Learning a table from (noisy mosaic, ideal XYZ) frame pairs, streaming
//! and in parallel, in four stages:
//! 1. [`survey`]: contrast histograms and saturation cases on a subset of
//!    frames, giving the saturation cases that get kernels and the
//!    flat/texture thresholds;
//! 2. [`accumulate`]: per-class normal equations in f64 over every frame;
//! 3. [`fill`]: classes with too few samples borrow from their neighbours;
//! 4. [`solve_classes`]: ridge regression per class, the channel sums of
//!    unsaturated kernels fixed to the level's colour map (see
//!    [`super::colour_map`]).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rayon::prelude::*;

use super::classify::MAX_CHANNELS;
use super::classify::sat_case_index;
use super::normal_eq::{ChannelSumConstraint, solve_with};
use super::{
    ClassReport, ColourMatrix, Gram, L3Error, L3Params, L3Table, PatchGeometry, RidgeChoice,
    TableMeta,
};

/// One training frame: a noisy mosaic in volts and the ideal XYZ at every
/// pixel (interleaved), captured with the CFA shifted by `cfa_shift`.
#[derive(Clone, Debug)]
pub struct TrainingFrame {
    pub width: usize,
    pub height: usize,
    pub volts: Vec<f32>,
    pub xyz: Vec<f32>,
    /// Pixel (r, c) sits under the base CFA's (r + dr, c + dc) filter.
    pub cfa_shift: (usize, usize),
}

/// Progress and cancellation hooks of a training run.
pub struct TrainControl<'a> {
    /// Called with a stage name and the fraction done (0–1) of the whole run.
    pub progress: &'a (dyn Fn(&str, f64) + Sync),
    pub cancel: &'a AtomicBool,
}

/// Sensor noise at a signal level, for the noise-variance ridge.
#[derive(Clone, Copy, Debug)]
pub struct NoiseModel {
    pub conversion_gain_v: f64,
    pub read_noise_v: f64,
    pub dsnu_v: f64,
    pub prnu_fraction: f64,
}

impl NoiseModel {
    /// Variance in volts² of a pixel at mean signal `v` volts.
    pub fn variance(&self, v: f64) -> f64 {
        self.conversion_gain_v * v
            + (self.prnu_fraction * v).powi(2)
            + self.dsnu_v.powi(2)
            + self.read_noise_v.powi(2)
    }
}

const HIST_BINS: usize = 480;
const HIST_LO: f64 = -7.0; // log10 volts
const HIST_HI: f64 = 1.0;

fn hist_bin(contrast: f32) -> usize {
    let l = (contrast.max(1e-12) as f64).log10();
    (((l - HIST_LO) / (HIST_HI - HIST_LO) * HIST_BINS as f64)
        .floor()
        .max(0.0) as usize)
        .min(HIST_BINS - 1)
}

fn hist_edge(bin: usize) -> f32 {
    10f64.powf(HIST_LO + bin as f64 * (HIST_HI - HIST_LO) / HIST_BINS as f64) as f32
}

/// Pass-1 statistics.
#[derive(Clone)]
struct Survey {
    /// Per (pos, level, mask): contrast histogram.
    hist: Vec<Vec<u32>>,
    /// Samples per (pos, level, mask).
    count: Vec<u64>,
}

struct Dims {
    n_pos: usize,
    n_levels: usize,
    n_masks: usize,
}

impl Dims {
    fn pl_mask(&self, pos: usize, level: usize, mask: u32) -> usize {
        (pos * self.n_levels + level) * self.n_masks + mask as usize
    }
}

/// Training result before packaging: kernels, thresholds, reports and the
/// saturation cases found.
pub struct Learned {
    pub kernels: Vec<f32>,
    pub contrast_thresholds: Vec<f32>,
    pub reports: Vec<ClassReport>,
    pub sat_cases: Vec<u32>,
    pub samples: u64,
}

/// The classes of a run: saturation cases and contrast thresholds.
struct Classes {
    sat_cases: Vec<u32>,
    /// Per (pos, level, case).
    thresholds: Vec<f32>,
}

impl Classes {
    fn n_sat(&self) -> usize {
        self.sat_cases.len()
    }
}

/// Progress over the two passes, and cancellation.
struct Ticker<'a> {
    ctl: &'a TrainControl<'a>,
    done: AtomicUsize,
    total: usize,
}

impl Ticker<'_> {
    fn tick(&self, stage: &str) {
        let k = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        (self.ctl.progress)(stage, 0.95 * k as f64 / self.total.max(1) as f64);
    }

    fn check(&self) -> Result<(), L3Error> {
        if self.ctl.cancel.load(Ordering::Relaxed) {
            Err(L3Error::Canceled)
        } else {
            Ok(())
        }
    }
}

/// Learn kernels from `n_frames` batches of frames produced on demand by
/// `frame(i)` (deterministic in `i`; called in parallel, and twice for the
/// survey subset). A batch is typically one scene under one illuminant at
/// several exposures and CFA shifts.
///
/// `colour_maps`, one per level, fix the channel sums of every unsaturated
/// kernel (how it renders a uniform patch); `None` leaves every kernel to
/// plain ridge regression on the patches.
pub fn learn<F>(
    geo: &PatchGeometry,
    params: &L3Params,
    noise: NoiseModel,
    n_frames: usize,
    frame: F,
    colour_maps: Option<&[ColourMatrix]>,
    ctl: &TrainControl,
) -> Result<Learned, L3Error>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, L3Error> + Sync,
{
    params.validate()?;
    if n_frames == 0 {
        return Err(L3Error::InvalidParams("no training frames".into()));
    }
    if params.ridge == RidgeChoice::NoiseVariance && noise.conversion_gain_v <= 0.0 {
        return Err(L3Error::InvalidParams(
            "noise-variance ridge needs a noise model".into(),
        ));
    }
    if let Some(maps) = colour_maps
        && (maps.len() != geo.n_levels() || maps.iter().any(|m| m.m.len() != geo.n_channels()))
    {
        return Err(L3Error::InvalidParams(format!(
            "{} colour maps for {} levels and {} channels",
            maps.len(),
            geo.n_levels(),
            geo.n_channels()
        )));
    }
    let d = Dims {
        n_pos: geo.n_positions(),
        n_levels: geo.n_levels(),
        n_masks: 1 << geo.n_channels(),
    };
    let survey_idx: Vec<usize> = (0..n_frames).step_by(4).collect();
    let ticker = Ticker {
        ctl,
        done: AtomicUsize::new(0),
        total: survey_idx.len() + n_frames,
    };
    let surveyed = survey(geo, params, &d, &survey_idx, &frame, &ticker)?;
    let classes = classes_from_survey(&surveyed, params, &d);
    let grams = accumulate(geo, params, &d, &classes, n_frames, &frame, &ticker)?;
    ticker.check()?;
    (ctl.progress)("solve", 0.95);
    let samples: u64 = grams.iter().map(|g| g.count()).sum();
    let learned = solve_classes(geo, params, &noise, &d, &classes, grams, colour_maps)?;
    (ctl.progress)("done", 1.0);
    Ok(Learned {
        kernels: learned.0,
        contrast_thresholds: classes.thresholds,
        reports: learned.1,
        sat_cases: classes.sat_cases,
        samples,
    })
}

/// Stage 1: contrast histograms and sample counts per (position, level,
/// saturation mask) on the frames `idx`.
fn survey<F>(
    geo: &PatchGeometry,
    params: &L3Params,
    d: &Dims,
    idx: &[usize],
    frame: &F,
    ticker: &Ticker,
) -> Result<Survey, L3Error>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, L3Error> + Sync,
{
    let n_pl = d.n_pos * d.n_levels * d.n_masks;
    let empty = || Survey {
        hist: vec![Vec::new(); n_pl],
        count: vec![0; n_pl],
    };
    let s = idx
        .par_iter()
        .map(|&i| -> Result<Survey, L3Error> {
            ticker.check()?;
            let frames = frame(i)?;
            let mut s = empty();
            for f in &frames {
                for_each_patch(geo, f, |pos, st, _patch| {
                    let level = geo.level_of(st.luminance);
                    let mask = if params.saturation_classes {
                        st.sat_mask
                    } else {
                        0
                    };
                    let k = d.pl_mask(pos, level, mask);
                    if s.hist[k].is_empty() {
                        s.hist[k] = vec![0; HIST_BINS];
                    }
                    s.hist[k][hist_bin(st.contrast)] += 1;
                    s.count[k] += 1;
                });
            }
            ticker.tick("survey");
            Ok(s)
        })
        .try_reduce(empty, |mut a, b| {
            for k in 0..n_pl {
                if !b.hist[k].is_empty() {
                    if a.hist[k].is_empty() {
                        a.hist[k] = b.hist[k].clone();
                    } else {
                        for (x, y) in a.hist[k].iter_mut().zip(&b.hist[k]) {
                            *x += y;
                        }
                    }
                }
                a.count[k] += b.count[k];
            }
            Ok(a)
        })?;
    ticker.check()?;
    Ok(s)
}

/// The saturation cases seen often enough (the empty case first) and the
/// contrast threshold of every (position, level, case): the quantile of the
/// contrasts of the samples that map to that case.
fn classes_from_survey(survey: &Survey, params: &L3Params, d: &Dims) -> Classes {
    let total: u64 = survey.count.iter().sum();
    let mut mask_count = vec![0u64; d.n_masks];
    for pos in 0..d.n_pos {
        for l in 0..d.n_levels {
            for m in 0..d.n_masks {
                mask_count[m] += survey.count[d.pl_mask(pos, l, m as u32)];
            }
        }
    }
    let mut sat_cases = vec![0u32];
    if params.saturation_classes {
        for (m, &cnt) in mask_count.iter().enumerate().skip(1) {
            if cnt as f64 >= params.min_saturation_case_fraction * total as f64 && cnt > 0 {
                sat_cases.push(m as u32);
            }
        }
    }
    let n_sat = sat_cases.len();
    let mut thresholds = vec![0f32; d.n_pos * d.n_levels * n_sat];
    for pos in 0..d.n_pos {
        for l in 0..d.n_levels {
            let mut hs = vec![vec![0u64; HIST_BINS]; n_sat];
            let mut pooled = vec![0u64; HIST_BINS];
            for m in 0..d.n_masks {
                let h = &survey.hist[d.pl_mask(pos, l, m as u32)];
                if h.is_empty() {
                    continue;
                }
                // which case this mask maps to (means unknown here: the
                // channel index order stands in for darkness)
                let case = sat_case_index(&sat_cases, m as u32, &[0.0; MAX_CHANNELS]).0;
                for (b, &v) in h.iter().enumerate() {
                    hs[case][b] += v as u64;
                    pooled[b] += v as u64;
                }
            }
            for (c, h) in hs.iter().enumerate() {
                let use_h = if h.iter().sum::<u64>() >= 50 {
                    h
                } else {
                    &pooled
                };
                thresholds[(pos * d.n_levels + l) * n_sat + c] =
                    quantile_edge(use_h, params.contrast_quantile);
            }
        }
    }
    Classes {
        sat_cases,
        thresholds,
    }
}

/// Stage 2: the normal equations of every class, over every frame. Batches
/// run in parallel a chunk at a time and their f64 sums are merged in batch
/// order, so the result does not depend on thread timing.
fn accumulate<F>(
    geo: &PatchGeometry,
    params: &L3Params,
    d: &Dims,
    classes: &Classes,
    n_frames: usize,
    frame: &F,
    ticker: &Ticker,
) -> Result<Vec<Gram>, L3Error>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, L3Error> + Sync,
{
    let nf = geo.n_features();
    let n_sat = classes.n_sat();
    let n_classes = d.n_pos * d.n_levels * n_sat * 2;
    let new_acc = || -> Vec<Option<Box<Gram>>> { (0..n_classes).map(|_| None).collect() };
    let batch = |i: usize| -> Result<Vec<Option<Box<Gram>>>, L3Error> {
        ticker.check()?;
        let frames = frame(i)?;
        let mut acc = new_acc();
        let mut feat = vec![0f32; nf];
        for f in &frames {
            ticker.check()?;
            for_each_patch(geo, f, |pos, st, patch| {
                let level = geo.level_of(st.luminance);
                let mask = if params.saturation_classes {
                    st.sat_mask
                } else {
                    0
                };
                let case = sat_case_index(&classes.sat_cases, mask, &st.channel_means).0;
                let group = (pos * d.n_levels + level) * n_sat + case;
                let texture = params.contrast_classes && st.contrast > classes.thresholds[group];
                let class = group * 2 + texture as usize;
                geo.features(patch, pos, classes.sat_cases[case], &mut feat);
                let idx = st.index;
                let y = [f.xyz[idx * 3], f.xyz[idx * 3 + 1], f.xyz[idx * 3 + 2]];
                acc[class]
                    .get_or_insert_with(|| Box::new(Gram::new(nf)))
                    .push(&feat, y);
            });
        }
        ticker.tick("accumulate");
        Ok(acc)
    };
    const CHUNK: usize = 8;
    let mut accs = new_acc();
    for start in (0..n_frames).step_by(CHUNK) {
        let end = (start + CHUNK).min(n_frames);
        let parts = (start..end)
            .into_par_iter()
            .map(batch)
            .collect::<Result<Vec<_>, L3Error>>()?;
        for part in parts {
            for (x, y) in accs.iter_mut().zip(part) {
                match (x.as_mut(), y) {
                    (Some(g), Some(h)) => g.merge(&h),
                    (None, Some(h)) => *x = Some(h),
                    _ => {}
                }
            }
        }
    }
    Ok(accs
        .into_iter()
        .map(|g| g.map(|b| *b).unwrap_or_else(|| Gram::new(nf)))
        .collect())
}

/// Index of class (position, level, case, texture).
fn class_index(d: &Dims, n_sat: usize, pos: usize, l: usize, c: usize, t: usize) -> usize {
    ((pos * d.n_levels + l) * n_sat + c) * 2 + t
}

/// Add to every flat class the mirror images of its samples, where the
/// CFA pattern around its position is symmetric.
fn symmetrize_flat(geo: &PatchGeometry, d: &Dims, n_sat: usize, grams: &mut [Gram]) {
    let nf = geo.n_features();
    for pos in 0..d.n_pos {
        let syms = geo.symmetries(pos);
        if syms.len() < 2 {
            continue;
        }
        for l in 0..d.n_levels {
            for c in 0..n_sat {
                let k = class_index(d, n_sat, pos, l, c, 0);
                if grams[k].count() == 0 {
                    continue;
                }
                let mut sum = Gram::new(nf);
                for map in &syms {
                    sum.merge(&grams[k].permuted(map));
                }
                grams[k] = sum;
            }
        }
    }
}

/// Stage 3: the samples a class is solved from, and the level they were
/// borrowed from (−1 for its own). A class with fewer than `need` samples
/// merges its neighbouring levels, nearest first; one with none at any level
/// takes the other contrast class; a saturation case this position never
/// saw borrows the case it falls back to, with this case's saturated
/// channels zeroed (exactly the features those samples would have here).
#[allow(clippy::too_many_arguments)]
fn fill(
    geo: &PatchGeometry,
    d: &Dims,
    classes: &Classes,
    grams: &mut [Gram],
    pos: usize,
    l: usize,
    c: usize,
    t_src: usize,
    need: u64,
) -> (Gram, i32) {
    let n_sat = classes.n_sat();
    let nf = geo.n_features();
    let ci = |l: usize, c: usize, t: usize| class_index(d, n_sat, pos, l, c, t);
    let mut g = grams[ci(l, c, t_src)].clone();
    let mut filled_from = -1i32;
    let neighbours = |step: usize| {
        [l as isize - step as isize, (l + step) as isize]
            .into_iter()
            .filter(|&nl| nl >= 0 && (nl as usize) < d.n_levels)
            .map(|nl| nl as usize)
    };
    let mut step = 1;
    while g.count() < need && step < d.n_levels {
        for nl in neighbours(step) {
            let src = ci(nl, c, t_src);
            if grams[src].count() > 0 {
                g.merge(&grams[src]);
                if filled_from < 0 {
                    filled_from = nl as i32;
                }
            }
        }
        step += 1;
    }
    let mut step = 0;
    while g.count() == 0 && step < d.n_levels {
        for nl in neighbours(step) {
            let other = ci(nl, c, 1 - t_src);
            if g.count() == 0 && grams[other].count() > 0 {
                g = grams[other].clone();
                filled_from = nl as i32;
            }
        }
        step += 1;
    }
    let sat_cases = &classes.sat_cases;
    let mut others = sat_cases.clone();
    let mut fb = c;
    while g.count() == 0 && fb != 0 {
        others[fb] = u32::MAX;
        fb = sat_case_index(&others, sat_cases[c], &[0.0; MAX_CHANNELS]).0;
        let chans = geo.channels_of(pos);
        let zero: Vec<usize> = (0..nf - 1)
            .filter(|&k| sat_cases[c] & (1 << chans[k]) != 0)
            .collect();
        'levels: for step in 0..d.n_levels {
            for nl in neighbours(step) {
                for tt in [t_src, 1 - t_src] {
                    let src = ci(nl, fb, tt);
                    if grams[src].count() > 0 {
                        g.merge(&grams[src].with_zeroed(&zero));
                        filled_from = nl as i32;
                    }
                }
                if g.count() > 0 {
                    break 'levels;
                }
            }
        }
    }
    (g, filled_from)
}

/// The channel-sum constraint of level `l`'s colour map for position `pos`.
fn colour_constraint<'a>(
    geo: &'a PatchGeometry,
    pos: usize,
    map: &ColourMatrix,
) -> ChannelSumConstraint<'a> {
    ChannelSumConstraint {
        channel_of: geo.channels_of(pos),
        n_channels: geo.n_channels(),
        sums: [0, 1, 2].map(|k| map.m.iter().map(|col| col[k]).collect()),
        intercept: [0.0; 3],
    }
}

/// Stage 4: fill and solve every class. Unsaturated kernels (flat and
/// texture) have their channel sums fixed to the level's colour map when
/// one is given; saturated cases, whose clipped channels carry no colour,
/// are plain ridge regressions.
fn solve_classes(
    geo: &PatchGeometry,
    params: &L3Params,
    noise: &NoiseModel,
    d: &Dims,
    classes: &Classes,
    mut grams: Vec<Gram>,
    colour_maps: Option<&[ColourMatrix]>,
) -> Result<(Vec<f32>, Vec<ClassReport>), L3Error> {
    let nf = geo.n_features();
    let n_sat = classes.n_sat();
    let n_classes = d.n_pos * d.n_levels * n_sat * 2;
    let raw_counts: Vec<u64> = grams.iter().map(|g| g.count()).collect();
    if params.symmetrize_flat {
        symmetrize_flat(geo, d, n_sat, &mut grams);
    }
    let sym_factor = |pos: usize| -> u64 {
        if params.symmetrize_flat {
            geo.symmetries(pos).len().max(1) as u64
        } else {
            1
        }
    };
    let mut kernels = vec![0f32; n_classes * 3 * nf];
    let mut reports = Vec::with_capacity(n_classes);
    for pos in 0..d.n_pos {
        for l in 0..d.n_levels {
            for c in 0..n_sat {
                for t in 0..2 {
                    let k = class_index(d, n_sat, pos, l, c, t);
                    // without contrast classes, texture uses the flat data
                    let t_src = if params.contrast_classes { t } else { 0 };
                    let need =
                        params.min_class_samples * if t_src == 0 { sym_factor(pos) } else { 1 };
                    let (mut g, filled_from) =
                        fill(geo, d, classes, &mut grams, pos, l, c, t_src, need);
                    if g.count() == 0 {
                        return Err(L3Error::Table(format!(
                            "class (position {pos}, level {l}, case {c}) has no samples at any level"
                        )));
                    }
                    let level_v = geo.levels()[l] as f64;
                    let con = match colour_maps {
                        Some(maps) if c == 0 => Some(colour_constraint(geo, pos, &maps[l])),
                        _ => None,
                    };
                    let sol =
                        solve_with(&mut g, params.ridge, noise.variance(level_v), con.as_ref())
                            .map_err(|e| {
                                L3Error::Table(format!(
                                    "class (position {pos}, level {l}, case {c}, texture {t}): {e}"
                                ))
                            })?;
                    for (dst, src) in kernels[k * 3 * nf..(k + 1) * 3 * nf]
                        .iter_mut()
                        .zip(&sol.kernel)
                    {
                        *dst = *src as f32;
                    }
                    reports.push(ClassReport::new(
                        raw_counts[class_index(d, n_sat, pos, l, c, t_src)],
                        filled_from,
                        &sol,
                        nf,
                        noise.variance(level_v).sqrt(),
                    ));
                }
            }
        }
    }
    Ok((kernels, reports))
}

/// Package learned kernels as a table.
pub fn package(meta: TableMeta, learned: Learned) -> Result<L3Table, L3Error> {
    let mut meta = meta;
    meta.sat_cases = learned.sat_cases;
    let t = L3Table {
        meta,
        kernels: learned.kernels,
        contrast_thresholds: learned.contrast_thresholds,
        reports: learned.reports,
    };
    t.validate()?;
    Ok(t)
}

fn quantile_edge(h: &[u64], q: f64) -> f32 {
    let total: u64 = h.iter().sum();
    if total == 0 {
        return 0.0;
    }
    let target = (q * total as f64).ceil() as u64;
    let mut acc = 0;
    for (b, &v) in h.iter().enumerate() {
        acc += v;
        if acc >= target {
            return hist_edge(b + 1);
        }
    }
    hist_edge(HIST_BINS)
}

/// Per-patch statistics with the flat index of the centre pixel.
struct IndexedStats {
    index: usize,
    luminance: f32,
    sat_mask: u32,
    contrast: f32,
    channel_means: [f32; MAX_CHANNELS],
}

fn for_each_patch(
    geo: &PatchGeometry,
    f: &TrainingFrame,
    mut visit: impl FnMut(usize, &IndexedStats, &[f32]),
) {
    let mut patch = vec![0f32; geo.n_features() - 1];
    let (dr, dc) = f.cfa_shift;
    if f.volts.len() != f.width * f.height || f.xyz.len() != f.volts.len() * 3 {
        return;
    }
    for r in 0..f.height {
        for c in 0..f.width {
            geo.gather(&f.volts, f.width, f.height, r, c, &mut patch);
            let pos = geo.position(r + dr, c + dc);
            let s = geo.stats(&patch, pos);
            let st = IndexedStats {
                index: r * f.width + c,
                luminance: s.luminance,
                sat_mask: s.sat_mask,
                contrast: s.contrast,
                channel_means: s.channel_means,
            };
            visit(pos, &st, &patch);
        }
    }
}
