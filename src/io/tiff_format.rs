//! TIFF: 32-bit float and 16-bit RGB images, grayscale mosaics (8/16-bit, 32-bit float),
//! encoding and bounded decoding (via the `tiff` crate).

use std::io::{Cursor, Seek, Write};
use std::path::Path;

use tiff::decoder::{Decoder, DecodingResult};
use tiff::encoder::{TiffEncoder, colortype};
use tiff::tags::Tag;

use super::atomic::{read_capped, write_atomic};
use super::error::{IoError, IoResult};
use super::limits::Limits;
use super::png_format::header_dims;
use super::raw::{RawFrame, check_len};

/// Memory the TIFF decoder may use for IFD values (tag arrays such as strip offsets).
const IFD_VALUE_BYTES: usize = 4 << 20;

fn encode_err(e: tiff::TiffError) -> IoError {
    IoError::Encode {
        format: "TIFF",
        msg: e.to_string(),
    }
}

fn decode_err(e: tiff::TiffError) -> IoError {
    match e {
        tiff::TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            IoError::Tiff("the data ends early (truncated file)".to_string())
        }
        tiff::TiffError::LimitsExceeded => IoError::Tiff(
            "a strip, tile or tag is larger than the file or the pixel limit allows".to_string(),
        ),
        other => IoError::Tiff(other.to_string()),
    }
}

/// Refuses NaN and ±∞ with the position of the first one.
pub(crate) fn check_finite(
    what: &'static str,
    data: &[f32],
    width: usize,
    channels: usize,
) -> IoResult<()> {
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        let px = i / channels;
        return Err(IoError::NonFinite {
            what,
            x: px % width,
            y: px / width,
            channel: if channels > 1 {
                format!(" channel {}", i % channels)
            } else {
                String::new()
            },
            value: data[i],
        });
    }
    Ok(())
}

fn encode_f32_rgb_to<W: Write + Seek>(
    out: W,
    width: usize,
    height: usize,
    data: &[f32],
) -> IoResult<()> {
    let (w, h) = header_dims(width, height)?;
    check_len("RGB data", data.len(), width, height, 3, "values")?;
    check_finite("float RGB data", data, width, 3)?;
    let mut enc = TiffEncoder::new(out).map_err(encode_err)?;
    enc.write_image::<colortype::RGB32Float>(w, h, data)
        .map_err(encode_err)
}

fn encode_rgb16_to<W: Write + Seek>(
    out: W,
    width: usize,
    height: usize,
    data: &[u16],
) -> IoResult<()> {
    let (w, h) = header_dims(width, height)?;
    check_len("RGB data", data.len(), width, height, 3, "values")?;
    let mut enc = TiffEncoder::new(out).map_err(encode_err)?;
    enc.write_image::<colortype::RGB16>(w, h, data)
        .map_err(encode_err)
}

fn encode_gray16_to<W: Write + Seek>(out: W, frame: &RawFrame) -> IoResult<()> {
    let (w, h) = header_dims(frame.width, frame.height)?;
    check_len(
        "frame data",
        frame.data.len(),
        frame.width,
        frame.height,
        1,
        "values",
    )?;
    let mut enc = TiffEncoder::new(out).map_err(encode_err)?;
    enc.write_image::<colortype::Gray16>(w, h, &frame.data)
        .map_err(encode_err)
}

fn encode_gray_f32_to<W: Write + Seek>(
    out: W,
    width: usize,
    height: usize,
    data: &[f32],
) -> IoResult<()> {
    let (w, h) = header_dims(width, height)?;
    check_len("float data", data.len(), width, height, 1, "values")?;
    check_finite("float data", data, width, 1)?;
    let mut enc = TiffEncoder::new(out).map_err(encode_err)?;
    enc.write_image::<colortype::Gray32Float>(w, h, data)
        .map_err(encode_err)
}

/// Runs an encoder into a fresh in-memory buffer.
fn to_vec(
    capacity: usize,
    f: impl FnOnce(&mut Cursor<Vec<u8>>) -> IoResult<()>,
) -> IoResult<Vec<u8>> {
    let mut cur = Cursor::new(crate::buffers::with_capacity(capacity));
    f(&mut cur)?;
    Ok(cur.into_inner())
}

