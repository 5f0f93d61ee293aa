//! The camera simulator: scene → optics → sensor (docs/design.md §3).
//!
//! - [`SensorDesign`]: every parameter as data (TOML in `config/sensors/`),
//!   with parametric or CSV filters ([`FilterSpec`]).
//! - [`Camera`]: a design resolved on a wavelength grid.
//! - [`Optics`]: the diffraction-limited lens; [`Optics::image`] blurs a
//!   scene into an [`OpticalImage`].
//! - [`Camera::channel_rates`] → [`mosaic`] → [`Camera::capture`]: noise-free
//!   photo-electron rates for every channel, the CFA sampling, and a noisy
//!   frame in volts. [`Camera::xyz_rates`] gives the ideal XYZ target.
//! - [`simulate`]: all of it in one call.
//!
//! Units: wavelengths in nm, radiance W/(sr·m²·nm), irradiance W/(m²·nm),
//! rates in electrons/s, frames in volts.

pub mod catalogue;
mod cfa;
mod colour_matrix;
mod design;
mod neutral;
mod optics;
mod sensor;

use ndarray::{Array2, Array3};

pub use cfa::{Cfa, MAX_CFA_SIDE};
pub use design::{
    COVERAGE_SLACK_NM, CoverageNote, FilterSpec, LoadedDesign, SensorDesign, parametric,
};
pub use neutral::{NEUTRAL_CCT_RANGE, NeutralMatch};
pub use optics::{
    DEFAULT_SAMPLES_PER_PIXEL, KM, MAX_SAMPLES_PER_PIXEL, OpticalImage, Optics, diffraction_otf,
};
pub use sensor::{
    AUTO_EXPOSURE_PERCENTILE, Camera, Exposure, MAX_AUTO_EXPOSURE_S, NoiseSwitches, mosaic,
};

use crate::scene::Scene;
use crate::spectral::{SpectralError, WavelengthGrid};

/// Errors of the camera simulator.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    #[error(transparent)]
    Spectral(#[from] SpectralError),
    #[error("invalid sensor design {0}")]
    InvalidDesign(String),
    #[error("invalid CFA {0}")]
    InvalidCfa(String),
    #[error("{path}: {msg}")]
    Toml { path: String, msg: String },
    /// A design object (a training job's `sensor`) that does not deserialize.
    #[error("{0}")]
    Json(String),
    #[error("cannot read {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{what} is on grid {got:?} but the camera uses {expected:?}")]
    GridMismatch {
        what: String,
        expected: WavelengthGrid,
        got: WavelengthGrid,
    },
    #[error("{0}")]
    InvalidArgument(String),
}

/// One simulated frame with its ground truth.
#[derive(Clone, Debug)]
pub struct Capture {
    /// The raw mosaic in volts, shape `(rows, cols)`.
    pub volts: Array2<f32>,
    /// Exposure time used, s.
    pub exposure_s: f64,
    /// The CFA of `volts` (pixel (0, 0) at the tile's origin).
    pub cfa: Cfa,
    /// Noise-free XYZ of the optical image under the scene illuminant, in
    /// volts-equivalent (see [`Camera::xyz_scale`]), shape `(rows, cols, 3)`.
    pub ideal_xyz: Array3<f32>,
}

/// Simulate `scene` through `camera`: optics sampled at the pixel pitch (one
/// scene pixel per sensor pixel), channel rates, the CFA mosaic, exposure,
/// noise from `seed`, and the ideal XYZ under the scene's illuminant.
pub fn simulate(
    camera: &Camera,
    scene: &Scene,
    exposure: Exposure,
    noise: &NoiseSwitches,
    seed: u64,
) -> Result<Capture, CameraError> {
    let optical = camera.optical_image(scene)?;
    let rates = camera.channel_rates(&optical)?;
    let cfa = camera.cfa().clone();
    let mean = mosaic(&rates, &cfa)?;
    let exposure_s = match exposure {
        Exposure::Auto { target_fraction } => {
            camera.auto_exposure(&rates, &cfa, target_fraction)?
        }
        Exposure::Seconds(t) => t,
        Exposure::Scaled {
            target_fraction,
            factor,
        } => {
            if !(factor.is_finite() && factor > 0.0) {
                return Err(CameraError::InvalidArgument(format!(
                    "exposure factor {factor} must be finite and positive"
                )));
            }
            camera.auto_exposure(&rates, &cfa, target_fraction)? * factor
        }
    };
    let volts = camera.capture(&mean, exposure_s, noise, seed)?;
    let t = exposure_s as f32;
    let ideal_xyz = camera
        .xyz_rates(&optical, &scene.illuminant)?
        .mapv_into(|v| v * t);
    Ok(Capture {
        volts,
        exposure_s,
        cfa,
        ideal_xyz,
    })
}
