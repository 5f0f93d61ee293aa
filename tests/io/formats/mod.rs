//! File formats (`l3::io`): round trips of every writer/reader pair, and hostile input —
//! wrong sizes, huge declared dimensions (refused before allocating), truncation, garbage,
//! wrong colour types, non-finite floats.
//!
//! The tests, by topic: `round_trips` (every writer/reader pair, and writers leave no
//! temporary files), `limits` (wrong sizes, huge declared dimensions), `layouts` (wrong colour
//! types and sample formats, non-finite floats, other formats named) and `garbage` (truncation,
//! corruption, random bytes). The helpers below build their fixtures in code.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::Cursor;

use l3::io::*;

mod garbage;
mod layouts;
mod limits;
mod round_trips;

// ---------------------------------------------------------------------------------------------
// Peak allocation of the current thread, to show that decoders refuse oversized input before
// allocating its pixel buffer.

struct PeakAlloc;

thread_local! {
    static CURRENT: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

fn note(delta: isize) {
    let _ = CURRENT.try_with(|c| {
        let v = c.get().wrapping_add(delta);
        c.set(v);
        let _ = PEAK.try_with(|p| {
            if v > p.get() {
                p.set(v);
            }
        });
    });
}

unsafe impl GlobalAlloc for PeakAlloc {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            note(l.size() as isize);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(l) };
        if !p.is_null() {
            note(l.size() as isize);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) };
        note(-(l.size() as isize));
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, l, new) };
        if !q.is_null() {
            note(new as isize - l.size() as isize);
        }
        q
    }
}

#[global_allocator]
static ALLOC: PeakAlloc = PeakAlloc;

/// Runs `f` and returns its result with the peak number of bytes it had allocated at once
/// (on this thread).
fn peak_bytes<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let base = CURRENT.with(|c| c.get());
    PEAK.with(|p| p.set(base));
    let r = f();
    let peak = PEAK.with(|p| p.get()) - base;
    (r, peak.max(0) as usize)
}

// ---------------------------------------------------------------------------------------------
// Fixtures built in code.

fn frame(w: usize, h: usize) -> RawFrame {
    let data = (0..w * h)
        .map(|i| ((i as u64 * 2_654_435_761) >> 7) as u16)
        .collect();
    RawFrame::new(w, h, data).unwrap()
}

fn frame8(w: usize, h: usize) -> RawFrame {
    let mut f = frame(w, h);
    f.data.iter_mut().for_each(|v| *v &= 0xff);
    f
}

fn meta(w: usize, h: usize) -> RawMeta {
    let mut m = RawMeta::new(w, h, "RG/WB", 64, 4095, 1.8);
    m.illuminant = Some("D65".into());
    m.exposure_s = Some(0.0125);
    m.seed = Some(42);
    m.sensor = Some("ar0132at-rgbw".into());
    m.extra.insert("analog_gain".into(), serde_json::json!(1.0));
    m
}

fn png_with(w: u32, h: u32, color: png::ColorType, depth: png::BitDepth, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut e = png::Encoder::new(&mut out, w, h);
    e.set_color(color);
    e.set_depth(depth);
    if color == png::ColorType::Indexed {
        e.set_palette(vec![0u8; 3 * 256]);
    }
    let mut wr = e.write_header().unwrap();
    wr.write_image_data(data).unwrap();
    wr.finish().unwrap();
    out
}

fn png_gray8(f: &RawFrame) -> Vec<u8> {
    let bytes: Vec<u8> = f.data.iter().map(|&v| v as u8).collect();
    png_with(
        f.width as u32,
        f.height as u32,
        png::ColorType::Grayscale,
        png::BitDepth::Eight,
        &bytes,
    )
}

fn tiff_with<C: tiff::encoder::colortype::ColorType>(
    w: u32,
    h: u32,
    data: &[C::Inner],
    compression: tiff::encoder::Compression,
    predictor: tiff::tags::Predictor,
) -> Vec<u8>
where
    [C::Inner]: tiff::encoder::TiffValue,
{
    let mut c = Cursor::new(Vec::new());
    let mut e = tiff::encoder::TiffEncoder::new(&mut c)
        .unwrap()
        .with_compression(compression)
        .with_predictor(predictor);
    e.write_image::<C>(w, h, data).unwrap();
    c.into_inner()
}

fn tiff_plain<C: tiff::encoder::colortype::ColorType>(w: u32, h: u32, data: &[C::Inner]) -> Vec<u8>
where
    [C::Inner]: tiff::encoder::TiffValue,
{
    tiff_with::<C>(
        w,
        h,
        data,
        tiff::encoder::Compression::Uncompressed,
        tiff::tags::Predictor::None,
    )
}

