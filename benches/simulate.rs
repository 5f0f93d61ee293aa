//! Camera simulator throughput: a 512×512, 31-band scene through the optics,
//! the channel rates and a full-noise capture; and the capture alone.
//!
//! Run: `cargo bench --bench simulate -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use l3::camera::{Camera, NoiseSwitches, SensorDesign, mosaic};
use l3::scene::Scene;
use l3::spectral::{Extrapolation, WavelengthGrid, ces_reflectances, cie_illuminant};
use ndarray::{Array2, Array3};

const SIZE: usize = 512;

/// A 512×512 chart of 16×16-pixel patches of the CIE CES reflectances.
fn scene() -> Scene {
    let grid = WavelengthGrid::default();
    let ces: Vec<Vec<f64>> = ces_reflectances()
        .into_iter()
        .map(|(_, s)| s.resample(&grid, Extrapolation::Hold).into_values())
        .collect();
    let reflectance = Array3::from_shape_fn((grid.n, SIZE, SIZE), |(b, r, c)| {
        ces[((r / 16) * 31 + c / 16) % ces.len()][b] as f32
    });
    Scene {
        name: "ces-chart".into(),
        grid,
        reflectance,
        illuminant: cie_illuminant("D65")
            .expect("D65 is built in")
            .resample(&grid, Extrapolation::Zero),
        illuminant_name: "D65".into(),
        mean_luminance: 100.0,
        fov_deg: 10.0,
        patches: vec![],
    }
}

fn bench(c: &mut Criterion) {
    let cam = Camera::new(
        &SensorDesign::paper_default(),
        WavelengthGrid::default(),
        None,
    )
    .expect("the paper's design is valid");
    let scene = scene();
    let noise = NoiseSwitches::all();
    let t = 0.01;

    let mut g = c.benchmark_group("simulate_512x512_31bands");
    g.sample_size(10);
    g.bench_function("optics", |b| {
        b.iter(|| black_box(cam.optical_image(black_box(&scene)).expect("optics")))
    });
    let optical = cam.optical_image(&scene).expect("optics");
    g.bench_function("channel_rates", |b| {
        b.iter(|| black_box(cam.channel_rates(black_box(&optical)).expect("rates")))
    });
    let rates = cam.channel_rates(&optical).expect("rates");
    let mean = mosaic(&rates, cam.cfa()).expect("mosaic");
    let mut out = Array2::zeros((SIZE, SIZE));
    g.bench_function("capture_full_noise", |b| {
        let mut seed = 0;
        b.iter(|| {
            seed += 1;
            cam.capture_into(mean.view(), t, &noise, seed, &mut out)
                .expect("capture");
            black_box(&out);
        })
    });
    g.bench_function("optics_rates_capture", |b| {
        let mut seed = 0;
        b.iter(|| {
            seed += 1;
            let optical = cam.optical_image(&scene).expect("optics");
            let rates = cam.channel_rates(&optical).expect("rates");
            let mean = mosaic(&rates, cam.cfa()).expect("mosaic");
            black_box(cam.capture(&mean, t, &noise, seed).expect("capture"))
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
