//! Streaming normal equations per class and their ridge (Wiener) solution.

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use ndarray::{Array2, ArrayView2, linalg::general_mat_mul, s};
use serde::{Deserialize, Serialize};

use super::LearnError;
use crate::l3::params::RidgeChoice;

const BATCH: usize = 64;

/// Accumulated `[x; y]ᵀ[x; y]` over samples, in f64, with samples buffered
/// and added in blocks (a rank-64 update is far faster than 64 rank-1 ones).
#[derive(Clone, Debug)]
pub struct Gram {
    n_features: usize,
    dim: usize,
    gram: Array2<f64>,
    buf: Array2<f64>,
    filled: usize,
    n: u64,
}

impl Gram {
    /// `n_features` regressors (including the constant) and 3 targets.
    pub fn new(n_features: usize) -> Self {
        let dim = n_features + 3;
        Self {
            n_features,
            dim,
            gram: Array2::zeros((dim, dim)),
            buf: Array2::zeros((BATCH, dim)),
            filled: 0,
            n: 0,
        }
    }

    pub fn n_features(&self) -> usize {
        self.n_features
    }

    /// Samples seen so far.
    pub fn count(&self) -> u64 {
        self.n + self.filled as u64
    }

    #[inline]
    pub fn push(&mut self, x: &[f32], y: [f32; 3]) {
        let mut row = self.buf.row_mut(self.filled);
        let row = row.as_slice_mut().unwrap_or(&mut []);
        for (d, &v) in row.iter_mut().zip(x) {
            *d = v as f64;
        }
        if row.len() == self.dim {
            row[self.n_features] = y[0] as f64;
            row[self.n_features + 1] = y[1] as f64;
            row[self.n_features + 2] = y[2] as f64;
        }
        self.filled += 1;
        if self.filled == BATCH {
            self.flush();
        }
    }

    /// Fold buffered samples into the Gram matrix.
    pub fn flush(&mut self) {
        if self.filled == 0 {
            return;
        }
        let b = self.buf.slice(s![..self.filled, ..]);
        general_mat_mul(1.0, &b.t(), &b, 1.0, &mut self.gram);
        self.n += self.filled as u64;
        self.filled = 0;
    }

    /// Add another accumulator's samples.
    pub fn merge(&mut self, other: &Gram) {
        let mut o = other.clone();
        o.flush();
        self.flush();
        self.gram += &o.gram;
        self.n += o.n;
    }

    /// Add another accumulator's samples, consuming it: the same sums as
    /// [`Gram::merge`] without the copy.
    pub fn merge_owned(&mut self, mut other: Gram) {
        other.flush();
        self.flush();
        self.gram += &other.gram;
        self.n += other.n;
    }

    /// The accumulated `[x; y]ᵀ[x; y]` (row-major, `dim × dim` with
    /// `dim = n_features + 3`) and sample count, when every sample has been
    /// folded in (after [`Gram::flush`]); `None` while samples are buffered.
    pub fn flushed_sums(&self) -> Option<(&[f64], u64)> {
        if self.filled != 0 {
            return None;
        }
        self.gram.as_slice().map(|m| (m, self.n))
    }

    /// The accumulator holding exactly the sums `matrix` (row-major,
    /// `(n_features + 3)²` values) over `n` samples, as
    /// [`Gram::flushed_sums`] gives them.
    pub fn from_sums(n_features: usize, matrix: Vec<f64>, n: u64) -> Result<Gram, LearnError> {
        let dim = n_features + 3;
        if n_features == 0 || matrix.len() != dim * dim {
            return Err(LearnError::InvalidInput(format!(
                "{} sums for {n_features} features",
                matrix.len()
            )));
        }
        let gram = Array2::from_shape_vec((dim, dim), matrix)
            .map_err(|e| LearnError::InvalidInput(format!("sums: {e}")))?;
        Ok(Self {
            n_features,
            dim,
            gram,
            buf: Array2::zeros((BATCH, dim)),
            filled: 0,
            n,
        })
    }

