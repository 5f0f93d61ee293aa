//! Round trips of every writer/reader pair of `l3::io`, and writers that leave no temporary files.

use std::path::Path;

use l3::io::*;

use super::{
    err_of, frame, frame8, gray_tags, hand_tiff, lim, meta, pgm_p2, pgm_p5, png_gray8, tiff_plain,
    tiff_with, tiled_tiff, u16_of,
};

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
