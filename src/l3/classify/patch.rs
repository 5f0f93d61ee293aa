//! Patch geometry and per-pixel class statistics (docs/design.md §5).

use std::borrow::Cow;

use crate::camera::Cfa;

use super::ClassifyError;

mod lanes;

pub use lanes::{LANES, LaneChannels};

/// The most CFA channels a table can classify (saturation cases are bit masks).
pub const MAX_CHANNELS: usize = 8;

/// Statistics of one patch that decide its class.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PatchStats {
    /// Mean over channels of each channel's mean over its unsaturated pixels, volts.
    pub luminance: f32,
    /// Bit `c` set when channel `c` has a saturated pixel in the patch.
    pub sat_mask: u32,
    /// Mean absolute deviation of each pixel from its channel's patch mean, volts.
    pub contrast: f32,
    /// Each channel's mean over all its pixels in the patch.
    pub channel_means: [f32; MAX_CHANNELS],
}

/// A map of patch coordinates (y, x) in a patch of side s.
type IndexMap = fn(usize, usize, usize) -> (usize, usize);

/// Where each channel sits in a patch around each CFA position, plus the
/// level and saturation thresholds: everything needed to classify a pixel.
#[derive(Clone, Debug)]
pub struct PatchGeometry {
    pub size: usize,
    pub radius: usize,
    pub cfa: Cfa,
    n_channels: usize,
    /// `chan_of[pos][k]`: channel of patch element `k` (row-major) when the
    /// centre pixel is at CFA position `pos`.
    chan_of: Vec<Vec<u8>>,
    /// `inv_count[pos][ch]`: 1 / number of patch pixels of channel `ch`.
    inv_count: Vec<[f32; MAX_CHANNELS]>,
    sat_threshold: f32,
    levels: Vec<f32>,
    /// Midpoints between consecutive levels: a patch goes to the nearest level.
    level_edges: Vec<f32>,
    /// Chroma class centroids (channel chromaticities); one or none: no
    /// chroma split (see [`super::chroma`]).
    chroma: Vec<[f32; MAX_CHANNELS]>,
    /// Per class, its score's weights ([`Self::chroma_coefficients`]).
    chroma_coef: Vec<[f32; MAX_CHANNELS]>,
    /// Whether the classes are of white-balanced chromaticities (see
    /// [`super::chroma`]), so that the light changes the scores.
    chroma_balanced: bool,
}

/// The saturation case a patch with channel mask `mask` uses among `cases`
/// (bit masks, the empty case first): its own mask if it has kernels, else
/// un-saturate the darkest saturated channel (lowest patch mean) until a
/// known case is reached. Returns the case index and whether it fell back.
pub fn sat_case_index(cases: &[u32], mask: u32, means: &[f32]) -> (usize, bool) {
    if let Some(i) = cases.iter().position(|&c| c == mask) {
        return (i, false);
    }
    let mut m = mask;
    while m != 0 {
        let mut darkest: Option<(usize, f32)> = None;
        for ch in 0..MAX_CHANNELS {
            if m & (1 << ch) != 0 {
                let v = means.get(ch).copied().unwrap_or(0.0);
                if darkest.is_none_or(|(_, dv)| v < dv) {
                    darkest = Some((ch, v));
                }
            }
        }
        match darkest {
            Some((ch, _)) => m &= !(1 << ch),
            None => break,
        }
        if let Some(i) = cases.iter().position(|&c| c == m) {
            return (i, true);
        }
    }
    (0, true)
}

/// Reflect index `i` into `0..n` without repeating the edge sample
/// (…, 2, 1, 0, 1, 2, …), so the CFA phase of a 2-periodic pattern is kept.
pub fn mirror(i: isize, n: usize) -> usize {
    if n <= 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let m = i.rem_euclid(period);
    (if m >= n as isize { period - m } else { m }) as usize
}