/// Encodes interleaved float RGB/XYZ (`width × height × 3`, finite) as an in-memory TIFF,
/// 32-bit IEEE float, 3 samples per pixel, uncompressed.
pub fn encode_tiff_f32_rgb(width: usize, height: usize, data: &[f32]) -> IoResult<Vec<u8>> {
    to_vec(data.len() * 4 + 4096, |c| {
        encode_f32_rgb_to(c, width, height, data)
    })
}

/// Writes interleaved float RGB/XYZ as a 32-bit float TIFF file (atomically).
pub fn write_tiff_f32_rgb(path: &Path, width: usize, height: usize, data: &[f32]) -> IoResult<()> {
    write_atomic(path, |w| encode_f32_rgb_to(w, width, height, data))
}

/// Encodes interleaved 16-bit RGB (`width × height × 3`) as an in-memory TIFF.
pub fn encode_tiff_rgb16(width: usize, height: usize, data: &[u16]) -> IoResult<Vec<u8>> {
    to_vec(data.len() * 2 + 4096, |c| {
        encode_rgb16_to(c, width, height, data)
    })
}

/// Writes interleaved 16-bit RGB as a TIFF file (atomically).
pub fn write_tiff_rgb16(path: &Path, width: usize, height: usize, data: &[u16]) -> IoResult<()> {
    write_atomic(path, |w| encode_rgb16_to(w, width, height, data))
}

/// Encodes a mosaic as an in-memory 16-bit grayscale TIFF.
pub fn encode_tiff_gray16(frame: &RawFrame) -> IoResult<Vec<u8>> {
    to_vec(frame.data.len() * 2 + 4096, |c| encode_gray16_to(c, frame))
}

/// Writes a mosaic as a 16-bit grayscale TIFF file (atomically).
pub fn write_tiff_gray16(path: &Path, frame: &RawFrame) -> IoResult<()> {
    write_atomic(path, |w| encode_gray16_to(w, frame))
}

/// Encodes a float mosaic (e.g. volts; `width × height`, finite) as an in-memory 32-bit float
/// grayscale TIFF.
pub fn encode_tiff_gray_f32(width: usize, height: usize, data: &[f32]) -> IoResult<Vec<u8>> {
    to_vec(data.len() * 4 + 4096, |c| {
        encode_gray_f32_to(c, width, height, data)
    })
}

/// Writes a float mosaic as a 32-bit float grayscale TIFF file (atomically).
pub fn write_tiff_gray_f32(path: &Path, width: usize, height: usize, data: &[f32]) -> IoResult<()> {
    write_atomic(path, |w| encode_gray_f32_to(w, width, height, data))
}

/// Decoded TIFF samples of a supported layout.
pub(crate) enum TiffPixels {
    U8(Vec<u8>),
    U16(Vec<u16>),
    F32(Vec<f32>),
}

/// "16-bit RGB", "32-bit float grayscale", "8-bit palette", ...
fn describe(color: tiff::ColorType, format: u16) -> String {
    use tiff::ColorType as C;
    let (bits, kind) = match color {
        C::Gray(b) => (b, "grayscale".to_string()),
        C::RGB(b) => (b, "RGB".to_string()),
        C::Palette(b) => (b, "palette (indexed colour)".to_string()),
        C::GrayA(b) => (b, "grayscale with alpha".to_string()),
        C::RGBA(b) => (b, "RGBA".to_string()),
        C::CMYK(b) => (b, "CMYK".to_string()),
        C::CMYKA(b) => (b, "CMYK with alpha".to_string()),
        C::YCbCr(b) => (b, "YCbCr".to_string()),
        C::Lab(b) => (b, "CIE L*a*b*".to_string()),
        C::Multiband {
            bit_depth,
            num_samples,
        } => (bit_depth, format!("{num_samples}-channel")),
        _ => (color.bit_depth(), "an unknown colour type".to_string()),
    };
    let fmt = match format {
        1 if bits > 16 => " unsigned integer",
        1 => "",
        2 => " signed integer",
        3 => " float",
        _ => " unknown-format",
    };
    format!("{bits}-bit{fmt} {kind}")
}

