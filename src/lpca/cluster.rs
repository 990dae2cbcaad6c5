//! Local PCA by iterated clustering (Kambhatla and Leen 1997, as used by Müller et al. 2003,
//! section 3.3) over any matrix of row vectors.
//!
//! 1. Pick `K` distinct rows at random (seeded) as cluster centres; the bases start empty, so
//!    the first partition is by Euclidean distance to the centres.
//! 2. Assign every row to the cluster that reconstructs it best: the distance to cluster `j` is
//!    the squared reconstruction error `‖x − r_j − Σ_i ⟨x − r_j, e_ij⟩ e_ij‖²`.
//! 3. New centres: the mean of each cluster's rows.
//! 4. New bases: the top `C` principal directions of each cluster's centred rows
//!    ([`super::pca`]).
//! 5. Repeat 2-4 until the mean reconstruction error changes by less than `tolerance`
//!    (relative) or `max_iterations` updates were made; a last assignment (step 2) then fixes
//!    the partition and the weights `⟨x − r_j, e_ij⟩`.
//!
//! The distances to all clusters come from one GEMM per iteration: with the data centred on
//! its global mean, `‖x − r‖² − Σ ⟨x − r, e⟩² = ‖x‖² − 2⟨x, r⟩ + ‖r‖² − Σ (⟨x, e⟩ − ⟨r, e⟩)²`,
//! and all `⟨x, r_j⟩`, `⟨x, e_ij⟩` are one `n x d` by `d x K(C+1)` product.
//!
//! A cluster left empty is re-seeded at the row worst reconstructed so far (deterministic).

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use rand::SeedableRng;
use rand::seq::index::sample;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

use super::error::{LpcaError, Result};
use super::pca::principal_directions;
use crate::progress::Progress;

/// `K` clusters of row vectors of length `dim`, each a mean plus `C` orthonormal directions,
/// and every row's cluster and weights: row `i` is approximated by
/// `mean[k] + Σ_j weights[i][j] basis[k][j]` with `k = assignment[i]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Factorization {
    /// Vector length `d`.
    pub dim: usize,
    /// Components per cluster `C`.
    pub components: usize,
    /// `K x d`, row-major.
    pub means: Vec<f32>,
    /// `K x C x d`, row-major (cluster, component, value).
    pub bases: Vec<f32>,
    /// The cluster of every row (`n`).
    pub assignment: Vec<u16>,
    /// `n x C`, row-major.
    pub weights: Vec<f32>,
}

impl Factorization {
    /// Number of clusters `K`.
    pub fn clusters(&self) -> usize {
        self.means.len() / self.dim.max(1)
    }

    /// Number of rows `n`.
    pub fn items(&self) -> usize {
        self.assignment.len()
    }

    /// The reconstruction of value `j` of row `i`.
    pub fn value(&self, i: usize, j: usize) -> f32 {
        let (d, c) = (self.dim, self.components);
        let k = usize::from(self.assignment[i]);
        let mut v = self.means[k * d + j];
        for (t, &w) in self.weights[i * c..(i + 1) * c].iter().enumerate() {
            v += w * self.bases[(k * c + t) * d + j];
        }
        v
    }

    /// The whole reconstruction of row `i`.
    pub fn row(&self, i: usize) -> Vec<f32> {
        let (d, c) = (self.dim, self.components);
        let k = usize::from(self.assignment[i]);
        let mut v = self.means[k * d..(k + 1) * d].to_vec();
        for (t, &w) in self.weights[i * c..(i + 1) * c].iter().enumerate() {
            let e = &self.bases[(k * c + t) * d..(k * c + t + 1) * d];
            v.iter_mut().zip(e).for_each(|(x, &b)| *x += w * b);
        }
        v
    }

    /// Rounds every stored number through IEEE half precision (what the `.lpca` file keeps),
    /// so that the model in memory reconstructs exactly what its file will.
    pub fn round_to_half(&mut self) {
        let round = |v: &mut Vec<f32>| {
            v.iter_mut()
                .for_each(|x| *x = half::f16::from_f32(*x).to_f32());
        };
        round(&mut self.means);
        round(&mut self.bases);
        round(&mut self.weights);
    }
}

