//! JPEG: 8-bit sRGB as baseline JPEG, with the sRGB ICC profile ([`super::icc`]) in APP2 and
//! a JFIF APP0, at a chosen quality and chroma subsampling.
//!
//! The encoder is our own: baseline sequential DCT, Annex K's tables scaled by quality the IJG
//! way, Huffman coding with Annex K's tables (no per-image optimisation: a second pass costs
//! more than the bytes it saves are worth here). It is hand-written because a JPEG answer
//! must cost no more than a PNG one, and no encoder that builds with cargo alone came close.
//! Candidates, one thread, release builds, on rendered frames of the sine-and-noise test
//! mosaic (2 MP: 1600 × 1250; 12 MP: 4000 × 3000), quality 90, 4:2:0. Wall times are the
//! best of 7–15 runs on the two shared cores while other builds ran (medians were up to 1.7×
//! higher; under the heaviest load, with a load average of 9–13, every figure was 2–3× the
//! quiet one), so the instruction counts (callgrind, one encoding, load-independent) compare
//! the two pure-Rust encoders better:
//!
//! | encoder | 2 MP | 12 MP | instructions, 2 MP / 12 MP | bytes, 2 MP | builds from |
//! |---|---|---|---|---|---|
//! | this module (AVX2 DCT, portable elsewhere) | 12.2 ms (load 9–13) | 139 ms (load 13) | 36 M / 393 M | 141 kB | Rust |
//! | `jpeg-encoder` 0.7.1, `simd` | 25.0 ms; 54 ms (load 9–13) | 105 ms; 418 ms (load 13) | 211 M / 1 454 M | 147 kB | Rust |
//! | `image` 0.25 `JpegEncoder` | 77.6 ms | 520 ms | | 250 kB | Rust |
//! | `mozjpeg` 0.10 (fastest settings; no NASM here, so no SIMD) | 33.8 ms | 225 ms | | 79 kB | C, by `cc` |
//!
//! (The 2 MP byte counts of the first two rows are of the current renderer's frame; the
//! older rows' 178 kB, 250 kB and 79 kB of an earlier one.) `jpeg-encoder` spent its time
//! in chroma averaging and block gathering, colour conversion, and bit writing; ours does
//! 1/6 of its instructions. libjpeg-turbo (whose SIMD this module's tricks imitate) would
//! be as fast or faster, but it is C and NASM: a C toolchain and an assembler at build time,
//! which the pure-cargo quick start does not need today. mozjpeg's files are less than half
//! the size at the same nominal quality (its tables and trellis quantisation), but it is
//! slower even before counting its C build. Lossy WebP (libwebp 1.x through the `webp` crate,
//! method 4) took 164 ms (q75, 27 kB) and 251 ms (q90) on the 2 MP frame, 1.3–1.7 s on
//! 12 MP: far too slow to answer in line, so there is no WebP output; AVIF encoders (rav1e)
//! are slower still.
//!
//! Where the time goes, and what makes it short:
//! - colour conversion and downsampling ([`color`]): `f32` over contiguous rows, which the
//!   compiler vectorises; chroma is averaged over each block (libjpeg's way), not taken from
//!   its first pixel: where a render keeps a trace of the CFA's 2 × 2 period, the first pixel
//!   picks the same phase in every block, and a small simulated chart came out 2.3 codes
//!   darker on average than its PNG;
//! - the DCT ([`dct`]): AAN in `f32`, eight columns at once, quantised by multiplying with
//!   reciprocals and rounded with a magic constant; in AVX2 intrinsics ([`dct_avx2`]) where
//!   the CPU has it (chosen at run time), portable code everywhere else, the same bytes;
//! - Huffman coding ([`entropy`]): a nonzero mask in zig-zag order from eight table look-ups,
//!   runs from `trailing_zeros`, a 64-bit bit buffer, byte stuffing tested a word at a time.
//!
//! A frame is encoded in strips of [`STRIP_ROWS`] rows on all cores, each strip one restart
//! interval, joined with RST markers ([`encode`]); the strip height is fixed, so the bytes
//! never depend on the thread count and the CLI and service write the same file.

mod color;
mod dct;
#[cfg(target_arch = "x86_64")]
mod dct_avx2;
mod entropy;
mod headers;
mod scan;
mod tables;
#[cfg(test)]
mod tests;

use std::str::FromStr;

use super::error::{IoError, IoResult};
use super::icc::srgb_profile;
use super::raw::check_len;
use headers::{Frame, icc_fits, write_headers};
use scan::Plan;

/// The quality used when none is given.
pub const DEFAULT_JPEG_QUALITY: u8 = 90;

/// A JPEG quality from 1 (smallest) to 100 (best).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct JpegQuality(u8);

impl JpegQuality {
    /// `q` if it is 1–100.
    pub fn new(q: u32) -> Result<Self, InvalidJpegQuality> {
        match u8::try_from(q) {
            Ok(v @ 1..=100) => Ok(JpegQuality(v)),
            _ => Err(InvalidJpegQuality(q.to_string())),
        }
    }

    pub fn get(self) -> u8 {
        self.0
    }
}

impl Default for JpegQuality {
    fn default() -> Self {
        JpegQuality(DEFAULT_JPEG_QUALITY)
    }
}

