//! Learning a table from (noisy mosaic, ideal XYZ) frame pairs, streaming
//! and in parallel, in four stages:
//! 1. [`survey_batches`]: contrast histograms and saturation cases on a
//!    subset of frames, giving the saturation cases that get kernels and
//!    the flat/texture thresholds ([`classes_from_survey`]);
//! 2. [`accumulate_batches`]: per-class normal equations in f64 over every
//!    frame, summed over a fixed tree of batches ([`super::shards`]);
//! 3. and 4. [`solve_learned`] (`solve.rs`): classes with too few samples borrow
//!    from their neighbours, then ridge regression per class, the channel sums of
//!    unsaturated kernels fixed to the level's colour map (see `colour_map.rs`).
//!
//! Stages 1 and 2 work on a range of batches, so that a run can be split
//! into shards computed anywhere and merged bit for bit
//! ([`super::shards`]); [`learn`] runs them on one range covering every
//! batch.

use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

use super::LearnError;
use super::normal_eq::Gram;
use super::setup::{ClassMaps, HIST_BINS, Learned, TrainControl, TrainSetup, TrainingFrame};
use super::shards::{
    ClassSums, Classes, GramPartial, Node, SurveyPartial, add_class_sums, cover, merge_partials,
    tree_sum,
};
use super::solve::solve_learned;
use crate::l3::classify::{LANES, MAX_CHANNELS, PatchGeometry, PatchStats, sat_case_index};
use crate::l3::correct::NoiseModel;
use crate::l3::params::L3Params;

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

    fn check(&self) -> Result<(), LearnError> {
        if self.ctl.cancel.load(Ordering::Relaxed) {
            Err(LearnError::Canceled)
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
/// `colour_maps`, one per band for the flat and for the texture classes, fix the channel
/// sums of every unsaturated kernel (how it renders a uniform patch); `None` leaves every
/// kernel to plain ridge regression on the patches.
///
/// This is the sharded path of the `shards` module with one shard: survey,
/// classes, accumulation, merge, solve.
pub fn learn<F>(
    geo: &PatchGeometry,
    params: &L3Params,
    noise: NoiseModel,
    n_frames: usize,
    frame: F,
    colour_maps: Option<ClassMaps>,
    ctl: &TrainControl,
) -> Result<Learned, LearnError>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, LearnError> + Sync,
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
) -> Result<SurveyPartial, LearnError>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, LearnError> + Sync,
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
) -> Result<SurveyPartial, LearnError>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, LearnError> + Sync,
{
    let (geo, params, d) = (setup.geo, setup.params, setup.dims());
    let shape = setup.survey_shape();
    let empty = || SurveyPartial::empty(setup.run_key, setup.n_batches, batches.clone(), shape);
    let idx: Vec<usize> = batches.clone().filter(|&i| is_surveyed(i)).collect();
    let s = idx
        .par_iter()
        .map(|&i| -> Result<SurveyPartial, LearnError> {
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
pub fn classes_from_survey(
    setup: &TrainSetup,
    survey: &SurveyPartial,
) -> Result<Classes, LearnError> {
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
        return Err(LearnError::PartialSums(format!(
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
/// halves in parallel; see the `shards` module for why the sums do not
/// depend on the split). `ctl` sees this shard's progress (0 to 1).
pub fn accumulate_batches<F>(
    setup: &TrainSetup,
    classes: &Classes,
    batches: Range<usize>,
    frame: &F,
    ctl: &TrainControl,
) -> Result<GramPartial, LearnError>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, LearnError> + Sync,
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
) -> Result<GramPartial, LearnError>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, LearnError> + Sync,
{
    let (geo, params, d) = (setup.geo, setup.params, setup.dims());
    let nf = geo.n_features();
    let n_sat = classes.n_sat();
    let n_classes = setup.n_classes(classes);
    if n_sat == 0 || classes.thresholds.len() != d.n_pos * d.n_bands * n_sat {
        return Err(LearnError::InvalidParams(format!(
            "{} thresholds for {n_sat} saturation cases",
            classes.thresholds.len()
        )));
    }
    let batch = |i: usize| -> Result<ClassSums, LearnError> {
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
    let leaf = |node: Node| -> Result<Option<ClassSums>, LearnError> {
        if node.log2 == 0 {
            batch(node.lo).map(Some)
        } else {
            Ok(None)
        }
    };
    let nodes = cover(batches.clone(), n)
        .into_par_iter()
        .map(|node| -> Result<(Node, ClassSums), LearnError> {
            let mut sums = tree_sum(node, n, &leaf, &add_class_sums)?;
            for g in sums.iter_mut().flatten() {
                g.flush();
            }
            Ok((node, sums))
        })
        .collect::<Result<Vec<_>, LearnError>>()?;
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

/// Visits every pixel of `f` in raster order with its CFA position, stats and patch. Interior
/// pixels are classified [`LANES`] at a time ([`PatchGeometry::stats_run`], the same stats bit
/// for bit), the borders one by one.
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
    let lanes = geo.lane_channels();
    let (rows, cols) = (geo.cfa.rows, geo.cfa.cols);
    // the stats of the row's run of LANES pixels from column `run.0` (interior pixels only)
    let mut run = (usize::MAX, [PatchStats::default(); LANES]);
    for r in 0..f.height {
        run.0 = usize::MAX;
        for c in 0..f.width {
            geo.gather(&f.volts, f.width, f.height, r, c, &mut patch);
            let pos = geo.position(r + dr, c + dc);
            if !(run.0..run.0.saturating_add(LANES)).contains(&c) {
                // the run from here, else the row's last run that holds this pixel
                let start = c.min((f.width + geo.radius).saturating_sub(LANES + 2 * geo.radius));
                let inside = c >= geo.radius && c + geo.radius < f.width;
                let phase = ((r + dr) % rows, (start + dc) % cols);
                if inside && geo.stats_run(&lanes, phase, &f.volts, f.width, (r, start), &mut run.1)
                {
                    run.0 = start;
                }
            }
            let s = if (run.0..run.0.saturating_add(LANES)).contains(&c) {
                run.1[c - run.0]
            } else {
                geo.stats(&patch, pos)
            };
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Cfa;

    /// Every pixel is visited once, in raster order, with its position, its gathered patch
    /// and the stats `stats` gives that patch, bit for bit: whichever path (runs of lanes or
    /// one pixel) classified it, on frames narrower than a run, as wide as one, and with a
    /// tail shorter than one.
    #[test]
    fn each_patch_is_visited_once_with_its_own_stats() {
        let geo =
            PatchGeometry::new(5, &Cfa::parse("RG/WB").unwrap(), &[0.01, 0.1, 1.0], 1.5).unwrap();
        let mut state = 0x9e37_79b9_u32;
        for (width, height) in [
            (3, 4),
            (19, 6),
            (20, 7),
            (21, 5),
            (22, 9),
            (37, 8),
            (45, 11),
        ] {
            for cfa_shift in [(0, 0), (1, 1), (0, 1)] {
                let volts: Vec<f32> = (0..width * height)
                    .map(|_| {
                        state ^= state << 13;
                        state ^= state >> 17;
                        state ^= state << 5;
                        (state % 2000) as f32 / 1000.0
                    })
                    .collect();
                let f = TrainingFrame {
                    width,
                    height,
                    xyz: vec![0.0; volts.len() * 3],
                    volts,
                    cfa_shift,
                    neutral: None,
                };
                let mut next = 0;
                let mut patch = vec![0f32; 25];
                for_each_patch(&geo, &f, |pos, st, got| {
                    let (r, c) = (next / width, next % width);
                    assert_eq!(st.index, next);
                    geo.gather(&f.volts, width, height, r, c, &mut patch);
                    assert_eq!(got, &patch[..]);
                    assert_eq!(pos, geo.position(r + cfa_shift.0, c + cfa_shift.1));
                    let want = geo.stats(&patch, pos);
                    let bits = |m: &[f32; MAX_CHANNELS]| m.map(f32::to_bits);
                    assert_eq!(
                        (st.luminance.to_bits(), st.contrast.to_bits(), st.sat_mask),
                        (
                            want.luminance.to_bits(),
                            want.contrast.to_bits(),
                            want.sat_mask
                        ),
                        "{width}×{height} ({r}, {c})"
                    );
                    assert_eq!(bits(&st.channel_means), bits(&want.channel_means));
                    next += 1;
                });
                assert_eq!(next, width * height);
            }
        }
    }
}
