//! How to render: output white, region (`x,y,width,height`), preview downscale (1–16), PNG
//! compression and JPEG options; the output size they give, and the box-average downscale.

use super::error::PipelineError;
use super::output::Encoding;
use crate::io::{JpegOptions, PngCompression};
use crate::l3::render::ChromaMode;
use crate::l3::render::{Region, WhiteLevel};

/// Largest preview downscale factor.
pub const MAX_PREVIEW: usize = 16;

/// How to render.
#[derive(Debug, Clone, Copy)]
pub struct RenderOptions {
    /// The Y that maps to white (display-referred outputs).
    pub white: WhiteLevel,
    /// The part of the frame to render (default: all of it).
    pub region: Option<Region>,
    /// Integer box-average downscale, 1 (none) to [`MAX_PREVIEW`].
    pub preview: usize,
    /// PNG compression.
    pub png: PngCompression,
    /// JPEG quality and chroma subsampling.
    pub jpeg: JpegOptions,
    /// Whether the chroma stage runs ([`ChromaMode`]; `auto`: when the frame needs it).
    pub chroma: ChromaMode,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            white: WhiteLevel::Auto,
            region: None,
            preview: 1,
            png: PngCompression::Fast,
            jpeg: JpegOptions::default(),
            chroma: ChromaMode::Auto,
        }
    }
}

impl RenderOptions {
    /// Whether the whole frame is rendered at full size (no region, no preview).
    pub fn whole_frame(&self) -> bool {
        self.region.is_none() && self.preview == 1
    }

    /// How the compressed outputs are encoded.
    pub fn encoding(&self) -> Encoding {
        Encoding {
            png: self.png,
            jpeg: self.jpeg,
        }
    }
}

/// A crop written `x,y,width,height`.
pub fn parse_region(s: &str) -> Result<Region, PipelineError> {
    let v: Vec<usize> = s
        .split(',')
        .map(|p| p.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            PipelineError::Options(format!(
                "region '{s}': expected x,y,width,height (non-negative integers)"
            ))
        })?;
    let [x, y, width, height] = v[..] else {
        return Err(PipelineError::Options(format!(
            "region '{s}': expected four numbers x,y,width,height"
        )));
    };
    Ok(Region {
        x,
        y,
        width,
        height,
    })
}

/// A preview factor from 1 to [`MAX_PREVIEW`].
pub fn check_preview(preview: usize) -> Result<usize, PipelineError> {
    if (1..=MAX_PREVIEW).contains(&preview) {
        Ok(preview)
    } else {
        Err(PipelineError::Options(format!(
            "preview {preview}: an integer downscale factor from 1 to {MAX_PREVIEW}"
        )))
    }
}

/// The output size of a `width × height` frame under `opts`, or why the options do not fit.
pub fn output_size(
    width: usize,
    height: usize,
    opts: &RenderOptions,
) -> Result<(usize, usize), PipelineError> {
    let preview = check_preview(opts.preview)?;
    let (ow, oh) = match opts.region {
        None => (width, height),
        Some(r) => {
            let inside = r.width > 0
                && r.height > 0
                && r.x.checked_add(r.width).is_some_and(|e| e <= width)
                && r.y.checked_add(r.height).is_some_and(|e| e <= height);
            if !inside {
                return Err(PipelineError::Options(format!(
                    "region {},{},{}×{} is empty or not inside the {width}×{height} frame",
                    r.x, r.y, r.width, r.height
                )));
            }
            (r.width, r.height)
        }
    };
    if ow / preview == 0 || oh / preview == 0 {
        return Err(PipelineError::Options(format!(
            "preview {preview} leaves nothing of a {ow}×{oh} image"
        )));
    }
    Ok((ow / preview, oh / preview))
}

/// Box-average downscale by `k` (partial edge blocks dropped).
pub fn downscale(xyz: &[f32], w: usize, h: usize, k: usize) -> (Vec<f32>, usize, usize) {
    let (ow, oh) = (w / k, h / k);
    let mut out = vec![0f32; ow * oh * 3];
    let n = (k * k) as f64;
    for oy in 0..oh {
        for ox in 0..ow {
            let mut acc = [0f64; 3];
            for dy in 0..k {
                let row = (oy * k + dy) * w;
                for dx in 0..k {
                    let p = (row + ox * k + dx) * 3;
                    for (c, a) in acc.iter_mut().enumerate() {
                        *a += f64::from(xyz[p + c]);
                    }
                }
            }
            for (c, a) in acc.iter().enumerate() {
                out[(oy * ow + ox) * 3 + c] = (a / n) as f32;
            }
        }
    }
    (out, ow, oh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn region_and_preview() {
        let opts = |region: &str, preview| RenderOptions {
            region: Some(parse_region(region).unwrap()),
            preview,
            ..RenderOptions::default()
        };
        assert_eq!(output_size(4, 4, &opts("0,0,2,2", 1)).unwrap(), (2, 2));
        assert!(output_size(4, 4, &opts("3,0,2,2", 1)).is_err());
        assert!(output_size(4, 4, &opts("0,0,0,2", 1)).is_err());
        assert!(output_size(4, 4, &opts("0,0,2,2", 4)).is_err());
        assert!(parse_region("a,b").is_err());
        assert!(parse_region("1,2,3").is_err());
        assert!(check_preview(0).is_err() && check_preview(17).is_err());
        let xyz: Vec<f32> = (0..4 * 2 * 3).map(|v| v as f32).collect();
        let (d, w, h) = downscale(&xyz, 4, 2, 2);
        assert_eq!((w, h), (2, 1));
        // mean of pixels 0,1,4,5 channel 0: (0+3+12+15)/4
        assert_eq!(d[0], 7.5);
    }
}