impl PatchGeometry {
    pub fn new(
        size: usize,
        cfa: &Cfa,
        levels: &[f64],
        sat_threshold: f64,
    ) -> Result<Self, ClassifyError> {
        if size.is_multiple_of(2) || !(3..=9).contains(&size) {
            return Err(ClassifyError::InvalidParams(format!(
                "patch size {size} (3, 5, 7 or 9)"
            )));
        }
        let n_channels = cfa.n_channels();
        if n_channels == 0 || n_channels > MAX_CHANNELS {
            return Err(ClassifyError::InvalidParams(format!(
                "{n_channels} CFA channels (1 to {MAX_CHANNELS} supported)"
            )));
        }
        if cfa.rows == 0 || cfa.cols == 0 || cfa.pattern.len() != cfa.rows * cfa.cols {
            return Err(ClassifyError::InvalidParams("malformed CFA".into()));
        }
        if cfa.pattern.iter().any(|&c| c >= n_channels) {
            return Err(ClassifyError::InvalidParams(
                "CFA names an undefined channel".into(),
            ));
        }
        if levels.is_empty() || levels.iter().any(|v| !v.is_finite()) {
            return Err(ClassifyError::InvalidParams(
                "levels must be finite and non-empty".into(),
            ));
        }
        let radius = size / 2;
        let n_pos = cfa.rows * cfa.cols;
        let mut chan_of = Vec::with_capacity(n_pos);
        let mut inv_count = Vec::with_capacity(n_pos);
        for pos in 0..n_pos {
            let (pr, pc) = (pos / cfa.cols, pos % cfa.cols);
            let mut chans = Vec::with_capacity(size * size);
            let mut counts = [0u32; MAX_CHANNELS];
            for dy in 0..size {
                for dx in 0..size {
                    // offsets relative to the centre, shifted by a multiple of the period
                    let r = pr + dy + cfa.rows * size - radius;
                    let c = pc + dx + cfa.cols * size - radius;
                    let ch = cfa.channel_at(r, c);
                    chans.push(ch as u8);
                    counts[ch] += 1;
                }
            }
            let mut inv = [0f32; MAX_CHANNELS];
            for ch in 0..MAX_CHANNELS {
                if counts[ch] > 0 {
                    inv[ch] = 1.0 / counts[ch] as f32;
                }
            }
            chan_of.push(chans);
            inv_count.push(inv);
        }
        let lv: Vec<f32> = levels.iter().map(|&v| v as f32).collect();
        let level_edges = lv.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
        Ok(Self {
            size,
            radius,
            cfa: cfa.clone(),
            n_channels,
            chan_of,
            inv_count,
            sat_threshold: sat_threshold as f32,
            levels: lv,
            level_edges,
            chroma: Vec::new(),
            chroma_coef: Vec::new(),
            chroma_balanced: false,
        })
    }

    /// This geometry with `classes`' chroma split: every luminance level
    /// becomes one band per chroma class (band = level × classes + class),
    /// classified under the classes' reference light ([`Self::under_light`]
    /// for another).
    pub fn with_chroma(mut self, classes: &super::ChromaClasses) -> Result<Self, ClassifyError> {
        classes.validate(self.n_channels)?;
        self.chroma = if classes.len() > 1 {
            classes
                .centroids
                .iter()
                .map(|c| {
                    let mut v = [0f32; MAX_CHANNELS];
                    for (d, s) in v.iter_mut().zip(c) {
                        *d = *s as f32;
                    }
                    v
                })
                .collect()
        } else {
            Vec::new()
        };
        self.chroma_balanced = classes.white.is_some();
        self.chroma_coef = self.chroma_scores(classes.white.as_deref());
        Ok(self)
    }

