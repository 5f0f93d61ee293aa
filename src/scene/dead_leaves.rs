//! Dead-leaves textures: occluding discs with power-law radii.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::spectral::Spectrum;

use super::options::{MAX_SCENE_VALUES, new_cube, reflectance_on_grid};
use super::{Scene, SceneError, SceneOptions};

/// Size, seed and disc radii of a dead-leaves scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeadLeavesParams {
    pub rows: usize,
    pub cols: usize,
    pub seed: u64,
    /// Smallest disc radius, pixels (≥ 0.5).
    pub r_min_px: f64,
    /// Largest disc radius, pixels (≥ `r_min_px`).
    pub r_max_px: f64,
}

impl DeadLeavesParams {
    /// Radii from 2 px to a quarter of the larger side (at least 2 px).
    pub fn new(rows: usize, cols: usize, seed: u64) -> Self {
        Self {
            rows,
            cols,
            seed,
            r_min_px: 2.0,
            r_max_px: (rows.max(cols) as f64 / 4.0).max(2.0),
        }
    }

    fn validate(&self) -> Result<(), SceneError> {
        let (a, b) = (self.r_min_px, self.r_max_px);
        if !(a.is_finite() && b.is_finite() && a >= 0.5 && b >= a) {
            return Err(SceneError::Invalid(format!(
                "dead-leaves radii must satisfy 0.5 ≤ r_min ≤ r_max (finite), got {a} and {b}"
            )));
        }
        if b > 10.0 * self.rows.max(self.cols) as f64 {
            return Err(SceneError::Invalid(format!(
                "dead-leaves r_max {b} px is over ten times the scene size"
            )));
        }
        Ok(())
    }
}

/// A radius with density ∝ r⁻³ on `[a, b]` by inverting its CDF.
fn power_law_radius(rng: &mut ChaCha8Rng, a: f64, b: f64) -> f64 {
    let (ia, ib) = (a.powi(-2), b.powi(-2));
    let u: f64 = rng.random();
    (ia - u * (ia - ib)).powf(-0.5)
}

/// The index map of a dead-leaves texture: pixel → index into a set of
/// `n_reflectances` (`rows × cols`, row-major). Discs are drawn front to
/// back (each new disc lies behind the earlier ones, which is the same
/// texture as painting back to front), centres uniform over the image,
/// radii ∝ r⁻³, until every pixel is covered.
pub fn dead_leaves_labels(
    params: &DeadLeavesParams,
    n_reflectances: usize,
) -> Result<Vec<u32>, SceneError> {
    params.validate()?;
    if n_reflectances == 0 || n_reflectances > u32::MAX as usize {
        return Err(SceneError::Invalid(format!(
            "dead leaves needs 1 to 2³² − 1 reflectances, got {n_reflectances}"
        )));
    }
    let (rows, cols) = (params.rows, params.cols);
    let pixels = rows
        .checked_mul(cols)
        .filter(|&p| p > 0 && p <= MAX_SCENE_VALUES)
        .ok_or_else(|| {
            SceneError::Invalid(format!(
                "dead-leaves size {rows} × {cols} must be positive and at most {MAX_SCENE_VALUES} pixels"
            ))
        })?;
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    let mut label = vec![u32::MAX; pixels];
    let mut uncovered = pixels;
    // Full coverage takes ~ A·ln(A)/(π·E[r²]) discs; this cap is far above it.
    let max_discs = pixels.saturating_mul(50).saturating_add(10_000);
    let mut discs = 0usize;
    while uncovered > 0 && discs < max_discs {
        discs += 1;
        let r = power_law_radius(&mut rng, params.r_min_px, params.r_max_px);
        let cx = rng.random::<f64>() * cols as f64;
        let cy = rng.random::<f64>() * rows as f64;
        let idx = rng.random_range(0..n_reflectances) as u32;
        let y0 = (cy - r).floor().max(0.0) as usize;
        let y1 = ((cy + r).ceil().max(0.0) as usize).min(rows);
        let x0 = (cx - r).floor().max(0.0) as usize;
        let x1 = ((cx + r).ceil().max(0.0) as usize).min(cols);
        let r2 = r * r;
        for y in y0..y1 {
            let dy = y as f64 + 0.5 - cy;
            let row = &mut label[y * cols..(y + 1) * cols];
            for (x, l) in row.iter_mut().enumerate().take(x1).skip(x0) {
                let dx = x as f64 + 0.5 - cx;
                if *l == u32::MAX && dx * dx + dy * dy <= r2 {
                    *l = idx;
                    uncovered -= 1;
                }
            }
        }
    }
    if uncovered > 0 {
        let idx = rng.random_range(0..n_reflectances) as u32;
        label
            .iter_mut()
            .filter(|l| **l == u32::MAX)
            .for_each(|l| *l = idx);
    }
    Ok(label)
}