/// A minimal hand-built TIFF: one IFD with the given (tag, values) entries (SHORT when all
/// values fit, else LONG) plus chunk offsets/byte counts for `chunks`, which are stored as given.
fn hand_tiff(
    big_endian: bool,
    mut entries: Vec<(u16, Vec<u32>)>,
    chunks: &[Vec<u8>],
    tiled: bool,
) -> Vec<u8> {
    let w16 = |v: u16| {
        if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let w32 = |v: u32| {
        if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let mut out = Vec::new();
    out.extend_from_slice(if big_endian { b"MM" } else { b"II" });
    out.extend_from_slice(&w16(42));
    out.extend_from_slice(&[0; 4]);
    let mut offsets = Vec::new();
    for c in chunks {
        offsets.push(out.len() as u32);
        out.extend_from_slice(c);
    }
    let (off_tag, cnt_tag) = if tiled { (324, 325) } else { (273, 279) };
    entries.push((off_tag, offsets));
    entries.push((cnt_tag, chunks.iter().map(|c| c.len() as u32).collect()));
    entries.sort_by_key(|e| e.0);
    // Out-of-line values.
    let mut placed = Vec::new();
    for (tag, vals) in &entries {
        let short = vals.iter().all(|&v| v <= 0xffff);
        let size = vals.len() * if short { 2 } else { 4 };
        let mut field = Vec::new();
        for &v in vals {
            if short {
                field.extend_from_slice(&w16(v as u16));
            } else {
                field.extend_from_slice(&w32(v));
            }
        }
        if size > 4 {
            if out.len() % 2 == 1 {
                out.push(0);
            }
            let at = out.len() as u32;
            out.extend_from_slice(&field);
            field = w32(at).to_vec();
        } else {
            field.resize(4, 0);
        }
        placed.push((
            *tag,
            if short { 3u16 } else { 4u16 },
            vals.len() as u32,
            field,
        ));
    }
    if out.len() % 2 == 1 {
        out.push(0);
    }
    let ifd = out.len() as u32;
    out.extend_from_slice(&w16(placed.len() as u16));
    for (tag, typ, count, field) in placed {
        out.extend_from_slice(&w16(tag));
        out.extend_from_slice(&w16(typ));
        out.extend_from_slice(&w32(count));
        out.extend_from_slice(&field);
    }
    out.extend_from_slice(&[0; 4]);
    out[4..8].copy_from_slice(&w32(ifd));
    out
}

/// Sets the (single, inline) value of `tag` in a little-endian TIFF from [`hand_tiff`] to a LONG.
fn patch_tag_le(tiff: &[u8], tag: u16, value: u32) -> Vec<u8> {
    let mut b = tiff.to_vec();
    let ifd = u32::from_le_bytes([b[4], b[5], b[6], b[7]]) as usize;
    let n = u16::from_le_bytes([b[ifd], b[ifd + 1]]) as usize;
    for i in 0..n {
        let e = ifd + 2 + 12 * i;
        if u16::from_le_bytes([b[e], b[e + 1]]) == tag {
            b[e + 2..e + 4].copy_from_slice(&4u16.to_le_bytes());
            b[e + 4..e + 8].copy_from_slice(&1u32.to_le_bytes());
            b[e + 8..e + 12].copy_from_slice(&value.to_le_bytes());
            return b;
        }
    }
    panic!("tag {tag} not found");
}

/// Basic tags of an uncompressed single-channel image.
fn gray_tags(w: u32, h: u32, bits: u32, format: u32) -> Vec<(u16, Vec<u32>)> {
    vec![
        (256, vec![w]),
        (257, vec![h]),
        (258, vec![bits]),
        (259, vec![1]),
        (262, vec![1]),
        (277, vec![1]),
        (339, vec![format]),
    ]
}

/// A tiled, uncompressed 16-bit TIFF of `f` with `t`×`t` tiles, stored full size (edge tiles
/// padded with junk).
fn tiled_tiff(f: &RawFrame, t: usize) -> Vec<u8> {
    let (w, h) = (f.width, f.height);
    let mut tiles = Vec::new();
    for ty in 0..h.div_ceil(t) {
        for tx in 0..w.div_ceil(t) {
            let mut tile = Vec::new();
            for y in ty * t..ty * t + t {
                for x in tx * t..tx * t + t {
                    let v = if x < w && y < h {
                        f.data[y * w + x]
                    } else {
                        0xdead
                    };
                    tile.extend_from_slice(&v.to_le_bytes());
                }
            }
            tiles.push(tile);
        }
    }
    let mut tags = gray_tags(w as u32, h as u32, 16, 1);
    tags.push((322, vec![t as u32]));
    tags.push((323, vec![t as u32]));
    hand_tiff(false, tags, &tiles, true)
}

fn pgm_p5(f: &RawFrame, maxval: u16) -> Vec<u8> {
    let mut b = format!("P5\n# l3 test\n{} {}\n{maxval}\n", f.width, f.height).into_bytes();
    for &v in &f.data {
        if maxval > 255 {
            b.extend_from_slice(&v.min(maxval).to_be_bytes());
        } else {
            b.push(v.min(maxval) as u8);
        }
    }
    b
}

fn pgm_p2(f: &RawFrame, maxval: u16) -> Vec<u8> {
    let mut s = format!("P2\n{} {}\n{maxval}\n", f.width, f.height);
    for row in f.data.chunks(f.width) {
        let line: Vec<String> = row.iter().map(|v| v.min(&maxval).to_string()).collect();
        s.push_str(&line.join(" "));
        s.push('\n');
    }
    s.into_bytes()
}

fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in data {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// Rewrites the IHDR size of a PNG (with a valid CRC).
fn patch_png_size(png: &[u8], w: u32, h: u32) -> Vec<u8> {
    let mut b = png.to_vec();
    b[16..20].copy_from_slice(&w.to_be_bytes());
    b[20..24].copy_from_slice(&h.to_be_bytes());
    let crc = crc32(&b[12..29]);
    b[29..33].copy_from_slice(&crc.to_be_bytes());
    b
}

fn u16_of(m: DecodedMosaic) -> RawFrame {
    match m {
        DecodedMosaic::U16(f) => f,
        other => panic!("expected integer mosaic, got {other:?}"),
    }
}

fn err_of<T: std::fmt::Debug>(r: Result<T, IoError>) -> String {
    r.unwrap_err().to_string()
}

fn lim() -> Limits {
    Limits::default()
}
