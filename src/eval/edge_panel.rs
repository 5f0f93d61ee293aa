//! The data of the evaluation figure's sharpness panel: each method's SFR curve on the
//! slanted edge beside the edge's ideal image (the lens and the pixel aperture alone), and a
//! crop of the edge from each, as small sRGB PNGs so that the report's JSON carries what the
//! figure draws.

use serde::{Deserialize, Serialize};

use super::EvalError;
use super::edge::EdgeCapture;
use super::sfr::Sfr;
use super::workflow::{ChannelSet, ColourFit, fit_colour_matrix};
use crate::baseline::{Isp, NoiseProfile};
use crate::camera::Camera;
use crate::colour::{encode_srgb8, xyz_to_linear_srgb};
use crate::l3::table::TableKind;
use crate::spectral::IsetData;

/// The side of an edge crop, pixels.
pub const CROP_SIDE: usize = 40;

/// The crops' display level: each crop is scaled so its brighter side's mean luminance is this
/// (sRGB), which shows the edge and any fringe without clipping.
const CROP_WHITE_Y: f64 = 0.8;

/// A crop of an edge image as an sRGB PNG.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EdgeCrop {
    pub width: usize,
    pub height: usize,
    /// The crop as an 8-bit sRGB PNG, base64 (standard alphabet, padded).
    pub png_base64: String,
}

/// One image of the edge: its name, sharpness and false colour, SFR curve and crop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EdgeCurve {
    pub name: String,
    /// MTF50, cycles per pixel; absent where no edge was found (noise at very low light).
    pub mtf50: Option<f64>,
    /// Mean C*ab at the neutral edge beyond the flat sides' (0 for the ideal image).
    pub false_colour: Option<f64>,
    /// The SFR from 0 to 0.5 cycles per pixel (empty where no edge was found).
    pub frequencies: Vec<f64>,
    pub sfr: Vec<f64>,
    pub crop: EdgeCrop,
}

/// The panel: the ideal image's edge and each method's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EdgePanel {
    pub ideal: EdgeCurve,
    pub methods: Vec<EdgeCurve>,
}

impl EdgePanel {
    /// The panel of `edge`: its ideal image, then each `(name, rendered XYZ)` of it.
    pub fn new(edge: &EdgeCapture, renders: &[(String, Vec<f32>)]) -> Result<Self, EvalError> {
        let (w, h) = (edge.width, edge.height);
        let ideal = EdgeCurve::new(
            "ideal (lens)",
            &edge.ideal_image,
            w,
            h,
            Some(&edge.ideal_sfr),
            edge.false_colour(&edge.ideal_image).ok(),
        )?;
        let methods = renders
            .iter()
            .map(|(name, xyz)| match edge.score(xyz) {
                Ok(s) => EdgeCurve::new(name, xyz, w, h, Some(&s.sfr), Some(s.false_colour)),
                // no edge the SFR finds (noise at very low light): the crop and false colour
                Err(EvalError::Sfr(_)) => {
                    EdgeCurve::new(name, xyz, w, h, None, edge.false_colour(xyz).ok())
                }
                Err(e) => Err(e),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { ideal, methods })
    }
}

/// The rival a method's edge is shown beside: the strong ISP with the white-balanced colour
/// matrix fitted under `acquisition` (a conventional 3×3 on R, G, B where the CFA has them;
/// Table 1's `ISP_<light>`), denoising by the camera's noise model when `noise`. It renders
/// with no further correction (its output is already under D65).
pub fn acquisition_isp(
    camera: &Camera,
    acquisition: &str,
    iset: Option<&IsetData>,
    noise: bool,
) -> Result<Isp, EvalError> {
    let lights = [acquisition.to_string()];
    let fit = ColourFit {
        illuminants: &lights,
        kind: TableKind::CrossIlluminant,
        channels: ChannelSet::Rgb,
        preserve_white: true,
        through_correction: false,
    };
    let m = fit_colour_matrix(camera, &fit, iset)?;
    Ok(Isp::new(m, noise.then(|| NoiseProfile::new(camera, 0.0))))
}

/// The SFR up to Nyquist (the figure's range).
fn to_nyquist(sfr: Option<&Sfr>) -> (Vec<f64>, Vec<f64>) {
    sfr.map(|s| {
        s.frequencies
            .iter()
            .zip(&s.sfr)
            .filter(|(f, v)| **f <= 0.5 + 1e-9 && v.is_finite())
            .map(|(f, v)| (*f, *v))
            .unzip()
    })
    .unwrap_or_default()
}

impl EdgeCurve {
    /// An edge image's entry: `xyz` interleaved `width × height × 3`, its SFR (None where none
    /// was found) and false colour.
    pub fn new(
        name: &str,
        xyz: &[f32],
        width: usize,
        height: usize,
        sfr: Option<&Sfr>,
        false_colour: Option<f64>,
    ) -> Result<Self, EvalError> {
        let (frequencies, values) = to_nyquist(sfr);
        Ok(Self {
            name: name.to_string(),
            mtf50: sfr.map(|s| s.mtf50_cycles_per_pixel),
            false_colour,
            frequencies,
            sfr: values,
            crop: EdgeCrop::centre(xyz, width, height)?,
        })
    }
}

impl EdgeCrop {
    /// The central [`CROP_SIDE`]² pixels of `xyz` (or the whole image when smaller), scaled so
    /// the brighter half's mean luminance is `CROP_WHITE_Y`, as an sRGB PNG.
    pub fn centre(xyz: &[f32], width: usize, height: usize) -> Result<Self, EvalError> {
        if width == 0 || height == 0 || xyz.len() != width * height * 3 {
            return Err(EvalError::Invalid(format!(
                "an edge crop of a {width}×{height} image with {} values",
                xyz.len()
            )));
        }
        let (w, h) = (CROP_SIDE.min(width), CROP_SIDE.min(height));
        let (x0, y0) = ((width - w) / 2, (height - h) / 2);
        let px = |x: usize, y: usize| {
            let i = ((y0 + y) * width + x0 + x) * 3;
            [xyz[i], xyz[i + 1], xyz[i + 2]].map(f64::from)
        };
        let mut ys: Vec<f64> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| px(x, y)[1])
            .filter(|v| v.is_finite())
            .collect();
        ys.sort_by(f64::total_cmp);
        let bright = &ys[ys.len() / 2..];
        let mean = bright.iter().sum::<f64>() / bright.len().max(1) as f64;
        let scale = if mean > 0.0 && mean.is_finite() {
            CROP_WHITE_Y / mean
        } else {
            1.0
        };
        let mut rgb = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                let v = px(x, y).map(|c| if c.is_finite() { c * scale } else { 0.0 });
                rgb.extend(xyz_to_linear_srgb(v).map(encode_srgb8));
            }
        }
        Ok(Self {
            width: w,
            height: h,
            png_base64: png_base64(&rgb, w, h)?,
        })
    }
}

