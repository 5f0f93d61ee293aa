use std::path::{Path, PathBuf};

use super::{Samples, SpectralError, SpectralTable, bundled_paths, bundled_table, load_csv};

/// Where the tables come from.
#[derive(Clone, Debug, PartialEq)]
enum Source {
    /// An ISET data directory, over the built-in copies.
    Dir(PathBuf),
    /// The built-in copies only.
    BuiltIn,
}

/// ISETCam's spectral data exported as CSV: Vrhel reflectances, the Macbeth
/// chart, measured lights, sensor filters. The tables the defaults need are
/// built into the binary (`config/spectra/`, see [`bundled_table`]). An ISET
/// data directory (`--iset-dir`, `$L3_ISET_DIR` or `../shared/data/iset`,
/// read in place) overrides them file by file and adds the rest of the export:
/// a table is read from the directory when the directory holds it, else from
/// the built-in copy.
///
/// Functions that take an `Option<&IsetData>` read `None` as the built-in
/// data ([`IsetData::or_built_in`]).
#[derive(Clone, Debug, PartialEq)]
pub struct IsetData {
    source: Source,
}

/// Environment variable naming the ISET data directory.
pub const ISET_DIR_ENV: &str = "L3_ISET_DIR";

static BUILT_IN: IsetData = IsetData {
    source: Source::BuiltIn,
};

impl IsetData {
    /// Use the directory `root`, which must exist and hold a `lights/` folder.
    pub fn at(root: impl Into<PathBuf>) -> Result<Self, SpectralError> {
        let root = root.into();
        if root.join("lights").is_dir() {
            Ok(Self {
                source: Source::Dir(root),
            })
        } else {
            Err(SpectralError::IsetDataMissing(format!(
                "{} has no lights/ folder",
                root.display()
            )))
        }
    }

    /// The built-in data alone.
    pub fn built_in() -> &'static IsetData {
        &BUILT_IN
    }

    /// `iset`, or the built-in data for `None`.
    pub fn or_built_in(iset: Option<&IsetData>) -> &IsetData {
        iset.unwrap_or(&BUILT_IN)
    }

    /// Find an ISET data directory: `$L3_ISET_DIR` when set (and valid), else
    /// `../shared/data/iset` or `shared/data/iset` relative to the working
    /// directory. `None` when there is none: the built-in data serves.
    pub fn locate() -> Option<Self> {
        if let Ok(dir) = std::env::var(ISET_DIR_ENV) {
            return Self::at(dir).ok();
        }
        ["../shared/data/iset", "shared/data/iset"]
            .into_iter()
            .find_map(|p| Self::at(p).ok())
    }

    /// The ISET data directory, or `None` for the built-in data alone.
    pub fn dir(&self) -> Option<&Path> {
        match &self.source {
            Source::Dir(root) => Some(root),
            Source::BuiltIn => None,
        }
    }

    /// A CSV table by path relative to the data root, e.g.
    /// `lights/Tungsten.csv`: the directory's file when it has one, else the
    /// built-in copy.
    pub fn table(&self, rel: &str) -> Result<SpectralTable, SpectralError> {
        if let Source::Dir(root) = &self.source {
            let file = root.join(rel);
            if file.is_file() {
                return load_csv(file);
            }
        }
        bundled_table(rel).unwrap_or_else(|| {
            let dir = match &self.source {
                Source::Dir(root) => format!("in the ISET data directory {}", root.display()),
                Source::BuiltIn => format!(
                    "in an ISET data directory (none given or found: --iset-dir, \
                     {ISET_DIR_ENV}, ../shared/data/iset)"
                ),
            };
            Err(SpectralError::NoSuchTable {
                path: rel.to_string(),
                dir,
                built_in: {
                    let (cams, rest): (Vec<&str>, Vec<&str>) =
                        bundled_paths().partition(|p| p.starts_with("cameras/rawtoaces/"));
                    format!(
                        "{}, and {} catalogue cameras as cameras/rawtoaces/<maker>_<model>.csv",
                        rest.join(", "),
                        cams.len()
                    )
                },
            })
        })
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

    /// Names of the lights: the built-in ones and those in the directory's
    /// `lights/`, sorted.
    pub fn light_names(&self) -> Vec<String> {
        let mut v: Vec<String> = bundled_paths()
            .filter_map(|p| p.strip_prefix("lights/")?.strip_suffix(".csv"))
            .filter(|n| !n.contains('/'))
            .map(String::from)
            .collect();
        if let Source::Dir(root) = &self.source
            && let Ok(rd) = std::fs::read_dir(root.join("lights"))
        {
            v.extend(rd.filter_map(|e| e.ok()).filter_map(|e| {
                let p = e.path();
                (p.extension()? == "csv").then(|| p.file_stem()?.to_str().map(String::from))?
            }));
        }
        v.sort();
        v.dedup();
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn built_in_data_has_the_default_lights() {
        let d = IsetData::built_in();
        assert_eq!(d.dir(), None);
        assert_eq!(d.light_names(), ["Fluorescent", "Tungsten"]);
        let t = d.light("Tungsten").unwrap();
        assert!(t.at(600.0, crate::spectral::Extrapolation::Zero) > 0.0);
        assert_eq!(IsetData::or_built_in(None), d);
        assert!(d.light("../lights/Tungsten").is_err());
        let e = d.light("LED405nm").unwrap_err().to_string();
        assert!(
            e.contains("lights/LED405nm.csv") && e.contains("--iset-dir"),
            "{e}"
        );
    }

    #[test]
    fn a_directory_overrides_the_built_in_copies_file_by_file() {
        let tmp = tempfile::tempdir().unwrap();
        let lights = tmp.path().join("lights");
        std::fs::create_dir(&lights).unwrap();
        std::fs::write(
            lights.join("Tungsten.csv"),
            "wavelength_nm,mine\n400,1\n700,2\n",
        )
        .unwrap();
        std::fs::write(
            lights.join("Lamp.csv"),
            "wavelength_nm,lamp\n400,1\n700,1\n",
        )
        .unwrap();
        let d = IsetData::at(tmp.path()).unwrap();
        assert_eq!(d.dir(), Some(tmp.path()));
        // the directory's copy wins
        let t = d.table("lights/Tungsten.csv").unwrap();
        assert_eq!(t.names, ["mine"]);
        // what the directory lacks comes from the built-in data
        assert_eq!(
            d.table("lights/Fluorescent.csv").unwrap().path,
            "built-in:lights/Fluorescent.csv"
        );
        assert_eq!(d.light_names(), ["Fluorescent", "Lamp", "Tungsten"]);
        let e = d.table("lights/None.csv").unwrap_err().to_string();
        assert!(
            e.contains(&tmp.path().display().to_string()) && e.contains("built in"),
            "{e}"
        );
        // a folder without lights/ is not ISET data
        assert!(IsetData::at(lights.join("nowhere")).is_err());
    }
}