impl std::fmt::Display for JpegQuality {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// A JPEG quality that is not an integer from 1 to 100.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("JPEG quality '{0}': expected an integer from 1 to 100")]
pub struct InvalidJpegQuality(pub String);

impl FromStr for JpegQuality {
    type Err = InvalidJpegQuality;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        s.trim()
            .parse::<u32>()
            .ok()
            .and_then(|q| JpegQuality::new(q).ok())
            .ok_or_else(|| InvalidJpegQuality(s.to_string()))
    }
}

/// Chroma subsampling: how many luma samples share one pair of chroma samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Subsampling {
    /// Half the chroma resolution both ways (the common default).
    #[default]
    S420,
    /// Half horizontally.
    S422,
    /// Full chroma resolution.
    S444,
}

impl Subsampling {
    /// The names [`FromStr`] takes.
    pub const NAMES: [&'static str; 3] = ["420", "422", "444"];

    pub fn name(self) -> &'static str {
        match self {
            Subsampling::S420 => "420",
            Subsampling::S422 => "422",
            Subsampling::S444 => "444",
        }
    }

    /// Luma's sampling factors, horizontal and vertical (chroma's are 1 × 1).
    fn factors(self) -> (u8, u8) {
        match self {
            Subsampling::S420 => (2, 2),
            Subsampling::S422 => (2, 1),
            Subsampling::S444 => (1, 1),
        }
    }
}

impl std::fmt::Display for Subsampling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A subsampling name that is none of `420`, `422` and `444`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("chroma subsampling '{0}': expected 420, 422 or 444")]
pub struct UnknownSubsampling(pub String);

impl FromStr for Subsampling {
    type Err = UnknownSubsampling;

    /// `420`, `422`, `444` (also written `4:2:0` …).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().replace(':', "").as_str() {
            "420" => Ok(Subsampling::S420),
            "422" => Ok(Subsampling::S422),
            "444" => Ok(Subsampling::S444),
            _ => Err(UnknownSubsampling(s.to_string())),
        }
    }
}

/// How to encode a JPEG.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct JpegOptions {
    pub quality: JpegQuality,
    pub subsampling: Subsampling,
}

/// Rows per strip encoded on its own thread (a multiple of every MCU height): ten strips
/// for a 2 MP frame, so that two cores share them evenly.
const STRIP_ROWS: usize = 128;

/// The whole file. With `strips`, a frame taller than one strip is coded in strips of
/// [`STRIP_ROWS`] rows on all cores, each strip one restart interval (a restart resets the
/// DC predictions, so each strip is coded as if it were an image of its own), joined with RST
/// markers; not when the interval (MCUs per strip) would not fit its 16 bits.
fn encode(rgb: &[u8], w: u16, h: u16, opts: JpegOptions, strips: bool) -> IoResult<Vec<u8>> {
    use rayon::prelude::*;
    let (width, height) = (usize::from(w), usize::from(h));
    let quality = opts.quality.get();
    let quant = [
        tables::quant_table(quality, false),
        tables::quant_table(quality, true),
    ];
    let factors = opts.subsampling.factors();
    let plan = Plan::new(factors, [&quant[0], &quant[1]]);
    let interval = plan.mcus_across(width) * (STRIP_ROWS / plan.mcu_rows());
    let interval = u16::try_from(interval)
        .ok()
        .filter(|_| strips && height > STRIP_ROWS);
    let parts: Vec<Vec<u8>> = match interval {
        Some(_) => rgb
            .par_chunks(width * 3 * STRIP_ROWS)
            .map(|rows| plan.encode_rows(rows, width))
            .collect(),
        None => vec![plan.encode_rows(rgb, width)],
    };
    let icc = srgb_profile();
    if !icc_fits(icc) {
        return Err(IoError::Encode {
            format: "JPEG",
            msg: format!("an ICC profile of {} bytes does not fit APP2", icc.len()),
        });
    }
    let frame = Frame {
        width: w,
        height: h,
        luma_factors: factors,
        quant: [&quant[0], &quant[1]],
        icc: Some(icc),
        restart_interval: interval,
    };
    let mut out = crate::buffers::with_capacity(parts.iter().map(Vec::len).sum::<usize>() + 4096);
    write_headers(&mut out, &frame);
    for (i, part) in parts.iter().enumerate() {
        if i > 0 {
            out.extend_from_slice(&[0xff, 0xd0 + ((i - 1) % 8) as u8]);
        }
        out.extend_from_slice(part);
    }
    out.extend_from_slice(&[0xff, 0xd9]);
    Ok(out)
}

/// Encodes interleaved 8-bit sRGB (`width × height × 3` bytes) as an in-memory JPEG. Frames
/// taller than one strip are encoded in strips on all cores (`encode`); the strip
/// height is fixed, so the bytes never depend on the thread count.
pub fn encode_jpeg_rgb8(
    width: usize,
    height: usize,
    data: &[u8],
    opts: JpegOptions,
) -> IoResult<Vec<u8>> {
    if width == 0 || height == 0 {
        return Err(IoError::ZeroDimension { width, height });
    }
    let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
        return Err(IoError::DimensionTooLarge {
            width,
            height,
            max_dim: usize::from(u16::MAX),
        });
    };
    check_len("RGB data", data.len(), width, height, 3, "bytes")?;
    encode(data, w, h, opts, true)
}
