//! End-to-end tests of the L3 core on synthetic sensors (no optics): a
//! linear 4-channel sensor viewing blocky scenes.

use std::sync::atomic::AtomicBool;

use super::classify::ChromaClasses;
use super::correct::{IDENTITY, IlluminantEntry, Mat3};
use super::render::{
    FastRenderer, Mosaic, Region, RenderError, WhiteLevel, fuse_entry, fuse_kernels,
    render_reference, render_reference_under, white_y, xyz_to_srgb8,
};
use super::{L3Params, L3Table};
use crate::baseline::ColourMatrix;
use crate::test_support::{synthetic_frame_with_blocks, train_synthetic_table};

/// Block size of the synthetic scenes (the crate's one fixture, [`crate::test_support`]).
const BLOCK: usize = 12;

fn train_synthetic(noise: f32) -> L3Table {
    train_synthetic_with(noise, None)
}

/// Three chroma classes of the synthetic sensor's `R G W B` responses.
fn synthetic_chroma() -> ChromaClasses {
    ChromaClasses {
        centroids: vec![
            vec![0.4, 0.15, 0.35, 0.1],
            vec![0.1, 0.3, 0.3, 0.3],
            vec![0.2, 0.25, 0.35, 0.2],
        ],
        white: Some(vec![1.0; 4]),
    }
}

fn train_synthetic_with(noise: f32, chroma: Option<ChromaClasses>) -> L3Table {
    let params = L3Params {
        levels: L3Params::levels_for(8, 1.8).unwrap(),
        min_class_samples: 60,
        chroma,
        ..L3Params::default()
    };
    train_synthetic_table(&params, 48, |i| {
        let scale = [0.01f32, 0.05, 0.2, 0.8, 1.5][i % 5];
        let shift = ((i / 5) % 2, (i / 10) % 2);
        Ok(vec![synthetic_frame_with_blocks(
            i as u64, 48, BLOCK, scale, noise, shift,
        )])
    })
    .unwrap()
}

#[test]
fn learns_a_linear_sensor_and_renders_block_interiors() {
    let table = train_synthetic(0.0);
    let f = synthetic_frame_with_blocks(999, 48, BLOCK, 0.5, 0.0, (0, 0));
    let (xyz, stats) = render_reference(&table, &table.kernels, &f.volts, 48, 48).unwrap();
    assert_eq!(stats.pixels, 48 * 48);
    // interior pixels of blocks (2 px from block edges) are recovered closely
    let mut worst = 0f32;
    for r in 0..48 {
        for c in 0..48 {
            if (2..10).contains(&(r % 12)) && (2..10).contains(&(c % 12)) {
                for k in 0..3 {
                    let i = (r * 48 + c) * 3 + k;
                    worst = worst.max((xyz[i] - f.xyz[i]).abs());
                }
            }
        }
    }
    assert!(worst < 0.002, "worst interior error {worst}");
    assert!(xyz.iter().all(|v| v.is_finite()));
}

#[test]
fn fused_correction_equals_correction_after_rendering() {
    let table = train_synthetic(0.01);
    let t = [[1.1, 0.05, -0.1], [0.02, 0.98, 0.01], [-0.03, 0.04, 1.4]];
    let fused = fuse_kernels(&table, &t);
    let f = synthetic_frame_with_blocks(5, 32, BLOCK, 0.4, 0.01, (1, 0));
    let (a, _) = render_reference(&table, &table.kernels, &f.volts, 32, 32).unwrap();
    let (b, _) = render_reference(&table, &fused, &f.volts, 32, 32).unwrap();
    for (pa, pb) in a.chunks_exact(3).zip(b.chunks_exact(3)) {
        for i in 0..3 {
            let want: f32 = (0..3).map(|k| t[i][k] as f32 * pa[k]).sum();
            assert!((want - pb[i]).abs() < 1e-4 * (1.0 + want.abs()));
        }
    }
}

