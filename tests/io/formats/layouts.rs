//! Wrong pixel layouts: colour, alpha and integer images, non-finite floats, other formats named.

use l3::io::*;

use super::{err_of, frame8, lim, png_gray8, png_with, tiff_plain};

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
