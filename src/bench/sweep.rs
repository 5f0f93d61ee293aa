//! The configurations of the sweep, the options of a run, and the conventional baselines.

use serde::{Deserialize, Serialize};

use super::BenchError;
use crate::baseline::ColourMatrix;
use crate::camera::Camera;
use crate::eval::{ChannelSet, ChartSetup, ColourFit, fit_colour_matrix};
use crate::l3::correct::IlluminantEntry;
use crate::l3::table::TableKind;
use crate::spectral::IsetData;

/// Which tables an L3 configuration trains.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TableChoice {
    /// One same-illuminant table on D65 + every acquisition illuminant, then T.
    SiEnsemble,
    /// One cross-illuminant table (→ D65) per acquisition illuminant.
    CrossPerIlluminant,
}

/// One L3 configuration of the sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct L3Config {
    pub name: String,
    pub patch_size: usize,
    pub levels: usize,
    pub contrast_classes: bool,
    pub saturation_classes: bool,
    pub tables: TableChoice,
    /// Chroma classes per level (`TrainingSpec::chroma_classes`; 1: no split).
    #[serde(default = "one")]
    pub chroma_classes: usize,
}

fn one() -> usize {
    1
}

impl L3Config {
    /// The default: patch 5, 20 levels, contrast and saturation classes,
    /// [`crate::l3::learn::DEFAULT_CHROMA_CLASSES`] chroma classes, SI ensemble + T.
    pub fn default_config() -> Self {
        Self {
            name: "default (5×5, 20 lv, 8 chroma, SI+T)".into(),
            patch_size: 5,
            levels: 20,
            contrast_classes: true,
            saturation_classes: true,
            tables: TableChoice::SiEnsemble,
            chroma_classes: crate::l3::learn::DEFAULT_CHROMA_CLASSES,
        }
    }

    fn with(name: &str, f: impl FnOnce(&mut Self)) -> Self {
        let mut c = Self::default_config();
        c.name = name.into();
        f(&mut c);
        c
    }
}

/// The full sweep: the default and one change at a time from it.
pub fn default_sweep() -> Vec<L3Config> {
    vec![
        L3Config::default_config(),
        L3Config::with("patch 3", |c| c.patch_size = 3),
        L3Config::with("patch 7", |c| c.patch_size = 7),
        L3Config::with("10 levels", |c| c.levels = 10),
        L3Config::with("40 levels", |c| c.levels = 40),
        L3Config::with("no contrast classes", |c| c.contrast_classes = false),
        L3Config::with("no saturation classes", |c| c.saturation_classes = false),
        L3Config::with("I tables", |c| c.tables = TableChoice::CrossPerIlluminant),
        L3Config::with("one chroma class", |c| c.chroma_classes = 1),
        L3Config::with("4 chroma classes", |c| c.chroma_classes = 4),
    ]
}

/// The configurations of the sensor sweep: the default and the I tables,
/// each with the default chroma classes and with one.
pub(super) fn sensor_sweep_configs() -> Vec<L3Config> {
    vec![
        L3Config::default_config(),
        L3Config::with("I tables", |c| c.tables = TableChoice::CrossPerIlluminant),
        L3Config::with("one chroma class", |c| c.chroma_classes = 1),
        L3Config::with("I tables, one chroma class", |c| {
            c.tables = TableChoice::CrossPerIlluminant;
            c.chroma_classes = 1;
        }),
    ]
}

/// Options of a benchmark run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BenchOptions {
    pub configs: Vec<L3Config>,
    /// Training scenes per table, and their side in pixels.
    pub scenes: usize,
    pub scene_size: usize,
    /// Timed runs per throughput figure (after one untimed warm-up run).
    pub runs: usize,
    pub seed: u64,
    /// The throughput frame (a simulated tile repeated to this size).
    pub frame_width: usize,
    pub frame_height: usize,
    pub tile_width: usize,
    pub tile_height: usize,
    /// Acquisition illuminants of the colour evaluation (tungsten first; the
    /// throughput frame is simulated under the first).
    pub acquisitions: Vec<String>,
    pub chart: ChartSetup,
    /// Exposure factor of the low-light column (relative to auto-exposure).
    #[serde(default = "default_low_light")]
    pub low_light_factor: f64,
    /// Measure the skips and encoders on the default table.
    #[serde(default = "yes")]
    pub skips: bool,
}

fn default_low_light() -> f64 {
    0.1
}