/// Opens a TIFF, checks its first image against `limits`, and decodes it if `accept` takes its
/// (colour type, sample format); otherwise the error names `expected`. `samples` is the number
/// of samples per pixel of accepted layouts.
fn decode_tiff(
    bytes: &[u8],
    limits: &Limits,
    accept: impl Fn(tiff::ColorType, u16) -> bool,
    samples: usize,
    expected: &'static str,
) -> IoResult<(usize, usize, TiffPixels)> {
    let mut small = tiff::decoder::Limits::default();
    small.ifd_value_size = IFD_VALUE_BYTES;
    small.decoding_buffer_size = IFD_VALUE_BYTES;
    small.intermediate_buffer_size = bytes.len();
    let mut dec = Decoder::new(Cursor::new(bytes)).map_err(decode_err)?;
    dec = dec.with_limits(small);
    let (w, h) = dec.dimensions().map_err(decode_err)?;
    let (width, height) = (w as usize, h as usize);
    let pixels = limits.check(width, height)?;
    let color = dec.colortype().map_err(decode_err)?;
    let format: u16 = dec
        .find_tag_unsigned_vec::<u16>(Tag::SampleFormat)
        .map_err(decode_err)?
        .and_then(|v| v.first().copied())
        .unwrap_or(1);
    if !accept(color, format) {
        return Err(IoError::PixelLayout {
            format: "TIFF",
            found: describe(color, format),
            expected,
        });
    }
    if samples > 1 {
        let planar: u16 = dec
            .find_tag_unsigned(Tag::PlanarConfiguration)
            .map_err(decode_err)?
            .unwrap_or(1);
        if planar != 1 {
            return Err(IoError::PixelLayout {
                format: "TIFF",
                found: "stored in separate colour planes".to_string(),
                expected: "interleaved (chunky) samples",
            });
        }
    }
    let bytes_per_sample = usize::from(color.bit_depth()).div_ceil(8);
    let mut lim = tiff::decoder::Limits::default();
    lim.ifd_value_size = IFD_VALUE_BYTES;
    // This limit also bounds tag arrays (strip offsets), so it is never below the IFD limit.
    lim.decoding_buffer_size = pixels
        .saturating_mul(samples)
        .saturating_mul(bytes_per_sample)
        .max(IFD_VALUE_BYTES);
    lim.intermediate_buffer_size = bytes.len();
    dec = dec.with_limits(lim);
    let shape = Shape {
        width,
        height,
        samples,
    };
    let pixels = match (color.bit_depth(), format) {
        (8, 1) => TiffPixels::U8(read_chunks(&mut dec, shape, 1, bytes.len())?),
        (16, 1) => TiffPixels::U16(read_chunks(&mut dec, shape, 2, bytes.len())?),
        (32, 3) => TiffPixels::F32(read_chunks(&mut dec, shape, 4, bytes.len())?),
        _ => {
            return Err(IoError::PixelLayout {
                format: "TIFF",
                found: describe(color, format),
                expected,
            });
        }
    };
    let len = match &pixels {
        TiffPixels::U8(v) => v.len(),
        TiffPixels::U16(v) => v.len(),
        TiffPixels::F32(v) => v.len(),
    };
    check_len("decoded TIFF", len, width, height, samples, "samples")?;
    Ok((width, height, pixels))
}

/// Image size in pixels and samples per pixel.
#[derive(Clone, Copy)]
struct Shape {
    width: usize,
    height: usize,
    samples: usize,
}

/// A sample type the decoder can return.
trait Sample: Copy + Default {
    fn take(r: DecodingResult) -> Option<Vec<Self>>;
}

impl Sample for u8 {
    fn take(r: DecodingResult) -> Option<Vec<Self>> {
        match r {
            DecodingResult::U8(v) => Some(v),
            _ => None,
        }
    }
}

impl Sample for u16 {
    fn take(r: DecodingResult) -> Option<Vec<Self>> {
        match r {
            DecodingResult::U16(v) => Some(v),
            _ => None,
        }
    }
}

impl Sample for f32 {
    fn take(r: DecodingResult) -> Option<Vec<Self>> {
        match r {
            DecodingResult::F32(v) => Some(v),
            _ => None,
        }
    }
}

/// A positive u32 tag, or `default` when absent.
fn tag_u32(dec: &mut Decoder<Cursor<&[u8]>>, tag: Tag, default: u32) -> IoResult<usize> {
    let v: u32 = dec
        .find_tag_unsigned(tag)
        .map_err(decode_err)?
        .unwrap_or(default);
    if v == 0 {
        return Err(IoError::Tiff(format!("tag {tag:?} is 0")));
    }
    Ok(v as usize)
}

