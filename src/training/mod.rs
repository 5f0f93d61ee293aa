//! Training an L3 table from the camera simulation: the training scenes,
//! the frames simulated from them, and the call into the learner
//! (DESIGN.md §5). Shared by the CLI and the service's training jobs.
//!
//! A [`TrainingRun`] trains in one call or in shards (batch ranges) whose
//! partial sums can be computed on other machines and merged into the same
//! table bytes (`src/l3/shards.rs` explains why they are equal).

mod colour_samples;
mod scenes;
mod transfer_fit;

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::camera::{Camera, CameraError, NoiseSwitches, SensorDesign, mosaic};
use crate::colour::mat3_mul_vec;
use crate::l3::{
    ChromaClasses, Classes, ColourLoss, ColourMapFit, ColourMatrix, GramPartial, L3Error, L3Params,
    L3Table, Learned, MIN_SURFACES_PER_CHANNEL, NoiseModel, PatchGeometry, RidgeChoice, ShardSpec,
    SurveyPartial, TABLE_FORMAT_VERSION, TableKind, TableMeta, TrainControl, TrainSetup,
    TrainingFrame, accumulate_batches, band_maps, classes_from_survey, learn, level_maps,
    merge_partials, merge_surveys, package, plan_shards, solve_learned, survey_batches,
};
use crate::scene::SceneError;
use crate::spectral::{
    Extrapolation, IlluminantSpec, IsetData, SpectralError, Spectrum, WavelengthGrid,
    cie_illuminant,
};

pub use crate::scene::training_reflectances;
pub use colour_samples::{
    ColourTarget, camera_corrected, colour_samples, inverse_correction, noise_model,
    same_illuminant_corrections, with_neutral,
};
pub use scenes::TrainingScenes;
pub use transfer_fit::{
    HELD_OUT_LIGHTS, HeldOutLight, TransferChoice, TransferFit, choose_transfer_fit,
    held_out_error, held_out_lights,
};

/// Errors of a training run.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("invalid training spec: {0}")]
    Invalid(String),
    #[error(transparent)]
    L3(#[from] L3Error),
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Spectral(#[from] SpectralError),
}

impl From<TrainError> for L3Error {
    fn from(e: TrainError) -> Self {
        match e {
            TrainError::L3(e) => e,
            other => L3Error::InvalidInput(other.to_string()),
        }
    }
}

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
    /// absent: [`crate::l3::CROSS_AVERAGING_PX`] for the maps a table renders
    /// with, and [`crate::l3::UNDER_LIGHT_AVERAGING_PX`] for a same-illuminant
    /// table's maps for lights it was not trained under; given, both).
    #[serde(default)]
    pub colour_averaging_px: Option<f64>,
    /// What each level's colour map minimises over its samples (see
    /// [`crate::l3::ColourLoss`]); absent: [`TrainingSpec::colour_loss`].
    #[serde(default)]
    pub colour_loss: Option<crate::l3::ColourLoss>,
    /// Chroma classes splitting every level (k-means on the training
    /// reflectances' channel chromaticities, each class with its own colour
    /// maps and kernels: see `src/l3/chroma.rs`); 1: no split. Classes left
    /// with too few surfaces are dropped, so a table may hold fewer.
    #[serde(default = "default_chroma_classes", skip_serializing_if = "is_one")]
    pub chroma_classes: usize,
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
fn default_chroma_classes() -> usize {
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
            chroma_classes: default_chroma_classes(),
        }
    }
}

impl TrainingSpec {
    pub fn validate(&self) -> Result<(), TrainError> {
        let bad = |m: String| Err(TrainError::Invalid(m));
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
        if let Some(px) = self.colour_averaging_px
            && !(px.is_finite() && (px == 0.0 || px >= 1.0))
        {
            return bad(format!("colour_averaging_px {px} (0, or at least 1)"));
        }
        if !(self.mean_luminance.is_finite() && self.mean_luminance > 0.0) {
            return bad(format!("mean_luminance {}", self.mean_luminance));
        }
        if !(1..=crate::l3::MAX_CHROMA_CLASSES).contains(&self.chroma_classes) {
            return bad(format!(
                "chroma_classes {} (1 to {})",
                self.chroma_classes,
                crate::l3::MAX_CHROMA_CLASSES
            ));
        }
        Ok(())
    }