    /// The accumulated matrix (flushes first).
    pub fn matrix(&mut self) -> ArrayView2<'_, f64> {
        self.flush();
        self.gram.view()
    }

    /// The accumulator of the same samples with the regressors `idx` set to
    /// zero (how saturated pixels enter a kernel: with zero weight).
    pub fn with_zeroed(&mut self, idx: &[usize]) -> Gram {
        self.flush();
        let mut out = self.clone();
        for &k in idx {
            if k < self.n_features {
                out.gram.row_mut(k).fill(0.0);
                out.gram.column_mut(k).fill(0.0);
            }
        }
        out
    }

    /// Remap regressors: the accumulator of `x' = P x` where `x'_k = x_{map[k]}`.
    /// Used to average a class with its mirror images.
    pub fn permuted(&mut self, map: &[usize]) -> Gram {
        self.flush();
        let mut out = Gram::new(self.n_features);
        let idx = |k: usize| -> usize { if k < map.len() { map[k] } else { k } };
        for i in 0..self.dim {
            for j in 0..self.dim {
                out.gram[[i, j]] = self.gram[[idx(i), idx(j)]];
            }
        }
        out.n = self.n;
        out
    }
}

/// The solved affine kernel of one class.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ClassSolution {
    /// `kernel[k * n_features + j]`: weight of feature j for output k (X, Y, Z).
    pub kernel: Vec<f64>,
    pub lambda: f64,
    /// Condition number of the centred covariance of the active regressors
    /// (largest / smallest eigenvalue; 1 when none is active).
    pub condition: f64,
    /// Regressors (patch pixels) with non-zero variance.
    pub active: usize,
    /// Eigenvalues above 1e-12 of the largest.
    pub rank: usize,
    pub samples: u64,
    /// Mean squared training residual per output at the chosen λ.
    pub rss_per_sample: f64,
}

/// A linear equality constraint on a kernel: for each output k and each
/// channel c, the weights of the patch pixels of channel c sum to
/// `sums[k][c]` — the kernel then maps a flat patch exactly as the colour
/// map `sums` (plus its intercept) does, whatever it does spatially.
#[derive(Clone, Debug)]
pub struct ChannelSumConstraint<'a> {
    /// Channel of each patch pixel (the non-constant regressors).
    pub channel_of: &'a [u8],
    pub n_channels: usize,
    /// `sums[k][c]`: required weight sum of channel c for output k.
    pub sums: [Vec<f64>; 3],
    /// Required intercept per output.
    pub intercept: [f64; 3],
}

/// Solve ridge regression from a Gram matrix whose last regressor is the
/// constant 1. The constant is not penalised: the problem is centred first.
pub fn solve(
    gram: &mut Gram,
    ridge: RidgeChoice,
    noise_var: f64,
) -> Result<ClassSolution, LearnError> {
    solve_with(gram, ridge, noise_var, None)
}

/// Eigenvalues and eigenvectors (columns) of the symmetric matrix `m`.
/// nalgebra's symmetric QR iteration returns NaN on some finite covariance
/// matrices (met on a noise-free Bayer class whose saturated channels'
/// regressors are all but constant); the SVD, which for a symmetric
/// positive semi-definite matrix gives the same decomposition, is the
/// fallback.
fn symmetric_eigen(m: &DMatrix<f64>) -> Result<(DVector<f64>, DMatrix<f64>), LearnError> {
    let finite = |v: &DVector<f64>, u: &DMatrix<f64>| {
        v.iter().all(|x| x.is_finite()) && u.iter().all(|x| x.is_finite())
    };
    let eig = SymmetricEigen::new(m.clone());
    if finite(&eig.eigenvalues, &eig.eigenvectors) {
        return Ok((eig.eigenvalues, eig.eigenvectors));
    }
    svd_eigen(m).filter(|(v, u)| finite(v, u)).ok_or_else(|| {
        LearnError::Solve("the class's covariance has no finite eigendecomposition".into())
    })
}

/// The eigendecomposition of a symmetric positive semi-definite `m` from
/// its SVD (`m = U Σ Uᵀ`).
fn svd_eigen(m: &DMatrix<f64>) -> Option<(DVector<f64>, DMatrix<f64>)> {
    let svd = m.clone().svd(true, false);
    Some((svd.singular_values, svd.u?))
}

