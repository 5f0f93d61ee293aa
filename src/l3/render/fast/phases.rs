//! How a 2×2 CFA's phase sums become channel means and luminance.

use super::{LANES, PatchGeometry};

/// Position-free phase weights: `mean[p] = inv[p] · sum[p]`, `luminance = Σ lum[p] · sum[p]`.
#[derive(Clone, Copy, Debug)]
pub(super) struct UniformPhases {
    pub(super) inv: [f32; 4],
    pub(super) lum: [f32; 4],
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct PhaseMap {
    /// `mean[p] = Σ_q to_mean[p][q] · sum[q]` for phase p = 2·(row parity) + column parity.
    pub(super) to_mean: [[f32; 4]; 4],
    /// `luminance = Σ_q lum[q] · sum[q]`.
    pub(super) lum: [f32; 4],
}

/// For 2×2 CFAs: per centre position, how phase sums give channel means and luminance.
pub(super) fn phase_maps(geo: &PatchGeometry) -> Option<Vec<PhaseMap>> {
    if geo.cfa.rows != 2 || geo.cfa.cols != 2 || geo.size > LANES {
        return None;
    }
    let s = geo.size;
    let rad = geo.radius;
    // pixels per phase: offsets −rad..=rad with the same (0) or other (1) parity
    let n_even = (0..s).filter(|d| (d + rad).is_multiple_of(2)).count();
    let count = |p: usize| -> usize { if p == 0 { n_even } else { s - n_even } };
    let n_ch = geo.n_channels();
    let mut maps = Vec::with_capacity(4);
    for pos in 0..4 {
        let (pr, pc) = (pos / 2, pos % 2);
        let chan = |p: usize| geo.cfa.channel_at(pr + p / 2, pc + p % 2);
        let mut ch_count = vec![0usize; n_ch];
        for p in 0..4 {
            ch_count[chan(p)] += count(p / 2) * count(p % 2);
        }
        if ch_count.contains(&0) {
            return None;
        }
        let mut to_mean = [[0f32; 4]; 4];
        let mut lum = [0f32; 4];
        for p in 0..4 {
            for q in 0..4 {
                if chan(p) == chan(q) {
                    to_mean[p][q] = 1.0 / ch_count[chan(p)] as f32;
                }
            }
            lum[p] = 1.0 / (n_ch * ch_count[chan(p)]) as f32;
        }
        maps.push(PhaseMap { to_mean, lum });
    }
    Some(maps)
}

/// Per lane of a chunk of [`CHUNK`] columns, the phase map of the lane's CFA
/// position: a row's maps laid out so that the means of a whole chunk are
/// element-wise products, which vectorise (a map chosen per pixel does not).
pub(super) struct LaneMaps {
    pub(super) to_mean: [[[f32; CHUNK]; 4]; 4],
    pub(super) lum: [[f32; CHUNK]; 4],
}

/// Columns per [`LaneMaps`] chunk (the scratch rows are whole chunks long).
pub(super) const CHUNK: usize = 2 * LANES;

impl LaneMaps {
    /// The maps of row parity `rpar` for a chunk whose first column has parity `cpar`.
    pub(super) fn of_row(maps: &[PhaseMap], rpar: usize, cpar: usize) -> Self {
        let mut out = Self {
            to_mean: [[[0.0; CHUNK]; 4]; 4],
            lum: [[0.0; CHUNK]; 4],
        };
        for lane in 0..CHUNK {
            let Some(pm) = maps.get((rpar * 2 + (cpar + lane) % 2) % maps.len().max(1)) else {
                continue;
            };
            for p in 0..4 {
                out.lum[p][lane] = pm.lum[p];
                for q in 0..4 {
                    out.to_mean[p][q][lane] = pm.to_mean[p][q];
                }
            }
        }
        out
    }

    /// Means and luminance of the first `n` columns (a multiple of [`CHUNK`])
    /// from their phase sums, in the order of operations of a pixel at a time.
    #[inline(always)]
    pub(super) fn apply(
        &self,
        sums: &[Vec<f32>; 4],
        means: &mut [Vec<f32>; 4],
        lum: &mut [f32],
        n: usize,
    ) {
        for base in (0..n).step_by(CHUNK) {
            let q: [[f32; CHUNK]; 4] = std::array::from_fn(|k| {
                sums[k]
                    .get(base..base + CHUNK)
                    .and_then(|v| <[f32; CHUNK]>::try_from(v).ok())
                    .unwrap_or([0.0; CHUNK])
            });
            let mut l_sum = [0f32; CHUNK];
            for k in 0..4 {
                let t = &self.to_mean[k];
                let mut m = [0f32; CHUNK];
                for l in 0..CHUNK {
                    l_sum[l] += self.lum[k][l] * q[k][l];
                    m[l] = t[0][l] * q[0][l]
                        + t[1][l] * q[1][l]
                        + t[2][l] * q[2][l]
                        + t[3][l] * q[3][l];
                }
                if let Some(out) = means[k].get_mut(base..base + CHUNK) {
                    out.copy_from_slice(&m);
                }
            }
            if let Some(out) = lum.get_mut(base..base + CHUNK) {
                out.copy_from_slice(&l_sum);
            }
        }
    }
}

/// The position-free form of the phase maps, when there is one.
pub(super) fn uniform_phases(maps: &[PhaseMap]) -> Option<UniformPhases> {
    let first = maps.first()?;
    let diagonal = (0..4).all(|p| (0..4).all(|q| p == q || first.to_mean[p][q] == 0.0));
    if !diagonal || maps.iter().any(|m| m != first) {
        return None;
    }
    Some(UniformPhases {
        inv: [0, 1, 2, 3].map(|p| first.to_mean[p][p]),
        lum: first.lum,
    })
}
