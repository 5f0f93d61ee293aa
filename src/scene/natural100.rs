//! The Natural-100 chart (docs/design.md §7, the paper's §3.3): 100 natural
//! reflectances picked by clustering principal-component weights per
//! category, plus a 10-step grey strip; and a chart of the 99 CES from
//! crate data.

use std::collections::HashSet;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::spectral::{Extrapolation, IsetData, Samples, ces_reflectances};

use super::chart::reflectance_chart;
use super::kmeans::kmeans;
use super::options::samples_on_grid;
use super::pca::Pca;
use super::{Scene, SceneError, SceneOptions};

/// A reflectance picked for a chart.
#[derive(Clone, Debug)]
pub struct ChartSample {
    /// Column name in the source CSV (e.g. `obj065`, `dupont017`, `CES42`).
    pub name: String,
    pub category: String,
    pub samples: Samples,
}

/// One category of the Natural-100 chart: its ISET CSVs and how many
/// samples the chart takes from it.
#[derive(Clone, Copy, Debug)]
pub struct Natural100Category {
    pub name: &'static str,
    pub files: &'static [&'static str],
    pub count: usize,
}

/// The categories in selection order (a category never takes a sample an
/// earlier one took; Food and Nature share 22 samples).
pub const NATURAL100_CATEGORIES: [Natural100Category; 6] = [
    Natural100Category {
        name: "Food",
        files: &["surfaces/reflectances/Food_Vhrel.csv"],
        count: 20,
    },
    Natural100Category {
        name: "Clothes",
        files: &["surfaces/reflectances/Clothes_Vhrel.csv"],
        count: 20,
    },
    Natural100Category {
        name: "Nature",
        files: &["surfaces/reflectances/Nature_Vhrel.csv"],
        count: 20,
    },
    Natural100Category {
        name: "Hair",
        files: &["surfaces/reflectances/Hair_Vhrel.csv"],
        count: 5,
    },
    Natural100Category {
        name: "Skin",
        files: &[
            "surfaces/reflectances/skin/Caucasian_Vhrel.csv",
            "surfaces/reflectances/skin/AfricanAmerican_Vhrel.csv",
            "surfaces/reflectances/skin/Asian_Vhrel.csv",
            "surfaces/reflectances/skin/EastIndian_Vhrel.csv",
        ],
        count: 15,
    },
    Natural100Category {
        name: "Paint",
        files: &["surfaces/reflectances/DupontPaintChip_Vhrel.csv"],
        count: 20,
    },
];

/// Seed of the Natural-100 selection.
pub const NATURAL100_SEED: u64 = 2016;
/// Principal components used to describe each reflectance.
pub const NATURAL100_COMPONENTS: usize = 7;
/// Default patch size of the chart, pixels.
pub const NATURAL100_PATCH_PX: usize = 24;
/// Columns of the chart.
pub const NATURAL100_COLS: usize = 10;
/// k-means++ restarts per category (the lowest inertia wins).
const KMEANS_RESTARTS: usize = 20;

/// The PCA grid: the Vrhel sets' native 400–700 nm at 10 nm.
fn pca_vector(s: &Samples) -> Vec<f64> {
    (0..31)
        .map(|i| s.at(400.0 + 10.0 * i as f64, Extrapolation::Hold))
        .collect()
}

/// The 100 Natural-100 samples with the default seed, in category order
/// (names sorted within a category).
pub fn natural100_samples(iset: &IsetData) -> Result<Vec<ChartSample>, SceneError> {
    natural100_samples_seeded(iset, NATURAL100_SEED)
}