/// Decodes one chunk (strip or tile) and checks it holds `cols × rows` pixels.
fn read_chunk<T: Sample>(
    dec: &mut Decoder<Cursor<&[u8]>>,
    index: usize,
    cols: usize,
    rows: usize,
    samples: usize,
) -> IoResult<Vec<T>> {
    let i = u32::try_from(index)
        .map_err(|_| IoError::Tiff(format!("chunk index {index} is out of range")))?;
    let r = dec.read_chunk(i).map_err(decode_err)?;
    let v = T::take(r).ok_or_else(|| {
        IoError::Tiff(format!("chunk {index} decodes to a different sample type"))
    })?;
    if v.len() != cols * rows * samples {
        return Err(IoError::Tiff(format!(
            "chunk {index} holds {} samples; {cols}×{rows}×{samples} expected",
            v.len()
        )));
    }
    Ok(v)
}

/// Makes room for `extra` more values, at most doubling and never beyond `total`.
fn grow<T>(out: &mut Vec<T>, extra: usize, total: usize) {
    let need = out.len() + extra;
    if need > out.capacity() {
        let target = (out.len() * 2).max(need).min(total.max(need));
        out.reserve_exact(target - out.len());
    }
}

/// Where the chunks (strips or tiles) are and what they must hold, from the IFD.
struct ChunkTable {
    offsets: Vec<u64>,
    counts: Vec<u64>,
    /// Most a chunk's bytes can expand under its compression (1 when uncompressed); `None`
    /// for methods without a useful bound (JPEG, ZSTD, ...).
    max_ratio: Option<u128>,
    compression: u16,
    bytes_per_sample: usize,
    file_len: u64,
}

impl ChunkTable {
    fn read(
        dec: &mut Decoder<Cursor<&[u8]>>,
        tiled: bool,
        bytes_per_sample: usize,
        file_len: usize,
    ) -> IoResult<Self> {
        let (off_tag, cnt_tag) = if tiled {
            (Tag::TileOffsets, Tag::TileByteCounts)
        } else {
            (Tag::StripOffsets, Tag::StripByteCounts)
        };
        let mut vec_tag = |tag: Tag| -> IoResult<Vec<u64>> {
            dec.find_tag_unsigned_vec::<u64>(tag)
                .map_err(decode_err)?
                .ok_or_else(|| IoError::Tiff(format!("the required tag {tag:?} is missing")))
        };
        let offsets = vec_tag(off_tag)?;
        let counts = vec_tag(cnt_tag)?;
        let compression: u16 = dec
            .find_tag_unsigned(Tag::Compression)
            .map_err(decode_err)?
            .unwrap_or(1);
        let max_ratio = match compression {
            1 => Some(1),
            32773 => Some(64),       // PackBits: 2 bytes → at most 128
            8 | 32946 => Some(1100), // Deflate: at most 1032:1
            5 => Some(4096),         // LZW: a ≥ 9-bit code → at most ~3840 bytes
            _ => None,
        };
        Ok(ChunkTable {
            offsets,
            counts,
            max_ratio,
            compression,
            bytes_per_sample,
            file_len: file_len as u64,
        })
    }

    /// Checks that chunk `index` lies inside the file and can hold the `stored_samples` it
    /// must: exactly when uncompressed, within the compression's maximum ratio otherwise. This
    /// refuses a tiny chunk that declares a huge strip before its buffer is allocated.
    fn check(&self, index: usize, stored_samples: usize) -> IoResult<()> {
        let (Some(&off), Some(&cnt)) = (self.offsets.get(index), self.counts.get(index)) else {
            return Err(IoError::Tiff(format!(
                "chunk {index} is missing: the file lists {} offsets and {} byte counts",
                self.offsets.len(),
                self.counts.len()
            )));
        };
        if off.checked_add(cnt).is_none_or(|end| end > self.file_len) {
            return Err(IoError::Tiff(format!(
                "chunk {index} (offset {off}, {cnt} bytes) runs past the end of the {}-byte file \
                 (truncated file?)",
                self.file_len
            )));
        }
        let need = stored_samples as u128 * self.bytes_per_sample as u128;
        match self.max_ratio {
            Some(1) if u128::from(cnt) < need => Err(IoError::Tiff(format!(
                "uncompressed chunk {index} has {cnt} bytes; {need} expected"
            ))),
            Some(r) if u128::from(cnt) * r < need => Err(IoError::Tiff(format!(
                "chunk {index} has {cnt} bytes, which {} cannot expand to the {need} bytes it \
                 must hold (corrupt or truncated file)",
                match self.compression {
                    5 => "LZW",
                    8 | 32946 => "Deflate",
                    _ => "PackBits",
                }
            ))),
            _ => Ok(()),
        }?;
        Ok(())
    }
}

