//! Where the 24 patches of a ColorChecker lie in a frame: the four corners the user gives, the
//! homography from the chart's own coordinates onto the frame, and the pixels sampled in the
//! middle of each patch.
//!
//! Chart coordinates: `u` across, `v` down, both 0–1 over the 6 × 4 grid of patches, with dark
//! skin at (0, 0) and black at (1, 1). The corners are the grid's outer corners (see
//! [`Corners`]); patches are squares of side `s` separated by gaps of `gap · s`, so the grid is
//! `6s + 5·gap·s` wide and `4s + 3·gap·s` high. The homography (8 unknowns from the 4 point
//! pairs, solved directly) is written out here: it is one small linear solve, and an image
//! crate would bring a whole toolbox for it.

use nalgebra::{Matrix3, SMatrix, SVector};
use serde::{Deserialize, Serialize};

use crate::eval::EvalError;

/// Patches across and down the chart.
pub const COLS: usize = 6;
pub const ROWS: usize = 4;
/// The gap between neighbouring patches of a ColorChecker Classic, as a fraction of a patch's
/// side (OpenCV's `mcc` chart model: 2.5-unit patches, 0.25-unit gaps).
pub const CLASSIC_GAP: f64 = 0.1;
/// The part of each patch's side that is sampled, centred (the middle 60 % of its width and
/// of its height), away from blur and the corners' error. It is the interior the chart
/// evaluation of a simulated chart averages (a fifth of the side off each edge), so the two
/// sample the same pixels of the same chart.
pub const SAMPLE_FRACTION: f64 = 0.6;
/// Fewest pixels a patch's sample may hold.
pub const MIN_SAMPLE_PIXELS: usize = 4;
/// A pixel of a sample is an outlier, and left out of its mean, when one of its channels lies
/// further than this many robust standard deviations (1.4826 × the median absolute
/// deviation) from that channel's median: a speck of dust, a glint or a hot pixel. Gaussian noise
/// alone puts about one pixel in 5,000 there (6e-5 per channel), so the mean of a clean patch
/// is its plain mean.
pub const OUTLIER_SIGMAS: f64 = 4.0;

/// The chart's four outer corners in the frame, in pixels (`x` right, `y` down; pixel
/// `(i, j)` covers `[i, i+1) × [j, j+1)`, so a frame `W` wide ends at `x = W`), in the
/// chart's own order, clockwise as the chart is seen from the front: the outer corner of
/// dark skin (patch 1), of bluish green (patch 6), of black (patch 24), of white (patch 19).
/// Whatever way up the chart is in the frame, corner 1 is dark skin's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Corners(pub [[f64; 2]; 4]);

impl std::str::FromStr for Corners {
    type Err = EvalError;

    /// `x1,y1,x2,y2,x3,y3,x4,y4`, checked: finite, a convex quadrilateral, clockwise.
    fn from_str(s: &str) -> Result<Self, EvalError> {
        let v: Vec<f64> = s
            .split(',')
            .map(|t| t.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| {
                EvalError::Invalid(format!(
                    "corners '{s}': expected eight numbers x1,y1,x2,y2,x3,y3,x4,y4"
                ))
            })?;
        if v.len() != 8 {
            return Err(EvalError::Invalid(format!(
                "corners '{s}': expected eight numbers x1,y1,x2,y2,x3,y3,x4,y4, got {}",
                v.len()
            )));
        }
        let c = Corners(std::array::from_fn(|i| [v[2 * i], v[2 * i + 1]]));
        c.check()?;
        Ok(c)
    }
}

impl Corners {
    /// Refuses non-finite values, a quadrilateral that is not convex, and corners given
    /// counter-clockwise (a mirrored chart, or the order mixed up).
    pub fn check(&self) -> Result<(), EvalError> {
        let p = &self.0;
        if p.iter().flatten().any(|v| !v.is_finite() || v.abs() > 1e7) {
            return Err(EvalError::Invalid(
                "corners: every coordinate must be a finite number of pixels".into(),
            ));
        }
        let turns: Vec<f64> = (0..4)
            .map(|i| {
                let (a, b, c) = (p[i], p[(i + 1) % 4], p[(i + 2) % 4]);
                (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])
            })
            .collect();
        if turns.iter().all(|t| *t < 0.0) {
            return Err(EvalError::Invalid(
                "corners: they go counter-clockwise; give them clockwise as the chart is seen: dark skin's corner, bluish green's, black's, white's".into(),
            ));
        }
        if !turns.iter().all(|t| *t > 0.0) {
            return Err(EvalError::Invalid(
                "corners: they do not make a convex quadrilateral (order: dark skin's corner, bluish green's, black's, white's)".into(),
            ));
        }
        Ok(())
    }
}

