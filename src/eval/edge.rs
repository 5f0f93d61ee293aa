//! Sharpness and false colour of a rendering method on a simulated slanted edge
//! ([`crate::scene::slanted_edge`]) captured through the full camera model.
//!
//! **Sharpness.** The e-SFR ([`slanted_edge_sfr`]) of the rendered luminance Y over the edge's
//! region of interest: the edge region below the white strip, less [`ROI_MARGIN`] pixels on
//! every side (the strip's own edge and the image borders stay out). MTF50 and the SFR at half
//! Nyquist are in cycles per pixel. The ideal image (the noise-free XYZ of the same optical
//! image relit by D65, what a perfect camera behind this lens records) gives the lens's and
//! the pixel aperture's own MTF50 on the same region: no render can beat it without
//! sharpening.
//!
//! **False colour.** How much chroma the render puts at the neutral edge beyond what it puts
//! on the flat sides:
//! 1. The render is normalised channel by channel (a von Kries scaling in XYZ) so that the
//!    mean of the light side's flat region is the D65 white at Y = 1. A global colour cast of
//!    the render (any 3×3 applied to a neutral scene) is thereby removed: every neutral level
//!    has the same chromaticity, so it lands on the neutral axis.
//! 2. Every pixel's CIELAB chroma C*ab (D65 white) is taken, and squared.
//! 3. False colour = √(max(0, B − F)): B the mean C*ab² over the **band** (pixels whose centre
//!    lies within [`BAND_PX`] pixels of the edge line, horizontally), F the mean of the mean
//!    C*ab² of the two **flat strips** (pixels [`FLAT_NEAR_PX`]–[`FLAT_FAR_PX`] from the line,
//!    each side). It is the RMS chroma the edge itself gains (demosaicking fringes, colour
//!    zippers, chromatic blur), in C*ab units. A neutral render scores 0, a uniform cast 0,
//!    a one-pixel red–cyan fringe clearly more.
//!
//! Squares, not magnitudes: pixel noise adds chroma too, and the band's noise is the flat
//! strips' (half of the band lies on each side). A fringe `f` and zero-mean noise `n` give
//! E|f + n|² = |f|² + E|n|², so subtracting the flat strips' mean square leaves the fringe's
//! whatever the noise; magnitudes would add in quadrature and a fringe would vanish under low
//! light's noise. Per pixel rather than averaged along the edge: a demosaicking fringe on a
//! slanted edge changes hue with the CFA phase along the edge, and averaging a*, b* first
//! would cancel it.

use ndarray::Array2;
use serde::{Deserialize, Serialize};

use super::workflow::{ChartSetup, capture_scene, ideal_d65_image};
use super::{EvalError, Sfr, slanted_edge_sfr};
use crate::camera::Camera;
use crate::colour::{D65_WHITE_XYZ, xyz_to_lab};
use crate::scene::{SceneOptions, SlantedEdgeParams, slanted_edge};
use crate::spectral::{IlluminantSpec, IsetData};

/// Pixels left out on every side of the edge region for the SFR and the false colour.
pub const ROI_MARGIN: usize = 4;
/// Half-width of the false-colour band about the edge line, pixels.
pub const BAND_PX: f64 = 4.0;
/// The flat strips' distance from the edge line, pixels.
pub const FLAT_NEAR_PX: f64 = 10.0;
pub const FLAT_FAR_PX: f64 = 20.0;

/// The slanted edge captured once under one acquisition light, with its ideal image.
#[derive(Clone, Debug)]
pub struct EdgeCapture {
    pub params: SlantedEdgeParams,
    /// The acquisition illuminant's resolved name.
    pub acquisition: String,
    /// The raw mosaic in volts, row-major `width × height`.
    pub volts: Vec<f32>,
    pub width: usize,
    pub height: usize,
    pub exposure_s: f64,
    /// The noise-free XYZ of the optical image relit by D65 (interleaved).
    pub ideal_image: Vec<f32>,
    /// The ideal image's own e-SFR over the region of interest: the lens's and the pixel
    /// aperture's.
    pub ideal_sfr: Sfr,
}

/// A render of the edge, scored.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EdgeScore {
    /// MTF50 of the rendered luminance Y, cycles per pixel.
    pub mtf50: f64,
    /// The rendered SFR at half the Nyquist frequency (0.25 cycles per pixel).
    pub mtf_at_half_nyquist: f64,
    /// The ideal image's MTF50 on the same region (the lens's), cycles per pixel.
    pub ideal_mtf50: f64,
    /// RMS C*ab at the edge beyond the flat sides' (see the module doc).
    pub false_colour: f64,
    /// The rendered SFR (frequencies and values, for plotting).
    pub sfr: Sfr,
}

