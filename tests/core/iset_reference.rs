//! The ISET data directory (`$L3_ISET_DIR`, else `../shared/data/iset` beside the repository)
//! for the tests that need reference data beyond the built-in spectral data.

use l3::spectral::IsetData;

/// The ISET data directory, or `None` with a printed `skipped:` line. When
/// `CI` is set the directory must be there, so a missing one fails the test.
pub fn iset_dir(test: &str) -> Option<IsetData> {
    // the tests run in tests/, so `IsetData::locate`'s `../shared` is looked for from the root
    let beside_the_repository = concat!(env!("L3_ROOT"), "/../shared/data/iset");
    match IsetData::locate().or_else(|| IsetData::at(beside_the_repository).ok()) {
        Some(d) => Some(d),
        None if std::env::var_os("CI").is_some() => {
            panic!("{test}: CI is set but ../shared/data/iset was not found (set L3_ISET_DIR)")
        }
        None => {
            eprintln!("skipped: {test}: ../shared/data/iset not found (set L3_ISET_DIR)");
            None
        }
    }
}