/// The Natural-100 selection with a given seed: 7 principal components of the
/// pooled reflectances (each sample once), then per category `count` k-means
/// clusters of the component weights of its not-yet-chosen samples and, per
/// cluster, the member nearest the centroid.
pub fn natural100_samples_seeded(
    iset: &IsetData,
    seed: u64,
) -> Result<Vec<ChartSample>, SceneError> {
    // Load every category.
    let mut members: Vec<Vec<(String, Samples)>> = Vec::new();
    for cat in &NATURAL100_CATEGORIES {
        let mut list = Vec::new();
        for f in cat.files {
            let t = iset
                .table(f)
                .map_err(|e| SceneError::Invalid(format!("the Natural-100 chart: {e}")))?;
            list.extend(t.all()?);
        }
        if list.len() < cat.count {
            return Err(SceneError::Invalid(format!(
                "category {} has {} samples, the chart needs {}",
                cat.name,
                list.len(),
                cat.count
            )));
        }
        members.push(list);
    }
    // PCA of the pooled set, each sample once.
    let mut seen = HashSet::new();
    let pooled: Vec<Vec<f64>> = members
        .iter()
        .flatten()
        .filter(|(n, _)| seen.insert(n.clone()))
        .map(|(_, s)| pca_vector(s))
        .collect();
    let pca = Pca::fit(&pooled, NATURAL100_COMPONENTS)?;

    let mut taken: HashSet<String> = HashSet::new();
    let mut out = Vec::with_capacity(100);
    for (ci, (cat, list)) in NATURAL100_CATEGORIES.iter().zip(&members).enumerate() {
        let avail: Vec<&(String, Samples)> =
            list.iter().filter(|(n, _)| !taken.contains(n)).collect();
        if avail.len() < cat.count {
            return Err(SceneError::Invalid(format!(
                "category {}: only {} samples left after earlier categories, need {}",
                cat.name,
                avail.len(),
                cat.count
            )));
        }
        let w: Vec<Vec<f64>> = avail
            .iter()
            .map(|(_, s)| pca.weights(&pca_vector(s)))
            .collect();
        let mut rng =
            ChaCha8Rng::seed_from_u64(seed ^ (ci as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let cl = kmeans(&w, cat.count, KMEANS_RESTARTS, &mut rng);
        let d2 = |i: usize, j: usize| -> f64 {
            w[i].iter()
                .zip(&cl.centroids[j])
                .map(|(a, b)| (a - b) * (a - b))
                .sum()
        };
        let mut picked: Vec<usize> = Vec::with_capacity(cat.count);
        for j in 0..cat.count {
            let best_in = |own: bool| {
                (0..avail.len())
                    .filter(|&i| !picked.contains(&i) && (!own || cl.assignment[i] == j))
                    .map(|i| (i, d2(i, j)))
                    .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
                    .map(|x| x.0)
            };
            // A cluster's own nearest member; for an empty cluster, the
            // nearest sample not picked yet.
            if let Some(i) = best_in(true).or_else(|| best_in(false)) {
                picked.push(i);
            }
        }
        let mut chosen: Vec<ChartSample> = picked
            .into_iter()
            .map(|i| ChartSample {
                name: avail[i].0.clone(),
                category: cat.name.to_string(),
                samples: avail[i].1.clone(),
            })
            .collect();
        chosen.sort_by(|a, b| a.name.cmp(&b.name));
        for c in &chosen {
            taken.insert(c.name.clone());
        }
        out.extend(chosen);
    }
    Ok(out)
}

fn chart_of(
    samples: &[ChartSample],
    opts: &SceneOptions,
    patch_px: usize,
    name: &str,
) -> Result<Scene, SceneError> {
    opts.validate()?;
    let list = samples
        .iter()
        .map(|s| {
            Ok((
                s.name.clone(),
                s.category.clone(),
                samples_on_grid(&s.name, &s.samples, &opts.grid)?,
            ))
        })
        .collect::<Result<Vec<_>, SceneError>>()?;
    let mut scene = reflectance_chart(opts, &list, NATURAL100_COLS, patch_px, true)?;
    scene.name = name.to_string();
    Ok(scene)
}

/// The Natural-100 chart: the 100 samples of [`natural100_samples`] in 10
/// columns (category order), then the grey strip; 11 rows of `patch_px`.
pub fn natural100_chart(
    iset: &IsetData,
    opts: &SceneOptions,
    patch_px: usize,
) -> Result<Scene, SceneError> {
    opts.validate()?;
    chart_of(&natural100_samples(iset)?, opts, patch_px, "natural100")
}

/// The 99 CIE 224 colour evaluation samples (crate data), category `CES`.
pub fn ces_samples() -> Vec<ChartSample> {
    ces_reflectances()
        .into_iter()
        .map(|(name, samples)| ChartSample {
            name,
            category: "CES".into(),
            samples,
        })
        .collect()
}

/// A chart from crate data: the 99 CES in 10 columns, then the grey strip.
pub fn ces_chart(opts: &SceneOptions, patch_px: usize) -> Result<Scene, SceneError> {
    chart_of(&ces_samples(), opts, patch_px, "ces99")
}
