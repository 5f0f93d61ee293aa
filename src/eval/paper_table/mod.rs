//! The paper's Table 1: I_Tun, SI_Tun+T, SI_D65+T, SI_Ens+T and the
//! conventional baseline on the Natural-100 chart, under tungsten and again
//! under fluorescent, beside the published figures; and the SI tables again
//! with the camera-aware correction C in place of T (`+C` rows, see
//! `crate::l3::camera_correction`).

mod baselines;
mod markdown;
mod rows;
mod run;
#[cfg(test)]
mod tests;

pub(crate) use baselines::short;
pub use markdown::paper_summary;
pub use rows::{
    BaselineComparison, BaselineFamily, ExposurePoint, PAPER_TABLE1, PaperOptions, PaperRow,
    PaperTable, Spatial, StorageComparison,
};
pub use run::run_paper_table;
pub(crate) use run::{linear_counterpart, table_spec};
