//! Chroma classes: a partition of a sensor's channel space by the *ratios*
//! of the channel responses, so that each class can hold its own colour map.
//!
//! A linear channel → XYZ map has one error floor per sensor (the filters
//! are not a linear transform of the colour-matching functions). Splitting
//! the surfaces by their channel chromaticity (each response over the sum
//! of the responses, so the class does not depend on exposure) and fitting
//! a map per class makes the colour piecewise linear, which is what the L3
//! method does for luminance with its levels. The classes are found by
//! k-means (k-means++ start from a seeded generator, then Lloyd's
//! iterations) on the chromaticities of a reflectance set's responses; a
//! class that ends with fewer than `min_size` members is dropped and its
//! members reassigned, so every class has enough surfaces to fit a map on.
//!
//! The chromaticity is taken *white-balanced*: each channel over the
//! camera's response to a white surface under the light (the neutral a raw
//! file records as AsShotNeutral). A grey then has one chromaticity under
//! every light, so a table's classes mean the same surfaces under the light
//! it renders under as under the light it was trained under. Classified on
//! the raw ratios, every surface shifts toward the light's colour: under
//! tungsten a D65 table's greys fell into its orange class and got that
//! class's map, which the illuminant correction T cannot undo (rgbw-ar0132at
//! SI_D65+T under tungsten 2.69 ΔE2000 with one class, 4.10 with eight
//! classes on raw ratios). The table keeps a reference neutral
//! ([`ChromaClasses::white`]) for a light nobody names.
//!
//! Written here rather than taken from a clustering crate: the sets are a
//! few hundred points of at most [`super::MAX_CHANNELS`] dimensions, the
//! result must reproduce bit for bit from a seed, and the class of a patch
//! must be computed by the same few lines everywhere it is needed.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::ClassifyError;

/// Lloyd iterations at most (the sets converge in far fewer).
const MAX_ITERATIONS: usize = 200;

/// The fewest surfaces a class may keep, per sensor channel: a class's
/// colour map has 3 × channels unknowns per level.
pub const MIN_SURFACES_PER_CHANNEL: usize = 4;

/// The most chroma classes a table may have.
pub const MAX_CHROMA_CLASSES: usize = 32;

/// The chroma classes of a sensor: one centroid per class, each a
/// chromaticity (white-balanced channel responses over their sum).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChromaClasses {
    pub centroids: Vec<Vec<f64>>,
    /// The neutral (channel responses to white, largest 1) the responses are
    /// balanced by when the light is not known: the training light's, or the
    /// geometric mean of an ensemble's. `None` in tables whose classes were
    /// fitted on raw ratios: they classify every light unbalanced.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub white: Option<Vec<f64>>,
}

/// `neutral` scaled so its largest channel is 1, or an error naming what is
/// wrong with it (a neutral must be positive and finite in every channel).
pub fn normalised_neutral(neutral: &[f64]) -> Result<Vec<f64>, ClassifyError> {
    let max = neutral.iter().copied().fold(0.0, f64::max);
    if neutral.is_empty() || !neutral.iter().all(|v| v.is_finite() && *v > 0.0) || max <= 0.0 {
        return Err(ClassifyError::InvalidInput(format!(
            "a light's neutral must be positive and finite in every channel, got {neutral:?}"
        )));
    }
    Ok(neutral.iter().map(|v| v / max).collect())
}

/// The channel-wise geometric mean of `neutrals` (each normalised), itself
/// normalised: the reference neutral of an ensemble of lights.
pub fn mean_neutral(neutrals: &[Vec<f64>]) -> Result<Vec<f64>, ClassifyError> {
    let normed = neutrals
        .iter()
        .map(|n| normalised_neutral(n))
        .collect::<Result<Vec<_>, _>>()?;
    let nc = normed.first().map(Vec::len).unwrap_or(0);
    if nc == 0 || normed.iter().any(|n| n.len() != nc) {
        return Err(ClassifyError::InvalidInput(
            "neutrals of one length are needed for a mean".into(),
        ));
    }
    let logs: Vec<f64> = (0..nc)
        .map(|ch| {
            let s: f64 = normed.iter().map(|n| n[ch].ln()).sum();
            (s / normed.len() as f64).exp()
        })
        .collect();
    normalised_neutral(&logs)
}

