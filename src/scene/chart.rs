//! Reflectance charts: a grid of uniform patches, an optional grey strip, and
//! the Macbeth ColorChecker.

use crate::spectral::{IsetData, Spectrum};

use super::options::{fill_rect, new_cube, reflectance_on_grid, samples_on_grid};
use super::{Patch, Scene, SceneError, SceneOptions};

/// Number of patches in the grey strip.
pub const GREY_STRIP_STEPS: usize = 10;
/// Reflectance of chart cells that hold no patch (a dark-grey surround).
pub const CHART_SURROUND: f64 = 0.2;
/// Category of the grey-strip and neutral patches.
pub const GREY_CATEGORY: &str = "grey";
/// The Macbeth ColorChecker in the ISET data (built in).
pub const MACBETH_CSV: &str = "surfaces/reflectances/macbethChart.csv";

/// The grey strip: flat reflectances 0.05, 0.15, …, 0.95 (equal steps of 0.1).
pub fn grey_strip_levels() -> [f64; GREY_STRIP_STEPS] {
    std::array::from_fn(|i| 0.05 + 0.1 * i as f64)
}

fn grey_name(level: f64) -> String {
    format!("grey_{:02}", (level * 100.0).round() as u32)
}

/// A chart of uniform square patches, `cols` per row, in the order given,
/// each `patch_px` pixels wide. With `with_grey_strip`, the 10 grey patches
/// of [`grey_strip_levels`] follow on a new row (wrapping at `cols`), named
/// `grey_05` … `grey_95` with category `grey`. Empty cells hold
/// [`CHART_SURROUND`]. Each input is `(name, category, reflectance)`.
pub fn reflectance_chart(
    opts: &SceneOptions,
    reflectances: &[(String, String, Spectrum)],
    cols: usize,
    patch_px: usize,
    with_grey_strip: bool,
) -> Result<Scene, SceneError> {
    opts.validate()?;
    if cols == 0 {
        return Err(SceneError::Invalid(
            "chart needs at least one column".into(),
        ));
    }
    if patch_px == 0 {
        return Err(SceneError::Invalid(
            "patch size must be at least 1 px".into(),
        ));
    }
    if reflectances.is_empty() && !with_grey_strip {
        return Err(SceneError::Invalid(
            "chart has no reflectances and no grey strip".into(),
        ));
    }
    let grid = opts.grid;
    let mut cells: Vec<(usize, String, String, Spectrum)> = Vec::new();
    for (i, (name, cat, r)) in reflectances.iter().enumerate() {
        cells.push((
            i,
            name.clone(),
            cat.clone(),
            reflectance_on_grid(name, r, &grid)?,
        ));
    }
    let colour_rows = reflectances.len().div_ceil(cols);
    if with_grey_strip {
        let first = colour_rows * cols;
        for (i, g) in grey_strip_levels().into_iter().enumerate() {
            cells.push((
                first + i,
                grey_name(g),
                GREY_CATEGORY.to_string(),
                Spectrum::constant(grid, g),
            ));
        }
    }
    let rows = cells.last().map_or(0, |c| c.0 / cols + 1);
    let too_big = || {
        SceneError::Invalid(format!(
            "chart of {rows} × {cols} patches of {patch_px} px is too large"
        ))
    };
    let height = rows.checked_mul(patch_px).ok_or_else(too_big)?;
    let width = cols.checked_mul(patch_px).ok_or_else(too_big)?;
    let mut cube = new_cube(&grid, height, width)?;
    cube.fill(CHART_SURROUND as f32);
    let mut patches = Vec::with_capacity(cells.len());
    for (cell, name, category, r) in cells {
        let (row, col) = ((cell / cols) * patch_px, (cell % cols) * patch_px);
        fill_rect(&mut cube, &r, row, col, patch_px, patch_px);
        patches.push(Patch {
            name,
            category,
            row,
            col,
            height: patch_px,
            width: patch_px,
            reflectance: r,
        });
    }
    Ok(opts.scene("reflectance-chart", cube, patches))
}

