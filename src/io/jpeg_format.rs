//! JPEG: 8-bit sRGB as baseline JPEG, with the sRGB ICC profile ([`super::icc`]) in APP2 and
//! a JFIF APP0, at a chosen quality and chroma subsampling.
//!
//! The encoder is the `jpeg-encoder` crate (pure Rust; AVX2 colour conversion and DCT,
//! chosen at run time). Three candidates were measured on rendered 2 MP (1600 × 1250) and
//! 12 MP (4000 × 3000) frames of the sine-and-noise test mosaic, quality 90, 4:2:0, one
//! thread, release builds; best of 7 runs on the two shared cores while other builds ran
//! (medians were up to 1.7× higher):
//!
//! | encoder | 2 MP | 12 MP | bytes, 2 MP | builds from |
//! |---|---|---|---|---|
//! | `jpeg-encoder` 0.7.1, `simd` | 25.0 ms | 105 ms | 178 kB | Rust |
//! | `image` 0.25 `JpegEncoder` | 77.6 ms | 520 ms | 250 kB | Rust |
//! | `mozjpeg` 0.10 (fastest settings; no NASM here, so no SIMD) | 33.8 ms | 225 ms | 79 kB | C, by `cc` |
//!
//! `jpeg-encoder` is the fastest, is pure Rust (no C toolchain or assembler for CI), and is
//! maintained. mozjpeg's files are less than half the size at the same nominal quality
//! (its tables and trellis quantisation), but it is slower even before counting its
//! C build; with NASM its SIMD would make it faster, at the cost of a system dependency.
//! Lossy WebP (libwebp 1.x through the `webp` crate, method 4) took 164 ms (q75, 27 kB) and
//! 251 ms (q90) on the 2 MP frame, 1.3–1.7 s on 12 MP: far too slow to answer in line, so
//! there is no WebP output; AVIF encoders (rav1e) are slower still.
//!
//! A frame is encoded in strips of [`STRIP_ROWS`] rows on all cores and joined with restart
//! markers ([`encode_strips`]); the strip height is fixed, so the bytes never depend on the
//! thread count and the CLI and service write the same file. Chroma is subsampled by averaging
//! each block (libjpeg's way), not by taking its first pixel (the crate's default): that took
//! 8 % of the encoder's time in a profile against 12 %, but where a render keeps a trace of
//! the CFA's 2 × 2 period it picks the same phase in every block, and a small simulated
//! chart came out 2.3 codes darker on average than its PNG.

use std::str::FromStr;

use jpeg_encoder::{ChromaSubsamplingMethod, ColorType, Encoder, SamplingFactor};

