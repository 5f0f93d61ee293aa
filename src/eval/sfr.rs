//! Sharpness: the ISO 12233 edge spatial frequency response (e-SFR) of a slanted edge.
//!
//! The method of ISO 12233:2017 Annex D (as in its reference implementation, `sfrmat`):
//! 1. The edge is made near-vertical (a near-horizontal edge is transposed) and rising
//!    (a falling edge is negated; the SFR does not change).
//! 2. Per row, the centroid of the Hamming-windowed derivative locates the edge; a line
//!    fitted to the centroids gives its position and slant. A second pass centres each row's
//!    window on the fitted line and fits again.
//! 3. Rows are kept to a whole number of phase cycles of the slant, so every sub-pixel phase
//!    is sampled as often.
//! 4. Every pixel's horizontal distance to the line is binned at 1/4 pixel: the 4×
//!    oversampled edge spread function (ESF). Empty bins are interpolated.
//! 5. Its central difference is the line spread function (LSF), Hamming-windowed about its
//!    centroid. The magnitude of its DFT, over its DC value, is the SFR; it is divided by the
//!    central difference's own response, and its frequency axis is scaled by 1/cos(slant) so it
//!    reads in cycles per pixel across the edge.
//!
//! MTF50 is the first frequency where the SFR falls to 0.5 (linear interpolation between
//! samples). Written here because no crate implements e-SFR; the FFT is `rustfft`'s.

use ndarray::{Array2, ArrayView2};
use rustfft::FftPlanner;
use rustfft::num_complex::Complex;
use serde::{Deserialize, Serialize};

/// Oversampling of the edge spread function (ISO 12233: 4).
pub const OVERSAMPLE: usize = 4;

/// The largest RMS scatter of the rows' edge positions about the fitted line, in pixels:
/// a straight edge at SNR 100 scatters by a few hundredths; rows of texture or noise by
/// pixels.
pub const MAX_SCATTER_PX: f64 = 1.0;

/// The smallest region side, in pixels.
pub const MIN_SIDE: usize = 8;

/// Why an SFR cannot be measured.
#[derive(Debug, thiserror::Error)]
pub enum SfrError {
    #[error("the edge region is {width}×{height}; it needs at least {MIN_SIDE}×{MIN_SIDE} pixels")]
    TooSmall { width: usize, height: usize },
    #[error("the edge region holds a value that is not finite")]
    NotFinite,
    #[error("no edge found: {0}")]
    NoEdge(String),
}

/// Which way the edge runs in the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EdgeOrientation {
    /// Within 45° of vertical: the SFR is measured along rows.
    Vertical,
    /// Within 45° of horizontal: along columns.
    Horizontal,
}

/// An e-SFR measurement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sfr {
    /// The first frequency where the SFR falls to 0.5, cycles per pixel.
    pub mtf50_cycles_per_pixel: f64,
    /// The SFR at half the Nyquist frequency (0.25 cycles per pixel).
    pub mtf_at_half_nyquist: f64,
    /// The SFR at the Nyquist frequency (0.5 cycles per pixel).
    pub mtf_at_nyquist: f64,
    pub orientation: EdgeOrientation,
    /// The edge's angle to the nearest axis, degrees (signed).
    pub slant_degrees: f64,
    /// Whether the edge falls (bright to dark) along its measurement direction.
    pub falling: bool,
    /// The rows (columns for a horizontal edge) used: a whole number of phase cycles.
    pub lines_used: usize,
    /// The SFR curve from 0 to 1 cycle per pixel.
    pub frequencies: Vec<f64>,
    pub sfr: Vec<f64>,
}

/// The e-SFR of the straight edge in `img` (linear values, e.g. luminance Y).
pub fn slanted_edge_sfr(img: ArrayView2<'_, f64>) -> Result<Sfr, SfrError> {
    let (h, w) = img.dim();
    if h < MIN_SIDE || w < MIN_SIDE {
        return Err(SfrError::TooSmall {
            width: w,
            height: h,
        });
    }
    if img.iter().any(|v| !v.is_finite()) {
        return Err(SfrError::NotFinite);
    }
    let orientation = orientation_of(img);
    let mut a: Array2<f64> = match orientation {
        EdgeOrientation::Vertical => img.to_owned(),
        EdgeOrientation::Horizontal => img.t().to_owned(),
    };
    let rise: f64 = a.column(a.ncols() - 1).sum() - a.column(0).sum();
    let falling = rise < 0.0;
    if falling {
        a.mapv_inplace(|v| -v);
    }
    let (offset, slope) = locate_edge(&a)?;
    let lines = whole_phase_cycles(a.nrows(), slope);
    let esf = edge_spread(&a, offset, slope, lines)?;
    let (frequencies, sfr) = spectrum(&esf, slope);
    let at = |f: f64| interpolate_at(&frequencies, &sfr, f);
    let mtf50 = first_crossing(&frequencies, &sfr, 0.5).ok_or_else(|| {
        SfrError::NoEdge("the SFR never falls to 0.5 below 1 cycle per pixel".into())
    })?;
    let out = Sfr {
        mtf50_cycles_per_pixel: mtf50,
        mtf_at_half_nyquist: at(0.25),
        mtf_at_nyquist: at(0.5),
        orientation,
        slant_degrees: slope.atan().to_degrees(),
        falling,
        lines_used: lines,
        frequencies,
        sfr,
    };
    if out
        .sfr
        .iter()
        .chain(&out.frequencies)
        .any(|v| !v.is_finite())
    {
        return Err(SfrError::NoEdge("the SFR is not finite".into()));
    }
    Ok(out)
}

