//! The CIEDE2000 colour difference (Sharma, Wu & Dalal 2005), kL = kC = kH = 1.

use super::Lab;

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
    let c_bar = 0.5 * (c1 + c2);
    let c_bar7 = c_bar.powi(7);
    let g = 0.5 * (1.0 - (c_bar7 / (c_bar7 + 25f64.powi(7))).sqrt());
    let a1p = (1.0 + g) * a1;
    let a2p = (1.0 + g) * a2;
    let c1p = a1p.hypot(b1);
    let c2p = a2p.hypot(b2);
    let hue = |bb: f64, ap: f64| -> f64 {
        if bb == 0.0 && ap == 0.0 {
            0.0
        } else {
            let h = bb.atan2(ap) / deg;
            if h < 0.0 { h + 360.0 } else { h }
        }
    };
    let h1p = hue(b1, a1p);
    let h2p = hue(b2, a2p);

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
    let t = 1.0 - 0.17 * ((hp_bar - 30.0) * deg).cos()
        + 0.24 * (2.0 * hp_bar * deg).cos()
        + 0.32 * ((3.0 * hp_bar + 6.0) * deg).cos()
        - 0.20 * ((4.0 * hp_bar - 63.0) * deg).cos();
    let d_theta = 30.0 * (-((hp_bar - 275.0) / 25.0).powi(2)).exp();
    let cp_bar7 = cp_bar.powi(7);
    let rc = 2.0 * (cp_bar7 / (cp_bar7 + 25f64.powi(7))).sqrt();
    let l50 = (l_bar - 50.0).powi(2);
    let sl = 1.0 + 0.015 * l50 / (20.0 + l50).sqrt();
    let sc = 1.0 + 0.045 * cp_bar;
    let sh = 1.0 + 0.015 * cp_bar * t;
    let rt = -(2.0 * d_theta * deg).sin() * rc;

    let tl = dlp / sl;
    let tc = dcp / sc;
    let th = big_dhp / sh;
    (tl * tl + tc * tc + th * th + rt * tc * th).max(0.0).sqrt()
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
}