    /// Batches of a run of this spec (one training scene each): what a run
    /// can be split into ([`TrainingRun::plan`]).
    pub fn n_batches(&self) -> usize {
        // A fixed scene budget: scene s is lit by illuminant s mod n (an
        // ensemble is a mixture of scenes, not every scene under every
        // light), so an ensemble costs what a single-illuminant table costs.
        self.scenes
    }

    /// The averaging (pixels per channel) of the colour maps this spec's
    /// table renders with: a cross table's maps, and a same-illuminant
    /// table's maps aimed through T, which carry a cross map's white-balance
    /// gain ([`crate::l3::CROSS_AVERAGING_PX`]).
    pub fn colour_averaging(&self) -> f64 {
        self.colour_averaging_px
            .unwrap_or(crate::l3::CROSS_AVERAGING_PX)
    }

    /// The averaging of a same-illuminant table's transfer maps, aimed at XYZ
    /// under the light for lights it was not trained under
    /// ([`crate::l3::UNDER_LIGHT_AVERAGING_PX`]).
    pub fn transfer_averaging(&self) -> f64 {
        self.colour_averaging_px
            .unwrap_or(crate::l3::UNDER_LIGHT_AVERAGING_PX)
    }

    /// The loss this spec's colour maps minimise: as given, or by the number
    /// of training lights. A one-light table minimises its mean ΔE00
    /// ([`ColourLoss::MeanDeltaE`](crate::l3::ColourLoss)); an ensemble keeps
    /// the squared loss, whose compromise between lights served the lights
    /// it was not trained on better. Measured on the six shipped sensors
    /// (Table 1, one capture): with the mean loss on ensembles too, the D65 +
    /// tungsten tables lost under tungsten on both measured Bayer cameras
    /// (Canon 1.91 → 2.01, Nikon 2.22 → 2.30) and under the lamp they never
    /// saw (Canon 3.75 → 3.87, past its baseline's 3.70), and ISET's RGBW
    /// three-light table lost under fluorescent (8.73 → 8.80 against its
    /// matching linear map's 8.35).
    pub fn colour_loss(&self) -> crate::l3::ColourLoss {
        self.colour_loss.unwrap_or(if self.illuminants.len() == 1 {
            crate::l3::ColourLoss::MeanDeltaE
        } else {
            crate::l3::ColourLoss::SquaredDeltaE
        })
    }

    /// The L3 parameters this spec implies for a sensor with `swing` volts.
    pub fn params(&self, swing: f64) -> Result<L3Params, TrainError> {
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
            colour_map: Some(crate::l3::ColourMapFit {
                averaging_px: Some(self.colour_averaging()).filter(|&px| px > 0.0),
                perceptual: true,
                loss: self.colour_loss(),
            }),
            ..L3Params::default()
        };
        p.validate()?;
        Ok(p)
    }
}

/// A training run prepared from a spec: the camera, the training scenes
/// and illuminants, the L3 parameters and the per-level colour maps. It
/// trains in one call ([`TrainingRun::train`]) or in shards
/// ([`TrainingRun::survey_shard`], [`TrainingRun::accumulate_shard`],
/// [`TrainingRun::finish`]; see `src/l3/shards.rs`) with byte-identical
/// tables; both go through the same core functions.
pub struct TrainingRun {
    spec: TrainingSpec,
    design: SensorDesign,
    started: Instant,
    grid: WavelengthGrid,
    camera: Camera,
    params: L3Params,
    sat_threshold: f64,
    geo: PatchGeometry,
    illuminants: Vec<(String, Spectrum)>,
    d65: Spectrum,
    scenes: TrainingScenes,
    noise: NoiseSwitches,
    nm: NoiseModel,
    maps: Option<Vec<ColourMatrix>>,
    /// Which fit a same-illuminant table's transfer maps took, and each
    /// candidate's score on the held-out lights.
    transfer_choice: Option<TransferChoice>,
    /// Per training illuminant, the sensor's channel responses to white.
    neutrals: Vec<Vec<f64>>,
    /// Per training illuminant of a same-illuminant table, `T⁻¹` of its
    /// correction to D65: a pixel's target is `T⁻¹ · xyz_D65`, as its colour
    /// samples' are ([`ColourTarget::ThroughCorrection`]). Empty for a cross
    /// table.
    aim_through: Vec<crate::l3::Mat3>,
    run_key: String,
}

