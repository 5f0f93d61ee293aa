//! The L3 method: classify each sensor pixel by CFA position, response level, saturation
//! case, local contrast and (optionally) chroma, and apply the class's learned affine kernel
//! to its patch (docs/design.md §2, §5).
//!
//! The pipeline, by module:
//! - [`params`]: what a table is made with ([`L3Params`]: patch size, levels, the ridge,
//!   the colour-map fit, chroma classes);
//! - [`classify`]: the patch geometry and per-pixel class statistics, and the chroma classes;
//! - [`learn`]: training a table from the camera simulation, in one process or in shards
//!   whose partial sums merge bit for bit: the training scenes and frames, the normal
//!   equations and their ridge solution, the colour maps that fix every kernel's colour;
//! - [`table`]: the trained table ([`L3Table`]) and its checksummed file format;
//! - [`correct`]: the illuminant correction of a same-illuminant table's output: the
//!   paper's T and the registry of named lights, the camera-aware C fitted on the table's
//!   own colour maps, the light estimated from the frame, and the kernels for a light the
//!   table was not trained under;
//! - [`render`]: the reference and the fast renderer, and the output encodings.
//!
//! Dependencies run one way: `learn` uses the others; `table`, `classify`, `correct` and
//! `render` never use `learn`. The conventional pipeline L3 is compared with is the
//! crate's `baseline` module.

pub mod classify;
pub mod correct;
pub mod learn;
pub mod params;
pub mod render;
pub mod table;

pub use params::L3Params;
pub use table::L3Table;

#[cfg(test)]
mod tests;
