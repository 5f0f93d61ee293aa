use std::fmt;

use serde::{Deserialize, Serialize};

use super::{
    CIE_ILLUMINANT_NAMES, IsetData, Samples, SpectralError, cie_daylight, cie_illuminant, load_csv,
    planck,
};

/// How a user names an illuminant on the command line or in a request:
/// a CIE name (`D65`, `A`, `F11`…), an ISET measured light (`Tungsten`,
/// `Fluorescent`, or `iset:NAME`), a correlated colour temperature
/// (`cct:3200`: Planck below 4000 K, CIE daylight from 4000 K), a CSV file
/// (`csv:PATH` or `csv:PATH:COLUMN`), or a named light given by its SPD samples
/// (`spd:NAME:400=0.5,410=0.6,…`: wavelength in nm `=` relative power).
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
    /// A light given inline by its samples (no file: what a light registered from an SPD
    /// becomes in a request that must not depend on the registry), resolved under `name`.
    Samples {
        name: String,
        samples: Samples,
    },
}

/// The most samples an inline light ([`IlluminantSpec::Samples`]) may hold.
pub const MAX_INLINE_SPD_SAMPLES: usize = 4096;

/// A resolved illuminant: a display name and its spectral power distribution.
#[derive(Clone, Debug)]
pub struct NamedSpd {
    pub name: String,
    pub spd: Samples,
}

impl IlluminantSpec {
    /// A light named `name` given by its samples (wavelengths in nm, strictly increasing;
    /// relative power, finite, not negative and not all zero), at most
    /// [`MAX_INLINE_SPD_SAMPLES`] of them.
    pub fn samples(
        name: &str,
        wavelengths: Vec<f64>,
        values: Vec<f64>,
    ) -> Result<Self, SpectralError> {
        let bad = |why: String| SpectralError::InvalidIlluminantSpec(format!("spd:{name}:…"), why);
        if name.trim().is_empty() {
            return Err(bad("the light needs a name".into()));
        }
        if values.len() > MAX_INLINE_SPD_SAMPLES {
            return Err(bad(format!(
                "{} samples; at most {MAX_INLINE_SPD_SAMPLES}",
                values.len()
            )));
        }
        let samples = Samples::new(wavelengths, values).map_err(|e| bad(e.to_string()))?;
        if let Some(i) = samples.values().iter().position(|v| *v < 0.0) {
            return Err(bad(format!(
                "power {} at {} nm is negative",
                samples.values()[i],
                samples.wavelengths()[i]
            )));
        }
        if samples.values().iter().all(|v| *v == 0.0) {
            return Err(bad("every sample is zero: the light has no power".into()));
        }
        Ok(Self::Samples {
            name: name.to_string(),
            samples,
        })
    }

    /// `NAME:W=V,W=V,…` after `spd:` (the name may hold `:`; the samples hold none).
    fn parse_samples(rest: &str) -> Result<Self, SpectralError> {
        let Some((name, data)) = rest.rsplit_once(':') else {
            return Err(SpectralError::InvalidIlluminantSpec(
                format!("spd:{rest}"),
                "expected spd:NAME:W=V,W=V,… (wavelength in nm = relative power)".into(),
            ));
        };
        let bad = |why: String| SpectralError::InvalidIlluminantSpec(format!("spd:{name}:…"), why);
        let mut wavelengths = Vec::new();
        let mut values = Vec::new();
        for (i, pair) in data.split(',').enumerate() {
            if i >= MAX_INLINE_SPD_SAMPLES {
                return Err(bad(format!("more than {MAX_INLINE_SPD_SAMPLES} samples")));
            }
            let number = |t: &str| t.trim().parse::<f64>().ok();
            let (w, v) = pair
                .split_once('=')
                .and_then(|(w, v)| Some((number(w)?, number(v)?)))
                .ok_or_else(|| {
                    bad(format!(
                        "sample {} is '{}'; expected WAVELENGTH=POWER",
                        i + 1,
                        pair.trim()
                    ))
                })?;
            wavelengths.push(w);
            values.push(v);
        }
        Self::samples(name, wavelengths, values)
    }

