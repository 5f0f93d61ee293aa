//! File formats (`l3::io`): round trips of every writer/reader pair, and hostile input —
//! wrong sizes, huge declared dimensions (refused before allocating), truncation, garbage,
//! wrong colour types, non-finite floats.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::Cursor;
use std::path::Path;

use l3::io::*;
use proptest::prelude::*;

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

// ---------------------------------------------------------------------------------------------
// Round trips.

#[test]
fn raw_and_sidecar_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let f = frame(37, 21);
    let m = meta(37, 21);
    let paths = write_raw(&dir.path().join("frame"), &f, &m).unwrap();
    assert_eq!(paths.raw, dir.path().join("frame.raw"));
    assert_eq!(paths.json, dir.path().join("frame.json"));
    let bytes = std::fs::read(&paths.raw).unwrap();
    assert_eq!(bytes, encode_raw_u16_le(&f));
    assert_eq!(&bytes[..2], &f.data[0].to_le_bytes());
    let json = std::fs::read_to_string(&paths.json).unwrap();
    assert!(
        json.contains("\n  \"cfa\": \"RG/WB\""),
        "not pretty: {json}"
    );
    let (f2, m2) = read_raw(&paths.raw, &lim()).unwrap();
    assert_eq!(f2, f);
    assert_eq!(m2, m);
    // Through read_mosaic, by the .raw extension.
    let loaded = read_mosaic(&paths.raw, &lim()).unwrap();
    assert_eq!(loaded.mosaic, DecodedMosaic::U16(f.clone()));
    assert_eq!(loaded.meta, Some(m.clone()));
    assert_eq!(loaded.info.format, MosaicFormat::Raw);
    // Only the two files exist (no temporary files left).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    // Overwriting works.
    let f3 = frame8(37, 21);
    write_raw(&paths.raw, &f3, &m).unwrap();
    assert_eq!(read_raw(&paths.json, &lim()).unwrap().0, f3);
}

#[test]
fn raw_volts_round_trip() {
    let m = meta(64, 64);
    let mut f = frame(64, 64);
    f.data.iter_mut().for_each(|v| *v = 64 + *v % 4032);
    let volts = f.to_volts(&m).unwrap();
    assert!(volts.iter().all(|&v| (0.0..=1.8).contains(&v)));
    assert_eq!(RawFrame::from_volts(&volts, 64, 64, &m).unwrap(), f);
    let mut buf = vec![0.0; 64 * 64];
    f.to_volts_into(&m, &mut buf).unwrap();
    assert_eq!(buf, volts);
    assert!(f.to_volts_into(&m, &mut buf[1..]).is_err());
}

#[test]
fn png_gray16_file_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("m.png");
    let f = frame(41, 17);
    write_png_gray16(&p, &f).unwrap();
    let loaded = read_mosaic(&p, &lim()).unwrap();
    assert_eq!(loaded.mosaic, DecodedMosaic::U16(f.clone()));
    assert_eq!(
        loaded.info,
        SourceInfo {
            format: MosaicFormat::Png,
            bits_per_sample: 16,
            max_value: Some(65535)
        }
    );
    assert_eq!(loaded.meta, None);
    for c in [
        PngCompression::Fast,
        PngCompression::Default,
        PngCompression::Best,
    ] {
        let b = encode_png_gray16(&f, c).unwrap();
        assert_eq!(u16_of(decode_mosaic(&b, &lim()).unwrap()), f);
    }
}

#[test]
fn png_gray8_widens_without_rescaling() {
    let f = frame8(9, 4);
    let (m, info) = decode_mosaic_with_info(&png_gray8(&f), &lim()).unwrap();
    assert_eq!(u16_of(m), f);
    assert_eq!((info.bits_per_sample, info.max_value), (8, Some(255)));
}

#[test]
fn png_rgb8_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (33, 19);
    let data: Vec<u8> = (0..w * h * 3).map(|i| (i * 101 % 251) as u8).collect();
    for (i, c) in [
        PngCompression::Fast,
        PngCompression::Default,
        PngCompression::Best,
    ]
    .into_iter()
    .enumerate()
    {
        let p = dir.path().join(format!("rgb{i}.png"));
        write_png_rgb8(&p, w, h, &data, c).unwrap();
        let file = std::fs::read(&p).unwrap();
        assert_eq!(file, encode_png_rgb8(w, h, &data, c).unwrap());
        assert_eq!(
            decode_png_rgb8(&file, &lim()).unwrap(),
            (w, h, data.clone())
        );
    }
}

