//! A slanted edge for ISO 12233 sharpness (`crate::eval::slanted_edge_sfr`), and the white
//! reference strip the spatial evaluation scenes carry.
//!
//! The scene: a strip of [`WHITE_REFERENCE`] across the top (the chart's white, so that
//! auto-exposure puts it, not the edge, at 95 % of the swing, as it does the chart's white
//! patch), and below it a dark grey ([`EDGE_DARK`], left) meeting a light grey
//! ([`EDGE_BRIGHT`], right) along a straight line [`EDGE_ANGLE_DEG`] from vertical through the
//! centre of the edge region. Both greys are flat (spectrally neutral), so any colour at the
//! edge is the camera's or the pipeline's. The light grey then sits near 60 % of the swing,
//! well clear of clipping at any exposure factor ≤ 1.
//!
//! The edge is **anti-aliased by area**: each pixel's reflectance is the exact area-weighted
//! mix of the two greys over its square (computed analytically, not point-sampled), so the
//! scene holds no staircase for the lens and the sensor to alias.

use crate::spectral::Spectrum;

use super::chart::GREY_CATEGORY;
use super::options::{fill_rect, new_cube};
use super::{Patch, Scene, SceneError, SceneOptions};

/// Reflectance of the dark side.
pub const EDGE_DARK: f64 = 0.18;
/// Reflectance of the light side.
pub const EDGE_BRIGHT: f64 = 0.6;
/// Reflectance of the white reference strip: Natural-100's white (`grey_95`).
pub const WHITE_REFERENCE: f64 = 0.95;
/// The edge's default angle from vertical, degrees.
pub const EDGE_ANGLE_DEG: f64 = 5.0;
/// The default side of the edge scene, pixels.
pub const EDGE_SIZE: usize = 128;
/// The smallest side of an edge scene, pixels.
pub const MIN_EDGE_SIZE: usize = 48;
/// Names of the edge scene's patches.
pub const WHITE_PATCH: &str = "white";
pub const DARK_PATCH: &str = "edge_dark";
pub const BRIGHT_PATCH: &str = "edge_bright";

/// Size, angle and reflectances of a slanted-edge scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlantedEdgeParams {
    pub rows: usize,
    pub cols: usize,
    /// Angle of the edge from vertical, degrees (positive: it runs right as it goes down);
    /// 2–10° in magnitude keeps every sub-pixel phase sampled.
    pub angle_deg: f64,
    pub dark: f64,
    pub bright: f64,
    /// Rows of the white reference strip at the top.
    pub white_rows: usize,
}

