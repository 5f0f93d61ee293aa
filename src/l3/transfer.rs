//! Kernels for a light a chroma-split same-illuminant table was not trained on.
//!
//! A chroma class's colour map is a local fit: to the spectra its surfaces
//! sent under the training light(s). Under another light, corrected by the
//! paper's T (colorimetry only, blind to the table), the same surfaces send
//! other spectra and a class map extrapolates worse than the one map per level
//! fitted over every class. Measured in Table 1 with 8 balanced classes
//! against one class: rgbw-ar0132at SI_D65+T under tungsten 2.69 → 5.04 and
//! under the lamp 3.69 → 5.94, the Canon's under the lamp 3.43 → 4.17, while
//! the same tables under their own light, or through the camera-aware C,
//! gained (`docs/table1/summary-chroma8.md`).
//!
//! So such a table keeps its per-level maps over every class
//! ([`super::L3Params::transfer_maps`]), and under a foreign light with T
//! every unsaturated kernel's channel sums are moved onto them: each
//! channel's difference is spread evenly over that channel's pixels in the
//! patch. On a uniform patch the kernel then applies the level's pooled map,
//! as a table without a chroma split does; its spatial weights (the
//! demosaicking) stay the class's. The intercept, fixed to 0 in training,
//! and the saturated cases, whose kernels carry no colour map, are left as
//! they are.

use super::{L3Error, L3Table};

impl L3Table {
    /// Whether the table was trained under the light named `name` (one of
    /// its training illuminants, compared without case).
    pub fn trained_under(&self, name: &str) -> bool {
        self.meta
            .train_illuminants
            .iter()
            .any(|n| n.eq_ignore_ascii_case(name))
    }

    /// Whether the table renders under the light named `name`, corrected by
    /// one 3×3 matrix, with [`Self::transfer_kernels`] rather than its own:
    /// it keeps transfer maps and was not trained under that light.
    pub fn transfers_to(&self, name: &str) -> bool {
        self.meta.params.transfer_maps.is_some() && !self.trained_under(name)
    }

    /// The table's kernels with every unsaturated kernel's channel sums moved
    /// to its level's transfer map (see the module doc); `None` for a table
    /// without transfer maps.
    pub fn transfer_kernels(&self) -> Result<Option<Vec<f32>>, L3Error> {
        let Some(maps) = &self.meta.params.transfer_maps else {
            return Ok(None);
        };
        let geo = self.geometry()?;
        let nch = geo.n_channels();
        let nf = self.n_features();
        if maps.len() != self.n_levels() || maps.iter().any(|m| m.n_channels != nch) {
            return Err(L3Error::Table(format!(
                "{} transfer maps of {:?} channels for {} levels of {nch} channels",
                maps.len(),
                maps.first().map(|m| m.n_channels),
                self.n_levels()
            )));
        }
        let mut kernels = self.kernels.clone();
        for pos in 0..self.n_positions() {
            let chan = geo.channels_of(pos);
            let mut count = vec![0usize; nch];
            for &c in chan {
                if let Some(n) = count.get_mut(c as usize) {
                    *n += 1;
                }
            }
            for band in 0..self.n_bands() {
                let map = &maps[band / self.n_chroma()];
                for texture in [false, true] {
                    let class = self.class_index(pos, band, 0, texture);
                    let kernel = &mut kernels[class * 3 * nf..(class + 1) * 3 * nf];
                    for (k, row) in kernel.chunks_exact_mut(nf).enumerate() {
                        let mut sums = vec![0f64; nch];
                        for (&c, &w) in chan.iter().zip(row.iter()) {
                            if let Some(s) = sums.get_mut(c as usize) {
                                *s += f64::from(w);
                            }
                        }
                        for (&c, w) in chan.iter().zip(row.iter_mut()) {
                            let c = c as usize;
                            if c < nch && count[c] > 0 {
                                let step = (map.m[c][k] - sums[c]) / count[c] as f64;
                                *w = (f64::from(*w) + step) as f32;
                            }
                        }
                    }
                }
            }
        }
        Ok(Some(kernels))
    }
}