/// [`solve`], optionally subject to a [`ChannelSumConstraint`] (the ridge λ
/// is still chosen on the unconstrained problem).
pub fn solve_with(
    gram: &mut Gram,
    ridge: RidgeChoice,
    noise_var: f64,
    constraint: Option<&ChannelSumConstraint>,
) -> Result<ClassSolution, LearnError> {
    let nf = gram.n_features();
    let n = gram.count();
    if n == 0 {
        return Err(LearnError::Solve("class has no samples".into()));
    }
    let g = gram.matrix();
    let p = nf - 1; // non-constant regressors
    let nn = n as f64;
    let mx: Vec<f64> = (0..p).map(|i| g[[p, i]] / nn).collect();
    let my: [f64; 3] = [0, 1, 2].map(|k| g[[p, nf + k]] / nn);
    let cxx = DMatrix::from_fn(p, p, |i, j| g[[i, j]] / nn - mx[i] * mx[j]);
    let cxy = DMatrix::from_fn(p, 3, |i, k| g[[i, nf + k]] / nn - mx[i] * my[k]);
    let cyy: f64 = (0..3)
        .map(|k| g[[nf + k, nf + k]] / nn - my[k] * my[k])
        .sum();
    if !(cxx.iter().all(|v| v.is_finite()) && cxy.iter().all(|v| v.is_finite())) {
        return Err(LearnError::Solve("non-finite normal equations".into()));
    }
    let (raw_evals, vecs) = symmetric_eigen(&cxx)?;
    let evals: Vec<f64> = raw_evals.iter().map(|&e| e.max(0.0)).collect();
    let emax = evals.iter().copied().fold(0.0, f64::max);
    let emin = evals.iter().copied().fold(f64::INFINITY, f64::min);
    let mean_e = (evals.iter().sum::<f64>() / p as f64).max(f64::MIN_POSITIVE);
    // Regressors with no variance (zeroed saturated channels, a constant
    // patch) add exact zero eigenvalues: the condition number is that of the
    // active regressors, and the rank counts directions above 1e-12 of the
    // largest.
    let active = (0..p).filter(|&i| cxx[(i, i)] > 0.0).count();
    let mut sorted = evals.clone();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let rank = sorted.iter().filter(|&&e| e > emax * 1e-12).count();
    let condition = if active == 0 || emax <= 0.0 {
        1.0
    } else {
        emax / sorted[active - 1].max(emax * 1e-16)
    };
    let q = vecs.transpose() * &cxy; // p × 3
    let qn: Vec<f64> = (0..p)
        .map(|i| (0..3).map(|k| q[(i, k)].powi(2)).sum())
        .collect();
    let rss = |lam: f64| -> f64 {
        let mut r = cyy;
        for i in 0..p {
            let d = evals[i] + lam;
            if d > 0.0 {
                r -= qn[i] * (evals[i] + 2.0 * lam) / (d * d);
            }
        }
        r.max(0.0)
    };
    let lambda = choose_lambda(ridge, noise_var, &evals, mean_e, nn, &rss);
    // w = V diag(1/(e+λ)) q
    let mut scaled = q.clone();
    for i in 0..p {
        let d = 1.0 / (evals[i] + lambda);
        for k in 0..3 {
            scaled[(i, k)] *= d;
        }
    }
    let mut w = &vecs * scaled; // p × 3
    let intercept = match constraint {
        Some(con) if con.channel_of.len() == p => constrain(con, &vecs, &evals, lambda, &mut w),
        _ => None,
    };
    let mut kernel = vec![0.0; 3 * nf];
    for k in 0..3 {
        let mut b = my[k];
        for i in 0..p {
            kernel[k * nf + i] = w[(i, k)];
            b -= w[(i, k)] * mx[i];
        }
        kernel[k * nf + p] = intercept.map(|c| c[k]).unwrap_or(b);
    }
    if kernel.iter().any(|v| !v.is_finite()) {
        return Err(LearnError::Solve(format!(
            "non-finite kernel ({n} samples, λ {lambda:.3e}, eigenvalues {emin:.3e}–{emax:.3e})"
        )));
    }
    Ok(ClassSolution {
        kernel,
        lambda,
        condition,
        active,
        rank,
        samples: n,
        rss_per_sample: rss(lambda) / 3.0,
    })
}