/// Simulate the slanted edge of `params` under `acquisition` as `setup` says (noise, seed,
/// exposure factor, mean luminance), with its ideal image.
pub fn simulate_edge(
    camera: &Camera,
    acquisition: &str,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
    params: &SlantedEdgeParams,
) -> Result<EdgeCapture, EvalError> {
    let named = IlluminantSpec::parse(acquisition)?.resolve(iset)?;
    let opts = SceneOptions::from_samples(*camera.grid(), &named.spd, named.name.clone())?
        .with_mean_luminance(setup.mean_luminance);
    let scene = slanted_edge(&opts, params)?;
    let cap = capture_scene(camera, &scene, setup)?;
    let (height, width) = cap.volts.dim();
    let ideal_image = ideal_d65_image(camera, &scene)?;
    let roi = Roi::of(params);
    let ideal_sfr = slanted_edge_sfr(roi.luminance(&ideal_image, width)?.view())?;
    Ok(EdgeCapture {
        params: *params,
        acquisition: named.name,
        volts: cap.volts.into_raw_vec_and_offset().0,
        width,
        height,
        exposure_s: cap.exposure_s,
        ideal_image,
        ideal_sfr,
    })
}

impl EdgeCapture {
    /// Score a rendered XYZ image (interleaved, `width × height × 3`) of this capture:
    /// its e-SFR and its false colour. An edge the SFR cannot find in the render is an
    /// error ([`EvalError::Sfr`]).
    pub fn score(&self, rendered_xyz: &[f32]) -> Result<EdgeScore, EvalError> {
        let sfr = self.sfr(rendered_xyz)?;
        Ok(EdgeScore {
            mtf50: sfr.mtf50_cycles_per_pixel,
            mtf_at_half_nyquist: sfr.mtf_at_half_nyquist,
            ideal_mtf50: self.ideal_sfr.mtf50_cycles_per_pixel,
            false_colour: self.false_colour(rendered_xyz)?,
            sfr,
        })
    }

    /// The e-SFR of a rendered XYZ image alone ([`EvalError::Sfr`] when it finds no edge).
    pub fn sfr(&self, rendered_xyz: &[f32]) -> Result<Sfr, EvalError> {
        self.check(rendered_xyz)?;
        let roi = Roi::of(&self.params);
        Ok(slanted_edge_sfr(
            roi.luminance(rendered_xyz, self.width)?.view(),
        )?)
    }

    /// The false colour of a rendered XYZ image alone (see the module doc);
    /// [`EvalError::NoSignal`] when the edge's light side is dark in some XYZ channel.
    pub fn false_colour(&self, rendered_xyz: &[f32]) -> Result<f64, EvalError> {
        self.check(rendered_xyz)?;
        false_colour(&self.params, rendered_xyz, self.width)
    }

    fn check(&self, xyz: &[f32]) -> Result<(), EvalError> {
        if xyz.len() != self.width * self.height * 3 {
            return Err(EvalError::Invalid(format!(
                "the edge render has {} values; {}×{}×3 expected",
                xyz.len(),
                self.width,
                self.height
            )));
        }
        if xyz.iter().any(|v| !v.is_finite()) {
            return Err(EvalError::Invalid(
                "the edge render holds a value that is not finite".into(),
            ));
        }
        Ok(())
    }
}

/// The edge's region of interest: rows `r0..r1`, columns `c0..c1`.
#[derive(Clone, Copy, Debug)]
struct Roi {
    r0: usize,
    r1: usize,
    c0: usize,
    c1: usize,
}

impl Roi {
    fn of(p: &SlantedEdgeParams) -> Self {
        Roi {
            r0: p.white_rows + ROI_MARGIN,
            r1: p.rows.saturating_sub(ROI_MARGIN),
            c0: ROI_MARGIN,
            c1: p.cols.saturating_sub(ROI_MARGIN),
        }
    }

    /// Y over the region.
    fn luminance(&self, xyz: &[f32], width: usize) -> Result<Array2<f64>, EvalError> {
        if self.r1 <= self.r0 || self.c1 <= self.c0 || xyz.len() < self.r1 * width * 3 {
            return Err(EvalError::Invalid(
                "the edge region is empty or outside the image".into(),
            ));
        }
        Ok(Array2::from_shape_fn(
            (self.r1 - self.r0, self.c1 - self.c0),
            |(r, c)| f64::from(xyz[((self.r0 + r) * width + self.c0 + c) * 3 + 1]),
        ))
    }
}

