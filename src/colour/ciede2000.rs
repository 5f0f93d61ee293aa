//! The CIEDE2000 colour difference (Sharma, Wu & Dalal 2005), kL = kC = kH = 1.

use super::Lab;

/// CIEDE2000's weighting functions `S_L`, `S_C`, `S_H` and rotation term
/// `R_T` at mean lightness `l`, mean chroma `cp` and mean hue `hp` (degrees).
struct Weights {
    sl: f64,
    sc: f64,
    sh: f64,
    rt: f64,
}

impl Weights {
    fn at(l: f64, cp: f64, hp: f64) -> Self {
        let deg = std::f64::consts::PI / 180.0;
        let t = 1.0 - 0.17 * ((hp - 30.0) * deg).cos()
            + 0.24 * (2.0 * hp * deg).cos()
            + 0.32 * ((3.0 * hp + 6.0) * deg).cos()
            - 0.20 * ((4.0 * hp - 63.0) * deg).cos();
        let d_theta = 30.0 * (-((hp - 275.0) / 25.0).powi(2)).exp();
        let l50 = (l - 50.0).powi(2);
        Self {
            sl: 1.0 + 0.015 * l50 / (20.0 + l50).sqrt(),
            sc: 1.0 + 0.045 * cp,
            sh: 1.0 + 0.015 * cp * t,
            rt: -(2.0 * d_theta * deg).sin() * 2.0 * chroma7(cp).sqrt(),
        }
    }
}

/// The hue angle `h'` in degrees, [0, 360); 0 for a neutral.
fn hue_deg(b: f64, ap: f64) -> f64 {
    if b == 0.0 && ap == 0.0 {
        0.0
    } else {
        let h = b.atan2(ap) / (std::f64::consts::PI / 180.0);
        if h < 0.0 { h + 360.0 } else { h }
    }
}

/// `C⁷ / (C⁷ + 25⁷)`, the chroma term of `G` and `R_C`.
fn chroma7(c: f64) -> f64 {
    let c7 = c.powi(7);
    c7 / (c7 + 25f64.powi(7))
}

/// ΔE00 between two CIELAB colours, following Sharma, Wu & Dalal (2005),
/// "The CIEDE2000 color-difference formula: implementation notes,
/// supplementary test data, and mathematical observations".
pub fn ciede2000(a: Lab, b: Lab) -> f64 {
    use std::f64::consts::PI;
    let deg = PI / 180.0;
    let [l1, a1, b1] = a;
    let [l2, a2, b2] = b;

    let c1 = a1.hypot(b1);
    let c2 = a2.hypot(b2);
    let g = 0.5 * (1.0 - chroma7(0.5 * (c1 + c2)).sqrt());
    let a1p = (1.0 + g) * a1;
    let a2p = (1.0 + g) * a2;
    let c1p = a1p.hypot(b1);
    let c2p = a2p.hypot(b2);
    let h1p = hue_deg(b1, a1p);
    let h2p = hue_deg(b2, a2p);

    let dlp = l2 - l1;
    let dcp = c2p - c1p;
    let cprod = c1p * c2p;
    let dhp = if cprod == 0.0 {
        0.0
    } else {
        let d = h2p - h1p;
        if d > 180.0 {
            d - 360.0
        } else if d < -180.0 {
            d + 360.0
        } else {
            d
        }
    };
    let big_dhp = 2.0 * cprod.sqrt() * (0.5 * dhp * deg).sin();

    let l_bar = 0.5 * (l1 + l2);
    let cp_bar = 0.5 * (c1p + c2p);
    let hp_bar = if cprod == 0.0 {
        h1p + h2p
    } else if (h1p - h2p).abs() <= 180.0 {
        0.5 * (h1p + h2p)
    } else if h1p + h2p < 360.0 {
        0.5 * (h1p + h2p + 360.0)
    } else {
        0.5 * (h1p + h2p - 360.0)
    };
    let Weights { sl, sc, sh, rt } = Weights::at(l_bar, cp_bar, hp_bar);

    let tl = dlp / sl;
    let tc = dcp / sc;
    let th = big_dhp / sh;
    (tl * tl + tc * tc + th * th + rt * tc * th).max(0.0).sqrt()
}

