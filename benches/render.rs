//! Render throughput: a 12 MP RGBW frame → XYZ → sRGB 8-bit with the
//! reference renderer (fused T) and the fast renderer (pooled, new and reused
//! output buffers; AVX-512 and AVX2 kernels), against a plain copy of the same
//! frame measured in the same run; and the conventional baseline (bilinear demosaic + colour
//! matrix → sRGB 8-bit) as separate steps and fused in one pass. Run: `cargo bench --bench render`
//! (`L3_BENCH_TABLE=FILE` renders that table instead of training one;
//! `L3_BENCH_SENSOR=TOML` simulates the frame, and trains the table, on that
//! sensor instead of the default RGBW design, e.g. a Bayer camera).

use std::hint::black_box;
use std::sync::atomic::AtomicBool;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use l3::baseline::{render_baseline, render_baseline_fused_srgb8};
use l3::camera::{Camera, NoiseSwitches, SensorDesign, mosaic};
use l3::l3::correct::IlluminantRegistry;
use l3::l3::learn::{TrainingSpec, train_table};
use l3::l3::render::{
    FastRenderer, Mosaic, WhiteLevel, fuse_kernels, render_reference, xyz_to_srgb8,
};
use l3::scene::{DeadLeavesParams, SceneOptions, dead_leaves};
use l3::spectral::{Extrapolation, WavelengthGrid, ces_reflectances, cie_illuminant};

const W: usize = 4000;
const H: usize = 3000;

