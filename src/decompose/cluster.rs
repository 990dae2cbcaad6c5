//! Clustering of the view x light space into c subspace images (seed 001, sec. 5.3;
//! mrf_math.md 1(a)): every BTF image becomes a feature vector of cumulative colour histograms
//! in CIE Lab, k-means++ (seeded, with restarts) groups them, and each cluster is represented by
//! its member image nearest the centre. The (view, light) -> cluster table is part of a model.

use ndarray::Array3;
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;

use crate::btf::{Btf, BtfError};
use crate::color::linear_to_lab;
use crate::progress::Progress;

/// Settings of [`SubspaceClustering::fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClusterOptions {
    /// Number of subspace images c (the survey's default is 20). Reduced automatically when
    /// the BTF has fewer distinct images.
    pub clusters: usize,
    /// Seed of the k-means++ initialisation.
    pub seed: u64,
    /// Independent k-means runs; the one with the lowest within-cluster sum of squares wins.
    pub restarts: usize,
    /// Lloyd iterations per run at most.
    pub max_iterations: usize,
    /// Histogram bins per Lab channel.
    pub bins: usize,
}

impl Default for ClusterOptions {
    fn default() -> Self {
        Self {
            clusters: 20,
            seed: 1,
            restarts: 4,
            max_iterations: 100,
            bins: 32,
        }
    }
}

/// The cumulative histograms of L* in [0, 100] and a*, b* in [-128, 128), `bins` each,
/// concatenated (`3 * bins` values in [0, 1]). At most about 64 x 64 pixels are sampled.
pub fn lab_features(image: &Array3<f32>, bins: usize) -> Vec<f32> {
    let (_, h, w) = image.dim();
    let stride = (h.max(w) / 64).max(1);
    let mut hist = vec![0u32; 3 * bins];
    let mut count = 0u32;
    let bin = |v: f32, lo: f32, hi: f32| {
        (((v - lo) / (hi - lo) * bins as f32) as isize).clamp(0, bins as isize - 1) as usize
    };
    for y in (0..h).step_by(stride) {
        for x in (0..w).step_by(stride) {
            let lab = linear_to_lab(
                [image[[0, y, x]], image[[1, y, x]], image[[2, y, x]]].map(|v| v.clamp(0.0, 1.0)),
            );
            hist[bin(lab[0], 0.0, 100.0)] += 1;
            hist[bins + bin(lab[1], -128.0, 128.0)] += 1;
            hist[2 * bins + bin(lab[2], -128.0, 128.0)] += 1;
            count += 1;
        }
    }
    let mut out = vec![0f32; 3 * bins];
    for c in 0..3 {
        let mut acc = 0u32;
        for b in 0..bins {
            acc += hist[c * bins + b];
            out[c * bins + b] = acc as f32 / count.max(1) as f32;
        }
    }
    out
}

fn dist2(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum()
}

/// One k-means result: labels, centres and the within-cluster sum of squares.
#[derive(Debug, Clone)]
pub struct KMeans {
    /// Cluster of every point.
    pub labels: Vec<usize>,
    /// The cluster centres.
    pub centres: Vec<Vec<f32>>,
    /// Sum over points of the squared distance to their centre.
    pub inertia: f64,
}

/// k-means++ with `restarts` seeded runs; `k` is reduced to the number of distinct points.
/// An emptied cluster is re-seeded with the point farthest from its centre.
pub fn kmeans(
    points: &[Vec<f32>],
    k: usize,
    seed: u64,
    restarts: usize,
    max_iterations: usize,
) -> KMeans {
    let mut distinct: Vec<&Vec<f32>> = Vec::new();
    for p in points {
        if !distinct.contains(&p) {
            distinct.push(p);
            if distinct.len() >= k {
                break;
            }
        }
    }
    let k = k.clamp(1, distinct.len().max(1));
    (0..restarts.max(1))
        .map(|run| {
            kmeans_once(
                points,
                k,
                seed.wrapping_add(run as u64 * 0x9e37),
                max_iterations,
            )
        })
        .min_by(|a, b| a.inertia.total_cmp(&b.inertia))
        .expect("at least one run")
}

fn nearest(p: &[f32], centres: &[Vec<f32>]) -> (usize, f64) {
    centres
        .iter()
        .enumerate()
        .map(|(i, c)| (i, dist2(p, c)))
        .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
        .expect("at least one centre")
}