/// Mean XYZ of the pixels of the region whose signed horizontal distance `d` from the edge
/// line (pixel centre minus line) satisfies `keep(d)`, and their count.
fn mean_where(
    p: &SlantedEdgeParams,
    xyz: &[f32],
    width: usize,
    keep: impl Fn(f64) -> bool,
) -> ([f64; 3], usize) {
    let roi = Roi::of(p);
    let (mut s, mut n) = ([0.0; 3], 0usize);
    for r in roi.r0..roi.r1 {
        let x = p.edge_x(r as f64 + 0.5);
        for c in roi.c0..roi.c1 {
            if keep(c as f64 + 0.5 - x) {
                let i = (r * width + c) * 3;
                for k in 0..3 {
                    s[k] += f64::from(xyz[i + k]);
                }
                n += 1;
            }
        }
    }
    (s.map(|v| v / n.max(1) as f64), n)
}

/// Mean C*ab² (after `scale`, per XYZ channel, and the D65 white) of the pixels `keep` selects.
fn mean_square_chroma(
    p: &SlantedEdgeParams,
    xyz: &[f32],
    width: usize,
    scale: [f64; 3],
    keep: impl Fn(f64) -> bool,
) -> Result<f64, EvalError> {
    let roi = Roi::of(p);
    let (mut sum, mut n) = (0.0, 0usize);
    for r in roi.r0..roi.r1 {
        let x = p.edge_x(r as f64 + 0.5);
        for c in roi.c0..roi.c1 {
            if keep(c as f64 + 0.5 - x) {
                let i = (r * width + c) * 3;
                let v = [0, 1, 2].map(|k| (f64::from(xyz[i + k]) * scale[k]).max(0.0));
                let lab = xyz_to_lab(v, D65_WHITE_XYZ);
                sum += lab[1] * lab[1] + lab[2] * lab[2];
                n += 1;
            }
        }
    }
    if n == 0 {
        return Err(EvalError::Invalid(
            "the edge region holds no pixels for the false colour".into(),
        ));
    }
    Ok(sum / n as f64)
}