fn yes() -> bool {
    true
}

impl BenchOptions {
    /// The full sweep on a 12 MP (4000×3000) frame, 5 runs, 48 scenes.
    pub fn full() -> Self {
        Self {
            configs: default_sweep(),
            scenes: 48,
            scene_size: 96,
            runs: 5,
            seed: 1,
            frame_width: 4000,
            frame_height: 3000,
            tile_width: 1000,
            tile_height: 750,
            acquisitions: vec!["Tungsten".into(), "Fluorescent".into()],
            chart: ChartSetup::default(),
            low_light_factor: default_low_light(),
            skips: true,
        }
    }

    /// A tiny run for tests: 2 configurations, 6 scenes, a 0.6 MP frame, 2 runs.
    pub fn quick() -> Self {
        let mut o = Self::full();
        o.configs = vec![
            L3Config::default_config(),
            L3Config::with("patch 3", |c| c.patch_size = 3),
        ];
        o.scenes = 6;
        o.scene_size = 48;
        o.runs = 2;
        o.frame_width = 768;
        o.frame_height = 768;
        o.tile_width = 256;
        o.tile_height = 256;
        o
    }

    pub fn validate(&self) -> Result<(), BenchError> {
        let bad = |m: String| Err(BenchError::Invalid(m));
        if self.runs == 0 || self.runs > 1000 {
            return bad(format!("runs {} (1 to 1000)", self.runs));
        }
        if self.frame_width < 16 || self.frame_height < 16 {
            return bad(format!(
                "frame {}×{} (at least 16×16)",
                self.frame_width, self.frame_height
            ));
        }
        if self.frame_width.saturating_mul(self.frame_height) > 100_000_000 {
            return bad("frame larger than 100 Mpix".into());
        }
        if self.tile_width < 16 || self.tile_height < 16 {
            return bad(format!(
                "tile {}×{} (at least 16×16)",
                self.tile_width, self.tile_height
            ));
        }
        if self.acquisitions.is_empty() {
            return bad("no acquisition illuminant".into());
        }
        if !(self.low_light_factor > 0.0 && self.low_light_factor <= 1.0) {
            return bad(format!(
                "low-light exposure factor {} (0 to 1)",
                self.low_light_factor
            ));
        }
        let mut names: Vec<&str> = self.configs.iter().map(|c| c.name.as_str()).collect();
        names.sort_unstable();
        if names.windows(2).any(|w| w[0] == w[1]) {
            return bad("configuration names must be unique".into());
        }
        Ok(())
    }
}

/// The conventional pipelines of the benchmark: bilinear demosaic of every
/// CFA channel and a least-squares colour matrix; [`BaselineChoice::ISP`]'s matrices
/// also serve the strong ISP's rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BaselineChoice {
    /// R, G, B → XYZ fitted under the acquisition light, white-balanced.
    AcquisitionRgb,
    /// Every channel → XYZ fitted under the acquisition light, white-balanced.
    AcquisitionAll,
    /// R, G, B → XYZ fitted under D65, then T.
    D65RgbThenT,
}

impl BaselineChoice {
    pub const ALL: [BaselineChoice; 3] = [
        BaselineChoice::AcquisitionRgb,
        BaselineChoice::AcquisitionAll,
        BaselineChoice::D65RgbThenT,
    ];

    /// The matrices of the strong ISP's rows: the acquisition light's RGB fit (Table 1's
    /// `ISP_<light>`) and D65's then T (`ISP_D65+T`).
    pub const ISP: [BaselineChoice; 2] =
        [BaselineChoice::AcquisitionRgb, BaselineChoice::D65RgbThenT];