/// A plane projective map.
#[derive(Clone, Copy, Debug)]
pub struct Homography(Matrix3<f64>);

impl Homography {
    /// The map taking chart coordinates (0,0), (1,0), (1,1), (0,1) onto `corners`.
    pub fn unit_square_to(corners: &Corners) -> Result<Homography, EvalError> {
        let src = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let mut a = SMatrix::<f64, 8, 8>::zeros();
        let mut b = SVector::<f64, 8>::zeros();
        for (i, ([u, v], [x, y])) in src.iter().zip(corners.0.iter()).enumerate() {
            let r = 2 * i;
            a.row_mut(r)
                .copy_from_slice(&[*u, *v, 1.0, 0.0, 0.0, 0.0, -u * x, -v * x]);
            a.row_mut(r + 1)
                .copy_from_slice(&[0.0, 0.0, 0.0, *u, *v, 1.0, -u * y, -v * y]);
            b[r] = *x;
            b[r + 1] = *y;
        }
        let h = a
            .lu()
            .solve(&b)
            .filter(|h| h.iter().all(|v| v.is_finite()))
            .ok_or_else(|| EvalError::Invalid("corners: degenerate quadrilateral".into()))?;
        Ok(Homography(Matrix3::new(
            h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0,
        )))
    }

    /// The point `p` maps to (`None` at infinity).
    pub fn map(&self, p: [f64; 2]) -> Option<[f64; 2]> {
        let v = self.0 * nalgebra::Vector3::new(p[0], p[1], 1.0);
        (v[2].abs() > 1e-12).then(|| [v[0] / v[2], v[1] / v[2]])
    }

    pub fn inverse(&self) -> Option<Homography> {
        self.0.try_inverse().map(Homography)
    }
}

/// The chart-coordinate rectangle `(u0, v0, u1, v1)` of patch `k` (0-based, row by row)
/// shrunk to its sampled middle.
pub fn sample_rect(k: usize, gap: f64) -> [f64; 4] {
    let (row, col) = ((k / COLS) as f64, (k % COLS) as f64);
    let su = 1.0 / (COLS as f64 + (COLS - 1) as f64 * gap);
    let sv = 1.0 / (ROWS as f64 + (ROWS - 1) as f64 * gap);
    let (u0, v0) = (col * (1.0 + gap) * su, row * (1.0 + gap) * sv);
    let m = (1.0 - SAMPLE_FRACTION) / 2.0;
    [
        u0 + m * su,
        v0 + m * sv,
        u0 + (1.0 - m) * su,
        v0 + (1.0 - m) * sv,
    ]
}

/// One patch's sample: the robust mean XYZ, how many pixels it holds, its centre in the frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub xyz: [f64; 3],
    pub pixels: usize,
    pub centre: [f64; 2],
}

