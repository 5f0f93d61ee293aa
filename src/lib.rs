//! l3 — the L3 (Local, Linear, Learned) camera pipeline.
//!
//! The crate is layered:
//! - a pure numeric core with no knowledge of HTTP or SQL:
//!   [`spectral`] (wavelength grids, spectra, built-in and CSV data),
//!   [`colour`] (XYZ, CIELAB, CIEDE2000, sRGB, CCT),
//!   [`camera`] (optics and sensor simulation),
//!   [`scene`] (charts, textures and images as spectral scenes),
//!   [`l3`] (classification, training, tables, rendering, illuminant correction),
//!   [`baseline`] (the conventional pipeline L3 is compared with),
//!   [`eval`] (ΔE2000 reports, the paper's Table 1);
//! - file formats in [`io`];
//! - [`pipeline`]: one render request end to end (bytes or a decoded mosaic → levels, CFA
//!   check, light, kernels → render → encoded output), what `l3 render` and the service run;
//! - the command line in [`cli`], which only calls the core;
//! - the HTTP render service in [`service`], which depends on the core (never the reverse).
//!
//! Test support (the synthetic-table fixture and the fuzz bodies) is compiled only for the
//! crate's own tests and with the `test-support` feature, never into a release build.

// Index loops read best in numeric kernels.
#![allow(clippy::needless_range_loop)]

pub mod baseline;
pub mod bench;
pub mod buffers;
pub mod camera;
pub mod cli;
pub mod colour;
pub mod eval;
#[cfg(feature = "test-support")]
pub mod fuzzing;
pub mod io;
pub mod l3;
pub mod pipeline;
pub mod scene;
pub mod service;
pub mod spectral;
#[cfg(any(test, feature = "test-support"))]
pub mod test_support;
