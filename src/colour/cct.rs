//! Correlated colour temperature: the nearest point on the Planckian locus in
//! the CIE 1960 (u, v) diagram, with the locus computed from Planck's law and
//! the CIE 1931 observer at 1 nm (the definition Robertson's 1968 table
//! approximates), so the result does not carry the table's interpolation
//! error.

use std::sync::OnceLock;

use crate::spectral::cie1931_cmfs;

use super::{ColourError, Xyz, xy};

/// Second radiation constant c₂ = hc/k, in m·K (CODATA 2018).
const C2: f64 = 1.438_776_877e-2;
/// The CCT domain, in kelvin.
const T_MIN: f64 = 1000.0;
const T_MAX: f64 = 100_000.0;
const DOMAIN: &str = "1000–100000 K";
/// Largest distance from the locus for which a CCT is defined (CIE 15).
const MAX_DUV: f64 = 0.05;

struct Observer1nm {
    wavelengths_m: Vec<f64>,
    cmf: [Vec<f64>; 3],
}

fn observer() -> &'static Observer1nm {
    static OBS: OnceLock<Observer1nm> = OnceLock::new();
    OBS.get_or_init(|| {
        let [x, y, z] = cie1931_cmfs();
        Observer1nm {
            wavelengths_m: x.wavelengths().iter().map(|w| w * 1e-9).collect(),
            cmf: [
                x.values().to_vec(),
                y.values().to_vec(),
                z.values().to_vec(),
            ],
        }
    })
}

/// XYZ (arbitrary scale) of a blackbody at `t` kelvin.
fn planck_xyz(t: f64) -> Xyz {
    let obs = observer();
    let mut acc = [0.0; 3];
    for (i, &l) in obs.wavelengths_m.iter().enumerate() {
        // Relative spectral radiance; the 1e-9 scaling keeps values near 1.
        let ln = l * 1e6;
        let p = 1.0 / (ln.powi(5) * (C2 / (l * t)).exp_m1());
        for (a, c) in acc.iter_mut().zip(&obs.cmf) {
            *a += c[i] * p;
        }
    }
    acc
}

/// CIE 1960 (u, v) of a chromaticity (x, y).
pub fn xy_to_uv(xy: [f64; 2]) -> [f64; 2] {
    let d = -2.0 * xy[0] + 12.0 * xy[1] + 3.0;
    [4.0 * xy[0] / d, 6.0 * xy[1] / d]
}

fn xyz_to_uv(v: Xyz) -> [f64; 2] {
    let d = v[0] + 15.0 * v[1] + 3.0 * v[2];
    [4.0 * v[0] / d, 6.0 * v[1] / d]
}

fn check_t(t: f64) -> Result<(), ColourError> {
    if t.is_finite() && (T_MIN..=T_MAX).contains(&t) {
        Ok(())
    } else {
        Err(ColourError::TemperatureOutOfRange(t, DOMAIN))
    }
}

/// Chromaticity (x, y) of a blackbody at `cct` kelvin (1000–100000 K).
pub fn planck_xy(cct: f64) -> Result<[f64; 2], ColourError> {
    check_t(cct)?;
    Ok(xy(planck_xyz(cct)))
}

/// Chromaticity (x, y) of CIE daylight at `cct` kelvin (4000–25000 K), from
/// the CIE daylight-locus polynomials.
pub fn daylight_xy(cct: f64) -> Result<[f64; 2], ColourError> {
    if !(cct.is_finite() && (4000.0..=25_000.0).contains(&cct)) {
        return Err(ColourError::TemperatureOutOfRange(cct, "4000–25000 K"));
    }
    let t = cct;
    let x = if t <= 7000.0 {
        -4.6070e9 / t.powi(3) + 2.9678e6 / t.powi(2) + 0.09911e3 / t + 0.244063
    } else {
        -2.0064e9 / t.powi(3) + 1.9018e6 / t.powi(2) + 0.24748e3 / t + 0.237040
    };
    Ok([x, -3.0 * x * x + 2.870 * x - 0.275])
}