use super::error::{IoError, IoResult};
use super::icc::srgb_profile;
use super::raw::check_len;

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

    fn factor(self) -> SamplingFactor {
        match self {
            Subsampling::S420 => SamplingFactor::F_2_2,
            Subsampling::S422 => SamplingFactor::F_2_1,
            Subsampling::S444 => SamplingFactor::F_1_1,
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

fn encode_err(e: jpeg_encoder::EncodingError) -> IoError {
    IoError::Encode {
        format: "JPEG",
        msg: e.to_string(),
    }
}

/// Rows per strip encoded on its own thread (a multiple of every MCU height): ten strips
/// for a 2 MP frame, so that two cores share them evenly.
const STRIP_ROWS: usize = 128;

/// One JPEG of `rows` (whole, with its headers), the profile only when `icc`.
fn encode_part(rows: &[u8], w: u16, h: u16, opts: JpegOptions, icc: bool) -> IoResult<Vec<u8>> {
    let mut out = crate::buffers::with_capacity(rows.len() / 8 + 4096);
    let mut enc = Encoder::new(&mut out, opts.quality.get());
    enc.set_sampling_factor(opts.subsampling.factor());
    enc.set_chroma_subsampling_method(ChromaSubsamplingMethod::Average);
    if icc {
        enc.add_icc_profile(srgb_profile()).map_err(encode_err)?;
    }
    enc.encode(rows, w, h, ColorType::Rgb).map_err(encode_err)?;
    Ok(out)
}

/// Where a marker segment `0xff kind` starts, searching the headers (before the scan).
fn find_marker(jpeg: &[u8], kind: u8) -> Option<usize> {
    let mut at = 2;
    while at + 4 <= jpeg.len() && jpeg[at] == 0xff {
        if jpeg[at + 1] == kind {
            return Some(at);
        }
        at += 2 + usize::from(u16::from_be_bytes([jpeg[at + 2], jpeg[at + 3]]));
    }
    None
}

/// The entropy-coded data of a whole JPEG: after the SOS segment, before EOI.
fn scan_data(jpeg: &[u8]) -> Option<(usize, &[u8])> {
    let sos = find_marker(jpeg, 0xda)?;
    let start = sos + 2 + usize::from(u16::from_be_bytes([jpeg[sos + 2], jpeg[sos + 3]]));
    (jpeg.len() >= start + 2).then(|| (sos, &jpeg[start..jpeg.len() - 2]))
}

/// Strips of [`STRIP_ROWS`] rows encoded in parallel as separate JPEGs with the same tables,
/// joined into one: the first strip's headers (its height made the whole one's, a restart
/// interval of one strip's MCUs added), then each strip's scan, RST markers between. A
/// restart resets what one MCU's coding carries to the next (the DC predictions), which is
/// what starting a new image does, so the joined scan decodes as one image. `None` when the
/// interval would not fit its 16 bits.
fn encode_strips(data: &[u8], w: u16, h: u16, opts: JpegOptions) -> Option<IoResult<Vec<u8>>> {
    use rayon::prelude::*;
    let (mcu_w, mcu_h) = match opts.subsampling {
        Subsampling::S420 => (16, 16),
        Subsampling::S422 => (16, 8),
        Subsampling::S444 => (8, 8),
    };
    let interval = usize::from(w).div_ceil(mcu_w) * (STRIP_ROWS / mcu_h);
    let interval = u16::try_from(interval).ok()?;
    let row = usize::from(w) * 3;
    let parts: Vec<IoResult<Vec<u8>>> = data
        .par_chunks(row * STRIP_ROWS)
        .enumerate()
        .map(|(i, rows)| encode_part(rows, w, (rows.len() / row) as u16, opts, i == 0))
        .collect();
    Some(join_strips(parts, h, interval))
}

fn join_strips(parts: Vec<IoResult<Vec<u8>>>, h: u16, interval: u16) -> IoResult<Vec<u8>> {
    let parts: Vec<Vec<u8>> = parts.into_iter().collect::<IoResult<_>>()?;
    let malformed = || IoError::Encode {
        format: "JPEG",
        msg: "the encoder wrote no frame or scan header".into(),
    };
    let first = &parts[0];
    let (sos, _) = scan_data(first).ok_or_else(malformed)?;
    let sof = find_marker(first, 0xc0).ok_or_else(malformed)?;
    let mut out = crate::buffers::with_capacity(parts.iter().map(Vec::len).sum::<usize>() + 64);
    out.extend_from_slice(&first[..sos]);
    out[sof + 5..sof + 7].copy_from_slice(&h.to_be_bytes());
    out.extend_from_slice(&[0xff, 0xdd, 0, 4]);
    out.extend_from_slice(&interval.to_be_bytes());
    let sos_len = usize::from(u16::from_be_bytes([first[sos + 2], first[sos + 3]]));
    out.extend_from_slice(&first[sos..sos + 2 + sos_len]);
    for (i, part) in parts.iter().enumerate() {
        if i > 0 {
            out.extend_from_slice(&[0xff, 0xd0 + ((i - 1) % 8) as u8]);
        }
        out.extend_from_slice(scan_data(part).ok_or_else(malformed)?.1);
    }
    out.extend_from_slice(&[0xff, 0xd9]);
    Ok(out)
}

/// Encodes interleaved 8-bit sRGB (`width × height × 3` bytes) as an in-memory JPEG. Frames
/// taller than one strip are encoded in strips on all cores ([`encode_strips`]); the strip
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
    if height > STRIP_ROWS
        && let Some(joined) = encode_strips(data, w, h, opts)
    {
        return joined;
    }
    encode_part(data, w, h, opts, true)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth colour gradient with some texture.
    fn frame(w: usize, h: usize) -> Vec<u8> {
        (0..w * h)
            .flat_map(|i| {
                let (x, y) = (i % w, i / w);
                [
                    (x * 255 / w) as u8,
                    (y * 255 / h) as u8,
                    (((x / 4 + y / 4) % 2) * 40 + 100) as u8,
                ]
            })
            .collect()
    }

    fn decode(bytes: &[u8]) -> (Vec<u8>, usize, usize, Option<Vec<u8>>) {
        let mut d =
            zune_jpeg::JpegDecoder::new(zune_jpeg::zune_core::bytestream::ZCursor::new(bytes));
        let px = d.decode().expect("decodes");
        let info = d.info().unwrap();
        (
            px,
            usize::from(info.width),
            usize::from(info.height),
            d.icc_profile(),
        )
    }

    /// The sampling factors of the frame header (SOF0): per component, horizontal × vertical.
    fn sampling(bytes: &[u8]) -> Vec<u8> {
        let sof = bytes.windows(2).position(|w| w == [0xff, 0xc0]).unwrap();
        let n = usize::from(bytes[sof + 9]);
        (0..n).map(|c| bytes[sof + 10 + 3 * c + 1]).collect()
    }

    #[test]
    fn round_trip_with_the_srgb_profile() {
        let (w, h) = (97, 61);
        let rgb = frame(w, h);
        let bytes = encode_jpeg_rgb8(w, h, &rgb, JpegOptions::default()).unwrap();
        assert_eq!(&bytes[..2], &[0xff, 0xd8]);
        let (px, dw, dh, icc) = decode(&bytes);
        assert_eq!((dw, dh), (w, h));
        assert_eq!(icc.as_deref(), Some(srgb_profile()));
        let mean_err: f64 = px
            .iter()
            .zip(&rgb)
            .map(|(a, b)| (f64::from(*a) - f64::from(*b)).abs())
            .sum::<f64>()
            / rgb.len() as f64;
        assert!(mean_err < 4.0, "mean error {mean_err}");
        // the APP2 marker carries the profile
        assert!(bytes.windows(12).any(|w| w == b"ICC_PROFILE\0"));
    }

    #[test]
    fn quality_and_subsampling_are_honoured() {
        let (w, h) = (128, 96);
        let rgb = frame(w, h);
        let enc = |q: u32, s: Subsampling| {
            encode_jpeg_rgb8(
                w,
                h,
                &rgb,
                JpegOptions {
                    quality: JpegQuality::new(q).unwrap(),
                    subsampling: s,
                },
            )
            .unwrap()
        };
        assert!(enc(50, Subsampling::S420).len() < enc(95, Subsampling::S420).len());
        assert_eq!(sampling(&enc(90, Subsampling::S420)), [0x22, 0x11, 0x11]);
        assert_eq!(sampling(&enc(90, Subsampling::S422)), [0x21, 0x11, 0x11]);
        assert_eq!(sampling(&enc(90, Subsampling::S444)), [0x11, 0x11, 0x11]);
        // the same input and options: the same bytes
        assert_eq!(enc(77, Subsampling::S444), enc(77, Subsampling::S444));
    }

    #[test]
    fn options_parse_or_say_why_not() {
        assert_eq!("90".parse::<JpegQuality>().unwrap().get(), 90);
        assert_eq!(" 1".parse::<JpegQuality>().unwrap().get(), 1);
        for bad in ["0", "101", "-3", "ninety", "9.5", ""] {
            let e = bad.parse::<JpegQuality>().unwrap_err();
            assert_eq!(
                e.to_string(),
                format!("JPEG quality '{bad}': expected an integer from 1 to 100")
            );
        }
        assert_eq!("4:2:2".parse::<Subsampling>().unwrap(), Subsampling::S422);
        assert_eq!("444".parse::<Subsampling>().unwrap(), Subsampling::S444);
        assert!("411".parse::<Subsampling>().is_err());
        assert_eq!(JpegOptions::default().quality.get(), DEFAULT_JPEG_QUALITY);
        assert_eq!(JpegOptions::default().subsampling, Subsampling::S420);
    }

    /// A frame of several strips (the last one partial) decodes as one image, the same
    /// pixels as the one-strip encoding gives within the codec's error, with one profile.
    #[test]
    fn strips_join_into_one_image() {
        for s in [Subsampling::S420, Subsampling::S422, Subsampling::S444] {
            let (w, h) = (200, STRIP_ROWS * 2 + 37);
            let rgb = frame(w, h);
            let opts = JpegOptions {
                subsampling: s,
                ..JpegOptions::default()
            };
            let joined = encode_jpeg_rgb8(w, h, &rgb, opts).unwrap();
            let whole = encode_part(&rgb, w as u16, h as u16, opts, true).unwrap();
            assert_ne!(joined, whole, "{s}: not split");
            let (a, dw, dh, icc) = decode(&joined);
            let (b, ..) = decode(&whole);
            assert_eq!((dw, dh), (w, h));
            assert_eq!(icc.as_deref(), Some(srgb_profile()));
            let max = a.iter().zip(&b).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
            assert!(max <= 2, "{s}: strips differ from the whole by {max}");
            assert_eq!(
                joined
                    .windows(12)
                    .filter(|w| *w == b"ICC_PROFILE\0")
                    .count(),
                1
            );
        }
    }

    #[test]
    fn sizes_it_cannot_write_are_errors() {
        let e = encode_jpeg_rgb8(70_000, 1, &[0; 210_000], JpegOptions::default()).unwrap_err();
        assert!(matches!(e, IoError::DimensionTooLarge { .. }), "{e}");
        assert!(encode_jpeg_rgb8(0, 4, &[], JpegOptions::default()).is_err());
        assert!(encode_jpeg_rgb8(2, 2, &[0; 5], JpegOptions::default()).is_err());
    }
}
