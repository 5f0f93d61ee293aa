use std::path::{Path, PathBuf};

use super::{Samples, SpectralError, SpectralTable, load_csv};

/// The ISETCam spectral data exported as CSV (`../shared/data/iset`): Vrhel
/// reflectances, Macbeth, measured lights, sensor filters. Read in place, never
/// copied. The location is `L3_ISET_DIR` if set, else `../shared/data/iset`
/// relative to the working directory or to the crate.
#[derive(Clone, Debug)]
pub struct IsetData {
    root: PathBuf,
}

/// Environment variable naming the ISET data directory.
pub const ISET_DIR_ENV: &str = "L3_ISET_DIR";

impl IsetData {
    /// Use the directory `root`, which must exist.
    pub fn at(root: impl Into<PathBuf>) -> Result<Self, SpectralError> {
        let root = root.into();
        if root.join("lights").is_dir() {
            Ok(Self { root })
        } else {
            Err(SpectralError::IsetDataMissing(format!(
                "{} has no lights/ folder",
                root.display()
            )))
        }
    }

    /// Find the data: `$L3_ISET_DIR`, `./../shared/data/iset`, `./shared/data/iset`,
    /// or `../shared/data/iset` beside the crate.
    pub fn locate() -> Option<Self> {
        if let Ok(dir) = std::env::var(ISET_DIR_ENV) {
            return Self::at(dir).ok();
        }
        [
            PathBuf::from("../shared/data/iset"),
            PathBuf::from("shared/data/iset"),
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/iset"),
        ]
        .into_iter()
        .find_map(|p| Self::at(p).ok())
    }

    /// For tests: the data, or `None` with a printed reason. When `CI` is set
    /// the data must be there, so a missing directory fails the test.
    pub fn for_tests() -> Option<Self> {
        match Self::locate() {
            Some(d) => Some(d),
            None if std::env::var_os("CI").is_some() => {
                panic!("CI is set but ../shared/data/iset was not found (set {ISET_DIR_ENV})")
            }
            None => {
                eprintln!("skipped: ../shared/data/iset not found (set {ISET_DIR_ENV})");
                None
            }
        }
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// A CSV table by path relative to the root, e.g. `lights/Tungsten.csv`.
    pub fn table(&self, rel: &str) -> Result<SpectralTable, SpectralError> {
        load_csv(self.root.join(rel))
    }

    /// The first spectrum of `lights/<name>.csv` (e.g. `Tungsten`, `Fluorescent`).
    pub fn light(&self, name: &str) -> Result<Samples, SpectralError> {
        if name.contains(['/', '\\']) || name.contains("..") {
            return Err(SpectralError::UnknownIlluminant(
                name.to_string(),
                "ISET light names".into(),
            ));
        }
        self.table(&format!("lights/{name}.csv"))?.samples_at(0)
    }

    /// Names of the lights in `lights/`.
    pub fn light_names(&self) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(self.root.join("lights"))
            .map(|rd| {
                rd.filter_map(|e| e.ok())
                    .filter_map(|e| {
                        let p = e.path();
                        (p.extension()? == "csv")
                            .then(|| p.file_stem()?.to_str().map(String::from))?
                    })
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    }
}
