//! What a DNG says of the light and its camera besides the pixels.

use super::*;

#[test]
fn as_shot_white_xy_is_read_and_names_the_light_without_a_neutral() {
    let (w, h) = (4, 4);
    let img = ramp(w, h, 16);
    let b = Builder::new(true);
    let xy = b.rational(50729, &[(4476, 10000), (4074, 10000)]);
    let d = decode_dng(
        &strips_dng(true, &img, w, h, 16, h, vec![xy.clone()]),
        &lim(),
    )
    .unwrap();
    assert_eq!(d.info.as_shot_white_xy, Some([0.4476, 0.4074]));
    assert_eq!(d.info.as_shot_neutral, None);
    assert_eq!(
        d.info.white_xy_light().as_deref(),
        Some("xy:0.447600,0.407400")
    );
    // with AsShotNeutral too, the neutral says the light
    let neutral = b.rational(50728, &[(1, 2), (1, 1), (1, 1), (4, 5)]);
    let both = strips_dng(true, &img, w, h, 16, h, vec![xy, neutral]);
    let d = decode_dng(&both, &lim()).unwrap();
    assert!(d.info.as_shot_white_xy.is_some() && d.info.as_shot_neutral.is_some());
    assert_eq!(d.info.white_xy_light(), None);
    // one value, or a zero, is no chromaticity
    for bad in [
        b.rational(50729, &[(1, 3)]),
        b.rational(50729, &[(0, 1), (1, 3)]),
    ] {
        let e = decode_dng(&strips_dng(true, &img, w, h, 16, h, vec![bad]), &lim())
            .unwrap_err()
            .to_string();
        assert!(e.contains("AsShotWhiteXY"), "{e}");
    }
}

#[test]
fn default_crop_rationals_round_to_nearest() {
    let (w, h) = (8, 6);
    let img = ramp(w, h, 16);
    let b = Builder::new(false);
    let extra = vec![
        b.rational(50719, &[(1, 4), (3, 4)]),  // 0.25 → 0, 0.75 → 1
        b.rational(50720, &[(31, 4), (9, 2)]), // 7.75 → 8, 4.5 → 5
    ];
    let d = decode_dng(&strips_dng(false, &img, w, h, 16, h, extra), &lim()).unwrap();
    assert_eq!((d.frame.width, d.frame.height), (8, 5));
    assert_eq!(d.frame.data[0], img[w]);
    assert_eq!(d.cfa, "WB/RG");
}
