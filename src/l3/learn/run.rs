//! Training an L3 table from the camera simulation: the training scenes,
//! the frames simulated from them, and the call into the learner
//! (docs/design.md §5). Shared by the CLI and the service's training jobs.
//!
//! A [`TrainingRun`] trains in one call or in shards (batch ranges) whose
//! partial sums can be computed on other machines and merged into the same
//! table bytes (`shards.rs` explains why they are equal).

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sha2::{Digest, Sha256};

use super::LearnError;
use super::colour_map::{MapInputs, band_maps, level_maps};
use super::partial_format::PARTIAL_FORMAT_VERSION;
use super::scenes::{TrainingScenes, mix};
use super::setup::{ClassMaps, Learned, TrainControl, TrainSetup, TrainingFrame};
use super::shards::{
    Classes, GramPartial, ShardSpec, SurveyPartial, merge_partials, merge_surveys, plan_shards,
};
use super::solve::{package, solve_learned};
use super::spec::TrainingSpec;
use super::trainer::{accumulate_batches, classes_from_survey, learn, survey_batches};
use super::transfer_fit::{TransferChoice, transfer_maps};
use crate::baseline::ColourMatrix;
use crate::camera::{Camera, NoiseSwitches, SensorDesign, mosaic};
use crate::colour::{Cmfs, mat3_mul_vec, xy};
use crate::l3::classify::{ChromaClasses, MIN_SURFACES_PER_CHANNEL, PatchGeometry};
use crate::l3::correct::{
    ColourTarget, Mat3, NoiseModel, colour_samples, inverse_correction, noise_model,
    same_illuminant_corrections,
};
use crate::l3::params::{ColourMapFit, L3Params};
use crate::l3::table::{L3Table, TABLE_FORMAT_VERSION, TableKind, TableMeta};
use crate::spectral::{
    Extrapolation, IlluminantSpec, IsetData, Spectrum, WavelengthGrid, cie_illuminant,
};

/// A training run prepared from a spec: the camera, the training scenes
/// and illuminants, the L3 parameters and the per-level colour maps. It
/// trains in one call ([`TrainingRun::train`]) or in shards
/// ([`TrainingRun::survey_shard`], [`TrainingRun::accumulate_shard`],
/// [`TrainingRun::finish`]; see `shards.rs`) with byte-identical
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
    /// The texture classes' own maps, when the parameters ask for them
    /// ([`L3Params::texture_averaging_px`]).
    texture_maps: Option<Vec<ColourMatrix>>,
    /// Which fit a same-illuminant table's transfer maps took, and each
    /// candidate's score on the held-out lights.
    transfer_choice: Option<TransferChoice>,
    /// Per training illuminant, the sensor's channel responses to white.
    neutrals: Vec<Vec<f64>>,
    /// Per training illuminant of a same-illuminant table, `T⁻¹` of its
    /// correction to D65: a pixel's target is `T⁻¹ · xyz_D65`, as its colour
    /// samples' are ([`ColourTarget::ThroughCorrection`]). Empty for a cross
    /// table.
    aim_through: Vec<Mat3>,
    run_key: String,
}

/// The spec's training lights, named and on `grid`, and D65 on `grid`.
fn training_lights(
    spec: &TrainingSpec,
    iset: Option<&IsetData>,
    grid: WavelengthGrid,
) -> Result<(Vec<(String, Spectrum)>, Spectrum), LearnError> {
    let illuminants = spec
        .illuminants
        .iter()
        .map(|s| {
            let named = IlluminantSpec::parse(s)?.resolve(iset)?;
            Ok((named.name, named.spd.resample(&grid, Extrapolation::Zero)))
        })
        .collect::<Result<Vec<_>, LearnError>>()?;
    let d65 = cie_illuminant("D65")
        .ok_or_else(|| LearnError::Invalid("D65 missing".into()))?
        .resample(&grid, Extrapolation::Zero);
    Ok((illuminants, d65))
}

