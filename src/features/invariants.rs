//! The numerical core of the features: colour whitening, the per-level 3D CAR invariants, the
//! per-channel 2D CAR coefficients and the gain-normalised colour moments. Small pure
//! functions over `f64` arrays; see the module docs of [`super`] for the maths.

use nalgebra::{DMatrix, Matrix3, SymmetricEigen};
use ndarray::{Array3, Axis};

use crate::mrf::neighbourhood::reach;
use crate::mrf::{car2d, car3d, is_flat};

use super::D;

/// Colour directions whose variance is below this fraction of the largest one are treated as
/// absent (rank-deficient colour, e.g. a grey photograph).
const RANK_TOLERANCE: f64 = 1e-6;

/// In an image stored at 8 bits, colour directions whose variance is below this many times the
/// variance of 8-bit sRGB rounding (at the image's brightest channel mean) are treated as
/// absent too: what they hold is the rounding error of a grey or near-grey photograph, not
/// texture.
const QUANTISATION_FLOOR: f64 = 10.0;

/// Variance of the rounding error of 8-bit sRGB storage, in linear units, at linear level `m`
/// (a uniform error of one code step: `step^2 / 12`).
fn srgb8_rounding_variance(m: f64) -> f64 {
    use crate::color::{linear_to_srgb, srgb_to_linear};
    let m = m.clamp(0.0, 1.0) as f32;
    let encoded = linear_to_srgb(m);
    let step = if encoded + 1.0 / 255.0 <= 1.0 {
        srgb_to_linear(encoded + 1.0 / 255.0) - m
    } else {
        m - srgb_to_linear(encoded - 1.0 / 255.0)
    };
    (step as f64).powi(2) / 12.0
}

/// Smallest share of innovation kept (bounds `alpha3` by `sqrt(3e6)` for perfectly predictable
/// levels such as a linear ramp).
const MIN_INNOVATION: f64 = 1e-6;

/// Relative ridge added to the normal equations (times their mean diagonal).
const RIDGE: f64 = 1e-9;

/// The whitening map of an image's colours: rows `u_j^T / sqrt(lambda_j)` of the covariance
/// eigenvectors that carry variance (between 0 and 3 of them), with the unit eigenvectors and
/// the mean colour, to project the image onto the colour directions it really has.
#[derive(Debug, Clone)]
pub(super) struct Whitening {
    rows: Vec<[f64; 3]>,
    directions: Vec<[f64; 3]>,
    mean: [f64; 3],
}

impl Whitening {
    /// The whitening of a `(3, h, w)` image (its colour covariance over all pixels);
    /// `eight_bit`: the image was stored at 8 bits (see [`looks_8bit`]), so directions at the
    /// level of rounding noise are dropped.
    pub(super) fn of(image: &Array3<f64>, eight_bit: bool) -> Self {
        let n = (image.len() / D).max(1) as f64;
        let mean: [f64; 3] = std::array::from_fn(|c| image.index_axis(Axis(0), c).sum() / n);
        let mut cov = Matrix3::<f64>::zeros();
        for i in 0..D {
            for j in 0..=i {
                let a = image.index_axis(Axis(0), i);
                let b = image.index_axis(Axis(0), j);
                let s = ndarray::Zip::from(&a)
                    .and(&b)
                    .fold(0.0, |acc, &x, &y| acc + (x - mean[i]) * (y - mean[j]));
                cov[(i, j)] = s / n;
                cov[(j, i)] = s / n;
            }
        }
        let eigen = SymmetricEigen::new(cov);
        let largest = eigen.eigenvalues.max();
        let magnitude = mean.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if is_flat(magnitude, largest.max(0.0)) {
            return Self {
                rows: Vec::new(),
                directions: Vec::new(),
                mean,
            };
        }
        let floor = if eight_bit {
            (RANK_TOLERANCE * largest).max(QUANTISATION_FLOOR * srgb8_rounding_variance(magnitude))
        } else {
            RANK_TOLERANCE * largest
        };
        let mut order: Vec<usize> = (0..D).collect();
        order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
        let kept: Vec<usize> = order
            .into_iter()
            .filter(|&j| eigen.eigenvalues[j] > floor)
            .collect();
        let unit = |j: usize| -> [f64; 3] { std::array::from_fn(|c| eigen.eigenvectors[(c, j)]) };
        let rows = kept
            .iter()
            .map(|&j| unit(j).map(|u| u / eigen.eigenvalues[j].sqrt()))
            .collect();
        Self {
            rows,
            directions: kept.into_iter().map(unit).collect(),
            mean,
        }
    }

