//! sRGB (IEC 61966-2-1): primaries, D65 white, transfer function, 8/16-bit
//! encoding and a lookup-table encoder for the render hot path.

use super::{Xyz, mat3_mul_vec};

/// Chromaticities of the sRGB red, green and blue primaries.
pub const SRGB_PRIMARIES_XY: [[f64; 2]; 3] = [[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]];
/// The sRGB white (D65 as IEC 61966-2-1 specifies it: x = 0.3127, y = 0.3290).
pub const SRGB_WHITE_XY: [f64; 2] = [0.3127, 0.3290];

/// Linear sRGB → XYZ (Y = 1 for RGB white), derived from the primaries and
/// the white at compile time.
pub const LINEAR_SRGB_TO_XYZ: [[f64; 3]; 3] = rgb_to_xyz_matrix(SRGB_PRIMARIES_XY, SRGB_WHITE_XY);
/// XYZ → linear sRGB: the exact inverse of [`LINEAR_SRGB_TO_XYZ`].
pub const XYZ_TO_LINEAR_SRGB: [[f64; 3]; 3] = inverse3(LINEAR_SRGB_TO_XYZ);

const fn xyz_of_xy(p: [f64; 2]) -> [f64; 3] {
    [p[0] / p[1], 1.0, (1.0 - p[0] - p[1]) / p[1]]
}

/// The inverse of a 3×3 matrix, or `None` when it is (numerically) singular.
pub fn checked_inverse3(m: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    let det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    let scale = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    if !det.is_finite() || det.abs() <= 1e-12 * scale.powi(3) {
        return None;
    }
    Some(inverse3(m))
}