/// A dead-leaves scene: reflectances drawn uniformly from `reflectances`
/// (seeded), on discs of [`dead_leaves_labels`]. No patches.
pub fn dead_leaves(
    opts: &SceneOptions,
    reflectances: &[Spectrum],
    params: &DeadLeavesParams,
) -> Result<Scene, SceneError> {
    opts.validate()?;
    if reflectances.is_empty() {
        return Err(SceneError::Invalid(
            "dead leaves needs at least one reflectance".into(),
        ));
    }
    let on_grid: Vec<Vec<f32>> = reflectances
        .iter()
        .enumerate()
        .map(|(i, r)| {
            Ok(reflectance_on_grid(&format!("#{i}"), r, &opts.grid)?
                .values()
                .iter()
                .map(|&v| v as f32)
                .collect())
        })
        .collect::<Result<_, SceneError>>()?;
    let mut cube = new_cube(&opts.grid, params.rows, params.cols)?;
    let label = dead_leaves_labels(params, reflectances.len())?;
    let pixels = label.len();
    let data = cube
        .as_slice_mut()
        .ok_or_else(|| SceneError::Invalid("reflectance cube is not contiguous".into()))?;
    data.par_chunks_mut(pixels)
        .enumerate()
        .for_each(|(b, band)| {
            for (v, &l) in band.iter_mut().zip(&label) {
                *v = on_grid[l as usize][b];
            }
        });
    Ok(opts.scene("dead-leaves", cube, Vec::new()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radii_follow_the_power_law() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (a, b) = (2.0, 50.0);
        let n = 20_000;
        let rs: Vec<f64> = (0..n).map(|_| power_law_radius(&mut rng, a, b)).collect();
        assert!(rs.iter().all(|&r| (a..=b).contains(&r)));
        // P(r ≤ 2a) = (a⁻² − (2a)⁻²)/(a⁻² − b⁻²) ≈ 0.7517.
        let frac = rs.iter().filter(|&&r| r <= 2.0 * a).count() as f64 / n as f64;
        let want = (a.powi(-2) - (2.0 * a).powi(-2)) / (a.powi(-2) - b.powi(-2));
        assert!((frac - want).abs() < 0.015, "{frac} vs {want}");
    }

    #[test]
    fn labels_cover_and_use_several_reflectances() {
        let p = DeadLeavesParams::new(40, 60, 9);
        let l = dead_leaves_labels(&p, 5).unwrap();
        assert!(l.iter().all(|&x| x < 5));
        let distinct: std::collections::HashSet<_> = l.iter().collect();
        assert!(distinct.len() >= 3);
        let mut bad = p;
        bad.r_min_px = 0.1;
        assert!(dead_leaves_labels(&bad, 5).is_err());
        bad = p;
        bad.r_max_px = f64::NAN;
        assert!(dead_leaves_labels(&bad, 5).is_err());
        assert!(dead_leaves_labels(&p, 0).is_err());
    }
}
