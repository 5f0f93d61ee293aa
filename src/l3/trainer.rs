//! Learning a table from (noisy mosaic, ideal XYZ) frame pairs, streaming
//! and in parallel, in four stages:
//! 1. [`survey_batches`]: contrast histograms and saturation cases on a
//!    subset of frames, giving the saturation cases that get kernels and
//!    the flat/texture thresholds ([`classes_from_survey`]);
//! 2. [`accumulate_batches`]: per-class normal equations in f64 over every
//!    frame, summed over a fixed tree of batches ([`super::shards`]);
//! 3. [`fill`]: classes with too few samples borrow from their neighbours;
//! 4. [`solve_classes`]: ridge regression per class, the channel sums of
//!    unsaturated kernels fixed to the level's colour map (see
//!    [`super::colour_map`]).
//!
//! Stages 1 and 2 work on a range of batches, so that a run can be split
//! into shards computed anywhere and merged bit for bit
//! ([`super::shards`]); [`learn`] runs them on one range covering every
//! batch.

use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rayon::prelude::*;

use super::classify::MAX_CHANNELS;
use super::classify::sat_case_index;
use super::normal_eq::{ChannelSumConstraint, solve_with};
use super::shards::{
    ClassSums, Classes, GramPartial, Node, SurveyPartial, SurveyShape, add_class_sums, cover,
    merge_partials, tree_sum,
};
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
    /// The sensor's channel responses to white under the frame's light, which
    /// chroma classes balance by ([`PatchGeometry::under_light`]); `None`: the
    /// classes' reference light.
    pub neutral: Option<Vec<f64>>,
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

/// The run's class layout: positions × bands (luminance levels × chroma
/// classes, band = level × chroma classes + class) × saturation.
struct Dims {
    n_pos: usize,
    n_bands: usize,
    n_chroma: usize,
    n_masks: usize,
}

impl Dims {
    fn pl_mask(&self, pos: usize, band: usize, mask: u32) -> usize {
        (pos * self.n_bands + band) * self.n_masks + mask as usize
    }

    fn n_levels(&self) -> usize {
        self.n_bands / self.n_chroma.max(1)
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

/// What every stage and every shard of a training run share.
#[derive(Clone, Copy)]
pub struct TrainSetup<'a> {
    pub geo: &'a PatchGeometry,
    pub params: &'a L3Params,
    pub noise: NoiseModel,
    /// Batches of the run, numbered `0..n_batches`.
    pub n_batches: usize,
    /// One per level: the channel sums of every unsaturated kernel; `None`
    /// leaves every kernel to plain ridge regression.
    pub colour_maps: Option<&'a [ColourMatrix]>,
    /// Names the run in its partial sums, whose merge refuses parts of
    /// another run (e.g. a digest of the training spec).
    pub run_key: &'a str,
}

impl TrainSetup<'_> {
    pub fn validate(&self) -> Result<(), L3Error> {
        let (geo, params) = (self.geo, self.params);
        params.validate()?;
        if self.n_batches == 0 {
            return Err(L3Error::InvalidParams("no training frames".into()));
        }
        if params.ridge == RidgeChoice::NoiseVariance && self.noise.conversion_gain_v <= 0.0 {
            return Err(L3Error::InvalidParams(
                "noise-variance ridge needs a noise model".into(),
            ));
        }
        if let Some(maps) = self.colour_maps
            && (maps.len() != geo.n_bands() || maps.iter().any(|m| m.m.len() != geo.n_channels()))
        {
            return Err(L3Error::InvalidParams(format!(
                "{} colour maps for {} bands and {} channels",
                maps.len(),
                geo.n_bands(),
                geo.n_channels()
            )));
        }
        Ok(())
    }

    fn dims(&self) -> Dims {
        Dims {
            n_pos: self.geo.n_positions(),
            n_bands: self.geo.n_bands(),
            n_chroma: self.geo.n_chroma(),
            n_masks: 1 << self.geo.n_channels(),
        }
    }

    /// The sizes of this run's survey.
    pub fn survey_shape(&self) -> SurveyShape {
        let d = self.dims();
        SurveyShape {
            n_positions: d.n_pos,
            n_levels: d.n_bands,
            n_masks: d.n_masks,
            bins: HIST_BINS,
        }
    }

    /// Classes of the run for `classes`' saturation cases.
    pub fn n_classes(&self, classes: &Classes) -> usize {
        let d = self.dims();
        d.n_pos * d.n_bands * classes.n_sat() * 2
    }

    fn check_range(&self, batches: &Range<usize>) -> Result<(), L3Error> {
        if batches.start >= batches.end || batches.end > self.n_batches {
            return Err(L3Error::InvalidParams(format!(
                "batches {}..{} of 0..{}",
                batches.start, batches.end, self.n_batches
            )));
        }
        Ok(())
    }
}