const fn inverse3(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    let det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    let d = 1.0 / det;
    [
        [
            c00 * d,
            (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * d,
            (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * d,
        ],
        [
            c01 * d,
            (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * d,
            (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * d,
        ],
        [
            c02 * d,
            (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * d,
            (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * d,
        ],
    ]
}

/// The RGB → XYZ matrix of a display with the given primaries and white
/// (RGB = (1,1,1) maps to the white with Y = 1).
const fn rgb_to_xyz_matrix(primaries: [[f64; 2]; 3], white: [f64; 2]) -> [[f64; 3]; 3] {
    let r = xyz_of_xy(primaries[0]);
    let g = xyz_of_xy(primaries[1]);
    let b = xyz_of_xy(primaries[2]);
    let p = [[r[0], g[0], b[0]], [r[1], g[1], b[1]], [r[2], g[2], b[2]]];
    let pi = inverse3(p);
    let w = xyz_of_xy(white);
    let s = [
        pi[0][0] * w[0] + pi[0][1] * w[1] + pi[0][2] * w[2],
        pi[1][0] * w[0] + pi[1][1] * w[1] + pi[1][2] * w[2],
        pi[2][0] * w[0] + pi[2][1] * w[1] + pi[2][2] * w[2],
    ];
    [
        [p[0][0] * s[0], p[0][1] * s[1], p[0][2] * s[2]],
        [p[1][0] * s[0], p[1][1] * s[1], p[1][2] * s[2]],
        [p[2][0] * s[0], p[2][1] * s[1], p[2][2] * s[2]],
    ]
}

/// XYZ (Y = 1 white) → linear sRGB.
#[inline]
pub fn xyz_to_linear_srgb(xyz: Xyz) -> [f64; 3] {
    mat3_mul_vec(&XYZ_TO_LINEAR_SRGB, xyz)
}

/// Linear sRGB → XYZ (Y = 1 white).
#[inline]
pub fn linear_srgb_to_xyz(rgb: [f64; 3]) -> Xyz {
    mat3_mul_vec(&LINEAR_SRGB_TO_XYZ, rgb)
}

/// The sRGB transfer function (linear → encoded), not clamped; values below
/// the linear segment (incl. negatives) use the linear branch.
#[inline]
pub fn srgb_encode(v: f64) -> f64 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The inverse sRGB transfer function (encoded → linear), not clamped.
#[inline]
pub fn srgb_decode(v: f64) -> f64 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear value → 8-bit sRGB code, clamped to [0, 1] (NaN → 0) and rounded.
#[inline]
pub fn encode_srgb8(linear: f64) -> u8 {
    let v = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    (srgb_encode(v) * 255.0).round() as u8
}

/// Linear value → 16-bit sRGB code, clamped to [0, 1] (NaN → 0) and rounded.
#[inline]
pub fn encode_srgb16(linear: f64) -> u16 {
    let v = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    (srgb_encode(v) * 65535.0).round() as u16
}

/// A lookup-table sRGB encoder for f32 linear values: the table samples
/// [0, 1] uniformly and a value takes the entry nearest to it. With the
/// default 4096 entries the code is within 1 of [`encode_srgb8`] everywhere
/// (the steepest slope of the curve, 12.92·255 codes per unit, moves at most
/// 0.4 codes over half a table step). Out-of-range values clamp; NaN → 0.
#[derive(Clone, Debug)]
pub struct SrgbLut {
    table: Vec<u8>,
    scale: f32,
}

impl Default for SrgbLut {
    fn default() -> Self {
        Self::new()
    }
}

impl SrgbLut {
    /// The largest table (keeps every index inside an i32).
    pub const MAX_ENTRIES: usize = 1 << 20;

    /// Default table size.
    pub const DEFAULT_ENTRIES: usize = 4096;

    /// A table with [`Self::DEFAULT_ENTRIES`] entries.
    pub fn new() -> Self {
        Self::with_entries(Self::DEFAULT_ENTRIES)
    }

    /// A table with `entries` entries (clamped to 2 ..= [`Self::MAX_ENTRIES`]).
    pub fn with_entries(entries: usize) -> Self {
        let n = entries.clamp(2, Self::MAX_ENTRIES);
        let last = (n - 1) as f64;
        let table = (0..n).map(|i| encode_srgb8(i as f64 / last)).collect();
        Self {
            table,
            scale: last as f32,
        }
    }

    /// Number of table entries.
    pub fn len(&self) -> usize {
        self.table.len()
    }

    /// Always false (a table has at least two entries).
    pub fn is_empty(&self) -> bool {
        self.table.is_empty()
    }

    /// Encode one linear value.
    #[inline]
    pub fn encode(&self, linear: f32) -> u8 {
        self.at(self.index(linear))
    }

    /// The table index of a linear value (NaN and negatives give 0, values past 1 the
    /// last entry); branch-free, so loops over it vectorise.
    #[inline(always)]
    pub fn index(&self, linear: f32) -> u32 {
        self.index_times(linear, self.scale)
    }

    /// The table index of `linear · gain`, computed as `linear · (gain · scale)`
    /// where `times` is that product (e.g. a white level folded into the scale:
    /// one multiply per value).
    #[inline(always)]
    pub fn index_times(&self, linear: f32, times: f32) -> u32 {
        // max/min return the non-NaN operand, so NaN becomes 0
        let x = (linear * times + 0.5).max(0.0).min(self.scale);
        // SAFETY: x is finite and within [0, scale] (scale < MAX_ENTRIES < 2³¹), so it fits an i32;
        // the unchecked conversion lets the loops over it vectorise
        (unsafe { x.to_int_unchecked::<i32>() }) as u32
    }

    /// The entry at `index` (clamped to the table).
    #[inline(always)]
    pub fn at(&self, index: u32) -> u8 {
        let i = (index as usize).min(self.table.len() - 1);
        self.table[i]
    }

    /// The table's entries (index with [`Self::index`]).
    pub fn entries(&self) -> &[u8] {
        &self.table
    }

    /// The linear value → index scale (the last index).
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// Encode a slice into `out` (pairs up to the shorter length).
    pub fn encode_slice(&self, linear: &[f32], out: &mut [u8]) {
        for (o, &v) in out.iter_mut().zip(linear) {
            *o = self.encode(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrix_matches_the_published_one() {
        // IEC 61966-2-1 quotes the matrix to 4 decimals.
        let m = LINEAR_SRGB_TO_XYZ;
        let published = [
            [0.4124, 0.3576, 0.1805],
            [0.2126, 0.7152, 0.0722],
            [0.0193, 0.1192, 0.9505],
        ];
        for i in 0..3 {
            for j in 0..3 {
                assert!((m[i][j] - published[i][j]).abs() < 1e-4, "{m:?}");
            }
        }
        let w = linear_srgb_to_xyz([1.0, 1.0, 1.0]);
        assert!((w[1] - 1.0).abs() < 1e-15);
        let id = mat3_mul_vec(&XYZ_TO_LINEAR_SRGB, linear_srgb_to_xyz([0.2, 0.5, 0.7]));
        assert!((id[0] - 0.2).abs() < 1e-14 && (id[2] - 0.7).abs() < 1e-14);
    }

    #[test]
    fn transfer_function_values() {
        assert_eq!(encode_srgb8(0.0), 0);
        assert_eq!(encode_srgb8(1.0), 255);
        assert_eq!(encode_srgb8(2.0), 255);
        assert_eq!(encode_srgb8(-1.0), 0);
        assert_eq!(encode_srgb8(f64::NAN), 0);
        assert_eq!(encode_srgb8(0.18), 118);
        assert_eq!(encode_srgb8(0.5), 188);
        assert_eq!(encode_srgb16(1.0), 65535);
        assert!((srgb_decode(srgb_encode(0.002)) - 0.002).abs() < 1e-15);
    }

    #[test]
    fn lut_is_within_one_code_everywhere() {
        let lut = SrgbLut::new();
        let n = 1_000_000;
        let (mut max_err, mut exact) = (0i32, 0usize);
        for i in 0..=n {
            let x = i as f64 / n as f64;
            let a = lut.encode(x as f32) as i32;
            let b = encode_srgb8(x) as i32;
            max_err = max_err.max((a - b).abs());
            exact += usize::from(a == b);
        }
        println!(
            "SrgbLut(4096): max error {max_err} code, exact for {:.2} % of inputs",
            100.0 * exact as f64 / (n + 1) as f64
        );
        assert!(max_err <= 1);
        assert_eq!(lut.encode(f32::NAN), 0);
        assert_eq!(lut.encode(-3.0), 0);
        assert_eq!(lut.encode(7.0), 255);
        assert_eq!(lut.encode(f32::INFINITY), 255);
        let mut out = [0u8; 3];
        lut.encode_slice(&[0.0, 0.5, 1.0], &mut out);
        assert_eq!(out, [0, 188, 255]);
    }

    #[test]
    fn a_gain_in_the_index_is_the_gain_on_the_value() {
        let lut = SrgbLut::new();
        // at the table's own scale, the plain index
        for i in 0..=4096 {
            let v = i as f32 / 4000.0;
            assert_eq!(lut.index_times(v, lut.scale()), lut.index(v));
        }
        // a white level of 0.5 (gain 2): half of white encodes as white, a quarter
        // as the code of half, within the table's one-code bound
        let times = 2.0 * lut.scale();
        assert_eq!(lut.at(lut.index_times(0.5, times)), 255);
        let half = lut.at(lut.index_times(0.25, times));
        assert!(half.abs_diff(encode_srgb8(0.5)) <= 1, "{half}");
        // past white, negatives, NaN and a gain of 0 clamp as the plain index does
        assert_eq!(lut.index_times(3.0, times), lut.scale() as u32);
        assert_eq!(lut.index_times(-1.0, times), 0);
        assert_eq!(lut.index_times(f32::NAN, times), 0);
        assert_eq!(lut.index_times(0.7, 0.0), 0);
    }
}
