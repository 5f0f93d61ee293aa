//! Camera-aware illuminant correction: the 3×3 matrix C that takes a
//! same-illuminant table's output under an acquisition light to XYZ under
//! D65, fitted on what this table and its sensor actually produce.
//!
//! The paper's correction T ([`super::correction_matrix`]) maps the *true*
//! XYZ under the acquisition light to XYZ under D65. It assumes the table
//! renders the light's XYZ exactly. A table trained under D65 does not: under
//! another light the sensor's channels move in ways its colour map was never
//! fitted for, and on real filters the error is large (ISET's RGBW under ISET's
//! fluorescent lamp: 15.3 ΔE2000 with T). C instead fits, by least squares
//! over the natural reflectances (`scene::natural_reflectances`),
//!
//! `C · (M · channels_X(r)) ≈ XYZ_D65(r)` (errors weighted by a first-order
//! ΔE00, as the colour maps are),
//!
//! where `M` is the table's own colour map ([`L3Table::colour_map`]). The
//! result is still one table and one 3×3 matrix per light. The fit needs the
//! table's sensor and the light's spectrum; T needs neither.

use nalgebra::{SMatrix, SVector};

use super::colour_map::delta_e_weights;
use super::{ColourMatrix, ColourSamples, L3Error, L3Table, MAX_MATRIX_ENTRY, Mat3};

impl L3Table {
    /// The linear channel → XYZ map this table applies to a uniform,
    /// unsaturated patch at its brightest level: the channel sums of the flat,
    /// unsaturated kernels, averaged over CFA positions. The trainer fixes
    /// these sums to the level's colour map, and the brightest level's is the
    /// least shrunk by the noise term.
    pub fn colour_map(&self) -> Result<ColourMatrix, L3Error> {
        let geo = self.geometry()?;
        let nf = self.n_features();
        let nch = geo.n_channels();
        let top = self
            .n_levels()
            .checked_sub(1)
            .ok_or_else(|| L3Error::Table("the table has no levels".into()))?;
        let np = self.n_positions();
        let mut m = vec![[0.0f64; 3]; nch];
        for pos in 0..np {
            let kernel = self.kernel(self.class_index(pos, top, 0, false));
            for (k, out) in kernel.chunks_exact(nf).take(3).enumerate() {
                for (&c, &w) in geo.channels_of(pos).iter().zip(out) {
                    let c = c as usize;
                    if c < nch {
                        m[c][k] += f64::from(w) / np as f64;
                    }
                }
            }
        }
        Ok(ColourMatrix { m, n_channels: nch })
    }
}

/// C = argmin Σ ΔE00²(C · map(channels), xyz), to first order, over `samples`: channel
/// responses under the acquisition light and their target XYZ under D65,
/// relit to the same luminance (the cross-illuminant samples of the training
/// set). `J` is the CIELAB Jacobian at the target colour relative to the
/// sample's white, taken through CIEDE2000's local metric (the norm is
/// `eᵀ Jᵀ Q J e`, see `delta_e_weights`), so the fit minimises a first-order
/// ΔE00, as the trainer's colour maps do; a plain XYZ fit lets bright
/// surfaces decide and costs the dark ones.
pub fn camera_correction(map: &ColourMatrix, samples: &ColourSamples) -> Result<Mat3, L3Error> {
    if samples.n_channels() != map.n_channels || map.m.len() != map.n_channels {
        return Err(L3Error::InvalidParams(format!(
            "a {}-channel colour map for {}-channel samples",
            map.n_channels,
            samples.n_channels()
        )));
    }
    if samples.len() < 3
        || samples.xyz.len() != samples.len()
        || samples.white.len() != samples.len()
    {
        return Err(L3Error::InvalidParams(
            "a camera-aware correction needs at least 3 consistent samples".into(),
        ));
    }
    // unknowns: C[i][j] at 3i + j
    let mut a = SMatrix::<f64, 9, 9>::zeros();
    let mut b = SVector::<f64, 9>::zeros();
    for ((c, x), w) in samples
        .channels
        .iter()
        .zip(&samples.xyz)
        .zip(&samples.white)
    {
        let y: [f64; 3] = [0, 1, 2].map(|k| c.iter().zip(&map.m).map(|(v, col)| v * col[k]).sum());
        let wm = delta_e_weights(*x, *w);
        for i in 0..3 {
            for k in 0..3 {
                for p in 0..3 {
                    for l in 0..3 {
                        a[(3 * i + p, 3 * k + l)] += wm[i][k] * y[p] * y[l];
                    }
                    b[3 * i + p] += wm[i][k] * x[k] * y[p];
                }
            }
        }
    }
    let floor = (0..9).map(|i| a[(i, i)]).fold(0.0, f64::max) * 1e-12;
    for i in 0..9 {
        a[(i, i)] += floor.max(f64::MIN_POSITIVE);
    }
    let sol = a
        .cholesky()
        .map(|ch| ch.solve(&b))
        .ok_or_else(|| L3Error::Table("the camera-aware correction is singular".into()))?;
    let c: Mat3 = [0, 1, 2].map(|i| [0, 1, 2].map(|p| sol[3 * i + p]));
    if c.iter()
        .flatten()
        .any(|v| !v.is_finite() || v.abs() > MAX_MATRIX_ENTRY)
    {
        return Err(L3Error::Table(format!(
            "the camera-aware correction is not finite or out of bounds: {c:?}"
        )));
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples_from(truth: &[[f64; 3]], t: &Mat3) -> ColourSamples {
        let mut s = ColourSamples::default();
        for i in 0..30 {
            let c: Vec<f64> = (0..truth.len())
                .map(|k| 0.05 + ((i * 7 + k * 11) % 13) as f64 / 13.0)
                .collect();
            let x = [0, 1, 2].map(|q| (0..c.len()).map(|k| truth[k][q] * c[k]).sum::<f64>());
            let y = [0, 1, 2].map(|r| (0..3).map(|q| t[r][q] * x[q]).sum::<f64>());
            s.channels.push(c);
            s.xyz.push(y);
            s.white.push([0.95, 1.0, 1.09]);
        }
        s
    }

    #[test]
    fn recovers_the_correction_after_an_exact_map() {
        let truth = [
            [0.6, 0.3, 0.0],
            [0.3, 0.6, 0.1],
            [0.05, 0.1, 0.9],
            [0.2, 0.2, 0.2],
        ];
        let t = [[1.1, 0.1, -0.05], [0.02, 0.97, 0.01], [-0.03, 0.05, 1.4]];
        let map = ColourMatrix {
            m: truth.to_vec(),
            n_channels: 4,
        };
        let c = camera_correction(&map, &samples_from(&truth, &t)).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                assert!((c[i][j] - t[i][j]).abs() < 1e-7, "{c:?}");
            }
        }
    }

    #[test]
    fn a_map_for_other_channels_is_refused() {
        let truth = [[0.6, 0.3, 0.0], [0.3, 0.6, 0.1], [0.05, 0.1, 0.9]];
        let s = samples_from(&truth, &crate::l3::IDENTITY);
        let map = ColourMatrix {
            m: vec![[1.0, 0.0, 0.0]; 4],
            n_channels: 4,
        };
        assert!(camera_correction(&map, &s).is_err());
    }
}
