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
/// `mean(k) + Σ_t weights_of(i)[t] component(k, t)` with `k = cluster_of(i)`.
///
/// Stored flat (means `K x d`, bases `K x C x d`, weights `n x C`, row-major) and read through
/// the accessors below, which hold the index arithmetic in one place.
#[derive(Debug, Clone, PartialEq)]
pub struct Factorization {
    dim: usize,
    components: usize,
    means: Vec<f32>,
    bases: Vec<f32>,
    assignment: Vec<u16>,
    weights: Vec<f32>,
}

impl Factorization {
    /// A factorization from its arrays (`K x d` means, `K x C x d` bases, `n` cluster indices,
    /// `n x C` weights, all row-major), checking that they fit together.
    ///
    /// # Errors
    /// A size of zero, `C` above `d`, array lengths that disagree, more clusters than rows or
    /// than 65535, or a cluster index out of range; the reason is returned.
    pub fn new(
        dim: usize,
        components: usize,
        means: Vec<f32>,
        bases: Vec<f32>,
        assignment: Vec<u16>,
        weights: Vec<f32>,
    ) -> Result<Self, String> {
        let (d, c, n) = (dim, components, assignment.len());
        if d == 0 || c == 0 || c > d {
            return Err(format!("{c} components for vectors of {d} values"));
        }
        let k = means.len() / d;
        if k == 0 || !means.len().is_multiple_of(d) {
            return Err(format!("{} mean values for vectors of {d}", means.len()));
        }
        if k > usize::from(u16::MAX) || k > n {
            return Err(format!("{k} clusters for {n} vectors"));
        }
        if bases.len() != k * c * d {
            return Err(format!(
                "{} basis values for {k} clusters of {c} components of {d}",
                bases.len()
            ));
        }
        if weights.len() != n * c {
            return Err(format!(
                "{} weights for {n} vectors of {c} components",
                weights.len()
            ));
        }
        if let Some(bad) = assignment.iter().find(|&&j| usize::from(j) >= k) {
            return Err(format!("cluster index {bad} of {k} clusters"));
        }
        Ok(Self {
            dim,
            components,
            means,
            bases,
            assignment,
            weights,
        })
    }

    /// Vector length `d`.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Components per cluster `C`.
    pub fn components(&self) -> usize {
        self.components
    }

    /// Number of clusters `K`.
    pub fn clusters(&self) -> usize {
        self.means.len() / self.dim.max(1)
    }

    /// Number of rows `n`.
    pub fn items(&self) -> usize {
        self.assignment.len()
    }

    /// The mean of cluster `k` (`d` values).
    pub fn mean(&self, k: usize) -> &[f32] {
        &self.means[k * self.dim..(k + 1) * self.dim]
    }

    /// Principal direction `t` of cluster `k` (`d` values).
    pub fn component(&self, k: usize, t: usize) -> &[f32] {
        let at = (k * self.components + t) * self.dim;
        &self.bases[at..at + self.dim]
    }

    /// The cluster of row `i`.
    pub fn cluster_of(&self, i: usize) -> usize {
        usize::from(self.assignment[i])
    }

    /// The `C` weights of row `i`.
    pub fn weights_of(&self, i: usize) -> &[f32] {
        &self.weights[i * self.components..(i + 1) * self.components]
    }

    /// The cluster of every row (`n`), for upload or storage.
    pub fn assignment(&self) -> &[u16] {
        &self.assignment
    }

    /// The weights of every row, `n x C` row-major, for upload or storage.
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    /// The `C + 1` terms of cluster `k` at values `col..col + 3` (one RGB triple of a
    /// BRDF-wise or reflectance-field vector): the mean first, then each component. A row's
    /// triple is `terms[0] + Σ_t weights_of(i)[t] terms[1 + t]`; this is the decoding table of
    /// [`super::LpcaModel::reconstruct`] and of the GPU renderer.
    pub fn rgb_terms(&self, k: usize, col: usize) -> impl Iterator<Item = [f32; 3]> + '_ {
        std::iter::once(self.mean(k))
            .chain((0..self.components).map(move |t| self.component(k, t)))
            .map(move |v| [v[col], v[col + 1], v[col + 2]])
    }

    /// The whole reconstruction of row `i`.
    pub fn row(&self, i: usize) -> Vec<f32> {
        let k = self.cluster_of(i);
        let mut v = self.mean(k).to_vec();
        for (t, &w) in self.weights_of(i).iter().enumerate() {
            v.iter_mut()
                .zip(self.component(k, t))
                .for_each(|(x, &b)| *x += w * b);
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
pub struct FactorizationOptions {
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
    options: &FactorizationOptions,
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
    let x = Matrix {
        values: &centred,
        rows: n,
        dim: d,
    };
    let (mut f, stats) = iterate(x, options, progress)?;
    drop(centred);
    for mean in f.means.chunks_exact_mut(d) {
        mean.iter_mut().zip(&global).for_each(|(m, &g)| *m += g);
    }
    Ok((f, stats))
}

/// A data matrix: `rows` vectors of `dim` values, row-major.
#[derive(Clone, Copy)]
struct Matrix<'a> {
    values: &'a [f32],
    rows: usize,
    dim: usize,
}

impl Matrix<'_> {
    fn row(&self, i: usize) -> &[f32] {
        &self.values[i * self.dim..(i + 1) * self.dim]
    }

    /// The mean of the listed rows, accumulated in f64.
    fn mean_of(&self, rows: &[usize]) -> Vec<f32> {
        let mut acc = vec![0.0f64; self.dim];
        for &i in rows {
            acc.iter_mut()
                .zip(self.row(i))
                .for_each(|(a, &v)| *a += f64::from(v));
        }
        let count = rows.len().max(1) as f64;
        acc.iter().map(|a| (a / count) as f32).collect()
    }
}

