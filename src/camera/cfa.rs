//! Colour filter arrays: an m×n tile of channel indices repeated over the sensor.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::CameraError;

/// Largest CFA tile side accepted.
pub const MAX_CFA_SIDE: usize = 16;

/// A colour filter array: a `rows × cols` tile, repeated over the sensor, of
/// channel indices into `channel_names`.
///
/// Build one with [`Cfa::parse`] or [`Cfa::new`], which validate it; the
/// fields are public for reading.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Cfa {
    pub rows: usize,
    pub cols: usize,
    /// Row-major channel index of each tile position (`rows * cols` entries).
    pub pattern: Vec<usize>,
    /// Channel names; index `i` is channel `i` (e.g. of the sensor's rate cube).
    pub channel_names: Vec<String>,
}

impl Cfa {
    /// A CFA from its tile and channel names, validated: non-empty, at most
    /// [`MAX_CFA_SIDE`] per side, every index in range, every channel used,
    /// names unique and made of letters, digits or `_`.
    pub fn new(
        rows: usize,
        cols: usize,
        pattern: Vec<usize>,
        channel_names: Vec<String>,
    ) -> Result<Self, CameraError> {
        let bad = |msg: String| Err(CameraError::InvalidCfa(msg));
        if rows == 0 || cols == 0 {
            return bad(format!("the tile is {rows}×{cols}; it must not be empty"));
        }
        if rows > MAX_CFA_SIDE || cols > MAX_CFA_SIDE {
            return bad(format!(
                "the tile is {rows}×{cols}; each side must be at most {MAX_CFA_SIDE}"
            ));
        }
        if pattern.len() != rows * cols {
            return bad(format!(
                "a {rows}×{cols} tile needs {} entries, got {}",
                rows * cols,
                pattern.len()
            ));
        }
        if channel_names.is_empty() {
            return bad("no channel names".into());
        }
        for (i, n) in channel_names.iter().enumerate() {
            if n.is_empty() || !n.chars().all(|c| c.is_alphanumeric() || c == '_') {
                return bad(format!(
                    "channel name '{n}' must be non-empty letters, digits or '_'"
                ));
            }
            if channel_names[..i].contains(n) {
                return bad(format!("channel name '{n}' appears twice"));
            }
        }
        if let Some(&p) = pattern.iter().find(|&&p| p >= channel_names.len()) {
            return bad(format!(
                "channel index {p} is out of range ({} channels)",
                channel_names.len()
            ));
        }
        for (i, n) in channel_names.iter().enumerate() {
            if !pattern.contains(&i) {
                return bad(format!("channel '{n}' does not appear in the tile"));
            }
        }
        Ok(Self {
            rows,
            cols,
            pattern,
            channel_names,
        })
    }

    /// Parse a tile written row by row, rows separated by `/`: `"RG/WB"`
    /// (one-letter names) or `"R G / W B"` (names separated by spaces, for
    /// longer names such as `"C1 C2 / C3 C4"`). Channels are numbered in
    /// order of first appearance, row-major: `"RG/WB"` gives R=0, G=1, W=2, B=3.
    pub fn parse(s: &str) -> Result<Self, CameraError> {
        let bad = |msg: String| CameraError::InvalidCfa(format!("'{s}': {msg}"));
        let s_trim = s.trim();
        if s_trim.is_empty() {
            return Err(bad("empty pattern".into()));
        }
        let spaced = s_trim
            .split('/')
            .any(|r| r.trim().contains(char::is_whitespace));
        let mut names: Vec<String> = Vec::new();
        let mut pattern = Vec::new();
        let mut cols = None;
        let mut rows = 0;
        for row in s_trim.split('/') {
            let cells: Vec<String> = if spaced {
                row.split_whitespace().map(String::from).collect()
            } else {
                row.trim().chars().map(String::from).collect()
            };
            if cells.is_empty() {
                return Err(bad(format!("row {} is empty", rows + 1)));
            }
            match cols {
                None => cols = Some(cells.len()),
                Some(n) if n != cells.len() => {
                    return Err(bad(format!(
                        "row {} has {} entries but row 1 has {n}; the tile must be rectangular",
                        rows + 1,
                        cells.len()
                    )));
                }
                Some(_) => {}
            }
            for cell in cells {
                let idx = match names.iter().position(|n| *n == cell) {
                    Some(i) => i,
                    None => {
                        names.push(cell);
                        names.len() - 1
                    }
                };
                pattern.push(idx);
            }
            rows += 1;
        }
        Self::new(rows, cols.unwrap_or(0), pattern, names).map_err(|e| match e {
            CameraError::InvalidCfa(m) if !m.starts_with('\'') => bad(m),
            other => other,
        })
    }

