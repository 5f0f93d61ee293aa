//! What every stage of a training run shares: the frames it learns from, its progress
//! and cancellation hooks, its setup (geometry, parameters, noise, colour maps) and class
//! layout, and what it produces before packaging.

use std::ops::Range;
use std::sync::atomic::AtomicBool;

use super::LearnError;
use super::shards::{Classes, SurveyShape};
use crate::baseline::ColourMatrix;
use crate::l3::classify::PatchGeometry;
use crate::l3::correct::NoiseModel;
use crate::l3::params::{L3Params, RidgeChoice};
use crate::l3::table::ClassReport;

/// One training frame: a noisy mosaic in volts and the ideal XYZ at every
/// pixel (interleaved), captured with the CFA shifted by `cfa_shift`.
#[derive(Clone, Debug)]
pub struct TrainingFrame {
    pub width: usize,
    pub height: usize,
    pub volts: Vec<f32>,
    pub xyz: Vec<f32>,
    /// Pixel (r, c) sits under the base CFA's (r + dr, c + dc) filter.
    pub cfa_shift: (usize, usize),
    /// The sensor's channel responses to white under the frame's light, which
    /// chroma classes balance by ([`PatchGeometry::under_light`]); `None`: the
    /// classes' reference light.
    pub neutral: Option<Vec<f64>>,
}

/// Progress and cancellation hooks of a training run.
pub struct TrainControl<'a> {
    /// Called with a stage name and the fraction done (0–1) of the whole run.
    pub progress: &'a (dyn Fn(&str, f64) + Sync),
    pub cancel: &'a AtomicBool,
}

/// Histogram bins of the contrast survey (log-spaced, see `trainer.rs`).
pub(super) const HIST_BINS: usize = 480;

/// The run's class layout: positions × bands (luminance levels × chroma
/// classes, band = level × chroma classes + class) × saturation.
pub(super) struct Dims {
    pub(super) n_pos: usize,
    pub(super) n_bands: usize,
    pub(super) n_chroma: usize,
    pub(super) n_masks: usize,
}

impl Dims {
    pub(super) fn pl_mask(&self, pos: usize, band: usize, mask: u32) -> usize {
        (pos * self.n_bands + band) * self.n_masks + mask as usize
    }

    pub(super) fn n_levels(&self) -> usize {
        self.n_bands / self.n_chroma.max(1)
    }
}

/// Training result before packaging: kernels, thresholds, reports and the
/// saturation cases found.
pub struct Learned {
    pub kernels: Vec<f32>,
    pub contrast_thresholds: Vec<f32>,
    pub reports: Vec<ClassReport>,
    pub sat_cases: Vec<u32>,
    pub samples: u64,
}

/// The colour maps (one per band) that fix the channel sums of the unsaturated kernels: the
/// flat classes' and the texture classes' (the same maps unless the table asks for its own
/// texture maps, [`crate::l3::L3Params::texture_averaging_px`]).
#[derive(Clone, Copy, Debug)]
pub struct ClassMaps<'a> {
    pub flat: &'a [ColourMatrix],
    pub texture: &'a [ColourMatrix],
}

impl<'a> ClassMaps<'a> {
    /// `flat` for every class, and `texture` for the texture classes when given.
    pub fn new(flat: &'a [ColourMatrix], texture: Option<&'a [ColourMatrix]>) -> Self {
        Self {
            flat,
            texture: texture.unwrap_or(flat),
        }
    }

    /// The map of band `band` for the flat (`texture` false) or texture classes.
    pub fn at(&self, band: usize, texture: bool) -> &'a ColourMatrix {
        if texture {
            &self.texture[band]
        } else {
            &self.flat[band]
        }
    }
}

/// What every stage and every shard of a training run share.
#[derive(Clone, Copy)]
pub struct TrainSetup<'a> {
    pub geo: &'a PatchGeometry,
    pub params: &'a L3Params,
    pub noise: NoiseModel,
    /// Batches of the run, numbered `0..n_batches`.
    pub n_batches: usize,
    /// The channel sums of every unsaturated kernel; `None` leaves every kernel to plain
    /// ridge regression.
    pub colour_maps: Option<ClassMaps<'a>>,
    /// Names the run in its partial sums, whose merge refuses parts of
    /// another run (e.g. a digest of the training spec).
    pub run_key: &'a str,
}

impl TrainSetup<'_> {
    pub fn validate(&self) -> Result<(), LearnError> {
        let (geo, params) = (self.geo, self.params);
        params.validate()?;
        if self.n_batches == 0 {
            return Err(LearnError::InvalidParams("no training frames".into()));
        }
        if params.ridge == RidgeChoice::NoiseVariance && self.noise.conversion_gain_v <= 0.0 {
            return Err(LearnError::InvalidParams(
                "noise-variance ridge needs a noise model".into(),
            ));
        }
        if let Some(maps) = self.colour_maps {
            for set in [maps.flat, maps.texture] {
                if set.len() != geo.n_bands() || set.iter().any(|m| m.m.len() != geo.n_channels()) {
                    return Err(LearnError::InvalidParams(format!(
                        "{} colour maps for {} bands and {} channels",
                        set.len(),
                        geo.n_bands(),
                        geo.n_channels()
                    )));
                }
            }
        }
        Ok(())
    }

    pub(super) fn dims(&self) -> Dims {
        Dims {
            n_pos: self.geo.n_positions(),
            n_bands: self.geo.n_bands(),
            n_chroma: self.geo.n_chroma(),
            n_masks: 1 << self.geo.n_channels(),
        }
    }

    /// The sizes of this run's survey.
    pub fn survey_shape(&self) -> SurveyShape {
        let d = self.dims();
        SurveyShape {
            n_positions: d.n_pos,
            n_levels: d.n_bands,
            n_masks: d.n_masks,
            bins: HIST_BINS,
        }
    }

    /// Classes of the run for `classes`' saturation cases.
    pub fn n_classes(&self, classes: &Classes) -> usize {
        let d = self.dims();
        d.n_pos * d.n_bands * classes.n_sat() * 2
    }

    pub(super) fn check_range(&self, batches: &Range<usize>) -> Result<(), LearnError> {
        if batches.start >= batches.end || batches.end > self.n_batches {
            return Err(LearnError::InvalidParams(format!(
                "batches {}..{} of 0..{}",
                batches.start, batches.end, self.n_batches
            )));
        }
        Ok(())
    }
}