impl TrainingRun {
    /// Check `spec` and prepare everything its batches are simulated from.
    pub fn new(
        design: &SensorDesign,
        spec: &TrainingSpec,
        iset: Option<&IsetData>,
    ) -> Result<Self, TrainError> {
        spec.validate()?;
        let started = Instant::now();
        let grid = WavelengthGrid::default();
        let camera = Camera::new(design, grid, iset)?;
        let swing = design.voltage_swing_v;
        let mut params = spec.params(swing)?;
        let sat_threshold = swing - params.saturation_margin_v;
        let mut geo = PatchGeometry::new(
            params.patch_size,
            camera.cfa(),
            &params.levels,
            sat_threshold,
        )?;
        let illuminants = spec
            .illuminants
            .iter()
            .map(|s| {
                let named = IlluminantSpec::parse(s)?.resolve(iset)?;
                Ok((named.name, named.spd.resample(&grid, Extrapolation::Zero)))
            })
            .collect::<Result<Vec<_>, TrainError>>()?;
        let d65 = cie_illuminant("D65")
            .ok_or_else(|| TrainError::Invalid("D65 missing".into()))?
            .resample(&grid, Extrapolation::Zero);
        let white = Spectrum::constant(grid, 1.0);
        let neutrals = illuminants
            .iter()
            .map(|(_, spd)| Ok(camera.reflectance_response(&white, spd)?.0.to_vec()))
            .collect::<Result<Vec<_>, TrainError>>()?;
        let scenes =
            TrainingScenes::new(grid, iset, spec.seed, spec.scene_size, spec.mean_luminance)?;
        let noise = if spec.noise {
            NoiseSwitches::all()
        } else {
            NoiseSwitches::none()
        };
        let nm = noise_model(design);
        let refl: Vec<_> = crate::scene::natural_reflectances(&grid, iset)
            .map_err(|e| TrainError::Invalid(e.to_string()))?
            .into_iter()
            .map(|(_, s)| s)
            .collect();
        let spds: Vec<_> = illuminants.iter().map(|(_, s)| s.clone()).collect();
        let corrections = same_illuminant_corrections(spec.kind, grid, &refl, &spds)?;
        let mut transfer_choice = None;
        let maps = match params.colour_map {
            Some(ref fit) => {
                let target = match spec.kind {
                    TableKind::CrossIlluminant => ColourTarget::D65,
                    TableKind::SameIlluminant => ColourTarget::ThroughCorrection(&corrections),
                };
                let samples = colour_samples(&camera, &spds, target, &d65, &refl)?;
                let pooled = level_maps(&samples, &params.levels, &nm, swing, fit)?;
                if spec.kind == TableKind::SameIlluminant {
                    let (maps, choice) =
                        transfer_maps(&camera, design, spec, &spds, &corrections, &refl, &params)?;
                    params.transfer_maps = Some(maps);
                    transfer_choice = Some(choice);
                }
                if spec.chroma_classes > 1 {
                    let classes = ChromaClasses::fit_balanced(
                        &samples.channels,
                        &samples.light,
                        &samples.neutral,
                        spec.chroma_classes,
                        MIN_SURFACES_PER_CHANNEL * camera.n_channels(),
                        spec.seed,
                    )?;
                    geo = geo.with_chroma(&classes)?;
                    let maps =
                        band_maps(&samples, &classes, &pooled, &params.levels, &nm, swing, fit)?;
                    params.chroma = Some(classes);
                    Some(maps)
                } else {
                    Some(pooled)
                }
            }
            None => None,
        };
        let run_key = run_key(design, spec, iset.is_some());
        Ok(Self {
            spec: spec.clone(),
            design: design.clone(),
            started,
            grid,
            camera,
            params,
            sat_threshold,
            geo,
            illuminants,
            d65,
            scenes,
            noise,
            nm,
            maps,
            transfer_choice,
            neutrals,
            aim_through: corrections
                .iter()
                .map(inverse_correction)
                .collect::<Result<_, _>>()?,
            run_key,
        })
    }

