//! Rendering a mosaic with a table: the reference renderer (`reference.rs`: simple,
//! parallel over rows), the fast renderer ([`FastRenderer`], docs/design.md §9: the same classes
//! and kernels, organised for speed), the chroma stage at low light ([`chroma`]) and the
//! output encodings (`output.rs`).

pub mod chroma;
pub(super) mod error;
mod fast;
pub(super) mod output;
pub(super) mod reference;

pub use chroma::{ChromaMode, ChromaStage, UnknownChromaMode};
pub use error::RenderError;
pub use fast::{DnScale, FastOptions, FastRenderer, Frame, Mosaic, Region};
pub use output::{
    WHITE_GRID, WhiteLevel, linear_srgb_matrix, white_from_samples, white_sample_points, white_y,
    xyz_to_srgb8, xyz_to_srgb16,
};
pub use reference::{
    RenderStats, fuse_entry, fuse_kernels, render_reference, render_reference_under,
    resolve_sat_case,
};
