//! The parameters of an L3 table ([`L3Params`]) and the configuration they hold: how the
//! ridge of every class is chosen ([`RidgeChoice`]) and how each level's colour map is
//! fitted ([`ColourMapFit`], [`ColourLoss`]). A table file stores them; the trainer reads
//! them; the renderer needs only the classification a table derives from them.

use serde::{Deserialize, Serialize};

use super::classify::{ChromaClasses, ClassifyError};
use crate::baseline::ColourMatrix;

/// Errors of the parameters: a value out of range, or chroma classes that do not fit.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    #[error("invalid parameters: {0}")]
    Invalid(String),
    #[error(transparent)]
    Classify(#[from] ClassifyError),
}

/// ISET's tuned RGBW luminance levels for a 1.8 V swing (docs/design.md §5), volts.
pub const DEFAULT_LEVELS_1V8: [f64; 20] = [
    0.001, 0.0016, 0.0026, 0.0041, 0.0065, 0.0104, 0.0166, 0.0266, 0.0424, 0.0678, 0.1082, 0.1729,
    0.2762, 0.4505, 0.6753, 0.9, 1.1248, 1.3495, 1.5743, 1.782,
];

/// Classification and learning parameters of an L3 table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct L3Params {
    /// Patch side: 3, 5, 7 or 9.
    pub patch_size: usize,
    /// Luminance levels in volts, increasing.
    pub levels: Vec<f64>,
    /// A pixel is saturated at or above `voltage_swing − saturation_margin_v`.
    pub saturation_margin_v: f64,
    /// Flat/texture split at this quantile of the class's training contrasts.
    pub contrast_quantile: f64,
    /// Whether to split classes by contrast at all.
    pub contrast_classes: bool,
    /// Whether to keep separate saturation cases (otherwise all pixels are
    /// treated as unsaturated).
    pub saturation_classes: bool,
    /// A saturation case needs this fraction of a level's samples to get kernels.
    pub min_saturation_case_fraction: f64,
    /// Classes with fewer samples borrow from neighbouring levels.
    pub min_class_samples: u64,
    pub ridge: RidgeChoice,
    /// Average flat kernels with their mirror images where the CFA allows.
    pub symmetrize_flat: bool,
    /// How the per-level colour maps that fix the channel sums of every
    /// unsaturated kernel were fitted (see `src/l3/learn/colour_map.rs`); `None`
    /// when the kernels were learned without them.
    #[serde(default)]
    pub colour_map: Option<ColourMapFit>,
    /// Chroma classes splitting every level (see [`super::classify::chroma`]); `None`
    /// (a single class) in tables without a chroma split, whose files do
    /// not name the field.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chroma: Option<ChromaClasses>,
    /// Per level, the colour map a same-illuminant table renders a light it
    /// was not trained on with: fitted over every chroma class at once and
    /// aimed at XYZ under the training lights (the paper's target), not
    /// through their T as the table's own maps are, with the fit that
    /// renders standard lights held out from training better
    /// (`src/l3/learn/transfer_fit.rs`). Under such a light,
    /// corrected by one T, the table's unsaturated kernels' channel sums are
    /// moved to these maps (`L3Table::transfer_kernels`). `None` in
    /// cross-illuminant tables and in tables trained before the field.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transfer_maps: Option<Vec<ColourMatrix>>,
    /// Pixels per channel whose mean the colour maps of the *texture* classes' channel sums
    /// are fitted for (as [`ColourMapFit::averaging_px`] is for the flat classes'); `None`:
    /// texture kernels share the flat classes' maps, as every table trained before the
    /// field did. A patch across an edge averages fewer pixels of each channel on either
    /// side, and a map fitted for fewer pixels has smaller, less opposed weights, so the
    /// CFA's sampling phase leaks less into colour at edges (`src/l3/learn/colour_map.rs`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture_averaging_px: Option<f64>,
}

impl Default for L3Params {
    fn default() -> Self {
        Self {
            patch_size: 5,
            levels: DEFAULT_LEVELS_1V8.to_vec(),
            saturation_margin_v: 0.001,
            contrast_quantile: 0.6,
            contrast_classes: true,
            saturation_classes: true,
            min_saturation_case_fraction: 0.002,
            min_class_samples: 2000,
            ridge: RidgeChoice::Gcv,
            symmetrize_flat: true,
            colour_map: Some(ColourMapFit::default()),
            chroma: None,
            transfer_maps: None,
            texture_averaging_px: None,
        }
    }
}