/// `channels` white-balanced by `neutral` (each channel over the light's
/// response to white); unchanged without a neutral or with one of another
/// length.
pub fn balanced(channels: &[f64], neutral: Option<&[f64]>) -> Vec<f64> {
    match neutral {
        Some(n) if n.len() == channels.len() => {
            channels.iter().zip(n).map(|(c, w)| c / w).collect()
        }
        _ => channels.to_vec(),
    }
}

/// The chromaticity of a channel response: each channel over the sum of
/// the (non-negative) responses; `None` when nothing responds.
pub fn chromaticity(channels: &[f64]) -> Option<Vec<f64>> {
    let clamped: Vec<f64> = channels.iter().map(|v| v.max(0.0)).collect();
    let sum: f64 = clamped.iter().sum();
    (sum.is_finite() && sum > 0.0).then(|| clamped.iter().map(|v| v / sum).collect())
}

fn distance2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

fn nearest(centroids: &[Vec<f64>], p: &[f64]) -> usize {
    let mut best = (0, f64::INFINITY);
    for (i, c) in centroids.iter().enumerate() {
        let d = distance2(c, p);
        if d < best.1 {
            best = (i, d);
        }
    }
    best.0
}

impl ChromaClasses {
    /// One class holding every response (a plain linear map).
    pub fn single(n_channels: usize) -> Self {
        Self {
            centroids: vec![vec![1.0 / n_channels.max(1) as f64; n_channels.max(1)]],
            white: None,
        }
    }

    pub fn len(&self) -> usize {
        self.centroids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.centroids.is_empty()
    }

