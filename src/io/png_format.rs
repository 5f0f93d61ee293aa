//! PNG: 16-bit grayscale mosaics and 8-bit RGB images, encoding and bounded decoding.

use std::io::{Cursor, Write};
use std::path::Path;

use super::atomic::write_atomic;
use super::error::{IoError, IoResult};
use super::limits::Limits;
use super::raw::{RawFrame, check_len};

/// PNG magic bytes.
pub(crate) const PNG_MAGIC: &[u8; 8] = b"\x89PNG\r\n\x1a\n";

/// Most a DEFLATE stream can expand (1032:1), with a margin: a PNG whose pixel payload exceeds
/// this many times its file size cannot be complete, and is rejected before allocating.
const MAX_INFLATE_RATIO: u128 = 1100;

/// Memory the PNG decoder may use besides the output buffer (row buffers, chunks).
const DECODER_INTERNAL_BYTES: usize = 32 << 20;

/// PNG compression effort.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PngCompression {
    /// Fastest useful compression: 8-bit RGB by the band encoder (`png_bands`:
    /// `Up` filter, per-band Huffman codes, on all cores), 16-bit gray by fdeflate; for
    /// interactive responses.
    Fast,
    /// Balanced speed and size.
    #[default]
    Default,
    /// Smallest files, slowest.
    Best,
}

impl PngCompression {
    /// The names [`FromStr`](std::str::FromStr) takes, in order of effort.
    pub const NAMES: [&'static str; 3] = ["fast", "default", "best"];

    /// `fast`, `default` or `best`.
    pub fn name(self) -> &'static str {
        match self {
            PngCompression::Fast => "fast",
            PngCompression::Default => "default",
            PngCompression::Best => "best",
        }
    }

    fn to_png(self) -> png::Compression {
        match self {
            PngCompression::Fast => png::Compression::Fast,
            PngCompression::Default => png::Compression::Balanced,
            PngCompression::Best => png::Compression::High,
        }
    }
}

impl std::fmt::Display for PngCompression {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A PNG compression name that is none of `fast`, `default` and `best`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("PNG compression '{0}': expected fast, default or best")]
pub struct UnknownPngCompression(pub String);

impl std::str::FromStr for PngCompression {
    type Err = UnknownPngCompression;

    fn from_str(s: &str) -> Result<Self, UnknownPngCompression> {
        match s.trim().to_ascii_lowercase().as_str() {
            "fast" => Ok(PngCompression::Fast),
            "default" => Ok(PngCompression::Default),
            "best" => Ok(PngCompression::Best),
            _ => Err(UnknownPngCompression(s.to_string())),
        }
    }
}

