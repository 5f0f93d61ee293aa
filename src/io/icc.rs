//! The sRGB ICC profile that 8-bit outputs embed to declare their colour space.
//!
//! Built here from the published definition rather than shipped as a file: an ICC v2.1
//! display profile (`mntr`, RGB → XYZ) whose colourants are the sRGB primaries (IEC 61966-2-1)
//! chromatically adapted to the D50 profile connection space with the Bradford transform,
//! whose white point is D50 (the adapted white), and whose three tone curves share one
//! 1024-point table of the sRGB decoding function. Nothing is copied from a third-party
//! profile; the numbers are the standard's. About 2.6 kB.

use std::sync::OnceLock;

/// The sRGB colourants adapted to D50 (Bradford): columns R, G, B of the RGB → XYZ matrix.
const COLOURANTS: [[f64; 3]; 3] = [
    [0.436_074_7, 0.222_504_5, 0.013_932_2],
    [0.385_064_9, 0.716_878_6, 0.097_104_5],
    [0.143_080_4, 0.060_616_9, 0.714_173_3],
];

/// The D50 white of the profile connection space (the ICC's rounding).
const D50: [f64; 3] = [0.9642, 1.0, 0.8249];

/// Points in the shared tone curve.
const CURVE_POINTS: usize = 1024;

/// The profile's description (`desc`).
pub const SRGB_PROFILE_DESCRIPTION: &str = "sRGB IEC61966-2.1";

/// The sRGB ICC profile bytes (built once).
pub fn srgb_profile() -> &'static [u8] {
    static PROFILE: OnceLock<Vec<u8>> = OnceLock::new();
    PROFILE.get_or_init(build_srgb_profile)
}

fn s15_fixed16(v: f64) -> [u8; 4] {
    ((v * 65536.0).round() as i32).to_be_bytes()
}

fn xyz_tag(xyz: [f64; 3]) -> Vec<u8> {
    let mut t = b"XYZ \0\0\0\0".to_vec();
    for v in xyz {
        t.extend_from_slice(&s15_fixed16(v));
    }
    t
}

/// `textDescriptionType` (ICC v2): the ASCII description, no Unicode or ScriptCode text.
fn desc_tag(text: &str) -> Vec<u8> {
    let mut t = b"desc\0\0\0\0".to_vec();
    t.extend_from_slice(&(text.len() as u32 + 1).to_be_bytes());
    t.extend_from_slice(text.as_bytes());
    t.push(0);
    t.extend_from_slice(&[0; 4]); // Unicode language code
    t.extend_from_slice(&[0; 4]); // Unicode count
    t.extend_from_slice(&[0; 2]); // ScriptCode code
    t.push(0); // ScriptCode count
    t.extend_from_slice(&[0; 67]);
    t
}

fn text_tag(text: &str) -> Vec<u8> {
    let mut t = b"text\0\0\0\0".to_vec();
    t.extend_from_slice(text.as_bytes());
    t.push(0);
    t
}

/// The sRGB decoding function (IEC 61966-2-1) sampled at `CURVE_POINTS` points.
fn curve_tag() -> Vec<u8> {
    let mut t = b"curv\0\0\0\0".to_vec();
    t.extend_from_slice(&(CURVE_POINTS as u32).to_be_bytes());
    for i in 0..CURVE_POINTS {
        let v = i as f64 / (CURVE_POINTS - 1) as f64;
        let lin = if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        };
        t.extend_from_slice(&((lin * 65535.0).round() as u16).to_be_bytes());
    }
    t
}