    /// Up to `k` classes of `responses` (channel responses, one per
    /// surface, each lit by the light whose neutral is `neutrals[light[i]]`),
    /// each with at least `min_size` members, from `seed`. The classes are
    /// of white-balanced chromaticities; their reference neutral is the
    /// lights' mean ([`mean_neutral`]).
    pub fn fit_balanced(
        responses: &[Vec<f64>],
        light: &[usize],
        neutrals: &[Vec<f64>],
        k: usize,
        min_size: usize,
        seed: u64,
    ) -> Result<Self, ClassifyError> {
        let normed = neutrals
            .iter()
            .map(|n| normalised_neutral(n))
            .collect::<Result<Vec<_>, _>>()?;
        let balanced_responses = responses
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let n = normed
                    .get(light.get(i).copied().unwrap_or(0))
                    .ok_or_else(|| {
                        ClassifyError::InvalidInput(format!(
                            "response {i} is lit by an unknown light"
                        ))
                    })?;
                Ok(balanced(r, Some(n)))
            })
            .collect::<Result<Vec<_>, ClassifyError>>()?;
        let mut classes = Self::fit(&balanced_responses, k, min_size, seed)?;
        classes.white = Some(mean_neutral(&normed)?);
        Ok(classes)
    }

    /// Up to `k` classes of `responses` (channel responses, one per
    /// surface, taken as they are), each with at least `min_size` members,
    /// from `seed`.
    pub fn fit(
        responses: &[Vec<f64>],
        k: usize,
        min_size: usize,
        seed: u64,
    ) -> Result<Self, ClassifyError> {
        let points: Vec<Vec<f64>> = responses.iter().filter_map(|r| chromaticity(r)).collect();
        let nc = points.first().map(Vec::len).unwrap_or(0);
        if k == 0 || nc == 0 || points.iter().any(|p| p.len() != nc) {
            return Err(ClassifyError::InvalidParams(format!(
                "chroma classes need k ≥ 1 and responses of one length ({k} classes, {} points)",
                points.len()
            )));
        }
        if points.len() < min_size.max(1) {
            return Err(ClassifyError::InvalidParams(format!(
                "{} responding surfaces cannot make a class of {min_size}",
                points.len()
            )));
        }
        if k == 1 {
            return Ok(Self {
                centroids: vec![mean(&points, &vec![true; points.len()])],
                white: None,
            });
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut centroids = plus_plus_start(&points, k.min(points.len()), &mut rng);
        loop {
            let assign = lloyd(&points, &mut centroids);
            let sizes = (0..centroids.len())
                .map(|c| assign.iter().filter(|&&a| a == c).count())
                .collect::<Vec<_>>();
            // drop the smallest class under the minimum, then re-run
            let small = (0..centroids.len())
                .filter(|&c| sizes[c] < min_size)
                .min_by_key(|&c| sizes[c]);
            match small {
                Some(c) if centroids.len() > 1 => {
                    centroids.remove(c);
                }
                _ => break,
            }
        }
        Ok(Self {
            centroids,
            white: None,
        })
    }

    /// Check a stored set of classes for a sensor of `n_channels`: 1 to
    /// [`MAX_CHROMA_CLASSES`] centroids of that length, finite.
    pub fn validate(&self, n_channels: usize) -> Result<(), ClassifyError> {
        let n = self.centroids.len();
        if n == 0 || n > MAX_CHROMA_CLASSES {
            return Err(ClassifyError::InvalidParams(format!(
                "{n} chroma classes (1 to {MAX_CHROMA_CLASSES})"
            )));
        }
        if self
            .centroids
            .iter()
            .any(|c| c.len() != n_channels || c.iter().any(|v| !v.is_finite()))
        {
            return Err(ClassifyError::InvalidParams(format!(
                "chroma centroids must be {n_channels} finite values each"
            )));
        }
        if let Some(w) = &self.white {
            if w.len() != n_channels {
                return Err(ClassifyError::InvalidParams(format!(
                    "the chroma classes' neutral has {} values for {n_channels} channels",
                    w.len()
                )));
            }
            normalised_neutral(w).map_err(|e| ClassifyError::InvalidParams(e.to_string()))?;
        }
        Ok(())
    }

    /// The neutral a response under a light of neutral `light` is balanced
    /// by: `light` itself, the reference ([`Self::white`]) when the light is
    /// not known, none for classes of raw ratios.
    pub fn neutral_for<'a>(&'a self, light: Option<&'a [f64]>) -> Option<&'a [f64]> {
        self.white.as_ref()?;
        light.or(self.white.as_deref())
    }

    /// The class of a channel response under the light of neutral `light`
    /// (`None`: the reference light); class 0 when nothing responds.
    pub fn classify_under(&self, channels: &[f64], light: Option<&[f64]>) -> usize {
        self.classify_raw(&balanced(channels, self.neutral_for(light)))
    }

    /// The class of a channel response under the reference light (class 0
    /// when nothing responds).
    pub fn classify(&self, channels: &[f64]) -> usize {
        self.classify_under(channels, None)
    }

    fn classify_raw(&self, channels: &[f64]) -> usize {
        match chromaticity(channels) {
            Some(p) if self.centroids.len() > 1 => nearest(&self.centroids, &p),
            _ => 0,
        }
    }
}

fn mean(points: &[Vec<f64>], keep: &[bool]) -> Vec<f64> {
    let nc = points.first().map(Vec::len).unwrap_or(0);
    let mut sum = vec![0.0; nc];
    let mut n = 0usize;
    for (p, _) in points.iter().zip(keep).filter(|(_, k)| **k) {
        for (s, v) in sum.iter_mut().zip(p) {
            *s += v;
        }
        n += 1;
    }
    sum.iter().map(|s| s / n.max(1) as f64).collect()
}

