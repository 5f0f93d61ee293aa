//! `l3 render` to `.jpg`: a JPEG that decodes to the PNG's pixels within the codec's error,
//! carries the sRGB ICC profile, honours `--quality` and `--subsampling`, and refuses a
//! quality outside 1–100.

use crate::support::run_l3;

fn decode(bytes: &[u8]) -> (Vec<u8>, (usize, usize), Option<Vec<u8>>) {
    let mut d = zune_jpeg::JpegDecoder::new(zune_jpeg::zune_core::bytestream::ZCursor::new(bytes));
    let px = d.decode().expect("a JPEG");
    let info = d.info().unwrap();
    (
        px,
        (usize::from(info.width), usize::from(info.height)),
        d.icc_profile(),
    )
}

/// The sampling factors of the first component (luma) in the SOF0 header.
fn luma_sampling(bytes: &[u8]) -> u8 {
    let sof = bytes.windows(2).position(|w| w == [0xff, 0xc0]).unwrap();
    bytes[sof + 11]
}

#[test]
fn render_to_jpeg_with_quality_and_subsampling() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let (ok, out) = run_l3(
        &[
            "simulate", "--scene", "macbeth", "--seed", "5", "--out", "sim",
        ],
        d,
    );
    assert!(ok, "simulate: {out}");
    l3::test_support::tiny_table()
        .save(&d.join("t.safetensors"))
        .unwrap();
    let render = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "render",
            "--table",
            "t.safetensors",
            "--in",
            "sim/mosaic.raw",
            "--out",
            out,
        ];
        args.extend_from_slice(extra);
        run_l3(&args, d)
    };
    for (file, extra) in [
        ("a.png", &[][..]),
        ("a.jpg", &[][..]),
        ("q50.jpeg", &["--quality", "50"][..]),
        ("s444.jpg", &["--subsampling", "444"][..]),
    ] {
        let (ok, out) = render(file, extra);
        assert!(ok, "{file}: {out}");
    }
    let read = |f: &str| std::fs::read(d.join(f)).unwrap();
    let png = image::load_from_memory(&read("a.png")).unwrap().to_rgb8();
    let (jpg, size, icc) = decode(&read("a.jpg"));
    assert_eq!(size, (png.width() as usize, png.height() as usize));
    assert_eq!(icc.as_deref(), Some(l3::io::srgb_profile()));
    let mean = |v: &[u8]| v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
    let (mj, mp) = (mean(&jpg), mean(png.as_raw()));
    assert!((mj - mp).abs() < 2.0, "mean sRGB {mj} vs the PNG's {mp}");
    assert!(read("q50.jpeg").len() < read("a.jpg").len());
    assert_eq!(luma_sampling(&read("a.jpg")), 0x22);
    assert_eq!(luma_sampling(&read("s444.jpg")), 0x11);
    // the same options give the same bytes
    let (ok, out) = render("again.jpg", &[]);
    assert!(ok, "{out}");
    assert_eq!(read("again.jpg"), read("a.jpg"));

    let (ok, out) = render("bad.jpg", &["--quality", "0"]);
    assert!(
        !ok && out.contains("expected an integer from 1 to 100"),
        "{out}"
    );
    let (ok, out) = render("bad.jpg", &["--subsampling", "411"]);
    assert!(!ok && out.contains("expected 420, 422 or 444"), "{out}");
    assert!(!d.join("bad.jpg").exists());
}
