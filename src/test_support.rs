//! Test support, compiled only for the crate's own tests and with the `test-support`
//! feature (which the crate's tests and the fuzz crate turn on; `cargo build --release`
//! never has it): the one synthetic-table fixture, a linear `RG/WB` sensor seeing blocks
//! of random colour, used by the unit tests, the integration tests and the fuzz bodies.

use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use crate::camera::Cfa;
use crate::l3::classify::PatchGeometry;
use crate::l3::correct::NoiseModel;
use crate::l3::learn::{LearnError, Learned, TrainControl, TrainingFrame, learn, package};
use crate::l3::table::{TABLE_FORMAT_VERSION, TableKind, TableMeta};
use crate::l3::{L3Params, L3Table};
use crate::spectral::WavelengthGrid;

/// Linear responses of the synthetic sensor's R, G, W, B channels to XYZ.
pub const SYNTH_SENSOR: [[f32; 3]; 4] = [
    [0.9, 0.1, -0.05],
    [-0.3, 1.1, 0.1],
    [0.5, 0.6, 0.4],
    [0.0, -0.1, 0.9],
];

/// The paper's RGBW sensor on the default wavelength grid, from the built-in data.
pub fn paper_camera() -> crate::camera::Camera {
    match crate::camera::Camera::new(
        &crate::camera::SensorDesign::paper_default(),
        WavelengthGrid::default(),
        None,
    ) {
        Ok(c) => c,
        Err(e) => panic!("the paper's sensor does not build: {e}"),
    }
}

/// The synthetic sensor's voltage swing.
pub const SYNTH_SWING: f32 = 1.8;

/// The channel (an index of [`SYNTH_SENSOR`]) at row `r`, column `c` of the `R G / W B`
/// mosaic shifted by `shift`.
pub fn synthetic_channel(r: usize, c: usize, shift: (usize, usize)) -> usize {
    ((r + shift.0) % 2) * 2 + (c + shift.1) % 2
}

/// The volts channel `ch` of the synthetic sensor gives for `xyz` (plus `noise`), clipped to
/// the swing.
pub fn synthetic_volts(ch: usize, xyz: [f32; 3], noise: f32) -> f32 {
    let v: f32 = (0..3).map(|k| SYNTH_SENSOR[ch][k] * xyz[k]).sum();
    (v + noise).clamp(0.0, SYNTH_SWING)
}

/// A small deterministic generator (SplitMix64) for the synthetic frames.
struct SplitMix(u64);

