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

use super::{BaselineError, bilinear_demosaic, check_frame, pad_mirrored};
use crate::camera::Cfa;

/// The gradient gain the ISP uses (see the module doc).
pub const DEFAULT_GRADIENT_GAIN: f32 = 1.0;

/// How one channel is estimated at one tile position.
#[derive(Clone, Copy, Default)]
struct Plan {
    own: bool,
    offsets: [(isize, isize); 8],
    n: usize,
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
            let mut p = Plan {
                own: k == own,
                ..Plan::default()
            };
            if p.own {
                return p;
            }
            let (mut axx, mut ayy) = (0f32, 0f32);
            let mut add = |offs: &[(isize, isize)], xx: f32, yy: f32| {
                for &o in offs {
                    p.offsets[p.n] = o;
                    p.n += 1;
                }
                axx += xx;
                ayy += yy;
            };
            if h == k {
                add(&[(0, -1), (0, 1)], 1.0, 0.0);
            }
            if v == k {
                add(&[(-1, 0), (1, 0)], 0.0, 1.0);
            }
            if d == k {
                add(&[(-1, -1), (-1, 1), (1, -1), (1, 1)], 2.0, 2.0);
            }
            let n = p.n.max(1) as f32;
            p.cxx = axx / (2.0 * n);
            p.cyy = ayy / (2.0 * n);
            p
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
    let pw = width + 4;
    let p = pad_mirrored(volts, width, height, 2);
    let mut out = vec![0f32; width * height * nc];
    out.par_chunks_mut(width * nc)
        .enumerate()
        .for_each(|(r, row)| {
            let base = (r + 2) * pw + 2;
            for (c, px) in row.chunks_exact_mut(nc).enumerate() {
                let at = |dy: isize, dx: isize| {
                    p[(base as isize + dy * pw as isize + c as isize + dx) as usize]
                };
                let x = at(0, 0);
                let (h2, v2) = (at(0, -2) + at(0, 2), at(-2, 0) + at(2, 0));
                let lx = x - 0.5 * h2;
                let ly = x - 0.5 * v2;
                let own_mean = 0.5 * x + 0.125 * (h2 + v2);
                for (k, plan) in tile[(r % 2) * 2 + c % 2].iter().enumerate() {
                    px[k] = if plan.own {
                        x
                    } else {
                        let s: f32 = plan.offsets[..plan.n]
                            .iter()
                            .map(|&(dy, dx)| at(dy, dx))
                            .sum();
                        let mean = s / plan.n.max(1) as f32;
                        let rho = if own_mean > 0.0 {
                            (mean / own_mean).clamp(0.0, 4.0)
                        } else {
                            1.0
                        };
                        mean + gain * rho * (plan.cxx * lx + plan.cyy * ly)
                    };
                }
            }
        });
    Ok(out)
}