    /// The same tile with channels renumbered to follow `order` (a permutation
    /// of this CFA's channel names), e.g. to match a sensor's channel list.
    pub fn with_channel_order(&self, order: &[String]) -> Result<Self, CameraError> {
        if order.len() != self.channel_names.len() {
            return Err(CameraError::InvalidCfa(format!(
                "{self}: {} channels given for {} in the tile",
                order.len(),
                self.channel_names.len()
            )));
        }
        let map: Vec<usize> = self
            .channel_names
            .iter()
            .map(|n| {
                order.iter().position(|o| o == n).ok_or_else(|| {
                    CameraError::InvalidCfa(format!("{self}: channel '{n}' missing from the order"))
                })
            })
            .collect::<Result<_, _>>()?;
        Self::new(
            self.rows,
            self.cols,
            self.pattern.iter().map(|&p| map[p]).collect(),
            order.to_vec(),
        )
    }

    /// Channel index at sensor pixel `(r, c)` (the tile repeats).
    #[inline]
    pub fn channel_at(&self, r: usize, c: usize) -> usize {
        self.pattern[(r % self.rows) * self.cols + c % self.cols]
    }

    /// Channel name at sensor pixel `(r, c)`.
    pub fn name_at(&self, r: usize, c: usize) -> &str {
        &self.channel_names[self.channel_at(r, c)]
    }

    /// Index of the channel called `name`.
    pub fn channel_index(&self, name: &str) -> Option<usize> {
        self.channel_names.iter().position(|n| n == name)
    }

    /// The CFA seen from an origin moved by `(dr, dc)`: pixel `(r, c)` of the
    /// result has the channel at `(r + dr, c + dc)` of `self`.
    pub fn shifted(&self, dr: usize, dc: usize) -> Cfa {
        let mut pattern = Vec::with_capacity(self.pattern.len());
        for r in 0..self.rows {
            for c in 0..self.cols {
                pattern.push(self.channel_at(r + dr, c + dc));
            }
        }
        Cfa {
            rows: self.rows,
            cols: self.cols,
            pattern,
            channel_names: self.channel_names.clone(),
        }
    }

    /// Number of distinct channels.
    pub fn n_channels(&self) -> usize {
        self.channel_names.len()
    }

    /// Number of tile positions (`rows * cols`).
    pub fn n_positions(&self) -> usize {
        self.rows * self.cols
    }
}

impl fmt::Display for Cfa {
    /// `RG/WB` for one-letter names, `C1 C2 / C3 C4` otherwise.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let short = self.channel_names.iter().all(|n| n.chars().count() == 1);
        for r in 0..self.rows {
            if r > 0 {
                f.write_str(if short { "/" } else { " / " })?;
            }
            for c in 0..self.cols {
                if c > 0 && !short {
                    f.write_str(" ")?;
                }
                f.write_str(&self.channel_names[self.channel_at(r, c)])?;
            }
        }
        Ok(())
    }
}

impl FromStr for Cfa {
    type Err = CameraError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Cfa::parse(s)
    }
}

impl TryFrom<String> for Cfa {
    type Error = CameraError;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        Cfa::parse(&s)
    }
}