/// 8-bit RGB pixels as a base64 PNG.
fn png_base64(rgb: &[u8], width: usize, height: usize) -> Result<String, EvalError> {
    use base64::Engine as _;
    let bad = |e: String| EvalError::Invalid(format!("encoding an edge crop: {e}"));
    let mut out = Vec::new();
    {
        let w = u32::try_from(width).map_err(|e| bad(e.to_string()))?;
        let h = u32::try_from(height).map_err(|e| bad(e.to_string()))?;
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(|e| bad(e.to_string()))?;
        writer
            .write_image_data(rgb)
            .map_err(|e| bad(e.to_string()))?;
    }
    Ok(base64::engine::general_purpose::STANDARD.encode(out))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(width: usize, height: usize) -> Vec<f32> {
        (0..width * height)
            .flat_map(|i| {
                let y = if i % width < width / 2 { 0.1 } else { 0.5 };
                [0.9505 * y, y, 1.089 * y]
            })
            .collect()
    }

    #[test]
    fn a_crop_is_a_png_of_the_centre_scaled_to_the_display_white() {
        let xyz = step(64, 50);
        let c = EdgeCrop::centre(&xyz, 64, 50).unwrap();
        assert_eq!((c.width, c.height), (CROP_SIDE, CROP_SIDE));
        use base64::Engine as _;
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(&c.png_base64)
            .unwrap();
        let img = image::load_from_memory(&bytes).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (40, 40));
        // the bright side at Y 0.8: sRGB about 231; the dark side a fifth of it, neutral
        let (dark, bright) = (img.get_pixel(0, 0), img.get_pixel(39, 39));
        assert!((i32::from(bright[1]) - 231).abs() <= 2, "{bright:?}");
        assert!(bright[0].abs_diff(bright[2]) <= 2 && dark[0].abs_diff(dark[2]) <= 2);
        assert!(dark[1] < bright[1] / 2);
        // smaller than the crop: the whole image
        let c = EdgeCrop::centre(&step(8, 6), 8, 6).unwrap();
        assert_eq!((c.width, c.height), (8, 6));
        assert!(EdgeCrop::centre(&xyz, 64, 49).is_err());
    }

    #[test]
    fn a_curve_keeps_the_sfr_up_to_nyquist() {
        let sfr = Sfr {
            mtf50_cycles_per_pixel: 0.3,
            mtf_at_half_nyquist: 0.7,
            mtf_at_nyquist: 0.2,
            orientation: crate::eval::EdgeOrientation::Vertical,
            slant_degrees: 5.0,
            falling: false,
            lines_used: 40,
            frequencies: vec![0.0, 0.25, 0.5, 0.75, 1.0],
            sfr: vec![1.0, 0.7, 0.2, 0.1, f64::NAN],
        };
        let c = EdgeCurve::new("L3", &step(64, 64), 64, 64, Some(&sfr), Some(0.4)).unwrap();
        assert_eq!(c.frequencies, [0.0, 0.25, 0.5]);
        assert_eq!(c.sfr, [1.0, 0.7, 0.2]);
        assert_eq!(c.mtf50, Some(0.3));
        let none = EdgeCurve::new("noisy", &step(64, 64), 64, 64, None, None).unwrap();
        assert!(none.frequencies.is_empty() && none.mtf50.is_none());
    }
}
