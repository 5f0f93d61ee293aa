//! The training scenes: random-size patch charts and dead-leaves textures
//! of training reflectances, and grey ramps, each seeded by its index.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::LearnError;
use crate::scene::{
    DeadLeavesParams, Scene, SceneOptions, dead_leaves, grey_ramp, reflectance_chart,
    training_reflectances,
};
use crate::spectral::{IsetData, Spectrum, WavelengthGrid};

/// Generator of the training scenes.
pub struct TrainingScenes {
    grid: WavelengthGrid,
    reflectances: Vec<Spectrum>,
    seed: u64,
    size: usize,
    mean_luminance: f64,
}

impl TrainingScenes {
    pub fn new(
        grid: WavelengthGrid,
        iset: Option<&IsetData>,
        seed: u64,
        size: usize,
        mean_luminance: f64,
    ) -> Result<Self, LearnError> {
        let reflectances = training_reflectances(&grid, iset)?
            .into_iter()
            .map(|(_, s)| s)
            .collect();
        Ok(Self {
            grid,
            reflectances,
            seed,
            size,
            mean_luminance,
        })
    }

    /// The training reflectances on the grid.
    pub fn reflectances(&self) -> &[Spectrum] {
        &self.reflectances
    }

    pub fn reflectance_count(&self) -> usize {
        self.reflectances.len()
    }

    /// Scene `index` lit by `illuminant` (on the grid). Every 8th scene is a
    /// grey ramp, every 4th a dead-leaves texture, the rest random-size
    /// patch charts.
    pub fn scene(
        &self,
        index: usize,
        illuminant: &Spectrum,
        name: &str,
    ) -> Result<Scene, LearnError> {
        let opts = SceneOptions::new(self.grid, illuminant.clone(), name)?
            .with_mean_luminance(self.mean_luminance);
        let seed = mix(self.seed, index as u64, 0x5CE7E);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = self.size;
        let scene = if index % 8 == 7 {
            grey_ramp(&opts, n, n, rng.random_range(8..=n.min(32)))?
        } else if index % 4 == 2 {
            let p = DeadLeavesParams::new(n, n, seed);
            dead_leaves(&opts, &self.reflectances, &p)?
        } else {
            let patch = rng.random_range(4..=(n / 3).max(5));
            let cols = n.div_ceil(patch);
            let count = cols * cols;
            let picks: Vec<(String, String, Spectrum)> = (0..count)
                .map(|k| {
                    let j = rng.random_range(0..self.reflectances.len());
                    (
                        format!("t{k}"),
                        "train".to_string(),
                        self.reflectances[j].clone(),
                    )
                })
                .collect();
            let mut chart = reflectance_chart(&opts, &picks, cols, patch, false)?;
            crop(&mut chart, n);
            chart
        };
        Ok(scene)
    }
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

/// Crop a scene to `n × n` from its top-left corner (charts round up).
fn crop(scene: &mut Scene, n: usize) {
    use ndarray::s;
    let (_, r, c) = scene.reflectance.dim();
    if r > n || c > n {
        scene.reflectance = scene
            .reflectance
            .slice(s![.., ..n.min(r), ..n.min(c)])
            .to_owned();
        scene.patches.clear();
    }
}