/// Decodes the image strip by strip (or tile row by tile row), growing the output only as
/// chunks decode: a small file that declares a large image fails before the whole pixel
/// buffer is allocated. Every chunk must lie inside the file, and uncompressed chunks must
/// hold all their samples.
fn read_chunks<T: Sample>(
    dec: &mut Decoder<Cursor<&[u8]>>,
    shape: Shape,
    bytes_per_sample: usize,
    file_len: usize,
) -> IoResult<Vec<T>> {
    let Shape {
        width,
        height,
        samples,
    } = shape;
    let row_len = width * samples;
    let total = row_len * height;
    let mut out: Vec<T> = Vec::new();
    match dec.get_chunk_type() {
        tiff::decoder::ChunkType::Strip => {
            let table = ChunkTable::read(dec, false, bytes_per_sample, file_len)?;
            let rps = tag_u32(dec, Tag::RowsPerStrip, u32::MAX)?.min(height);
            for (index, y0) in (0..height).step_by(rps).enumerate() {
                let rows = rps.min(height - y0);
                table.check(index, rows * row_len)?;
                let v = read_chunk::<T>(dec, index, width, rows, samples)?;
                grow(&mut out, v.len(), total);
                out.extend_from_slice(&v);
            }
        }
        tiff::decoder::ChunkType::Tile => {
            let table = ChunkTable::read(dec, true, bytes_per_sample, file_len)?;
            let tw = tag_u32(dec, Tag::TileWidth, 0)?;
            let th = tag_u32(dec, Tag::TileLength, 0)?;
            let across = width.div_ceil(tw);
            for (ty, y0) in (0..height).step_by(th).enumerate() {
                let rows = th.min(height - y0);
                let start = out.len();
                grow(&mut out, rows * row_len, total);
                out.resize(start + rows * row_len, T::default());
                let block = &mut out[start..];
                for (tx, x0) in (0..width).step_by(tw).enumerate() {
                    let cols = tw.min(width - x0);
                    let index = ty * across + tx;
                    table.check(index, tw.saturating_mul(th).saturating_mul(samples))?;
                    let v = read_chunk::<T>(dec, index, cols, rows, samples)?;
                    for (r, src) in v.chunks_exact(cols * samples).enumerate() {
                        let at = r * row_len + x0 * samples;
                        block[at..at + src.len()].copy_from_slice(src);
                    }
                }
            }
        }
    }
    Ok(out)
}

/// Decodes a single-channel TIFF mosaic: 8- or 16-bit unsigned, or 32-bit float (finite).
pub(crate) fn decode_tiff_mosaic(
    bytes: &[u8],
    limits: &Limits,
) -> IoResult<(usize, usize, TiffPixels)> {
    let (w, h, px) = decode_tiff(
        bytes,
        limits,
        |c, f| {
            matches!(
                (c, f),
                (tiff::ColorType::Gray(8 | 16), 1) | (tiff::ColorType::Gray(32), 3)
            )
        },
        1,
        "a single-channel 16-bit (or 8-bit) unsigned or 32-bit float grayscale mosaic",
    )
    .map_err(|e| {
        if super::dng::is_cfa_tiff_without_dng_version(bytes) {
            IoError::Tiff(
                "a CFA image (CFAPattern or PhotometricInterpretation 32803) without DNGVersion (50706): \
                 raw CFA files are read as DNG, so the file needs the DNG tags (docs/dng.md)"
                    .to_string(),
            )
        } else {
            e
        }
    })?;
    if let TiffPixels::F32(v) = &px {
        check_finite("float TIFF", v, w, 1)?;
    }
    Ok((w, h, px))
}

