//! The one place where the benchmark renders: every throughput and every
//! colour figure goes through these wrappers, so swapping the renderer here
//! changes both at once. (The strong ISP's colour figures are the evaluation's own scoring
//! of [`crate::eval::Method::Isp`], which renders with the same [`Isp::render`] as
//! [`render_isp_srgb8`].)

use crate::baseline::{
    BaselineError, ColourMatrix, Isp, render_baseline_fused, render_baseline_fused_srgb8,
};
use crate::camera::Cfa;
use crate::l3::L3Table;
use crate::l3::correct::IlluminantEntry;
use crate::l3::render::{FastRenderer, Frame, Mosaic, RenderError, WhiteLevel, xyz_to_srgb8};
use crate::pipeline::RenderPipeline;

/// Name of the L3 renderer the wrappers call (recorded in the JSON).
pub const RENDERER: &str = "fast";

/// Fixed white level (XYZ Y in the table's volts-equivalent units) of the
/// sRGB output: no per-frame white estimate in the timed path.
pub const BENCH_WHITE_Y: f64 = 1.0;

/// L3: the table prepared for rendering under `entry` as the service and `l3 render`
/// prepare it ([`RenderPipeline::new`]: its own kernels or fused with the light's
/// correction, chroma classes balanced by the light's neutral), once per table and
/// illuminant.
pub fn prepare(table: &L3Table, entry: &IlluminantEntry) -> Result<FastRenderer, RenderError> {
    Ok(RenderPipeline::new(table, entry)?.into_renderer())
}

/// L3: mosaic volts → interleaved XYZ.
pub fn render_xyz(
    renderer: &FastRenderer,
    volts: &[f32],
    width: usize,
    height: usize,
) -> Result<Vec<f32>, RenderError> {
    Ok(renderer
        .render_xyz(Mosaic::Volts(volts), width, height, None)?
        .0)
}

/// L3: mosaic volts → 8-bit sRGB (interleaved RGB) at [`BENCH_WHITE_Y`].
pub fn render_srgb8(
    renderer: &FastRenderer,
    volts: &[f32],
    width: usize,
    height: usize,
) -> Result<Frame, RenderError> {
    Ok(renderer
        .render_srgb8(
            Mosaic::Volts(volts),
            width,
            height,
            None,
            WhiteLevel::Y(BENCH_WHITE_Y),
        )?
        .0)
}

/// Baseline: bilinear demosaic + colour matrix (T already folded in) → XYZ, in one pass
/// ([`render_baseline_fused`]: [`crate::baseline::render_baseline`]'s values bit for bit).
pub fn render_baseline_xyz(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
    m: &ColourMatrix,
) -> Result<Vec<f32>, BaselineError> {
    render_baseline_fused(volts, width, height, cfa, m)
}

/// Baseline → 8-bit sRGB at [`BENCH_WHITE_Y`], in one pass (the bytes [`xyz_to_srgb8`]
/// makes of [`render_baseline_xyz`]'s XYZ).
pub fn render_baseline_srgb8(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
    m: &ColourMatrix,
) -> Result<Vec<u8>, BaselineError> {
    render_baseline_fused_srgb8(volts, width, height, cfa, m, BENCH_WHITE_Y)
}

/// The strong ISP → 8-bit sRGB at [`BENCH_WHITE_Y`].
pub fn render_isp_srgb8(
    isp: &Isp,
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
) -> Result<Vec<u8>, BaselineError> {
    Ok(xyz_to_srgb8(
        &isp.render(volts, width, height, cfa)?,
        BENCH_WHITE_Y,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::l3::L3Params;
    use crate::l3::classify::ChromaClasses;
    use crate::l3::correct::IDENTITY;
    use crate::test_support::{synthetic_frame_with_blocks, train_synthetic_table};

    #[test]
    fn conventional_wrappers_render_as_the_pipelines_do() {
        let cfa = crate::camera::Cfa::parse("RG/WB").unwrap();
        let f = synthetic_frame_with_blocks(3, 48, 12, 1.0, 0.02, (0, 0));
        let m = ColourMatrix {
            m: vec![
                [0.5, 0.2, 0.0],
                [0.3, 0.7, 0.1],
                [0.1, 0.1, 0.1],
                [0.0, 0.1, 0.9],
            ],
            n_channels: 4,
        };
        // the baseline's fused pass is the straightforward render, bit for bit
        let xyz = crate::baseline::render_baseline(&f.volts, 48, 48, &cfa, &m).unwrap();
        assert_eq!(
            render_baseline_xyz(&f.volts, 48, 48, &cfa, &m).unwrap(),
            xyz
        );
        assert_eq!(
            render_baseline_srgb8(&f.volts, 48, 48, &cfa, &m).unwrap(),
            xyz_to_srgb8(&xyz, BENCH_WHITE_Y)
        );
        let isp = Isp::new(m, None);
        let isp_xyz = isp.render(&f.volts, 48, 48, &cfa).unwrap();
        assert_ne!(isp_xyz, xyz);
        assert_eq!(
            render_isp_srgb8(&isp, &f.volts, 48, 48, &cfa).unwrap(),
            xyz_to_srgb8(&isp_xyz, BENCH_WHITE_Y)
        );
    }

    #[test]
    fn prepare_balances_chroma_classes_by_the_lights_neutral() {
        let params = L3Params {
            levels: L3Params::levels_for(6, 1.8).unwrap(),
            min_class_samples: 60,
            chroma: Some(ChromaClasses {
                centroids: vec![vec![0.4, 0.15, 0.35, 0.1], vec![0.1, 0.3, 0.3, 0.3]],
                white: Some(vec![1.0; 4]),
            }),
            ..L3Params::default()
        };
        let table = train_synthetic_table(&params, 30, |i| {
            let scale = [0.05f32, 0.2, 0.8, 1.5][i % 4];
            Ok(vec![synthetic_frame_with_blocks(
                i as u64,
                48,
                12,
                scale,
                0.01,
                (i % 2, (i / 2) % 2),
            )])
        })
        .unwrap();
        let lamp = vec![1.0, 0.7, 0.9, 0.45];
        let entry = IlluminantEntry {
            neutral: Some(lamp.clone()),
            ..IlluminantEntry::from_matrix("synthetic", IDENTITY)
        };
        let f = synthetic_frame_with_blocks(5, 96, 12, 1.0, 0.02, (0, 0));
        let render = |r: &FastRenderer| render_xyz(r, &f.volts, 96, 96).unwrap();
        let got = render(&prepare(&table, &entry).unwrap());
        let under_lamp = FastRenderer::under_light(&table, &table.kernels, Some(&lamp)).unwrap();
        assert_eq!(got, render(&under_lamp));
        // what the bench rendered before: the classes' reference light
        let reference = FastRenderer::new(&table, &table.kernels).unwrap();
        assert_ne!(
            got,
            render(&reference),
            "the light's neutral changed nothing"
        );
    }
}