/// k-means++: the first centre at random, each next one drawn with
/// probability proportional to the squared distance to the nearest centre.
fn plus_plus_start(points: &[Vec<f64>], k: usize, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
    let mut centroids = vec![points[rng.random_range(0..points.len())].clone()];
    while centroids.len() < k {
        let d: Vec<f64> = points
            .iter()
            .map(|p| distance2(p, &centroids[nearest(&centroids, p)]))
            .collect();
        let total: f64 = d.iter().sum();
        if total.is_nan() || total <= 0.0 {
            break; // every point is a centre already
        }
        let mut target = rng.random::<f64>() * total;
        let mut pick = points.len() - 1;
        for (i, v) in d.iter().enumerate() {
            if target < *v {
                pick = i;
                break;
            }
            target -= v;
        }
        centroids.push(points[pick].clone());
    }
    centroids
}

/// Lloyd's iterations until the assignment no longer changes; returns it.
/// A class left empty keeps its centre (and is dropped by the caller).
fn lloyd(points: &[Vec<f64>], centroids: &mut [Vec<f64>]) -> Vec<usize> {
    let mut assign: Vec<usize> = points.iter().map(|p| nearest(centroids, p)).collect();
    for _ in 0..MAX_ITERATIONS {
        for (c, centre) in centroids.iter_mut().enumerate() {
            let keep: Vec<bool> = assign.iter().map(|&a| a == c).collect();
            if keep.iter().any(|&k| k) {
                *centre = mean(points, &keep);
            }
        }
        let next: Vec<usize> = points.iter().map(|p| nearest(centroids, p)).collect();
        if next == assign {
            break;
        }
        assign = next;
    }
    assign
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Three well-separated groups of responses, each at several exposures.
    fn groups() -> Vec<Vec<f64>> {
        let centres = [[0.7, 0.2, 0.1], [0.1, 0.2, 0.7], [0.3, 0.5, 0.2]];
        let mut out = Vec::new();
        for (g, c) in centres.iter().enumerate() {
            for i in 0..20 {
                let scale = 0.5 + i as f64 * 0.1;
                let jitter = 0.01 * ((i * 7 + g) % 5) as f64;
                out.push(vec![
                    (c[0] + jitter) * scale,
                    c[1] * scale,
                    (c[2] - jitter).max(0.0) * scale,
                ]);
            }
        }
        out
    }

    #[test]
    fn separated_groups_get_one_class_each() {
        let pts = groups();
        let classes = ChromaClasses::fit(&pts, 3, 5, 7).unwrap();
        assert_eq!(classes.len(), 3);
        for g in 0..3 {
            let first = classes.classify(&pts[g * 20]);
            assert!(
                (0..20).all(|i| classes.classify(&pts[g * 20 + i]) == first),
                "group {g} split"
            );
        }
        let ids: std::collections::BTreeSet<usize> =
            (0..3).map(|g| classes.classify(&pts[g * 20])).collect();
        assert_eq!(ids.len(), 3, "two groups share a class");
    }

    #[test]
    fn the_same_seed_gives_the_same_classes() {
        let pts = groups();
        assert_eq!(
            ChromaClasses::fit(&pts, 4, 3, 11).unwrap(),
            ChromaClasses::fit(&pts, 4, 3, 11).unwrap()
        );
    }

    #[test]
    fn classes_under_the_minimum_size_are_dropped() {
        let mut pts = groups();
        pts.truncate(45); // the third group keeps 5 members
        let classes = ChromaClasses::fit(&pts, 3, 6, 7).unwrap();
        assert_eq!(classes.len(), 2);
        assert!(ChromaClasses::fit(&pts, 3, 100, 7).is_err());
    }

    #[test]
    fn one_class_and_silent_responses_go_to_class_zero() {
        let classes = ChromaClasses::fit(&groups(), 1, 1, 7).unwrap();
        assert_eq!(classes.len(), 1);
        assert_eq!(classes.classify(&[0.9, 0.05, 0.05]), 0);
        let three = ChromaClasses::fit(&groups(), 3, 5, 7).unwrap();
        assert_eq!(three.classify(&[0.0, 0.0, 0.0]), 0);
        assert_eq!(three.classify(&[f64::NAN; 3]), 0);
        assert!(ChromaClasses::fit(&[], 2, 1, 7).is_err());
        assert!(ChromaClasses::fit(&groups(), 0, 1, 7).is_err());
    }

    #[test]
    fn balanced_classes_put_a_surface_in_one_class_under_every_light() {
        let d65 = vec![0.8, 1.0, 0.9];
        let lamp = vec![1.0, 0.6, 0.25];
        // the groups' surfaces seen under both lights
        let surfaces = groups();
        let mut responses = Vec::new();
        let mut light = Vec::new();
        for (l, n) in [&d65, &lamp].into_iter().enumerate() {
            for s in &surfaces {
                responses.push(s.iter().zip(n.iter()).map(|(a, b)| a * b).collect());
                light.push(l);
            }
        }
        let neutrals = vec![d65.clone(), lamp.clone()];
        let classes = ChromaClasses::fit_balanced(&responses, &light, &neutrals, 3, 5, 7).unwrap();
        assert_eq!(classes.len(), 3);
        let n = surfaces.len();
        for i in 0..n {
            assert_eq!(
                classes.classify_under(&responses[i], Some(&d65)),
                classes.classify_under(&responses[n + i], Some(&lamp)),
                "surface {i}"
            );
        }
        // the reference is the lights' geometric mean, largest channel 1
        let white = classes.white.clone().unwrap();
        let expect = [
            (0.8f64 * 1.0).sqrt(),
            (1.0f64 * 0.6).sqrt(),
            (0.9f64 * 0.25).sqrt(),
        ];
        let max = expect.iter().copied().fold(0.0, f64::max);
        for (w, e) in white.iter().zip(expect) {
            assert!((w - e / max).abs() < 1e-12);
        }
        assert!(classes.validate(3).is_ok());
        // a light's neutral must respond in every channel
        assert!(
            ChromaClasses::fit_balanced(&responses, &light, &[d65, vec![1.0, 0.0, 0.2]], 3, 5, 7)
                .is_err()
        );
        assert!(ChromaClasses::fit_balanced(&responses, &light, &neutrals[..1], 3, 5, 7).is_err());
    }

    proptest! {
        /// Balanced, a class does not depend on the light's neutral.
        #[test]
        fn balanced_classes_do_not_depend_on_the_light(
            r in 0.01f64..1.0, g in 0.01f64..1.0, b in 0.01f64..1.0,
            nr in 0.05f64..1.0, ng in 0.05f64..1.0, nb in 0.05f64..1.0,
        ) {
            let mut classes = ChromaClasses::fit(&groups(), 3, 5, 7).unwrap();
            classes.white = Some(vec![1.0, 0.7, 0.4]);
            let n = [nr, ng, nb];
            prop_assert_eq!(
                classes.classify_under(&[r, g, b], Some(&[1.0, 1.0, 1.0])),
                classes.classify_under(&[r * nr, g * ng, b * nb], Some(&n))
            );
        }

        /// A class depends on the ratios of the responses, not on exposure.
        #[test]
        fn classes_do_not_depend_on_exposure(
            r in 0.01f64..1.0, g in 0.01f64..1.0, b in 0.01f64..1.0, scale in 1e-3f64..1e3,
        ) {
            let classes = ChromaClasses::fit(&groups(), 3, 5, 7).unwrap();
            prop_assert_eq!(
                classes.classify(&[r, g, b]),
                classes.classify(&[r * scale, g * scale, b * scale])
            );
        }
    }
}