/// False colour of `xyz` (interleaved, `p.cols` wide) on the edge of `p`: see the module doc.
pub fn false_colour(p: &SlantedEdgeParams, xyz: &[f32], width: usize) -> Result<f64, EvalError> {
    if width != p.cols || xyz.len() != p.rows * p.cols * 3 {
        return Err(EvalError::Invalid(format!(
            "an image of {} values, {width} wide, for a {}×{} edge",
            xyz.len(),
            p.cols,
            p.rows
        )));
    }
    let flat = |d: f64| (FLAT_NEAR_PX..=FLAT_FAR_PX).contains(&d);
    let (bright, n) = mean_where(p, xyz, width, flat);
    if n == 0 || !bright.iter().all(|v| v.is_finite() && *v > 0.0) {
        return Err(EvalError::NoSignal(format!(
            "the edge's light side has no signal (mean XYZ {bright:?})"
        )));
    }
    let scale = [0, 1, 2].map(|k| D65_WHITE_XYZ[k] / bright[k]);
    let band = mean_square_chroma(p, xyz, width, scale, |d| d.abs() <= BAND_PX)?;
    let light = mean_square_chroma(p, xyz, width, scale, flat)?;
    let dark = mean_square_chroma(p, xyz, width, scale, |d| flat(-d))?;
    let fc = (band - 0.5 * (light + dark)).max(0.0).sqrt();
    if !fc.is_finite() {
        return Err(EvalError::Invalid("the false colour is not finite".into()));
    }
    Ok(fc)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A neutral render of the edge: the analytic coverage blurred by a 3-tap box, as XYZ of
    /// the D65 white times the level, times `cast` per channel.
    fn neutral(p: &SlantedEdgeParams, cast: [f64; 3]) -> Vec<f32> {
        let mut out = vec![0f32; p.rows * p.cols * 3];
        for r in 0..p.rows {
            for c in 0..p.cols {
                let level = if r < p.white_rows {
                    0.95
                } else {
                    let cov: f64 = (c.saturating_sub(1)..(c + 2).min(p.cols))
                        .map(|k| p.bright_coverage(r, k))
                        .sum::<f64>()
                        / 3.0;
                    p.dark + cov * (p.bright - p.dark)
                };
                for k in 0..3 {
                    out[(r * p.cols + c) * 3 + k] = (level * D65_WHITE_XYZ[k] * cast[k]) as f32;
                }
            }
        }
        out
    }

    #[test]
    fn a_neutral_render_and_a_colour_cast_score_no_false_colour() {
        let p = SlantedEdgeParams::new(64, 64);
        let fc = false_colour(&p, &neutral(&p, [1.0; 3]), p.cols).unwrap();
        // (f32 rounding, under the square root)
        assert!(fc.abs() < 1e-2, "{fc}");
        let cast = false_colour(&p, &neutral(&p, [1.1, 1.0, 0.7]), p.cols).unwrap();
        assert!(cast.abs() < 1e-2, "{cast}");
    }

    #[test]
    fn a_one_pixel_red_cyan_fringe_scores_clearly() {
        let p = SlantedEdgeParams::new(64, 64);
        let mut img = neutral(&p, [1.0; 3]);
        for r in p.white_rows..p.rows {
            let x = p.edge_x(r as f64 + 0.5).floor() as usize;
            // red just left of the edge, cyan just right (X up / Z down and back)
            for (c, f) in [(x - 1, [1.25, 1.0, 0.8]), (x + 1, [0.8, 1.0, 1.25])] {
                for k in 0..3 {
                    img[(r * p.cols + c) * 3 + k] *= f[k] as f32;
                }
            }
        }
        let fc = false_colour(&p, &img, p.cols).unwrap();
        // two of the band's ~9 pixels per row carry ~15 C*ab: RMS ~7
        assert!(fc > 4.0, "{fc}");
        // and the same fringe under a cast still scores
        let cast: Vec<f32> = img
            .chunks(3)
            .flat_map(|v| [v[0] * 1.1, v[1], v[2] * 0.7])
            .collect();
        let fc_cast = false_colour(&p, &cast, p.cols).unwrap();
        assert!((fc_cast - fc).abs() < 0.2 * fc, "{fc_cast} vs {fc}");
    }

    #[test]
    fn noise_alone_scores_little_and_does_not_hide_a_fringe() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let p = SlantedEdgeParams::new(96, 96);
        let clean = neutral(&p, [1.0; 3]);
        let mut fringed = clean.clone();
        for r in p.white_rows..p.rows {
            let x = p.edge_x(r as f64 + 0.5).floor() as usize;
            for (c, f) in [(x - 1, [1.25, 1.0, 0.8]), (x + 1, [0.8, 1.0, 1.25])] {
                for k in 0..3 {
                    fringed[(r * p.cols + c) * 3 + k] *= f[k] as f32;
                }
            }
        }
        let noisy = |img: &[f32], seed| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let n = Normal::new(1.0, 0.03).unwrap();
            img.iter()
                .map(|v| v * n.sample(&mut rng) as f32)
                .collect::<Vec<f32>>()
        };
        let fc = |img: &[f32]| false_colour(&p, img, p.cols).unwrap();
        let (fringe, noise) = (fc(&fringed), fc(&noisy(&clean, 1)));
        // 3 % channel noise is ~5 C*ab per pixel: its excess at the edge is small
        assert!(noise < 0.3 * fringe, "{noise} vs {fringe}");
        // and the fringe under that noise keeps most of its score
        let both = fc(&noisy(&fringed, 2));
        assert!((both - fringe).abs() < 0.25 * fringe, "{both} vs {fringe}");
    }

    #[test]
    fn bad_renders_are_errors() {
        let p = SlantedEdgeParams::new(64, 64);
        assert!(false_colour(&p, &[0.0; 12], 2).is_err());
        let black = vec![0f32; p.rows * p.cols * 3];
        assert!(false_colour(&p, &black, p.cols).is_err());
    }

    #[test]
    fn the_captured_edge_is_sharp_as_the_lens_and_finds_its_edge() {
        let camera = crate::test_support::paper_camera();
        let setup = ChartSetup {
            noise: false,
            ..ChartSetup::default()
        };
        let p = SlantedEdgeParams::new(64, 64);
        let cap = simulate_edge(&camera, "D65", None, &setup, &p).unwrap();
        let m = cap.ideal_sfr.mtf50_cycles_per_pixel;
        // the lens at f/4 and the 2.2 µm pixel: below Nyquist, far from nothing
        assert!(m.is_finite() && m > 0.1 && m < 0.5, "{m}");
        assert!((cap.ideal_sfr.slant_degrees.abs() - 5.0).abs() < 0.3);
        // the ideal image scored as a render: itself, no false colour
        let s = cap.score(&cap.ideal_image).unwrap();
        assert!((s.mtf50 - m).abs() < 1e-9);
        // (the lens blurs short wavelengths less: a trace of colour at the edge, no more)
        assert!(s.false_colour.abs() < 1.0, "{}", s.false_colour);
        // a flat render has no edge: an error, not a panic
        let flat = vec![0.5f32; cap.width * cap.height * 3];
        assert!(matches!(cap.score(&flat), Err(EvalError::Sfr(_))));
        assert!(cap.score(&flat[3..]).is_err());
        // a render with no Z on the light side (a light with almost no blue) finds its edge,
        // but has no false colour to measure
        let no_blue: Vec<f32> = cap
            .ideal_image
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], 0.0])
            .collect();
        assert!(cap.sfr(&no_blue).is_ok());
        assert!(matches!(
            cap.false_colour(&no_blue),
            Err(EvalError::NoSignal(_))
        ));
    }
}
