//! Unit tests of [`super`].

use super::*;

#[test]
fn a_same_illuminant_tables_matching_map_aims_through_t_only_under_its_own_lights() {
    let camera = crate::test_support::paper_camera();
    let mut table = crate::test_support::tiny_table().clone();
    table.meta.kind = TableKind::SameIlluminant;
    table.meta.train_illuminants = vec!["Tungsten".into()];
    // a table that keeps maps for other lights (what the trainer gives an SI table)
    table.meta.params.transfer_maps = Some(Vec::new());
    let own = matching_linear_map(&camera, &table, "tungsten", None).unwrap();
    let foreign = matching_linear_map(&camera, &table, "Fluorescent", None).unwrap();
    let t = crate::l3::correct::IlluminantRegistry::with_defaults(*camera.grid(), None)
        .unwrap()
        .resolve("Tungsten", None)
        .unwrap()
        .t;
    let ills = ["Tungsten".to_string()];
    let fit = |kind, through_correction| {
        let f = ColourFit {
            illuminants: &ills,
            kind,
            channels: ChannelSet::All,
            preserve_white: false,
            through_correction,
        };
        fit_colour_matrix(&camera, &f, None).unwrap()
    };
    // under its own light: the map that T takes to the cross map
    let cross = fit(TableKind::CrossIlluminant, false);
    for (a, b) in own.then(&t).m.iter().zip(&cross.m) {
        for k in 0..3 {
            assert!(
                (a[k] - b[k]).abs() < 1e-6 * (1.0 + b[k].abs()),
                "{a:?} {b:?}"
            );
        }
    }
    // under another light: the paper's map, XYZ under the light
    let plain = fit(TableKind::SameIlluminant, false);
    assert_eq!(foreign.m, plain.m);
    assert_ne!(own.m, plain.m);
    // a table without maps for other lights aims through T everywhere
    table.meta.params.transfer_maps = None;
    let old = matching_linear_map(&camera, &table, "Fluorescent", None).unwrap();
    assert_eq!(old.m, own.m);
}

#[test]
fn light_levels_set_the_exposure_factor() {
    let base = ChartSetup::default();
    let s = LightLevel::ExposureFactor(0.25).apply(&base).unwrap();
    assert_eq!(s.exposure_factor, 0.25);
    assert_eq!(s.mean_luminance, base.mean_luminance);
    // dimmer than the reference: the longest exposure, less signal
    let s = LightLevel::SceneLuminance(10.0).apply(&base).unwrap();
    assert_eq!((s.mean_luminance, s.exposure_factor), (10.0, 0.1));
    // brighter: auto-exposure shortens the time
    let s = LightLevel::SceneLuminance(400.0).apply(&base).unwrap();
    assert_eq!((s.mean_luminance, s.exposure_factor), (400.0, 1.0));
    for bad in [0.0, -0.5, 1.5, f64::NAN, f64::INFINITY] {
        assert!(
            LightLevel::ExposureFactor(bad).apply(&base).is_err(),
            "{bad}"
        );
    }
    for bad in [0.0, -1.0, 1e9, f64::NAN] {
        assert!(
            LightLevel::SceneLuminance(bad).apply(&base).is_err(),
            "{bad}"
        );
    }
}

#[test]
fn setups_without_a_factor_read_as_full_exposure() {
    let v = serde_json::json!({"patch_px": 24, "mean_luminance": 100.0,
        "exposure_fraction": 0.95, "seed": 7, "noise": true});
    let s: ChartSetup = serde_json::from_value(v).unwrap();
    assert_eq!(s.exposure_factor, 1.0);
}