/// Parameters of [`fit_rows`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClusterOptions {
    /// Clusters `K` (1 = plain PCA).
    pub clusters: usize,
    /// Principal components per cluster `C`.
    pub components: usize,
    /// The most updates (steps 2-4) made.
    pub max_iterations: usize,
    /// Stop when the mean error changes by less than this fraction between iterations.
    pub tolerance: f64,
    /// Seed of the initial centres and of randomized PCA.
    pub seed: u64,
}

/// How the iteration went.
#[derive(Debug, Clone, PartialEq)]
pub struct FitStats {
    /// Updates (steps 2-4) made.
    pub iterations: usize,
    /// Whether the relative change of the mean error fell below the tolerance.
    pub converged: bool,
    /// The mean squared reconstruction error per row (sum over the `d` values) after each
    /// assignment, the last one being the final model's.
    pub error_history: Vec<f64>,
}

impl FitStats {
    /// The final model's mean squared reconstruction error per row.
    pub fn final_error(&self) -> f64 {
        self.error_history.last().copied().unwrap_or(0.0)
    }
}

/// Fits `K` local PCA clusters to the rows of `data` (`n x d`, row-major).
///
/// Memory: a centred copy of `data` is made (another `n * d` floats).
///
/// # Errors
/// Inconsistent sizes, `K` of 0, above 65535 or above `n`, `C` of 0 or above `d`, or an
/// eigen decomposition that fails.
pub fn fit_rows(
    data: &[f32],
    n: usize,
    d: usize,
    options: &ClusterOptions,
    progress: &dyn Progress,
) -> Result<(Factorization, FitStats)> {
    let (k, c) = (options.clusters, options.components);
    if n == 0 || d == 0 || data.len() != n * d {
        return Err(LpcaError::parameter(
            "data",
            format!("{} values for a {n} x {d} matrix", data.len()),
        ));
    }
    if k == 0 || k > usize::from(u16::MAX) || k > n {
        return Err(LpcaError::parameter(
            "--clusters",
            format!("{k} clusters for {n} vectors (1..={})", n.min(65535)),
        ));
    }
    if c == 0 || c > d {
        return Err(LpcaError::parameter(
            "--components",
            format!("{c} components for vectors of {d} values (1..={d})"),
        ));
    }
    if !(options.tolerance >= 0.0 && options.tolerance.is_finite()) {
        return Err(LpcaError::parameter(
            "tolerance",
            format!("{} is not a finite non-negative number", options.tolerance),
        ));
    }
    // Centre a copy on the global mean (accumulated in f64) so that the expanded distances
    // below do not cancel catastrophically; the caller's data stay untouched.
    let mut global = vec![0.0f64; d];
    for row in data.chunks_exact(d) {
        global
            .iter_mut()
            .zip(row)
            .for_each(|(g, &x)| *g += f64::from(x));
    }
    let global: Vec<f32> = global.iter().map(|g| (g / n as f64) as f32).collect();
    let mut centred = super::data::zeroed(n * d, "a centred copy of the data")?;
    centred
        .par_chunks_mut(d)
        .zip(data.par_chunks(d))
        .for_each(|(dst, row)| {
            dst.iter_mut()
                .zip(row)
                .zip(&global)
                .for_each(|((o, &x), &g)| *o = x - g);
        });
    let (mut f, stats) = iterate(&centred, n, d, options, progress)?;
    drop(centred);
    for mean in f.means.chunks_exact_mut(d) {
        mean.iter_mut().zip(&global).for_each(|(m, &g)| *m += g);
    }
    Ok((f, stats))
}

