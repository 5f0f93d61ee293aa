//! Colorimetry: tristimulus values, xyY, CIELAB, CIEDE2000, sRGB, CCT.