impl From<Cfa> for String {
    fn from(c: Cfa) -> String {
        c.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_rgbw_and_numbers_by_first_appearance() {
        let c = Cfa::parse("RG/WB").unwrap();
        assert_eq!((c.rows, c.cols), (2, 2));
        assert_eq!(c.channel_names, vec!["R", "G", "W", "B"]);
        assert_eq!(c.pattern, vec![0, 1, 2, 3]);
        assert_eq!(c.n_channels(), 4);
        assert_eq!(c.name_at(0, 0), "R");
        assert_eq!(c.name_at(1, 0), "W");
        assert_eq!(c.name_at(3, 2), "W");
        assert_eq!(c.name_at(5, 5), "B");
        assert_eq!(c.to_string(), "RG/WB");
        assert_eq!(Cfa::parse(" R G / W B ").unwrap(), c);
        let bayer: Cfa = "RG/GB".parse().unwrap();
        assert_eq!(bayer.channel_names, vec!["R", "G", "B"]);
        assert_eq!(bayer.pattern, vec![0, 1, 1, 2]);
    }

    #[test]
    fn long_names_round_trip() {
        let c = Cfa::parse("C1 C2 C3 / C3 C1 C2").unwrap();
        assert_eq!((c.rows, c.cols, c.n_channels()), (2, 3, 3));
        assert_eq!(c.to_string(), "C1 C2 C3 / C3 C1 C2");
        assert_eq!(Cfa::parse(&c.to_string()).unwrap(), c);
    }

    #[test]
    fn shift_moves_the_origin() {
        let c = Cfa::parse("RG/WB").unwrap();
        let s = c.shifted(1, 0);
        assert_eq!(s.to_string(), "WB/RG");
        assert_eq!(c.shifted(0, 1).to_string(), "GR/BW");
        assert_eq!(c.shifted(1, 1).to_string(), "BW/GR");
        assert_eq!(c.shifted(2, 4), c);
        for r in 0..4 {
            for col in 0..4 {
                assert_eq!(s.channel_at(r, col), c.channel_at(r + 1, col));
                assert_eq!(
                    c.shifted(1, 3).channel_at(r, col),
                    c.channel_at(r + 1, col + 3)
                );
            }
        }
        // Channel numbering is kept.
        assert_eq!(s.channel_names, c.channel_names);
    }

    #[test]
    fn rejects_bad_patterns() {
        for bad in ["", "RG/W", "R G/ W", "RG//WB", "R-/GB", "/"] {
            let e = Cfa::parse(bad);
            assert!(e.is_err(), "{bad:?} parsed");
        }
        let msg = Cfa::parse("RG/W").unwrap_err().to_string();
        assert!(msg.contains("rectangular"), "{msg}");
        assert!(Cfa::new(1, 2, vec![0, 2], vec!["A".into(), "B".into()]).is_err());
        assert!(Cfa::new(1, 2, vec![0, 0], vec!["A".into(), "B".into()]).is_err());
        assert!(Cfa::new(1, 2, vec![0, 1], vec!["A".into(), "A".into()]).is_err());
        assert!(Cfa::new(17, 1, vec![0; 17], vec!["A".into()]).is_err());
    }

    #[test]
    fn reorders_channels() {
        let c = Cfa::parse("RG/WB").unwrap();
        let order: Vec<String> = ["R", "G", "B", "W"].map(String::from).to_vec();
        let o = c.with_channel_order(&order).unwrap();
        assert_eq!(o.pattern, vec![0, 1, 3, 2]);
        assert_eq!(o.to_string(), "RG/WB");
        assert!(c.with_channel_order(&order[..3]).is_err());
    }

    #[test]
    fn serde_as_string() {
        #[derive(Serialize, Deserialize)]
        struct W {
            cfa: Cfa,
        }
        let w: W = toml::from_str("cfa = \"RG/GB\"").unwrap();
        assert_eq!(w.cfa.to_string(), "RG/GB");
        assert_eq!(toml::to_string(&w).unwrap().trim(), "cfa = \"RG/GB\"");
        assert!(toml::from_str::<W>("cfa = \"RG/G\"").is_err());
    }
}
