//! Every spatial metric of a rendering method in one call: sharpness and false colour on a
//! slanted edge ([`super::edge`]) and S-CIELAB on a texture of natural reflectances
//! ([`super::texture`]), each simulated through the full camera model with the chart
//! evaluation's set-up (exposure rules and factor, noise, seed) and rendered as the chart is
//! ([`render_method`] with [`method_correction`]).

use serde::{Deserialize, Serialize};

use super::EvalError;
use super::edge::{EdgeCapture, simulate_edge};
use super::texture::{TextureCapture, simulate_texture};
use super::workflow::{ChartSetup, Method, method_correction, render_method};
use crate::camera::Camera;
use crate::l3::correct::IlluminantEntry;
use crate::l3::render::ChromaMode;
use crate::scene::SlantedEdgeParams;
use crate::spectral::IsetData;

/// The side of the edge and texture scenes of a spatial evaluation, pixels.
pub const SPATIAL_SIZE: usize = 128;

/// A method's spatial metrics; each absent where it was not measured (and the edge's
/// MTF figures where the render shows no edge the SFR can find).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SpatialScore {
    /// MTF50 of the rendered edge's luminance, cycles per pixel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mtf50: Option<f64>,
    /// The rendered edge's SFR at half the Nyquist frequency.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mtf_at_half_nyquist: Option<f64>,
    /// MTF50 of the edge's ideal image (the lens and the pixel aperture), cycles per pixel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ideal_mtf50: Option<f64>,
    /// RMS C*ab the render puts at the neutral edge beyond the flat sides'.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub false_colour: Option<f64>,
    /// Mean S-CIELAB ΔE2000 of the rendered texture against its ideal image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub s_cielab_texture: Option<f64>,
}

/// The edge and the texture simulated once under one light and set-up, to score any
/// number of methods on.
#[derive(Clone, Debug)]
pub struct SpatialCaptures {
    pub edge: EdgeCapture,
    pub texture: TextureCapture,
    /// Whether L3 renders of them run the chroma stage (the set-up's).
    pub chroma: ChromaMode,
}

/// Simulate the edge and the texture (`size × size` each) under `acquisition` as `setup` says.
pub fn simulate_spatial(
    camera: &Camera,
    acquisition: &str,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
    size: usize,
) -> Result<SpatialCaptures, EvalError> {
    Ok(SpatialCaptures {
        edge: simulate_edge(
            camera,
            acquisition,
            iset,
            setup,
            &SlantedEdgeParams::new(size, size),
        )?,
        texture: simulate_texture(camera, acquisition, iset, setup, size)?,
        chroma: setup.chroma_denoise,
    })
}

impl SpatialCaptures {
    /// Render both captures with `method` under `correction` (balanced as
    /// [`method_correction`] says) and score them.
    pub fn score(
        &self,
        camera: &Camera,
        method: &Method,
        correction: &IlluminantEntry,
    ) -> Result<SpatialScore, EvalError> {
        let correction = method_correction(camera, method, correction)?;
        self.score_with(|volts: &[f32], w, h| {
            render_method(
                method,
                &correction,
                volts,
                (w, h),
                camera.cfa(),
                self.chroma,
            )
        })
    }

    /// Render both captures with `render(volts, width, height)` (interleaved XYZ out) and
    /// score them: for renderers that are not a [`Method`] (the bench's prepared ones).
    pub fn score_with(
        &self,
        render: impl Fn(&[f32], usize, usize) -> Result<Vec<f32>, EvalError>,
    ) -> Result<SpatialScore, EvalError> {
        let e = &self.edge;
        let edge_xyz = render(&e.volts, e.width, e.height)?;
        let mut out = SpatialScore {
            ideal_mtf50: Some(e.ideal_sfr.mtf50_cycles_per_pixel),
            ..SpatialScore::default()
        };
        // what cannot be measured is left out: an edge the SFR cannot find in the render
        // (noise at very low light), or a light side with no signal in some XYZ channel to
        // measure false colour against (a light with almost no blue, such as cct:1000)
        match e.sfr(&edge_xyz) {
            Ok(s) => {
                out.mtf50 = Some(s.mtf50_cycles_per_pixel);
                out.mtf_at_half_nyquist = Some(s.mtf_at_half_nyquist);
            }
            Err(EvalError::Sfr(_)) => {}
            Err(other) => return Err(other),
        }
        match e.false_colour(&edge_xyz) {
            Ok(f) => out.false_colour = Some(f),
            Err(EvalError::NoSignal(_)) => {}
            Err(other) => return Err(other),
        }
        let t = &self.texture;
        out.s_cielab_texture = Some(t.score(&render(&t.volts, t.width, t.height)?)?);
        Ok(out)
    }
}

/// Simulate the edge and the texture ([`SPATIAL_SIZE`]) under `acquisition` with `setup`,
/// render them with `method` under `correction` and score them.
pub fn spatial_score(
    camera: &Camera,
    method: &Method,
    correction: &IlluminantEntry,
    acquisition: &str,
    iset: Option<&IsetData>,
    setup: &ChartSetup,
) -> Result<SpatialScore, EvalError> {
    simulate_spatial(camera, acquisition, iset, setup, SPATIAL_SIZE)?
        .score(camera, method, correction)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::l3::correct::IlluminantRegistry;

    #[test]
    fn the_baseline_is_softer_than_the_lens_and_colours_the_edge() {
        let camera = crate::test_support::paper_camera();
        let setup = ChartSetup {
            noise: false,
            ..ChartSetup::default()
        };
        let matrix = super::super::fit_baseline_matrix(&camera, &["D65".into()], None).unwrap();
        let corr = IlluminantRegistry::with_defaults(*camera.grid(), None)
            .unwrap()
            .resolve("Tungsten", None)
            .unwrap();
        let caps = simulate_spatial(&camera, "Tungsten", None, &setup, 64).unwrap();
        let s = caps
            .score(&camera, &Method::Baseline(&matrix), &corr)
            .unwrap();
        let (m, ideal) = (s.mtf50.unwrap(), s.ideal_mtf50.unwrap());
        // bilinear demosaicking blurs: below the lens's own MTF50
        assert!(m > 0.05 && m < ideal, "{m} vs {ideal}");
        // and a bilinear RGBW demosaic fringes the edge
        assert!(s.false_colour.unwrap() > 0.0, "{s:?}");
        assert!(s.s_cielab_texture.unwrap() > 0.0, "{s:?}");
        let json = serde_json::to_value(&s).unwrap();
        assert!(json.get("mtf50").is_some());
        assert_eq!(
            serde_json::to_value(SpatialScore::default()).unwrap(),
            serde_json::json!({})
        );
    }
}