/// Locus (u, v) sampled every 2 mired from T_MAX to T_MIN, for the coarse
/// search.
fn coarse_locus() -> &'static [(f64, [f64; 2])] {
    static TABLE: OnceLock<Vec<(f64, [f64; 2])>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let (m0, m1) = (1e6 / T_MAX, 1e6 / T_MIN);
        let n = ((m1 - m0) / 2.0).round() as usize;
        (0..=n)
            .map(|i| {
                let m = m0 + (m1 - m0) * i as f64 / n as f64;
                (m, xyz_to_uv(planck_xyz(1e6 / m)))
            })
            .collect()
    })
}

/// CCT (kelvin) and Duv (signed distance from the Planckian locus in the
/// CIE 1960 diagram, positive above it) of a chromaticity.
pub fn cct_duv_from_xy(xy: [f64; 2]) -> Result<(f64, f64), ColourError> {
    let [x, y] = xy;
    let out = |why: &str| ColourError::CctOutOfRange {
        x,
        y,
        why: why.to_string(),
    };
    if !(x.is_finite() && y.is_finite()) {
        return Err(out("not finite"));
    }
    if !(x > 0.0 && y > 0.0 && x + y < 1.0) {
        return Err(out("not a chromaticity (need x > 0, y > 0, x + y < 1)"));
    }
    let [u, v] = xy_to_uv(xy);
    let dist2 = |p: [f64; 2]| (p[0] - u).powi(2) + (p[1] - v).powi(2);
    let table = coarse_locus();
    let mut best = 0;
    let mut best_d = f64::INFINITY;
    for (i, (_, p)) in table.iter().enumerate() {
        let d = dist2(*p);
        if d < best_d {
            best_d = d;
            best = i;
        }
    }
    let lo = table[best.saturating_sub(1)].0;
    let hi = table[(best + 1).min(table.len() - 1)].0;
    // Golden-section search over mired in [lo, hi].
    let f = |m: f64| dist2(xyz_to_uv(planck_xyz(1e6 / m)));
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (lo, hi);
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    while b - a > 1e-7 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    let m = 0.5 * (a + b);
    let t = 1e6 / m;
    let [pu, pv] = xyz_to_uv(planck_xyz(t));
    let duv = ((u - pu).powi(2) + (v - pv).powi(2)).sqrt() * if v >= pv { 1.0 } else { -1.0 };
    if duv.abs() > MAX_DUV {
        return Err(out(&format!(
            "{:.4} from the Planckian locus (limit {MAX_DUV})",
            duv.abs()
        )));
    }
    let edge = 0.5;
    if t < T_MIN + edge || t > T_MAX * (1.0 - 1e-5) {
        return Err(out(&format!("nearest locus point is beyond {DOMAIN}")));
    }
    Ok((t, duv))
}

/// Correlated colour temperature (kelvin) of a chromaticity; an error when the
/// point is more than 0.05 (Duv) from the Planckian locus or outside
/// 1000–100000 K.
pub fn cct_from_xy(xy: [f64; 2]) -> Result<f64, ColourError> {
    cct_duv_from_xy(xy).map(|(t, _)| t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planck_round_trip() {
        for t in [1500.0, 2856.0, 4000.0, 6504.0, 10_000.0, 40_000.0] {
            let p = planck_xy(t).unwrap();
            let (c, duv) = cct_duv_from_xy(p).unwrap();
            assert!((c - t).abs() / t < 1e-6, "{t} → {c}");
            assert!(duv.abs() < 1e-9);
        }
        // Known locus point: 2856 K ≈ (0.4476, 0.4074) (CIE A).
        let a = planck_xy(2856.0).unwrap();
        assert!(
            (a[0] - 0.44757).abs() < 2e-4 && (a[1] - 0.40745).abs() < 2e-4,
            "{a:?}"
        );
    }

    #[test]
    fn daylight_locus_and_errors() {
        let d = daylight_xy(6504.0).unwrap();
        assert!(
            (d[0] - 0.3127).abs() < 2e-4 && (d[1] - 0.3291).abs() < 2e-4,
            "{d:?}"
        );
        let (t, duv) = cct_duv_from_xy(d).unwrap();
        assert!((t - 6504.0).abs() < 10.0, "{t}");
        assert!(duv > 0.0);
        assert!(cct_from_xy([0.7, 0.29]).is_err()); // far off the locus
        assert!(cct_from_xy([f64::NAN, 0.3]).is_err());
        assert!(cct_from_xy([0.5, 0.6]).is_err());
        assert!(planck_xy(10.0).is_err());
        assert!(daylight_xy(3000.0).is_err());
    }
}