/// The ridge λ of a class whose centred covariance has eigenvalues `evals` (their mean
/// `mean_e`), over `nn` samples, as `ridge` says (GCV scores the residual `rss(λ)`).
fn choose_lambda(
    ridge: RidgeChoice,
    noise_var: f64,
    evals: &[f64],
    mean_e: f64,
    nn: f64,
    rss: &dyn Fn(f64) -> f64,
) -> f64 {
    // a floor keeps rank-deficient classes (e.g. zeroed saturated channels) solvable
    let floor = (mean_e * 1e-9).max(1e-24);
    match ridge {
        RidgeChoice::Fixed { relative } => (relative * mean_e).max(floor),
        RidgeChoice::NoiseVariance => noise_var.max(floor),
        RidgeChoice::Gcv => {
            let mut best = (f64::INFINITY, floor);
            for i in 0..=48 {
                let lam = mean_e * 10f64.powf(-9.0 + i as f64 * 0.25);
                let df: f64 = evals.iter().map(|&e| e / (e + lam)).sum::<f64>() + 1.0;
                let denom = (1.0 - df / nn).max(1e-12);
                let score = rss(lam) / (denom * denom);
                if score < best.0 {
                    best = (score, lam);
                }
            }
            best.1
        }
    }
    .max(floor)
}