/// The loop of steps 2-5 on globally centred data.
fn iterate(
    x: &[f32],
    n: usize,
    d: usize,
    options: &ClusterOptions,
    progress: &dyn Progress,
) -> Result<(Factorization, FitStats)> {
    let (k, c) = (options.clusters, options.components);
    let norms: Vec<f64> = x
        .par_chunks(d)
        .map(|r| r.iter().map(|&v| f64::from(v) * f64::from(v)).sum())
        .collect();
    // Step 1: K distinct rows, empty bases.
    let mut rng = Pcg64Mcg::seed_from_u64(options.seed);
    let mut means = vec![0.0f32; k * d];
    let mut picks: Vec<usize> = sample(&mut rng, n, k).into_vec();
    picks.sort_unstable();
    for (j, &i) in picks.iter().enumerate() {
        means[j * d..(j + 1) * d].copy_from_slice(&x[i * d..(i + 1) * d]);
    }
    let mut bases = vec![0.0f32; k * c * d];
    let mut stats = FitStats {
        iterations: 0,
        converged: false,
        error_history: Vec::new(),
    };
    let single = k == 1;
    let max_iterations = if single { 1 } else { options.max_iterations };
    progress.start("clustering", max_iterations as u64 + 1);
    let mut current = assign(x, &norms, n, d, &means, &bases, k, c);
    stats.error_history.push(current.mean_error());
    progress.advance(1);
    while stats.iterations < max_iterations {
        // Steps 3 and 4.
        let seed = options
            .seed
            .wrapping_add((stats.iterations as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        update(x, n, d, &current, &mut means, &mut bases, k, c, seed)?;
        stats.iterations += 1;
        // Step 2 with the new clusters.
        current = assign(x, &norms, n, d, &means, &bases, k, c);
        let (prev, now) = (
            stats.error_history.last().copied().unwrap_or(0.0),
            current.mean_error(),
        );
        stats.error_history.push(now);
        progress.advance(1);
        if (prev - now).abs() <= options.tolerance * prev.abs() {
            stats.converged = true;
            break;
        }
    }
    progress.finish();
    if single {
        stats.converged = true;
    }
    Ok((
        Factorization {
            dim: d,
            components: c,
            means,
            bases,
            assignment: current.cluster.iter().map(|&j| j as u16).collect(),
            weights: current.weights,
        },
        stats,
    ))
}

/// The outcome of step 2.
struct Assignment {
    cluster: Vec<u32>,
    error: Vec<f64>,
    weights: Vec<f32>,
}

impl Assignment {
    fn mean_error(&self) -> f64 {
        self.error.iter().sum::<f64>() / self.error.len().max(1) as f64
    }
}

/// Step 2: every row to the cluster reconstructing it best, with its weights and error.
#[allow(clippy::too_many_arguments)]
fn assign(
    x: &[f32],
    norms: &[f64],
    n: usize,
    d: usize,
    means: &[f32],
    bases: &[f32],
    k: usize,
    c: usize,
) -> Assignment {
    let rows = k * (c + 1);
    let mut m = Vec::with_capacity(rows * d);
    m.extend_from_slice(means);
    m.extend_from_slice(bases);
    // Pᵀ = M Xᵀ (rows x n, column-major): each row's K(C+1) products are contiguous.
    let mut pt = Mat::<f32>::zeros(rows, n);
    matmul(
        pt.as_mut(),
        Accum::Replace,
        MatRef::from_row_major_slice(&m, rows, d),
        MatRef::from_row_major_slice(x, n, d).transpose(),
        1.0f32,
        Par::rayon(0),
    );
    // ‖r_j‖² and ⟨r_j, e_ij⟩, in f64.
    let dot = |a: &[f32], b: &[f32]| -> f64 {
        a.iter()
            .zip(b)
            .map(|(&u, &v)| f64::from(u) * f64::from(v))
            .sum()
    };
    let mm: Vec<f64> = (0..k)
        .map(|j| dot(&means[j * d..(j + 1) * d], &means[j * d..(j + 1) * d]))
        .collect();
    let me: Vec<f64> = (0..k * c)
        .map(|t| {
            let j = t / c;
            dot(&means[j * d..(j + 1) * d], &bases[t * d..(t + 1) * d])
        })
        .collect();
    let mut out = Assignment {
        cluster: vec![0; n],
        error: vec![0.0; n],
        weights: vec![0.0; n * c],
    };
    const CHUNK: usize = 256;
    out.cluster
        .par_chunks_mut(CHUNK)
        .zip(out.error.par_chunks_mut(CHUNK))
        .zip(out.weights.par_chunks_mut(CHUNK * c))
        .enumerate()
        .for_each(|(chunk, ((cl, er), we))| {
            let mut proj = vec![0.0f64; c];
            for (o, i) in (chunk * CHUNK..(chunk * CHUNK + cl.len())).enumerate() {
                let col = pt.col_as_slice(i);
                let mut best = (f64::INFINITY, 0usize);
                for j in 0..k {
                    let mut e = norms[i] - 2.0 * f64::from(col[j]) + mm[j];
                    let proj = &col[k + j * c..k + (j + 1) * c];
                    for (t, &v) in proj.iter().enumerate() {
                        let w = f64::from(v) - me[j * c + t];
                        e -= w * w;
                    }
                    if e < best.0 {
                        best = (e, j);
                    }
                }
                let j = best.1;
                for t in 0..c {
                    proj[t] = f64::from(col[k + j * c + t]) - me[j * c + t];
                }
                cl[o] = j as u32;
                er[o] = best.0.max(0.0);
                we[o * c..(o + 1) * c]
                    .iter_mut()
                    .zip(&proj)
                    .for_each(|(w, &v)| *w = v as f32);
            }
        });
    out
}

/// Steps 3 and 4: new means and bases from the current partition.
#[allow(clippy::too_many_arguments)]
fn update(
    x: &[f32],
    n: usize,
    d: usize,
    current: &Assignment,
    means: &mut [f32],
    bases: &mut [f32],
    k: usize,
    c: usize,
    seed: u64,
) -> Result<()> {
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); k];
    for (i, &j) in current.cluster.iter().enumerate() {
        members[j as usize].push(i);
    }
    // Empty clusters restart at the worst-reconstructed rows (of clusters with spare rows).
    let empty: Vec<usize> = (0..k).filter(|&j| members[j].is_empty()).collect();
    if !empty.is_empty() {
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| {
            current.error[b]
                .total_cmp(&current.error[a])
                .then(a.cmp(&b))
        });
        let mut donors = order.into_iter();
        for j in empty {
            // The worst row whose cluster keeps at least one other row.
            let Some(i) = donors.find(|&i| members[current.cluster[i] as usize].len() > 1) else {
                break;
            };
            let from = current.cluster[i] as usize;
            members[from].retain(|&r| r != i);
            members[j].push(i);
        }
    }
    let big = |m: &Vec<usize>| m.len() == n || m.len() * d >= 1 << 24;
    let fit = |j: usize, par: Par, warm: &[f32]| -> Result<(Vec<f32>, Vec<f32>)> {
        let rows = &members[j];
        if rows.len() == n {
            // One cluster of everything: the data are centred on their mean already (up to
            // rounding), so they are decomposed in place, without a copy.
            let mean = vec![0.0f32; d];
            let p = principal_directions(x, n, d, c, seed ^ j as u64, Some(warm), par)?;
            return Ok((mean, p.basis));
        }
        let mean = column_mean(x, n, d, rows);
        let mut y = Vec::with_capacity(rows.len() * d);
        for &i in rows {
            y.extend(
                x[i * d..(i + 1) * d]
                    .iter()
                    .zip(&mean)
                    .map(|(&v, &m)| v - m),
            );
        }
        let p = principal_directions(&y, rows.len(), d, c, seed ^ j as u64, Some(warm), par)?;
        Ok((mean, p.basis))
    };
    let small: Vec<usize> = (0..k).filter(|&j| !big(&members[j])).collect();
    type Fitted = (usize, Result<(Vec<f32>, Vec<f32>)>);
    let fitted: Vec<Fitted> = small
        .par_iter()
        .map(|&j| (j, fit(j, Par::Seq, &bases[j * c * d..(j + 1) * c * d])))
        .collect();
    let mut results = Vec::with_capacity(k);
    for (j, r) in fitted {
        results.push((j, r?));
    }
    for j in (0..k).filter(|&j| big(&members[j])) {
        let r = fit(j, Par::rayon(0), &bases[j * c * d..(j + 1) * c * d])?;
        results.push((j, r));
    }
    for (j, (mean, basis)) in results {
        if members[j].is_empty() {
            continue; // nothing to re-seed from (fewer rows than clusters cannot happen here)
        }
        means[j * d..(j + 1) * d].copy_from_slice(&mean);
        bases[j * c * d..(j + 1) * c * d].copy_from_slice(&basis);
    }
    Ok(())
}