impl TrainingRun {
    /// Check `spec` and prepare everything its batches are simulated from.
    pub fn new(
        design: &SensorDesign,
        spec: &TrainingSpec,
        iset: Option<&IsetData>,
    ) -> Result<Self, LearnError> {
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
        let (illuminants, d65) = training_lights(spec, iset, grid)?;
        let white = Spectrum::constant(grid, 1.0);
        let neutrals = illuminants
            .iter()
            .map(|(_, spd)| Ok(camera.reflectance_response(&white, spd)?.0.to_vec()))
            .collect::<Result<Vec<_>, LearnError>>()?;
        let scenes =
            TrainingScenes::new(grid, iset, spec.seed, spec.scene_size, spec.mean_luminance)?;
        let noise = if spec.noise {
            NoiseSwitches::all()
        } else {
            NoiseSwitches::none()
        };
        let nm = noise_model(design);
        let refl: Vec<_> = crate::scene::natural_reflectances(&grid, iset)
            .map_err(|e| LearnError::Invalid(e.to_string()))?
            .into_iter()
            .map(|(_, s)| s)
            .collect();
        let spds: Vec<_> = illuminants.iter().map(|(_, s)| s.clone()).collect();
        let names: Vec<_> = illuminants.iter().map(|(n, _)| n.clone()).collect();
        let corrections = same_illuminant_corrections(spec.kind, grid, &refl, &spds)?;
        let mut transfer_choice = None;
        let mut texture_maps = None;
        let maps = match params.colour_map {
            Some(fit) => {
                let inputs = MapInputs {
                    camera: &camera,
                    design,
                    spec,
                    names: &names,
                    lights: &spds,
                    corrections: &corrections,
                    d65: &d65,
                    refl: &refl,
                };
                let fitted = fit_colour_maps(&inputs, &fit, &params, geo)?;
                geo = fitted.geo;
                if let Some((maps, choice)) = fitted.transfer {
                    params.transfer_maps = Some(maps);
                    transfer_choice = Some(choice);
                }
                if let Some(classes) = fitted.chroma {
                    params.chroma = Some(classes);
                }
                texture_maps = fitted.texture;
                Some(fitted.maps)
            }
            None => None,
        };
        let run_key = run_key(design, spec, iset.is_some());
        Ok(Self {
            spec: spec.clone(),
            // the curves as the table records them: no file it was trained from is needed
            design: design.clone().portable(iset),
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
            texture_maps,
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
    pub fn plan(&self, n_shards: usize) -> Result<Vec<ShardSpec>, LearnError> {
        plan_shards(self.n_batches(), n_shards)
    }

    fn setup(&self) -> TrainSetup<'_> {
        TrainSetup {
            geo: &self.geo,
            params: &self.params,
            noise: self.nm,
            n_batches: self.n_batches(),
            colour_maps: self.class_maps(),
            run_key: &self.run_key,
        }
    }

    /// The maps that fix the kernels' channel sums: the flat classes', and the texture
    /// classes' own where the run fitted them.
    fn class_maps(&self) -> Option<ClassMaps<'_>> {
        self.maps
            .as_deref()
            .map(|flat| ClassMaps::new(flat, self.texture_maps.as_deref()))
    }

    fn check_shard(&self, shard: &ShardSpec) -> Result<(), LearnError> {
        if shard.n_batches != self.n_batches() {
            return Err(LearnError::Invalid(format!(
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
    ) -> Result<L3Table, LearnError> {
        let ctl = TrainControl { progress, cancel };
        let frame = |b: usize| self.frame(b);
        let learned = learn(
            &self.geo,
            &self.params,
            self.nm,
            self.n_batches(),
            frame,
            self.class_maps(),
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
    ) -> Result<SurveyPartial, LearnError> {
        self.check_shard(shard)?;
        let ctl = TrainControl { progress, cancel };
        let frame = |b: usize| self.frame(b);
        survey_batches(&self.setup(), shard.batches(), &frame, &ctl)
    }

    /// The classes of the run from its survey shards, merged.
    pub fn classes(&self, surveys: &[SurveyPartial]) -> Result<Classes, LearnError> {
        let all = merge_surveys(surveys)?;
        classes_from_survey(&self.setup(), &all)
    }

    /// Normal equations of one shard's batches for the run's `classes`
    /// (phase 2 of a sharded run).
    pub fn accumulate_shard(
        &self,
        shard: &ShardSpec,
        classes: &Classes,
        progress: &(dyn Fn(&str, f64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<GramPartial, LearnError> {
        self.check_shard(shard)?;
        let ctl = TrainControl { progress, cancel };
        let frame = |b: usize| self.frame(b);
        accumulate_batches(&self.setup(), classes, shard.batches(), &frame, &ctl)
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
    ) -> Result<L3Table, LearnError> {
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
    ) -> Result<(L3Table, f64), LearnError> {
        let ctl = TrainControl { progress, cancel };
        if parts.iter().any(|p| p.run_key != self.run_key) {
            return Err(LearnError::PartialSums(
                "sums of another training run".into(),
            ));
        }
        let t = Instant::now();
        let grams = merge_partials(&classes, parts)?;
        let merged = t.elapsed().as_secs_f64();
        let learned = solve_learned(&self.setup(), classes, grams, &ctl)?;
        Ok((self.package(learned)?, merged))
    }

    /// Batch `b`: scene `b` under illuminant `b mod n`, at every level
    /// (exposure jittered across the level's bin) and CFA shift.
    fn frame(&self, b: usize) -> Result<Vec<TrainingFrame>, LearnError> {
        let (spec, camera, design) = (&self.spec, &self.camera, &self.design);
        let levels = &self.params.levels;
        let cfa = camera.cfa();
        let n_ill = self.illuminants.len();
        let (s, i) = (b, b % n_ill);
        let (ill_name, ill) = &self.illuminants[i];
        let scene = self.scenes.scene(s, ill, ill_name).map_err(frame_error)?;
        let optical = camera.optical_image(&scene).map_err(frame_error)?;
        let rates = camera.channel_rates(&optical).map_err(frame_error)?;
        // the target: XYZ under D65, taken back through the light's T for a
        // same-illuminant table
        let xyz_rates = camera.xyz_rates(&optical, &self.d65).map_err(frame_error)?;
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
                let mean = mosaic(&rates, &shifted).map_err(frame_error)?;
                let seed = mix(spec.seed, b as u64, (l * 64 + shift) as u64);
                let volts = camera
                    .capture(&mean, exposure, &self.noise, seed)
                    .map_err(frame_error)?;
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

    fn package(&self, learned: Learned) -> Result<L3Table, LearnError> {
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
            train_white_xy: {
                let cmfs = Cmfs::cie1931(&self.grid);
                self.illuminants
                    .iter()
                    .map(|(_, spd)| cmfs.white(spd).ok().map(xy))
                    .collect::<Option<Vec<_>>>()
                    .unwrap_or_default()
            },
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
                "texture_colour_maps": self.texture_maps.as_deref().map(map_summary),
                "transfer_fit": self.transfer_choice,
            }),
        };
        let mut table = package(meta, learned)?;
        table.meta.training_seconds = self.started.elapsed().as_secs_f64();
        Ok(table)
    }
}

/// A run's colour maps, and what they bring into its parameters and geometry.
struct FittedMaps {
    /// One per band (level × chroma classes + class).
    maps: Vec<ColourMatrix>,
    /// The geometry, with the chroma classes when the spec asks for them.
    geo: PatchGeometry,
    chroma: Option<ChromaClasses>,
    /// A same-illuminant table's transfer maps and the fit they took.
    transfer: Option<(Vec<ColourMatrix>, TransferChoice)>,
    /// The texture classes' own maps (one per band), fitted for
    /// [`L3Params::texture_averaging_px`] pixels.
    texture: Option<Vec<ColourMatrix>>,
}

/// The colour maps of a run with parameters `params` (before its transfer maps and chroma
/// classes) and geometry `geo`, fitted as `fit` says: every level's map on the samples
/// aimed as the table's kind wants, a same-illuminant table's transfer maps, and with
/// chroma classes each class's maps.
fn fit_colour_maps(
    inputs: &MapInputs,
    fit: &ColourMapFit,
    params: &L3Params,
    geo: PatchGeometry,
) -> Result<FittedMaps, LearnError> {
    let MapInputs {
        camera,
        design,
        spec,
        lights,
        corrections,
        d65,
        refl,
        ..
    } = *inputs;
    let (nm, swing) = (noise_model(design), design.voltage_swing_v);
    let target = match spec.kind {
        TableKind::CrossIlluminant => ColourTarget::D65,
        TableKind::SameIlluminant => ColourTarget::ThroughCorrection(corrections),
    };
    let samples = colour_samples(camera, lights, target, d65, refl)?;
    let pooled = level_maps(&samples, &params.levels, &nm, swing, fit)?;
    let texture_fit = params.texture_averaging_px.map(|px| ColourMapFit {
        averaging_px: Some(px),
        ..*fit
    });
    let texture_pooled = texture_fit
        .as_ref()
        .map(|f| level_maps(&samples, &params.levels, &nm, swing, f))
        .transpose()?;
    let transfer = if spec.kind == TableKind::SameIlluminant {
        Some(transfer_maps(inputs, params)?)
    } else {
        None
    };
    if spec.chroma_classes > 1 {
        let classes = ChromaClasses::fit_balanced(
            &samples.channels,
            &samples.light,
            &samples.neutral,
            spec.chroma_classes,
            MIN_SURFACES_PER_CHANNEL * camera.n_channels(),
            spec.seed,
        )?;
        let geo = geo.with_chroma(&classes)?;
        let maps = band_maps(&samples, &classes, &pooled, &params.levels, &nm, swing, fit)?;
        let texture = match (texture_fit, texture_pooled) {
            (Some(f), Some(p)) => Some(band_maps(
                &samples,
                &classes,
                &p,
                &params.levels,
                &nm,
                swing,
                &f,
            )?),
            _ => None,
        };
        Ok(FittedMaps {
            maps,
            geo,
            chroma: Some(classes),
            transfer,
            texture,
        })
    } else {
        Ok(FittedMaps {
            maps: pooled,
            geo,
            chroma: None,
            transfer,
            texture: texture_pooled,
        })
    }
}

/// A frame's error as the learner has always reported it: its own errors as they are, and
/// the simulation's (the camera, the scene, the spectral data, the spec) as invalid input.
fn frame_error(e: impl Into<LearnError>) -> LearnError {
    match e.into() {
        e @ (LearnError::Invalid(_)
        | LearnError::Camera(_)
        | LearnError::Scene(_)
        | LearnError::Spectral(_)) => LearnError::InvalidInput(e.to_string()),
        e => e,
    }
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
        "partial_format": PARTIAL_FORMAT_VERSION,
        "trainer": TRAINER_REVISION,
    })
    .to_string();
    hex::encode(Sha256::digest(text.as_bytes()))
}

/// Train a table for `design` as `spec` says. `progress(stage, fraction)`
/// is called as work completes; setting `cancel` stops the run with
/// [`LearnError::Canceled`].
pub fn train_table(
    design: &SensorDesign,
    spec: &TrainingSpec,
    iset: Option<&IsetData>,
    progress: &(dyn Fn(&str, f64) + Sync),
    cancel: &AtomicBool,
) -> Result<L3Table, LearnError> {
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