/// Samples the 24 patches of an interleaved XYZ image (`width × height × 3`): each patch's
/// pixels whose centres fall in its sampled middle ([`sample_rect`]), averaged over the
/// pixels that are not outliers ([`OUTLIER_SIGMAS`]: a speck of dust, a glint or a hot pixel
/// does not move it).
pub fn sample_patches(
    xyz: &[f32],
    width: usize,
    height: usize,
    corners: &Corners,
    gap: f64,
) -> Result<Vec<Sample>, EvalError> {
    if xyz.len() != width * height * 3 {
        return Err(EvalError::Invalid(format!(
            "image has {} values, {width}×{height}×3 expected",
            xyz.len()
        )));
    }
    if !(gap.is_finite() && (0.0..=1.0).contains(&gap)) {
        return Err(EvalError::Invalid(format!(
            "chart gap {gap}: expected 0 to 1 (a fraction of a patch's side)"
        )));
    }
    corners.check()?;
    let h = Homography::unit_square_to(corners)?;
    let inv = h
        .inverse()
        .ok_or_else(|| EvalError::Invalid("corners: degenerate quadrilateral".into()))?;
    (0..ROWS * COLS)
        .map(|k| {
            let [u0, v0, u1, v1] = sample_rect(k, gap);
            let quad = [[u0, v0], [u1, v0], [u1, v1], [u0, v1]].map(|p| h.map(p));
            let quad: Vec<[f64; 2]> = quad.into_iter().collect::<Option<_>>().ok_or_else(|| {
                EvalError::Invalid("corners: degenerate quadrilateral".into())
            })?;
            let (lo_x, hi_x) = bounds(quad.iter().map(|p| p[0]));
            let (lo_y, hi_y) = bounds(quad.iter().map(|p| p[1]));
            if lo_x < 0.0 || lo_y < 0.0 || hi_x > width as f64 || hi_y > height as f64 {
                return Err(EvalError::Invalid(format!(
                    "patch {} lies partly outside the {width}×{height} frame: check the corners",
                    k + 1
                )));
            }
            let mut values: Vec<[f32; 3]> = Vec::new();
            for y in lo_y.floor() as usize..(hi_y.ceil() as usize).min(height) {
                for x in lo_x.floor() as usize..(hi_x.ceil() as usize).min(width) {
                    let Some([u, v]) = inv.map([x as f64 + 0.5, y as f64 + 0.5]) else {
                        continue;
                    };
                    if (u0..=u1).contains(&u) && (v0..=v1).contains(&v) {
                        let o = (y * width + x) * 3;
                        values.push([xyz[o], xyz[o + 1], xyz[o + 2]]);
                    }
                }
            }
            let pixels = values.len();
            if pixels < MIN_SAMPLE_PIXELS {
                return Err(EvalError::Invalid(format!(
                    "patch {} has {pixels} pixels in its sampled middle ({MIN_SAMPLE_PIXELS} needed): the chart is too small in the frame",
                    k + 1
                )));
            }
            let centre = h
                .map([(u0 + u1) / 2.0, (v0 + v1) / 2.0])
                .unwrap_or([f64::NAN; 2]);
            Ok(Sample {
                xyz: robust_mean(&values),
                pixels,
                centre,
            })
        })
        .collect()
}

fn bounds(it: impl Iterator<Item = f64>) -> (f64, f64) {
    it.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    })
}

/// The mean of the pixels that are not outliers ([`OUTLIER_SIGMAS`] from the per-channel
/// median); a pixel with a non-finite channel is one. With every pixel an outlier, NaN.
fn robust_mean(px: &[[f32; 3]]) -> [f64; 3] {
    let centre: [(f64, f64); 3] = std::array::from_fn(|c| {
        let mut v: Vec<f64> = px
            .iter()
            .map(|p| p[c] as f64)
            .filter(|v| v.is_finite())
            .collect();
        let med = median(&mut v);
        let mut dev: Vec<f64> = v.iter().map(|x| (x - med).abs()).collect();
        let sigma = 1.4826 * median(&mut dev);
        // a patch of equal values (MAD 0) still admits a sliver around its value
        let bound = (OUTLIER_SIGMAS * sigma).max(0.005 * med.abs()).max(1e-12);
        (med, bound)
    });
    let mut sum = [0f64; 3];
    let mut n = 0usize;
    for p in px {
        let ok = (0..3).all(|c| {
            let v = p[c] as f64;
            v.is_finite() && (v - centre[c].0).abs() <= centre[c].1
        });
        if ok {
            (0..3).for_each(|c| sum[c] += p[c] as f64);
            n += 1;
        }
    }
    sum.map(|s| if n == 0 { f64::NAN } else { s / n as f64 })
}

