//! Classification: where each channel sits in a pixel's patch and the statistics that put
//! the pixel in a class ([`PatchGeometry`], docs/design.md §5), and the chroma classes that split
//! every level by the ratios of the channel responses ([`ChromaClasses`]).

pub mod chroma;
mod patch;

pub use chroma::{ChromaClasses, MAX_CHROMA_CLASSES, MIN_SURFACES_PER_CHANNEL, chromaticity};
pub use patch::{
    LANES, LaneChannels, MAX_CHANNELS, PatchGeometry, PatchStats, mirror, sat_case_index,
};

/// Errors of the classification: parameters that make no geometry or no chroma classes,
/// and inputs (a light's neutral, a response set) that cannot be classified.
#[derive(Debug, thiserror::Error)]
pub enum ClassifyError {
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    #[error("invalid input: {0}")]
    InvalidInput(String),
}