/// Vertical when the values change more along rows than down columns.
fn orientation_of(img: ArrayView2<'_, f64>) -> EdgeOrientation {
    let (h, w) = img.dim();
    let mut along_rows = 0.0;
    let mut down_cols = 0.0;
    for r in 0..h {
        for c in 0..w {
            if c + 1 < w {
                along_rows += (img[[r, c + 1]] - img[[r, c]]).abs();
            }
            if r + 1 < h {
                down_cols += (img[[r + 1, c]] - img[[r, c]]).abs();
            }
        }
    }
    if along_rows >= down_cols {
        EdgeOrientation::Vertical
    } else {
        EdgeOrientation::Horizontal
    }
}

/// A Hamming window of `n` samples centred at `centre` (sample units), as ISO 12233 uses:
/// its half-width is the larger distance from `centre` to the ends.
fn hamming(n: usize, centre: f64) -> Vec<f64> {
    let half = centre.max(n as f64 - 1.0 - centre).max(1.0);
    (0..n)
        .map(|i| {
            let x = (i as f64 - centre) / half; // −1 … 1
            0.54 + 0.46 * (std::f64::consts::PI * x).cos()
        })
        .collect()
}

/// The centroid (in pixel coordinates) of row `r`'s derivative under a window centred at
/// `centre`; the derivative between pixels c and c+1 sits at c + 0.5.
fn row_centroid(a: &Array2<f64>, r: usize, centre: f64) -> Option<f64> {
    let w = a.ncols();
    let win = hamming(w - 1, centre - 0.5);
    let (mut num, mut den) = (0.0, 0.0);
    for c in 0..w - 1 {
        let d = (a[[r, c + 1]] - a[[r, c]]) * win[c];
        num += d * (c as f64 + 0.5);
        den += d;
    }
    (den > 0.0).then(|| num / den)
}

/// Least-squares line `x = offset + slope · row` through the points.
fn fit_line(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = points.len() as f64;
    if points.len() < 2 {
        return None;
    }
    let (sy, sx) = points
        .iter()
        .fold((0.0, 0.0), |(sy, sx), (y, x)| (sy + y, sx + x));
    let (my, mx) = (sy / n, sx / n);
    let (mut syy, mut sxy) = (0.0, 0.0);
    for (y, x) in points {
        syy += (y - my) * (y - my);
        sxy += (y - my) * (x - mx);
    }
    if syy <= 0.0 {
        return None;
    }
    let slope = sxy / syy;
    Some((mx - slope * my, slope))
}

