//! Malvar–He–Cutler demosaicking (Malvar, He and Cutler, *High-quality linear interpolation
//! for demosaicing of Bayer-patterned color images*, ICASSP 2004): bilinear interpolation
//! corrected by the Laplacian of the channel the pixel has, with the paper's 5×5 kernels
//! (weights in eighths). Any of the four Bayer phases.
//!
//! Written here rather than taken from a crate: no maintained Rust crate implements it on
//! `f32` volts with l3's mirrored border, and the kernels are a page. It agrees with
//! colour-demosaicing's `demosaicing_CFA_Bayer_Malvar2004` to float rounding away from a
//! 2-pixel border (`scripts/malvar_crosscheck.py`; that package reflects the border about
//! the edge pixel's outer side, l3 about the edge pixel itself).

use rayon::prelude::*;

use super::{BaselineError, Window5, check_frame};
use crate::camera::Cfa;

/// A Bayer CFA: a 2×2 tile of channels named R, G, G, B with the two G on a diagonal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BayerLayout {
    /// Channel indices of R, G and B in the CFA's numbering.
    pub r: usize,
    pub g: usize,
    pub b: usize,
    /// Tile position (row, column) of the R pixel.
    pub r_at: (usize, usize),
}

impl BayerLayout {
    /// The layout of `cfa` when it is a Bayer CFA (any of RGGB, GRBG, GBRG, BGGR).
    pub fn of(cfa: &Cfa) -> Option<Self> {
        if cfa.rows != 2 || cfa.cols != 2 || cfa.n_channels() != 3 {
            return None;
        }
        let (r, g, b) = (
            cfa.channel_index("R")?,
            cfa.channel_index("G")?,
            cfa.channel_index("B")?,
        );
        let at = |ch: usize| (0..4).find(|&i| cfa.pattern[i] == ch);
        let ri = at(r)?;
        let bi = at(b)?;
        // R and B on one diagonal, the two G on the other
        (ri + bi == 3 && cfa.pattern.iter().filter(|&&p| p == g).count() == 2).then_some(Self {
            r,
            g,
            b,
            r_at: (ri / 2, ri % 2),
        })
    }
}

/// What a pixel is, for the kernels.
#[derive(Clone, Copy)]
enum Site {
    R,
    B,
    /// G on a row with R pixels.
    GonR,
    /// G on a row with B pixels.
    GonB,
}

/// Malvar–He–Cutler demosaicking of a Bayer frame; interleaved `width × height × 3` in the
/// CFA's channel numbering, border mirrored. Errors when `cfa` is not Bayer
/// ([`BayerLayout::of`]) or the frame's size is wrong.
pub fn malvar_demosaic(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
) -> Result<Vec<f32>, BaselineError> {
    check_frame(volts, width, height)?;
    let lay = BayerLayout::of(cfa).ok_or_else(|| {
        BaselineError::InvalidParams(format!("Malvar demosaicking needs a Bayer CFA, not {cfa}"))
    })?;
    let site = |r: usize, c: usize| -> Site {
        let (rr, rc) = lay.r_at;
        match (r % 2 == rr, c % 2 == rc) {
            (true, true) => Site::R,
            (false, false) => Site::B,
            (true, false) => Site::GonR,
            (false, true) => Site::GonB,
        }
    };
    let mut out = vec![0f32; width * height * 3];
    out.par_chunks_mut(width * 3)
        .enumerate()
        .for_each(|(r, row)| {
            let sites = [site(r, 0), site(r, 1)];
            let win = Window5::new(volts, width, height, r);
            for (c, px) in row.chunks_exact_mut(3).enumerate() {
                let t = win.taps(c);
                let x = t.x;
                let h1 = t.l1 + t.r1;
                let v1 = t.u1 + t.d1;
                let h2 = t.l2 + t.r2;
                let v2 = t.u2 + t.d2;
                let dg = t.ul + t.ur + t.dl + t.dr;
                // G at R or B; R at B or B at R; the other colour at G (its row's, its column's)
                let g_at_rb = || (4.0 * x + 2.0 * (h1 + v1) - (h2 + v2)) * 0.125;
                let opp = || (6.0 * x + 2.0 * dg - 1.5 * (h2 + v2)) * 0.125;
                let along_row = || (5.0 * x + 4.0 * h1 - dg - h2 + 0.5 * v2) * 0.125;
                let along_col = || (5.0 * x + 4.0 * v1 - dg - v2 + 0.5 * h2) * 0.125;
                let (rv, gv, bv) = match sites[c & 1] {
                    Site::R => (x, g_at_rb(), opp()),
                    Site::B => (opp(), g_at_rb(), x),
                    Site::GonR => (along_row(), x, along_col()),
                    Site::GonB => (along_col(), x, along_row()),
                };
                px[lay.r] = rv;
                px[lay.g] = gv;
                px[lay.b] = bv;
            }
        });
    Ok(out)
}