/// The 24-patch Macbeth ColorChecker from the ISET data (4 rows × 6 columns,
/// standard layout; ISET stores the patches column-major, so patch `k` of the
/// file sits at row `k % 4`, column `k / 4`). The neutral series (white …
/// black) is the bottom row, category `grey`; the others are `colour`.
pub fn macbeth(iset: &IsetData, opts: &SceneOptions, patch_px: usize) -> Result<Scene, SceneError> {
    opts.validate()?;
    let table = iset
        .table(MACBETH_CSV)
        .map_err(|e| SceneError::Invalid(format!("the Macbeth chart: {e}")))?;
    if table.names.len() != 24 {
        return Err(SceneError::Invalid(format!(
            "{}: expected 24 patches, found {}",
            table.path,
            table.names.len()
        )));
    }
    let mut cells = Vec::with_capacity(24);
    for (k, (name, s)) in table.all()?.into_iter().enumerate() {
        let r = samples_on_grid(&name, &s, &opts.grid)?;
        let (row, col) = (k % 4, k / 4);
        let cat = if row == 3 { GREY_CATEGORY } else { "colour" };
        cells.push((row * 6 + col, name, cat.to_string(), r));
    }
    cells.sort_by_key(|c| c.0);
    let list: Vec<(String, String, Spectrum)> =
        cells.into_iter().map(|(_, n, c, r)| (n, c, r)).collect();
    let mut scene = reflectance_chart(opts, &list, 6, patch_px, false)?;
    scene.name = "macbeth".into();
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectral::WavelengthGrid;

    fn opts() -> SceneOptions {
        SceneOptions::d65(WavelengthGrid::default()).unwrap()
    }

    #[test]
    fn chart_layout_and_grey_strip() {
        let g = WavelengthGrid::default();
        let list: Vec<_> = (0..7)
            .map(|i| {
                (
                    format!("s{i}"),
                    "x".to_string(),
                    Spectrum::constant(g, 0.1 * i as f64),
                )
            })
            .collect();
        let s = reflectance_chart(&opts(), &list, 4, 3, true).unwrap();
        // 2 colour rows + 3 grey rows (10 greys wrap at 4 columns).
        assert_eq!((s.rows(), s.cols(), s.bands()), (15, 12, 31));
        assert_eq!(s.patches.len(), 17);
        let p = &s.patches[5];
        assert_eq!((p.row, p.col), (3, 3));
        assert!((s.reflectance[[0, 4, 4]] - 0.5).abs() < 1e-6);
        // Cell 7 is empty: surround.
        assert!((s.reflectance[[0, 4, 10]] - 0.2).abs() < 1e-6);
        let greys: Vec<_> = s.patches.iter().filter(|p| p.category == "grey").collect();
        assert_eq!(greys.len(), 10);
        assert_eq!((greys[0].row, greys[0].col), (6, 0));
        assert_eq!(greys[9].name, "grey_95");
    }

    #[test]
    fn chart_rejects_bad_input() {
        let g = WavelengthGrid::default();
        let one = vec![("a".to_string(), "x".to_string(), Spectrum::constant(g, 0.5))];
        assert!(reflectance_chart(&opts(), &one, 0, 3, false).is_err());
        assert!(reflectance_chart(&opts(), &one, 2, 0, false).is_err());
        assert!(reflectance_chart(&opts(), &[], 2, 3, false).is_err());
        let bad = vec![(
            "b".to_string(),
            "x".to_string(),
            Spectrum::constant(g, f64::NAN),
        )];
        assert!(reflectance_chart(&opts(), &bad, 2, 3, false).is_err());
        assert!(reflectance_chart(&opts(), &one, usize::MAX / 2, 1 << 20, true).is_err());
        let mut o = opts();
        o.mean_luminance = -1.0;
        assert!(reflectance_chart(&o, &one, 2, 3, false).is_err());
    }
}