impl<'de> serde::Deserialize<'de> for PngCompression {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

fn encode_err(e: png::EncodingError) -> IoError {
    IoError::Encode {
        format: "PNG",
        msg: e.to_string(),
    }
}

/// Width and height as the u32 that PNG and TIFF headers need; zero sizes are refused.
pub(crate) fn header_dims(width: usize, height: usize) -> IoResult<(u32, u32)> {
    if width == 0 || height == 0 {
        return Err(IoError::ZeroDimension { width, height });
    }
    match (u32::try_from(width), u32::try_from(height)) {
        (Ok(w), Ok(h)) => Ok((w, h)),
        _ => Err(IoError::DimensionTooLarge {
            width,
            height,
            max_dim: u32::MAX as usize,
        }),
    }
}

/// Encodes interleaved 8-bit RGB (`width × height × 3` bytes) as PNG into `out`.
fn encode_rgb8_to<W: Write>(
    out: W,
    width: usize,
    height: usize,
    data: &[u8],
    compression: PngCompression,
) -> IoResult<()> {
    let (w, h) = header_dims(width, height)?;
    check_len("RGB data", data.len(), width, height, 3, "bytes")?;
    if compression == PngCompression::Fast {
        let mut out = out;
        return out
            .write_all(&super::png_bands::encode_rgb8(w, h, data))
            .map_err(|e| IoError::Encode {
                format: "PNG",
                msg: e.to_string(),
            });
    }
    let mut enc = png::Encoder::new(out, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(compression.to_png());
    let mut writer = enc.write_header().map_err(encode_err)?;
    writer.write_image_data(data).map_err(encode_err)?;
    writer.finish().map_err(encode_err)
}

/// Encodes a 16-bit grayscale mosaic as PNG into `out`, one row at a time.
fn encode_gray16_to<W: Write>(
    out: W,
    frame: &RawFrame,
    compression: PngCompression,
) -> IoResult<()> {
    let (w, h) = header_dims(frame.width, frame.height)?;
    check_len(
        "frame data",
        frame.data.len(),
        frame.width,
        frame.height,
        1,
        "values",
    )?;
    let mut enc = png::Encoder::new(out, w, h);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Sixteen);
    enc.set_compression(compression.to_png());
    let mut writer = enc.write_header().map_err(encode_err)?;
    {
        let mut stream = writer.stream_writer().map_err(encode_err)?;
        let mut row = Vec::with_capacity(frame.width * 2);
        for line in frame.data.chunks_exact(frame.width) {
            row.clear();
            row.extend(line.iter().flat_map(|v| v.to_be_bytes()));
            stream.write_all(&row).map_err(|e| IoError::Encode {
                format: "PNG",
                msg: e.to_string(),
            })?;
        }
        stream.finish().map_err(encode_err)?;
    }
    writer.finish().map_err(encode_err)
}

/// Encodes interleaved 8-bit RGB (`width × height × 3` bytes) as an in-memory PNG.
pub fn encode_png_rgb8(
    width: usize,
    height: usize,
    data: &[u8],
    compression: PngCompression,
) -> IoResult<Vec<u8>> {
    if compression == PngCompression::Fast {
        let (w, h) = header_dims(width, height)?;
        check_len("RGB data", data.len(), width, height, 3, "bytes")?;
        return Ok(super::png_bands::encode_rgb8(w, h, data));
    }
    let mut out = crate::buffers::with_capacity(data.len() / 2 + 1024);
    encode_rgb8_to(&mut out, width, height, data, compression)?;
    Ok(out)
}

/// Writes interleaved 8-bit RGB as a PNG file (atomically).
pub fn write_png_rgb8(
    path: &Path,
    width: usize,
    height: usize,
    data: &[u8],
    compression: PngCompression,
) -> IoResult<()> {
    write_atomic(path, |w| {
        encode_rgb8_to(w, width, height, data, compression)
    })
}

/// Encodes a mosaic as an in-memory 16-bit grayscale PNG.
pub fn encode_png_gray16(frame: &RawFrame, compression: PngCompression) -> IoResult<Vec<u8>> {
    let mut out = crate::buffers::with_capacity(frame.data.len() + 1024);
    encode_gray16_to(&mut out, frame, compression)?;
    Ok(out)
}

/// Writes a mosaic as a 16-bit grayscale PNG file (atomically, default compression).
pub fn write_png_gray16(path: &Path, frame: &RawFrame) -> IoResult<()> {
    write_atomic(path, |w| {
        encode_gray16_to(w, frame, PngCompression::Default)
    })
}

fn decode_err(e: png::DecodingError) -> IoError {
    match e {
        png::DecodingError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            IoError::Png("the data ends early (truncated file)".to_string())
        }
        other => IoError::Png(other.to_string()),
    }
}

/// "8-bit RGB", "16-bit grayscale", "4-bit palette (indexed colour)", ...
fn describe(color: png::ColorType, depth: png::BitDepth) -> String {
    let bits = depth as u8;
    let kind = match color {
        png::ColorType::Grayscale => "grayscale",
        png::ColorType::Rgb => "RGB",
        png::ColorType::Indexed => "palette (indexed colour)",
        png::ColorType::GrayscaleAlpha => "grayscale with alpha",
        png::ColorType::Rgba => "RGBA",
    };
    format!("{bits}-bit {kind}")
}

/// A PNG stream ready to decode one image of a checked size.
struct PngImage<'a> {
    reader: png::Reader<Cursor<&'a [u8]>>,
    width: usize,
    height: usize,
    color: png::ColorType,
    depth: png::BitDepth,
}

/// Reads the header, checks the size against `limits` and the file length, and accepts only
/// the colour types for which `accept` returns true (else the error names `expected`).
fn open_png<'a>(
    bytes: &'a [u8],
    limits: &Limits,
    accept: impl Fn(png::ColorType, png::BitDepth) -> bool,
    expected: &'static str,
) -> IoResult<PngImage<'a>> {
    let mut dec = png::Decoder::new_with_limits(
        Cursor::new(bytes),
        png::Limits {
            bytes: DECODER_INTERNAL_BYTES,
        },
    );
    dec.set_ignore_text_chunk(true);
    dec.set_ignore_iccp_chunk(true);
    dec.set_transformations(png::Transformations::IDENTITY);
    let (width, height, color, depth, row_bytes) = {
        let info = dec.read_header_info().map_err(decode_err)?;
        (
            info.width as usize,
            info.height as usize,
            info.color_type,
            info.bit_depth,
            // Filtered row length (1 filter byte + samples), computed without allocating.
            info.raw_row_length_from_width(info.width),
        )
    };
    limits.check(width, height)?;
    if !accept(color, depth) {
        return Err(IoError::PixelLayout {
            format: "PNG",
            found: describe(color, depth),
            expected,
        });
    }
    let payload = height as u128 * row_bytes as u128;
    if payload > MAX_INFLATE_RATIO * bytes.len() as u128 {
        return Err(IoError::Png(format!(
            "header declares {width}×{height} {} pixels ({payload} bytes) but the file has only {} bytes, \
             which cannot inflate to that much (truncated or corrupt)",
            describe(color, depth),
            bytes.len()
        )));
    }
    let reader = dec.read_info().map_err(decode_err)?;
    Ok(PngImage {
        reader,
        width,
        height,
        color,
        depth,
    })
}

