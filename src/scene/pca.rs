//! Principal components of a set of spectra (f64, nalgebra symmetric eigen).

use nalgebra::{DMatrix, SymmetricEigen};

use super::SceneError;

/// Mean and leading principal components of a sample set.
#[derive(Clone, Debug)]
pub(crate) struct Pca {
    pub mean: Vec<f64>,
    /// `k` unit-length components, each of the data's dimension, by
    /// decreasing variance. Signs are fixed: each component sums to a
    /// non-negative value (or, if it sums to ~0, its largest entry is positive).
    pub components: Vec<Vec<f64>>,
}

impl Pca {
    /// PCA of `data` (rows are samples, all of one length) keeping `k` components.
    pub fn fit(data: &[Vec<f64>], k: usize) -> Result<Self, SceneError> {
        let n = data.len();
        let d = data.first().map_or(0, Vec::len);
        if n < 2 || d == 0 || data.iter().any(|r| r.len() != d) {
            return Err(SceneError::Invalid(format!(
                "PCA needs at least two samples of one length ({n} samples)"
            )));
        }
        if k == 0 || k > d {
            return Err(SceneError::Invalid(format!(
                "cannot keep {k} principal components of {d}-dimensional data"
            )));
        }
        let mut mean = vec![0.0; d];
        for r in data {
            for (m, v) in mean.iter_mut().zip(r) {
                *m += v;
            }
        }
        mean.iter_mut().for_each(|m| *m /= n as f64);
        let mut cov = DMatrix::<f64>::zeros(d, d);
        let mut centred = vec![0.0; d];
        for r in data {
            for ((c, v), m) in centred.iter_mut().zip(r).zip(&mean) {
                *c = v - m;
            }
            for i in 0..d {
                for j in i..d {
                    cov[(i, j)] += centred[i] * centred[j];
                }
            }
        }
        for i in 0..d {
            for j in i..d {
                let v = cov[(i, j)] / (n - 1) as f64;
                cov[(i, j)] = v;
                cov[(j, i)] = v;
            }
        }
        if cov.iter().any(|v| !v.is_finite()) {
            return Err(SceneError::Invalid("PCA input is not finite".into()));
        }
        let eig = SymmetricEigen::new(cov);
        let mut order: Vec<usize> = (0..d).collect();
        order.sort_by(|&a, &b| {
            eig.eigenvalues[b]
                .total_cmp(&eig.eigenvalues[a])
                .then(a.cmp(&b))
        });
        let mut components = Vec::with_capacity(k);
        for &j in order.iter().take(k) {
            let mut c: Vec<f64> = eig.eigenvectors.column(j).iter().copied().collect();
            let sum: f64 = c.iter().sum();
            let flip = if sum.abs() > 1e-9 {
                sum < 0.0
            } else {
                let big = c
                    .iter()
                    .copied()
                    .fold(0.0f64, |a, v| if v.abs() > a.abs() { v } else { a });
                big < 0.0
            };
            if flip {
                c.iter_mut().for_each(|v| *v = -*v);
            }
            components.push(c);
        }
        Ok(Self { mean, components })
    }

    /// Component weights of a sample: `cᵢ · (x − mean)`.
    pub fn weights(&self, x: &[f64]) -> Vec<f64> {
        self.components
            .iter()
            .map(|c| {
                c.iter()
                    .zip(x)
                    .zip(&self.mean)
                    .map(|((c, x), m)| c * (x - m))
                    .sum()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_the_main_axis() {
        // Points along (1, 2, 0)/√5 with a little spread along z.
        let data: Vec<Vec<f64>> = (0..50)
            .map(|i| {
                let t = i as f64 - 25.0;
                vec![1.0 + t, 2.0 + 2.0 * t, 0.01 * ((i % 3) as f64 - 1.0)]
            })
            .collect();
        let p = Pca::fit(&data, 2).unwrap();
        let c = &p.components[0];
        let s5 = 5f64.sqrt();
        assert!(
            (c[0] - 1.0 / s5).abs() < 1e-9 && (c[1] - 2.0 / s5).abs() < 1e-9,
            "{c:?}"
        );
        let c2 = &p.components[1];
        assert!(c2[2].abs() > 0.99, "second axis is z: {c2:?}");
        let w = p.weights(&data[0]);
        assert!((w[0] + 24.5 * s5).abs() < 1e-6, "{w:?}");
        assert!(Pca::fit(&data[..1], 1).is_err());
        assert!(Pca::fit(&data, 4).is_err());
    }
}
