//! Uniform fields and grey ramps.

use crate::spectral::Spectrum;

use super::chart::GREY_CATEGORY;
use super::options::{fill_rect, new_cube, reflectance_on_grid};
use super::{Patch, Scene, SceneError, SceneOptions};

/// A uniform field of one reflectance, recorded as one patch `uniform`.
pub fn uniform(
    opts: &SceneOptions,
    reflectance: &Spectrum,
    rows: usize,
    cols: usize,
) -> Result<Scene, SceneError> {
    opts.validate()?;
    let r = reflectance_on_grid("uniform", reflectance, &opts.grid)?;
    let mut cube = new_cube(&opts.grid, rows, cols)?;
    fill_rect(&mut cube, &r, 0, 0, rows, cols);
    let patch = Patch {
        name: "uniform".into(),
        category: String::new(),
        row: 0,
        col: 0,
        height: rows,
        width: cols,
        reflectance: r,
    };
    Ok(opts.scene("uniform", cube, vec![patch]))
}

/// A horizontal grey ramp of `steps` vertical bars (2 ≤ steps ≤ cols), flat
/// reflectance `(i + 1) / steps` for bar `i` (white last). Bar `i` spans
/// columns `i·cols/steps .. (i+1)·cols/steps`; each is a patch `ramp_NN`,
/// category `grey`.
pub fn grey_ramp(
    opts: &SceneOptions,
    rows: usize,
    cols: usize,
    steps: usize,
) -> Result<Scene, SceneError> {
    opts.validate()?;
    if steps < 2 || steps > cols {
        return Err(SceneError::Invalid(format!(
            "grey ramp needs 2 ≤ steps ≤ cols, got {steps} steps for {cols} columns"
        )));
    }
    let mut cube = new_cube(&opts.grid, rows, cols)?;
    let mut patches = Vec::with_capacity(steps);
    for i in 0..steps {
        let (c0, c1) = (i * cols / steps, (i + 1) * cols / steps);
        let level = (i + 1) as f64 / steps as f64;
        let r = Spectrum::constant(opts.grid, level);
        fill_rect(&mut cube, &r, 0, c0, rows, c1 - c0);
        patches.push(Patch {
            name: format!("ramp_{i:02}"),
            category: GREY_CATEGORY.into(),
            row: 0,
            col: c0,
            height: rows,
            width: c1 - c0,
            reflectance: r,
        });
    }
    Ok(opts.scene("grey-ramp", cube, patches))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectral::WavelengthGrid;

    #[test]
    fn ramp_and_uniform() {
        let o = SceneOptions::d65(WavelengthGrid::default()).unwrap();
        let s = grey_ramp(&o, 4, 10, 3).unwrap();
        assert_eq!(s.patches.len(), 3);
        assert_eq!(s.patches.iter().map(|p| p.width).sum::<usize>(), 10);
        assert!((s.reflectance[[5, 2, 9]] - 1.0).abs() < 1e-6);
        assert!((s.reflectance[[5, 2, 0]] - 1.0 / 3.0).abs() < 1e-6);
        assert!(grey_ramp(&o, 4, 10, 1).is_err());
        assert!(grey_ramp(&o, 4, 10, 11).is_err());
        assert!(grey_ramp(&o, 0, 10, 2).is_err());
        let u = uniform(&o, &Spectrum::constant(o.grid, 0.3), 3, 5).unwrap();
        assert!(u.reflectance.iter().all(|&v| (v - 0.3).abs() < 1e-6));
        assert!(uniform(&o, &Spectrum::constant(o.grid, -0.3), 3, 5).is_err());
    }
}