    /// Batches of the run (one training scene each).
    pub fn n_batches(&self) -> usize {
        self.spec.n_batches()
    }

    /// SHA-256 (hex) of the sensor design and the spec: names the run in
    /// its partial sums, so that parts of different runs are not merged.
    pub fn run_key(&self) -> &str {
        &self.run_key
    }

    /// Split the run into `n_shards` contiguous batch ranges.
    pub fn plan(&self, n_shards: usize) -> Result<Vec<ShardSpec>, TrainError> {
        Ok(plan_shards(self.n_batches(), n_shards)?)
    }

    fn setup(&self) -> TrainSetup<'_> {
        TrainSetup {
            geo: &self.geo,
            params: &self.params,
            noise: self.nm,
            n_batches: self.n_batches(),
            colour_maps: self.maps.as_deref(),
            run_key: &self.run_key,
        }
    }

    fn check_shard(&self, shard: &ShardSpec) -> Result<(), TrainError> {
        if shard.n_batches != self.n_batches() {
            return Err(TrainError::Invalid(format!(
                "shard of {} batches for a run of {}",
                shard.n_batches,
                self.n_batches()
            )));
        }
        Ok(())
    }

    /// Train the whole run in this process.
    pub fn train(
        &self,
        progress: &(dyn Fn(&str, f64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<L3Table, TrainError> {
        let ctl = TrainControl { progress, cancel };
        let frame = |b: usize| self.frame(b);
        let learned = learn(
            &self.geo,
            &self.params,
            self.nm,
            self.n_batches(),
            frame,
            self.maps.as_deref(),
            &ctl,
        )?;
        self.package(learned)
    }

    /// Survey statistics of one shard's batches (phase 1 of a sharded run).
    pub fn survey_shard(
        &self,
        shard: &ShardSpec,
        progress: &(dyn Fn(&str, f64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<SurveyPartial, TrainError> {
        self.check_shard(shard)?;
        let ctl = TrainControl { progress, cancel };
        let frame = |b: usize| self.frame(b);
        Ok(survey_batches(
            &self.setup(),
            shard.batches(),
            &frame,
            &ctl,
        )?)
    }

    /// The classes of the run from its survey shards, merged.
    pub fn classes(&self, surveys: &[SurveyPartial]) -> Result<Classes, TrainError> {
        let all = merge_surveys(surveys)?;
        Ok(classes_from_survey(&self.setup(), &all)?)
    }

    /// Normal equations of one shard's batches for the run's `classes`
    /// (phase 2 of a sharded run).
    pub fn accumulate_shard(
        &self,
        shard: &ShardSpec,
        classes: &Classes,
        progress: &(dyn Fn(&str, f64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<GramPartial, TrainError> {
        self.check_shard(shard)?;
        let ctl = TrainControl { progress, cancel };
        let frame = |b: usize| self.frame(b);
        Ok(accumulate_batches(
            &self.setup(),
            classes,
            shard.batches(),
            &frame,
            &ctl,
        )?)
    }

    /// Merge every shard's normal equations in batch order, solve, and
    /// package the table (`training_seconds` counts from [`TrainingRun::new`]
    /// in this process).
    pub fn finish(
        &self,
        classes: Classes,
        parts: Vec<GramPartial>,
        progress: &(dyn Fn(&str, f64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<L3Table, TrainError> {
        Ok(self.finish_timed(classes, parts, progress, cancel)?.0)
    }

    /// [`TrainingRun::finish`], also giving the seconds the merge of the
    /// sums took (the rest is the solve and the packaging).
    pub fn finish_timed(
        &self,
        classes: Classes,
        parts: Vec<GramPartial>,
        progress: &(dyn Fn(&str, f64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<(L3Table, f64), TrainError> {
        let ctl = TrainControl { progress, cancel };
        if parts.iter().any(|p| p.run_key != self.run_key) {
            return Err(L3Error::PartialSums("sums of another training run".into()).into());
        }
        let t = Instant::now();
        let grams = merge_partials(&classes, parts)?;
        let merged = t.elapsed().as_secs_f64();
        let learned = solve_learned(&self.setup(), classes, grams, &ctl)?;
        Ok((self.package(learned)?, merged))
    }

    /// Batch `b`: scene `b` under illuminant `b mod n`, at every level
    /// (exposure jittered across the level's bin) and CFA shift.
    fn frame(&self, b: usize) -> Result<Vec<TrainingFrame>, L3Error> {
        let (spec, camera, design) = (&self.spec, &self.camera, &self.design);
        let levels = &self.params.levels;
        let cfa = camera.cfa();
        let n_ill = self.illuminants.len();
        let (s, i) = (b, b % n_ill);
        let (ill_name, ill) = &self.illuminants[i];
        let scene = self.scenes.scene(s, ill, ill_name)?;
        let optical = camera.optical_image(&scene).map_err(TrainError::from)?;
        let rates = camera.channel_rates(&optical).map_err(TrainError::from)?;
        // the target: XYZ under D65, taken back through the light's T for a
        // same-illuminant table
        let xyz_rates = camera
            .xyz_rates(&optical, &self.d65)
            .map_err(TrainError::from)?;
        let mut xyz_rates = xyz_rates.as_slice().map(|v| v.to_vec()).unwrap_or_default();
        if let Some(inv) = self.aim_through.get(i) {
            for px in xyz_rates.chunks_exact_mut(3) {
                let v = mat3_mul_vec(inv, [px[0] as f64, px[1] as f64, px[2] as f64]);
                for (o, v) in px.iter_mut().zip(v) {
                    *o = v as f32;
                }
            }
        }
        // luminance statistic of the noise-free frame: median over pixels of
        // the mean over channels of the channel rates
        let (_, rows, cols) = rates.dim();
        let mut lum: Vec<f32> = (0..rows * cols)
            .map(|p| {
                let (r, c) = (p / cols, p % cols);
                (0..rates.dim().0).map(|ch| rates[[ch, r, c]]).sum::<f32>() / rates.dim().0 as f32
            })
            .collect();
        lum.sort_by(f32::total_cmp);
        let median_rate =
            lum[lum.len() / 2].max(1e-3) as f64 * design.conversion_gain_v() * design.analog_gain;
        let mut rng = ChaCha8Rng::seed_from_u64(mix(spec.seed, b as u64, 0x5eed));
        let mut frames = Vec::with_capacity(levels.len() * cfa.n_positions());
        for (l, &level) in levels.iter().enumerate() {
            // jitter the level across its bin (geometric midpoints)
            let lo = if l == 0 {
                level * 0.7
            } else {
                (level * levels[l - 1]).sqrt()
            };
            let hi = if l + 1 == levels.len() {
                level * 1.1
            } else {
                (level * levels[l + 1]).sqrt()
            };
            for shift in 0..cfa.n_positions() {
                let target = (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp();
                let exposure = target / median_rate;
                let (dr, dc) = (shift / cfa.cols, shift % cfa.cols);
                let shifted = cfa.shifted(dr, dc);
                let mean = mosaic(&rates, &shifted).map_err(TrainError::from)?;
                let seed = mix(spec.seed, b as u64, (l * 64 + shift) as u64);
                let volts = camera
                    .capture(&mean, exposure, &self.noise, seed)
                    .map_err(TrainError::from)?;
                let t = exposure as f32;
                frames.push(TrainingFrame {
                    width: cols,
                    height: rows,
                    volts: volts.into_raw_vec_and_offset().0,
                    xyz: xyz_rates.iter().map(|v| v * t).collect(),
                    cfa_shift: (dr, dc),
                    neutral: self
                        .params
                        .chroma
                        .as_ref()
                        .map(|_| self.neutrals[i].clone()),
                });
            }
        }
        Ok(frames)
    }

    fn package(&self, learned: Learned) -> Result<L3Table, TrainError> {
        let (spec, design) = (&self.spec, &self.design);
        let cfa = self.camera.cfa().clone();
        let n_batches = self.n_batches();
        let samples = learned.samples;
        let maps = self.maps.as_deref();
        let meta = TableMeta {
            format: "l3-table".into(),
            version: TABLE_FORMAT_VERSION,
            kind: spec.kind,
            train_illuminants: self.illuminants.iter().map(|(n, _)| n.clone()).collect(),
            target_illuminant: match spec.kind {
                TableKind::SameIlluminant => "same".into(),
                TableKind::CrossIlluminant => "D65".into(),
            },
            sensor_name: design.name.clone(),
            sensor: serde_json::to_value(design).unwrap_or(serde_json::Value::Null),
            cfa: cfa.clone(),
            grid: self.grid,
            params: self.params.clone(),
            voltage_swing: design.voltage_swing_v,
            saturation_threshold: self.sat_threshold,
            sat_cases: vec![0],
            xyz_scale_note: format!(
                "XYZ in volts-equivalent: an equal-energy irradiance gives Y equal to the mean channel volts (kappa = {:.6e})",
                self.camera.xyz_scale()
            ),
            seed: spec.seed,
            created_unix_s: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
            training_seconds: self.started.elapsed().as_secs_f64(),
            summary: serde_json::json!({
                "spec": spec,
                "batches": n_batches,
                "frames": n_batches * self.params.levels.len() * cfa.n_positions(),
                "samples": samples,
                "colour_maps": maps.map(map_summary),
                "transfer_fit": self.transfer_choice,
            }),
        };
        let mut table = package(meta, learned)?;
        table.meta.training_seconds = self.started.elapsed().as_secs_f64();
        Ok(table)
    }
}

/// A same-illuminant table's maps for lights it was not trained under, one
/// per level, aimed at XYZ under the light (which any light's T can take),
/// with the fit, on all its training lights or (an ensemble) on one of them,
/// that [`choose_transfer_fit`] picks on the held-out lights (see
/// `transfer_fit`).
fn transfer_maps(
    camera: &Camera,
    design: &SensorDesign,
    spec: &TrainingSpec,
    lights: &[Spectrum],
    corrections: &[crate::l3::Mat3],
    refl: &[Spectrum],
    params: &L3Params,
) -> Result<(Vec<ColourMatrix>, TransferChoice), TrainError> {
    let fit = params
        .colour_map
        .ok_or_else(|| TrainError::Invalid("transfer maps need a colour map fit".into()))?;
    let d65 = cie_illuminant("D65")
        .ok_or_else(|| TrainError::Invalid("D65 missing".into()))?
        .resample(camera.grid(), Extrapolation::Zero);
    let (nm, swing) = (noise_model(design), design.voltage_swing_v);
    let averaging_px = Some(spec.transfer_averaging()).filter(|&px| px > 0.0);
    // the colour maps' fit, each error weighed after the training light's T
    let perceptual = ColourMapFit {
        averaging_px,
        ..fit
    };
    // plain least squares in XYZ: no T, no perceptual weights
    let least_squares = ColourMapFit {
        averaging_px,
        perceptual: false,
        loss: ColourLoss::SquaredDeltaE,
    };
    // each fit on every training light, then (an ensemble) on each alone
    let singles = if lights.len() > 1 { lights.len() } else { 0 };
    let subsets = std::iter::once(0..lights.len()).chain((0..singles).map(|i| i..i + 1));
    let mut candidates = Vec::new();
    for range in subsets {
        let mismatch = || TrainError::Invalid("lights, corrections and names differ".into());
        let spds = lights.get(range.clone()).ok_or_else(mismatch)?;
        let ts = corrections.get(range.clone()).ok_or_else(mismatch)?;
        let names = spec.illuminants.get(range).ok_or_else(mismatch)?.to_vec();
        let weighed = colour_samples(camera, spds, ColourTarget::UnderLight(ts), &d65, refl)?;
        let as_is = colour_samples(camera, spds, ColourTarget::UnderLight(&[]), &d65, refl)?;
        candidates.push((TransferFit::Perceptual, names.clone(), weighed, perceptual));
        candidates.push((TransferFit::LeastSquares, names, as_is, least_squares));
    }
    let level = params.levels.first().copied().unwrap_or(swing);
    let noise_free = candidates
        .iter()
        .map(|(fit, names, samples, how)| {
            let how = ColourMapFit {
                averaging_px: None,
                ..*how
            };
            let map = level_maps(samples, &[level], &nm, swing, &how)?
                .pop()
                .ok_or_else(|| TrainError::Invalid("no transfer map".into()))?;
            Ok((*fit, names.clone(), map))
        })
        .collect::<Result<Vec<_>, TrainError>>()?;
    let held_out = held_out_lights(camera, &spec.illuminants, refl)?;
    let (best, choice) = choose_transfer_fit(&noise_free, &held_out);
    let (_, _, samples, how) = candidates
        .get(best)
        .ok_or_else(|| TrainError::Invalid("no transfer map candidate".into()))?;
    Ok((
        level_maps(samples, &params.levels, &nm, swing, how)?,
        choice,
    ))
}

/// SHA-256 (hex) of what a run's batches depend on.
/// Bumped whenever the trainer's output for a given spec changes (targets,
/// colour maps, their noise terms), so that a shard's partial sums from an
/// older trainer are refused rather than merged with this one's
/// ([`TrainingRun::run_key`]). 2: same-illuminant maps aimed through T with
/// the cross averaging; 3: transfer maps fitted as the held-out lights
/// choose; 4: an ensemble's transfer maps may take one training light's fit.
const TRAINER_REVISION: u32 = 4;

fn run_key(design: &SensorDesign, spec: &TrainingSpec, iset: bool) -> String {
    let text = serde_json::json!({
        "design": design,
        "spec": spec,
        "iset": iset,
        "partial_format": crate::l3::PARTIAL_FORMAT_VERSION,
        "trainer": TRAINER_REVISION,
    })
    .to_string();
    hex::encode(Sha256::digest(text.as_bytes()))
}

/// Train a table for `design` as `spec` says. `progress(stage, fraction)`
/// is called as work completes; setting `cancel` stops the run with
/// [`L3Error::Canceled`].
pub fn train_table(
    design: &SensorDesign,
    spec: &TrainingSpec,
    iset: Option<&IsetData>,
    progress: &(dyn Fn(&str, f64) + Sync),
    cancel: &AtomicBool,
) -> Result<L3Table, TrainError> {
    TrainingRun::new(design, spec, iset)?.train(progress, cancel)
}

/// The per-level colour maps as JSON for the table's summary: `[level][channel]
/// = [X, Y, Z]` weights.
fn map_summary(maps: &[ColourMatrix]) -> serde_json::Value {
    serde_json::Value::from(
        maps.iter()
            .map(|m| serde_json::json!(m.m))
            .collect::<Vec<_>>(),
    )
}

/// A well-mixed 64-bit seed from three inputs (SplitMix64 finaliser).
pub fn mix(a: u64, b: u64, c: u64) -> u64 {
    let mut z = a
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(b.wrapping_mul(0xBF58_476D_1CE4_E5B9))
        .wrapping_add(c.wrapping_mul(0x94D0_49BB_1331_11EB))
        .wrapping_add(0x2545_F491_4F6C_DD1D);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