#[test]
fn tiff_f32_rgb_round_trip_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("xyz.tiff");
    let (w, h) = (23, 11);
    let mut data: Vec<f32> = (0..w * h * 3)
        .map(|i| ((i as f32) * 0.731).sin() * 95.047)
        .collect();
    data[0] = f32::MIN_POSITIVE / 8.0; // subnormal
    data[1] = -0.0;
    data[2] = f32::MAX;
    write_tiff_f32_rgb(&p, w, h, &data).unwrap();
    let (w2, h2, back) = read_tiff_f32_rgb(&p, &lim()).unwrap();
    assert_eq!((w2, h2), (w, h));
    assert_eq!(back.len(), data.len());
    assert!(
        back.iter()
            .zip(&data)
            .all(|(a, b)| a.to_bits() == b.to_bits())
    );
    assert_eq!(
        std::fs::read(&p).unwrap(),
        encode_tiff_f32_rgb(w, h, &data).unwrap()
    );
}

#[test]
fn tiff_rgb16_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("rgb16.tif");
    let data: Vec<u16> = (0..15 * 7 * 3).map(|i| (i * 4099 % 65536) as u16).collect();
    write_tiff_rgb16(&p, 15, 7, &data).unwrap();
    assert_eq!(read_tiff_rgb16(&p, &lim()).unwrap(), (15, 7, data.clone()));
    assert_eq!(
        decode_tiff_rgb16(&encode_tiff_rgb16(15, 7, &data).unwrap(), &lim()).unwrap(),
        (15, 7, data)
    );
}

#[test]
fn tiff_mosaics_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let f = frame(29, 13);
    let p = dir.path().join("m16.tif");
    write_tiff_gray16(&p, &f).unwrap();
    let loaded = read_mosaic(&p, &lim()).unwrap();
    assert_eq!(loaded.mosaic, DecodedMosaic::U16(f.clone()));
    assert_eq!(
        (loaded.info.format, loaded.info.bits_per_sample),
        (MosaicFormat::Tiff, 16)
    );

    let volts: Vec<f32> = (0..29 * 13).map(|i| i as f32 * 1e-3).collect();
    let p = dir.path().join("volts.tif");
    write_tiff_gray_f32(&p, 29, 13, &volts).unwrap();
    let loaded = read_mosaic(&p, &lim()).unwrap();
    assert_eq!(
        loaded.mosaic,
        DecodedMosaic::F32 {
            width: 29,
            height: 13,
            data: volts.clone()
        }
    );
    assert_eq!(loaded.info.max_value, None);
    assert_eq!(
        decode_mosaic(&encode_tiff_gray_f32(29, 13, &volts).unwrap(), &lim()).unwrap(),
        loaded.mosaic
    );

    let f8 = frame8(29, 13);
    let bytes: Vec<u8> = f8.data.iter().map(|&v| v as u8).collect();
    let t8 = tiff_plain::<tiff::encoder::colortype::Gray8>(29, 13, &bytes);
    let (m, info) = decode_mosaic_with_info(&t8, &lim()).unwrap();
    assert_eq!(u16_of(m), f8);
    assert_eq!(info.max_value, Some(255));
}

#[test]
fn compressed_tiffs_decode() {
    use tiff::encoder::{Compression, DeflateLevel};
    use tiff::tags::Predictor;
    let f = frame(31, 9);
    for comp in [
        Compression::Lzw,
        Compression::Deflate(DeflateLevel::Fast),
        Compression::Packbits,
    ] {
        for pred in [Predictor::None, Predictor::Horizontal] {
            let t = tiff_with::<tiff::encoder::colortype::Gray16>(31, 9, &f.data, comp, pred);
            assert_eq!(u16_of(decode_mosaic(&t, &lim()).unwrap()), f, "{pred:?}");
        }
    }
}

