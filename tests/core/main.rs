//! The library's core, one test binary: spectral data, colour, scenes, the camera simulator,
//! training, the reference and fast renderers, their numerical stability and property tests.
//!
//! Proptest keeps the failing cases of `tests/<binary>/<module>.rs` in
//! `tests/proptest-regressions/<module>.txt` (its default persistence, `SourceParallel`, takes
//! the directory holding `main.rs` as the root) and replays them first.

mod colour_reference;
mod fast_render;
mod iset_reference;
mod macbeth_ideal;
mod partial_sums;
mod properties;
mod render_properties;
mod scenes;
mod simulator;
mod spectral_data;
mod stability;
mod training;
