use super::*;

mod leniency;
mod metadata;
mod opcodes;

/// Builds little- or big-endian TIFF/DNG files: data blocks and IFDs appended in order.
struct Builder {
    be: bool,
    buf: Vec<u8>,
}

/// (tag, TIFF type, count, value bytes in the file's order)
type E = (u16, u16, u32, Vec<u8>);

impl Builder {
    fn new(be: bool) -> Self {
        let buf = if be {
            b"MM\0*\0\0\0\0".to_vec()
        } else {
            b"II*\0\0\0\0\0".to_vec()
        };
        Builder { be, buf }
    }
    fn s(&self, v: &[u16]) -> Vec<u8> {
        v.iter()
            .flat_map(|x| {
                if self.be {
                    x.to_be_bytes()
                } else {
                    x.to_le_bytes()
                }
            })
            .collect()
    }
    fn l(&self, v: &[u32]) -> Vec<u8> {
        v.iter()
            .flat_map(|x| {
                if self.be {
                    x.to_be_bytes()
                } else {
                    x.to_le_bytes()
                }
            })
            .collect()
    }
    fn short(&self, tag: u16, v: &[u16]) -> E {
        (tag, 3, v.len() as u32, self.s(v))
    }
    fn long(&self, tag: u16, v: &[u32]) -> E {
        (tag, 4, v.len() as u32, self.l(v))
    }
    fn rational(&self, tag: u16, v: &[(u32, u32)]) -> E {
        let flat: Vec<u32> = v.iter().flat_map(|&(n, d)| [n, d]).collect();
        (tag, 5, v.len() as u32, self.l(&flat))
    }
    fn data(&mut self, d: &[u8]) -> u32 {
        if self.buf.len() % 2 == 1 {
            self.buf.push(0);
        }
        let at = self.buf.len() as u32;
        self.buf.extend_from_slice(d);
        at
    }
    /// Writes an IFD (entries sorted by tag) and returns its offset.
    fn ifd(&mut self, mut entries: Vec<E>) -> u32 {
        entries.sort_by_key(|e| e.0);
        // values longer than 4 bytes first
        let mut placed = Vec::new();
        for (tag, typ, count, val) in entries {
            let v = if val.len() > 4 {
                let at = self.data(&val);
                self.l(&[at])
            } else {
                let mut v = val.clone();
                v.resize(4, 0);
                v
            };
            placed.push((tag, typ, count, v));
        }
        let at = self.data(&[]);
        let n = placed.len() as u16;
        let head = self.s(&[n]);
        self.buf.extend(head);
        for (tag, typ, count, v) in placed {
            let b = [self.s(&[tag, typ]), self.l(&[count]), v].concat();
            self.buf.extend(b);
        }
        self.buf.extend([0u8; 4]);
        at
    }
    fn finish(mut self, ifd0: u32) -> Vec<u8> {
        let b = self.l(&[ifd0]);
        self.buf[4..8].copy_from_slice(&b);
        self.buf
    }
}

fn ramp(w: usize, h: usize, bits: u32) -> Vec<u16> {
    (0..w * h)
        .map(|i| ((i * 7919 + 13) % (1 << bits)) as u16)
        .collect()
}

/// Packs samples MSB first, each row byte-aligned.
fn pack(v: &[u16], w: usize, bits: u32) -> Vec<u8> {
    let mut out = Vec::new();
    for row in v.chunks(w) {
        let (mut acc, mut n) = (0u64, 0u32);
        for &s in row {
            acc = (acc << bits) | u64::from(s);
            n += bits;
            while n >= 8 {
                n -= 8;
                out.push((acc >> n) as u8);
            }
        }
        if n > 0 {
            out.push((acc << (8 - n)) as u8);
        }
    }
    out
}

/// The CFA and level tags of an RGBW `R G / W B` sensor.
fn cfa_tags(b: &Builder, pattern: &[u8]) -> Vec<E> {
    vec![
        b.short(33421, &[2, 2]),
        (33422, 1, pattern.len() as u32, pattern.to_vec()),
        (50710, 1, 4, vec![0, 1, 2, 6]),
    ]
}