/// The edge line `x = offset + slope · row`, in two passes (ISO 12233 D.3).
fn locate_edge(a: &Array2<f64>) -> Result<(f64, f64), SfrError> {
    let (h, w) = a.dim();
    // first pass: every row's window at the column where the mean derivative peaks
    let peak = (0..w - 1)
        .max_by(|&i, &j| {
            let d = |c: usize| a.column(c + 1).sum() - a.column(c).sum();
            d(i).total_cmp(&d(j))
        })
        .unwrap_or(0) as f64
        + 0.5;
    let first: Vec<(f64, f64)> = (0..h)
        .filter_map(|r| row_centroid(a, r, peak).map(|x| (r as f64, x)))
        .collect();
    let no_edge = || {
        SfrError::NoEdge(
            "the region holds no straight edge with a clear step (crop to one edge, with both sides flat)"
                .into(),
        )
    };
    let (o, s) = fit_line(&first).ok_or_else(no_edge)?;
    let second: Vec<(f64, f64)> = (0..h)
        .filter_map(|r| row_centroid(a, r, o + s * r as f64).map(|x| (r as f64, x)))
        .collect();
    if second.len() < h / 2 {
        return Err(no_edge());
    }
    let (o, s) = fit_line(&second).ok_or_else(no_edge)?;
    let scatter = (second
        .iter()
        .map(|(r, x)| (x - o - s * r).powi(2))
        .sum::<f64>()
        / second.len() as f64)
        .sqrt();
    if scatter > MAX_SCATTER_PX {
        // rows whose derivative nearly cancels (two edges of opposite sense, texture) put
        // their centroids far outside the region: a figure beyond its width means nothing
        let by = if scatter > w as f64 {
            format!("by more than the region is wide ({w} px across the edge)")
        } else {
            format!("by {scatter:.2} px")
        };
        return Err(SfrError::NoEdge(format!(
            "the rows' edge positions scatter {by} about a line (at most {MAX_SCATTER_PX} px for a straight edge), as they do when the region holds two edges or texture; crop to one straight edge"
        )));
    }
    let (lo, hi) = (o.min(o + s * (h - 1) as f64), o.max(o + s * (h - 1) as f64));
    if lo < 1.0 || hi > (w - 1) as f64 || s.abs() > 1.0 {
        return Err(SfrError::NoEdge(format!(
            "the edge leaves the region (columns {lo:.1} to {hi:.1} of {w}); crop so the edge crosses it fully"
        )));
    }
    Ok((o, s))
}

/// The rows spanning a whole number of phase cycles of the slant (all rows when less than
/// one cycle fits).
fn whole_phase_cycles(h: usize, slope: f64) -> usize {
    let cycles = (h as f64 * slope.abs()).floor();
    if cycles < 1.0 {
        return h;
    }
    ((cycles / slope.abs()).round() as usize).clamp(MIN_SIDE.min(h), h)
}

/// The 4× oversampled ESF over the first `lines` rows.
fn edge_spread(
    a: &Array2<f64>,
    offset: f64,
    slope: f64,
    lines: usize,
) -> Result<Vec<f64>, SfrError> {
    let w = a.ncols();
    let n = OVERSAMPLE * w;
    let half = (n / 2) as f64;
    let mut sum = vec![0.0; n];
    let mut count = vec![0u32; n];
    for r in 0..lines {
        let edge = offset + slope * r as f64;
        for c in 0..w {
            let d = c as f64 - edge;
            let k = (d * OVERSAMPLE as f64 + half).floor();
            if k >= 0.0 && (k as usize) < n {
                sum[k as usize] += a[[r, c]];
                count[k as usize] += 1;
            }
        }
    }
    // the span every bin near the edge must fill: ± a quarter of the width
    let (lo, hi) = (n / 4, n - n / 4);
    let empty = (lo..hi).filter(|&k| count[k] == 0).count();
    if empty * 10 > hi - lo {
        return Err(SfrError::NoEdge(format!(
            "{empty} of {} sub-pixel bins near the edge are empty: tilt the edge 2–10° from the axis, or use a taller region",
            hi - lo
        )));
    }
    let filled: Vec<usize> = (0..n).filter(|&k| count[k] > 0).collect();
    let mean = |k: usize| sum[k] / f64::from(count[k]);
    let mut esf = vec![0.0; n];
    for (k, v) in esf.iter_mut().enumerate() {
        *v = if count[k] > 0 {
            mean(k)
        } else {
            let after = filled.partition_point(|&j| j < k);
            match (after.checked_sub(1).map(|i| filled[i]), filled.get(after)) {
                (Some(p), Some(&q)) => {
                    let t = (k - p) as f64 / (q - p) as f64;
                    mean(p) * (1.0 - t) + mean(q) * t
                }
                (Some(p), None) => mean(p),
                (None, Some(&q)) => mean(q),
                (None, None) => 0.0,
            }
        };
    }
    Ok(esf)
}

