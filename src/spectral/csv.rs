use std::path::Path;

use super::{Samples, SpectralError};

/// A CSV file of spectra: a `wavelength_nm` column followed by one column per
/// named spectrum (the layout of `../shared/data/iset`). Grids may be
/// non-uniform; rows must be in increasing wavelength order. Read with the `csv` crate
/// (quoted cells, CRLF); cells are separated by commas, or by semicolons or tabs when the header
/// has more of those; a decimal comma (in a quoted cell where commas separate cells) is a
/// point; lines starting with `#` are comments.
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
        let mut at = self.names.iter().enumerate().filter(|(_, n)| *n == name);
        let (j, _) = at.next().ok_or_else(|| SpectralError::NoSuchColumn {
            path: self.path.clone(),
            column: name.to_string(),
            available: self.names.join(", "),
        })?;
        if let Some((k, _)) = at.next() {
            // which of two same-named columns is meant is anyone's guess (Gr and Gb, say)
            return Err(SpectralError::Csv {
                path: self.path.clone(),
                line: 1,
                msg: format!(
                    "two columns are named '{name}' (columns {} and {}); name each once",
                    j + 2,
                    k + 2
                ),
            });
        }
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
        // a UTF-8 byte-order mark, as spreadsheets write before "CSV UTF-8"
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let dialect = Dialect::of(text);
        let mut rows = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .comment(Some(b'#'))
            .delimiter(dialect.delimiter)
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes())
            .into_records()
            .map(|r| -> Result<(usize, csv::StringRecord), SpectralError> {
                let r = r.map_err(|e| {
                    let line = e.position().map_or(1, |p| p.line() as usize);
                    err(line, e.to_string())
                })?;
                let line = r.position().map_or(1, |p| p.line() as usize);
                Ok((line, r))
            })
            .filter(|r| !matches!(r, Ok((_, rec)) if rec.iter().all(str::is_empty)));
        let (_, header) = rows.next().ok_or_else(|| err(1, "empty file".into()))??;
        let mut head: Vec<String> = header.iter().map(str::to_string).collect();
        if head.len() < 2 {
            return Err(err(
                1,
                "header needs a wavelength column and at least one spectrum, separated by \
                 commas (or semicolons or tabs)"
                    .into(),
            ));
        }
        let wavelength_column = head.remove(0);
        check_wavelength_header(&wavelength_column).map_err(|m| err(1, m))?;
        let mut wavelengths = Vec::new();
        let mut columns = vec![Vec::new(); head.len()];
        for row in rows {
            let (line, cells) = row?;
            if cells.len() != head.len() + 1 {
                let hint = if dialect.delimiter == b',' && cells.len() > head.len() + 1 {
                    " (decimal commas? where commas separate cells, quote such numbers or \
                     separate cells with semicolons)"
                } else {
                    ""
                };
                return Err(err(
                    line,
                    format!("{} cells, header has {}{hint}", cells.len(), head.len() + 1),
                ));
            }
            let first_row = wavelengths.is_empty();
            let parse = |s: &str, column: &str| -> Result<f64, SpectralError> {
                let v: f64 = dialect.number(s).parse().map_err(|_| {
                    // a row of units under the header ("nm, rel, …") is a common sight
                    let hint = if first_row {
                        " (a row of units? comment it out with '#')"
                    } else {
                        ""
                    };
                    err(
                        line,
                        format!("'{s}' in column '{column}' is not a number{hint}"),
                    )
                })?;
                if !v.is_finite() {
                    return Err(err(
                        line,
                        format!("'{s}' in column '{column}' is not finite"),
                    ));
                }
                Ok(v)
            };
            let w = parse(&cells[0], wavelength_column.trim())?;
            if let Some(&prev) = wavelengths.last()
                && w <= prev
            {
                return Err(err(
                    line,
                    format!("wavelength {w} does not increase (after {prev})"),
                ));
            }
            wavelengths.push(w);
            for (j, c) in cells.iter().skip(1).enumerate() {
                columns[j].push(parse(c, &head[j])?);
            }
        }
        if wavelengths.len() < 2 {
            return Err(err(1, "fewer than two rows".into()));
        }
        let last = wavelengths[wavelengths.len() - 1];
        if last < MIN_LAST_WAVELENGTH_NM {
            return Err(err(
                1,
                format!(
                    "wavelengths {}–{last} are not nanometres (micrometres?); give them in nm",
                    wavelengths[0]
                ),
            ));
        }
        Ok(Self {
            path: path.to_string(),
            wavelengths,
            names: head,
            columns,
        })
    }
}

