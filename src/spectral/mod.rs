//! Spectral data: wavelength grids, spectra on grids, irregular samples with
//! area-preserving resampling, CSV loading, and the built-in CIE data.

mod builtin;
mod bundled;
mod csv;
mod grid;
mod illuminant;
mod iset;
mod spectrum;

pub use builtin::{
    CIE_ILLUMINANT_NAMES, ces_reflectances, cie_daylight, cie_illuminant, cie1931_cmfs,
    munsell_reflectances, planck,
};
pub use bundled::{bundled_paths, bundled_table};
pub use csv::{SpectralTable, load_csv};
pub use grid::WavelengthGrid;
pub use illuminant::{IlluminantSpec, MAX_INLINE_SPD_SAMPLES, NamedSpd};
pub use iset::{ISET_DIR_ENV, IsetData};
pub use spectrum::{Extrapolation, Samples, Spectrum};

/// Errors of the spectral layer.
#[derive(Debug, thiserror::Error)]
pub enum SpectralError {
    #[error("invalid wavelength grid: {0}")]
    InvalidGrid(String),
    #[error("spectrum has {got} values but its grid has {expected} bands")]
    LengthMismatch { expected: usize, got: usize },
    #[error("invalid samples: {0}")]
    InvalidSamples(String),
    #[error("grids differ: {0:?} vs {1:?}")]
    GridMismatch(WavelengthGrid, WavelengthGrid),
    #[error("cannot read {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: line {line}: {msg}")]
    Csv {
        path: String,
        line: usize,
        msg: String,
    },
    #[error("{path}: no column named '{column}' (columns: {available})")]
    NoSuchColumn {
        path: String,
        column: String,
        available: String,
    },
    #[error("unknown illuminant '{0}' (known: {1})")]
    UnknownIlluminant(String, String),
    #[error("invalid illuminant spec '{0}': {1}")]
    InvalidIlluminantSpec(String, String),
    #[error("ISET data directory not found: {0}")]
    IsetDataMissing(String),
    #[error("spectral table '{path}' is neither {dir} nor built in (built in: {built_in})")]
    NoSuchTable {
        path: String,
        dir: String,
        built_in: String,
    },
}
