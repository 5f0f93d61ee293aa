//! Stages 3 and 4 of learning a table, on a run's merged normal equations: classes with
//! too few samples borrow from their neighbours ([`fill`]), then every class is solved by
//! ridge regression, the channel sums of its unsaturated kernels fixed to its level's colour
//! map ([`solve_classes`]); and the packaging of the result as a table.

use std::sync::atomic::Ordering;

use super::LearnError;
use super::normal_eq::{ChannelSumConstraint, ClassSolution, Gram, solve_with};
use super::setup::{ClassMaps, Dims, Learned, TrainControl, TrainSetup};
use super::shards::Classes;
use crate::baseline::ColourMatrix;
use crate::l3::classify::{MAX_CHANNELS, PatchGeometry, sat_case_index};
use crate::l3::correct::NoiseModel;
use crate::l3::params::L3Params;
use crate::l3::table::{ClassReport, L3Table, TableMeta};

/// Stages 3 and 4 on a run's merged normal equations
/// ([`super::shards::merge_partials`]): fill and solve every class.
pub fn solve_learned(
    setup: &TrainSetup,
    classes: Classes,
    grams: Vec<Gram>,
    ctl: &TrainControl,
) -> Result<Learned, LearnError> {
    setup.validate()?;
    let n_classes = setup.n_classes(&classes);
    let nf = setup.geo.n_features();
    if grams.len() != n_classes
        || grams.iter().any(|g| g.n_features() != nf)
        || classes.thresholds.len() != n_classes / 2
    {
        return Err(LearnError::PartialSums(format!(
            "{} class sums for {n_classes} classes",
            grams.len()
        )));
    }
    if ctl.cancel.load(Ordering::Relaxed) {
        return Err(LearnError::Canceled);
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

/// The class a fill is for: its CFA position, band and saturation case, and the contrast
/// class (0 flat, 1 texture) whose samples it takes.
#[derive(Clone, Copy)]
struct Slot {
    pos: usize,
    band: usize,
    case: usize,
    t_src: usize,
}

/// Stage 3: the samples a class is solved from, and the level they were
/// borrowed from (−1 for its own). A class with fewer than `need` samples
/// merges its neighbouring levels of its chroma class, nearest first
/// (`band` is level × chroma classes + chroma class); one with none at any level
/// takes the other contrast class; a saturation case this position never
/// saw borrows the case it falls back to, with this case's saturated
/// channels zeroed (exactly the features those samples would have here).
fn fill(
    geo: &PatchGeometry,
    d: &Dims,
    classes: &Classes,
    grams: &mut [Gram],
    slot: Slot,
    need: u64,
) -> (Gram, i32) {
    let Slot {
        pos,
        band,
        case: c,
        t_src,
    } = slot;
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
    colour_maps: Option<ClassMaps>,
) -> Result<(Vec<f32>, Vec<ClassReport>), LearnError> {
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
                    let slot = Slot {
                        pos,
                        band: l,
                        case: c,
                        t_src,
                    };
                    let (mut g, filled_from) = fill(geo, d, classes, &mut grams, slot, need);
                    if g.count() == 0 {
                        return Err(LearnError::Solve(format!(
                            "class (position {pos}, band {l}, case {c}) has no samples at any level"
                        )));
                    }
                    let level_v = geo.levels()[l / d.n_chroma.max(1)] as f64;
                    let con = match colour_maps {
                        Some(maps) if c == 0 => {
                            Some(colour_constraint(geo, pos, maps.at(l, t_src == 1)))
                        }
                        _ => None,
                    };
                    let sol =
                        solve_with(&mut g, params.ridge, noise.variance(level_v), con.as_ref())
                            .map_err(|e| {
                                LearnError::Solve(format!(
                                    "class (position {pos}, band {l}, case {c}, texture {t}): {e}"
                                ))
                            })?;
                    for (dst, src) in kernels[k * 3 * nf..(k + 1) * 3 * nf]
                        .iter_mut()
                        .zip(&sol.kernel)
                    {
                        *dst = *src as f32;
                    }
                    reports.push(class_report(
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
pub fn package(meta: TableMeta, learned: Learned) -> Result<L3Table, LearnError> {
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

/// The report of a solved class with `n_features` regressors (the last the constant) at a
/// level with per-pixel noise `sigma` volts.
fn class_report(
    samples: u64,
    filled_from: i32,
    sol: &ClassSolution,
    n_features: usize,
    sigma: f64,
) -> ClassReport {
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
    ClassReport {
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
