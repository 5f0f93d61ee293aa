//! What to train: a [`TrainingSpec`], the JSON body of a training job (the CLI builds the
//! same), and the L3 parameters it implies.

use serde::{Deserialize, Serialize};

use super::LearnError;
use crate::l3::classify::MAX_CHROMA_CLASSES;
use crate::l3::params::{
    CROSS_AVERAGING_PX, ColourLoss, ColourMapFit, L3Params, RidgeChoice, UNDER_LIGHT_AVERAGING_PX,
};
use crate::l3::table::TableKind;
use crate::spectral::IlluminantSpec;

/// What to train (the JSON body of a training job; the CLI builds the same).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingSpec {
    /// `si` (same-illuminant) or `cross` (to D65).
    #[serde(default = "default_kind")]
    pub kind: TableKind,
    /// Training illuminants (IlluminantSpec strings); several make an ensemble.
    #[serde(default = "default_illuminants")]
    pub illuminants: Vec<String>,
    #[serde(default = "default_patch")]
    pub patch_size: usize,
    #[serde(default = "default_levels")]
    pub levels: usize,
    #[serde(default)]
    pub seed: u64,
    /// Number of training scenes; scene s is lit by illuminant s mod n.
    #[serde(default = "default_scenes")]
    pub scenes: usize,
    /// Side of each training scene, pixels.
    #[serde(default = "default_scene_size")]
    pub scene_size: usize,
    /// Simulate full sensor noise (otherwise noise-free patches with the
    /// analytic noise-variance ridge).
    #[serde(default = "default_true")]
    pub noise: bool,
    #[serde(default = "default_true")]
    pub contrast_classes: bool,
    #[serde(default = "default_true")]
    pub saturation_classes: bool,
    /// Mean scene luminance of the training scenes, cd/m² (exposure is set per level).
    #[serde(default = "default_luminance")]
    pub mean_luminance: f64,
    /// Pixels per channel whose mean each level's colour map is made best
    /// for under the sensor's noise (0: the noise-free map at every level;
    /// absent: [`CROSS_AVERAGING_PX`] for the maps a table renders
    /// with, and [`UNDER_LIGHT_AVERAGING_PX`] for a same-illuminant
    /// table's maps for lights it was not trained under; given, both).
    #[serde(default)]
    pub colour_averaging_px: Option<f64>,
    /// What each level's colour map minimises over its samples (see
    /// [`ColourLoss`]); absent: [`TrainingSpec::colour_loss`].
    #[serde(default)]
    pub colour_loss: Option<ColourLoss>,
    /// Chroma classes splitting every level (k-means on the training
    /// reflectances' channel chromaticities, each class with its own colour
    /// maps and kernels: see `src/l3/classify/chroma.rs`); 1: no split. Classes left
    /// with too few surfaces are dropped, so a table may hold fewer. A spec that does not
    /// name them is read as 1 (the records written before chroma classes); a new spec gets
    /// [`DEFAULT_CHROMA_CLASSES`].
    #[serde(default = "absent_chroma_classes", skip_serializing_if = "is_one")]
    pub chroma_classes: usize,
    /// Pixels per channel whose mean the texture classes' colour maps are fitted for
    /// ([`L3Params::texture_averaging_px`]); absent: the texture classes share the flat
    /// classes' maps, as in the records written before the field. A new spec gets
    /// [`DEFAULT_TEXTURE_AVERAGING_PX`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture_colour_averaging_px: Option<f64>,
}

/// The texture classes' colour-map averaging of a new table (see
/// [`TrainingSpec::texture_colour_averaging_px`] and docs/research/false-colour.md).
pub const DEFAULT_TEXTURE_AVERAGING_PX: f64 = 8.0;

