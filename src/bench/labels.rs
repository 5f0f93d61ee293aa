//! Where the plot's point labels go: beside their points without covering one another,
//! another point, or the plot's edge.
//!
//! Greedy placement in pixel space: labels are placed from the top of the plot down, each at
//! the first free candidate spot: right of its point, then left, then the same moved up or down
//! in steps of a line. A label moved off its point's row gets a leader line to it. plotters has
//! no label placement of its own, and a few dozen labels do not need a force-directed layout.

/// A box in pixels: left, top, right, bottom.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PxBox {
    pub l: i32,
    pub t: i32,
    pub r: i32,
    pub b: i32,
}

impl PxBox {
    fn overlaps(&self, o: &PxBox) -> bool {
        self.l < o.r && o.l < self.r && self.t < o.b && o.t < self.b
    }

    /// The box widened by [`PAD`] on both sides: two labels on one row must not read as one.
    fn padded(&self) -> PxBox {
        PxBox {
            l: self.l - PAD,
            r: self.r + PAD,
            ..*self
        }
    }

    fn inside(&self, o: &PxBox) -> bool {
        self.l >= o.l && self.r <= o.r && self.t >= o.t && self.b <= o.b
    }
}

/// Where one label went, relative to its point: the offset of its top-left corner and
/// whether it needs a leader line (it left its point's row).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Placement {
    pub dx: i32,
    pub dy: i32,
    pub leader: bool,
}

/// The text's size: average glyph width and line height of the font, in pixels.
#[derive(Debug, Clone, Copy)]
pub(super) struct TextMetrics {
    pub char_w: f64,
    pub line_h: i32,
}

/// Gap between a point and its label, in pixels.
pub(super) const GAP: i32 = 9;
/// Half the size of the box a marker is given, in pixels.
const MARKER: i32 = 6;
/// The least horizontal space between two boxes, in pixels.
const PAD: i32 = 6;
/// How many lines up or down a label may move from its point's row.
const MAX_SHIFT: i32 = 12;

