//! An image file (PNG, TIFF or PNM; grey or RGB; 8 or 16 bits or float) as linear luminance,
//! for measurements on a user's own images (the edge SFR). Decoding is `image`'s, under the
//! caller's [`Limits`] checked from the header before pixels are allocated.

use std::io::Cursor;

use image::{ImageDecoder, ImageReader};
use ndarray::Array2;

use super::{IoError, IoResult, Limits};

/// How the file's values relate to light.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Transfer {
    /// Values proportional to light (a linear 16-bit TIFF, a raw-derived PNG).
    #[default]
    Linear,
    /// sRGB-encoded values (a rendered 8-bit PNG): decoded with the sRGB curve first.
    Srgb,
}

impl std::str::FromStr for Transfer {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "linear" => Ok(Transfer::Linear),
            "srgb" => Ok(Transfer::Srgb),
            other => Err(format!("transfer '{other}': linear or srgb expected")),
        }
    }
}

fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The image in `bytes` as luminance in [0, 1] (full scale of its sample type, or float
/// values as stored): grey as is, RGB as Y = 0.2126 R + 0.7152 G + 0.0722 B of the linear
/// values (the BT.709 / sRGB primaries). Alpha is ignored.
pub fn decode_luminance(
    bytes: &[u8],
    transfer: Transfer,
    limits: &Limits,
) -> IoResult<Array2<f64>> {
    let unknown = |e: std::io::Error| IoError::UnknownFormat {
        detail: e.to_string(),
    };
    let reader = ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(unknown)?;
    let decoder = reader.into_decoder().map_err(|e| IoError::UnknownFormat {
        detail: e.to_string(),
    })?;
    let (w, h) = decoder.dimensions();
    limits.check(w as usize, h as usize)?;
    let img = image::DynamicImage::from_decoder(decoder).map_err(|e| IoError::UnknownFormat {
        detail: e.to_string(),
    })?;
    let (w, h) = (w as usize, h as usize);
    let lin = |v: f32| {
        let v = f64::from(v);
        match transfer {
            Transfer::Linear => v,
            Transfer::Srgb => srgb_to_linear(v),
        }
    };
    let grey = !img.color().has_color();
    let rgb = img.into_rgb32f();
    let mut out = Array2::zeros((h, w));
    for (x, y, p) in rgb.enumerate_pixels() {
        let [r, g, b] = p.0;
        let v = if grey {
            lin(r)
        } else {
            0.2126 * lin(r) + 0.7152 * lin(g) + 0.0722 * lin(b)
        };
        if !v.is_finite() {
            return Err(IoError::NonFinite {
                what: "image",
                x: x as usize,
                y: y as usize,
                channel: String::new(),
                value: v as f32,
            });
        }
        out[[y as usize, x as usize]] = v;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey16_and_rgb8_become_luminance() {
        let g = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(3, 2, |x, _| {
            image::Luma([(x * 30000) as u16])
        });
        let mut png = Vec::new();
        image::DynamicImage::ImageLuma16(g)
            .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let y = decode_luminance(&png, Transfer::Linear, &Limits::default()).unwrap();
        assert_eq!(y.dim(), (2, 3));
        assert!((y[[1, 2]] - 60000.0 / 65535.0).abs() < 1e-6);

        let c = image::RgbImage::from_pixel(2, 2, image::Rgb([255, 0, 0]));
        let mut png = Vec::new();
        image::DynamicImage::ImageRgb8(c)
            .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let y = decode_luminance(&png, Transfer::Srgb, &Limits::default()).unwrap();
        assert!((y[[0, 0]] - 0.2126).abs() < 1e-6);
        assert!(decode_luminance(b"not an image", Transfer::Linear, &Limits::default()).is_err());
        let tiny = Limits {
            max_pixels: 2,
            ..Limits::default()
        };
        assert!(decode_luminance(&png, Transfer::Linear, &tiny).is_err());
    }
}