/// A DNG of `img` (w × h) in IFD0, uncompressed, in strips of `rps` rows, with the CFA tags
/// of `R G / W B` and `extra` replacing tags of the same number (type 0: removing them).
fn strips_dng(
    be: bool,
    img: &[u16],
    w: usize,
    h: usize,
    bits: u32,
    rps: usize,
    extra: Vec<E>,
) -> Vec<u8> {
    let mut b = Builder::new(be);
    let mut offs = Vec::new();
    let mut counts = Vec::new();
    for rows in img.chunks(w * rps) {
        let d = match bits {
            16 => b.s(rows),
            8 => rows.iter().map(|&v| v as u8).collect(),
            _ => pack(rows, w, bits),
        };
        offs.push(b.data(&d));
        counts.push(d.len() as u32);
    }
    let mut e = vec![
        (50706, 1, 4, vec![1, 4, 0, 0]),
        b.long(256, &[w as u32]),
        b.long(257, &[h as u32]),
        b.short(258, &[bits as u16]),
        b.short(259, &[1]),
        b.short(262, &[32803]),
        b.short(277, &[1]),
        b.long(278, &[rps as u32]),
        b.long(273, &offs),
        b.long(279, &counts),
    ];
    e.extend(cfa_tags(&b, &[0, 1, 6, 2]));
    for x in extra {
        e.retain(|y| y.0 != x.0);
        // (an entry of type 0 removes the tag)
        if x.1 != 0 {
            e.push(x);
        }
    }
    let at = b.ifd(e);
    b.finish(at)
}

fn lim() -> Limits {
    Limits::default()
}

#[test]
fn uncompressed_strips_8_to_16_bits_both_byte_orders() {
    let (w, h) = (6, 5);
    for be in [false, true] {
        for bits in [8u32, 10, 12, 14, 16] {
            let img = ramp(w, h, bits);
            let b = Builder::new(be);
            let extra = vec![b.short(50714, &[3]), b.long(50717, &[(1 << bits) - 1])];
            let f = strips_dng(be, &img, w, h, bits, 2, extra);
            assert!(is_dng(&f));
            let d = decode_dng(&f, &lim()).unwrap();
            assert_eq!(d.frame.data, img, "{bits}-bit, big endian {be}");
            assert_eq!((d.frame.width, d.frame.height), (w, h));
            assert_eq!(d.cfa, "RG/WB");
            assert_eq!(
                (d.black_level, d.white_level),
                (3, ((1u32 << bits) - 1) as u16)
            );
            assert_eq!(d.info.bits_per_sample as u32, bits);
            assert_eq!(d.info.plane_colors, "RGBW");
        }
    }
}

#[test]
fn tiles_with_partial_edges_and_lossless_jpeg() {
    let (w, h) = (10, 7);
    let (tw, th) = (4usize, 4usize);
    let img = ramp(w, h, 12);
    for compression in [1u16, 7] {
        let mut b = Builder::new(false);
        let mut offs = Vec::new();
        let mut counts = Vec::new();
        for ty in 0..h.div_ceil(th) {
            for tx in 0..w.div_ceil(tw) {
                // a full tile, padded with zeros past the image
                let mut t = vec![0u16; tw * th];
                for r in 0..th {
                    for c in 0..tw {
                        let (y, x) = (ty * th + r, tx * tw + c);
                        if y < h && x < w {
                            t[r * tw + c] = img[y * w + x];
                        }
                    }
                }
                // lossless JPEG in the DNG way: 2 components of half the tile's width
                let d = if compression == 7 {
                    super::ljpeg::tests::encode(&t, (tw / 2, th, 2), 12, 1, 0)
                } else {
                    pack(&t, tw, 12)
                };
                offs.push(b.data(&d));
                counts.push(d.len() as u32);
            }
        }
        let mut e = vec![
            (50706, 1, 4, vec![1, 4, 0, 0]),
            b.long(256, &[w as u32]),
            b.long(257, &[h as u32]),
            b.short(258, &[12]),
            b.short(259, &[compression]),
            b.short(262, &[32803]),
            b.short(322, &[tw as u16]),
            b.short(323, &[th as u16]),
            b.long(324, &offs),
            b.long(325, &counts),
            b.short(50717, &[4095]),
        ];
        e.extend(cfa_tags(&b, &[1, 0, 2, 1]));
        e.retain(|x| x.0 != 50710);
        let at = b.ifd(e);
        let f = b.finish(at);
        let d = decode_dng(&f, &lim()).unwrap();
        assert_eq!(d.frame.data, img, "compression {compression}");
        assert_eq!(d.cfa, "GR/BG");
        assert_eq!(d.info.plane_colors, "RGB");
        assert_eq!(d.info.compression, compression);
    }
}

