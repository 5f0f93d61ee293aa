//! The built-in spectral data (`config/spectra/`) against its source, the
//! ISET data directory: every built-in ISET table holds the same numbers.

use crate::iset_reference;

use l3::spectral::{bundled_paths, bundled_table, load_csv};

#[test]
fn built_in_iset_tables_equal_the_iset_directory() {
    let Some(iset) = iset_reference::iset_dir("built_in_iset_tables_equal_the_iset_directory")
    else {
        return;
    };
    let Some(root) = iset.dir() else {
        panic!("a located ISET directory has a path");
    };
    let mut compared = 0;
    for rel in bundled_paths() {
        // the camera curves come from other sources (see config/spectra/README.md)
        if rel.starts_with("cameras/") {
            continue;
        }
        let theirs = load_csv(root.join(rel)).unwrap();
        let ours = bundled_table(rel).unwrap().unwrap();
        assert_eq!(ours.names, theirs.names, "{rel}");
        assert_eq!(ours.wavelengths, theirs.wavelengths, "{rel}");
        assert_eq!(ours.columns, theirs.columns, "{rel}");
        compared += 1;
    }
    println!("{compared} built-in tables equal their ISET source");
    assert_eq!(compared, 16);
}