#[test]
fn tiled_and_big_endian_tiffs_decode() {
    let (w, h) = (37usize, 21usize);
    let f = frame(w, h);
    assert_eq!(
        u16_of(decode_mosaic(&tiled_tiff(&f, 16), &lim()).unwrap()),
        f
    );

    // Big-endian, 3 rows per strip (last strip short).
    let mut strips = Vec::new();
    for rows in f.data.chunks(3 * w) {
        strips.push(
            rows.iter()
                .flat_map(|v| v.to_be_bytes())
                .collect::<Vec<u8>>(),
        );
    }
    let mut tags = gray_tags(w as u32, h as u32, 16, 1);
    tags.push((278, vec![3]));
    let be = hand_tiff(true, tags, &strips, false);
    assert_eq!(u16_of(decode_mosaic(&be, &lim()).unwrap()), f);
}

#[test]
fn pgm_p5_and_p2_decode() {
    let f = frame(19, 7);
    let (m, info) = decode_mosaic_with_info(&pgm_p5(&f, 65535), &lim()).unwrap();
    assert_eq!(u16_of(m), f);
    assert_eq!((info.format, info.bits_per_sample), (MosaicFormat::Pgm, 16));
    let mut f12 = f.clone();
    f12.data.iter_mut().for_each(|v| *v &= 4095);
    let (m, info) = decode_mosaic_with_info(&pgm_p5(&f12, 4095), &lim()).unwrap();
    assert_eq!(u16_of(m), f12);
    assert_eq!(info.max_value, Some(4095));
    let f8 = frame8(19, 7);
    let (m, info) = decode_mosaic_with_info(&pgm_p5(&f8, 255), &lim()).unwrap();
    assert_eq!(u16_of(m), f8);
    assert_eq!(info.bits_per_sample, 8);
    assert_eq!(
        u16_of(decode_mosaic(&pgm_p2(&f12, 4095), &lim()).unwrap()),
        f12
    );
}

