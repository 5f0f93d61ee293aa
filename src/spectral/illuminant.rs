use std::fmt;

use serde::{Deserialize, Serialize};

use super::{
    CIE_ILLUMINANT_NAMES, IsetData, Samples, SpectralError, cie_daylight, cie_illuminant, load_csv,
    planck,
};

/// How a user names an illuminant on the command line or in a request:
/// a CIE name (`D65`, `A`, `F11`…), an ISET measured light (`Tungsten`,
/// `Fluorescent`, or `iset:NAME`), a correlated colour temperature
/// (`cct:3200`: Planck below 4000 K, CIE daylight from 4000 K), or a CSV file
/// (`csv:PATH` or `csv:PATH:COLUMN`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum IlluminantSpec {
    Cie(String),
    Iset(String),
    Cct(f64),
    Csv {
        path: String,
        column: Option<String>,
    },
}

/// A resolved illuminant: a display name and its spectral power distribution.
#[derive(Clone, Debug)]
pub struct NamedSpd {
    pub name: String,
    pub spd: Samples,
}

impl IlluminantSpec {
    pub fn parse(s: &str) -> Result<Self, SpectralError> {
        let s = s.trim();
        let bad = |why: &str| SpectralError::InvalidIlluminantSpec(s.to_string(), why.to_string());
        if let Some(rest) = s.strip_prefix("cct:") {
            let k: f64 = rest
                .trim()
                .trim_end_matches(['K', 'k'])
                .parse()
                .map_err(|_| bad("expected cct:<kelvin>, e.g. cct:3200"))?;
            if !(k.is_finite() && (1000.0..=25_000.0).contains(&k)) {
                return Err(bad("colour temperature must be within 1000–25000 K"));
            }
            return Ok(Self::Cct(k));
        }
        if let Some(rest) = s.strip_prefix("csv:") {
            if rest.is_empty() {
                return Err(bad("expected csv:PATH or csv:PATH:COLUMN"));
            }
            // A trailing `:COLUMN` is a column name unless it looks like part of a path.
            if let Some((p, c)) = rest.rsplit_once(':')
                && !c.is_empty()
                && !c.contains(['/', '\\', '.'])
                && !p.is_empty()
            {
                return Ok(Self::Csv {
                    path: p.to_string(),
                    column: Some(c.to_string()),
                });
            }
            return Ok(Self::Csv {
                path: rest.to_string(),
                column: None,
            });
        }
        if let Some(rest) = s.strip_prefix("iset:") {
            if rest.is_empty() {
                return Err(bad("expected iset:NAME"));
            }
            return Ok(Self::Iset(rest.to_string()));
        }
        if s.is_empty() {
            return Err(bad("empty name"));
        }
        let up = s.to_ascii_uppercase();
        if CIE_ILLUMINANT_NAMES.contains(&up.as_str()) {
            return Ok(Self::Cie(up));
        }
        match up.as_str() {
            "TUNGSTEN" => Ok(Self::Iset("Tungsten".into())),
            "FLUORESCENT" => Ok(Self::Iset("Fluorescent".into())),
            _ => Err(SpectralError::UnknownIlluminant(
                s.to_string(),
                format!(
                    "{}, Tungsten, Fluorescent, iset:NAME, cct:K, csv:PATH[:COLUMN]",
                    CIE_ILLUMINANT_NAMES.join(", ")
                ),
            )),
        }
    }

    /// Load the SPD. ISET lights come from `iset` (`None`: the built-in
    /// data, which holds Tungsten and Fluorescent).
    pub fn resolve(&self, iset: Option<&IsetData>) -> Result<NamedSpd, SpectralError> {
        let name = self.to_string();
        let spd = match self {
            Self::Cie(n) => cie_illuminant(n).ok_or_else(|| {
                SpectralError::UnknownIlluminant(n.clone(), CIE_ILLUMINANT_NAMES.join(", "))
            })?,
            Self::Iset(n) => IsetData::or_built_in(iset).light(n)?,
            Self::Cct(k) => {
                if *k < 4000.0 {
                    planck(*k)?
                } else {
                    cie_daylight(*k)?
                }
            }
            Self::Csv { path, column } => {
                let t = load_csv(path)?;
                match column {
                    Some(c) => t.samples(c)?,
                    None => t.samples_at(0)?,
                }
            }
        };
        Ok(NamedSpd { name, spd })
    }
}

impl fmt::Display for IlluminantSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Cie(n) => write!(f, "{n}"),
            Self::Iset(n) => write!(f, "{n}"),
            Self::Cct(k) => write!(f, "cct:{k}"),
            Self::Csv { path, column: None } => write!(f, "csv:{path}"),
            Self::Csv {
                path,
                column: Some(c),
            } => write!(f, "csv:{path}:{c}"),
        }
    }
}

impl std::str::FromStr for IlluminantSpec {
    type Err = SpectralError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::parse(s)
    }
}

impl TryFrom<String> for IlluminantSpec {
    type Error = SpectralError;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        Self::parse(&s)
    }
}

impl From<IlluminantSpec> for String {
    fn from(s: IlluminantSpec) -> String {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_form() {
        assert_eq!(
            IlluminantSpec::parse("d65").unwrap(),
            IlluminantSpec::Cie("D65".into())
        );
        assert_eq!(
            IlluminantSpec::parse("cct:3200").unwrap(),
            IlluminantSpec::Cct(3200.0)
        );
        assert_eq!(
            IlluminantSpec::parse("tungsten").unwrap(),
            IlluminantSpec::Iset("Tungsten".into())
        );
        assert_eq!(
            IlluminantSpec::parse("csv:/a/b.csv:led1").unwrap(),
            IlluminantSpec::Csv {
                path: "/a/b.csv".into(),
                column: Some("led1".into())
            }
        );
        assert_eq!(
            IlluminantSpec::parse("csv:./x/b.csv").unwrap(),
            IlluminantSpec::Csv {
                path: "./x/b.csv".into(),
                column: None
            }
        );
        for bad in [
            "", "cct:", "cct:abc", "cct:-5", "cct:1e9", "csv:", "nonsense",
        ] {
            assert!(IlluminantSpec::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn resolves_builtins() {
        let a = IlluminantSpec::parse("A").unwrap().resolve(None).unwrap();
        assert_eq!(a.name, "A");
        assert!(
            IlluminantSpec::parse("cct:3000")
                .unwrap()
                .resolve(None)
                .is_ok()
        );
        assert!(
            IlluminantSpec::parse("cct:6500")
                .unwrap()
                .resolve(None)
                .is_ok()
        );
        // ISET's measured lights are built in; other ISET lights need the directory
        for name in ["Tungsten", "Fluorescent"] {
            let l = IlluminantSpec::parse(name).unwrap().resolve(None).unwrap();
            assert_eq!(l.name, name);
        }
        assert!(matches!(
            IlluminantSpec::parse("iset:LED405nm")
                .unwrap()
                .resolve(None),
            Err(SpectralError::NoSuchTable { .. })
        ));
    }
}