/// The mean of the listed rows, accumulated in f64.
fn column_mean(x: &[f32], _n: usize, d: usize, rows: &[usize]) -> Vec<f32> {
    let mut acc = vec![0.0f64; d];
    for &i in rows {
        acc.iter_mut()
            .zip(&x[i * d..(i + 1) * d])
            .for_each(|(a, &v)| *a += f64::from(v));
    }
    let count = rows.len().max(1) as f64;
    acc.iter().map(|a| (a / count) as f32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::progress::NoProgress;
    use rand_distr::{Distribution, StandardNormal};

    /// Rows drawn from `groups` affine subspaces of dimension 2 in R^d, plus small noise.
    fn grouped(n: usize, d: usize, groups: usize, seed: u64) -> Vec<f32> {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let mut g = |_: usize| -> f32 { StandardNormal.sample(&mut rng) };
        let centres: Vec<Vec<f32>> = (0..groups)
            .map(|_| (0..d).map(|i| 3.0 * g(i)).collect())
            .collect();
        let dirs: Vec<Vec<f32>> = (0..groups * 2)
            .map(|_| (0..d).map(&mut g).collect())
            .collect();
        let mut x = Vec::with_capacity(n * d);
        for i in 0..n {
            let s = i % groups;
            let (a, b) = (g(0), g(0));
            for j in 0..d {
                x.push(centres[s][j] + a * dirs[2 * s][j] + b * dirs[2 * s + 1][j] + 0.01 * g(j));
            }
        }
        x
    }

    fn options(k: usize, c: usize) -> ClusterOptions {
        ClusterOptions {
            clusters: k,
            components: c,
            max_iterations: 30,
            tolerance: 1e-6,
            seed: 3,
        }
    }

    #[test]
    fn error_never_rises_and_local_beats_global() {
        let (n, d) = (600, 40);
        let x = grouped(n, d, 4, 1);
        let (f4, s4) = fit_rows(&x, n, d, &options(4, 2), &NoProgress).unwrap();
        for w in s4.error_history.windows(2) {
            assert!(
                w[1] <= w[0] * (1.0 + 1e-5),
                "error rose: {:?}",
                s4.error_history
            );
        }
        let (_, s1) = fit_rows(&x, n, d, &options(1, 2), &NoProgress).unwrap();
        assert!(
            s4.final_error() < 0.2 * s1.final_error(),
            "4 clusters {} vs 1 cluster {}",
            s4.final_error(),
            s1.final_error()
        );
        // The reported error is the reconstruction error of the returned factorization.
        let direct: f64 = (0..n)
            .map(|i| {
                f4.row(i)
                    .iter()
                    .zip(&x[i * d..(i + 1) * d])
                    .map(|(&r, &v)| f64::from(r - v).powi(2))
                    .sum::<f64>()
            })
            .sum::<f64>()
            / n as f64;
        assert!((direct - s4.final_error()).abs() <= 1e-3 * s4.final_error().max(1e-3));
    }

    #[test]
    fn same_seed_same_factorization() {
        let (n, d) = (300, 30);
        let x = grouped(n, d, 3, 2);
        let a = fit_rows(&x, n, d, &options(5, 3), &NoProgress).unwrap();
        let b = fit_rows(&x, n, d, &options(5, 3), &NoProgress).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn bad_parameters_are_errors() {
        let x = vec![0.0f32; 20];
        assert!(fit_rows(&x, 4, 5, &options(5, 1), &NoProgress).is_err());
        assert!(fit_rows(&x, 4, 5, &options(2, 6), &NoProgress).is_err());
        assert!(fit_rows(&x, 4, 5, &options(0, 1), &NoProgress).is_err());
        assert!(fit_rows(&x, 5, 5, &options(1, 1), &NoProgress).is_err());
        // Constant data: a valid, exact fit.
        let (f, s) = fit_rows(&x, 4, 5, &options(2, 2), &NoProgress).unwrap();
        assert_eq!(s.final_error(), 0.0);
        assert_eq!(f.row(3), vec![0.0; 5]);
    }
}
