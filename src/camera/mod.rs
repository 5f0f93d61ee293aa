//! The camera simulator: scene → optics → sensor (DESIGN.md §3).
//! (temporary: only the CFA type, until the simulator lands)

/// A colour filter array: `pattern[r * cols + c]` is the channel index at (r, c).
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Cfa {
    pub rows: usize,
    pub cols: usize,
    pub pattern: Vec<usize>,
    pub channel_names: Vec<String>,
}

impl Cfa {
    pub fn channel_at(&self, r: usize, c: usize) -> usize {
        self.pattern[(r % self.rows) * self.cols + (c % self.cols)]
    }
    pub fn n_channels(&self) -> usize {
        self.channel_names.len()
    }
    pub fn shifted(&self, dr: usize, dc: usize) -> Cfa {
        let mut p = Vec::with_capacity(self.pattern.len());
        for r in 0..self.rows {
            for c in 0..self.cols {
                p.push(self.channel_at(r + dr, c + dc));
            }
        }
        Cfa {
            rows: self.rows,
            cols: self.cols,
            pattern: p,
            channel_names: self.channel_names.clone(),
        }
    }
    pub fn rgbw() -> Cfa {
        Cfa {
            rows: 2,
            cols: 2,
            pattern: vec![0, 1, 3, 2],
            channel_names: ["R", "G", "B", "W"].map(String::from).to_vec(),
        }
    }
}