/// The ridge solution `w` (p × 3, `w = H⁻¹ cxy`) moved onto the constraint `con`, and the
/// intercept the constraint fixes; `None` (and `w` unchanged) when the constraint's
/// system is singular. `H = V diag(e+λ) Vᵀ` from the eigenvectors `vecs` and eigenvalues
/// `evals` of the centred covariance.
fn constrain(
    con: &ChannelSumConstraint,
    vecs: &DMatrix<f64>,
    evals: &[f64],
    lambda: f64,
    w: &mut DMatrix<f64>,
) -> Option<[f64; 3]> {
    let p = evals.len();
    // KKT: w = H⁻¹(cxy − Aᵀν), ν = (A H⁻¹ Aᵀ)⁻¹ (A H⁻¹ cxy − m),
    // with H = V diag(e+λ) Vᵀ and A the channel-membership matrix.
    let nc = con.n_channels;
    let present: Vec<usize> = (0..nc)
        .filter(|&c| con.channel_of.iter().any(|&x| x as usize == c))
        .collect();
    let a = DMatrix::from_fn(present.len(), p, |r, j| {
        (con.channel_of[j] as usize == present[r]) as u8 as f64
    });
    let hinv = {
        let mut d = vecs.clone();
        for j in 0..p {
            let f = 1.0 / (evals[j] + lambda);
            for i in 0..p {
                d[(i, j)] *= f;
            }
        }
        d * vecs.transpose()
    };
    let ahinv = &a * &hinv; // nc × p
    let s_mat = &ahinv * a.transpose(); // nc × nc
    let s_inv = s_mat.try_inverse()?;
    for k in 0..3 {
        let m = nalgebra::DVector::from_fn(present.len(), |r, _| {
            con.sums[k].get(present[r]).copied().unwrap_or(0.0)
        });
        let wk = w.column(k).into_owned(); // = H⁻¹ cxy
        let nu = &s_inv * (&a * &wk - m);
        let corr = &hinv * (a.transpose() * nu);
        w.set_column(k, &(wk - corr));
    }
    Some(con.intercept)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn both_eigendecompositions_rebuild_a_singular_covariance() {
        // a covariance with a constant (zeroed) regressor, as saturated
        // channels give: one exact zero row and column
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x = DMatrix::from_fn(40, 6, |_, j| {
            if j == 2 {
                0.0
            } else {
                rng.random_range(-1.0..1.0)
            }
        });
        let m = x.transpose() * &x / 40.0;
        let svd = svd_eigen(&m).unwrap();
        for (vals, vecs) in [symmetric_eigen(&m).unwrap(), svd] {
            let back = &vecs * DMatrix::from_diagonal(&vals) * vecs.transpose();
            assert!((back - &m).abs().max() < 1e-12);
            assert!(vals.iter().all(|&v| v > -1e-12));
            assert_eq!(vals.iter().filter(|v| v.abs() < 1e-12).count(), 1);
        }
    }

    #[test]
    fn recovers_an_affine_map() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let truth = [
            [0.5, -0.2, 0.1, 0.05],
            [0.1, 0.7, -0.3, -0.02],
            [0.0, 0.2, 0.9, 0.3],
        ];
        let mut g = Gram::new(4);
        for _ in 0..1000 {
            let x = [
                rng.random::<f32>(),
                rng.random::<f32>(),
                rng.random::<f32>(),
                1.0,
            ];
            let y = truth.map(|t| (0..4).map(|j| t[j] * x[j] as f64).sum::<f64>() as f32);
            g.push(&x, y);
        }
        for ridge in [RidgeChoice::Gcv, RidgeChoice::Fixed { relative: 0.0 }] {
            let s = solve(&mut g, ridge, 0.0).unwrap();
            for k in 0..3 {
                for j in 0..4 {
                    assert!(
                        (s.kernel[k * 4 + j] - truth[k][j]).abs() < 1e-4,
                        "{ridge:?}"
                    );
                }
            }
            assert_eq!(s.samples, 1000);
        }
    }

    #[test]
    fn collinear_and_constant_regressors_stay_finite() {
        let mut g = Gram::new(4);
        for i in 0..50 {
            let v = i as f32 * 0.01;
            g.push(&[v, v, 0.0, 1.0], [v, 2.0 * v, 0.5]);
        }
        let s = solve(&mut g, RidgeChoice::Gcv, 0.0).unwrap();
        assert!(s.kernel.iter().all(|v| v.is_finite()));
        assert!(s.condition > 1e6);
        assert_eq!((s.active, s.rank), (2, 1));
        // all regressors constant (a fully saturated, zeroed class)
        let mut z = Gram::new(4);
        for _ in 0..30 {
            z.push(&[0.0, 0.0, 0.0, 1.0], [0.3, 0.2, 0.1]);
        }
        let s = solve(&mut z, RidgeChoice::Gcv, 0.0).unwrap();
        assert!(s.kernel.iter().all(|v| v.is_finite()));
        assert!((s.kernel[3] - 0.3).abs() < 1e-6);
        // the zero regressor gets zero weight
        assert!(s.kernel[2].abs() < 1e-9);
        let mut e = Gram::new(4);
        assert!(solve(&mut e, RidgeChoice::Gcv, 0.0).is_err());
    }

    #[test]
    fn channel_sum_constraint_is_met() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut g = Gram::new(5);
        for _ in 0..2000 {
            let base = rng.random::<f32>();
            let x = [
                base + 0.1 * rng.random::<f32>(),
                base + 0.1 * rng.random::<f32>(),
                0.5 * base + 0.1 * rng.random::<f32>(),
                0.5 * base + 0.1 * rng.random::<f32>(),
                1.0,
            ];
            g.push(&x, [base, 0.5 * base, 0.2]);
        }
        let con = ChannelSumConstraint {
            channel_of: &[0, 0, 1, 1],
            n_channels: 2,
            sums: [vec![0.7, 0.6], vec![0.5, 0.0], vec![0.0, 0.0]],
            intercept: [0.01, 0.0, 0.2],
        };
        let s = solve_with(&mut g, RidgeChoice::Gcv, 0.0, Some(&con)).unwrap();
        for k in 0..3 {
            let c0 = s.kernel[k * 5] + s.kernel[k * 5 + 1];
            let c1 = s.kernel[k * 5 + 2] + s.kernel[k * 5 + 3];
            assert!((c0 - con.sums[k][0]).abs() < 1e-9, "{k} {c0}");
            assert!((c1 - con.sums[k][1]).abs() < 1e-9);
            assert_eq!(s.kernel[k * 5 + 4], con.intercept[k]);
        }
    }

    #[test]
    fn merge_equals_single_stream() {
        let mut a = Gram::new(3);
        let mut b = Gram::new(3);
        let mut all = Gram::new(3);
        for i in 0..200 {
            let x = [i as f32, (i * i % 7) as f32, 1.0];
            let y = [1.0, i as f32, 0.0];
            all.push(&x, y);
            if i % 2 == 0 {
                a.push(&x, y)
            } else {
                b.push(&x, y)
            }
        }
        a.merge(&b);
        assert_eq!(a.count(), 200);
        assert_eq!(a.matrix(), all.matrix());
    }
}