#[test]
fn raw_image_in_a_sub_ifd_after_a_preview() {
    let (w, h) = (4, 4);
    let img = ramp(w, h, 16);
    let mut b = Builder::new(false);
    let strip = b.s(&img);
    let off = b.data(&strip);
    let mut raw = vec![
        b.long(254, &[0]),
        b.long(256, &[w as u32]),
        b.long(257, &[h as u32]),
        b.short(258, &[16]),
        b.short(262, &[32803]),
        b.long(273, &[off]),
        b.long(279, &[strip.len() as u32]),
    ];
    raw.extend(cfa_tags(&b, &[0, 1, 6, 2]));
    // a reduced-resolution CFA image first: skipped
    let mut reduced = raw.clone();
    reduced[0] = b.long(254, &[1]);
    let reduced_at = b.ifd(reduced);
    let raw_at = b.ifd(raw);
    let ifd0 = vec![
        b.long(254, &[1]),
        b.long(256, &[2]),
        b.long(257, &[2]),
        b.short(262, &[2]),
        (50706, 1, 4, vec![1, 4, 0, 0]),
        (50708, 2, 6, b"cam X\0".to_vec()),
        b.rational(50728, &[(1, 2), (1, 1), (3, 4), (1, 3)]),
        b.short(50778, &[17]),
        b.long(330, &[reduced_at, raw_at]),
    ];
    let at = b.ifd(ifd0);
    let f = b.finish(at);
    let d = decode_dng(&f, &lim()).unwrap();
    assert_eq!(d.frame.data, img);
    assert_eq!(d.info.unique_camera_model.as_deref(), Some("cam X"));
    assert_eq!(d.info.calibration_illuminants, [Some(17), None]);
    assert_eq!(
        d.info.neutral().unwrap(),
        vec![
            ("R".to_string(), 0.5),
            ("G".to_string(), 1.0),
            ("B".to_string(), 0.75),
            ("W".to_string(), 1.0 / 3.0)
        ]
    );
    assert_eq!(d.raw_meta(1.8).sensor.as_deref(), Some("cam X"));
}

#[test]
fn black_levels_per_position_are_folded_into_one() {
    let (w, h) = (4, 2);
    let img: Vec<u16> = vec![100, 200, 100, 200, 300, 400, 300, 400];
    let b = Builder::new(false);
    let extra = vec![
        b.short(50713, &[2, 2]),
        b.rational(50714, &[(60, 1), (62, 1), (64, 1), (66, 1)]),
        b.short(50717, &[1000]),
    ];
    let d = decode_dng(&strips_dng(false, &img, w, h, 16, h, extra), &lim()).unwrap();
    assert_eq!(d.black_level, 60);
    assert_eq!(d.info.black_levels, vec![60.0, 62.0, 64.0, 66.0]);
    let want = |v: f64, b: f64| ((v - b) * (1000.0 - 60.0) / (1000.0 - b) + 60.0).round() as u16;
    assert_eq!(d.frame.data[0], 100); // its own black is 60
    assert_eq!(d.frame.data[1], want(200.0, 62.0));
    assert_eq!(d.frame.data[4], want(300.0, 64.0));
    assert_eq!(d.frame.data[7], want(400.0, 66.0));
    // a uniform whole black, written per position, keeps the values
    let b = Builder::new(false);
    let extra = vec![b.short(50713, &[2, 2]), b.short(50714, &[64, 64, 64, 64])];
    let d = decode_dng(&strips_dng(false, &img, w, h, 16, h, extra), &lim()).unwrap();
    assert_eq!((d.black_level, d.frame.data.clone()), (64, img.clone()));
    // BlackLevelDeltaV raises the second row's black
    let b = Builder::new(false);
    let extra = vec![
        b.short(50714, &[50]),
        b.rational(50716, &[(0, 1), (10, 1)]),
        b.short(50717, &[1000]),
    ];
    let d = decode_dng(&strips_dng(false, &img, w, h, 16, h, extra), &lim()).unwrap();
    assert_eq!(d.black_level, 50);
    assert_eq!(d.frame.data[0], 100);
    let to_50 = |v: f64, b: f64| ((v - b) * (1000.0 - 50.0) / (1000.0 - b) + 50.0).round() as u16;
    assert_eq!(d.frame.data[4], to_50(300.0, 60.0));
}