impl SplitMix {
    fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// A synthetic training frame: 6×6 blocks of random colour seen by a linear
/// `RG/WB` sensor ([`SYNTH_SENSOR`]) at exposure `scale`, with uniform noise of
/// amplitude `noise` volts, the CFA shifted by `shift`.
pub fn synthetic_frame(
    seed: u64,
    size: usize,
    scale: f32,
    noise: f32,
    shift: (usize, usize),
) -> TrainingFrame {
    synthetic_frame_with_blocks(seed, size, 6, scale, noise, shift)
}

/// [`synthetic_frame`] with `block`×`block` blocks.
pub fn synthetic_frame_with_blocks(
    seed: u64,
    size: usize,
    block: usize,
    scale: f32,
    noise: f32,
    shift: (usize, usize),
) -> TrainingFrame {
    let mut rng = SplitMix(seed);
    let block = block.max(1);
    let nb = size.div_ceil(block);
    let colours: Vec<[f32; 3]> = (0..nb * nb)
        .map(|_| {
            let y = 0.05 + 0.95 * rng.next_f32();
            [
                y * (0.6 + 0.6 * rng.next_f32()),
                y,
                y * (0.5 + 0.8 * rng.next_f32()),
            ]
        })
        .collect();
    let mut volts = vec![0f32; size * size];
    let mut xyz = vec![0f32; size * size * 3];
    for r in 0..size {
        for c in 0..size {
            let col = colours[(r / block) * nb + c / block].map(|v| v * scale);
            let n = (2.0 * rng.next_f32() - 1.0) * noise;
            volts[r * size + c] = synthetic_volts(synthetic_channel(r, c, shift), col, n);
            xyz[(r * size + c) * 3..(r * size + c) * 3 + 3].copy_from_slice(&col);
        }
    }
    TrainingFrame {
        width: size,
        height: size,
        volts,
        xyz,
        cfa_shift: shift,
        neutral: None,
    }
}

/// Table metadata for a table learned from synthetic `RG/WB` frames.
pub fn synthetic_meta(params: &L3Params) -> Result<TableMeta, LearnError> {
    let cfa = Cfa::parse("RG/WB").map_err(|e| LearnError::InvalidParams(e.to_string()))?;
    Ok(TableMeta {
        format: "l3-table".into(),
        version: TABLE_FORMAT_VERSION,
        kind: TableKind::SameIlluminant,
        train_illuminants: vec!["synthetic".into()],
        train_white_xy: Vec::new(),
        target_illuminant: "same".into(),
        sensor_name: "synthetic-rgbw".into(),
        sensor: serde_json::Value::Null,
        cfa,
        grid: WavelengthGrid::default(),
        params: params.clone(),
        voltage_swing: 1.8,
        saturation_threshold: 1.8 - params.saturation_margin_v,
        sat_cases: vec![0],
        xyz_scale_note: "synthetic linear sensor".into(),
        seed: 0,
        created_unix_s: 0,
        training_seconds: 0.0,
        summary: serde_json::Value::Null,
    })
}

/// The noise model of the synthetic tables: read noise only.
pub fn synthetic_noise() -> NoiseModel {
    NoiseModel {
        conversion_gain_v: 2e-4,
        read_noise_v: 1e-3,
        dsnu_v: 0.0,
        prnu_fraction: 0.0,
    }
}

/// Learn from `n` batches of synthetic `RG/WB` frames produced by `frames(i)`, under `noise`.
pub fn learn_synthetic<F>(
    params: &L3Params,
    noise: NoiseModel,
    n: usize,
    frames: F,
) -> Result<Learned, LearnError>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, LearnError> + Sync,
{
    let cfa = Cfa::parse("RG/WB").map_err(|e| LearnError::InvalidParams(e.to_string()))?;
    let geo = PatchGeometry::new(
        params.patch_size,
        &cfa,
        &params.levels,
        f64::from(SYNTH_SWING) - params.saturation_margin_v,
    )?;
    let geo = match &params.chroma {
        Some(classes) => geo.with_chroma(classes)?,
        None => geo,
    };
    let cancel = AtomicBool::new(false);
    let ctl = TrainControl {
        progress: &|_, _| {},
        cancel: &cancel,
    };
    learn(&geo, params, noise, n, frames, None, &ctl)
}

/// A table learned from `n` batches of synthetic frames (`frames(i)`, read noise only) and
/// packaged with [`synthetic_meta`].
pub fn train_synthetic_table<F>(
    params: &L3Params,
    n: usize,
    frames: F,
) -> Result<L3Table, LearnError>
where
    F: Fn(usize) -> Result<Vec<TrainingFrame>, LearnError> + Sync,
{
    let learned = learn_synthetic(params, synthetic_noise(), n, frames)?;
    package(synthetic_meta(params)?, learned)
}

/// Learn a small table (3×3 patches, 4 levels) from synthetic frames: a
/// fraction of a second, no spectral data needed.
pub fn train_tiny_table() -> Result<L3Table, LearnError> {
    let params = L3Params {
        patch_size: 3,
        levels: L3Params::levels_for(4, 1.8)?,
        min_class_samples: 40,
        ..L3Params::default()
    };
    train_synthetic_table(&params, 16, |i| {
        let scale = [0.002f32, 0.02, 0.2, 1.0, 2.5][i % 5];
        let shift = (i % 2, (i / 2) % 2);
        Ok(vec![synthetic_frame(i as u64, 24, scale, 0.002, shift)])
    })
}

/// The tiny table of [`train_tiny_table`], trained once per process.
pub fn tiny_table() -> &'static L3Table {
    static T: OnceLock<Result<L3Table, String>> = OnceLock::new();
    match T.get_or_init(|| train_tiny_table().map_err(|e| e.to_string())) {
        Ok(t) => t,
        Err(e) => panic!("the tiny synthetic table does not train: {e}"),
    }
}