/// Whether batch `i` is surveyed (every fourth one).
fn is_surveyed(i: usize) -> bool {
    i.is_multiple_of(4)
}

/// Progress over the two passes, and cancellation. Tick `k` of `total`
/// reports `base + span · k / total`.
struct Ticker<'a> {
    ctl: &'a TrainControl<'a>,
    done: AtomicUsize,
    total: usize,
    base: f64,
    span: f64,
}

impl<'a> Ticker<'a> {
    fn new(ctl: &'a TrainControl<'a>, total: usize, base: f64, span: f64) -> Self {
        Self {
            ctl,
            done: AtomicUsize::new(0),
            total,
            base,
            span,
        }
    }

    fn tick(&self, stage: &str) {
        let k = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        (self.ctl.progress)(
            stage,
            self.base + self.span * k as f64 / self.total.max(1) as f64,
        );
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
///
/// This is the sharded path of [`super::shards`] with one shard: survey,
/// classes, accumulation, merge, solve.
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
    let setup = TrainSetup {
        geo,
        params,
        noise,
        n_batches: n_frames,
        colour_maps,
        run_key: "",
    };
    setup.validate()?;
    let all = 0..n_frames;
    let n_survey = all.clone().filter(|&i| is_surveyed(i)).count();
    let survey_part = 0.95 * n_survey as f64 / (n_survey + n_frames) as f64;
    let ticker = Ticker::new(ctl, n_survey, 0.0, survey_part);
    let surveyed = survey_with(&setup, all.clone(), &frame, &ticker)?;
    let classes = classes_from_survey(&setup, &surveyed)?;
    let ticker = Ticker::new(ctl, n_frames, survey_part, 0.95 - survey_part);
    let partial = accumulate_with(&setup, &classes, all, &frame, &ticker)?;
    ticker.check()?;
    let grams = merge_partials(&classes, vec![partial])?;
    solve_learned(&setup, classes, grams, ctl)
}

/// Stage 1 on batches `batches` of a run: contrast histograms and sample
/// counts per (position, level, saturation mask) of its surveyed batches.
/// `ctl` sees this shard's progress (0 to 1).
pub fn survey_batches<F>(
    setup: &TrainSetup,
    batches: Range<usize>,
    frame: &F,
    ctl: &TrainControl,
) -> Result<SurveyPartial, L3Error>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, L3Error> + Sync,
{
    setup.validate()?;
    setup.check_range(&batches)?;
    let n = batches.clone().filter(|&i| is_surveyed(i)).count();
    survey_with(setup, batches, frame, &Ticker::new(ctl, n, 0.0, 1.0))
}

fn survey_with<F>(
    setup: &TrainSetup,
    batches: Range<usize>,
    frame: &F,
    ticker: &Ticker,
) -> Result<SurveyPartial, L3Error>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, L3Error> + Sync,
{
    let (geo, params, d) = (setup.geo, setup.params, setup.dims());
    let shape = setup.survey_shape();
    let empty = || SurveyPartial::empty(setup.run_key, setup.n_batches, batches.clone(), shape);
    let idx: Vec<usize> = batches.clone().filter(|&i| is_surveyed(i)).collect();
    let s = idx
        .par_iter()
        .map(|&i| -> Result<SurveyPartial, L3Error> {
            ticker.check()?;
            let frames = frame(i)?;
            let mut s = empty();
            for f in &frames {
                let geo = geo.under_light(f.neutral.as_deref())?;
                for_each_patch(&geo, f, |pos, st, _patch| {
                    let level = geo.band_of(st.luminance, &st.channel_means);
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
            a.add_counts(&b);
            Ok(a)
        })?;
    ticker.check()?;
    Ok(s)
}

/// The saturation cases seen often enough (the empty case first) and the
/// contrast threshold of every (position, level, case): the quantile of the
/// contrasts of the samples that map to that case. `survey` must cover
/// every batch of the run ([`super::shards::merge_surveys`]).
pub fn classes_from_survey(setup: &TrainSetup, survey: &SurveyPartial) -> Result<Classes, L3Error> {
    let params = setup.params;
    let d = setup.dims();
    if survey.run_key != setup.run_key
        || survey.n_batches != setup.n_batches
        || survey.batches != (0..setup.n_batches)
        || survey.shape != setup.survey_shape()
        || survey.hist.len() != survey.shape.n_cells()
        || survey.count.len() != survey.shape.n_cells()
        || survey
            .hist
            .iter()
            .any(|h| !h.is_empty() && h.len() != HIST_BINS)
    {
        return Err(L3Error::PartialSums(format!(
            "the survey of batches {}..{} is not this run's whole survey",
            survey.batches.start, survey.batches.end
        )));
    }
    let total: u64 = survey.count.iter().sum();
    let mut mask_count = vec![0u64; d.n_masks];
    for pos in 0..d.n_pos {
        for l in 0..d.n_bands {
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
    let mut thresholds = vec![0f32; d.n_pos * d.n_bands * n_sat];
    for pos in 0..d.n_pos {
        for l in 0..d.n_bands {
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
                    hs[case][b] += v;
                    pooled[b] += v;
                }
            }
            for (c, h) in hs.iter().enumerate() {
                let use_h = if h.iter().sum::<u64>() >= 50 {
                    h
                } else {
                    &pooled
                };
                thresholds[(pos * d.n_bands + l) * n_sat + c] =
                    quantile_edge(use_h, params.contrast_quantile);
            }
        }
    }
    Ok(Classes {
        sat_cases,
        thresholds,
    })
}

/// Stage 2 on batches `batches` of a run: the normal equations of every
/// class, as the sums of the tree nodes tiling the range (each node's
/// halves in parallel; see [`super::shards`] for why the sums do not
/// depend on the split). `ctl` sees this shard's progress (0 to 1).
pub fn accumulate_batches<F>(
    setup: &TrainSetup,
    classes: &Classes,
    batches: Range<usize>,
    frame: &F,
    ctl: &TrainControl,
) -> Result<GramPartial, L3Error>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, L3Error> + Sync,
{
    setup.validate()?;
    setup.check_range(&batches)?;
    let ticker = Ticker::new(ctl, batches.len(), 0.0, 1.0);
    let partial = accumulate_with(setup, classes, batches, frame, &ticker)?;
    ticker.check()?;
    Ok(partial)
}

fn accumulate_with<F>(
    setup: &TrainSetup,
    classes: &Classes,
    batches: Range<usize>,
    frame: &F,
    ticker: &Ticker,
) -> Result<GramPartial, L3Error>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, L3Error> + Sync,
{
    let (geo, params, d) = (setup.geo, setup.params, setup.dims());
    let nf = geo.n_features();
    let n_sat = classes.n_sat();
    let n_classes = setup.n_classes(classes);
    if n_sat == 0 || classes.thresholds.len() != d.n_pos * d.n_bands * n_sat {
        return Err(L3Error::InvalidParams(format!(
            "{} thresholds for {n_sat} saturation cases",
            classes.thresholds.len()
        )));
    }
    let batch = |i: usize| -> Result<ClassSums, L3Error> {
        ticker.check()?;
        let frames = frame(i)?;
        let mut acc: ClassSums = (0..n_classes).map(|_| None).collect();
        let mut feat = vec![0f32; nf];
        for f in &frames {
            ticker.check()?;
            let geo = geo.under_light(f.neutral.as_deref())?;
            for_each_patch(&geo, f, |pos, st, patch| {
                let level = geo.band_of(st.luminance, &st.channel_means);
                let mask = if params.saturation_classes {
                    st.sat_mask
                } else {
                    0
                };
                let case = sat_case_index(&classes.sat_cases, mask, &st.channel_means).0;
                let group = (pos * d.n_bands + level) * n_sat + case;
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
    let n = setup.n_batches;
    let leaf = |node: Node| -> Result<Option<ClassSums>, L3Error> {
        if node.log2 == 0 {
            batch(node.lo).map(Some)
        } else {
            Ok(None)
        }
    };
    let nodes = cover(batches.clone(), n)
        .into_par_iter()
        .map(|node| -> Result<(Node, ClassSums), L3Error> {
            let mut sums = tree_sum(node, n, &leaf, &add_class_sums)?;
            for g in sums.iter_mut().flatten() {
                g.flush();
            }
            Ok((node, sums))
        })
        .collect::<Result<Vec<_>, L3Error>>()?;
    Ok(GramPartial {
        run_key: setup.run_key.to_string(),
        n_batches: n,
        batches,
        n_features: nf,
        n_classes,
        classes_digest: classes.digest(),
        nodes,
    })
}

/// Stages 3 and 4 on a run's merged normal equations
/// ([`super::shards::merge_partials`]): fill and solve every class.
pub fn solve_learned(
    setup: &TrainSetup,
    classes: Classes,
    grams: Vec<Gram>,
    ctl: &TrainControl,
) -> Result<Learned, L3Error> {
    setup.validate()?;
    let n_classes = setup.n_classes(&classes);
    let nf = setup.geo.n_features();
    if grams.len() != n_classes
        || grams.iter().any(|g| g.n_features() != nf)
        || classes.thresholds.len() != n_classes / 2
    {
        return Err(L3Error::PartialSums(format!(
            "{} class sums for {n_classes} classes",
            grams.len()
        )));
    }
    if ctl.cancel.load(Ordering::Relaxed) {
        return Err(L3Error::Canceled);
    }
    (ctl.progress)("solve", 0.95);
    let samples: u64 = grams.iter().map(|g| g.count()).sum();
    let d = setup.dims();
    let learned = solve_classes(
        setup.geo,
        setup.params,
        &setup.noise,
        &d,
        &classes,
        grams,
        setup.colour_maps,
    )?;
    (ctl.progress)("done", 1.0);
    Ok(Learned {
        kernels: learned.0,
        contrast_thresholds: classes.thresholds,
        reports: learned.1,
        sat_cases: classes.sat_cases,
        samples,
    })
}

/// Index of class (position, band, case, texture).
fn class_index(d: &Dims, n_sat: usize, pos: usize, b: usize, c: usize, t: usize) -> usize {
    ((pos * d.n_bands + b) * n_sat + c) * 2 + t
}

/// Give every chroma class of a saturated case the samples of all of them
/// at its (position, level): a clipped channel's mean no longer tells the
/// colour, and split K ways the saturated cases starve (rgbw-iset, 6
/// classes: kernels filled from far levels with norms up to 1.4e3). Their
/// kernels are then those of a table without chroma classes.
fn pool_saturated_chroma(d: &Dims, n_sat: usize, grams: &mut [Gram]) {
    let kc = d.n_chroma.max(1);
    if kc == 1 {
        return;
    }
    for pos in 0..d.n_pos {
        for l in 0..d.n_levels() {
            for c in 1..n_sat {
                for t in 0..2 {
                    let ids: Vec<usize> = (0..kc)
                        .map(|k| class_index(d, n_sat, pos, l * kc + k, c, t))
                        .collect();
                    let mut sum = grams[ids[0]].clone();
                    for &i in &ids[1..] {
                        sum.merge(&grams[i]);
                    }
                    for &i in &ids {
                        grams[i] = sum.clone();
                    }
                }
            }
        }
    }
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
        for l in 0..d.n_bands {
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
/// merges its neighbouring levels of its chroma class, nearest first
/// (`band` is level × chroma classes + chroma class); one with none at any level
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
    band: usize,
    c: usize,
    t_src: usize,
    need: u64,
) -> (Gram, i32) {
    let n_sat = classes.n_sat();
    let nf = geo.n_features();
    let (n_levels, kc) = (d.n_levels(), d.n_chroma.max(1));
    let (l, chroma) = (band / kc, band % kc);
    // class of level `l` in this chroma class
    let ci = |l: usize, c: usize, t: usize| class_index(d, n_sat, pos, l * kc + chroma, c, t);
    let mut g = grams[ci(l, c, t_src)].clone();
    let mut filled_from = -1i32;
    let neighbours = |step: usize| {
        [l as isize - step as isize, (l + step) as isize]
            .into_iter()
            .filter(|&nl| nl >= 0 && (nl as usize) < n_levels)
            .map(|nl| nl as usize)
    };
    let mut step = 1;
    while g.count() < need && step < n_levels {
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
    while g.count() == 0 && step < n_levels {
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
        'levels: for step in 0..n_levels {
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
    // a chroma class never seen at any level of this case: the nearest
    // level of the other chroma classes, pooled
    let mut step = 0;
    while g.count() == 0 && kc > 1 && step < n_levels {
        for nl in neighbours(step) {
            for other in (0..kc).filter(|&k| k != chroma) {
                let src = class_index(d, n_sat, pos, nl * kc + other, c, t_src);
                if grams[src].count() > 0 {
                    g.merge(&grams[src]);
                    filled_from = nl as i32;
                }
            }
        }
        step += 1;
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
    let n_classes = d.n_pos * d.n_bands * n_sat * 2;
    let raw_counts: Vec<u64> = grams.iter().map(|g| g.count()).collect();
    pool_saturated_chroma(d, n_sat, &mut grams);
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
        for l in 0..d.n_bands {
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
                            "class (position {pos}, band {l}, case {c}) has no samples at any level"
                        )));
                    }
                    let level_v = geo.levels()[l / d.n_chroma.max(1)] as f64;
                    let con = match colour_maps {
                        Some(maps) if c == 0 => Some(colour_constraint(geo, pos, &maps[l])),
                        _ => None,
                    };
                    let sol =
                        solve_with(&mut g, params.ridge, noise.variance(level_v), con.as_ref())
                            .map_err(|e| {
                                L3Error::Table(format!(
                                    "class (position {pos}, band {l}, case {c}, texture {t}): {e}"
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