/// The SFR from 0 to 1 cycle per pixel of the ESF: windowed LSF, |DFT| over DC, divided by
/// the central difference's response, frequencies scaled to the edge normal.
fn spectrum(esf: &[f64], slope: f64) -> (Vec<f64>, Vec<f64>) {
    let n = esf.len();
    let mut lsf = vec![0.0; n];
    for k in 1..n - 1 {
        lsf[k] = 0.5 * (esf[k + 1] - esf[k - 1]);
    }
    let total: f64 = lsf.iter().sum();
    let centre = if total > 0.0 {
        lsf.iter()
            .enumerate()
            .map(|(k, v)| k as f64 * v)
            .sum::<f64>()
            / total
    } else {
        n as f64 / 2.0
    };
    let win = hamming(n, centre);
    let mut buf: Vec<Complex<f64>> = lsf
        .iter()
        .zip(&win)
        .map(|(v, w)| Complex::new(v * w, 0.0))
        .collect();
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    let dc = buf[0].norm().max(f64::MIN_POSITIVE);
    let step = 1.0 / OVERSAMPLE as f64; // bin spacing, pixels
    let normal = 1.0 / slope.atan().cos(); // horizontal → across-edge frequency
    let mut freqs = Vec::new();
    let mut sfr = Vec::new();
    for (k, z) in buf.iter().enumerate().take(n / 2 + 1) {
        let f = k as f64 / (n as f64 * step); // cycles per pixel, horizontally
        let g = f * normal;
        if g > 1.0 + 1e-9 {
            break;
        }
        let x = 2.0 * std::f64::consts::PI * f * step;
        let diff = if x > 0.0 { x.sin() / x } else { 1.0 };
        freqs.push(g);
        sfr.push(z.norm() / dc / diff.max(0.1));
    }
    (freqs, sfr)
}

/// The first frequency where `v` falls to `level`.
fn first_crossing(f: &[f64], v: &[f64], level: f64) -> Option<f64> {
    (1..v.len()).find_map(|i| {
        (v[i - 1] >= level && v[i] < level).then(|| {
            let t = (v[i - 1] - level) / (v[i - 1] - v[i]);
            f[i - 1] + t * (f[i] - f[i - 1])
        })
    })
}