/// The clusters being iterated: `K` means (`K x d`) and bases (`K x C x d`), row-major.
struct Clusters {
    count: usize,
    components: usize,
    dim: usize,
    means: Vec<f32>,
    bases: Vec<f32>,
}

impl Clusters {
    fn mean(&self, j: usize) -> &[f32] {
        &self.means[j * self.dim..(j + 1) * self.dim]
    }

    /// The `C x d` basis of cluster `j`.
    fn basis(&self, j: usize) -> &[f32] {
        let size = self.components * self.dim;
        &self.bases[j * size..(j + 1) * size]
    }

    fn component(&self, j: usize, t: usize) -> &[f32] {
        &self.basis(j)[t * self.dim..(t + 1) * self.dim]
    }

    fn set(&mut self, j: usize, mean: &[f32], basis: &[f32]) {
        let size = self.components * self.dim;
        self.means[j * self.dim..(j + 1) * self.dim].copy_from_slice(mean);
        self.bases[j * size..(j + 1) * size].copy_from_slice(basis);
    }
}

/// The loop of steps 2-5 on globally centred data.
fn iterate(
    x: Matrix,
    options: &FactorizationOptions,
    progress: &dyn Progress,
) -> Result<(Factorization, FitStats)> {
    let (n, d) = (x.rows, x.dim);
    let (k, c) = (options.clusters, options.components);
    let norms: Vec<f64> = x
        .values
        .par_chunks(d)
        .map(|r| r.iter().map(|&v| f64::from(v) * f64::from(v)).sum())
        .collect();
    // Step 1: K distinct rows, empty bases.
    let mut rng = Pcg64Mcg::seed_from_u64(options.seed);
    let mut picks: Vec<usize> = sample(&mut rng, n, k).into_vec();
    picks.sort_unstable();
    let mut clusters = Clusters {
        count: k,
        components: c,
        dim: d,
        means: picks.iter().flat_map(|&i| x.row(i)).copied().collect(),
        bases: vec![0.0f32; k * c * d],
    };
    let mut stats = FitStats {
        iterations: 0,
        converged: false,
        error_history: Vec::new(),
    };
    let single = k == 1;
    let max_iterations = if single { 1 } else { options.max_iterations };
    progress.start("clustering", max_iterations as u64 + 1);
    let mut current = assign(x, &norms, &clusters);
    stats.error_history.push(current.mean_error());
    progress.advance(1);
    while stats.iterations < max_iterations {
        // Steps 3 and 4.
        let seed = options
            .seed
            .wrapping_add((stats.iterations as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        update(x, &current, &mut clusters, seed)?;
        stats.iterations += 1;
        // Step 2 with the new clusters.
        current = assign(x, &norms, &clusters);
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
            means: clusters.means,
            bases: clusters.bases,
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

/// Step 2: every row of `x` (with squared norms `norms`) to the cluster reconstructing it
/// best, with its weights and error.
fn assign(x: Matrix, norms: &[f64], clusters: &Clusters) -> Assignment {
    let (n, d) = (x.rows, x.dim);
    let (k, c) = (clusters.count, clusters.components);
    let rows = k * (c + 1);
    let mut m = Vec::with_capacity(rows * d);
    m.extend_from_slice(&clusters.means);
    m.extend_from_slice(&clusters.bases);
    // Pᵀ = M Xᵀ (rows x n, column-major): each row's K(C+1) products are contiguous.
    let mut pt = Mat::<f32>::zeros(rows, n);
    matmul(
        pt.as_mut(),
        Accum::Replace,
        MatRef::from_row_major_slice(&m, rows, d),
        MatRef::from_row_major_slice(x.values, n, d).transpose(),
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
        .map(|j| dot(clusters.mean(j), clusters.mean(j)))
        .collect();
    let me: Vec<f64> = (0..k * c)
        .map(|t| dot(clusters.mean(t / c), clusters.component(t / c, t % c)))
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

/// Steps 3 and 4: new means and bases of `clusters` from the current partition of `x`
/// (`seed` drives randomized PCA).
fn update(x: Matrix, current: &Assignment, clusters: &mut Clusters, seed: u64) -> Result<()> {
    let (n, d) = (x.rows, x.dim);
    let (k, c) = (clusters.count, clusters.components);
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
    let fit = |j: usize, par: Par| -> Result<(Vec<f32>, Vec<f32>)> {
        let rows = &members[j];
        let warm = Some(clusters.basis(j));
        if rows.len() == n {
            // One cluster of everything: the data are centred on their mean already (up to
            // rounding), so they are decomposed in place, without a copy.
            let mean = vec![0.0f32; d];
            let p = principal_directions(x.values, n, d, c, seed ^ j as u64, warm, par)?;
            return Ok((mean, p.basis));
        }
        let mean = x.mean_of(rows);
        let mut y = Vec::with_capacity(rows.len() * d);
        for &i in rows {
            y.extend(x.row(i).iter().zip(&mean).map(|(&v, &m)| v - m));
        }
        let p = principal_directions(&y, rows.len(), d, c, seed ^ j as u64, warm, par)?;
        Ok((mean, p.basis))
    };
    let small: Vec<usize> = (0..k).filter(|&j| !big(&members[j])).collect();
    type Fitted = (usize, Result<(Vec<f32>, Vec<f32>)>);
    let fitted: Vec<Fitted> = small.par_iter().map(|&j| (j, fit(j, Par::Seq))).collect();
    let mut results = Vec::with_capacity(k);
    for (j, r) in fitted {
        results.push((j, r?));
    }
    for j in (0..k).filter(|&j| big(&members[j])) {
        results.push((j, fit(j, Par::rayon(0))?));
    }
    for (j, (mean, basis)) in results {
        if members[j].is_empty() {
            continue; // nothing to re-seed from (fewer rows than clusters cannot happen here)
        }
        clusters.set(j, &mean, &basis);
    }
    Ok(())
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

    fn options(k: usize, c: usize) -> FactorizationOptions {
        FactorizationOptions {
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

    #[test]
    fn accessors_agree_with_the_documented_layout() {
        // K = 2, C = 2, d = 3, n = 3.
        let means = vec![0.0, 1.0, 2.0, 10.0, 11.0, 12.0];
        let bases: Vec<f32> = (0..12).map(|v| v as f32 * 0.5).collect();
        let weights = vec![1.0, 0.0, 0.0, 1.0, 2.0, -1.0];
        let f = Factorization::new(3, 2, means, bases, vec![1, 0, 1], weights).unwrap();
        assert_eq!(
            (f.clusters(), f.items(), f.components(), f.dim()),
            (2, 3, 2, 3)
        );
        assert_eq!(f.mean(1), &[10.0, 11.0, 12.0]);
        assert_eq!(f.component(1, 0), &[3.0, 3.5, 4.0]);
        assert_eq!(f.component(0, 1), &[1.5, 2.0, 2.5]);
        assert_eq!((f.cluster_of(2), f.weights_of(2)), (1, &[2.0, -1.0][..]));
        // Row 0: cluster 1, weights (1, 0): mean(1) + component(1, 0).
        assert_eq!(f.row(0), vec![13.0, 14.5, 16.0]);
        let terms: Vec<[f32; 3]> = f.rgb_terms(1, 0).collect();
        assert_eq!(
            terms,
            vec![[10.0, 11.0, 12.0], [3.0, 3.5, 4.0], [4.5, 5.0, 5.5]]
        );
    }

    #[test]
    fn arrays_that_do_not_fit_together_are_refused() {
        let ok = |m: usize, b: usize, a: Vec<u16>, w: usize| {
            Factorization::new(3, 2, vec![0.0; m], vec![0.0; b], a, vec![0.0; w])
        };
        ok(6, 12, vec![0, 1, 1], 6).unwrap();
        assert!(ok(5, 12, vec![0, 1, 1], 6).unwrap_err().contains("mean"));
        assert!(ok(6, 11, vec![0, 1, 1], 6).unwrap_err().contains("basis"));
        assert!(ok(6, 12, vec![0, 1, 1], 5).unwrap_err().contains("weights"));
        assert!(
            ok(6, 12, vec![0, 2, 1], 6)
                .unwrap_err()
                .contains("cluster index 2")
        );
        assert!(
            ok(6, 12, vec![0], 2)
                .unwrap_err()
                .contains("2 clusters for 1")
        );
        assert!(ok(0, 0, vec![], 0).is_err());
        assert!(
            Factorization::new(3, 4, vec![0.0; 3], vec![0.0; 12], vec![0], vec![0.0; 4])
                .unwrap_err()
                .contains("components")
        );
    }
}
