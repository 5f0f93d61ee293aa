//! Learning a table from (noisy mosaic, ideal XYZ) frame pairs, streaming
//! and in parallel: pass 1 measures contrast distributions and saturation
//! cases on a subset of frames; pass 2 accumulates per-class normal
//! equations in f64; then every class is solved by ridge regression.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rayon::prelude::*;

use super::classify::MAX_CHANNELS;
use super::classify::sat_case_index;
use super::normal_eq::{ChannelSumConstraint, solve, solve_with};
use super::{ClassReport, Gram, L3Error, L3Params, L3Table, PatchGeometry, RidgeChoice, TableMeta};

/// One training frame: a noisy mosaic in volts and the ideal XYZ at every
/// pixel (interleaved), captured with the CFA shifted by `cfa_shift`.
#[derive(Clone, Debug)]
pub struct TrainingFrame {
    pub width: usize,
    pub height: usize,
    pub volts: Vec<f32>,
    pub xyz: Vec<f32>,
    /// The same mosaic without noise (volts), when known: flat kernels are
    /// then constrained to map flat patches without colour bias.
    pub clean: Option<Vec<f32>>,
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

/// Learn kernels from `n_frames` batches of frames produced on demand by
/// `frame(i)` (deterministic in `i`; called in parallel, and twice for the
/// survey subset). A batch is typically one scene under one illuminant at
/// several exposures and CFA shifts.
pub fn learn<F>(
    geo: &PatchGeometry,
    params: &L3Params,
    noise: NoiseModel,
    n_frames: usize,
    frame: F,
    ctl: &TrainControl,
) -> Result<Learned, L3Error>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, L3Error> + Sync,
{
    params.validate()?;
    if n_frames == 0 {
        return Err(L3Error::InvalidParams("no training frames".into()));
    }
    let d = Dims {
        n_pos: geo.n_positions(),
        n_levels: geo.n_levels(),
        n_masks: 1 << geo.n_channels(),
    };
    let check_cancel = || {
        if ctl.cancel.load(Ordering::Relaxed) {
            Err(L3Error::Canceled)
        } else {
            Ok(())
        }
    };

    // ---- pass 1: survey every 4th frame (at least 1) ----
    let survey_idx: Vec<usize> = (0..n_frames).step_by(4).collect();
    let total_work = survey_idx.len() + n_frames;
    let done = AtomicUsize::new(0);
    let tick = |stage: &str| {
        let k = done.fetch_add(1, Ordering::Relaxed) + 1;
        (ctl.progress)(stage, 0.95 * k as f64 / total_work as f64);
    };
    let n_pl = d.n_pos * d.n_levels * d.n_masks;
    let survey = survey_idx
        .par_iter()
        .map(|&i| -> Result<Survey, L3Error> {
            check_cancel()?;
            let frames = frame(i)?;
            let mut s = Survey {
                hist: vec![Vec::new(); n_pl],
                count: vec![0; n_pl],
            };
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
            tick("survey");
            Ok(s)
        })
        .try_reduce(
            || Survey {
                hist: vec![Vec::new(); n_pl],
                count: vec![0; n_pl],
            },
            |mut a, b| {
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
            },
        )?;
    check_cancel()?;

    // Saturation cases seen often enough (always the empty case first).
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
    // A provisional table shape to reuse the render-side case fallback.
    let case_of = |mask: u32, means: &[f32]| -> usize { sat_case_index(&sat_cases, mask, means).0 };

    // Contrast thresholds per (pos, level, case): the quantile of the
    // histogram of the samples that map to that case.
    let n_groups = d.n_pos * d.n_levels * n_sat;
    let mut thresholds = vec![0f32; n_groups];
    for pos in 0..d.n_pos {
        for l in 0..d.n_levels {
            let mut hs = vec![vec![0u64; HIST_BINS]; n_sat];
            let mut pooled = vec![0u64; HIST_BINS];
            for m in 0..d.n_masks {
                let h = &survey.hist[d.pl_mask(pos, l, m as u32)];
                if h.is_empty() {
                    continue;
                }
                // which case this mask maps to (means unknown here: use the
                // channel index order as a stand-in for darkness)
                let case = case_of(m as u32, &[0.0; MAX_CHANNELS]);
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

    // ---- pass 2: accumulate normal equations ----
    let nf = geo.n_features();
    let n_classes = n_groups * 2;
    // one noise-free colour map per level, pooled over CFA positions: a flat
    // patch maps to the same XYZ whichever filter sits at its centre
    let n_maps = d.n_levels;
    let nch = geo.n_channels();
    let use_maps = params.unbiased_flat;
    let new_acc = || -> Vec<Option<Box<Gram>>> { (0..n_classes + n_maps).map(|_| None).collect() };
    let batch = |i: usize| -> Result<Vec<Option<Box<Gram>>>, L3Error> {
        check_cancel()?;
        let frames = frame(i)?;
        let mut acc = new_acc();
        let mut feat = vec![0f32; nf];
        let mut clean_patch = vec![0f32; nf - 1];
        let mut map_feat = vec![0f32; nch + 1];
        for f in &frames {
            check_cancel()?;
            for_each_patch(geo, f, |pos, st, patch| {
                let level = geo.level_of(st.luminance);
                let mask = if params.saturation_classes {
                    st.sat_mask
                } else {
                    0
                };
                let case = case_of(mask, &st.channel_means);
                let group = (pos * d.n_levels + level) * n_sat + case;
                let texture = params.contrast_classes && st.contrast > thresholds[group];
                let class = group * 2 + texture as usize;
                geo.features(patch, pos, sat_cases[case], &mut feat);
                let idx = st.index;
                let y = [f.xyz[idx * 3], f.xyz[idx * 3 + 1], f.xyz[idx * 3 + 2]];
                acc[class]
                    .get_or_insert_with(|| Box::new(Gram::new(nf)))
                    .push(&feat, y);
                if use_maps
                    && case == 0
                    && !texture
                    && let Some(clean) = &f.clean
                {
                    let (r, c) = (idx / f.width, idx % f.width);
                    geo.gather(clean, f.width, f.height, r, c, &mut clean_patch);
                    let cs = geo.stats(&clean_patch, pos);
                    map_feat[..nch].copy_from_slice(&cs.channel_means[..nch]);
                    map_feat[nch] = 1.0;
                    let my = patch_mean_xyz(geo, f, r, c);
                    acc[n_classes + level]
                        .get_or_insert_with(|| Box::new(Gram::new(nch + 1)))
                        .push(&map_feat, my);
                }
            });
        }
        tick("accumulate");
        Ok(acc)
    };
    // Batches run in parallel a chunk at a time, and their f64 sums are
    // merged in batch order: the result does not depend on thread timing.
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
    check_cancel()?;
    (ctl.progress)("solve", 0.95);

    // ---- solve ----
    let mut accs = accs;
    let mut maps: Vec<Option<Box<Gram>>> = accs.split_off(n_classes);
    let mut grams: Vec<Gram> = accs
        .into_iter()
        .map(|g| g.map(|b| *b).unwrap_or_else(|| Gram::new(nf)))
        .collect();
    let samples: u64 = grams.iter().map(|g| g.count()).sum();
    let raw_counts: Vec<u64> = grams.iter().map(|g| g.count()).collect();
    // Symmetrise flat classes: add the mirror images of their samples.
    if params.symmetrize_flat {
        for pos in 0..d.n_pos {
            let syms = geo.symmetries(pos);
            if syms.len() < 2 {
                continue;
            }
            for l in 0..d.n_levels {
                for c in 0..n_sat {
                    let k = ((pos * d.n_levels + l) * n_sat + c) * 2;
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
    let count_of = |g: &Gram| g.count();
    let class_of =
        |pos: usize, l: usize, c: usize, t: usize| ((pos * d.n_levels + l) * n_sat + c) * 2 + t;
    let mut kernels = vec![0f32; n_classes * 3 * nf];
    let mut reports = Vec::with_capacity(n_classes);
    let sym_factor = |pos: usize| -> u64 {
        if params.symmetrize_flat {
            geo.symmetries(pos).len().max(1) as u64
        } else {
            1
        }
    };
    for pos in 0..d.n_pos {
        for l in 0..d.n_levels {
            for c in 0..n_sat {
                for t in 0..2 {
                    let k = class_of(pos, l, c, t);
                    // without contrast classes, texture uses the flat data
                    let t_src = if params.contrast_classes { t } else { 0 };
                    let need =
                        params.min_class_samples * if t_src == 0 { sym_factor(pos) } else { 1 };
                    let own = class_of(pos, l, c, t_src);
                    let mut g = grams[own].clone();
                    let mut filled_from = -1i32;
                    // borrow from neighbouring levels, nearest first
                    let mut step = 1;
                    while count_of(&g) < need && step < d.n_levels {
                        for nl in [l as isize - step as isize, (l + step) as isize] {
                            if nl >= 0 && (nl as usize) < d.n_levels {
                                let src = class_of(pos, nl as usize, c, t_src);
                                if grams[src].count() > 0 {
                                    g.merge(&grams[src]);
                                    if filled_from < 0 {
                                        filled_from = nl as i32;
                                    }
                                }
                            }
                        }
                        step += 1;
                    }
                    // none at any level: the other contrast class, nearest level first
                    let mut step = 0;
                    while count_of(&g) == 0 && step < d.n_levels {
                        for nl in [l as isize - step as isize, (l + step) as isize] {
                            if nl >= 0 && (nl as usize) < d.n_levels && count_of(&g) == 0 {
                                let other = class_of(pos, nl as usize, c, 1 - t_src);
                                if grams[other].count() > 0 {
                                    g = grams[other].clone();
                                    filled_from = nl as i32;
                                }
                            }
                        }
                        step += 1;
                    }
                    // A saturation case this position never saw (the survey
                    // found it at other positions): borrow the samples of the
                    // case it falls back to, nearest level first, with this
                    // case's channels zeroed — exactly the features those
                    // samples would have in this case.
                    let mut others = sat_cases.clone();
                    let mut fb = c;
                    while count_of(&g) == 0 && fb != 0 {
                        others[fb] = u32::MAX;
                        fb = sat_case_index(&others, sat_cases[c], &[0.0; MAX_CHANNELS]).0;
                        let chans = geo.channels_of(pos);
                        let zero: Vec<usize> = (0..nf - 1)
                            .filter(|&k| sat_cases[c] & (1 << chans[k]) != 0)
                            .collect();
                        'levels: for step in 0..d.n_levels {
                            for nl in [l as isize - step as isize, (l + step) as isize] {
                                if nl < 0 || nl as usize >= d.n_levels {
                                    continue;
                                }
                                for tt in [t_src, 1 - t_src] {
                                    let src = class_of(pos, nl as usize, fb, tt);
                                    if grams[src].count() > 0 {
                                        g.merge(&grams[src].with_zeroed(&zero));
                                        filled_from = nl as i32;
                                    }
                                }
                                if count_of(&g) > 0 {
                                    break 'levels;
                                }
                            }
                        }
                    }
                    if count_of(&g) == 0 {
                        return Err(L3Error::Table(format!(
                            "class (position {pos}, level {l}, case {c}) has no samples at any level"
                        )));
                    }
                    let lv = geo.levels()[l] as f64;
                    // flat, unsaturated: unbiased on flat patches
                    let mut con_sums = None;
                    if c == 0
                        && t_src == 0
                        && use_maps
                        && let Some(mg) = maps[l].as_mut()
                        && mg.count() >= 50
                        && let Ok(ms) = solve(mg, RidgeChoice::Fixed { relative: 1e-9 }, 0.0)
                    {
                        let w = nch + 1;
                        con_sums = Some((
                            [0, 1, 2].map(|k| ms.kernel[k * w..k * w + nch].to_vec()),
                            [0, 1, 2].map(|k| ms.kernel[k * w + nch]),
                        ));
                    }
                    let con = con_sums.map(|(sums, intercept)| ChannelSumConstraint {
                        channel_of: geo.channels_of(pos),
                        n_channels: nch,
                        sums,
                        intercept,
                    });
                    let sol = solve_with(&mut g, params.ridge, noise.variance(lv), con.as_ref())
                        .map_err(|e| {
                            L3Error::Table(format!(
                                "class (position {pos}, level {l}, case {c}, texture {t}): {e}"
                            ))
                        })?;
                    let norm = sol.kernel.iter().map(|v| v * v).sum::<f64>().sqrt();
                    for (dst, src) in kernels[k * 3 * nf..(k + 1) * 3 * nf]
                        .iter_mut()
                        .zip(&sol.kernel)
                    {
                        *dst = *src as f32;
                    }
                    reports.push(ClassReport {
                        samples: raw_counts[own],
                        lambda: sol.lambda,
                        condition: sol.condition,
                        kernel_norm: norm,
                        filled_from,
                    });
                }
            }
        }
    }
    if params.ridge == RidgeChoice::NoiseVariance && noise.conversion_gain_v <= 0.0 {
        return Err(L3Error::InvalidParams(
            "noise-variance ridge needs a noise model".into(),
        ));
    }
    (ctl.progress)("done", 1.0);
    Ok(Learned {
        kernels,
        contrast_thresholds: thresholds,
        reports,
        sat_cases,
        samples,
    })
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

/// Mean target XYZ over the patch window centred on (r, c) (mirrored borders).
fn patch_mean_xyz(geo: &PatchGeometry, f: &TrainingFrame, r: usize, c: usize) -> [f32; 3] {
    let rad = geo.radius as isize;
    let mut s = [0f32; 3];
    for dy in -rad..=rad {
        let rr = super::classify::mirror(r as isize + dy, f.height);
        for dx in -rad..=rad {
            let cc = super::classify::mirror(c as isize + dx, f.width);
            let o = (rr * f.width + cc) * 3;
            for k in 0..3 {
                s[k] += f.xyz[o + k];
            }
        }
    }
    let n = (geo.size * geo.size) as f32;
    s.map(|v| v / n)
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