#[test]
fn read_mosaic_uses_a_matching_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let f = frame(8, 6);
    let p = dir.path().join("shot.png");
    write_png_gray16(&p, &f).unwrap();
    let json = dir.path().join("shot.json");
    std::fs::write(&json, meta(8, 6).to_json_pretty().unwrap()).unwrap();
    assert_eq!(read_mosaic(&p, &lim()).unwrap().meta, Some(meta(8, 6)));
    std::fs::write(&json, meta(8, 7).to_json_pretty().unwrap()).unwrap();
    let e = err_of(read_mosaic(&p, &lim()));
    assert!(e.contains("says 8×7 but") && e.contains("is 8×6"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// Wrong sizes and limits.

#[test]
fn raw_length_errors_are_exact() {
    let e = err_of(decode_raw_u16_le(&[0; 1000], 32, 32, &lim()));
    assert_eq!(
        e,
        "body has 1000 bytes; width×height×2 (32×32×2) = 2048 expected"
    );
    let e = err_of(decode_raw_u16_le(&[0; 2049], 32, 32, &lim()));
    assert!(e.contains("has 2049 bytes"), "{e}");
    let e = err_of(decode_raw_u16_le(&[], 0, 32, &lim()));
    assert_eq!(e, "image is 0×32; both dimensions must be at least 1");
    let (r, peak) = peak_bytes(|| decode_raw_u16_le(&[0; 1000], 100_000, 100_000, &lim()));
    assert!(matches!(r, Err(IoError::DimensionTooLarge { .. })));
    assert!(peak < 1 << 16, "allocated {peak} bytes");
    let small = Limits {
        max_pixels: 1000,
        max_dim: 100,
    };
    let e = err_of(decode_raw_u16_le(&[0; 2048], 32, 32, &small));
    assert_eq!(
        e,
        "image is 32×32 = 1024 pixels; at most 1000 pixels are allowed"
    );
}

#[test]
fn raw_file_errors() {
    let dir = tempfile::tempdir().unwrap();
    let f = frame(10, 10);
    let paths = write_raw(&dir.path().join("a.raw"), &f, &meta(10, 10)).unwrap();
    // Truncated .raw.
    let bytes = std::fs::read(&paths.raw).unwrap();
    std::fs::write(&paths.raw, &bytes[..150]).unwrap();
    let e = err_of(read_raw(&paths.raw, &lim()));
    assert!(
        e.contains("has 150 bytes; width×height×2 (10×10×2) = 200 expected"),
        "{e}"
    );
    // A sidecar that declares more than the limit: refused before touching the .raw.
    std::fs::write(&paths.json, meta(40_000, 40_000).to_json_pretty().unwrap()).unwrap();
    let e = err_of(read_raw(&paths.raw, &lim()));
    assert!(e.contains("sidecar") && e.contains("at most 30000"), "{e}");
    // Broken sidecars.
    std::fs::write(&paths.json, "{\"width\": 10").unwrap();
    assert!(err_of(read_raw(&paths.raw, &lim())).contains("not a valid sidecar JSON"));
    let mut m = meta(10, 10);
    m.black_level = 5000;
    std::fs::write(&paths.json, serde_json::to_string(&m).unwrap()).unwrap();
    assert!(err_of(read_raw(&paths.raw, &lim())).contains("black_level 5000 is not below"));
    std::fs::remove_file(&paths.json).unwrap();
    let e = err_of(read_raw(&paths.raw, &lim()));
    assert!(e.contains("cannot read") && e.contains("a.json"), "{e}");
    // Writers check the metadata.
    let e = err_of(write_raw(&paths.raw, &f, &meta(10, 11)));
    assert!(
        e.contains("metadata says 10×11 but the frame is 10×10"),
        "{e}"
    );
    // A missing directory is an error naming the path.
    let e = err_of(write_png_gray16(&dir.path().join("no/such/dir/x.png"), &f));
    assert!(e.contains("no/such/dir"), "{e}");
}

#[test]
fn encoders_check_lengths_and_sizes() {
    let e = err_of(encode_tiff_f32_rgb(4, 4, &[0.0; 47]));
    assert_eq!(
        e,
        "RGB data has 47 values; width×height×3 (4×4×3) = 48 expected"
    );
    assert!(encode_tiff_rgb16(0, 4, &[]).is_err());
    assert!(encode_png_rgb8(4, 4, &[0; 49], PngCompression::Fast).is_err());
    let bad = RawFrame {
        width: 3,
        height: 3,
        data: vec![0; 8],
    };
    assert!(encode_png_gray16(&bad, PngCompression::Fast).is_err());
    assert!(encode_tiff_gray16(&bad).is_err());
}

#[test]
fn huge_declared_sizes_fail_before_allocating() {
    // Each input declares ≥ 80 MB of pixels in a few kilobytes.
    let small = png_gray8(&frame8(4, 4));
    let png_within_limit = patch_png_size(&small, 9000, 9000);
    let png_over_limit = patch_png_size(&small, 20_000, 20_000);
    let mut tiff_tiny = gray_tags(9000, 9000, 16, 1);
    tiff_tiny.push((278, vec![1]));
    let tiff_tiny = hand_tiff(
        false,
        tiff_tiny,
        &[vec![0u8; 18000], vec![0u8; 18000], vec![0u8; 18000]],
        false,
    );
    let tiff_over = hand_tiff(false, gray_tags(50_000, 10, 16, 1), &[vec![0u8; 64]], false);
    // 9000 one-row LZW strips of garbage, all pointing at the same 16 bytes.
    let mut lzw = gray_tags(9000, 9000, 16, 1);
    lzw[3] = (259, vec![5]);
    lzw.push((278, vec![1]));
    let garbage = vec![
        0x80u8, 0x01, 0xff, 0x00, 0x37, 0x12, 0x99, 0x42, 7, 7, 7, 7, 1, 2, 3, 4,
    ];
    let lzw = hand_tiff(false, lzw, &vec![garbage.clone(); 9000], false);
    // One 162 MB Deflate strip in 16 bytes.
    let mut deflate = gray_tags(9000, 9000, 16, 1);
    deflate[3] = (259, vec![8]);
    let deflate = hand_tiff(false, deflate, &[garbage], false);
    let pgm = b"P5 9000 9000 65535\n\x00\x01".to_vec();
    let p2 = b"P2 9000 9000 65535\n1 2 3".to_vec();
    let cases: [(&str, Vec<u8>, &str); 8] = [
        ("tiff lzw strips", lzw, "invalid TIFF"),
        ("tiff deflate strip", deflate, "cannot expand"),
        (
            "png in limit",
            png_within_limit,
            "cannot inflate to that much",
        ),
        ("png over limit", png_over_limit, "at most 100000000 pixels"),
        ("tiff strips", tiff_tiny, "invalid TIFF"),
        (
            "tiff over limit",
            tiff_over,
            "each side may be at most 30000",
        ),
        ("pgm", pgm, "raster has 2 bytes"),
        ("p2", p2, "too few"),
    ];
    // Control: the measurement sees a real decode's pixel buffer (1000×1000×2 bytes).
    let real = pgm_p5(&frame(1000, 1000), 65535);
    let (r, peak) = peak_bytes(|| decode_mosaic(&real, &lim()));
    assert!(r.is_ok() && peak >= 2_000_000, "peak {peak}");
    eprintln!("control: valid 1000×1000 16-bit PGM, peak {peak} bytes allocated");
    for (name, bytes, want) in cases {
        let (r, peak) = peak_bytes(|| decode_mosaic(&bytes, &lim()));
        let e = err_of(r);
        eprintln!(
            "{name}: {} input bytes, peak {peak} bytes allocated: {e}",
            bytes.len()
        );
        assert!(e.contains(want), "{name}: {e}");
        assert!(
            peak < 4 << 20,
            "{name}: allocated {peak} bytes before failing"
        );
    }
}

#[test]
fn tiff_zero_and_odd_sizes() {
    let zero = hand_tiff(false, gray_tags(0, 5, 16, 1), &[vec![]], false);
    assert!(decode_mosaic(&zero, &lim()).is_err());
    // Strip data shorter than declared.
    let short = hand_tiff(false, gray_tags(4, 4, 16, 1), &[vec![0u8; 20]], false);
    assert!(decode_mosaic(&short, &lim()).is_err());
    // A strip offset beyond the end of the file.
    let good = hand_tiff(false, gray_tags(4, 4, 16, 1), &[vec![0u8; 32]], false);
    assert!(decode_mosaic(&good, &lim()).is_ok());
    let bad = patch_tag_le(&good, 273, good.len() as u32 + 1000);
    assert!(decode_mosaic(&bad, &lim()).is_err());
    // RowsPerStrip 0 and an absurd strip byte count.
    let bad = patch_tag_le(&good, 279, u32::MAX);
    assert!(decode_mosaic(&bad, &lim()).is_err());
    let mut tags = gray_tags(4, 4, 16, 1);
    tags.push((278, vec![0]));
    let bad = hand_tiff(false, tags, &[vec![0u8; 32]], false);
    assert!(decode_mosaic(&bad, &lim()).is_err());
}

// ---------------------------------------------------------------------------------------------
// Wrong pixel layouts.

#[test]
fn colour_and_alpha_pngs_are_refused() {
    use png::{BitDepth as D, ColorType as C};
    let cases: [(C, D, usize, &str); 6] = [
        (C::Rgb, D::Eight, 12, "PNG is 8-bit RGB"),
        (C::Rgba, D::Sixteen, 32, "PNG is 16-bit RGBA"),
        (
            C::Indexed,
            D::Eight,
            4,
            "PNG is 8-bit palette (indexed colour)",
        ),
        (
            C::GrayscaleAlpha,
            D::Eight,
            8,
            "PNG is 8-bit grayscale with alpha",
        ),
        (C::Grayscale, D::One, 2, "PNG is 1-bit grayscale"),
        (C::Grayscale, D::Four, 2, "PNG is 4-bit grayscale"),
    ];
    for (c, d, n, want) in cases {
        let b = png_with(2, 2, c, d, &vec![0u8; n]);
        let e = err_of(decode_mosaic(&b, &lim()));
        assert_eq!(
            e,
            format!("{want}; a 16-bit (or 8-bit) grayscale mosaic is expected")
        );
    }
    let e = err_of(decode_png_rgb8(&png_gray8(&frame8(2, 2)), &lim()));
    assert_eq!(e, "PNG is 8-bit grayscale; an 8-bit RGB image is expected");
}

#[test]
fn colour_and_integer_tiffs_are_refused() {
    use tiff::encoder::colortype as ct;
    let expected = "is expected";
    let cases: [(Vec<u8>, &str); 5] = [
        (tiff_plain::<ct::RGB8>(2, 2, &[0; 12]), "TIFF is 8-bit RGB;"),
        (
            encode_tiff_f32_rgb(2, 2, &[0.0; 12]).unwrap(),
            "TIFF is 32-bit float RGB;",
        ),
        (
            tiff_plain::<ct::Gray32>(2, 2, &[0; 4]),
            "TIFF is 32-bit unsigned integer grayscale;",
        ),
        (
            tiff_plain::<ct::GrayI16>(2, 2, &[0; 4]),
            "TIFF is 16-bit signed integer grayscale;",
        ),
        (
            tiff_plain::<ct::RGBA16>(2, 2, &[0; 16]),
            "TIFF is 16-bit RGBA;",
        ),
    ];
    for (b, want) in cases {
        let e = err_of(decode_mosaic(&b, &lim()));
        assert!(e.starts_with(want) && e.ends_with(expected), "{e}");
    }
    let e = err_of(decode_tiff_f32_rgb(
        &tiff_plain::<ct::RGB16>(1, 1, &[0; 3]),
        &lim(),
    ));
    assert_eq!(
        e,
        "TIFF is 16-bit RGB; a 32-bit float RGB image is expected"
    );
}

#[test]
fn non_finite_float_tiffs_are_refused_with_the_position() {
    use tiff::encoder::colortype as ct;
    let mut v = vec![0.5f32; 6 * 4];
    v[2 * 6 + 5] = f32::NAN;
    let e = err_of(decode_mosaic(
        &tiff_plain::<ct::Gray32Float>(6, 4, &v),
        &lim(),
    ));
    assert_eq!(
        e,
        "float TIFF: pixel (x=5, y=2) is NaN; only finite values are accepted"
    );
    v[2 * 6 + 5] = 0.0;
    v[3 * 6] = f32::NEG_INFINITY;
    let e = err_of(decode_mosaic(
        &tiff_plain::<ct::Gray32Float>(6, 4, &v),
        &lim(),
    ));
    assert!(e.contains("pixel (x=0, y=3) is -inf"), "{e}");
    let mut rgb = vec![1.0f32; 2 * 2 * 3];
    rgb[3 * 3 + 2] = f32::INFINITY;
    let e = err_of(decode_tiff_f32_rgb(
        &tiff_plain::<ct::RGB32Float>(2, 2, &rgb),
        &lim(),
    ));
    assert!(e.contains("pixel (x=1, y=1) channel 2 is inf"), "{e}");
}

#[test]
fn other_netpbm_and_unknown_formats_are_named() {
    let e = err_of(decode_mosaic(b"P6\n1 1\n255\n\0\0\0", &lim()));
    assert_eq!(
        e,
        "Netpbm file is a colour pixmap (PPM), magic P6; a grayscale PGM (P5 or P2) is expected"
    );
    let e = err_of(decode_mosaic(b"\xff\xd8\xff\xe0\0\x10JFIF", &lim()));
    assert!(e.contains("JPEG"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("noise.bin");
    std::fs::write(&p, [7u8, 7, 7]).unwrap();
    let e = err_of(read_mosaic(&p, &lim()));
    assert!(
        e.contains("noise.bin") && e.contains("first bytes 07 07 07"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------------
// Truncation and garbage.

/// Valid files of every accepted kind.
fn valid_files() -> Vec<(&'static str, Vec<u8>)> {
    use tiff::encoder::{Compression, colortype as ct};
    use tiff::tags::Predictor;
    let f = frame(13, 7);
    let f8 = frame8(13, 7);
    let volts: Vec<f32> = (0..13 * 7).map(|i| i as f32 * 0.01).collect();
    let mut strips = Vec::new();
    for rows in f.data.chunks(2 * 13) {
        strips.push(
            rows.iter()
                .flat_map(|v| v.to_be_bytes())
                .collect::<Vec<u8>>(),
        );
    }
    let mut tags = gray_tags(13, 7, 16, 1);
    tags.push((278, vec![2]));
    vec![
        (
            "png16",
            encode_png_gray16(&f, PngCompression::Default).unwrap(),
        ),
        ("png8", png_gray8(&f8)),
        ("tiff16", encode_tiff_gray16(&f).unwrap()),
        ("tiff-f32", encode_tiff_gray_f32(13, 7, &volts).unwrap()),
        (
            "tiff-lzw",
            tiff_with::<ct::Gray16>(13, 7, &f.data, Compression::Lzw, Predictor::Horizontal),
        ),
        ("tiff-be", hand_tiff(true, tags, &strips, false)),
        ("tiff-tiled", tiled_tiff(&f, 16)),
        ("pgm16", pgm_p5(&f, 65535)),
        ("pgm8", pgm_p5(&f8, 255)),
    ]
}

#[test]
fn truncated_files_are_errors_at_every_offset() {
    for (name, b) in valid_files() {
        assert!(decode_mosaic(&b, &lim()).is_ok(), "{name} does not decode");
        for cut in 0..b.len() {
            assert!(
                decode_mosaic(&b[..cut], &lim()).is_err(),
                "{name} truncated to {cut} of {} bytes decoded",
                b.len()
            );
        }
    }
    // Plain PGM cannot always tell a cut number from a shorter one; it must never panic, and
    // cutting before the last sample is an error.
    let p2 = pgm_p2(&frame(13, 7), 65535);
    let last = p2[..p2.len() - 1].iter().rposition(|&c| c == b' ').unwrap();
    for cut in 0..p2.len() {
        let r = decode_mosaic(&p2[..cut], &lim());
        if cut <= last {
            assert!(r.is_err(), "P2 cut at {cut} decoded");
        }
    }
}

#[test]
fn corrupted_files_never_panic() {
    // Deterministic byte mutations of every valid file (headers, data and trailers).
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let files = valid_files();
    let small = Limits {
        max_pixels: 1 << 20,
        max_dim: 1 << 12,
    };
    for i in 0..20_000 {
        let (_, b) = &files[i % files.len()];
        let mut m = b.clone();
        for _ in 0..1 + next() % 4 {
            let at = (next() as usize) % m.len();
            m[at] = match next() % 4 {
                0 => 0xff,
                1 => 0,
                2 => m[at] ^ (1 << (next() % 8)),
                _ => next() as u8,
            };
        }
        let _ = decode_mosaic(&m, &small);
        let _ = decode_tiff_f32_rgb(&m, &small);
        let _ = decode_png_rgb8(&m, &small);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let _ = decode_mosaic(&bytes, &lim());
    }

    #[test]
    fn random_bodies_after_a_magic_never_panic(
        magic in 0usize..6,
        body in proptest::collection::vec(any::<u8>(), 0..1024),
    ) {
        let heads: [&[u8]; 6] =
            [b"\x89PNG\r\n\x1a\n", b"II*\0", b"MM\0*", b"II+\0", b"P5 ", b"P2\n"];
        let mut b = heads[magic].to_vec();
        b.extend_from_slice(&body);
        prop_assert!(decode_mosaic(&b, &lim()).is_err() || magic >= 4);
    }

    #[test]
    fn raw_decode_accepts_exactly_the_right_length(
        w in 1usize..40, h in 1usize..40, delta in -3i64..3,
    ) {
        let n = (w * h * 2) as i64 + delta;
        let bytes = vec![0u8; n.max(0) as usize];
        let r = decode_raw_u16_le(&bytes, w, h, &lim());
        prop_assert_eq!(r.is_ok(), delta == 0);
    }
}

#[test]
fn writers_leave_no_temporary_files() {
    let dir = tempfile::tempdir().unwrap();
    let f = frame(5, 5);
    write_png_gray16(&dir.path().join("a.png"), &f).unwrap();
    write_tiff_gray16(&dir.path().join("a.tif"), &f).unwrap();
    write_tiff_rgb16(&dir.path().join("b.tif"), 1, 1, &[1, 2, 3]).unwrap();
    write_png_rgb8(
        &dir.path().join("b.png"),
        1,
        1,
        &[1, 2, 3],
        PngCompression::Fast,
    )
    .unwrap();
    // A failing writer (bad length) leaves nothing behind either.
    assert!(write_tiff_f32_rgb(&dir.path().join("c.tif"), 2, 2, &[0.0; 3]).is_err());
    let mut names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["a.png", "a.tif", "b.png", "b.tif"]);
    assert!(Path::new(&dir.path().join("a.png")).is_file());
}
