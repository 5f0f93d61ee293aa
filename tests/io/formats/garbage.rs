//! Truncated, corrupted and random input: errors at every cut, and never a panic.

use l3::io::*;
use proptest::prelude::*;

use super::{
    frame, frame8, gray_tags, hand_tiff, lim, pgm_p2, pgm_p5, png_gray8, tiff_with, tiled_tiff,
};

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
