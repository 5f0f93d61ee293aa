//! The raw image's strips or tiles: where they are, checks that they can hold the image, and
//! decoding them (uncompressed, or lossless JPEG) into it.

use super::ifd::{Ifd, Tiff, dng_err, required, tag_name};
use super::ljpeg;
use crate::io::IoResult;
use crate::io::limits::Limits;
use rayon::prelude::*;

const TAG_STRIP_OFFSETS: u16 = 273;
const TAG_ROWS_PER_STRIP: u16 = 278;
const TAG_STRIP_BYTES: u16 = 279;
const TAG_TILE_WIDTH: u16 = 322;
const TAG_TILE_LENGTH: u16 = 323;
const TAG_TILE_OFFSETS: u16 = 324;
const TAG_TILE_BYTES: u16 = 325;

/// How the raw image is cut into chunks (strips are tiles as wide as the image).
pub(super) struct Layout {
    tile_w: usize,
    tile_h: usize,
    across: usize,
    offsets: Vec<u64>,
    counts: Vec<u64>,
}

pub(super) fn layout(
    t: &Tiff<'_>,
    ifd: &Ifd,
    w: usize,
    h: usize,
    limits: &Limits,
) -> IoResult<Layout> {
    let tiled = ifd.has(TAG_TILE_OFFSETS);
    let (tile_w, tile_h, off_tag, count_tag) = if tiled {
        // one tile and no tile size (PiDNG writes TileOffsets itself, one tile of the
        // whole image, and leaves TileWidth and TileLength to its caller): the image's size
        let (tw, th) = if ifd.count(TAG_TILE_OFFSETS) == Some(1)
            && !ifd.has(TAG_TILE_WIDTH)
            && !ifd.has(TAG_TILE_LENGTH)
        {
            (w as u64, h as u64)
        } else {
            (
                required(t, ifd, TAG_TILE_WIDTH)?,
                required(t, ifd, TAG_TILE_LENGTH)?,
            )
        };
        (tw, th, TAG_TILE_OFFSETS, TAG_TILE_BYTES)
    } else {
        let rps = t.uint(ifd, TAG_ROWS_PER_STRIP)?.unwrap_or(h as u64);
        (
            w as u64,
            rps.min(h as u64),
            TAG_STRIP_OFFSETS,
            TAG_STRIP_BYTES,
        )
    };
    let what = if tiled { "tile" } else { "strip" };
    let (tile_w, tile_h) = (
        usize::try_from(tile_w).unwrap_or(usize::MAX),
        usize::try_from(tile_h).unwrap_or(usize::MAX),
    );
    limits
        .check(tile_w, tile_h)
        .map_err(|e| dng_err(format!("a {what} of {tile_w}×{tile_h} pixels: {e}")))?;
    let across = w.div_ceil(tile_w);
    let down = h.div_ceil(tile_h);
    let n = across * down;
    // (read whatever count the file holds, to name a mismatch clearly)
    let offsets = t
        .uints(ifd, off_tag, usize::MAX)?
        .ok_or_else(|| dng_err(format!("the raw image has no {}", tag_name(off_tag))))?;
    let counts = t
        .uints(ifd, count_tag, usize::MAX)?
        .ok_or_else(|| dng_err(format!("the raw image has no {}", tag_name(count_tag))))?;
    if offsets.len() != n || counts.len() != n {
        return Err(dng_err(format!(
            "a {w}×{h} image in {tile_w}×{tile_h} {what}s needs {n} {what}s; {} lists {} and {} lists {}",
            tag_name(off_tag),
            offsets.len(),
            tag_name(count_tag),
            counts.len()
        )));
    }
    Ok(Layout {
        tile_w,
        tile_h,
        across,
        offsets,
        counts,
    })
}

/// Checks, before the image is allocated, that the chunks' data can hold the image: every
/// chunk lies inside the file, their bytes add up to no more than the file (chunks do not
/// share data), and lossless JPEG chunks have at least one bit per sample.
pub(super) fn check_chunks(
    t: &Tiff<'_>,
    lay: &Layout,
    compression: u64,
    bits: u32,
    w: usize,
    h: usize,
) -> IoResult<()> {
    let mut bytes = 0u64;
    let mut samples = 0u64;
    for (k, (&off, &count)) in lay.offsets.iter().zip(&lay.counts).enumerate() {
        let (x0, y0) = ((k % lay.across) * lay.tile_w, (k / lay.across) * lay.tile_h);
        let vis_w = lay.tile_w.min(w.saturating_sub(x0)) as u64;
        let vis_h = lay.tile_h.min(h.saturating_sub(y0)) as u64;
        let len = if compression == 1 {
            (lay.tile_w as u64 * u64::from(bits)).div_ceil(8) * vis_h
        } else {
            count
        };
        if t.slice(off, len).is_none() {
            return Err(dng_err(format!(
                "chunk {k} needs {len} bytes at offset {off} but the file has {}",
                t.len()
            )));
        }
        bytes = bytes.saturating_add(len);
        samples = samples.saturating_add(vis_w * vis_h);
    }
    if bytes > t.len() as u64 {
        return Err(dng_err(format!(
            "the {} chunks need {bytes} bytes, more than the file's {}",
            lay.offsets.len(),
            t.len()
        )));
    }
    if compression != 1 && samples > bytes.saturating_mul(8) {
        return Err(dng_err(format!(
            "{samples} samples cannot fit in {bytes} bytes of lossless JPEG data"
        )));
    }
    Ok(())
}

