//! Seeded k-means (k-means++ initialisation, Lloyd iterations).

use rand::RngExt;
use rand_chacha::ChaCha8Rng;

/// A clustering: centroids and each point's cluster.
#[derive(Clone, Debug)]
pub(crate) struct Clustering {
    pub centroids: Vec<Vec<f64>>,
    pub assignment: Vec<usize>,
    /// Sum of squared distances from points to their centroids.
    pub inertia: f64,
}

fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

fn nearest(p: &[f64], centroids: &[Vec<f64>]) -> (usize, f64) {
    let mut best = (0, f64::INFINITY);
    for (j, c) in centroids.iter().enumerate() {
        let d = dist2(p, c);
        if d < best.1 {
            best = (j, d);
        }
    }
    best
}

/// k-means++ seeding: the first centre uniformly, each next one with
/// probability proportional to the squared distance to the nearest chosen
/// centre (uniform over unchosen points when all distances are zero).
fn kmeanspp(points: &[Vec<f64>], k: usize, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
    let n = points.len();
    let mut chosen = vec![false; n];
    let first = rng.random_range(0..n);
    chosen[first] = true;
    let mut centroids = vec![points[first].clone()];
    let mut d2: Vec<f64> = points.iter().map(|p| dist2(p, &points[first])).collect();
    while centroids.len() < k {
        let total: f64 = d2.iter().sum();
        let pick = if total > 0.0 {
            let mut u = rng.random::<f64>() * total;
            let mut pick = None;
            for (i, &d) in d2.iter().enumerate() {
                if d > 0.0 {
                    pick = Some(i);
                    if u < d {
                        break;
                    }
                    u -= d;
                }
            }
            pick
        } else {
            None
        };
        let pick = match pick {
            Some(i) => i,
            None => {
                let free: Vec<usize> = (0..n).filter(|&i| !chosen[i]).collect();
                free[rng.random_range(0..free.len())]
            }
        };
        chosen[pick] = true;
        centroids.push(points[pick].clone());
        for (d, p) in d2.iter_mut().zip(points) {
            *d = d.min(dist2(p, &points[pick]));
        }
    }
    centroids
}

fn lloyd(points: &[Vec<f64>], mut centroids: Vec<Vec<f64>>, max_iter: usize) -> Clustering {
    let (n, k, dim) = (points.len(), centroids.len(), points[0].len());
    let mut assignment = vec![usize::MAX; n];
    for _ in 0..max_iter {
        let mut changed = false;
        for (a, p) in assignment.iter_mut().zip(points) {
            let (j, _) = nearest(p, &centroids);
            if *a != j {
                *a = j;
                changed = true;
            }
        }
        if !changed {
            break;
        }
        let mut sums = vec![vec![0.0; dim]; k];
        let mut counts = vec![0usize; k];
        for (p, &a) in points.iter().zip(&assignment) {
            counts[a] += 1;
            for (s, v) in sums[a].iter_mut().zip(p) {
                *s += v;
            }
        }
        for j in 0..k {
            if counts[j] > 0 {
                centroids[j] = sums[j].iter().map(|s| s / counts[j] as f64).collect();
            } else {
                // Empty cluster: move it to the point farthest from its centroid.
                let far = (0..n)
                    .map(|i| (i, dist2(&points[i], &centroids[assignment[i]])))
                    .fold((0, -1.0), |b, x| if x.1 > b.1 { x } else { b })
                    .0;
                centroids[j] = points[far].clone();
                assignment[far] = j;
            }
        }
    }
    let inertia = points
        .iter()
        .zip(&assignment)
        .map(|(p, &a)| dist2(p, &centroids[a]))
        .sum();
    Clustering {
        centroids,
        assignment,
        inertia,
    }
}

/// k-means of `points` (at least `k` of them, `k ≥ 1`) with `restarts`
/// k-means++ starts from `rng`, keeping the lowest inertia (the first on
/// ties). Deterministic for a given generator state.
pub(crate) fn kmeans(
    points: &[Vec<f64>],
    k: usize,
    restarts: usize,
    rng: &mut ChaCha8Rng,
) -> Clustering {
    debug_assert!(k >= 1 && points.len() >= k);
    let mut best: Option<Clustering> = None;
    for _ in 0..restarts.max(1) {
        let c = lloyd(points, kmeanspp(points, k, rng), 300);
        if best.as_ref().is_none_or(|b| c.inertia < b.inertia) {
            best = Some(c);
        }
    }
    best.unwrap_or_else(|| lloyd(points, points[..k].to_vec(), 300))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// Sizes of each cluster.
    fn cluster_sizes(c: &Clustering) -> Vec<usize> {
        let mut s = vec![0; c.centroids.len()];
        for &a in &c.assignment {
            s[a] += 1;
        }
        s
    }

    #[test]
    fn finds_separated_blobs_deterministically() {
        let mut pts = Vec::new();
        for (cx, cy) in [(0.0, 0.0), (10.0, 0.0), (0.0, 10.0)] {
            for i in 0..10 {
                let t = i as f64 * 0.1;
                pts.push(vec![cx + t, cy - t * 0.5]);
            }
        }
        let run = || kmeans(&pts, 3, 5, &mut ChaCha8Rng::seed_from_u64(7));
        let a = run();
        assert_eq!(cluster_sizes(&a), vec![10, 10, 10]);
        assert_eq!(a.assignment, run().assignment);
        for blob in pts.chunks(10).zip(a.assignment.chunks(10)) {
            assert!(blob.1.iter().all(|&x| x == blob.1[0]));
        }
        // k = n: every point its own cluster, even with duplicates.
        let dup = vec![vec![1.0], vec![1.0], vec![2.0]];
        let c = kmeans(&dup, 3, 2, &mut ChaCha8Rng::seed_from_u64(1));
        assert_eq!(cluster_sizes(&c).iter().filter(|&&s| s > 0).count(), 3);
    }
}