    /// The image with its colours projected onto the kept colour directions (mean colour plus
    /// the components along them): what is left when storage noise in the absent directions
    /// is removed. Unchanged (a copy) when all three directions carry variance.
    pub(super) fn project(&self, image: &Array3<f64>) -> Array3<f64> {
        if self.directions.len() == D {
            return image.clone();
        }
        let mut out = Array3::<f64>::zeros(image.dim());
        let (_, h, w) = image.dim();
        for r in 0..h {
            for x in 0..w {
                let y: [f64; 3] = std::array::from_fn(|c| image[[c, r, x]] - self.mean[c]);
                let mut p = self.mean;
                for u in &self.directions {
                    let t = u[0] * y[0] + u[1] * y[1] + u[2] * y[2];
                    for (pc, uc) in p.iter_mut().zip(u) {
                        *pc += t * uc;
                    }
                }
                for (c, v) in p.into_iter().enumerate() {
                    out[[c, r, x]] = v;
                }
            }
        }
        out
    }

    /// The statistics of the whitened level from those of the raw level: `T V T^T` with
    /// `T = diag(W, ..., W)` (`1 + eta` blocks, `W` is `k x 3`); `None` when the colour has
    /// rank 0. Whitening commutes with the statistics because both are linear.
    pub(super) fn congruence(&self, v: &DMatrix<f64>, eta: usize) -> Option<DMatrix<f64>> {
        let k = self.rows.len();
        if k == 0 {
            return None;
        }
        let mut t = DMatrix::<f64>::zeros(k * (1 + eta), D * (1 + eta));
        for block in 0..=eta {
            for (j, row) in self.rows.iter().enumerate() {
                for (c, &weight) in row.iter().enumerate() {
                    t[(block * k + j, block * D + c)] = weight;
                }
            }
        }
        Some(&t * v * t.transpose())
    }
}

/// True when up to 4096 evenly spread values of the image are all exact 8-bit sRGB codes
/// (decoded), i.e. the image was almost surely read from an 8-bit file.
pub(super) fn looks_8bit(image: &Array3<f32>) -> bool {
    let encoder = crate::color::Srgb8Encoder::new();
    let table = crate::color::srgb8_to_linear_table();
    let n = image.len();
    let stride = (n / 4096).max(1);
    image
        .iter()
        .step_by(stride)
        .all(|&v| (0.0..=1.0).contains(&v) && table[encoder.encode(v) as usize] == v)
}

/// Number of 3D CAR features per level for `eta` neighbours.
pub(super) fn car3d_len(eta: usize) -> usize {
    eta + D * eta + eta + 1 + D
}

/// All features of one `(3, h, w)` pyramid level: the 3D CAR invariants of the whitened
/// colours ([`car3d_invariants`]), then the 2D CAR `gamma` of R, G and B ([`car2d_gamma`]).
/// One pass over the level: the raw 3-channel statistics hold the per-channel ones as
/// principal sub-matrices, and the whitened ones by congruence.
pub(super) fn level_features(
    level: &Array3<f64>,
    whitening: &Whitening,
    offsets: &[(isize, isize)],
) -> Vec<f64> {
    let eta = offsets.len();
    let (_, h, w) = level.dim();
    let (up, left, right) = reach(offsets);
    let sites = h.saturating_sub(up) * w.saturating_sub(left + right);
    let n = (h * w).max(1) as f64;
    let means: Vec<f64> = level.outer_iter().map(|p| p.sum() / n).collect();
    let mut centred = level.clone();
    for (mut p, m) in centred.outer_iter_mut().zip(&means) {
        p.mapv_inplace(|v| v - m);
    }
    let raw = (sites > 0).then(|| car3d::statistics(&centred, offsets).0);
    let whitened = raw
        .as_ref()
        .filter(|_| sites >= 2 * D * eta)
        .and_then(|v| whitening.congruence(v, eta));
    let mut out = car3d_invariants(whitened, eta);
    for (c, &mean) in means.iter().enumerate() {
        let channel = raw.as_ref().filter(|_| sites >= 2 * eta).map(|v| {
            let idx: Vec<usize> = (0..=eta).map(|b| b * D + c).collect();
            v.select_rows(&idx).select_columns(&idx)
        });
        out.extend(car2d_gamma(channel, mean, sites, eta));
    }
    out
}