fn build_srgb_profile() -> Vec<u8> {
    let curve = curve_tag();
    // (signature, data); the three curves point at one copy of `curve`
    let data: [(&[u8; 4], Vec<u8>); 7] = [
        (b"desc", desc_tag(SRGB_PROFILE_DESCRIPTION)),
        (b"cprt", text_tag("No copyright, use freely")),
        (b"wtpt", xyz_tag(D50)),
        (b"rXYZ", xyz_tag(COLOURANTS[0])),
        (b"gXYZ", xyz_tag(COLOURANTS[1])),
        (b"bXYZ", xyz_tag(COLOURANTS[2])),
        (b"rTRC", curve),
    ];
    let tags = data.len() + 2;
    let mut offset = 128 + 4 + 12 * tags;
    let mut table = Vec::new();
    let mut body = Vec::new();
    let mut curve_at = (0, 0);
    for (sig, bytes) in &data {
        table.push((**sig, offset, bytes.len()));
        if *sig == b"rTRC" {
            curve_at = (offset, bytes.len());
        }
        body.extend_from_slice(bytes);
        offset += bytes.len();
        while !offset.is_multiple_of(4) {
            body.push(0);
            offset += 1;
        }
    }
    table.push((*b"gTRC", curve_at.0, curve_at.1));
    table.push((*b"bTRC", curve_at.0, curve_at.1));

    let mut p = Vec::with_capacity(offset);
    p.extend_from_slice(&(offset as u32).to_be_bytes());
    p.extend_from_slice(&[0; 4]); // preferred CMM
    p.extend_from_slice(&[2, 0x10, 0, 0]); // version 2.1
    p.extend_from_slice(b"mntrRGB XYZ ");
    // creation date: 2026-01-01 00:00:00
    for v in [2026u16, 1, 1, 0, 0, 0] {
        p.extend_from_slice(&v.to_be_bytes());
    }
    p.extend_from_slice(b"acsp");
    p.extend_from_slice(&[0; 24]); // platform, flags, manufacturer, model, attributes
    p.extend_from_slice(&[0; 4]); // rendering intent: perceptual
    for v in D50 {
        p.extend_from_slice(&s15_fixed16(v));
    }
    p.extend_from_slice(&[0; 4]); // creator
    p.extend_from_slice(&[0; 44]); // profile ID and reserved
    debug_assert_eq!(p.len(), 128);
    p.extend_from_slice(&(tags as u32).to_be_bytes());
    for (sig, off, len) in table {
        p.extend_from_slice(&sig);
        p.extend_from_slice(&(off as u32).to_be_bytes());
        p.extend_from_slice(&(len as u32).to_be_bytes());
    }
    p.extend_from_slice(&body);
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    fn u32_at(p: &[u8], at: usize) -> usize {
        u32::from_be_bytes(p[at..at + 4].try_into().unwrap()) as usize
    }

    #[test]
    fn profile_is_well_formed() {
        let p = srgb_profile();
        assert_eq!(u32_at(p, 0), p.len());
        assert_eq!(&p[36..40], b"acsp");
        assert_eq!(&p[12..24], b"mntrRGB XYZ ");
        let n = u32_at(p, 128);
        let mut sigs = Vec::new();
        for i in 0..n {
            let e = 132 + 12 * i;
            let (off, len) = (u32_at(p, e + 4), u32_at(p, e + 8));
            assert!(off.is_multiple_of(4) && off + len <= p.len());
            sigs.push(std::str::from_utf8(&p[e..e + 4]).unwrap().to_string());
        }
        for want in [
            "desc", "cprt", "wtpt", "rXYZ", "gXYZ", "bXYZ", "rTRC", "gTRC", "bTRC",
        ] {
            assert!(sigs.iter().any(|s| s == want), "{want} missing");
        }
        // the colourants add up to the D50 white
        for (c, &w) in D50.iter().enumerate() {
            let sum: f64 = COLOURANTS.iter().map(|col| col[c]).sum();
            assert!((sum - w).abs() < 1e-3, "{c}: {sum} vs {w}");
        }
    }

    #[test]
    fn curve_is_the_srgb_decoding() {
        let t = curve_tag();
        let at = |i: usize| u16::from_be_bytes([t[12 + 2 * i], t[13 + 2 * i]]);
        assert_eq!(at(0), 0);
        assert_eq!(at(CURVE_POINTS - 1), 65535);
        // sRGB 0.5 is 21.4 % linear
        let mid = f64::from(at(CURVE_POINTS / 2)) / 65535.0;
        assert!((mid - 0.2145).abs() < 2e-3, "{mid}");
    }
}