fn kmeans_once(points: &[Vec<f32>], k: usize, seed: u64, max_iterations: usize) -> KMeans {
    let mut rng = Pcg64::seed_from_u64(seed);
    let n = points.len();
    // k-means++ seeding: each next centre drawn with probability proportional to D^2.
    let mut centres = vec![points[rng.random_range(0..n)].clone()];
    let mut d2: Vec<f64> = points.iter().map(|p| dist2(p, &centres[0])).collect();
    while centres.len() < k {
        let total: f64 = d2.iter().sum();
        let pick = if total > 0.0 {
            let mut target = rng.random::<f64>() * total;
            d2.iter()
                .position(|&d| {
                    target -= d;
                    target <= 0.0
                })
                .unwrap_or(n - 1)
        } else {
            rng.random_range(0..n)
        };
        centres.push(points[pick].clone());
        for (d, p) in d2.iter_mut().zip(points) {
            *d = d.min(dist2(p, &centres[centres.len() - 1]));
        }
    }
    let mut labels = vec![usize::MAX; n];
    for _ in 0..max_iterations.max(1) {
        let assigned: Vec<(usize, f64)> = points.par_iter().map(|p| nearest(p, &centres)).collect();
        let changed = assigned.iter().zip(&labels).any(|(a, l)| a.0 != *l);
        labels = assigned.iter().map(|a| a.0).collect();
        let dim = points[0].len();
        let mut sums = vec![vec![0f64; dim]; k];
        let mut counts = vec![0usize; k];
        for (p, &l) in points.iter().zip(&labels) {
            counts[l] += 1;
            for (s, v) in sums[l].iter_mut().zip(p) {
                *s += f64::from(*v);
            }
        }
        for c in 0..k {
            if counts[c] == 0 {
                // Re-seed an empty cluster with the point worst served by its centre.
                let far = (0..n)
                    .max_by(|&a, &b| assigned[a].1.total_cmp(&assigned[b].1).then(b.cmp(&a)))
                    .expect("points");
                centres[c] = points[far].clone();
                labels[far] = c;
            } else {
                centres[c] = sums[c]
                    .iter()
                    .map(|s| (s / counts[c] as f64) as f32)
                    .collect();
            }
        }
        if !changed {
            break;
        }
    }
    let inertia = points
        .iter()
        .zip(&labels)
        .map(|(p, &l)| dist2(p, &centres[l]))
        .sum();
    KMeans {
        labels,
        centres,
        inertia,
    }
}

/// The view x light space split into subspaces, each represented by one measured image.
#[derive(Debug, Clone, PartialEq)]
pub struct SubspaceClustering {
    /// Number of lights of the BTF (the table is view-major).
    pub lights: usize,
    /// Cluster of image (view, light) at `view * lights + light`.
    pub labels: Vec<u16>,
    /// The (view, light) of each cluster's representative image.
    pub representatives: Vec<(usize, usize)>,
}

impl SubspaceClustering {
    /// Clusters every image of `btf`.
    ///
    /// # Errors
    /// An image cannot be read.
    pub fn fit(
        btf: &Btf,
        options: &ClusterOptions,
        progress: &dyn Progress,
    ) -> Result<Self, BtfError> {
        let lights = btf.lights().len();
        let total = btf.image_count();
        progress.start("clustering", total as u64);
        let features: Vec<Vec<f32>> = (0..total)
            .into_par_iter()
            .map(|i| {
                let f = lab_features(&btf.image(i / lights, i % lights)?, options.bins);
                progress.advance(1);
                Ok(f)
            })
            .collect::<Result<_, BtfError>>()?;
        progress.finish();
        let km = kmeans(
            &features,
            options.clusters.min(u16::MAX as usize),
            options.seed,
            options.restarts,
            options.max_iterations,
        );
        let representatives = (0..km.centres.len())
            .map(|c| {
                let best = (0..total)
                    .filter(|&i| km.labels[i] == c)
                    .min_by(|&a, &b| {
                        dist2(&features[a], &km.centres[c])
                            .total_cmp(&dist2(&features[b], &km.centres[c]))
                            .then(a.cmp(&b))
                    })
                    .expect("no cluster is empty after k-means");
                (best / lights, best % lights)
            })
            .collect();
        Ok(Self {
            lights,
            labels: km.labels.iter().map(|&l| l as u16).collect(),
            representatives,
        })
    }

    /// Number of subspace images.
    pub fn clusters(&self) -> usize {
        self.representatives.len()
    }

    /// The cluster of image (view, light).
    pub fn cluster_of(&self, view: usize, light: usize) -> usize {
        usize::from(self.labels[view * self.lights + light])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kmeans_finds_obvious_groups_deterministically() {
        let mut pts = Vec::new();
        for i in 0..30 {
            let base = [0.0f32, 5.0, 10.0][i % 3];
            pts.push(vec![base + (i as f32 * 0.01), base]);
        }
        let a = kmeans(&pts, 3, 7, 3, 50);
        let b = kmeans(&pts, 3, 7, 3, 50);
        assert_eq!(a.labels, b.labels);
        for i in 0..30 {
            assert_eq!(a.labels[i], a.labels[i % 3], "point {i}");
        }
        assert!(a.inertia < 0.3, "{}", a.inertia); // the within-group spread alone is 0.22
    }

    #[test]
    fn k_larger_than_distinct_points_is_reduced() {
        let pts = vec![vec![1.0f32], vec![1.0], vec![2.0], vec![2.0]];
        let km = kmeans(&pts, 20, 1, 2, 10);
        assert_eq!(km.centres.len(), 2);
        assert_eq!(km.labels[0], km.labels[1]);
        assert_ne!(km.labels[0], km.labels[2]);
    }

    #[test]
    fn features_are_cumulative() {
        let img = Array3::from_shape_fn((3, 8, 8), |(c, y, _)| 0.1 * (c + y) as f32);
        let f = lab_features(&img, 16);
        assert_eq!(f.len(), 48);
        for c in 0..3 {
            assert!((f[c * 16 + 15] - 1.0).abs() < 1e-6);
            assert!(f[c * 16..c * 16 + 16].windows(2).all(|w| w[0] <= w[1]));
        }
    }
}