/// The 3D CAR invariants from the statistics `v` of a whitened level with `k <= 3` colour
/// directions (`v` is `k (1 + eta)` square): `tr A_s` (per offset), the real parts of the
/// eigenvalues of every `A_s` (sorted descending, 3 per offset), their largest absolute
/// imaginary part (1 per offset), `alpha3`, and the eigenvalues of `Sigma Phi^-1` (sorted descending). Missing
/// colour directions, levels too small to fit (`None`) and failed fits count as white noise
/// (eigenvalue 0, innovation share 1).
pub(super) fn car3d_invariants(v: Option<DMatrix<f64>>, eta: usize) -> Vec<f64> {
    let fitted = v.and_then(|mut v| {
        let dim = v.nrows();
        let k = dim / (1 + eta);
        let ridge = RIDGE * v.trace() / dim as f64 + 1e-300;
        for i in 0..dim {
            v[(i, i)] += ridge;
        }
        car3d::estimate(&v, k, eta).map(|(gamma_t, lambda)| {
            let vyy = v.view((0, 0), (k, k)).into_owned();
            (k, gamma_t, innovation_shares(&lambda, &vyy))
        })
    });
    let mut out = Vec::with_capacity(car3d_len(eta));
    let (traces, re, im, shares) = match fitted {
        None => (
            vec![0.0; eta],
            vec![0.0; D * eta],
            vec![0.0; eta],
            vec![1.0; D],
        ),
        Some((k, gamma_t, shares)) => {
            let mut traces = Vec::with_capacity(eta);
            let (mut re, mut im) = (Vec::new(), Vec::new());
            for s in 0..eta {
                let a = DMatrix::from_fn(k, k, |c, cp| gamma_t[(k * s + cp, c)]);
                traces.push(a.trace());
                let (r, i) = sorted_eigenvalues(&a);
                re.extend(r);
                im.push(i);
            }
            (traces, re, im, shares)
        }
    };
    out.extend(traces);
    out.extend(re);
    out.extend(im);
    out.push(alpha3(&shares));
    out.extend(shares);
    out
}

/// Eigenvalues of a real `k x k` matrix (`k <= 3`): the real parts padded with zeros to 3 and
/// sorted descending, and the largest absolute imaginary part. A real 3x3 matrix has at most
/// one complex-conjugate pair, so that one number holds all its imaginary information (a
/// sorted list of three would repeat it and end in a zero that never varies). Both are
/// continuous, symmetric functions of the spectrum.
pub(super) fn sorted_eigenvalues(a: &DMatrix<f64>) -> ([f64; D], f64) {
    let ev = a.complex_eigenvalues();
    let mut re = [0.0; D];
    let mut im = 0.0f64;
    for (j, z) in ev.iter().take(D).enumerate() {
        re[j] = if z.re.is_finite() { z.re } else { 0.0 };
        if z.im.is_finite() {
            im = im.max(z.im.abs());
        }
    }
    re.sort_by(|a, b| b.total_cmp(a));
    (re, im)
}

/// Eigenvalues of `lambda V_yy^-1` (residual over total energy along each colour direction; in
/// [0, 1] for least squares), clamped to `[MIN_INNOVATION, 1]`, padded with 1 (white noise) to
/// 3 and sorted descending. Computed as the symmetric `L^-1 lambda L^-T` with `V_yy = L L^T`.
pub(super) fn innovation_shares(lambda: &DMatrix<f64>, vyy: &DMatrix<f64>) -> Vec<f64> {
    let k = lambda.nrows();
    let mut shares = vec![1.0; D];
    if let Some(chol) = vyy.clone().cholesky() {
        let l = chol.l();
        if let Some(l_inv) = l.clone().try_inverse() {
            let m = &l_inv * lambda * l_inv.transpose();
            let m = (&m + m.transpose()) * 0.5;
            let values = SymmetricEigen::new(m).eigenvalues;
            for (j, v) in values.iter().take(k).enumerate() {
                shares[j] = if v.is_finite() {
                    v.clamp(MIN_INNOVATION, 1.0)
                } else {
                    1.0
                };
            }
        }
    }
    shares.sort_by(|a, b| b.total_cmp(a));
    shares
}