/// Places the labels `texts` of the points `at` (pixels) inside `area`, clear of the boxes
/// `avoid` (the legend); a label that finds no free spot keeps the first candidate that stays
/// inside the area (so every label is drawn, overlapping as little as the greedy order allows).
pub(super) fn place_labels(
    at: &[(i32, i32)],
    texts: &[&str],
    area: PxBox,
    avoid: &[PxBox],
    m: TextMetrics,
) -> Vec<Placement> {
    let markers: Vec<PxBox> = at
        .iter()
        .map(|&(x, y)| PxBox {
            l: x - MARKER,
            t: y - MARKER,
            r: x + MARKER,
            b: y + MARKER,
        })
        .collect();
    let mut taken: Vec<PxBox> = avoid.to_vec();
    let mut out = vec![
        Placement {
            dx: GAP,
            dy: -m.line_h,
            leader: false,
        };
        at.len()
    ];
    let mut order: Vec<usize> = (0..at.len().min(texts.len())).collect();
    order.sort_by_key(|&i| (at[i].1, at[i].0));
    for i in order {
        let w = (texts[i].chars().count() as f64 * m.char_w).ceil() as i32;
        let (x, y) = at[i];
        let mut fallback = None;
        let mut chosen = None;
        'search: for shift in 0..=MAX_SHIFT {
            for sign in [-1, 1] {
                if shift == 0 && sign == 1 {
                    continue;
                }
                // the label's top: just above the point's row, then whole lines away
                let dy = -m.line_h + sign * shift * m.line_h;
                for dx in [GAP, -GAP - w] {
                    let b = PxBox {
                        l: x + dx,
                        t: y + dy,
                        r: x + dx + w,
                        b: y + dy + m.line_h,
                    };
                    if !b.inside(&area) {
                        continue;
                    }
                    fallback.get_or_insert((dx, dy, b));
                    let wide = b.padded();
                    let free = !taken.iter().any(|o| o.overlaps(&wide))
                        && !markers.iter().any(|o| o.overlaps(&b));
                    if free {
                        chosen = Some((dx, dy, b));
                        break 'search;
                    }
                }
            }
        }
        if let Some((dx, dy, b)) = chosen.or(fallback) {
            taken.push(b);
            out[i] = Placement {
                dx,
                dy,
                leader: dy != -m.line_h,
            };
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const M: TextMetrics = TextMetrics {
        char_w: 8.5,
        line_h: 17,
    };
    const AREA: PxBox = PxBox {
        l: 0,
        t: 0,
        r: 1000,
        b: 600,
    };

    fn boxes(at: &[(i32, i32)], texts: &[&str], p: &[Placement]) -> Vec<PxBox> {
        at.iter()
            .zip(texts)
            .zip(p)
            .map(|((&(x, y), t), p)| PxBox {
                l: x + p.dx,
                t: y + p.dy,
                r: x + p.dx + (t.chars().count() as f64 * M.char_w).ceil() as i32,
                b: y + p.dy + M.line_h,
            })
            .collect()
    }

    /// A tight cluster (the bench's configurations within a few pixels of one another) gets
    /// labels that overlap neither one another nor a marker, all inside the area.
    #[test]
    fn a_cluster_gets_disjoint_labels_inside_the_area() {
        let at: Vec<(i32, i32)> = (0..10).map(|i| (500 + 3 * i, 300 + 2 * (i % 3))).collect();
        let texts = [
            "baseline (bilinear + 3×3 D65 + T)",
            "one chroma class",
            "patch 3",
            "4 chroma classes",
            "no contrast classes",
            "default (5×5, 20 levels, SI)",
            "40 levels",
            "8 chroma classes",
            "per-light tables",
            "ISP (demosaic + denoise + matrix)",
        ];
        let p = place_labels(&at, &texts, AREA, &[], M);
        let b = boxes(&at, &texts, &p);
        for (i, x) in b.iter().enumerate() {
            assert!(x.inside(&AREA), "{i}: {x:?}");
            for (j, y) in b.iter().enumerate().skip(i + 1) {
                assert!(!x.overlaps(y), "labels {i} and {j} overlap: {x:?} {y:?}");
            }
            for &(mx, my) in &at {
                let marker = PxBox {
                    l: mx - MARKER,
                    t: my - MARKER,
                    r: mx + MARKER,
                    b: my + MARKER,
                };
                assert!(
                    !x.overlaps(&marker),
                    "label {i} covers the marker at {mx},{my}"
                );
            }
        }
        // the moved ones are the ones with leader lines
        assert!(p.iter().any(|p| p.leader));
        assert!(p.iter().all(|p| p.leader == (p.dy != -M.line_h)));
    }

    /// A label keeps out of a box to avoid (the legend) even where that is its first spot.
    #[test]
    fn labels_keep_out_of_the_legend() {
        let legend = PxBox {
            l: 600,
            t: 0,
            r: 1000,
            b: 120,
        };
        let at = [(580, 60)];
        let p = place_labels(&at, &["a long configuration name"], AREA, &[legend], M);
        let b = boxes(&at, &["a long configuration name"], &p)[0];
        assert!(!b.overlaps(&legend), "{b:?}");
    }

    /// A point at the right edge gets its label on its left, not cut off.
    #[test]
    fn a_label_at_the_right_edge_goes_left() {
        let at = [(990, 300)];
        let p = place_labels(&at, &["ISP (demosaic + denoise)"], AREA, &[], M);
        assert!(p[0].dx < 0, "{p:?}");
        assert!(!p[0].leader);
        assert!(boxes(&at, &["ISP (demosaic + denoise)"], &p)[0].inside(&AREA));
    }

    /// A lone point keeps the usual spot: right of it, on its row.
    #[test]
    fn a_lone_label_sits_right_of_its_point() {
        let p = place_labels(&[(100, 100)], &["a"], AREA, &[], M);
        assert_eq!(
            p,
            vec![Placement {
                dx: GAP,
                dy: -M.line_h,
                leader: false
            }]
        );
    }
}