/// Decodes every chunk into the `w × h` image: each row of chunks (a strip, or a row of
/// tiles) on its own rayon task, writing its own band of `out`. The first failing chunk in
/// file order gives the error, whichever task met it first.
pub(super) fn decode_chunks(
    t: &Tiff<'_>,
    lay: &Layout,
    compression: u64,
    bits: u32,
    w: usize,
    h: usize,
    out: &mut [u16],
) -> IoResult<()> {
    let band = lay.tile_h.saturating_mul(w).max(1);
    let results: Vec<IoResult<()>> = out
        .par_chunks_mut(band)
        .enumerate()
        .map(|(down, rows)| {
            let y0 = down * lay.tile_h;
            for across in 0..lay.across {
                let k = down * lay.across + across;
                let (Some(&off), Some(&count)) = (lay.offsets.get(k), lay.counts.get(k)) else {
                    return Err(dng_err(format!("chunk {k} is not listed")));
                };
                let x0 = across * lay.tile_w;
                let chunk = Chunk {
                    k,
                    off,
                    count,
                    x0,
                    vis_w: lay.tile_w.min(w.saturating_sub(x0)),
                    vis_h: lay.tile_h.min(h.saturating_sub(y0)),
                    w,
                };
                if compression == 1 {
                    chunk.uncompressed(t, lay, bits, rows)?;
                } else {
                    chunk.lossless_jpeg(t, lay, rows)?;
                }
            }
            Ok(())
        })
        .collect();
    results.into_iter().collect()
}

/// One chunk: its index, data, and the part of its band of the `w`-wide image it covers
/// (from column `x0` of the band's first row).
struct Chunk {
    k: usize,
    off: u64,
    count: u64,
    x0: usize,
    vis_w: usize,
    vis_h: usize,
    w: usize,
}

impl Chunk {
    fn put(&self, out: &mut [u16], r: usize, c: usize, v: u16) {
        if let Some(o) = out.get_mut(r * self.w + self.x0 + c) {
            *o = v;
        }
    }

    /// Uncompressed samples of `bits` bits: bytes, 16-bit words in the file's byte order, or
    /// packed most significant bit first in byte-aligned rows.
    fn uncompressed(&self, t: &Tiff<'_>, lay: &Layout, bits: u32, out: &mut [u16]) -> IoResult<()> {
        let (k, off, vis_w, vis_h) = (self.k, self.off, self.vis_w, self.vis_h);
        let row_bytes = (lay.tile_w as u64 * u64::from(bits)).div_ceil(8);
        let need = row_bytes * vis_h as u64;
        let data = t.slice(off, need).ok_or_else(|| {
            dng_err(format!(
                "chunk {k} needs {need} bytes at offset {off} but the file has {}",
                t.len()
            ))
        })?;
        for (r, row) in data.chunks(row_bytes as usize).enumerate().take(vis_h) {
            match bits {
                8 => {
                    for (c, &b) in row.iter().take(vis_w).enumerate() {
                        self.put(out, r, c, u16::from(b));
                    }
                }
                16 => {
                    for (c, p) in row.chunks_exact(2).take(vis_w).enumerate() {
                        let a = [
                            p.first().copied().unwrap_or(0),
                            p.get(1).copied().unwrap_or(0),
                        ];
                        let v = if t.big_endian() {
                            u16::from_be_bytes(a)
                        } else {
                            u16::from_le_bytes(a)
                        };
                        self.put(out, r, c, v);
                    }
                }
                _ => {
                    // packed samples, most significant bit first, rows byte-aligned
                    let mut acc = 0u32;
                    let mut n = 0u32;
                    let mut bytes = row.iter();
                    for c in 0..vis_w {
                        while n < bits {
                            acc = (acc << 8) | u32::from(bytes.next().copied().unwrap_or(0));
                            n += 8;
                        }
                        n -= bits;
                        self.put(out, r, c, ((acc >> n) & ((1 << bits) - 1)) as u16);
                    }
                }
            }
        }
        Ok(())
    }

    /// A lossless JPEG chunk of at most one chunk's samples.
    fn lossless_jpeg(&self, t: &Tiff<'_>, lay: &Layout, out: &mut [u16]) -> IoResult<()> {
        let (k, off, count, vis_w, vis_h) = (self.k, self.off, self.count, self.vis_w, self.vis_h);
        let chunk_samples = lay.tile_w * lay.tile_h;
        let data = t.slice(off, count).ok_or_else(|| {
            dng_err(format!(
                "chunk {k}: {count} bytes at offset {off} lie beyond the end of the file ({} bytes)",
                t.len()
            ))
        })?;
        let j = ljpeg::decode(data, chunk_samples)?;
        let need = (vis_h.saturating_sub(1)) * lay.tile_w + vis_w;
        if j.samples.len() < need {
            return Err(dng_err(format!(
                "chunk {k}: its lossless JPEG holds {} samples ({}×{}×{}); the {}×{} chunk needs {need}",
                j.samples.len(),
                j.width,
                j.height,
                j.components,
                lay.tile_w,
                lay.tile_h
            )));
        }
        for r in 0..vis_h {
            let from = j.samples.get(r * lay.tile_w..r * lay.tile_w + vis_w);
            let at = r * self.w + self.x0;
            if let (Some(from), Some(to)) = (from, out.get_mut(at..at + vis_w)) {
                to.copy_from_slice(from);
            }
        }
        Ok(())
    }
}
