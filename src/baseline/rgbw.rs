//! Gradient-corrected bilinear demosaicking for any CFA with a tile of at most 2×2 (RGBW
//! `RG/WB` and its phases, Bayer, CYGM-like 2×2 layouts): Malvar–He–Cutler's idea
//! generalised.
//!
//! Every missing channel k at a pixel of channel s is the mean of k's samples in the 3×3
//! neighbourhood (bilinear), corrected by the second derivatives of s measured on s's own
//! lattice (period 2 in both directions for a 2×2 tile):
//!
//! `k = mean_k + gain · ρ · (a_xx·Lx + a_yy·Ly) / (2n)`,
//!
//! with `Lx = s(0) − (s(−2,0) + s(2,0))/2` and `Ly` likewise vertically, `n` the number of k's
//! samples and `a_xx`, `a_yy` the curvature each of them carries (a horizontal pair 1 and 0, a
//! diagonal quad 2 and 2): with `gain = 1` the correction cancels the bias bilinear
//! interpolation has on a quadratic signal shared by the channels. `ρ` is the local ratio of
//! k's mean to s's (clamped to [0, 4]): RGBW channels differ in scale (W sees about as much as
//! R, G and B together), and a colour's curvature scales with its level (constant hue).
//! Malvar's Bayer kernels are this with gain 2 (G at R or B) and 1.5 (R at B), ρ = 1, and a
//! quincunx Laplacian for G's own lattice.
//!
//! **Choice** (measured on the simulated Natural-100 chart, docs/accuracy.md "Strong ISP
//! baseline"): residual interpolation guided by W needs W denser than the colours, which the
//! 2×2 RGBW tile (one W in four) does not give; the gradient correction uses every channel's own
//! lattice and works for any 2×2 tile. [`DEFAULT_GRADIENT_GAIN`] is the gain that measured best.
//! Larger tiles fall back to [`super::bilinear_demosaic`].

use rayon::prelude::*;

use super::{BaselineError, Taps, Window5, bilinear_demosaic, check_frame};
use crate::camera::Cfa;

/// The gradient gain the ISP uses (see the module doc).
pub const DEFAULT_GRADIENT_GAIN: f32 = 1.0;

/// How one channel is estimated at one tile position: the pixel's own value, or the mean of
/// the neighbour groups that hold the channel (the horizontal pair, the vertical pair, the
/// diagonal quad; `n` samples in all) corrected by the curvatures.
#[derive(Clone, Copy, Default)]
struct Plan {
    own: bool,
    h: bool,
    v: bool,
    d: bool,
    n: f32,
    cxx: f32,
    cyy: f32,
}

/// Whether `cfa` has a tile [`gradient_demosaic`] handles (at most 2×2).
pub fn gradient_handles(cfa: &Cfa) -> bool {
    cfa.rows <= 2 && cfa.cols <= 2
}

/// The plans of tile position `(pr, pc)` for every channel.
fn plans(cfa: &Cfa, pr: usize, pc: usize) -> Vec<Plan> {
    let own = cfa.channel_at(pr, pc);
    let h = cfa.channel_at(pr, pc + 1);
    let v = cfa.channel_at(pr + 1, pc);
    let d = cfa.channel_at(pr + 1, pc + 1);
    (0..cfa.n_channels())
        .map(|k| {
            if k == own {
                return Plan {
                    own: true,
                    ..Plan::default()
                };
            }
            let (h, v, d) = (h == k, v == k, d == k);
            // each group's samples and the curvature they carry: a horizontal pair 1 along
            // x, a vertical pair 1 along y, a diagonal quad 2 and 2
            let n = (2 * h as usize + 2 * v as usize + 4 * d as usize).max(1) as f32;
            let axx = h as u8 as f32 + 2.0 * d as u8 as f32;
            let ayy = v as u8 as f32 + 2.0 * d as u8 as f32;
            Plan {
                own: false,
                h,
                v,
                d,
                n,
                cxx: axx / (2.0 * n),
                cyy: ayy / (2.0 * n),
            }
        })
        .collect()
}

/// Gradient-corrected bilinear demosaicking (module doc) with `gain` (0 is bilinear);
/// interleaved `width × height × n_channels`, border mirrored. CFAs with a tile larger than
/// 2×2 get [`bilinear_demosaic`].
pub fn gradient_demosaic(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
    gain: f32,
) -> Result<Vec<f32>, BaselineError> {
    check_frame(volts, width, height)?;
    if !gradient_handles(cfa) || !gain.is_finite() {
        return bilinear_demosaic(volts, width, height, cfa);
    }
    let nc = cfa.n_channels();
    let tile: Vec<Vec<Plan>> = (0..4).map(|i| plans(cfa, i / 2, i % 2)).collect();
    let mut out = vec![0f32; width * height * nc];
    out.par_chunks_mut(width * nc)
        .enumerate()
        .for_each(|(r, row)| {
            let win = Window5::new(volts, width, height, r);
            let plans = [&tile[(r % 2) * 2][..], &tile[(r % 2) * 2 + 1][..]];
            // the common channel counts as constants, so that the channel loop unrolls
            match nc {
                3 => demosaic_row::<3>(&win, plans, gain, row),
                4 => demosaic_row::<4>(&win, plans, gain, row),
                _ => demosaic_row::<0>(&win, plans, gain, row),
            }
        });
    Ok(out)
}

/// One row of [`gradient_demosaic`]: `plans` for the even and the odd columns, `NC` the
/// channel count (0: `plans`' length).
fn demosaic_row<const NC: usize>(win: &Window5, plans: [&[Plan]; 2], gain: f32, row: &mut [f32]) {
    let nc = if NC == 0 { plans[0].len() } else { NC };
    for (c, px) in row.chunks_exact_mut(nc).enumerate() {
        estimate(&win.taps(c), plans[c & 1], gain, px);
    }
}

/// A pixel's channels from its taps.
#[inline(always)]
fn estimate(t: &Taps, plans: &[Plan], gain: f32, px: &mut [f32]) {
    let (h2, v2) = (t.l2 + t.r2, t.u2 + t.d2);
    let lx = t.x - 0.5 * h2;
    let ly = t.x - 0.5 * v2;
    let own_mean = 0.5 * t.x + 0.125 * (h2 + v2);
    for (o, p) in px.iter_mut().zip(plans) {
        *o = if p.own {
            t.x
        } else {
            let mut s = 0f32;
            if p.h {
                s += t.l1;
                s += t.r1;
            }
            if p.v {
                s += t.u1;
                s += t.d1;
            }
            if p.d {
                s += t.ul;
                s += t.ur;
                s += t.dl;
                s += t.dr;
            }
            let mean = s / p.n;
            let rho = if own_mean > 0.0 {
                (mean / own_mean).clamp(0.0, 4.0)
            } else {
                1.0
            };
            mean + gain * rho * (p.cxx * lx + p.cyy * ly)
        };
    }
}