impl L3Params {
    /// `n` levels spread like the ISET list over a swing: the default 20 are
    /// scaled by `swing / 1.8`; other counts are interpolated in log space
    /// between the first and last default level.
    pub fn levels_for(n: usize, swing: f64) -> Result<Vec<f64>, ParamsError> {
        if !(2..=256).contains(&n) {
            return Err(ParamsError::Invalid(format!(
                "{n} luminance levels: between 2 and 256 are supported"
            )));
        }
        if !(swing.is_finite() && swing > 0.0) {
            return Err(ParamsError::Invalid(format!("voltage swing {swing}")));
        }
        let k = swing / 1.8;
        if n == DEFAULT_LEVELS_1V8.len() {
            return Ok(DEFAULT_LEVELS_1V8.iter().map(|v| v * k).collect());
        }
        // Resample the default list's shape: interpolate the level value as a
        // function of its normalised index.
        let d = &DEFAULT_LEVELS_1V8;
        let m = d.len() - 1;
        Ok((0..n)
            .map(|i| {
                let t = i as f64 / (n - 1) as f64 * m as f64;
                let j = (t.floor() as usize).min(m - 1);
                let f = t - j as f64;
                // interpolate in log space: the list is geometric at the low end
                (d[j].ln() * (1.0 - f) + d[j + 1].ln() * f).exp() * k
            })
            .collect())
    }

    pub fn validate(&self) -> Result<(), ParamsError> {
        let bad = |m: String| Err(ParamsError::Invalid(m));
        if ![3, 5, 7, 9].contains(&self.patch_size) {
            return bad(format!("patch size {} (3, 5, 7 or 9)", self.patch_size));
        }
        if self.levels.len() < 2 || self.levels.len() > 256 {
            return bad(format!("{} levels (2 to 256)", self.levels.len()));
        }
        if self
            .levels
            .windows(2)
            .any(|w| !(w[0].is_finite() && w[1].is_finite() && w[1] > w[0] && w[0] > 0.0))
        {
            return bad("levels must be positive, finite and increasing".into());
        }
        if !(0.0..=0.5).contains(&self.saturation_margin_v) {
            return bad(format!("saturation margin {} V", self.saturation_margin_v));
        }
        if !(0.05..=0.95).contains(&self.contrast_quantile) {
            return bad(format!("contrast quantile {}", self.contrast_quantile));
        }
        if !(0.0..=0.5).contains(&self.min_saturation_case_fraction) {
            return bad("min_saturation_case_fraction must be within 0–0.5".into());
        }
        if let Some(fit) = &self.colour_map {
            fit.validate()?;
        }
        if let Some(px) = self.texture_averaging_px
            && !(px.is_finite() && px >= 1.0)
        {
            return bad(format!("texture colour map averaging {px} px (at least 1)"));
        }
        if let Some(c) = &self.chroma {
            c.validate(c.centroids.first().map(Vec::len).unwrap_or(0))?;
        }
        if let Some(maps) = &self.transfer_maps {
            if maps.len() != self.levels.len() {
                return bad(format!(
                    "{} transfer maps for {} levels",
                    maps.len(),
                    self.levels.len()
                ));
            }
            if maps
                .iter()
                .any(|m| m.m.len() != m.n_channels || m.m.iter().flatten().any(|v| !v.is_finite()))
            {
                return bad("transfer maps must be finite channel → XYZ maps".into());
            }
        }
        self.ridge.validate()
    }
}

/// How the ridge parameter λ of a class is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "snake_case")]
pub enum RidgeChoice {
    /// Generalised cross-validation over a log grid of λ.
    Gcv,
    /// λ = `relative` × the mean eigenvalue of the centred covariance.
    Fixed { relative: f64 },
    /// λ = the sensor's noise variance at the class level (volts²): the
    /// analytic noise-aware ridge for tables trained on noise-free patches.
    NoiseVariance,
}

impl RidgeChoice {
    pub fn validate(&self) -> Result<(), ParamsError> {
        match self {
            Self::Fixed { relative } if !(relative.is_finite() && *relative >= 0.0) => {
                Err(ParamsError::Invalid(format!("ridge relative λ {relative}")))
            }
            _ => Ok(()),
        }
    }
}

/// How each level's colour map is fitted.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColourMapFit {
    /// Pixels per channel whose mean the map is made best for under the
    /// sensor's noise; `None` fits the noise-free map at every level.
    pub averaging_px: Option<f64>,
    /// Weight errors by the CIELAB Jacobian (otherwise plain XYZ error).
    pub perceptual: bool,
    /// What the fit minimises over the samples (absent in tables trained
    /// before the choice existed, which minimised the squared error).
    #[serde(default = "ColourLoss::squared")]
    pub loss: ColourLoss,
}