/// Decodes a 32-bit float, 3-sample TIFF: (width, height, interleaved values). Non-finite
/// samples are an error.
pub fn decode_tiff_f32_rgb(bytes: &[u8], limits: &Limits) -> IoResult<(usize, usize, Vec<f32>)> {
    let (w, h, px) = decode_tiff(
        bytes,
        limits,
        |c, f| c == tiff::ColorType::RGB(32) && f == 3,
        3,
        "a 32-bit float RGB image",
    )?;
    match px {
        TiffPixels::F32(v) => {
            check_finite("float TIFF", &v, w, 3)?;
            Ok((w, h, v))
        }
        _ => Err(IoError::Tiff(
            "32-bit float samples were expected".to_string(),
        )),
    }
}

/// Reads a 32-bit float, 3-sample TIFF file (see [`decode_tiff_f32_rgb`]).
pub fn read_tiff_f32_rgb(path: &Path, limits: &Limits) -> IoResult<(usize, usize, Vec<f32>)> {
    let bytes = read_capped(path, limits.max_file_bytes(12))?;
    decode_tiff_f32_rgb(&bytes, limits)
}

/// Decodes a 16-bit unsigned, 3-sample TIFF: (width, height, interleaved values).
pub fn decode_tiff_rgb16(bytes: &[u8], limits: &Limits) -> IoResult<(usize, usize, Vec<u16>)> {
    let (w, h, px) = decode_tiff(
        bytes,
        limits,
        |c, f| c == tiff::ColorType::RGB(16) && f == 1,
        3,
        "a 16-bit RGB image",
    )?;
    match px {
        TiffPixels::U16(v) => Ok((w, h, v)),
        _ => Err(IoError::Tiff("16-bit samples were expected".to_string())),
    }
}

/// Reads a 16-bit unsigned, 3-sample TIFF file (see [`decode_tiff_rgb16`]).
pub fn read_tiff_rgb16(path: &Path, limits: &Limits) -> IoResult<(usize, usize, Vec<u16>)> {
    let bytes = read_capped(path, limits.max_file_bytes(6))?;
    decode_tiff_rgb16(&bytes, limits)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_rgb_round_trip_is_bit_exact() {
        let (w, h) = (5, 3);
        let data: Vec<f32> = (0..w * h * 3)
            .map(|i| (i as f32 * 0.37).sin() * 1e3 + f32::MIN_POSITIVE * i as f32)
            .collect();
        let t = encode_tiff_f32_rgb(w, h, &data).unwrap();
        let (w2, h2, back) = decode_tiff_f32_rgb(&t, &Limits::default()).unwrap();
        assert_eq!((w2, h2), (w, h));
        assert!(
            back.iter()
                .zip(&data)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
    }

    #[test]
    fn rgb16_round_trip() {
        let data: Vec<u16> = (0..4 * 2 * 3).map(|i| (i * 2749) as u16).collect();
        let t = encode_tiff_rgb16(4, 2, &data).unwrap();
        assert_eq!(
            decode_tiff_rgb16(&t, &Limits::default()).unwrap(),
            (4, 2, data)
        );
    }

    #[test]
    fn rgb_is_not_a_mosaic_and_gray_is_not_rgb() {
        let t = encode_tiff_rgb16(2, 2, &[0; 12]).unwrap();
        let e = decode_tiff_mosaic(&t, &Limits::default())
            .err()
            .unwrap()
            .to_string();
        assert!(e.starts_with("TIFF is 16-bit RGB; a single-channel"), "{e}");
        let g = encode_tiff_gray16(&RawFrame::new(2, 1, vec![1, 2]).unwrap()).unwrap();
        let e = decode_tiff_f32_rgb(&g, &Limits::default())
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "TIFF is 16-bit grayscale; a 32-bit float RGB image is expected"
        );
    }

    #[test]
    fn encoders_refuse_non_finite() {
        let e = encode_tiff_f32_rgb(2, 1, &[0.0, 0.0, 0.0, 0.0, f32::INFINITY, 0.0])
            .unwrap_err()
            .to_string();
        assert!(e.contains("pixel (x=1, y=0) channel 1 is inf"), "{e}");
        assert!(encode_tiff_gray_f32(1, 1, &[f32::NAN]).is_err());
    }
}
