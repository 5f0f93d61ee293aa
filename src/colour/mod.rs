//! Colorimetry: tristimulus values, xyY, CIELAB, CIEDE2000, sRGB, CCT.
//!
//! Plain `[f64; 3]` arrays throughout. XYZ is on the "Y = 1 for a perfect
//! white" scale unless a function says otherwise.

mod cct;
mod ciede2000;
mod lab;
mod srgb;
mod tristimulus;

pub use cct::{cct_duv_from_xy, cct_from_xy, daylight_xy, planck_xy, xy_to_uv};
pub use ciede2000::{ciede2000, ciede2000_metric};
pub use lab::{lab_to_xyz, xy, xy_to_xyz, xyy_to_xyz, xyz_to_lab, xyz_to_xyy};
pub use srgb::{
    LINEAR_SRGB_TO_XYZ, SRGB_PRIMARIES_XY, SRGB_WHITE_XY, SrgbLut, XYZ_TO_LINEAR_SRGB,
    checked_inverse3, encode_srgb8, encode_srgb16, linear_srgb_to_xyz, srgb_decode, srgb_encode,
    xyz_to_linear_srgb,
};
pub use tristimulus::Cmfs;

/// CIE XYZ tristimulus values.
pub type Xyz = [f64; 3];
/// CIE 1976 L*a*b*.
pub type Lab = [f64; 3];

/// The CIE D65 white point (2° observer), Y = 1.
pub const D65_WHITE_XYZ: Xyz = [0.95047, 1.0, 1.08883];

/// Errors of the colour layer.
#[derive(Debug, thiserror::Error)]
pub enum ColourError {
    #[error(transparent)]
    Spectral(#[from] crate::spectral::SpectralError),
    #[error("illuminant has no luminance (Y = {0}); cannot normalise to white")]
    ZeroLuminance(f64),
    #[error("non-finite value in {0}")]
    NonFinite(&'static str),
    #[error("chromaticity ({x}, {y}) is outside the CCT domain: {why}")]
    CctOutOfRange { x: f64, y: f64, why: String },
    #[error("colour temperature {0} K is outside {1}")]
    TemperatureOutOfRange(f64, &'static str),
}

/// 3×3 matrix times vector.
#[inline]
pub fn mat3_mul_vec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}