#[test]
fn per_level_corrections_fuse_each_class_with_its_levels_matrix() {
    let table = train_synthetic(0.01);
    let nl = table.n_levels();
    let per_level: Vec<Mat3> = (0..nl)
        .map(|l| {
            let s = 1.0 + 0.1 * l as f64;
            [
                [s, 0.02, 0.0],
                [0.0, 1.0, 0.03 * s],
                [-0.01, 0.0, 2.0 - 0.05 * l as f64],
            ]
        })
        .collect();
    let t = [[1.1, 0.05, -0.1], [0.02, 0.98, 0.01], [-0.03, 0.04, 1.4]];
    let mut entry = IlluminantEntry::from_matrix("test", t);
    // without per-level corrections: T everywhere
    assert_eq!(
        fuse_entry(&table, &entry).unwrap(),
        fuse_kernels(&table, &t)
    );
    // a list that does not match the table's levels is not used
    entry.level_corrections = per_level[..nl - 1].to_vec();
    assert_eq!(
        fuse_entry(&table, &entry).unwrap(),
        fuse_kernels(&table, &t)
    );
    entry.level_corrections = per_level.clone();
    let fused = fuse_entry(&table, &entry).unwrap();
    let nf = table.n_features();
    for pos in 0..table.n_positions() {
        for (level, m) in per_level.iter().enumerate() {
            for sat in 0..table.n_sat_cases() {
                for texture in [false, true] {
                    let c = table.class_index(pos, level, sat, texture);
                    assert_eq!(table.class_level(c), level);
                    let k = table.kernel(c);
                    let got = &fused[c * 3 * nf..(c + 1) * 3 * nf];
                    for i in 0..3 {
                        for j in 0..nf {
                            let want: f64 =
                                (0..3).map(|q| m[i][q] * f64::from(k[q * nf + j])).sum();
                            assert!(
                                (f64::from(got[i * nf + j]) - want).abs()
                                    < 1e-5 * (1.0 + want.abs()),
                                "class {c} (level {level}) row {i} weight {j}"
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn table_round_trips_and_rejects_corruption() {
    let table = train_synthetic(0.005);
    let bytes = table.to_bytes().unwrap();
    let back = L3Table::from_bytes(&bytes, "mem").unwrap();
    assert_eq!(back.kernels, table.kernels);
    assert_eq!(back.meta, table.meta);
    assert_eq!(back.reports, table.reports);
    // flip one byte near the end (kernel data region)
    let mut bad = bytes.clone();
    let n = bad.len();
    bad[n - 10] ^= 0x55;
    let e = L3Table::from_bytes(&bad, "mem").unwrap_err().to_string();
    assert!(e.contains("checksum") || e.contains("corrupt"), "{e}");
    // truncated
    assert!(L3Table::from_bytes(&bytes[..bytes.len() / 2], "mem").is_err());
    assert!(L3Table::from_bytes(b"garbage", "mem").is_err());
    // non-finite kernels are refused on save
    let mut nan = table.clone();
    nan.kernels[3] = f32::NAN;
    assert!(nan.to_bytes().is_err());
    // file round trip
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.safetensors");
    table.save(&p).unwrap();
    assert_eq!(L3Table::load(&p).unwrap().kernels, table.kernels);
}

#[test]
fn hostile_render_inputs_are_errors_or_clamped() {
    let table = train_synthetic(0.0);
    let k = &table.kernels;
    assert!(render_reference(&table, k, &[0.1; 10], 4, 4).is_err());
    assert!(render_reference(&table, k, &[], 0, 0).is_err());
    let mut v = vec![0.3f32; 16];
    v[5] = f32::NAN;
    assert!(render_reference(&table, k, &v, 4, 4).is_err());
    v[5] = -3.0;
    v[6] = 99.0;
    let (out, st) = render_reference(&table, k, &v, 4, 4).unwrap();
    assert_eq!(st.clamped, 2);
    assert!(out.iter().all(|x| x.is_finite()));
    // tiny frames
    for (w, h) in [(1, 1), (1, 7), (3, 1), (5, 3)] {
        let (o, _) = render_reference(&table, k, &vec![0.2; w * h], w, h).unwrap();
        assert_eq!(o.len(), w * h * 3);
        assert!(o.iter().all(|x| x.is_finite()));
    }
}

/// Max |a − b| over two equally long slices.
fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn fast_renderer_matches_the_reference() {
    let table = train_synthetic(0.01);
    let t = [[1.1, 0.05, -0.1], [0.02, 0.98, 0.01], [-0.03, 0.04, 1.4]];
    let fused = fuse_kernels(&table, &t);
    // blocks from dark to clipped, plus noise: every level and saturated patches
    let mut f = synthetic_frame_with_blocks(11, 96, BLOCK, 1.6, 0.02, (0, 0));
    f.volts[40 * 96 + 40] = 1.8;
    for (simd, avx512) in [(true, true), (true, false), (false, false)] {
        for kernels in [&table.kernels, &fused] {
            let mut fast = FastRenderer::new(&table, kernels).unwrap();
            fast.options.simd = simd;
            fast.options.avx512 = avx512;
            for (w, h) in [(96, 96), (95, 61), (1, 1), (1, 9), (7, 1), (2, 3), (13, 5)] {
                let v: Vec<f32> = f.volts[..w * h].to_vec();
                let (want, ws) = render_reference(&table, kernels, &v, w, h).unwrap();
                let (got, gs) = fast.render_xyz(Mosaic::Volts(&v), w, h, None).unwrap();
                let d = max_abs_diff(&want, &got);
                assert!(d <= 1e-5, "{w}×{h} simd {simd}: max diff {d}");
                assert_eq!(
                    (ws.pixels, ws.saturated, ws.fallback),
                    (gs.pixels, gs.saturated, gs.fallback)
                );
            }
            // a region equals the crop of the whole frame
            let (all, _) = fast
                .render_xyz(Mosaic::Volts(&f.volts), 96, 96, None)
                .unwrap();
            let reg = Region {
                x: 7,
                y: 30,
                width: 41,
                height: 19,
            };
            let (part, _) = fast
                .render_xyz(Mosaic::Volts(&f.volts), 96, 96, Some(reg))
                .unwrap();
            for y in 0..reg.height {
                let a = &all
                    [((reg.y + y) * 96 + reg.x) * 3..((reg.y + y) * 96 + reg.x + reg.width) * 3];
                assert_eq!(a, &part[y * reg.width * 3..(y + 1) * reg.width * 3]);
            }
        }
    }
}

#[test]
fn fast_srgb_and_dn_input_match_the_reference_pipeline() {
    let table = train_synthetic(0.01);
    let f = synthetic_frame_with_blocks(12, 64, BLOCK, 1.2, 0.01, (1, 1));
    let dn: Vec<u16> = f
        .volts
        .iter()
        .map(|v| (v / 1.8 * 4095.0).round() as u16 + 64)
        .collect();
    let volts: Vec<f32> = dn
        .iter()
        .map(|&d| ((f64::from(d) - 64.0) * 1.8 / (4159.0 - 64.0)).clamp(0.0, 1.8) as f32)
        .collect();
    let fast = FastRenderer::new(&table, &table.kernels).unwrap();
    let (want, _) = render_reference(&table, &table.kernels, &volts, 64, 64).unwrap();
    let (got, _) = fast
        .render_xyz(
            Mosaic::Dn {
                data: &dn,
                black: 64,
                white: 4159,
            },
            64,
            64,
            None,
        )
        .unwrap();
    assert!(max_abs_diff(&want, &got) <= 1e-5);
    let wy = white_y(&want, 64, 64, WhiteLevel::Auto);
    let srgb_ref = xyz_to_srgb8(&want, wy);
    let (srgb, wy_fast, _) = fast
        .render_srgb8(Mosaic::Volts(&volts), 64, 64, None, WhiteLevel::Auto)
        .unwrap();
    assert!((wy - wy_fast).abs() <= 1e-5 * wy, "{wy} {wy_fast}");
    let off = srgb.iter().zip(&srgb_ref).filter(|(a, b)| a != b).count();
    let worst = srgb
        .iter()
        .zip(&srgb_ref)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(
        worst <= 1 && off * 100 <= srgb.len(),
        "{off} codes differ, worst {worst}"
    );
    // errors
    assert!(
        fast.render_xyz(Mosaic::Volts(&volts[..10]), 64, 64, None)
            .is_err()
    );
    let bad = Region {
        x: 60,
        y: 0,
        width: 8,
        height: 8,
    };
    assert!(
        fast.render_xyz(Mosaic::Volts(&volts), 64, 64, Some(bad))
            .is_err()
    );
    let mut nan = volts.clone();
    nan[100] = f32::NAN;
    assert!(fast.render_xyz(Mosaic::Volts(&nan), 64, 64, None).is_err());
    assert!(
        fast.render_xyz(
            Mosaic::Dn {
                data: &dn,
                black: 9,
                white: 9
            },
            64,
            64,
            None
        )
        .is_err()
    );
}

#[test]
fn a_canceled_render_stops_with_render_canceled() {
    let table = train_synthetic(0.01);
    let f = synthetic_frame_with_blocks(13, 64, BLOCK, 1.0, 0.01, (0, 0));
    let fast = FastRenderer::new(&table, &table.kernels).unwrap();
    let frame = Mosaic::Volts(&f.volts);
    let go = AtomicBool::new(false);
    let stop = AtomicBool::new(true);
    assert!(fast.render_xyz_until(frame, 64, 64, None, &go).is_ok());
    assert!(matches!(
        fast.render_xyz_until(frame, 64, 64, None, &stop),
        Err(RenderError::RenderCanceled)
    ));
    assert!(matches!(
        fast.render_srgb8_until(frame, 64, 64, None, WhiteLevel::Auto, &stop),
        Err(RenderError::RenderCanceled)
    ));
}

#[test]
fn a_chroma_split_table_learns_round_trips_and_renders_fast_as_the_reference() {
    let table = train_synthetic_with(0.0, Some(synthetic_chroma()));
    assert_eq!((table.n_chroma(), table.n_bands()), (3, 24));
    assert_eq!(table.n_classes(), 4 * 24 * table.n_sat_cases() * 2);
    // a linear sensor: every chroma class renders block interiors closely
    let f = synthetic_frame_with_blocks(999, 48, BLOCK, 0.5, 0.0, (0, 0));
    let (xyz, _) = render_reference(&table, &table.kernels, &f.volts, 48, 48).unwrap();
    let mut worst = 0f32;
    for r in (0..48).filter(|r| (2..10).contains(&(r % 12))) {
        for c in (0..48).filter(|c| (2..10).contains(&(c % 12))) {
            for k in 0..3 {
                let i = (r * 48 + c) * 3 + k;
                worst = worst.max((xyz[i] - f.xyz[i]).abs());
            }
        }
    }
    assert!(worst < 0.002, "worst interior error {worst}");
    // the pixels of the frame fall in more than one chroma class
    let geo = table.geometry().unwrap();
    let mut seen = std::collections::BTreeSet::new();
    let mut patch = vec![0f32; 25];
    for r in 0..48 {
        for c in 0..48 {
            geo.gather(&f.volts, 48, 48, r, c, &mut patch);
            let s = geo.stats(&patch, geo.position(r, c));
            seen.insert(geo.band_of(s.luminance, &s.channel_means) % 3);
        }
    }
    assert!(seen.len() > 1, "one chroma class only: {seen:?}");
    // the chroma classes are part of the file
    let back = L3Table::from_bytes(&table.to_bytes().unwrap(), "mem").unwrap();
    assert_eq!(back.meta, table.meta);
    assert_eq!(back.kernels, table.kernels);
    // the fast renderer classifies chroma as the reference does
    let noisy = train_synthetic_with(0.01, Some(synthetic_chroma()));
    let mut g = synthetic_frame_with_blocks(11, 96, BLOCK, 1.2, 0.02, (0, 0));
    g.volts[40 * 96 + 40] = 1.8;
    // under the reference light and under another one, whose neutral moves
    // pixels between classes
    let lamp = [1.0, 0.7, 0.9, 0.45];
    let mut outputs = Vec::new();
    for light in [None, Some(&lamp[..])] {
        // AVX-512 kernels (where the CPU has them), AVX2, portable
        for (simd, avx512) in [(true, true), (true, false), (false, false)] {
            let mut fast = FastRenderer::under_light(&noisy, &noisy.kernels, light).unwrap();
            fast.options.simd = simd;
            fast.options.avx512 = avx512;
            let (want, ws) =
                render_reference_under(&noisy, &noisy.kernels, light, &g.volts, 96, 96).unwrap();
            let (got, gs) = fast
                .render_xyz(Mosaic::Volts(&g.volts), 96, 96, None)
                .unwrap();
            let d = max_abs_diff(&want, &got);
            assert!(
                d <= 1e-5,
                "light {light:?}, simd {simd}, avx512 {avx512}: max diff {d}"
            );
            assert_eq!((ws.pixels, ws.texture), (gs.pixels, gs.texture));
            assert!(gs.exact_path < gs.pixels / 4, "{gs:?}");
            outputs.push(want);
        }
    }
    assert!(
        max_abs_diff(&outputs[0], &outputs[3]) > 1e-3,
        "the light changed nothing"
    );
    // a dark frame (about 1 mV): the chroma margin scales with the signal, so its pixels
    // stay on the fast path, and agree with the reference
    let dark: Vec<f32> = g.volts.iter().map(|v| v * 1e-3).collect();
    let fast = FastRenderer::new(&noisy, &noisy.kernels).unwrap();
    let (want, _) = render_reference(&noisy, &noisy.kernels, &dark, 96, 96).unwrap();
    let (got, gs) = fast.render_xyz(Mosaic::Volts(&dark), 96, 96, None).unwrap();
    let d = max_abs_diff(&want, &got);
    assert!(d <= 1e-6, "dark frame: max diff {d}");
    assert!(gs.exact_path < gs.pixels / 10, "dark frame: {gs:?}");
}

#[test]
fn saturated_cases_share_their_samples_across_chroma_classes() {
    let table = train_synthetic_with(0.01, Some(synthetic_chroma()));
    let nf = table.n_features();
    let mut checked = 0;
    for pos in 0..table.n_positions() {
        for level in 0..table.n_levels() {
            for sat in 1..table.n_sat_cases() {
                let first = table.kernel(table.class_index(pos, level * 3, sat, false));
                for k in 1..3 {
                    let other = table.kernel(table.class_index(pos, level * 3 + k, sat, false));
                    assert_eq!(first, other, "position {pos}, level {level}, case {sat}");
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 0 || table.n_sat_cases() == 1);
    assert_eq!(table.kernels.len() % (3 * nf), 0);
}

#[test]
fn per_band_corrections_fuse_each_class_with_its_bands_matrix() {
    let table = train_synthetic_with(0.01, Some(synthetic_chroma()));
    let nb = table.n_bands();
    let per_band: Vec<Mat3> = (0..nb)
        .map(|b| {
            let s = 1.0 + 0.05 * b as f64;
            [[s, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0 - s * 0.1]]
        })
        .collect();
    let entry = IlluminantEntry {
        level_corrections: per_band.clone(),
        ..IlluminantEntry::from_matrix("test", IDENTITY)
    };
    let fused = fuse_entry(&table, &entry).unwrap();
    let nf = table.n_features();
    let per_class = 2 * table.n_sat_cases();
    for class in [0, per_class * 4 + 1, table.n_classes() - 1] {
        let band = table.class_band(class);
        assert_eq!(table.class_level(class), band / 3);
        let m = &per_band[band];
        let k = table.kernel(class);
        let got = &fused[class * 3 * nf..(class + 1) * 3 * nf];
        for i in 0..3 {
            for j in 0..nf {
                let want: f64 = (0..3).map(|r| m[i][r] * f64::from(k[r * nf + j])).sum();
                assert!((f64::from(got[i * nf + j]) - want).abs() < 1e-5);
            }
        }
    }
}

#[test]
fn transfer_kernels_carry_the_pooled_maps_to_a_light_the_table_was_not_trained_on() {
    let mut table = train_synthetic_with(0.01, Some(synthetic_chroma()));
    let t = [[1.1, 0.05, -0.1], [0.02, 0.98, 0.01], [-0.03, 0.04, 1.4]];
    let mut entry = IlluminantEntry::from_matrix("Lamp", t);
    // without transfer maps every light gets the table's own kernels
    assert!(table.transfer_kernels().unwrap().is_none());
    assert!(!table.transfers_to("Lamp"));
    assert_eq!(
        fuse_entry(&table, &entry).unwrap(),
        fuse_kernels(&table, &t)
    );
    // maps that differ from every class's own: class 0's, scaled
    let maps: Vec<ColourMatrix> = (0..table.n_levels())
        .map(|l| {
            let mut m = table.colour_map_at(l * 3).unwrap();
            m.m.iter_mut().flatten().for_each(|v| *v *= 1.1);
            m
        })
        .collect();
    table.meta.params.transfer_maps = Some(maps.clone());
    table.validate().unwrap();
    let moved_kernels = table.transfer_kernels().unwrap().unwrap();
    let mut moved = table.clone();
    moved.kernels = moved_kernels.clone();
    let geo = table.geometry().unwrap();
    let nf = table.n_features();
    for band in 0..table.n_bands() {
        // on a uniform patch every chroma class applies its level's map
        let got = moved.colour_map_at(band).unwrap();
        for (g, w) in got
            .m
            .iter()
            .flatten()
            .zip(maps[band / 3].m.iter().flatten())
        {
            assert!((g - w).abs() < 1e-5, "band {band}: {g} against {w}");
        }
        for pos in 0..table.n_positions() {
            for sat in 0..table.n_sat_cases() {
                for texture in [false, true] {
                    let class = table.class_index(pos, band, sat, texture);
                    let (old, new) = (table.kernel(class), moved.kernel(class));
                    if sat > 0 {
                        assert_eq!(old, new, "a saturated case moved");
                        continue;
                    }
                    for k in 0..3 {
                        // the intercept stays, and so does each channel's spatial shape:
                        // one step per channel
                        assert_eq!(old[k * nf + nf - 1], new[k * nf + nf - 1]);
                        let mut step = vec![None; geo.n_channels()];
                        for (j, &c) in geo.channels_of(pos).iter().enumerate() {
                            let d = new[k * nf + j] - old[k * nf + j];
                            let s = step[c as usize].get_or_insert(d);
                            assert!((*s - d).abs() < 1e-5, "class {class}: {s} against {d}");
                        }
                    }
                }
            }
        }
    }
    // a light the table was not trained on, through T: the transfer kernels
    assert!(table.transfers_to("Lamp"));
    assert_eq!(
        fuse_entry(&table, &entry).unwrap(),
        fuse_kernels(&moved, &t)
    );
    // its own light (named in any case): its own kernels
    entry.name = "SYNTHETIC".into();
    assert!(table.trained_under("SYNTHETIC") && !table.transfers_to("SYNTHETIC"));
    assert_eq!(
        fuse_entry(&table, &entry).unwrap(),
        fuse_kernels(&table, &t)
    );
    // another light registered under the training light's name, with another white, is
    // not the table's own: the transfer kernels
    let own = [0.4476, 0.4074];
    table.meta.train_white_xy = vec![own];
    entry.white_xy = Some([own[0] + 0.02, own[1]]);
    assert!(table.transfers_to_light("SYNTHETIC", entry.white_xy));
    assert_eq!(
        fuse_entry(&table, &entry).unwrap(),
        fuse_kernels(&moved, &t)
    );
    entry.white_xy = Some(own);
    assert!(!table.transfers_to_light("SYNTHETIC", entry.white_xy));
    // a table that did not record its whites (older files) goes by the name
    table.meta.train_white_xy.clear();
    entry.white_xy = Some([own[0] + 0.02, own[1]]);
    assert!(!table.transfers_to_light("SYNTHETIC", entry.white_xy));
    // a correction fitted per band on the table (C) keeps the class kernels
    entry.name = "Lamp".into();
    entry.level_corrections = vec![t; table.n_bands()];
    assert_eq!(
        fuse_entry(&table, &entry).unwrap(),
        fuse_kernels(&table, &t)
    );
    // the maps are part of the file, and checked on load
    let back = L3Table::from_bytes(&table.to_bytes().unwrap(), "mem").unwrap();
    assert_eq!(back.meta.params.transfer_maps, Some(maps.clone()));
    let mut short = table.clone();
    short.meta.params.transfer_maps = Some(maps[1..].to_vec());
    assert!(short.validate().is_err());
    let mut nan = table.clone();
    nan.meta.params.transfer_maps = Some(maps);
    if let Some(m) = nan.meta.params.transfer_maps.as_mut() {
        m[0].m[0][0] = f64::NAN;
    }
    assert!(nan.validate().is_err());
}
