//! xyY and CIE 1976 L*a*b*.

use super::{Lab, Xyz};

/// XYZ → xyY. Black maps to (0, 0, 0).
pub fn xyz_to_xyy(xyz: Xyz) -> [f64; 3] {
    let s = xyz[0] + xyz[1] + xyz[2];
    if s == 0.0 {
        return [0.0, 0.0, 0.0];
    }
    [xyz[0] / s, xyz[1] / s, xyz[1]]
}

/// xyY → XYZ. `y = 0` maps to black.
pub fn xyy_to_xyz(xyy: [f64; 3]) -> Xyz {
    let [x, y, big_y] = xyy;
    if y == 0.0 {
        return [0.0, 0.0, 0.0];
    }
    [x * big_y / y, big_y, (1.0 - x - y) * big_y / y]
}

/// Chromaticity coordinates (x, y) of XYZ.
pub fn xy(xyz: Xyz) -> [f64; 2] {
    let v = xyz_to_xyy(xyz);
    [v[0], v[1]]
}

/// XYZ with Y = 1 of a chromaticity.
pub fn xy_to_xyz(xy: [f64; 2]) -> Xyz {
    xyy_to_xyz([xy[0], xy[1], 1.0])
}

const EPSILON: f64 = 216.0 / 24389.0;
const KAPPA: f64 = 24389.0 / 27.0;

fn f_lab(t: f64) -> f64 {
    if t > EPSILON {
        t.cbrt()
    } else {
        (KAPPA * t + 16.0) / 116.0
    }
}

fn f_lab_inv(f: f64) -> f64 {
    let f3 = f * f * f;
    if f3 > EPSILON {
        f3
    } else {
        (116.0 * f - 16.0) / KAPPA
    }
}

/// XYZ → CIELAB relative to `white` (same scale as `xyz`).
pub fn xyz_to_lab(xyz: Xyz, white: Xyz) -> Lab {
    let fx = f_lab(xyz[0] / white[0]);
    let fy = f_lab(xyz[1] / white[1]);
    let fz = f_lab(xyz[2] / white[2]);
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIELAB → XYZ relative to `white`.
pub fn lab_to_xyz(lab: Lab, white: Xyz) -> Xyz {
    let fy = (lab[0] + 16.0) / 116.0;
    let fx = fy + lab[1] / 500.0;
    let fz = fy - lab[2] / 200.0;
    let yr = if lab[0] > KAPPA * EPSILON {
        fy * fy * fy
    } else {
        lab[0] / KAPPA
    };
    [
        f_lab_inv(fx) * white[0],
        yr * white[1],
        f_lab_inv(fz) * white[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::D65_WHITE_XYZ;

    #[test]
    fn white_is_l100_and_known_value() {
        let l = xyz_to_lab(D65_WHITE_XYZ, D65_WHITE_XYZ);
        assert!((l[0] - 100.0).abs() < 1e-12 && l[1].abs() < 1e-12 && l[2].abs() < 1e-12);
        // sRGB red (0.4124, 0.2126, 0.0193) → L*a*b* ≈ (53.24, 80.09, 67.20).
        let r = xyz_to_lab([0.412456, 0.212673, 0.019334], D65_WHITE_XYZ);
        assert!((r[0] - 53.24).abs() < 0.01, "{r:?}");
        assert!((r[1] - 80.09).abs() < 0.02, "{r:?}");
        assert!((r[2] - 67.20).abs() < 0.02, "{r:?}");
        // The dark branch.
        let d = xyz_to_lab([0.001, 0.001, 0.001], D65_WHITE_XYZ);
        assert!((d[0] - 0.9033).abs() < 1e-3, "{d:?}");
    }

    #[test]
    fn xyy_round_trip() {
        let v = [0.3, 0.4, 0.5];
        let b = xyy_to_xyz(xyz_to_xyy(v));
        for k in 0..3 {
            assert!((v[k] - b[k]).abs() < 1e-15);
        }
        assert_eq!(xyz_to_xyy([0.0; 3]), [0.0; 3]);
        let w = xy([0.95047, 1.0, 1.08883]);
        assert!((w[0] - 0.3127).abs() < 1e-4 && (w[1] - 0.3290).abs() < 1e-4);
    }
}
