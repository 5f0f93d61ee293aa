//! Output encodings of rendered XYZ: linear sRGB with a white level, then
//! the sRGB transfer to 8 or 16 bits.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::error::RenderError;
use crate::colour::{SrgbLut, XYZ_TO_LINEAR_SRGB};

/// The XYZ luminance that maps to sRGB white.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WhiteLevel {
    /// The 99th percentile of Y in the image (robust to specular highlights).
    Auto,
    /// A fixed Y, in the table's volts-equivalent units.
    Y(f64),
}

impl std::str::FromStr for WhiteLevel {
    type Err = RenderError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(Self::Auto);
        }
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() && v > 0.0 => Ok(Self::Y(v)),
            _ => Err(RenderError::InvalidInput(format!(
                "white level '{s}': expected 'auto' or a positive number"
            ))),
        }
    }
}

/// Pixels sampled for the automatic white level: a grid of at most
/// [`WHITE_GRID`]² points, centred in its cells, row-major.
pub fn white_sample_points(width: usize, height: usize) -> Vec<(usize, usize)> {
    let step = |n: usize| n.div_ceil(WHITE_GRID).max(1);
    let (sr, sc) = (step(height), step(width));
    let mut pts = Vec::new();
    for r in (sr / 2..height).step_by(sr) {
        for c in (sc / 2..width).step_by(sc) {
            pts.push((r, c));
        }
    }
    pts
}

/// Grid side of [`white_sample_points`].
pub const WHITE_GRID: usize = 128;

/// The 99th percentile of sampled Y values (finite ones), or 1 when there is none > 0.
pub fn white_from_samples(mut ys: Vec<f32>) -> f64 {
    ys.retain(|v| v.is_finite());
    if ys.is_empty() {
        return 1.0;
    }
    let k = ((ys.len() - 1) as f64 * 0.99) as usize;
    let (_, v, _) = ys.select_nth_unstable_by(k, f32::total_cmp);
    let v = f64::from(*v);
    if v > 0.0 { v } else { 1.0 }
}

/// Resolve the white level of an interleaved `width × height` XYZ image to a Y value > 0:
/// the given Y, or the 99th percentile of Y over [`white_sample_points`] (robust to
/// specular highlights, and cheap: the fast renderer renders only those pixels).
pub fn white_y(xyz: &[f32], width: usize, height: usize, white: WhiteLevel) -> f64 {
    match white {
        WhiteLevel::Y(v) => v,
        WhiteLevel::Auto => white_from_samples(
            white_sample_points(width, height)
                .into_iter()
                .filter_map(|(r, c)| xyz.get((r * width + c) * 3 + 1).copied())
                .collect(),
        ),
    }
}

fn linear_rgb(p: &[f32], m: &[[f32; 3]; 3]) -> [f32; 3] {
    [0, 1, 2].map(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2])
}

/// XYZ → linear sRGB in f32 with Y = `white_y` as white: the matrix [`xyz_to_srgb8`] applies
/// (before [`SrgbLut`]), for renderers that encode sRGB in a pass of their own.
pub fn linear_srgb_matrix(white_y: f64) -> [[f32; 3]; 3] {
    let k = 1.0 / white_y;
    XYZ_TO_LINEAR_SRGB.map(|r| r.map(|v| (v * k) as f32))
}

/// Interleaved XYZ → 8-bit sRGB (clipped), Y = `white_y` maps to white.
pub fn xyz_to_srgb8(xyz: &[f32], white_y: f64) -> Vec<u8> {
    let m = linear_srgb_matrix(white_y);
    let lut = SrgbLut::new();
    let mut out = vec![0u8; xyz.len()];
    out.par_chunks_mut(3 * 4096)
        .zip(xyz.par_chunks(3 * 4096))
        .for_each(|(o, x)| {
            for (op, xp) in o.chunks_exact_mut(3).zip(x.chunks_exact(3)) {
                let rgb = linear_rgb(xp, &m);
                for i in 0..3 {
                    op[i] = lut.encode(rgb[i]);
                }
            }
        });
    out
}

/// Interleaved XYZ → 16-bit sRGB (clipped).
pub fn xyz_to_srgb16(xyz: &[f32], white_y: f64) -> Vec<u16> {
    let m = linear_srgb_matrix(white_y);
    let mut out = vec![0u16; xyz.len()];
    out.par_chunks_mut(3 * 4096)
        .zip(xyz.par_chunks(3 * 4096))
        .for_each(|(o, x)| {
            for (op, xp) in o.chunks_exact_mut(3).zip(x.chunks_exact(3)) {
                let rgb = linear_rgb(xp, &m);
                for i in 0..3 {
                    op[i] = crate::colour::encode_srgb16(rgb[i] as f64);
                }
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn d65_white_is_white_and_levels_parse() {
        let w = crate::colour::D65_WHITE_XYZ.map(|v| (v * 0.5) as f32);
        let px = xyz_to_srgb8(&w, 0.5);
        assert!(px.iter().all(|&v| v >= 254), "{px:?}");
        let p16 = xyz_to_srgb16(&w, 0.5);
        assert!(p16.iter().all(|&v| v >= 65_500));
        assert_eq!("auto".parse::<WhiteLevel>().unwrap(), WhiteLevel::Auto);
        assert_eq!("0.7".parse::<WhiteLevel>().unwrap(), WhiteLevel::Y(0.7));
        assert!("-1".parse::<WhiteLevel>().is_err());
        assert!("nan".parse::<WhiteLevel>().is_err());
        let img: Vec<f32> = (0..300).map(|i| (i / 3) as f32 * 0.01).collect();
        assert!((white_y(&img, 100, 1, WhiteLevel::Auto) - 0.98).abs() < 0.011);
        assert_eq!(white_sample_points(300, 2).len(), 2 * 100);
        assert_eq!(white_sample_points(1, 1), vec![(0, 0)]);
        assert_eq!(white_sample_points(4000, 3000).len(), 125 * 125);
    }
}