/// `v` at frequency `x` (linear interpolation; the last value beyond the curve).
fn interpolate_at(f: &[f64], v: &[f64], x: f64) -> f64 {
    match f.iter().position(|&g| g >= x) {
        Some(0) => v[0],
        Some(i) => {
            let t = (x - f[i - 1]) / (f[i] - f[i - 1]);
            v[i - 1] + t * (v[i] - v[i - 1])
        }
        None => v.last().copied().unwrap_or(f64::NAN),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// The standard normal CDF, from `erfc` by its Chebyshev fit (W. H. Press et al.,
    /// accurate to 1.2e-7).
    fn phi(x: f64) -> f64 {
        let z = (x / std::f64::consts::SQRT_2).abs();
        let t = 1.0 / (1.0 + 0.5 * z);
        let poly = -z * z - 1.26551223
            + t * (1.00002368
                + t * (0.37409196
                    + t * (0.09678418
                        + t * (-0.18628806
                            + t * (0.27886807
                                + t * (-1.13520398
                                    + t * (1.48851973 + t * (-0.82215223 + t * 0.17087277))))))));
        let erfc = t * poly.exp();
        if x >= 0.0 {
            1.0 - 0.5 * erfc
        } else {
            0.5 * erfc
        }
    }

    /// A vertical edge slanted by `deg`, blurred by a Gaussian of `sigma` px, point-sampled,
    /// from 0.2 to 0.8, with Gaussian noise of contrast/`snr` (none when `snr` is 0).
    fn edge(w: usize, h: usize, deg: f64, sigma: f64, snr: f64, seed: u64) -> Array2<f64> {
        let th = deg.to_radians();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, if snr > 0.0 { 0.6 / snr } else { 0.0 }).unwrap();
        Array2::from_shape_fn((h, w), |(r, c)| {
            let x_edge = w as f64 / 2.0 + (r as f64 - h as f64 / 2.0) * th.tan();
            let d = (c as f64 - x_edge) * th.cos();
            0.2 + 0.6 * phi(d / sigma) + noise.sample(&mut rng)
        })
    }

    fn analytic(sigma: f64) -> f64 {
        (2f64.ln() / (2.0 * std::f64::consts::PI.powi(2) * sigma * sigma)).sqrt()
    }

    #[test]
    fn mtf50_of_gaussian_edges_is_within_3_percent() {
        for sigma in [0.6, 1.0, 1.5] {
            for deg in [4.0, 5.0, 6.0, -5.0] {
                let s = slanted_edge_sfr(edge(64, 96, deg, sigma, 0.0, 1).view()).unwrap();
                let err = s.mtf50_cycles_per_pixel / analytic(sigma) - 1.0;
                assert!(err.abs() < 0.03, "σ {sigma} at {deg}°: {err:+.4}");
                assert!((s.slant_degrees - deg).abs() < 0.2, "{}", s.slant_degrees);
            }
        }
    }

    #[test]
    fn noise_at_snr_100_stays_within_5_percent() {
        for sigma in [0.6, 1.0, 1.5] {
            for seed in 1..4 {
                let s = slanted_edge_sfr(edge(64, 96, 5.0, sigma, 100.0, seed).view()).unwrap();
                let err = s.mtf50_cycles_per_pixel / analytic(sigma) - 1.0;
                assert!(err.abs() < 0.05, "σ {sigma} seed {seed}: {err:+.4}");
            }
        }
    }

    #[test]
    fn polarity_and_orientation_do_not_change_the_answer() {
        let e = edge(64, 96, 5.0, 1.0, 0.0, 1);
        let base = slanted_edge_sfr(e.view()).unwrap();
        assert_eq!(base.orientation, EdgeOrientation::Vertical);
        assert!(!base.falling);
        let flipped = e.mapv(|v| 1.0 - v);
        let horizontal = e.t().to_owned();
        let mirrored = e.slice(ndarray::s![.., ..;-1]).to_owned();
        for (what, img) in [
            ("falling", flipped),
            ("horizontal", horizontal),
            ("mirrored", mirrored),
        ] {
            let s = slanted_edge_sfr(img.view()).unwrap();
            let rel = s.mtf50_cycles_per_pixel / base.mtf50_cycles_per_pixel - 1.0;
            assert!(rel.abs() < 0.01, "{what}: {rel:+.4}");
        }
        let h = slanted_edge_sfr(e.t()).unwrap();
        assert_eq!(h.orientation, EdgeOrientation::Horizontal);
        assert!(
            slanted_edge_sfr(e.mapv(|v| 1.0 - v).view())
                .unwrap()
                .falling
        );
    }

    #[test]
    fn what_is_not_an_edge_is_refused() {
        let flat = Array2::from_elem((32, 32), 0.5);
        assert!(matches!(
            slanted_edge_sfr(flat.view()),
            Err(SfrError::NoEdge(_))
        ));
        let small = Array2::from_elem((4, 32), 0.5);
        assert!(matches!(
            slanted_edge_sfr(small.view()),
            Err(SfrError::TooSmall { .. })
        ));
        let mut nan = edge(32, 32, 5.0, 1.0, 0.0, 1);
        nan[[3, 3]] = f64::NAN;
        assert!(matches!(
            slanted_edge_sfr(nan.view()),
            Err(SfrError::NotFinite)
        ));
        // texture is not an edge
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let noise = Normal::new(0.5, 0.2).unwrap();
        let texture = Array2::from_shape_fn((48, 48), |_| noise.sample(&mut rng));
        assert!(matches!(
            slanted_edge_sfr(texture.view()),
            Err(SfrError::NoEdge(_))
        ));
        // an edge at exactly 0° leaves sub-pixel bins empty
        let straight = edge(32, 32, 0.0, 1.0, 0.0, 1);
        assert!(slanted_edge_sfr(straight.view()).is_err());
    }

    /// The scatter a refusal quotes, in px, if it quotes one.
    fn quoted_scatter(message: &str) -> Option<f64> {
        let rest = message.split("scatter by ").nth(1)?;
        rest.split(" px").next()?.parse().ok()
    }

    /// Texture, or two edges, can scatter the rows' centroids far outside the region: the
    /// refusal then says the scatter exceeds the region's width rather than quoting a figure
    /// larger than it.
    #[test]
    fn a_scatter_beyond_the_region_is_not_quoted() {
        let noise = |x: usize, y: usize, k: usize| {
            ((x * 7919 + y * 104729 + k * 31337) % 1000) as f64 / 1000.0 - 0.5
        };
        let mut regions = Vec::new();
        for k in 0..12 {
            for side in [48, 64] {
                regions.push(Array2::from_shape_fn((side, side), |(r, c)| {
                    0.5 + 0.4 * noise(c, r, k)
                }));
            }
        }
        // a bright bar: a rising and a falling edge
        for (x0, x1) in [(60.0, 66.0), (60.0, 70.0), (40.0, 88.0)] {
            regions.push(Array2::from_shape_fn((128, 128), |(r, c)| {
                let x = c as f64 - (r as f64 - 64.0) * 5f64.to_radians().tan();
                0.2 + 0.6 * (phi(x - x0) - phi(x - x1))
            }));
        }
        let mut beyond = 0;
        for region in &regions {
            let width = region.ncols().max(region.nrows()) as f64;
            if let Err(SfrError::NoEdge(m)) = slanted_edge_sfr(region.view()) {
                if let Some(px) = quoted_scatter(&m) {
                    assert!(px <= width, "{m}");
                }
                if m.contains("more than the region is wide") {
                    assert!(m.contains("crop to one straight edge"), "{m}");
                    beyond += 1;
                }
            }
        }
        assert!(beyond > 0, "no region scattered beyond its width");
    }
}