/// The fields a new spec (a training job's body, the service's default table) gets when it
/// does not name them, where a stored record that does not name them keeps the older
/// meaning: [`DEFAULT_CHROMA_CLASSES`] and [`DEFAULT_TEXTURE_AVERAGING_PX`].
pub fn new_spec_defaults() -> [(&'static str, serde_json::Value); 2] {
    [
        ("chroma_classes", DEFAULT_CHROMA_CLASSES.into()),
        (
            "texture_colour_averaging_px",
            DEFAULT_TEXTURE_AVERAGING_PX.into(),
        ),
    ]
}

fn default_kind() -> TableKind {
    TableKind::SameIlluminant
}
fn default_illuminants() -> Vec<String> {
    vec!["D65".into(), "Tungsten".into()]
}
fn default_patch() -> usize {
    5
}
fn default_levels() -> usize {
    20
}
fn default_scenes() -> usize {
    48
}
fn default_scene_size() -> usize {
    96
}
fn default_true() -> bool {
    true
}
fn default_luminance() -> f64 {
    100.0
}
/// The chroma classes of a new table: on the paper's sensor they take I_Tun from 2.67 to 1.96
/// and SI_Ens+T from 3.08 to 2.52 (tungsten, seed 7), worsen no row of Table 1 on the six
/// shipped sensors, and cost about 1.4× the one-class render (docs/accuracy.md).
pub const DEFAULT_CHROMA_CLASSES: usize = 8;

/// A stored spec without `chroma_classes`: written when 1 was the only choice (and 1 is still
/// not written, so such records stay byte for byte).
fn absent_chroma_classes() -> usize {
    1
}
fn is_one(n: &usize) -> bool {
    *n == 1
}

impl Default for TrainingSpec {
    fn default() -> Self {
        Self {
            kind: default_kind(),
            illuminants: default_illuminants(),
            patch_size: default_patch(),
            levels: default_levels(),
            seed: 0,
            scenes: default_scenes(),
            scene_size: default_scene_size(),
            noise: true,
            contrast_classes: true,
            saturation_classes: true,
            mean_luminance: default_luminance(),
            colour_averaging_px: None,
            colour_loss: None,
            chroma_classes: DEFAULT_CHROMA_CLASSES,
            texture_colour_averaging_px: Some(DEFAULT_TEXTURE_AVERAGING_PX),
        }
    }
}

/// The largest scene mean luminance a training spec takes, cd/m² (a sunlit scene is about
/// 10⁴; beyond this the simulation's electron rates lose their meaning).
pub const MAX_MEAN_LUMINANCE: f64 = 1e6;

/// The most pixels per channel a colour map is fitted for (beyond it the noise is nil: 0 says
/// so).
pub const MAX_AVERAGING_PX: f64 = 1e6;

impl TrainingSpec {
    pub fn validate(&self) -> Result<(), LearnError> {
        let bad = |m: String| Err(LearnError::Invalid(m));
        if self.illuminants.is_empty() || self.illuminants.len() > 16 {
            return bad(format!("{} illuminants (1 to 16)", self.illuminants.len()));
        }
        for s in &self.illuminants {
            IlluminantSpec::parse(s)?;
        }
        if ![3, 5, 7, 9].contains(&self.patch_size) {
            return bad(format!("patch_size {} (3, 5, 7 or 9)", self.patch_size));
        }
        if !(2..=64).contains(&self.levels) {
            return bad(format!("levels {} (2 to 64)", self.levels));
        }
        if !(1..=10_000).contains(&self.scenes) {
            return bad(format!("scenes {} (1 to 10000)", self.scenes));
        }
        if !(16..=1024).contains(&self.scene_size) {
            return bad(format!("scene_size {} (16 to 1024)", self.scene_size));
        }
        let max_px = MAX_AVERAGING_PX;
        if let Some(px) = self.colour_averaging_px
            && !(px.is_finite() && (px == 0.0 || (1.0..=max_px).contains(&px)))
        {
            return bad(format!("colour_averaging_px {px} (0, or 1 to {max_px})"));
        }
        if let Some(px) = self.texture_colour_averaging_px
            && !(px.is_finite() && (1.0..=max_px).contains(&px))
        {
            return bad(format!("texture_colour_averaging_px {px} (1 to {max_px})"));
        }
        let l = self.mean_luminance;
        if !(l.is_finite() && l > 0.0 && l <= MAX_MEAN_LUMINANCE) {
            return bad(format!(
                "mean_luminance {l} (above 0, at most {MAX_MEAN_LUMINANCE} cd/m²)"
            ));
        }
        if !(1..=MAX_CHROMA_CLASSES).contains(&self.chroma_classes) {
            return bad(format!(
                "chroma_classes {} (1 to {})",
                self.chroma_classes, MAX_CHROMA_CLASSES
            ));
        }
        Ok(())
    }

    /// Batches of a run of this spec (one training scene each): what a run
    /// can be split into ([`TrainingRun::plan`](crate::l3::learn::TrainingRun::plan)).
    pub fn n_batches(&self) -> usize {
        // A fixed scene budget: scene s is lit by illuminant s mod n (an
        // ensemble is a mixture of scenes, not every scene under every
        // light), so an ensemble costs what a single-illuminant table costs.
        self.scenes
    }

    /// The averaging (pixels per channel) of the colour maps this spec's
    /// table renders with: a cross table's maps, and a same-illuminant
    /// table's maps aimed through T, which carry a cross map's white-balance
    /// gain ([`CROSS_AVERAGING_PX`]).
    pub fn colour_averaging(&self) -> f64 {
        self.colour_averaging_px.unwrap_or(CROSS_AVERAGING_PX)
    }

    /// The averaging of a same-illuminant table's transfer maps, aimed at XYZ
    /// under the light for lights it was not trained under
    /// ([`UNDER_LIGHT_AVERAGING_PX`]).
    pub fn transfer_averaging(&self) -> f64 {
        self.colour_averaging_px.unwrap_or(UNDER_LIGHT_AVERAGING_PX)
    }

    /// The loss this spec's colour maps minimise: as given, or by the number
    /// of training lights. A one-light table minimises its mean ΔE00
    /// ([`ColourLoss::MeanDeltaE`](ColourLoss)); an ensemble keeps
    /// the squared loss, whose compromise between lights served the lights
    /// it was not trained on better. Measured on the six shipped sensors
    /// (Table 1, one capture): with the mean loss on ensembles too, the D65 +
    /// tungsten tables lost under tungsten on both measured Bayer cameras
    /// (Canon 1.91 → 2.01, Nikon 2.22 → 2.30) and under the lamp they never
    /// saw (Canon 3.75 → 3.87, past its baseline's 3.70), and ISET's RGBW
    /// three-light table lost under fluorescent (8.73 → 8.80 against its
    /// matching linear map's 8.35).
    pub fn colour_loss(&self) -> ColourLoss {
        self.colour_loss.unwrap_or(if self.illuminants.len() == 1 {
            ColourLoss::MeanDeltaE
        } else {
            ColourLoss::SquaredDeltaE
        })
    }

    /// The L3 parameters this spec implies for a sensor with `swing` volts.
    pub fn params(&self, swing: f64) -> Result<L3Params, LearnError> {
        let p = L3Params {
            patch_size: self.patch_size,
            levels: L3Params::levels_for(self.levels, swing)?,
            contrast_classes: self.contrast_classes,
            saturation_classes: self.saturation_classes,
            ridge: if self.noise {
                RidgeChoice::Gcv
            } else {
                RidgeChoice::NoiseVariance
            },
            colour_map: Some(ColourMapFit {
                averaging_px: Some(self.colour_averaging()).filter(|&px| px > 0.0),
                perceptual: true,
                loss: self.colour_loss(),
            }),
            texture_averaging_px: self.texture_colour_averaging_px,
            ..L3Params::default()
        };
        p.validate()?;
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_spec_gets_texture_maps_and_a_stored_record_keeps_its_meaning() {
        assert_eq!(
            TrainingSpec::default().texture_colour_averaging_px,
            Some(DEFAULT_TEXTURE_AVERAGING_PX)
        );
        // a record written before the field: texture classes share the flat maps, and
        // writing it back does not add the field
        let old: TrainingSpec = serde_json::from_str(r#"{"kind":"si","scenes":4}"#).unwrap();
        assert_eq!(old.texture_colour_averaging_px, None);
        assert_eq!(old.params(1.8).unwrap().texture_averaging_px, None);
        let json = serde_json::to_string(&old).unwrap();
        assert!(!json.contains("texture_colour_averaging_px"), "{json}");
        // a new spec's defaults name real fields with valid values
        let mut map = serde_json::Map::new();
        for (k, v) in new_spec_defaults() {
            map.insert(k.into(), v);
        }
        let new: TrainingSpec = serde_json::from_value(map.into()).unwrap();
        new.validate().unwrap();
        assert_eq!(new.chroma_classes, DEFAULT_CHROMA_CLASSES);
        assert_eq!(
            new.params(1.8).unwrap().texture_averaging_px,
            Some(DEFAULT_TEXTURE_AVERAGING_PX)
        );
        // below one pixel is refused
        let bad = TrainingSpec {
            texture_colour_averaging_px: Some(0.5),
            ..TrainingSpec::default()
        };
        assert!(bad.validate().is_err());
    }
}