impl SlantedEdgeParams {
    /// A `rows × cols` edge at [`EDGE_ANGLE_DEG`] with the default greys and a white strip
    /// of an eighth of the rows (at least 6).
    pub fn new(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            angle_deg: EDGE_ANGLE_DEG,
            dark: EDGE_DARK,
            bright: EDGE_BRIGHT,
            white_rows: (rows / 8).max(6),
        }
    }

    /// The edge's column at height `y` (continuous pixel coordinates: pixel (r, c) covers
    /// `[c, c + 1] × [r, r + 1]`).
    pub fn edge_x(&self, y: f64) -> f64 {
        let y0 = self.white_rows as f64;
        let cy = y0 + (self.rows as f64 - y0) / 2.0;
        self.cols as f64 / 2.0 + (y - cy) * self.angle_deg.to_radians().tan()
    }

    /// The fraction of pixel (r, c)'s area on the light side (right of the edge).
    pub fn bright_coverage(&self, r: usize, c: usize) -> f64 {
        // the light part of the row segment [c, c + 1] at height y is clamp(c + 1 − x(y), 0, 1);
        // x is linear in y, so the integral over [r, r + 1] is exact through G' = clamp
        let g = |u: f64| {
            if u <= 0.0 {
                0.0
            } else if u <= 1.0 {
                0.5 * u * u
            } else {
                u - 0.5
            }
        };
        let (y0, y1) = (r as f64, r as f64 + 1.0);
        let (u0, u1) = (
            c as f64 + 1.0 - self.edge_x(y0),
            c as f64 + 1.0 - self.edge_x(y1),
        );
        let slope = u0 - u1; // −du/dy
        if slope.abs() < 1e-12 {
            return u0.clamp(0.0, 1.0);
        }
        ((g(u0) - g(u1)) / slope).clamp(0.0, 1.0)
    }

    fn validate(&self) -> Result<(), SceneError> {
        if self.rows < MIN_EDGE_SIZE || self.cols < MIN_EDGE_SIZE {
            return Err(SceneError::Invalid(format!(
                "a slanted edge needs at least {MIN_EDGE_SIZE} × {MIN_EDGE_SIZE} pixels, got {} × {}",
                self.rows, self.cols
            )));
        }
        if !(self.angle_deg.is_finite() && (2.0..=10.0).contains(&self.angle_deg.abs())) {
            return Err(SceneError::Invalid(format!(
                "edge angle {}°: expected 2 to 10° from vertical either way",
                self.angle_deg
            )));
        }
        for v in [self.dark, self.bright] {
            if !(v.is_finite() && (0.0..=WHITE_REFERENCE).contains(&v)) {
                return Err(SceneError::Invalid(format!(
                    "edge reflectance {v}: expected 0 to {WHITE_REFERENCE}"
                )));
            }
        }
        if self.dark >= self.bright {
            return Err(SceneError::Invalid(format!(
                "the edge's dark side ({}) must be darker than its light side ({})",
                self.dark, self.bright
            )));
        }
        if self.white_rows == 0 || self.white_rows * 2 > self.rows {
            return Err(SceneError::Invalid(format!(
                "a white strip of {} rows in a {}-row scene: expected 1 to half the rows",
                self.white_rows, self.rows
            )));
        }
        Ok(())
    }
}

/// The slanted-edge scene (see the module doc). Patches: [`WHITE_PATCH`] (the strip,
/// category `grey`), [`DARK_PATCH`] and [`BRIGHT_PATCH`]: the widest rectangles below the
/// strip wholly on either side of the edge.
pub fn slanted_edge(opts: &SceneOptions, params: &SlantedEdgeParams) -> Result<Scene, SceneError> {
    opts.validate()?;
    params.validate()?;
    let (rows, cols) = (params.rows, params.cols);
    let mut cube = new_cube(&opts.grid, rows, cols)?;
    let y0 = params.white_rows;
    for r in y0..rows {
        for c in 0..cols {
            let f = params.bright_coverage(r, c);
            let v = (params.dark + f * (params.bright - params.dark)) as f32;
            cube.slice_mut(ndarray::s![.., r, c]).fill(v);
        }
    }
    let mut scene = opts.scene("slanted-edge", cube, Vec::new());
    add_white_strip(&mut scene, y0)?;
    let (xa, xb) = (params.edge_x(y0 as f64), params.edge_x(rows as f64));
    let (left, right) = (xa.min(xb).floor() as usize, xa.max(xb).ceil() as usize);
    let side = |name: &str, col: usize, width: usize, level: f64| Patch {
        name: name.into(),
        category: String::new(),
        row: y0,
        col,
        height: rows - y0,
        width,
        reflectance: Spectrum::constant(opts.grid, level),
    };
    scene.patches.push(side(DARK_PATCH, 0, left, params.dark));
    scene.patches.push(side(
        BRIGHT_PATCH,
        right,
        cols.saturating_sub(right),
        params.bright,
    ));
    Ok(scene)
}