/// The local metric of CIEDE2000 at `lab`: the symmetric 3×3 matrix `Q` with
/// `ciede2000(lab, lab + d)² = dᵀ Q d` to second order in `d`. It is what a
/// least-squares fit has to weight CIELAB errors by to minimise ΔE00 rather
/// than ΔE76 (for which `Q` is the identity).
///
/// To first order the lightness, chroma and hue differences are linear in
/// `d`: `ΔL' = dL`, and in the `(a', b)` plane (`a' = (1 + G) a`, `G` held at
/// `lab`'s chroma) `ΔC'` and `ΔH'` are the radial and tangential parts of
/// the displacement. With the weights `S_L`, `S_C`, `S_H` and the rotation
/// term `R_T` at `lab`, `Q = Bᵀ D B`, where `B` maps `d` to
/// `(ΔL', ΔC', ΔH')` and `D` holds `1/S_L²`, `1/S_C²`, `1/S_H²` and
/// `R_T / (2 S_C S_H)`. `|R_T| ≤ 2`, so `Q` is positive semi-definite. At a
/// neutral `lab` every direction in the `(a', b)` plane is chroma.
pub fn ciede2000_metric(lab: Lab) -> [[f64; 3]; 3] {
    let [l, a, b] = lab;
    let g = 0.5 * (1.0 - chroma7(a.hypot(b)).sqrt());
    let ap = (1.0 + g) * a;
    let cp = ap.hypot(b);
    // radial (chroma) and tangential (hue) unit vectors in the (a', b) plane
    let (u, v) = if cp > 1e-12 {
        ([ap / cp, b / cp], [-b / cp, ap / cp])
    } else {
        ([1.0, 0.0], [0.0, 1.0])
    };
    let hp = hue_deg(b, ap);
    let Weights { sl, sc, sh, rt } = Weights::at(l, cp, hp);
    // B: (dL, da, db) → (ΔL', ΔC', ΔH'); da enters as (1 + G) da
    let bm = [
        [1.0, 0.0, 0.0],
        [0.0, u[0] * (1.0 + g), u[1]],
        [0.0, v[0] * (1.0 + g), v[1]],
    ];
    let dm = [
        [1.0 / (sl * sl), 0.0, 0.0],
        [0.0, 1.0 / (sc * sc), rt / (2.0 * sc * sh)],
        [0.0, rt / (2.0 * sc * sh), 1.0 / (sh * sh)],
    ];
    [0, 1, 2].map(|i| {
        [0, 1, 2].map(|j| {
            (0..3)
                .map(|p| (0..3).map(|q| bm[p][i] * dm[p][q] * bm[q][j]).sum::<f64>())
                .sum()
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_sharma_pairs() {
        let d = ciede2000([50.0, 2.6772, -79.7751], [50.0, 0.0, -82.7485]);
        assert!((d - 2.0425).abs() < 1e-4, "{d}");
        // Pair 7: achromatic against near-achromatic (hue of zero chroma).
        let d = ciede2000([50.0, 0.0, 0.0], [50.0, -1.0, 2.0]);
        assert!((d - 2.3669).abs() < 1e-4, "{d}");
        assert_eq!(ciede2000([50.0, 10.0, -3.0], [50.0, 10.0, -3.0]), 0.0);
    }

    #[test]
    fn the_metric_at_a_neutral_weighs_a_by_one_and_a_half() {
        // at C = 0, G = 1/2 and every (a, b) displacement is chroma
        let q = ciede2000_metric([50.0, 0.0, 0.0]);
        let d = [0.0, 1e-3, 2e-3];
        let quad: f64 = (0..3)
            .map(|i| (0..3).map(|j| d[i] * q[i][j] * d[j]).sum::<f64>())
            .sum();
        let de = ciede2000([50.0, 0.0, 0.0], [50.0, 1e-3, 2e-3]);
        assert!((quad / (de * de) - 1.0).abs() < 1e-3, "{quad} {}", de * de);
        assert!((q[1][1] - 2.25).abs() < 1e-9 && (q[2][2] - 1.0).abs() < 1e-9);
    }
}
