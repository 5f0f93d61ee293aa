//! The encoder against an independent decoder (zune-jpeg): sizes that are not whole MCUs,
//! every subsampling, the strips, the byte stuffing.

use proptest::prelude::*;

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
    let mut d = zune_jpeg::JpegDecoder::new(zune_jpeg::zune_core::bytestream::ZCursor::new(bytes));
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
        let whole = encode(&rgb, w as u16, h as u16, opts, false).unwrap();
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

/// Uniform noise: the worst case for the coder (every coefficient nonzero at quality 100, so
/// every bit pattern, `0xFF` bytes included, turns up in the scan).
fn noise(w: usize, h: usize, seed: u32) -> Vec<u8> {
    let mut s = seed;
    (0..w * h * 3)
        .map(|_| {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (s >> 24) as u8
        })
        .collect()
}

/// A smooth image at every size: neighbouring pixels differ by a few codes, so chroma
/// subsampling loses little and what is lost is the coder's.
fn smooth(w: usize, h: usize) -> Vec<u8> {
    let tri = |v: usize| (v % 128).abs_diff(64);
    (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w, i / w);
            [
                (60 + 2 * tri(x)) as u8,
                (50 + 2 * tri(y)) as u8,
                (100 + tri(x + y)) as u8,
            ]
        })
        .collect()
}

fn opts(q: u32, subsampling: Subsampling) -> JpegOptions {
    JpegOptions {
        quality: JpegQuality::new(q).unwrap(),
        subsampling,
    }
}

/// Peak signal-to-noise ratio (dB) and the largest difference of two 8-bit images.
fn psnr_max(a: &[u8], b: &[u8]) -> (f64, u8) {
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    let max = a
        .iter()
        .zip(b)
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap_or(0);
    (10.0 * (255.0f64.powi(2) / mse.max(1e-12)).log10(), max)
}

fn round_trip(rgb: &[u8], w: usize, h: usize, o: JpegOptions) -> (f64, u8) {
    let bytes = encode_jpeg_rgb8(w, h, rgb, o).unwrap();
    let (px, dw, dh, _) = decode(&bytes);
    assert_eq!((dw, dh), (w, h));
    psnr_max(&px, rgb)
}

const ALL: [Subsampling; 3] = [Subsampling::S420, Subsampling::S422, Subsampling::S444];

/// A smooth image survives every subsampling at quality 90 and 100, at sizes that leave
/// partial MCUs (and a frame of several strips); noise at 4:4:4, quality 100, comes back
/// within the decoder's rounding.
#[test]
fn decodes_close_to_the_input() {
    for (w, h) in [
        (1, 1),
        (7, 5),
        (17, 33),
        (33, 17),
        (200, 2 * STRIP_ROWS + 37),
    ] {
        let rgb = smooth(w, h);
        for s in ALL {
            let (p90, _) = round_trip(&rgb, w, h, opts(90, s));
            let (p100, max100) = round_trip(&rgb, w, h, opts(100, s));
            assert!(p90 > 30.0, "{w}×{h} {s} q90: {p90:.1} dB");
            assert!(p100 >= p90 && p100 > 36.0, "{w}×{h} {s} q100: {p100:.1} dB");
            if s == Subsampling::S444 {
                assert!(max100 <= 8, "{w}×{h} q100 4:4:4: off by {max100}");
            }
        }
        let (p, max) = round_trip(&noise(w, h, 3), w, h, opts(100, Subsampling::S444));
        assert!(
            p > 45.0 && max <= 6,
            "{w}×{h} noise: {p:.1} dB, off by {max}"
        );
    }
}

#[test]
fn a_frame_of_the_service_size_round_trips() {
    let (w, h) = (1600, 1250);
    let rgb = frame(w, h);
    let (p, _) = round_trip(&rgb, w, h, JpegOptions::default());
    assert!(p > 30.0, "{p:.1} dB");
}

/// `0xFF` bytes in the scan are followed by a stuffed zero, and the decoder reads them.
#[test]
fn ff_bytes_in_the_scan_are_stuffed() {
    let (w, h) = (64, 48);
    let rgb = noise(w, h, 11);
    let bytes = encode_jpeg_rgb8(w, h, &rgb, opts(100, Subsampling::S444)).unwrap();
    let sos = bytes.windows(2).rposition(|m| m == [0xff, 0xda]).unwrap();
    let scan = &bytes[sos + 14..bytes.len() - 2];
    let ffs: Vec<u8> = scan
        .windows(2)
        .filter(|m| m[0] == 0xff)
        .map(|m| m[1])
        .collect();
    assert!(!ffs.is_empty(), "no 0xFF byte to stuff");
    assert!(ffs.iter().all(|&b| b == 0), "an unstuffed 0xFF: {ffs:?}");
    let (p, max) = psnr_max(&decode(&bytes).0, &rgb);
    assert!(p > 45.0 && max <= 6, "{p:.1} dB, off by {max}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Any size up to a few MCUs, any subsampling and quality: the decoder reads the file at
    /// its size, close to the input.
    #[test]
    fn any_size_round_trips(
        w in 1usize..70,
        h in 1usize..70,
        s in 0usize..3,
        q in 75u32..=100,
    ) {
        let rgb = smooth(w, h);
        let (p, _) = round_trip(&rgb, w, h, opts(q, ALL[s]));
        prop_assert!(p > 28.0, "{}×{} {} q{}: {:.1} dB", w, h, ALL[s], q, p);
    }
}