fn bench(c: &mut Criterion) {
    let design = match std::env::var_os("L3_BENCH_SENSOR") {
        Some(p) => SensorDesign::load(std::path::Path::new(&p), None).expect("sensor"),
        None => SensorDesign::paper_default(),
    };
    let cancel = AtomicBool::new(false);
    let spec = TrainingSpec {
        illuminants: vec!["D65".into(), "A".into()],
        scenes: 16,
        ..TrainingSpec::default()
    };
    // L3_BENCH_TABLE=path renders a given table instead (to compare tables
    // on the same renderer, e.g. from two trainers)
    let table = match std::env::var_os("L3_BENCH_TABLE") {
        Some(p) => l3::l3::L3Table::load(std::path::Path::new(&p)).expect("load table"),
        None => train_table(&design, &spec, None, &|_, _| {}, &cancel).expect("train"),
    };
    let grid = WavelengthGrid::default();
    let camera = Camera::new(&design, grid, None).expect("camera");
    // a 1000×750 dead-leaves frame under A, tiled to 12 MP
    let a = cie_illuminant("A")
        .expect("A")
        .resample(&grid, Extrapolation::Zero);
    let opts = SceneOptions::new(grid, a, "A").expect("opts");
    let refl: Vec<_> = ces_reflectances()
        .into_iter()
        .map(|(_, s)| s.resample(&grid, Extrapolation::Hold))
        .collect();
    let scene = dead_leaves(&opts, &refl, &DeadLeavesParams::new(750, 1000, 3)).expect("scene");
    let optical = camera.optical_image(&scene).expect("optics");
    let rates = camera.channel_rates(&optical).expect("rates");
    let mean = mosaic(&rates, camera.cfa()).expect("mosaic");
    let t = camera
        .auto_exposure(&rates, camera.cfa(), 0.95)
        .expect("ae");
    let tile = camera
        .capture(&mean, t, &NoiseSwitches::all(), 1)
        .expect("capture");
    let (th, tw) = tile.dim();
    let tile = tile.as_slice().expect("contiguous").to_vec();
    let frame: Vec<f32> = (0..W * H)
        .map(|i| tile[((i / W) % th) * tw + (i % W) % tw])
        .collect();
    let mut reg = IlluminantRegistry::with_defaults(grid, None).expect("registry");
    let kernels = fuse_kernels(&table, &reg.resolve("A", None).expect("A").t);

    let mut g = c.benchmark_group("render_12mp");
    g.sample_size(10);
    g.throughput(Throughput::Elements((W * H) as u64));
    let mut copy = vec![0f32; W * H];
    g.bench_function("plain_copy_f32", |b| {
        b.iter(|| copy.copy_from_slice(black_box(&frame)))
    });
    g.bench_function("l3_reference_to_srgb8", |b| {
        b.iter(|| {
            let (xyz, _) =
                render_reference(&table, &kernels, black_box(&frame), W, H).expect("render");
            black_box(xyz_to_srgb8(&xyz, 1.0))
        })
    });
    let fast = FastRenderer::new(&table, &kernels).expect("fast");
    let dn: Vec<u16> = frame
        .iter()
        .map(|v| (v / design.voltage_swing_v as f32 * 65535.0).round() as u16)
        .collect();
    let (_, st) = fast
        .render_xyz(Mosaic::Volts(&frame), W, H, None)
        .expect("render");
    eprintln!("fast renderer: {st:?}, simd {}", fast.uses_simd());
    let dn_frame = Mosaic::Dn {
        data: &dn,
        black: 0,
        white: 65535,
    };
    // the service's call: the frame's buffer returns to the renderer's pool when dropped
    g.bench_function("l3_fast_u16_to_srgb8_auto_white", |b| {
        b.iter(|| {
            black_box(
                fast.render_srgb8(black_box(dn_frame), W, H, None, WhiteLevel::Auto)
                    .expect("render"),
            )
        })
    });
    // the same, keeping every frame (into_vec): each render faults in 36 MB of new memory
    g.bench_function(
        "l3_fast_u16_to_srgb8_auto_white_new_buffer_each_frame",
        |b| {
            b.iter(|| {
                let (rgb, wy, _) = fast
                    .render_srgb8(black_box(dn_frame), W, H, None, WhiteLevel::Auto)
                    .expect("render");
                black_box((rgb.into_vec(), wy))
            })
        },
    );
    // the same into an output buffer reused from frame to frame (no fresh 36 MB to fault in)
    let mut reused = vec![0u8; W * H * 3];
    g.bench_function("l3_fast_u16_to_srgb8_auto_white_reused_output", |b| {
        b.iter(|| {
            black_box(
                fast.render_srgb8_into(
                    black_box(dn_frame),
                    W,
                    H,
                    None,
                    WhiteLevel::Auto,
                    &mut reused,
                )
                .expect("render"),
            )
        })
    });
    // the same render on the AVX2 + FMA kernels (the "before" of the AVX-512 path)
    let mut avx2 = fast.clone();
    avx2.options.avx512 = false;
    eprintln!("AVX-512 kernels: {}", fast.uses_avx512());
    g.bench_function("l3_fast_avx2_u16_to_srgb8_auto_white", |b| {
        b.iter(|| {
            black_box(
                avx2.render_srgb8(black_box(dn_frame), W, H, None, WhiteLevel::Auto)
                    .expect("render"),
            )
        })
    });
    g.bench_function("l3_fast_f32_to_xyz", |b| {
        b.iter(|| {
            black_box(
                fast.render_xyz(Mosaic::Volts(black_box(&frame)), W, H, None)
                    .expect("render"),
            )
        })
    });
    // the conventional baseline: the straightforward steps one after another (what `l3 bench`
    // timed before) and fused in one pass (what it times now; the same bytes)
    let matrix = l3::eval::fit_baseline_matrix(&camera, &["D65".into()], None).expect("matrix");
    let cfa = camera.cfa();
    g.bench_function("baseline_bilinear_matrix_to_srgb8_stepwise", |b| {
        b.iter(|| {
            let xyz = render_baseline(black_box(&frame), W, H, cfa, &matrix).expect("render");
            black_box(xyz_to_srgb8(&xyz, 1.0))
        })
    });
    g.bench_function("baseline_bilinear_matrix_to_srgb8_fused", |b| {
        b.iter(|| {
            black_box(
                render_baseline_fused_srgb8(black_box(&frame), W, H, cfa, &matrix, 1.0)
                    .expect("render"),
            )
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