    /// This geometry classifying chroma under the light whose neutral (the
    /// channel responses to white) is `light`: the classes' balance divides
    /// each channel by it. Borrowed when nothing changes (no split, classes
    /// of raw ratios, or no light named).
    pub fn under_light(&self, light: Option<&[f64]>) -> Result<Cow<'_, Self>, ClassifyError> {
        let Some(light) = light.filter(|_| self.chroma_balanced && !self.chroma.is_empty()) else {
            return Ok(Cow::Borrowed(self));
        };
        if light.len() != self.n_channels {
            return Err(ClassifyError::InvalidInput(format!(
                "a neutral of {} channels for a sensor of {}",
                light.len(),
                self.n_channels
            )));
        }
        let n = super::chroma::normalised_neutral(light)?;
        let mut g = self.clone();
        g.chroma_coef = self.chroma_scores(Some(&n));
        Ok(Cow::Owned(g))
    }

    /// Per class, the weights of its score on the channel means balanced by
    /// `neutral` (see [`Self::chroma_of`]): `(|c|² − 2 c_ch) / neutral_ch`.
    fn chroma_scores(&self, neutral: Option<&[f64]>) -> Vec<[f32; MAX_CHANNELS]> {
        let nc = self.n_channels;
        self.chroma
            .iter()
            .map(|c| {
                let norm2: f32 = c[..nc].iter().map(|v| v * v).sum();
                let mut a = [0f32; MAX_CHANNELS];
                for ch in 0..nc {
                    let gain = neutral.and_then(|n| n.get(ch)).map_or(1.0, |w| 1.0 / *w);
                    a[ch] = ((norm2 - 2.0 * c[ch]) as f64 * gain) as f32;
                }
                a
            })
            .collect()
    }

    /// Chroma classes (1 without a chroma split).
    pub fn n_chroma(&self) -> usize {
        self.chroma.len().max(1)
    }

    /// Classification bands: luminance levels × chroma classes.
    pub fn n_bands(&self) -> usize {
        self.levels.len() * self.n_chroma()
    }

    /// The band of a patch: its level's, split by its chroma class.
    #[inline]
    pub fn band_of(&self, luminance: f32, means: &[f32; MAX_CHANNELS]) -> usize {
        let level = self.level_of(luminance);
        if self.chroma.is_empty() {
            level
        } else {
            level * self.chroma.len() + self.chroma_of(means).0
        }
    }

    /// The chroma class of a patch's channel means (each channel, clamped at
    /// 0 and balanced by the light's neutral, over their sum: the nearest
    /// centroid; class 0 when nothing responds), with how far it is from the
    /// runner-up: the difference of the squared distances times the sum of
    /// the balanced means (so a caller can tell a class its rounding cannot
    /// change). The balance is folded into the scores' weights.
    ///
    /// With `x = m / Σm`, `|x − c|² = |x|² + score(c) / Σm` where
    /// `score(c) = Σ_ch m_ch (|c|² − 2 c_ch)`: the class is the centroid of
    /// the lowest score and the margin is the gap to the next, linear in the
    /// means and free of the division ([`Self::chroma_coefficients`]).
    #[inline]
    pub fn chroma_of(&self, means: &[f32; MAX_CHANNELS]) -> (usize, f32) {
        if self.chroma.len() < 2 {
            return (0, f32::INFINITY);
        }
        let nc = self.n_channels;
        let (mut best, mut s1, mut s2) = (0usize, f32::INFINITY, f32::INFINITY);
        for (k, a) in self.chroma_coef.iter().enumerate() {
            let mut score = 0f32;
            for ch in 0..nc {
                score += a[ch] * means[ch].max(0.0);
            }
            if score < s1 {
                s2 = s1;
                s1 = score;
                best = k;
            } else if score < s2 {
                s2 = score;
            }
        }
        let gap = s2 - s1;
        if gap.is_nan() { (0, 0.0) } else { (best, gap) }
    }

    /// Per chroma class, the weights of its score (`|c|² − 2 c_ch` per
    /// channel, see [`Self::chroma_of`]); empty without a chroma split.
    pub fn chroma_coefficients(&self) -> &[[f32; MAX_CHANNELS]] {
        &self.chroma_coef
    }

    pub fn n_positions(&self) -> usize {
        self.cfa.rows * self.cfa.cols
    }

    pub fn n_channels(&self) -> usize {
        self.n_channels
    }

    pub fn n_levels(&self) -> usize {
        self.levels.len()
    }

    pub fn levels(&self) -> &[f32] {
        &self.levels
    }

    pub fn sat_threshold(&self) -> f32 {
        self.sat_threshold
    }

    /// Patch pixels plus the constant term.
    pub fn n_features(&self) -> usize {
        self.size * self.size + 1
    }

    /// CFA position of pixel (r, c).
    #[inline]
    pub fn position(&self, r: usize, c: usize) -> usize {
        (r % self.cfa.rows) * self.cfa.cols + (c % self.cfa.cols)
    }

    /// Channel of each patch element around CFA position `pos`.
    pub fn channels_of(&self, pos: usize) -> &[u8] {
        &self.chan_of[pos]
    }

    /// Midpoints between consecutive levels (the class boundaries).
    pub fn level_edges(&self) -> &[f32] {
        &self.level_edges
    }

    /// Index of the nearest level.
    #[inline]
    pub fn level_of(&self, luminance: f32) -> usize {
        self.level_edges.partition_point(|&e| e < luminance)
    }

    /// Copy the patch centred on (r, c) of a `width`×`height` image into
    /// `out` (row-major, `size²` values), mirroring at the borders.
    pub fn gather(
        &self,
        img: &[f32],
        width: usize,
        height: usize,
        r: usize,
        c: usize,
        out: &mut [f32],
    ) {
        let s = self.size;
        let rad = self.radius as isize;
        let interior = r >= self.radius
            && c >= self.radius
            && r + self.radius < height
            && c + self.radius < width;
        if interior {
            for dy in 0..s {
                let row = (r + dy - self.radius) * width + c - self.radius;
                out[dy * s..dy * s + s].copy_from_slice(&img[row..row + s]);
            }
        } else {
            for dy in 0..s {
                let rr = mirror(r as isize + dy as isize - rad, height);
                for dx in 0..s {
                    let cc = mirror(c as isize + dx as isize - rad, width);
                    out[dy * s + dx] = img[rr * width + cc];
                }
            }
        }
    }

    /// Class statistics of a gathered patch centred at CFA position `pos`.
    pub fn stats(&self, patch: &[f32], pos: usize) -> PatchStats {
        let chans = &self.chan_of[pos];
        let inv = &self.inv_count[pos];
        let mut sum = [0f32; MAX_CHANNELS];
        let mut usum = [0f32; MAX_CHANNELS];
        let mut ucount = [0u32; MAX_CHANNELS];
        let mut sat_mask = 0u32;
        for (k, &v) in patch.iter().enumerate() {
            let ch = chans[k] as usize;
            sum[ch] += v;
            if v >= self.sat_threshold {
                sat_mask |= 1 << ch;
            } else {
                usum[ch] += v;
                ucount[ch] += 1;
            }
        }
        let mut means = [0f32; MAX_CHANNELS];
        let mut lum = 0f32;
        let mut nl = 0u32;
        for ch in 0..self.n_channels {
            means[ch] = sum[ch] * inv[ch];
            if ucount[ch] > 0 {
                lum += usum[ch] / ucount[ch] as f32;
                nl += 1;
            }
        }
        let luminance = if nl > 0 {
            lum / nl as f32
        } else {
            // every channel saturated: the top of the range
            self.sat_threshold
        };
        let mut dev = 0f32;
        for (k, &v) in patch.iter().enumerate() {
            dev += (v - means[chans[k] as usize]).abs();
        }
        PatchStats {
            luminance,
            sat_mask,
            contrast: dev / patch.len() as f32,
            channel_means: means,
        }
    }

    /// Write the feature vector of a patch for saturation case `case_mask`:
    /// the patch values with pixels of the case's channels zeroed (saturated
    /// pixels enter with zero weight), then the constant 1.
    pub fn features(&self, patch: &[f32], pos: usize, case_mask: u32, out: &mut [f32]) {
        let chans = &self.chan_of[pos];
        let n = patch.len();
        if case_mask == 0 {
            out[..n].copy_from_slice(patch);
        } else {
            for k in 0..n {
                out[k] = if case_mask & (1 << chans[k]) != 0 {
                    0.0
                } else {
                    patch[k]
                };
            }
        }
        out[n] = 1.0;
    }

    /// The symmetries of patch element indices that map the CFA layout
    /// around position `pos` onto itself (identity always included): each
    /// entry maps element k to its mirror image.
    pub fn symmetries(&self, pos: usize) -> Vec<Vec<usize>> {
        let s = self.size;
        let chans = &self.chan_of[pos];
        let transforms: [IndexMap; 4] = [
            |y, x, _| (y, x),
            |y, x, s| (y, s - 1 - x),
            |y, x, s| (s - 1 - y, x),
            |y, x, s| (s - 1 - y, s - 1 - x),
        ];
        let mut out = Vec::new();
        for t in transforms {
            let map: Vec<usize> = (0..s * s)
                .map(|k| {
                    let (y, x) = t(k / s, k % s, s);
                    y * s + x
                })
                .collect();
            if (0..s * s).all(|k| chans[k] == chans[map[k]]) {
                out.push(map);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saturation_case_fallback_drops_the_darkest_channel() {
        let cases = [0, 0b1000, 0b1010];
        assert_eq!(sat_case_index(&cases, 0b1010, &[]), (2, false));
        // W (bit 3) and B (bit 2) saturated; B darker → drop B → W case
        let means = [0.5, 1.0, 0.2, 1.8];
        assert_eq!(sat_case_index(&cases, 0b1100, &means), (1, true));
        // R, G, W saturated: R darkest → G+W known
        assert_eq!(
            sat_case_index(&cases, 0b1011, &[0.1, 1.0, 0.2, 1.8]),
            (2, true)
        );
        assert_eq!(sat_case_index(&cases, 0b0001, &means), (0, true));
    }

    #[test]
    fn mirror_reflects_without_repeating_the_edge() {
        let v: Vec<usize> = (-3..8).map(|i| mirror(i, 5)).collect();
        assert_eq!(v, vec![3, 2, 1, 0, 1, 2, 3, 4, 3, 2, 1]);
        assert_eq!(mirror(-7, 1), 0);
        assert_eq!(mirror(5, 2), 1);
    }

    #[test]
    fn geometry_of_rgbw() {
        let cfa = Cfa::parse("RG/WB").unwrap();
        let g = PatchGeometry::new(5, &cfa, &[0.01, 0.1, 1.0], 1.799).unwrap();
        assert_eq!(g.n_positions(), 4);
        assert_eq!(g.n_features(), 26);
        // centre pixel of the patch around position 0 is R
        assert_eq!(g.channels_of(0)[12], 0);
        assert_eq!(g.channels_of(3)[12], cfa.pattern[3] as u8);
        // 2×2 CFA: all four flips preserve the layout
        assert_eq!(g.symmetries(0).len(), 4);
        assert_eq!(g.level_of(0.0), 0);
        assert_eq!(g.level_of(0.06), 1);
        assert_eq!(g.level_of(0.9), 2);
        assert_eq!(g.level_of(10.0), 2);
    }

    #[test]
    fn stats_of_a_flat_patch_with_saturated_white() {
        let cfa = Cfa::parse("RG/WB").unwrap();
        let g = PatchGeometry::new(3, &cfa, &[0.1, 1.0], 1.799).unwrap();
        let chans = g.channels_of(0).to_vec();
        let vals = [0.2f32, 0.4, 0.3, 1.8]; // R G B W
        let patch: Vec<f32> = chans.iter().map(|&c| vals[c as usize]).collect();
        let s = g.stats(&patch, 0);
        assert_eq!(s.sat_mask, 1 << 3);
        assert!((s.luminance - 0.3).abs() < 1e-6);
        assert!(s.contrast.abs() < 1e-6);
        let mut f = vec![0f32; 10];
        g.features(&patch, 0, 1 << 3, &mut f);
        for k in 0..9 {
            assert_eq!(f[k] == 0.0, chans[k] == 3);
        }
        assert_eq!(f[9], 1.0);
    }

    #[test]
    fn gather_mirrors_at_borders() {
        let cfa = Cfa::parse("RG/WB").unwrap();
        let g = PatchGeometry::new(3, &cfa, &[0.1, 1.0], 1.7).unwrap();
        let img: Vec<f32> = (0..16).map(|v| v as f32).collect();
        let mut p = [0f32; 9];
        g.gather(&img, 4, 4, 0, 0, &mut p);
        assert_eq!(p, [5.0, 4.0, 5.0, 1.0, 0.0, 1.0, 5.0, 4.0, 5.0]);
        g.gather(&img, 4, 4, 1, 1, &mut p);
        assert_eq!(p, [0.0, 1.0, 2.0, 4.0, 5.0, 6.0, 8.0, 9.0, 10.0]);
    }

    fn rgbw_geometry() -> PatchGeometry {
        let cfa = Cfa::parse("RG/WB").unwrap();
        PatchGeometry::new(5, &cfa, &[0.01, 0.1, 1.0], 1.79).unwrap()
    }

    fn means(v: [f32; 4]) -> [f32; MAX_CHANNELS] {
        let mut m = [0f32; MAX_CHANNELS];
        m[..4].copy_from_slice(&v);
        m
    }

    #[test]
    fn bands_split_each_level_by_chroma_class() {
        let classes = crate::l3::classify::ChromaClasses {
            centroids: vec![vec![0.7, 0.1, 0.1, 0.1], vec![0.1, 0.1, 0.1, 0.7]],
            white: None,
        };
        let plain = rgbw_geometry();
        assert_eq!((plain.n_chroma(), plain.n_bands()), (1, 3));
        assert_eq!(plain.band_of(0.8, &means([1.0, 0.0, 0.0, 0.0])), 2);
        let g = rgbw_geometry().with_chroma(&classes).unwrap();
        assert_eq!((g.n_chroma(), g.n_bands()), (2, 6));
        let red = means([0.6, 0.1, 0.1, 0.1]);
        let blue = means([0.1, 0.1, 0.1, 0.6]);
        assert_eq!(g.band_of(0.8, &red), 4);
        assert_eq!(g.band_of(0.8, &blue), 5);
        assert_eq!(g.band_of(0.001, &blue), 1);
        // the class does not depend on exposure; its margin scales with it
        let dim = means([0.006, 0.001, 0.001, 0.001]);
        assert_eq!(g.chroma_of(&dim).0, 0);
        assert!(g.chroma_of(&dim).1 < g.chroma_of(&red).1);
        // nothing responds (or noise below zero): class 0, no margin
        assert_eq!(g.chroma_of(&means([0.0, -0.1, 0.0, 0.0])), (0, 0.0));
        // a NaN mean (never from finite input) counts as no response
        assert_eq!(
            g.chroma_of(&means([f32::NAN, 0.1, 0.1, 0.1])),
            g.chroma_of(&means([0.0, 0.1, 0.1, 0.1]))
        );
        // a single class is no split; centroids of the wrong length are refused
        let one = crate::l3::classify::ChromaClasses::single(4);
        assert_eq!(rgbw_geometry().with_chroma(&one).unwrap().n_bands(), 3);
        let three = crate::l3::classify::ChromaClasses {
            centroids: vec![vec![0.5, 0.5, 0.0]; 2],
            white: None,
        };
        assert!(rgbw_geometry().with_chroma(&three).is_err());
        // classes of raw ratios ignore the light
        let lamp = [1.0, 0.5, 0.2, 0.8];
        assert!(matches!(
            g.under_light(Some(&lamp)).unwrap(),
            Cow::Borrowed(_)
        ));
    }

    #[test]
    fn balanced_classes_follow_the_light() {
        // a reddish and a bluish class, balanced by a neutral light
        let classes = crate::l3::classify::ChromaClasses {
            centroids: vec![vec![0.4, 0.2, 0.2, 0.2], vec![0.2, 0.2, 0.4, 0.2]],
            white: Some(vec![1.0; 4]),
        };
        let g = rgbw_geometry().with_chroma(&classes).unwrap();
        // under a warm lamp a surface's responses are its balanced ones times
        // the lamp's neutral, whatever the scale of the neutral
        let lamp = [1.0, 0.55, 0.2, 0.7];
        let warm = g.under_light(Some(&lamp)).unwrap();
        let doubled = g.under_light(Some(&lamp.map(|v| v * 2.0))).unwrap();
        let bluish = [0.25, 0.25, 0.45, 0.25];
        let under_lamp = means(std::array::from_fn(|ch| bluish[ch] * lamp[ch] as f32));
        assert_eq!(g.chroma_of(&means(bluish)).0, 1);
        assert_eq!(warm.chroma_of(&under_lamp).0, 1);
        assert_eq!(doubled.chroma_of(&under_lamp).0, 1);
        // read unbalanced, the lamp's shift moves it to the other class
        assert_eq!(g.chroma_of(&under_lamp).0, 0);
        // no light named: the reference light; a bad neutral is refused
        assert!(matches!(g.under_light(None).unwrap(), Cow::Borrowed(_)));
        assert!(g.under_light(Some(&[1.0, 0.0, 1.0, 1.0])).is_err());
        assert!(g.under_light(Some(&[1.0, 1.0, 1.0])).is_err());
        assert!(g.under_light(Some(&[1.0, f64::NAN, 1.0, 1.0])).is_err());
    }
}
