//! Kernels for a light a same-illuminant table was not trained on.
//!
//! A same-illuminant table's colour maps are fitted for the lights it was
//! trained under, aimed through each light's T at the true D65 colour
//! ([`ColourTarget::ThroughCorrection`](super::ColourTarget::ThroughCorrection)): they absorb what those
//! T's get wrong, which another light's T does not share. The maps of a
//! chroma class are also a local fit, to the spectra its surfaces sent under
//! the training light(s), and extrapolate worse under another light than one
//! map per level fitted over every class.
//!
//! Measured in Table 1 (`l3 eval --paper-table`, seed 7):
//! - aimed maps under a light outside the table's ensemble: rgbw-paper's
//!   SI_Ens+T (D65 and tungsten) under the fluorescent lamp went 1.68 → 2.42,
//!   while the same table under tungsten went 1.50 → 1.09;
//! - 8 balanced chroma classes against one: rgbw-ar0132at SI_D65+T under
//!   tungsten 2.69 → 5.04 and under the lamp 3.69 → 5.94, the Canon's under
//!   the lamp 3.43 → 4.17, while the same tables under their own light, or
//!   through the camera-aware C, gained (`docs/table1/summary-chroma8.md`).
//!
//! So a same-illuminant table keeps, per level, the map fitted over every
//! class and aimed at XYZ under the light ([`L3Params::transfer_maps`](crate::l3::params::L3Params::transfer_maps);
//! the trainer fits it for ΔE00 or by plain least squares, whichever renders
//! standard lights held out from training better: `src/l3/learn/transfer_fit.rs`),
//! and under a foreign light with T every unsaturated kernel's channel sums
//! are moved onto it: each channel's difference is spread evenly over that
//! channel's pixels in the patch. On a uniform patch the kernel then applies
//! that map, as the paper's table does; its spatial weights (the
//! demosaicking) stay the table's. The intercept, fixed to 0 in training,
//! and the saturated cases, whose kernels carry no colour map, are left as
//! they are. Through the camera-aware C (per-level corrections fitted on the
//! table's own maps) the table's kernels are used as they are.

use crate::l3::table::{L3Table, TableError};

/// How far (in CIE 1931 x and in y) a light's white may lie from a training light's recorded
/// white and still be that light. The same spectrum on the same grid gives the same white; the
/// margin is for rounding and for a copy of the spectral data resampled otherwise. A 100 K
/// step of a blackbody near 3000 K moves x by about 0.007, seven times the margin.
pub const TRAINING_WHITE_TOLERANCE: f64 = 1e-3;

impl L3Table {
    /// Whether the table was trained under the light named `name` (one of
    /// its training illuminants, compared without case).
    pub fn trained_under(&self, name: &str) -> bool {
        self.trained_under_light(name, None)
    }

    /// [`Self::trained_under`] for a light whose white is known (`white_xy`): the name must
    /// match, and, where the table recorded that training light's white, the white too
    /// (within `TRAINING_WHITE_TOLERANCE`). A light registered later under a training
    /// light's name with other samples is then not the table's own.
    pub fn trained_under_light(&self, name: &str, white_xy: Option<[f64; 2]>) -> bool {
        let recorded = &self.meta.train_white_xy;
        self.meta
            .train_illuminants
            .iter()
            .enumerate()
            .any(|(i, n)| {
                n.eq_ignore_ascii_case(name)
                    && match (white_xy, recorded.get(i)) {
                        (Some(w), Some(t)) => {
                            (w[0] - t[0]).abs() <= TRAINING_WHITE_TOLERANCE
                                && (w[1] - t[1]).abs() <= TRAINING_WHITE_TOLERANCE
                        }
                        _ => true,
                    }
            })
    }

    /// Whether the table renders under the light named `name`, corrected by
    /// one 3×3 matrix, with [`Self::transfer_kernels`] rather than its own:
    /// it keeps transfer maps and was not trained under that light.
    pub fn transfers_to(&self, name: &str) -> bool {
        self.transfers_to_light(name, None)
    }

    /// [`Self::transfers_to`] for a light whose white is known
    /// ([`Self::trained_under_light`]).
    pub fn transfers_to_light(&self, name: &str, white_xy: Option<[f64; 2]>) -> bool {
        self.meta.params.transfer_maps.is_some() && !self.trained_under_light(name, white_xy)
    }

    /// The table's kernels with every unsaturated kernel's channel sums moved
    /// to its level's transfer map (see the module doc); `None` for a table
    /// without transfer maps.
    pub fn transfer_kernels(&self) -> Result<Option<Vec<f32>>, TableError> {
        let Some(maps) = &self.meta.params.transfer_maps else {
            return Ok(None);
        };
        let geo = self.geometry()?;
        let nch = geo.n_channels();
        let nf = self.n_features();
        if maps.len() != self.n_levels() || maps.iter().any(|m| m.n_channels != nch) {
            return Err(TableError::Unusable(format!(
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