#[test]
fn linearization_table_and_crops() {
    let (w, h) = (8, 6);
    let img = ramp(w, h, 4); // values 0–15
    let b = Builder::new(true);
    let table: Vec<u16> = (0..10).map(|i| i * 100).collect(); // 10+ → 900
    let extra = vec![
        b.short(50712, &table),
        b.long(50829, &[1, 1, 6, 8]), // 7×5 active area at (1, 1)
        b.long(50719, &[1, 2]),       // crop origin x=1, y=2 in the active area
        b.long(50720, &[4, 3]),
        b.short(50717, &[1000]),
    ];
    let d = decode_dng(&strips_dng(true, &img, w, h, 8, 4, extra), &lim()).unwrap();
    assert_eq!((d.frame.width, d.frame.height), (4, 3));
    for r in 0..3 {
        for c in 0..4 {
            let v = img[(1 + 2 + r) * w + 1 + 1 + c] as usize;
            assert_eq!(d.frame.data[r * 4 + c], table[v.min(9)], "({r}, {c})");
        }
    }
    // the pattern R G / W B from the active area's origin, seen from (x 1, y 2)
    assert_eq!(d.cfa, "GR/BW");
    // crops outside the image
    let b = Builder::new(false);
    let e = decode_dng(
        &strips_dng(false, &img, w, h, 8, 6, vec![b.long(50829, &[0, 0, 7, 8])]),
        &lim(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("ActiveArea") && e.contains("not inside the 8×6"),
        "{e}"
    );
    let e = decode_dng(
        &strips_dng(false, &img, w, h, 8, 6, vec![b.long(50720, &[9, 1])]),
        &lim(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("default crop"), "{e}");
}

#[test]
fn unsupported_content_is_named() {
    let img = ramp(4, 4, 16);
    let b = Builder::new(false);
    let cases: Vec<(Vec<E>, &str)> = vec![
        (
            vec![(33422, 1, 4, vec![3, 1, 4, 5])],
            "colour code 3 (cyan) at row 0, column 0",
        ),
        (
            vec![(50710, 1, 3, vec![0, 1, 2])],
            "CFAPattern uses W, which CFAPlaneColor (RGB) does not list",
        ),
        (vec![b.short(262, &[34892])], "LinearRaw"),
        (
            vec![b.short(259, &[34892])],
            "compression 34892 (lossy JPEG)",
        ),
        (vec![b.short(258, &[32])], "32 bits per sample"),
        (vec![b.short(339, &[3])], "sample format 3"),
        (vec![b.short(277, &[3])], "3 samples per pixel"),
        (vec![b.short(50711, &[2])], "CFALayout 2"),
        (
            vec![b.short(33421, &[17, 2])],
            "CFARepeatPatternDim is 17×2",
        ),
        (vec![b.short(50714, &[7, 1])], "BlackLevel has 2 values"),
        (vec![b.short(50717, &[0])], "WhiteLevel 0"),
        (
            vec![b.short(50714, &[5000]), b.short(50717, &[4000])],
            "black level 5000 is not between 0 and the white level 4000",
        ),
        (
            vec![b.rational(50728, &[(1, 1), (1, 1)])],
            "AsShotNeutral holds",
        ),
    ];
    for (extra, want) in cases {
        let f = strips_dng(false, &img, 4, 4, 16, 4, extra);
        let e = decode_dng(&f, &lim()).unwrap_err().to_string();
        assert!(e.contains(want), "want {want:?}: {e}");
        assert!(e.starts_with("invalid DNG: "), "{e}");
    }
}

/// A CFA image in a TIFF without DNGVersion is no DNG: the TIFF reader refuses it, saying
/// what the file lacks rather than what the TIFF decoder tripped on.
#[test]
fn a_cfa_tiff_without_dng_version_is_named() {
    let img = ramp(4, 4, 16);
    for be in [false, true] {
        let f = strips_dng(be, &img, 4, 4, 16, 4, vec![(50706, 0, 0, vec![])]);
        assert!(!is_dng(&f) && is_cfa_tiff_without_dng_version(&f));
        let e = crate::io::decode_mosaic(&f, &lim())
            .unwrap_err()
            .to_string();
        assert!(e.contains("without DNGVersion (50706)"), "{e}");
    }
    // a DNG, and a grayscale TIFF, are neither
    let dng = strips_dng(false, &img, 4, 4, 16, 4, vec![]);
    assert!(!is_cfa_tiff_without_dng_version(&dng));
    let frame = crate::io::RawFrame {
        width: 4,
        height: 4,
        data: img,
    };
    let gray = crate::io::encode_tiff_gray16(&frame).unwrap();
    assert!(!is_cfa_tiff_without_dng_version(&gray));
}

#[test]
fn hostile_sizes_fail_before_allocating() {
    let img = ramp(4, 4, 16);
    let b = Builder::new(false);
    // a huge declared image
    let f = strips_dng(
        false,
        &img,
        4,
        4,
        16,
        4,
        vec![b.long(256, &[30_000]), b.long(257, &[30_000])],
    );
    let e = decode_dng(&f, &lim()).unwrap_err().to_string();
    assert!(e.contains("at most 150000000 pixels"), "{e}");
    // strips beyond the end of the file
    let f = strips_dng(false, &img, 4, 4, 16, 4, vec![b.long(273, &[1 << 30])]);
    let e = decode_dng(&f, &lim()).unwrap_err().to_string();
    assert!(e.contains("needs 32 bytes at offset"), "{e}");
    // a big image with a few bytes of data
    let f = strips_dng(
        false,
        &img,
        4,
        4,
        16,
        4,
        vec![
            b.long(256, &[9000]),
            b.long(257, &[9000]),
            b.long(278, &[9000]),
        ],
    );
    let e = decode_dng(&f, &lim()).unwrap_err().to_string();
    assert!(e.contains("needs 162000000 bytes at offset"), "{e}");
    // a tall image whose strips all point at the same bytes
    let wide = ramp(64, 2, 16);
    let f = strips_dng(
        false,
        &wide,
        64,
        2,
        16,
        2,
        vec![
            b.long(257, &[1000]),
            b.long(278, &[1]),
            b.long(273, &[8; 1000]),
            b.long(279, &[128; 1000]),
        ],
    );
    let e = decode_dng(&f, &lim()).unwrap_err().to_string();
    assert!(e.contains("more than the file"), "{e}");
    // a strip count that does not match the rows
    let f = strips_dng(false, &img, 4, 4, 16, 1, vec![b.long(278, &[2])]);
    let e = decode_dng(&f, &lim()).unwrap_err().to_string();
    assert!(e.contains("needs 2 strips"), "{e}");
    // huge tiles
    let f = strips_dng(
        false,
        &img,
        4,
        4,
        16,
        4,
        vec![
            b.long(322, &[1 << 20]),
            b.long(323, &[1 << 20]),
            b.long(324, &[8]),
        ],
    );
    let e = decode_dng(&f, &lim()).unwrap_err().to_string();
    assert!(e.contains("a tile of 1048576×1048576"), "{e}");
    // not a DNG at all; truncated anywhere
    assert!(!is_dng(b"II*\0\x08\0\0\0\0\0"));
    let good = strips_dng(false, &img, 4, 4, 16, 4, vec![]);
    // (all but the last IFD's next-IFD offset, which is not read)
    for cut in 0..good.len() - 4 {
        assert!(decode_dng(&good[..cut], &lim()).is_err(), "cut {cut}");
    }
}

#[test]
fn lossless_jpeg_from_pidng() {
    // a third-party LJ92 tile (PiDNG: one component, twice the width, half the height,
    // predictor 6) and the mosaic it holds
    let dng = include_bytes!("../../../tests/fixtures/dng/bayer_12_lj92.dng");
    let raw = include_bytes!("../../../tests/fixtures/dng/bayer_12_lj92.raw");
    let want: Vec<u16> = raw
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    let t = ifd::Tiff::parse(dng).unwrap();
    let ifd0 = t.first_ifd().unwrap();
    let off = t.uint(&ifd0, 324).unwrap().unwrap();
    let len = t.uint(&ifd0, 325).unwrap().unwrap();
    let j = ljpeg::decode(t.slice(off, len).unwrap(), 1 << 20).unwrap();
    assert_eq!(
        (j.width, j.height, j.components, j.precision),
        (64, 12, 1, 12)
    );
    assert_eq!(j.samples, want);
    assert_eq!(decode_dng(dng, &lim()).unwrap().frame.data, want);
}

#[test]
fn written_dng_reads_back() {
    let (w, h) = (6, 4);
    let frame = RawFrame::new(w, h, ramp(w, h, 16)).unwrap();
    let mut meta = RawMeta::new(w, h, "RG/WB", 64, 65535, 1.8);
    meta.sensor = Some("rgbw-paper".into());
    let info = DngWriteInfo {
        camera_model: None,
        as_shot_neutral: Some(vec![
            ("R".into(), 0.3),
            ("G".into(), 0.6),
            ("W".into(), 1.2),
            ("B".into(), 0.24),
        ]),
        calibration_illuminant: exif_light_source("Tungsten"),
        color_matrix: Some(vec![
            ("W".into(), [0.5, 0.75, 0.25]),
            ("R".into(), [1.0, -0.25, 0.0]),
            ("B".into(), [0.0, 0.125, 0.5]),
            ("G".into(), [-0.5, 1.0, 0.0625]),
        ]),
    };
    let bytes = encode_dng(&frame, &meta, &info).unwrap();
    assert!(is_dng(&bytes));
    let d = decode_dng(&bytes, &lim()).unwrap();
    assert_eq!(d.frame, frame);
    assert_eq!(
        (d.cfa.as_str(), d.black_level, d.white_level),
        ("RG/WB", 64, 65535)
    );
    assert_eq!(d.info.plane_colors, "RGBW");
    assert_eq!(d.info.as_shot_neutral, Some(vec![0.25, 0.5, 0.2, 1.0]));
    assert_eq!(d.info.calibration_illuminants, [Some(3), None]);
    // ColorMatrix1 in CFAPlaneColor order (R, G, B, W), signed
    assert_eq!(
        d.info.color_matrices[0],
        Some(vec![
            1.0, -0.25, 0.0, -0.5, 1.0, 0.0625, 0.0, 0.125, 0.5, 0.5, 0.75, 0.25
        ])
    );
    assert_eq!(d.info.unique_camera_model.as_deref(), Some("rgbw-paper"));
    assert_eq!(d.info.version, [1, 4, 0, 0]);
    assert_eq!(d.raw_meta(1.8), {
        let mut m = meta.clone();
        m.sensor = Some("rgbw-paper".into());
        m
    });
    // a Bayer CFA has three planes; letters without a DNG code are refused
    let bayer = RawMeta::new(w, h, "GR/BG", 0, 4095, 1.0);
    let d = decode_dng(
        &encode_dng(&frame, &bayer, &DngWriteInfo::default()).unwrap(),
        &lim(),
    )
    .unwrap();
    assert_eq!(
        (d.cfa.as_str(), d.info.plane_colors.as_str()),
        ("GR/BG", "RGB")
    );
    let cmy = RawMeta::new(w, h, "CY/MG", 0, 4095, 1.0);
    let e = encode_dng(&frame, &cmy, &DngWriteInfo::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("'C' has no DNG colour code"), "{e}");
    // UniqueCameraModel is ASCII
    let mut named = meta.clone();
    named.sensor = Some("caméra\0 2".into());
    let d = decode_dng(
        &encode_dng(&frame, &named, &DngWriteInfo::default()).unwrap(),
        &lim(),
    )
    .unwrap();
    assert_eq!(d.info.unique_camera_model.as_deref(), Some("cam?ra? 2"));
    assert_eq!(exif_light_source("d65"), Some(21));
    assert_eq!(exif_light_source("cct:3200"), None);
}

#[test]
fn make_model_and_the_camera_alone() {
    let (w, h) = (4, 4);
    let img = ramp(w, h, 16);
    let ascii = |tag: u16, s: &[u8]| (tag, 2u16, s.len() as u32, s.to_vec());
    let bytes = strips_dng(
        false,
        &img,
        w,
        h,
        16,
        h,
        vec![
            ascii(271, b"SONY \0\0"),
            ascii(272, b"  ILCE-9\0"),
            ascii(50708, b"Sony ILCE-9\0"),
        ],
    );
    let d = decode_dng(&bytes, &lim()).unwrap();
    assert_eq!(d.info.make.as_deref(), Some("SONY"));
    assert_eq!(d.info.model.as_deref(), Some("ILCE-9"));
    let cam = read_camera(&bytes).unwrap();
    assert_eq!(cam, d.info.camera());
    assert_eq!(cam.unique_camera_model.as_deref(), Some("Sony ILCE-9"));
    // empty names are absent
    let no_make = strips_dng(false, &img, w, h, 16, h, vec![ascii(272, b"\0\0")]);
    let cam = read_camera(&no_make).unwrap();
    assert_eq!(cam, DngCamera::default());
    // not a DNG
    assert!(read_camera(b"II*\0\x08\0\0\0\0\0").is_err());
}