/// The median of `v` (NaN when empty); reorders `v`.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        (v[m - 1] + v[m]) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn corners(s: &str) -> Corners {
        s.parse().unwrap()
    }

    #[test]
    fn homography_maps_the_corners_exactly() {
        for c in [
            "0,0,192,0,192,128,0,128",
            "10.5,20,300,35,280,250,30,210",
            // upside down: dark skin's corner at the bottom right of the frame
            "192,128,0,128,0,0,192,0",
        ] {
            let c = corners(c);
            let h = Homography::unit_square_to(&c).unwrap();
            let inv = h.inverse().unwrap();
            for (unit, want) in [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
                .iter()
                .zip(c.0)
            {
                let got = h.map(*unit).unwrap();
                assert!((got[0] - want[0]).abs() < 1e-9 && (got[1] - want[1]).abs() < 1e-9);
                let back = inv.map(want).unwrap();
                assert!((back[0] - unit[0]).abs() < 1e-9 && (back[1] - unit[1]).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn corners_are_checked() {
        assert!("1,2,3".parse::<Corners>().is_err());
        assert!("0,0,1,0,1,1,0,x".parse::<Corners>().is_err());
        assert!("0,0,1,0,1,1,0,NaN".parse::<Corners>().is_err());
        // counter-clockwise (mirrored)
        let e = "0,0,0,128,192,128,192,0".parse::<Corners>().unwrap_err();
        assert!(e.to_string().contains("counter-clockwise"), "{e}");
        // a bow tie
        assert!("0,0,192,128,192,0,0,128".parse::<Corners>().is_err());
    }

    /// A chart drawn edge to edge (no gaps) with each patch's index as its value: every
    /// patch's sample holds only its own pixels, the middle 60 % of its side.
    #[test]
    fn samples_hold_their_own_patch() {
        let (p, w, h) = (20usize, 120usize, 80usize);
        let mut xyz = vec![0f32; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let k = (y / p) * COLS + x / p;
                xyz[(y * w + x) * 3..][..3].copy_from_slice(&[k as f32, 1.0, 2.0]);
            }
        }
        let c = corners("0,0,120,0,120,80,0,80");
        let s = sample_patches(&xyz, w, h, &c, 0.0).unwrap();
        assert_eq!(s.len(), 24);
        for (k, s) in s.iter().enumerate() {
            assert_eq!(s.xyz, [k as f64, 1.0, 2.0]);
            assert_eq!(s.pixels, 144, "12 × 12 pixels: the middle 60 % of 20 × 20");
            let want = [
                (k % COLS) as f64 * 20.0 + 10.0,
                (k / COLS) as f64 * 20.0 + 10.0,
            ];
            assert!((s.centre[0] - want[0]).abs() < 1e-9 && (s.centre[1] - want[1]).abs() < 1e-9);
        }
        // the same chart rotated by 180° in the frame: corners given from dark skin's
        let mut rot = vec![0f32; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let from = ((h - 1 - y) * w + (w - 1 - x)) * 3;
                let v = [xyz[from], xyz[from + 1], xyz[from + 2]];
                rot[(y * w + x) * 3..][..3].copy_from_slice(&v);
            }
        }
        let c = corners("120,80,0,80,0,0,120,0");
        let s = sample_patches(&rot, w, h, &c, 0.0).unwrap();
        assert!(s.iter().enumerate().all(|(k, s)| s.xyz[0] == k as f64));
        // a frame too small for the corners
        assert!(sample_patches(&xyz, w, h, &corners("0,0,240,0,240,80,0,80"), 0.0).is_err());
    }

    #[test]
    fn gaps_move_the_samples_and_outliers_are_dropped() {
        // with gaps of a tenth of a patch, patch 1's middle starts a fifth of a patch in
        let r = sample_rect(0, 0.1);
        let s = 1.0 / 6.5;
        assert!((r[0] - 0.2 * s).abs() < 1e-12 && (r[2] - 0.8 * s).abs() < 1e-12);
        let last = sample_rect(23, 0.1);
        assert!((1.0 - last[2] - 0.2 * s).abs() < 1e-12);
        // a flat patch with a glint, a dead pixel and a NaN: the three are left out
        let mut v = vec![[1.0f32, 2.0, 3.0]; 18];
        v.extend([
            [1000.0, 2.0, 3.0],
            [1.0, -1000.0, 3.0],
            [1.0, 2.0, f32::NAN],
        ]);
        assert_eq!(robust_mean(&v), [1.0, 2.0, 3.0]);
    }

    /// Noise alone is not trimmed: the mean of a patch with Gaussian noise is its plain mean
    /// (a trimmed mean would differ), and a speck in it is still left out.
    #[test]
    fn noise_is_averaged_not_trimmed() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0f64, 0.01).unwrap();
        let mut v: Vec<[f32; 3]> = (0..400)
            .map(|_| {
                let e: [f64; 3] = std::array::from_fn(|_| noise.sample(&mut rng));
                [0.5 + e[0], 0.4 + e[1], 0.3 + e[2]].map(|x| x as f32)
            })
            .collect();
        let plain: Vec<f64> = (0..3)
            .map(|c| v.iter().map(|p| p[c] as f64).sum::<f64>() / v.len() as f64)
            .collect();
        let m = robust_mean(&v);
        for c in 0..3 {
            assert!((m[c] - plain[c]).abs() < 1e-4, "{m:?} {plain:?}");
        }
        v.push([5.0, 5.0, 5.0]);
        let m2 = robust_mean(&v);
        for c in 0..3 {
            assert!((m2[c] - m[c]).abs() < 1e-4, "{m2:?} {m:?}");
        }
    }
}
