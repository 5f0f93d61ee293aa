//! The conventional pipeline L3 is compared with: bilinear demosaicking
//! followed by a least-squares colour matrix (channels → XYZ), and T.

use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::camera::Cfa;
use crate::l3::classify::mirror;

/// Errors of the conventional pipeline: a colour matrix that cannot be fitted, a frame it
/// cannot render.
#[derive(Debug, thiserror::Error)]
pub enum BaselineError {
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// A colour matrix fit whose normal equations are singular.
    #[error("table is not usable: {0}")]
    Singular(String),
}

/// A least-squares colour matrix: XYZ = M · channels.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColourMatrix {
    /// `m[k][c]`: weight of channel c for output k.
    pub m: Vec<[f64; 3]>,
    pub n_channels: usize,
}

impl ColourMatrix {
    /// Fit by least squares from (channel responses, XYZ) pairs.
    pub fn fit(channels: &[Vec<f64>], xyz: &[[f64; 3]]) -> Result<Self, BaselineError> {
        let n = channels.len();
        let nc = channels.first().map(|c| c.len()).unwrap_or(0);
        if n < nc.max(3) || n != xyz.len() || nc == 0 || channels.iter().any(|c| c.len() != nc) {
            return Err(BaselineError::InvalidParams(format!(
                "colour matrix fit needs at least {} consistent samples, got {n}",
                nc.max(3)
            )));
        }
        let a = DMatrix::from_fn(n, nc, |i, j| channels[i][j]);
        let b = DMatrix::from_fn(n, 3, |i, k| xyz[i][k]);
        let ata = a.transpose() * &a;
        let atb = a.transpose() * &b;
        let sol = ata
            .cholesky()
            .map(|c| c.solve(&atb))
            .ok_or_else(|| BaselineError::Singular("colour matrix fit is singular".into()))?;
        let m = (0..nc)
            .map(|c| [sol[(c, 0)], sol[(c, 1)], sol[(c, 2)]])
            .collect();
        Ok(Self { m, n_channels: nc })
    }

    /// The matrix followed by `t` (T·M).
    pub fn then(&self, t: &[[f64; 3]; 3]) -> Self {
        let m = self
            .m
            .iter()
            .map(|col| [0, 1, 2].map(|i| (0..3).map(|k| t[i][k] * col[k]).sum()))
            .collect();
        Self {
            m,
            n_channels: self.n_channels,
        }
    }
}

/// Bilinear demosaicking: each missing channel is the mean of that
/// channel's pixels in the 3×3 neighbourhood (5×5 if none), borders mirrored.
/// Returns `width × height × n_channels`, interleaved.
pub fn bilinear_demosaic(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
) -> Result<Vec<f32>, BaselineError> {
    if width == 0 || height == 0 || volts.len() != width * height {
        return Err(BaselineError::InvalidInput(format!(
            "{} values for a {width}×{height} frame",
            volts.len()
        )));
    }
    let nc = cfa.n_channels();
    let mut out = vec![0f32; width * height * nc];
    out.par_chunks_mut(width * nc)
        .enumerate()
        .for_each(|(r, row)| {
            for c in 0..width {
                let own = cfa.channel_at(r, c);
                for ch in 0..nc {
                    let v = if ch == own {
                        volts[r * width + c]
                    } else {
                        let mut got = None;
                        for rad in [1isize, 2] {
                            let (mut s, mut n) = (0f32, 0u32);
                            for dy in -rad..=rad {
                                for dx in -rad..=rad {
                                    let rr = r as isize + dy;
                                    let cc = c as isize + dx;
                                    // the CFA phase of the true neighbour decides the channel
                                    if cfa.channel_at(
                                        rr.rem_euclid(2 * cfa.rows as isize) as usize,
                                        cc.rem_euclid(2 * cfa.cols as isize) as usize,
                                    ) == ch
                                    {
                                        s += volts[mirror(rr, height) * width + mirror(cc, width)];
                                        n += 1;
                                    }
                                }
                            }
                            if n > 0 {
                                got = Some(s / n as f32);
                                break;
                            }
                        }
                        got.unwrap_or(0.0)
                    };
                    row[c * nc + ch] = v;
                }
            }
        });
    Ok(out)
}

/// Render with the baseline: demosaic, then XYZ = M · channels.
pub fn render_baseline(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
    m: &ColourMatrix,
) -> Result<Vec<f32>, BaselineError> {
    let nc = cfa.n_channels();
    if m.n_channels != nc {
        return Err(BaselineError::InvalidInput(format!(
            "colour matrix has {} channels, the CFA {nc}",
            m.n_channels
        )));
    }
    let dm = bilinear_demosaic(volts, width, height, cfa)?;
    let mut out = vec![0f32; width * height * 3];
    out.par_chunks_mut(3)
        .zip(dm.par_chunks(nc))
        .for_each(|(o, ch)| {
            for k in 0..3 {
                o[k] = (0..nc).map(|c| m.m[c][k] * ch[c] as f64).sum::<f64>() as f32;
            }
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demosaic_of_a_flat_field_is_flat_and_fit_recovers_a_matrix() {
        let cfa = Cfa::parse("RG/WB").unwrap();
        let vals = [0.2f32, 0.4, 0.3, 0.9];
        let (w, h) = (7, 5);
        let v: Vec<f32> = (0..w * h)
            .map(|i| vals[cfa.channel_at(i / w, i % w)])
            .collect();
        let dm = bilinear_demosaic(&v, w, h, &cfa).unwrap();
        for px in dm.chunks_exact(4) {
            for ch in 0..4 {
                assert!((px[ch] - vals[ch]).abs() < 1e-6);
            }
        }
        let truth = [
            [0.5, 0.1, 0.0],
            [0.2, 0.8, 0.1],
            [0.0, 0.1, 0.9],
            [0.1, 0.1, 0.1],
        ];
        let chans: Vec<Vec<f64>> = (0..20)
            .map(|i| {
                (0..4)
                    .map(|c| ((i * 7 + c * 3) % 11) as f64 / 11.0 + c as f64 * 0.01)
                    .collect()
            })
            .collect();
        let xyz: Vec<[f64; 3]> = chans
            .iter()
            .map(|ch| [0, 1, 2].map(|k| (0..4).map(|c| truth[c][k] * ch[c]).sum()))
            .collect();
        let m = ColourMatrix::fit(&chans, &xyz).unwrap();
        for c in 0..4 {
            for k in 0..3 {
                assert!((m.m[c][k] - truth[c][k]).abs() < 1e-9);
            }
        }
        assert!(ColourMatrix::fit(&chans[..2], &xyz[..2]).is_err());
        let out = render_baseline(&v, w, h, &cfa, &m).unwrap();
        assert_eq!(out.len(), w * h * 3);
    }
}