/// Paint the top `rows` rows of `scene` with [`WHITE_REFERENCE`] and record them as the
/// patch [`WHITE_PATCH`] (category `grey`, so the chart evaluation's white-patch rule finds
/// it): the reference both sides of a spatial comparison are normalised by.
pub fn add_white_strip(scene: &mut Scene, rows: usize) -> Result<(), SceneError> {
    if rows == 0 || rows >= scene.rows() {
        return Err(SceneError::Invalid(format!(
            "a white strip of {rows} rows in a {}-row scene",
            scene.rows()
        )));
    }
    let white = Spectrum::constant(scene.grid, WHITE_REFERENCE);
    let cols = scene.cols();
    fill_rect(&mut scene.reflectance, &white, 0, 0, rows, cols);
    scene.patches.push(Patch {
        name: WHITE_PATCH.into(),
        category: GREY_CATEGORY.into(),
        row: 0,
        col: 0,
        height: rows,
        width: cols,
        reflectance: white,
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectral::WavelengthGrid;

    fn scene(p: &SlantedEdgeParams) -> Scene {
        let o = SceneOptions::d65(WavelengthGrid::default()).unwrap();
        slanted_edge(&o, p).unwrap()
    }

    #[test]
    fn coverage_is_the_area_right_of_the_line() {
        let p = SlantedEdgeParams::new(64, 64);
        // against a fine point-sampled estimate of the same area
        for r in [10, 20, 37, 63] {
            for c in 20..44 {
                let n = 200;
                let mut inside = 0;
                for i in 0..n {
                    for j in 0..n {
                        let y = r as f64 + (i as f64 + 0.5) / n as f64;
                        let x = c as f64 + (j as f64 + 0.5) / n as f64;
                        if x > p.edge_x(y) {
                            inside += 1;
                        }
                    }
                }
                let want = f64::from(inside) / (n * n) as f64;
                let got = p.bright_coverage(r, c);
                assert!((got - want).abs() < 2e-3, "({r}, {c}): {got} vs {want}");
            }
        }
    }

    #[test]
    fn a_row_crossing_the_edge_holds_the_analytic_mix() {
        let p = SlantedEdgeParams::new(64, 64);
        let s = scene(&p);
        let band = 15;
        for r in p.white_rows..p.rows {
            // the row's sum over the crossing equals dark·(x − c0) + bright·(c1 − x) with x
            // the edge's mean column over the row: the area split exactly
            let x = p.edge_x(r as f64 + 0.5);
            let (c0, c1) = (x.floor() as usize - 4, x.floor() as usize + 5);
            let sum: f64 = (c0..c1)
                .map(|c| f64::from(s.reflectance[[band, r, c]]))
                .sum();
            let want = p.dark * (x - c0 as f64) + p.bright * (c1 as f64 - x);
            assert!((sum - want).abs() < 1e-5, "row {r}: {sum} vs {want}");
            // and the mix is monotone from one grey to the other
            let row: Vec<f32> = (0..p.cols).map(|c| s.reflectance[[band, r, c]]).collect();
            assert!(row.windows(2).all(|w| w[1] >= w[0]));
        }
        // the white strip and the patches
        assert_eq!(s.reflectance[[band, 0, 0]], WHITE_REFERENCE as f32);
        let names: Vec<&str> = s.patches.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, [WHITE_PATCH, DARK_PATCH, BRIGHT_PATCH]);
        for patch in &s.patches[1..] {
            let level = patch.reflectance.values()[0] as f32;
            for r in patch.row..patch.row + patch.height {
                for c in patch.col..patch.col + patch.width {
                    let v = s.reflectance[[band, r, c]];
                    assert!((v - level).abs() < 1e-6, "{} ({r}, {c})", patch.name);
                }
            }
        }
    }

    #[test]
    fn bad_edges_are_refused() {
        let o = SceneOptions::d65(WavelengthGrid::default()).unwrap();
        let ok = SlantedEdgeParams::new(64, 64);
        for bad in [
            SlantedEdgeParams { rows: 20, ..ok },
            SlantedEdgeParams {
                angle_deg: 0.0,
                ..ok
            },
            SlantedEdgeParams {
                angle_deg: f64::NAN,
                ..ok
            },
            SlantedEdgeParams { dark: 0.7, ..ok },
            SlantedEdgeParams { bright: 1.5, ..ok },
            SlantedEdgeParams {
                white_rows: 40,
                ..ok
            },
        ] {
            assert!(slanted_edge(&o, &bad).is_err(), "{bad:?}");
        }
    }
}
