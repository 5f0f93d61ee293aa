//! The least-squares colour matrix (camera channels → XYZ) of the conventional pipelines.

use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::BaselineError;

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

    /// XYZ = M · channels for every pixel of an interleaved `n_channels` image; interleaved
    /// XYZ out. Errors when the image's channel count is not the matrix's or a value is not
    /// finite.
    pub fn apply(&self, channels: &[f32]) -> Result<Vec<f32>, BaselineError> {
        let nc = self.n_channels;
        if nc == 0 || !channels.len().is_multiple_of(nc) || self.m.len() != nc {
            return Err(BaselineError::InvalidInput(format!(
                "{} values are not whole pixels of {nc} channels",
                channels.len()
            )));
        }
        let m: Vec<[f32; 3]> = self.m.iter().map(|c| c.map(|v| v as f32)).collect();
        let mut out = vec![0f32; channels.len() / nc * 3];
        out.par_chunks_mut(3 * 4096)
            .zip(channels.par_chunks(nc * 4096))
            .for_each(|(o, ch)| {
                for (o, ch) in o.chunks_exact_mut(3).zip(ch.chunks_exact(nc)) {
                    let mut acc = [0f32; 3];
                    for (mc, &v) in m.iter().zip(ch) {
                        for k in 0..3 {
                            acc[k] += mc[k] * v;
                        }
                    }
                    o.copy_from_slice(&acc);
                }
            });
        if out.iter().any(|v| !v.is_finite()) {
            return Err(BaselineError::InvalidInput(
                "the colour matrix gives a non-finite value".into(),
            ));
        }
        Ok(out)
    }
}