/// A table whose wavelengths all lie below this is not in nanometres (a file in µm, say).
const MIN_LAST_WAVELENGTH_NM: f64 = 100.0;

/// The first column's name: `wavelength`, with no unit or nanometres (`wavelength_nm`,
/// `Wavelength (nm)`, `wavelength[nm]`).
fn check_wavelength_header(first: &str) -> Result<(), String> {
    let lower = first.to_lowercase();
    let Some(unit) = lower.strip_prefix("wavelength") else {
        return Err(format!(
            "first column must be wavelength_nm, found '{first}'"
        ));
    };
    let unit: String = unit
        .chars()
        .filter(|c| !matches!(c, '_' | ' ' | '(' | ')' | '[' | ']' | '-' | '/' | '.'))
        .collect();
    match unit.as_str() {
        "" | "nm" | "nanometers" | "nanometres" => Ok(()),
        _ => Err(format!(
            "first column '{first}' names another unit than nanometres; give wavelengths in nm \
             (wavelength_nm)"
        )),
    }
}

/// How a file separates its cells: the delimiter its header uses most (commas, semicolons or
/// tabs). A number's decimal comma is taken as a point.
#[derive(Clone, Copy)]
struct Dialect {
    delimiter: u8,
}

impl Dialect {
    fn of(text: &str) -> Dialect {
        let header = text
            .lines()
            .find(|l| !l.trim().is_empty() && !l.starts_with('#'))
            .unwrap_or("");
        let count = |c: char| header.matches(c).count();
        let delimiter = [(b';', count(';')), (b'\t', count('\t'))]
            .into_iter()
            .filter(|&(_, n)| n > count(','))
            .max_by_key(|&(_, n)| n)
            .map_or(b',', |(d, _)| d);
        Dialect { delimiter }
    }

    /// The cell as Rust parses a number: a decimal comma as a point (a cell holds a comma
    /// only when commas do not separate cells, or when it is quoted).
    fn number(&self, cell: &str) -> String {
        if cell.matches(',').count() == 1 && !cell.contains('.') {
            cell.replace(',', ".")
        } else {
            cell.to_string()
        }
    }
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

    /// Vendors' dialects: semicolons or tabs with decimal commas, quoted names holding a
    /// comma, comment lines, CRLF.
    #[test]
    fn reads_the_dialects_spreadsheets_write() {
        let want = [0.5, 0.25];
        for text in [
            "wavelength_nm;a;b\r\n400;0,5;1\r\n410;0,25;2\r\n",
            "Wavelength (nm)\ta\tb\n400\t0,5\t1\n410\t0.25\t2\n",
            "# vendor X, 2024\nwavelength_nm,a,b\n400,0.5,1\n# mid\n410,0.25,2\n",
            "wavelength[nm],\"a\",\"b, measured\"\n400,0.5,1\n410,0.25,2\n",
            "wavelength_nm,a,b\n400,\"0,5\",1\n410,\"0,25\",2\n",
        ] {
            let t = SpectralTable::parse("m", text).unwrap_or_else(|e| panic!("{text:?}: {e}"));
            assert_eq!(t.samples("a").unwrap().values(), &want, "{text:?}");
            assert_eq!(t.names.len(), 2, "{text:?}");
        }
    }

    #[test]
    fn refuses_other_units_and_ambiguous_columns() {
        let um = SpectralTable::parse("m", "wavelength_um,a\n0.4,1\n0.41,1\n").unwrap_err();
        assert!(um.to_string().contains("nanometres"), "{um}");
        let small = SpectralTable::parse("m", "wavelength,a\n0.4,1\n0.41,1\n").unwrap_err();
        assert!(small.to_string().contains("in nm"), "{small}");
        let t =
            SpectralTable::parse("m", "wavelength_nm,R,G,G,B\n400,1,1,1,1\n410,1,1,1,1\n").unwrap();
        assert!(t.samples("R").is_ok());
        let dup = t.samples("G").unwrap_err();
        assert!(dup.to_string().contains("columns 3 and 4"), "{dup}");
        let cell = SpectralTable::parse("m", "wavelength_nm,a,b\n400,1,\n410,1,1\n").unwrap_err();
        assert!(
            cell.to_string().contains("line 2") && cell.to_string().contains("'b'"),
            "{cell}"
        );
    }

    #[test]
    fn a_byte_order_mark_is_not_part_of_the_header() {
        let t = SpectralTable::parse("m", "\u{feff}wavelength_nm,a\n400,1\n410,0.5\n").unwrap();
        assert_eq!(t.names, vec!["a"]);
        assert_eq!(t.samples("a").unwrap().values(), &[1.0, 0.5]);
    }
}