/// `alpha3 = sqrt(mean_r (Y_r - mu)^T Sigma^-1 (Y_r - mu)) = sqrt(tr(Sigma^-1 Phi))`: the sum
/// of the inverse innovation shares, square-rooted (`sqrt(3)` for white noise).
pub(super) fn alpha3(shares: &[f64]) -> f64 {
    shares.iter().map(|s| 1.0 / s).sum::<f64>().sqrt()
}

/// The least-squares 2D CAR coefficients of one channel from its statistics `v` (`1 + eta`
/// square, index 0 = the pixel, mean removed; `None` when the level is too small) over
/// `sites` sites; zeros for a flat channel. A gain on the channel scales `v` and the ridge
/// alike, so `gamma` does not change.
pub(super) fn car2d_gamma(
    v: Option<DMatrix<f64>>,
    mean: f64,
    sites: usize,
    eta: usize,
) -> Vec<f64> {
    let Some(mut v) = v else {
        return vec![0.0; eta];
    };
    if is_flat(mean.abs(), v[(0, 0)] / sites.max(1) as f64) {
        return vec![0.0; eta];
    }
    let ridge = RIDGE * v.trace() / (eta + 1) as f64 + 1e-300;
    for i in 0..=eta {
        v[(i, i)] += ridge;
    }
    match car2d::estimate(&v, eta) {
        Some((gamma, _, _)) if gamma.iter().all(|g| g.is_finite()) => gamma,
        _ => vec![0.0; eta],
    }
}

/// Per-channel gain-invariant colour moments of a `(3, h, w)` linear image: coefficient of
/// variation (R, G, B), skewness (R, G, B), excess kurtosis (R, G, B), correlation coefficients
/// (RG, RB, GB). Flat channels give 0. Pass the image projected onto its kept colour
/// directions ([`Whitening::project`]): on a near-grey image the correlations would otherwise
/// measure rounding noise, which a per-channel gain changes by many database deviations.
pub(super) fn colour_statistics(image: &Array3<f64>) -> Vec<f64> {
    let n = (image.len() / D).max(1) as f64;
    let mut mean = [0.0; D];
    let mut sd = [0.0; D];
    let mut flat = [true; D];
    let mut out = vec![0.0; 12];
    for c in 0..D {
        let p = image.index_axis(Axis(0), c);
        let m = p.sum() / n;
        let (m2, m3, m4) = p.iter().fold((0.0, 0.0, 0.0), |(a, b, d), &v| {
            let x = v - m;
            (a + x * x, b + x * x * x, d + x * x * x * x)
        });
        let (m2, m3, m4) = (m2 / n, m3 / n, m4 / n);
        mean[c] = m;
        sd[c] = m2.sqrt();
        flat[c] = is_flat(m.abs(), m2);
        if !flat[c] {
            out[c] = if m.abs() > 0.0 { sd[c] / m } else { 0.0 };
            out[3 + c] = m3 / (m2 * sd[c]);
            out[6 + c] = m4 / (m2 * m2) - 3.0;
        }
    }
    for (slot, (i, j)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
        if flat[i] || flat[j] {
            continue;
        }
        let a = image.index_axis(Axis(0), i);
        let b = image.index_axis(Axis(0), j);
        let cov = ndarray::Zip::from(&a)
            .and(&b)
            .fold(0.0, |acc, &x, &y| acc + (x - mean[i]) * (y - mean[j]))
            / n;
        out[9 + slot] = (cov / (sd[i] * sd[j])).clamp(-1.0, 1.0);
    }
    for v in &mut out {
        if !v.is_finite() {
            *v = 0.0;
        }
    }
    out
}