/// The loss a colour map minimises over its samples, each sample's error
/// measured as its expected first-order ΔE00 (bias and noise).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ColourLoss {
    /// The sum of squared errors: one weighted least-squares solve.
    SquaredDeltaE,
    /// The mean error of every light, the mean ΔE an evaluation reports:
    /// `Σ_light (Σ_sample ΔE)²`, by iteratively reweighted least squares.
    #[default]
    MeanDeltaE,
}

impl ColourLoss {
    fn squared() -> Self {
        Self::SquaredDeltaE
    }
}

impl Default for ColourMapFit {
    fn default() -> Self {
        Self {
            averaging_px: Some(UNDER_LIGHT_AVERAGING_PX),
            perceptual: true,
            loss: ColourLoss::default(),
        }
    }
}

/// The averaging of the maps a same-illuminant table keeps for lights it
/// was not trained under ([`L3Params::transfer_maps`]), aimed at XYZ
/// under the light, and the default [`ColourMapFit`]. Such a
/// map has no white-balance gain, so it takes a lighter noise term than a
/// cross map. Measured on ISET's RGBW under tungsten when every
/// same-illuminant map was aimed so (SI_Tun+T, 16 captures; one capture's
/// mean / noise-free / per-pixel): 64 gave 3.17 / 2.98 / 4.91, 128 gave 3.25
/// / 2.89 / 6.05, 256 gave 3.42 / 2.84 / 7.28; on rgbw-ar0132at 2.52, 2.55
/// and 2.58. 128 was chosen with the earlier ΔE76 maps, where 64 cost two
/// fluorescent `+C` rows on rgbw-ar0132at.
pub const UNDER_LIGHT_AVERAGING_PX: f64 = 128.0;

/// The averaging of the maps a table renders with under its own lights: a
/// cross-illuminant table's, and a same-illuminant table's aimed through T
/// (`l3::correct::ColourTarget::ThroughCorrection`), which carry the same
/// white-balance gain. The lighter noise term of 128 left such maps noisy.
/// The value is measured, not derived: a 16×16-pixel patch interior holds
/// 64 pixels per channel (2×2 CFA), and over 16 noisy captures of the chart
/// the mean patch-mean ΔE2000 of one capture is lowest near 48 with the
/// mean-ΔE loss. I_Tun (one capture's mean / noise-free / per-pixel),
/// mean-ΔE loss: on ISET's RGBW 32 gave 2.81 / 2.72 / 3.72, 48 gave 2.77 /
/// 2.62 / 4.21, 64 gave 2.77 / 2.54 / 4.71, 96 gave 2.81 / 2.40 / 5.61; on
/// rgbw-ar0132at 2.21, 2.20, 2.20 and 2.21. (With the squared loss 32 was
/// best: 2.80 / 2.62 / 4.46 on ISET's RGBW, 2.29 on rgbw-ar0132at.) The
/// aimed same-illuminant maps took 128 until they were measured with it:
/// on the six sensors' Table 1, 48 moved 29 rows by 0.01 or more for the
/// better and 6 for the worse (mean −0.014), ISET's RGBW SI_Tun+T 2.73 →
/// 2.67 (per pixel 6.37 → 4.21, the cross table's figures: with the same
/// averaging an SI_Tun table followed by T is the cross table), and its
/// `+C` rows by 0.10–0.30.
pub const CROSS_AVERAGING_PX: f64 = 48.0;

impl ColourMapFit {
    pub fn validate(&self) -> Result<(), ParamsError> {
        match self.averaging_px {
            Some(n) if !(n.is_finite() && n >= 1.0) => Err(ParamsError::Invalid(format!(
                "colour map averaging {n} px (at least 1)"
            ))),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_lists() {
        let l = L3Params::levels_for(20, 1.8).unwrap();
        assert_eq!(l, DEFAULT_LEVELS_1V8.to_vec());
        for n in [10, 40] {
            let l = L3Params::levels_for(n, 1.8).unwrap();
            assert_eq!(l.len(), n);
            assert!((l[0] - 0.001).abs() < 1e-12 && (l[n - 1] - 1.782).abs() < 1e-9);
            assert!(l.windows(2).all(|w| w[1] > w[0]));
        }
        assert!(L3Params::levels_for(1, 1.8).is_err());
        let mut p = L3Params::default();
        assert!(p.validate().is_ok());
        p.patch_size = 4;
        assert!(p.validate().is_err());
    }
}