    pub fn parse(s: &str) -> Result<Self, SpectralError> {
        let s = s.trim();
        let bad = |why: &str| SpectralError::InvalidIlluminantSpec(s.to_string(), why.to_string());
        if let Some(rest) = s.strip_prefix("spd:") {
            return Self::parse_samples(rest);
        }
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
        if s.get(..3).is_some_and(|p| p.eq_ignore_ascii_case("xy:")) {
            // a chromaticity renders (as its nearest colour temperature) but is no spectrum
            return Err(bad(
                "a chromaticity gives no spectrum, which simulating or training under a light \
                 needs; give its colour temperature (cct:K) or its samples (spd:NAME:W=V,…)",
            ));
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
                    "{}, Tungsten, Fluorescent, iset:NAME, cct:K, csv:PATH[:COLUMN], spd:NAME:W=V,…",
                    CIE_ILLUMINANT_NAMES.join(", ")
                ),
            )),
        }
    }

    /// Load the SPD. ISET lights come from `iset` (`None`: the built-in
    /// data, which holds Tungsten and Fluorescent). The light is named by its spec, an
    /// inline one by its own name.
    pub fn resolve(&self, iset: Option<&IsetData>) -> Result<NamedSpd, SpectralError> {
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
            // known by its own name, not by its numbers
            Self::Samples { name, samples } => {
                return Ok(NamedSpd {
                    name: name.clone(),
                    spd: samples.clone(),
                });
            }
        };
        Ok(NamedSpd {
            name: self.to_string(),
            spd,
        })
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
            // `{}` of an f64 is the shortest text that parses back to it
            Self::Samples { name, samples } => {
                write!(f, "spd:{name}:")?;
                let pairs = samples.wavelengths().iter().zip(samples.values());
                for (i, (w, v)) in pairs.enumerate() {
                    let sep = if i == 0 { "" } else { "," };
                    write!(f, "{sep}{w}={v}")?;
                }
                Ok(())
            }
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
        // a chromaticity is a render's light, not a spectrum: the error says what to give
        let e = IlluminantSpec::parse("XY:0.3,0.3").unwrap_err().to_string();
        assert!(
            e.contains("gives no spectrum") && e.contains("cct:K"),
            "{e}"
        );
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

    #[test]
    fn an_inline_light_goes_by_its_name_and_its_text_parses_back_to_it() {
        let spec = IlluminantSpec::samples(
            "my:led",
            vec![380.0, 455.5, 600.0, 780.0],
            vec![0.0, 1.0, 0.1 + 0.2, 1e-7],
        )
        .unwrap();
        let text = spec.to_string();
        assert_eq!(
            text,
            "spd:my:led:380=0,455.5=1,600=0.30000000000000004,780=0.0000001"
        );
        assert_eq!(IlluminantSpec::parse(&text).unwrap(), spec);
        // as JSON it is that text, as every spec is
        let json = serde_json::to_string(&spec).unwrap();
        assert_eq!(serde_json::from_str::<IlluminantSpec>(&json).unwrap(), spec);
        let named = spec.resolve(None).unwrap();
        assert_eq!(named.name, "my:led");
        assert_eq!(named.spd.values(), &[0.0, 1.0, 0.1 + 0.2, 1e-7]);
        // spaces around the numbers are taken
        assert_eq!(
            IlluminantSpec::parse("spd:x: 400 = 1 , 500=2").unwrap(),
            IlluminantSpec::samples("x", vec![400.0, 500.0], vec![1.0, 2.0]).unwrap()
        );
    }

    #[test]
    fn an_inline_light_is_checked_and_its_errors_do_not_repeat_its_samples() {
        for (bad, needle) in [
            ("spd:", "expected spd:NAME"),
            ("spd:x", "expected spd:NAME"),
            ("spd::400=1,500=1", "needs a name"),
            ("spd:x:", "sample 1"),
            ("spd:x:400=1", "at least two"),
            ("spd:x:400=1,500", "sample 2 is '500'"),
            ("spd:x:400=1,500=a", "sample 2"),
            ("spd:x:500=1,400=1", "increasing"),
            ("spd:x:400=1,500=NaN", "not finite"),
            ("spd:x:400=1,500=-0.5", "negative"),
            ("spd:x:400=0,500=0", "no power"),
        ] {
            let e = IlluminantSpec::parse(bad).unwrap_err().to_string();
            assert!(e.contains(needle), "{bad}: {e}");
        }
        let many: Vec<String> = (0..=MAX_INLINE_SPD_SAMPLES)
            .map(|i| format!("{}=1", 300 + i))
            .collect();
        let e = IlluminantSpec::parse(&format!("spd:big:{}", many.join(",")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("at most") || e.contains("more than"), "{e}");
        assert!(e.len() < 200, "{e}");
    }
}
