//! AVX-512 kernels of the fast renderer, for 2×2 CFAs (RGBW, Bayer) and up
//! to 32 luminance levels:
//!
//! - [`classify_row`] classifies 16 pixels per step: phase sums → means and
//!   luminance (one multiply per phase where every phase holds its own
//!   channel, as on RGBW; a 4 × 4 map per CFA position, blended between the
//!   row's even and odd lanes, where two phases share one, as Bayer's greens
//!   do), the contrast, the level by a branch-free binary search over the
//!   level edges held in registers, the chroma class where the table has
//!   them (its scores in the reference's order, with the reference's margin
//!   to the runner-up), the contrast threshold by a register permute (a
//!   gather with chroma classes), and the mask of pixels the reference code
//!   must classify;
//! - [`apply::apply_row_packed`] (patch 3 and 5) applies the kernels of 8 pixels at a
//!   time, all three outputs sharing one 16-lane FMA per patch row (the input
//!   row spread to their lanes by one permute), and sums the lanes of the 8
//!   pixels with a tree of two-source permutes so results leave as whole
//!   vectors; [`apply::apply_row`] (patch 7) does the same with X and Y sharing one
//!   FMA and Z in 8 lanes;
//! - [`srgb8_row`] encodes three planes of linear sRGB (the table computed by a
//!   polynomial checked against every entry, else gathers) and interleaves the
//!   bytes with one permute.
//!
//! Every function checks the lengths of what it reads and writes before its
//! unchecked loads; the callers run them only when the CPU has the features.

mod apply;
mod classify;
mod srgb;

pub(super) use apply::{KernelRow, apply_kernels};
pub(super) use classify::{ChromaParams, ClassParams, ClassifyRow, MAX_LEVELS, classify_row};
pub(super) use srgb::{SrgbPoly, srgb8_row};

/// Lanes per classification step.
const WIDE: usize = 16;
