use std::path::Path;

use super::{Samples, SpectralError};

/// A CSV file of spectra: a `wavelength_nm` column followed by one column per
/// named spectrum (the layout of `../shared/data/iset`). Grids may be
/// non-uniform; rows must be in increasing wavelength order.
#[derive(Clone, Debug)]
pub struct SpectralTable {
    pub path: String,
    pub wavelengths: Vec<f64>,
    pub names: Vec<String>,
    /// `columns[j][i]` is the value of spectrum `j` at `wavelengths[i]`.
    pub columns: Vec<Vec<f64>>,
}

impl SpectralTable {
    /// The column called `name` as samples.
    pub fn samples(&self, name: &str) -> Result<Samples, SpectralError> {
        let j = self.names.iter().position(|n| n == name).ok_or_else(|| {
            SpectralError::NoSuchColumn {
                path: self.path.clone(),
                column: name.to_string(),
                available: self.names.join(", "),
            }
        })?;
        self.samples_at(j)
    }

    /// Column `j` (0-based, not counting the wavelength column) as samples.
    pub fn samples_at(&self, j: usize) -> Result<Samples, SpectralError> {
        let col = self
            .columns
            .get(j)
            .ok_or_else(|| SpectralError::NoSuchColumn {
                path: self.path.clone(),
                column: format!("#{j}"),
                available: self.names.join(", "),
            })?;
        Samples::new(self.wavelengths.clone(), col.clone())
    }

    /// Every column as `(name, samples)`.
    pub fn all(&self) -> Result<Vec<(String, Samples)>, SpectralError> {
        (0..self.names.len())
            .map(|j| Ok((self.names[j].clone(), self.samples_at(j)?)))
            .collect()
    }

    /// Parse CSV text (see [`load_csv`]).
    pub fn parse(path: &str, text: &str) -> Result<Self, SpectralError> {
        let err = |line: usize, msg: String| SpectralError::Csv {
            path: path.to_string(),
            line,
            msg,
        };
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let (_, header) = lines.next().ok_or_else(|| err(1, "empty file".into()))?;
        // a UTF-8 byte-order mark, as spreadsheets write before "CSV UTF-8"
        let header = header.strip_prefix('\u{feff}').unwrap_or(header);
        let mut head = split_row(header);
        if head.len() < 2 {
            return Err(err(
                1,
                "header needs a wavelength column and at least one spectrum".into(),
            ));
        }
        let first = head.remove(0);
        if !first.to_ascii_lowercase().starts_with("wavelength") {
            return Err(err(
                1,
                format!("first column must be wavelength_nm, found '{first}'"),
            ));
        }
        let mut wavelengths = Vec::new();
        let mut columns = vec![Vec::new(); head.len()];
        for (i, line) in lines {
            let cells = split_row(line);
            if cells.len() != head.len() + 1 {
                return Err(err(
                    i + 1,
                    format!("{} cells, header has {}", cells.len(), head.len() + 1),
                ));
            }
            let parse = |s: &str| -> Result<f64, SpectralError> {
                let v: f64 = s
                    .trim()
                    .parse()
                    .map_err(|_| err(i + 1, format!("'{s}' is not a number")))?;
                if !v.is_finite() {
                    return Err(err(i + 1, format!("'{s}' is not finite")));
                }
                Ok(v)
            };
            let w = parse(&cells[0])?;
            if let Some(&prev) = wavelengths.last()
                && w <= prev
            {
                return Err(err(
                    i + 1,
                    format!("wavelength {w} does not increase (after {prev})"),
                ));
            }
            wavelengths.push(w);
            for (j, c) in cells[1..].iter().enumerate() {
                columns[j].push(parse(c)?);
            }
        }
        if wavelengths.len() < 2 {
            return Err(err(1, "fewer than two rows".into()));
        }
        Ok(Self {
            path: path.to_string(),
            wavelengths,
            names: head,
            columns,
        })
    }
}

fn split_row(line: &str) -> Vec<String> {
    line.trim_end_matches(['\r', '\n'])
        .split(',')
        .map(|c| c.trim().trim_matches('"').to_string())
        .collect()
}

/// Load a `wavelength_nm,<name>,...` CSV file.
pub fn load_csv(path: impl AsRef<Path>) -> Result<SpectralTable, SpectralError> {
    let p = path.as_ref();
    let text = std::fs::read_to_string(p).map_err(|source| SpectralError::Io {
        path: p.display().to_string(),
        source,
    })?;
    SpectralTable::parse(&p.display().to_string(), &text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_non_uniform_grid_and_names() {
        let t = SpectralTable::parse(
            "mem",
            "wavelength_nm,a,\"IR Filter\"\n400,0.1,1\n413.5,0.2,1\n430,0.3,0.5\n",
        )
        .unwrap();
        assert_eq!(t.names, vec!["a", "IR Filter"]);
        assert_eq!(t.wavelengths, vec![400.0, 413.5, 430.0]);
        assert_eq!(t.samples("IR Filter").unwrap().values(), &[1.0, 1.0, 0.5]);
        assert!(matches!(
            t.samples("b"),
            Err(SpectralError::NoSuchColumn { .. })
        ));
    }

    #[test]
    fn rejects_bad_rows() {
        assert!(SpectralTable::parse("m", "wavelength_nm,a\n400,x\n410,1\n").is_err());
        assert!(SpectralTable::parse("m", "wavelength_nm,a\n400,1\n400,1\n").is_err());
        assert!(SpectralTable::parse("m", "wavelength_nm,a\n400,1,2\n410,1\n").is_err());
        assert!(SpectralTable::parse("m", "nm,a\n400,1\n410,1\n").is_err());
        assert!(SpectralTable::parse("m", "").is_err());
    }

    #[test]
    fn a_byte_order_mark_is_not_part_of_the_header() {
        let t = SpectralTable::parse("m", "\u{feff}wavelength_nm,a\n400,1\n410,0.5\n").unwrap();
        assert_eq!(t.names, vec!["a"]);
        assert_eq!(t.samples("a").unwrap().values(), &[1.0, 0.5]);
    }
}
