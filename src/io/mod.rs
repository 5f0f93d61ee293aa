//! File formats: raw sensor frames with JSON sidecars, PNG, TIFF, DNG, PGM (input) and PPM
//! (output).
//!
//! Every decoder treats its input as hostile: it checks the declared size against a caller's
//! [`Limits`] before allocating pixel memory, never panics, and reports what was wrong in an
//! [`IoError`]. Writers write atomically (a temporary file in the same directory, fsynced,
//! then a rename and an fsync of the directory); the `encode_*` functions return in-memory
//! files for HTTP responses.

mod atomic;
mod dng;
mod error;
mod icc;
mod jpeg;
mod limits;
mod luminance;
mod mosaic;
mod pgm;
mod png_bands;
mod png_format;
mod ppm;
mod raw;
mod tiff_format;

pub(crate) use atomic::{is_temp_of, write_bytes_atomic, write_bytes_atomic_then};
pub use dng::{
    DngCamera, DngImage, DngInfo, DngWriteInfo, decode_dng, encode_dng, exif_light_source, is_dng,
    read_camera, write_dng,
};
pub use error::{IoError, IoResult};
pub use icc::{SRGB_PROFILE_DESCRIPTION, srgb_profile};
pub use jpeg::{
    DEFAULT_JPEG_QUALITY, InvalidJpegQuality, JpegOptions, JpegQuality, Subsampling,
    UnknownSubsampling, encode_jpeg_rgb8,
};
pub use limits::Limits;
pub use luminance::{Transfer, decode_luminance};
pub use mosaic::{
    DecodedMosaic, LoadedMosaic, MosaicFormat, SourceInfo, decode_mosaic, decode_mosaic_with_info,
    decode_mosaic_with_meta, detect_format, read_mosaic,
};
pub use png_format::{
    PngCompression, UnknownPngCompression, decode_png_rgb8, encode_png_gray16, encode_png_rgb8,
    write_png_gray16, write_png_rgb8,
};
pub use ppm::{encode_ppm_rgb8, ppm_header};
pub use raw::{
    MAX_SIDECAR_BYTES, RawFrame, RawMeta, RawPaths, decode_raw_u16_le, encode_raw_u16_le, read_raw,
    read_sidecar, write_raw, write_raw_to,
};
pub use tiff_format::{
    decode_tiff_f32_rgb, decode_tiff_rgb16, encode_tiff_f32_rgb, encode_tiff_gray_f32,
    encode_tiff_gray16, encode_tiff_rgb16, read_tiff_f32_rgb, read_tiff_rgb16, write_tiff_f32_rgb,
    write_tiff_gray_f32, write_tiff_gray16, write_tiff_rgb16,
};
