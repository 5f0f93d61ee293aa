//! Wrong sizes and limits: exact length errors, and huge declared sizes refused before allocating.

use l3::io::*;

use super::{
    err_of, frame, frame8, gray_tags, hand_tiff, lim, meta, patch_png_size, patch_tag_le,
    peak_bytes, pgm_p5, png_gray8,
};

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
        ("png over limit", png_over_limit, "at most 150000000 pixels"),
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