impl PngImage<'_> {
    /// Decodes the (first) image into a freshly allocated buffer of the declared size, then
    /// checks the rest of the stream.
    fn read_pixels(mut self) -> IoResult<Vec<u8>> {
        let size = self
            .reader
            .output_buffer_size()
            .ok_or_else(|| IoError::Png("image size overflows memory".to_string()))?;
        let mut buf = vec![0u8; size];
        let out = self.reader.next_frame(&mut buf).map_err(decode_err)?;
        // Read through IEND so a truncated or corrupt tail is reported too.
        self.reader.finish().map_err(decode_err)?;
        if (out.width as usize, out.height as usize) != (self.width, self.height) {
            return Err(IoError::Png(format!(
                "first frame is {}×{} but the image is {}×{}",
                out.width, out.height, self.width, self.height
            )));
        }
        buf.truncate(out.buffer_size());
        Ok(buf)
    }
}

/// Decodes a grayscale PNG mosaic (8- or 16-bit). Returns the frame and its bit depth.
pub(crate) fn decode_png_mosaic(bytes: &[u8], limits: &Limits) -> IoResult<(RawFrame, u8)> {
    let img = open_png(
        bytes,
        limits,
        |c, d| {
            c == png::ColorType::Grayscale
                && matches!(d, png::BitDepth::Eight | png::BitDepth::Sixteen)
        },
        "a 16-bit (or 8-bit) grayscale mosaic",
    )?;
    let (width, height) = (img.width, img.height);
    let sixteen = img.depth == png::BitDepth::Sixteen;
    let buf = img.read_pixels()?;
    let data: Vec<u16> = if sixteen {
        check_len("decoded PNG", buf.len(), width, height, 2, "bytes")?;
        buf.chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect()
    } else {
        check_len("decoded PNG", buf.len(), width, height, 1, "bytes")?;
        buf.iter().map(|&v| u16::from(v)).collect()
    };
    Ok((
        RawFrame {
            width,
            height,
            data,
        },
        if sixteen { 16 } else { 8 },
    ))
}

/// Decodes an 8-bit RGB PNG: (width, height, interleaved RGB bytes).
pub fn decode_png_rgb8(bytes: &[u8], limits: &Limits) -> IoResult<(usize, usize, Vec<u8>)> {
    if !bytes.starts_with(PNG_MAGIC) {
        return Err(IoError::Png("missing PNG signature".to_string()));
    }
    let img = open_png(
        bytes,
        limits,
        |c, d| c == png::ColorType::Rgb && d == png::BitDepth::Eight,
        "an 8-bit RGB image",
    )?;
    let (width, height) = (img.width, img.height);
    debug_assert_eq!(img.color, png::ColorType::Rgb);
    let buf = img.read_pixels()?;
    check_len("decoded PNG", buf.len(), width, height, 3, "bytes")?;
    Ok((width, height, buf))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgb8_round_trip_every_compression() {
        let (w, h) = (7, 5);
        let data: Vec<u8> = (0..w * h * 3).map(|i| (i * 37 % 256) as u8).collect();
        for c in [
            PngCompression::Fast,
            PngCompression::Default,
            PngCompression::Best,
        ] {
            let png = encode_png_rgb8(w, h, &data, c).unwrap();
            let (w2, h2, back) = decode_png_rgb8(&png, &Limits::default()).unwrap();
            assert_eq!((w2, h2), (w, h));
            assert_eq!(back, data);
        }
    }

    #[test]
    fn gray16_round_trip() {
        let f = RawFrame::new(3, 2, vec![0, 1, 255, 256, 4095, 65535]).unwrap();
        let png = encode_png_gray16(&f, PngCompression::Fast).unwrap();
        let (back, bits) = decode_png_mosaic(&png, &Limits::default()).unwrap();
        assert_eq!(bits, 16);
        assert_eq!(back, f);
    }

    #[test]
    fn rgb_is_not_a_mosaic() {
        let png = encode_png_rgb8(2, 2, &[0; 12], PngCompression::Fast).unwrap();
        let e = decode_png_mosaic(&png, &Limits::default())
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "PNG is 8-bit RGB; a 16-bit (or 8-bit) grayscale mosaic is expected"
        );
    }

    #[test]
    fn encoders_check_sizes() {
        assert!(matches!(
            encode_png_rgb8(0, 3, &[], PngCompression::Fast),
            Err(IoError::ZeroDimension { .. })
        ));
        let e = encode_png_rgb8(2, 2, &[0; 11], PngCompression::Fast)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("RGB data has 11 bytes; width×height×3 (2×2×3) = 12 expected"),
            "{e}"
        );
    }
}