    /// The row name.
    pub fn name(self) -> &'static str {
        match self {
            BaselineChoice::AcquisitionRgb => "baseline (bilinear + RGB matrix per light)",
            BaselineChoice::AcquisitionAll => "baseline (bilinear + all-channel matrix per light)",
            BaselineChoice::D65RgbThenT => "baseline (bilinear + 3×3 D65 + T)",
        }
    }

    pub(super) fn label(self, acquisition: &str) -> String {
        match self {
            BaselineChoice::AcquisitionRgb => format!("Baseline_{acquisition}"),
            BaselineChoice::AcquisitionAll => format!("Baseline_{acquisition} all"),
            BaselineChoice::D65RgbThenT => "Baseline+T".into(),
        }
    }

    /// The name of the strong ISP's row with this matrix.
    pub fn isp_name(self) -> &'static str {
        match self {
            BaselineChoice::AcquisitionRgb => "ISP (demosaic + denoise + RGB matrix per light)",
            BaselineChoice::AcquisitionAll => {
                "ISP (demosaic + denoise + all-channel matrix per light)"
            }
            BaselineChoice::D65RgbThenT => "ISP (demosaic + denoise + 3×3 D65 + T)",
        }
    }

    /// The strong ISP's method label under `acquisition`, as Table 1 names it.
    pub(super) fn isp_label(self, acquisition: &str) -> String {
        match self {
            BaselineChoice::AcquisitionRgb => format!("ISP_{acquisition}"),
            BaselineChoice::AcquisitionAll => format!("ISP_{acquisition} all"),
            BaselineChoice::D65RgbThenT => "ISP_D65+T".into(),
        }
    }

    /// The matrix for `acquisition`, T folded in where the choice uses it.
    pub(super) fn matrix(
        self,
        camera: &Camera,
        acquisition: &str,
        correction: &IlluminantEntry,
        iset: Option<&IsetData>,
    ) -> Result<ColourMatrix, BenchError> {
        let acq = [acquisition.to_string()];
        let d65 = ["D65".to_string()];
        let (ills, kind, channels) = match self {
            BaselineChoice::AcquisitionRgb => (&acq, TableKind::CrossIlluminant, ChannelSet::Rgb),
            BaselineChoice::AcquisitionAll => (&acq, TableKind::CrossIlluminant, ChannelSet::All),
            BaselineChoice::D65RgbThenT => (&d65, TableKind::SameIlluminant, ChannelSet::Rgb),
        };
        let fit = ColourFit {
            illuminants: ills,
            kind,
            channels,
            preserve_white: kind == TableKind::CrossIlluminant,
            through_correction: false,
        };
        let m = fit_colour_matrix(camera, &fit, iset)?;
        Ok(match kind {
            TableKind::SameIlluminant => m.then(&correction.t),
            TableKind::CrossIlluminant => m,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::records::Throughput;
    use crate::bench::stats::median;

    #[test]
    fn medians_and_options() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
        let t = Throughput::from_samples(vec![20.0, 10.0, 30.0], 1, 2.0);
        assert_eq!(t.median_ms, 20.0);
        assert_eq!(t.ms_per_mpix, 10.0);
        assert_eq!(t.mpix_per_s, 100.0);
        assert!(BenchOptions::full().validate().is_ok());
        assert!(BenchOptions::quick().validate().is_ok());
        let mut o = BenchOptions::quick();
        o.runs = 0;
        assert!(o.validate().is_err());
        let mut o = BenchOptions::quick();
        o.configs.push(o.configs[0].clone());
        assert!(o.validate().is_err());
        let sweep = default_sweep();
        assert_eq!(sweep.len(), 10);
        // one change at a time from the default
        let d = &sweep[0];
        for c in &sweep[1..] {
            let changes = [
                c.patch_size != d.patch_size,
                c.levels != d.levels,
                c.contrast_classes != d.contrast_classes,
                c.saturation_classes != d.saturation_classes,
                c.tables != d.tables,
                c.chroma_classes != d.chroma_classes,
            ];
            assert_eq!(changes.iter().filter(|&&x| x).count(), 1, "{}", c.name);
        }
        // the sensor sweep: the default and the I tables, with and without chroma classes
        let sensors = sensor_sweep_configs();
        assert_eq!(sensors[0], *d);
        assert!(
            sensors
                .iter()
                .all(|c| c.patch_size == d.patch_size && c.levels == d.levels)
        );
        let kinds: Vec<_> = sensors
            .iter()
            .map(|c| (c.tables, c.chroma_classes))
            .collect();
        assert_eq!(kinds.len(), 4);
        assert!(kinds.contains(&(TableChoice::CrossPerIlluminant, 8)));
    }

    #[test]
    fn the_strong_isp_rows_are_named_as_table_1_names_them() {
        let labels: Vec<String> = BaselineChoice::ISP
            .iter()
            .map(|b| b.isp_label("Tungsten"))
            .collect();
        assert_eq!(labels, ["ISP_Tungsten", "ISP_D65+T"]);
        // every row name is distinct from every other
        let mut names: Vec<&str> = BaselineChoice::ALL
            .iter()
            .flat_map(|b| [b.name(), b.isp_name()])
            .collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), 2 * BaselineChoice::ALL.len());
    }
}
