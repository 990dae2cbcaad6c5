//! The 3D (multispectral) causal autoregressive model of a colour band (seed 001, sec. 5.3.2;
//! mrf_math.md sec. 4): `Y_r = sum_s A_s Y_{r-s} + e_r` with `Y_r` in R^d, d x d parameter
//! matrices `A_s` and correlated noise `e_r ~ N(0, Sigma)`. It models the colour channels
//! jointly, so no KL decorrelation is needed and spatial cross-channel correlation is kept.

use super::Car2dModel;
use super::car2d::bounded_sample;
use super::neighbourhood::{causal, reach};
use super::noise::require;
use super::torus;
use super::{BandModel, Fit, Repair, choose_stable, is_flat};
use crate::model::format::{Parse, Reader, Writer};
use nalgebra::{DMatrix, Matrix3};
use ndarray::{Array3, ArrayView3};

/// Channels modelled jointly (RGB).
pub const D: usize = 3;

/// A fitted 3D CAR model of one colour band.
#[derive(Debug, Clone, PartialEq)]
pub struct Car3dModel {
    /// Causal neighbourhood order (0 = correlated white noise).
    pub order: u8,
    /// `A_s` for each offset, row-major 3x3 each (`eta * 9` values).
    pub a: Vec<f64>,
    /// Noise covariance, row-major 3x3.
    pub sigma: [f64; 9],
    /// Channel means.
    pub mean: [f64; 3],
}

/// Largest order the 3D model tries (10 neighbours, 90 coefficients).
pub const MAX_ORDER_3D: usize = 4;

fn ln_det_spd(m: &DMatrix<f64>) -> Option<f64> {
    let chol = m.clone().cholesky()?;
    Some(2.0 * chol.l().diagonal().iter().map(|d| d.ln()).sum::<f64>())
}

/// Accumulates `V = sum_r z_r z_r^T` with `z_r = [Y_r; Y_{r-s_1}; ...; Y_{r-s_eta}]` over the
/// sites where every offset fits, for a zero-mean `(d, h, w)` band with any number `d` of
/// channels (mrf_math.md 4.2). `V` is `(d + d eta)` square; returns it with the site count `t`.
pub(crate) fn statistics(y: &Array3<f64>, offsets: &[(isize, isize)]) -> (DMatrix<f64>, usize) {
    let (d, h, w) = y.dim();
    let (up, left, right) = reach(offsets);
    let dim = d + d * offsets.len();
    let y = y.as_standard_layout();
    let data = y.as_slice().expect("standard layout");
    let plane = h * w;
    // Offsets as distances back in the flattened plane; sites start at row `up`, column
    // `left`, so every neighbour index stays in range.
    let back: Vec<usize> = offsets
        .iter()
        .map(|&(s1, s2)| (s1 * w as isize + s2) as usize)
        .collect();
    // Lower triangle, row-major in a flat buffer: the inner loop is a contiguous axpy.
    let mut acc = vec![0.0; dim * dim];
    let mut z = vec![0.0; dim];
    let mut t = 0usize;
    for r in up..h {
        for x in left..w.saturating_sub(right) {
            let i = r * w + x;
            for c in 0..d {
                z[c] = data[c * plane + i];
                for (k, &b) in back.iter().enumerate() {
                    z[d + d * k + c] = data[c * plane + i - b];
                }
            }
            for a in 0..dim {
                let za = z[a];
                for (v, &zb) in acc[a * dim..=a * dim + a].iter_mut().zip(&z) {
                    *v += za * zb;
                }
            }
            t += 1;
        }
    }
    let v = DMatrix::from_fn(dim, dim, |i, j| {
        if j <= i {
            acc[i * dim + j]
        } else {
            acc[j * dim + i]
        }
    });
    (v, t)
}

/// The least-squares (or, with a prior already added to `v`, Bayesian) estimate for the first
/// `eta` neighbours from statistics `v` of a `d`-channel band (see [`statistics`]):
/// `gamma^T = V_zz^-1 V_zy` (`d eta` x `d`, row `d k + c'` column `c` is `A_k[c][c']`) and
/// `lambda = V_yy - V_zy^T gamma^T` (`d` x `d`). `None` when `V_zz` is not positive definite.
pub(crate) fn estimate(
    v: &DMatrix<f64>,
    d: usize,
    eta: usize,
) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
    let m = d * eta;
    let vzz = v.view((d, d), (m, m)).into_owned();
    let vzy = v.view((d, 0), (m, d)).into_owned();
    let vyy = v.view((0, 0), (d, d)).into_owned();
    let gamma_t = vzz.cholesky()?.solve(&vzy);
    let lambda = vyy - vzy.transpose() * &gamma_t;
    Some((gamma_t, lambda))
}

impl Car3dModel {
    /// [`BandModel::fit`].
    fn fit_joint(band: ArrayView3<f64>, max_order: usize) -> Fit<Self> {
        let (_, h, w) = band.dim();
        let n = (h * w).max(1) as f64;
        let mean: [f64; 3] =
            std::array::from_fn(|c| band.index_axis(ndarray::Axis(0), c).sum() / n);
        let y = Array3::from_shape_fn(band.dim(), |(c, r, x)| band[[c, r, x]] - mean[c]);
        let mut cov = [0.0; 9];
        for r in 0..h {
            for x in 0..w {
                for i in 0..3 {
                    for j in 0..3 {
                        cov[3 * i + j] += y[[i, r, x]] * y[[j, r, x]] / n;
                    }
                }
            }
        }
        let total_var = cov[0] + cov[4] + cov[8];
        let white = Self {
            order: 0,
            a: Vec::new(),
            sigma: cov,
            mean,
        };
        if is_flat(mean.iter().fold(0.0, |m, v| m.max(v.abs())), total_var) {
            return Fit {
                model: Self {
                    sigma: [0.0; 9],
                    ..white
                },
                candidates: Vec::new(),
                repairs: Vec::new(),
            };
        }
        let feasible = (1..=max_order.min(MAX_ORDER_3D))
            .filter(|&k| {
                let (up, left, right) = reach(causal(k));
                h.saturating_sub(up) * w.saturating_sub(left + right) >= 20 * D * causal(k).len()
            })
            .max()
            .unwrap_or(0);
        if feasible == 0 {
            return Fit {
                model: white,
                candidates: Vec::new(),
                repairs: vec![Repair::TooSmall],
            };
        }
        let offsets = causal(feasible);
        let eta_max = offsets.len();
        let (mut v, t) = statistics(&y, offsets);
        let dim = v.nrows();
        let ridge = 1e-6 * (D..dim).map(|i| v[(i, i)]).sum::<f64>() / (dim - D) as f64 + 1e-300;
        for i in 0..dim {
            v[(i, i)] += ridge;
        }
        let d = D as f64;
        let beta0 = d * eta_max as f64 + 1.0;
        let beta_t = beta0 + t as f64;
        let mut scored = Vec::new();
        for k in 1..=feasible {
            let eta = causal(k).len();
            let m = D * eta;
            let vzz = v.view((D, D), (m, m)).into_owned();
            let Some((gamma_t, mut lambda)) = estimate(&v, D, eta) else {
                continue;
            };
            for i in 0..D {
                lambda[(i, i)] = lambda[(i, i)].max(ridge);
            }
            let (Some(ln_vzz), Some(ln_lambda)) = (ln_det_spd(&vzz), ln_det_spd(&lambda)) else {
                continue;
            };
            let e = eta as f64;
            let mut score = -0.5 * d * ln_vzz - 0.5 * (beta_t - d * e + d + 1.0) * ln_lambda
                + 0.5 * d * d * e * std::f64::consts::PI.ln();
            for i in 1..=D {
                let i = i as f64;
                score += libm::lgamma(0.5 * (beta_t - d * e + d + 2.0 - i))
                    - libm::lgamma(0.5 * (beta0 - d * e + d + 2.0 - i));
            }
            // A_s rows: Y_c = sum_k sum_c' A_k[c][c'] Y_{c'}(r - s_k); gamma^T is (k, c') x c.
            let mut a = vec![0.0; 9 * eta];
            for kk in 0..eta {
                for c in 0..D {
                    for cp in 0..D {
                        a[9 * kk + 3 * c + cp] = gamma_t[(D * kk + cp, c)];
                    }
                }
            }
            let sigma: [f64; 9] = std::array::from_fn(|q| lambda[(q / 3, q % 3)] / beta_t);
            scored.push((
                k as u8,
                score,
                Self {
                    order: k as u8,
                    a,
                    sigma,
                    mean,
                },
            ));
        }
        let candidates: Vec<(u8, f64)> = scored.iter().map(|s| (s.0, s.1)).collect();
        scored.sort_by(|x, y| y.1.total_cmp(&x.1));
        let sorted = scored.into_iter().map(|(order, _, m)| (order, m)).collect();
        choose_stable(
            sorted,
            candidates,
            white,
            |m| m.is_stable(total_var),
            Self::shrunk,
        )
    }

    fn shrunk(&self, kappa: f64) -> Self {
        Self {
            a: self.a.iter().map(|v| v * kappa).collect(),
            ..self.clone()
        }
    }

    /// Stable in the sense synthesis needs (see [`Car2dModel::is_stable`]): a test sample is
    /// finite, does not grow, and its per-channel energy stays within 4x the data's.
    ///
    /// [`Car2dModel::is_stable`]: super::Car2dModel::is_stable
    pub fn is_stable(&self, data_var: f64) -> bool {
        let mut probe = self.clone();
        probe.mean = [0.0; 3];
        let sample = probe.synthesize(128, 128, 0x5eed, false);
        bounded_sample(&sample, data_var / 3.0)
    }

    /// Cholesky factor of Sigma (with a small ridge when it is not positive definite).
    fn noise_factor(&self) -> Matrix3<f64> {
        let s = Matrix3::from_row_slice(&self.sigma);
        let mut ridge = 0.0;
        for _ in 0..20 {
            if let Some(c) = (s + Matrix3::identity() * ridge).cholesky() {
                return c.l();
            }
            ridge = if ridge == 0.0 {
                1e-12 * (s.trace().abs() + 1e-300)
            } else {
                ridge * 10.0
            };
        }
        Matrix3::from_diagonal(&s.diagonal().map(|v| v.max(0.0).sqrt()))
    }
}

/// A `(3, rows, cols)` sample solved exactly on a torus by the DFT (see [`torus`]): the
/// output's own (`tileable`) or one [`torus::MARGIN`] larger on every side, cropped (as the 2D
/// CAR); three noise values per site, row-major.
impl BandModel for Car3dModel {
    const NAME: &'static str = "3dcar";
    const PLANES: usize = D;

    /// Fits a `(3, h, w)` band: means removed, statistics accumulated once on the sites of the
    /// largest feasible order (at most [`MAX_ORDER_3D`]), every order scored by the Bayesian
    /// decision function (same sites, same prior), the best stable one kept (next best, then
    /// shrinkage, if unstable).
    fn fit(band: ArrayView3<f64>, max_order: usize) -> Fit<Self> {
        Self::fit_joint(band, max_order)
    }

    fn noise_len(rows: usize, cols: usize, tileable: bool) -> usize {
        D * Car2dModel::noise_len(rows, cols, tileable)
    }

    fn synthesize_from(
        &self,
        rows: usize,
        cols: usize,
        noise: &[f32],
        tileable: bool,
    ) -> Array3<f64> {
        let needed = Self::noise_len(rows, cols, tileable);
        require(noise, needed);
        if rows == 0 || cols == 0 {
            return Array3::zeros((3, rows, cols));
        }
        let offsets = causal(self.order as usize);
        let l = self.noise_factor();
        let (height, width) = torus::shape(rows, cols, tileable);
        // e_r = L w_r: three noise values per site, row-major.
        let mut e: [Vec<f32>; 3] = std::array::from_fn(|_| Vec::with_capacity(height * width));
        for w in noise[..needed].chunks_exact(3) {
            for (p, plane) in e.iter_mut().enumerate() {
                let v: f64 = (0..=p).map(|q| l[(p, q)] * f64::from(w[q])).sum();
                plane.push(v as f32);
            }
        }
        let blocks: Vec<[f64; 9]> = (0..offsets.len())
            .map(|k| std::array::from_fn(|q| self.a[9 * k + q]))
            .collect();
        let planes = torus::car3d((height, width), &e, (offsets, &blocks), self.mean)
            .map(|y| torus::cut(y, rows, cols, tileable));
        let views = planes.each_ref().map(|p| p.view());
        ndarray::stack(ndarray::Axis(0), &views).expect("equal channel shapes")
    }

    fn flat_means(&self) -> Option<Vec<f64>> {
        self.sigma.iter().all(|&v| v == 0.0).then(|| self.mean.to_vec())
    }

    fn write(&self, w: &mut Writer) {
        w.u8(self.order);
        w.f32s(&self.mean);
        w.f32s(&self.sigma);
        w.f32s(&self.a);
    }

    fn read(r: &mut Reader) -> Parse<Self> {
        let order = r.u8_at_most(MAX_ORDER_3D, "neighbourhood order")?;
        let mean: [f64; 3] = r.f32s(3)?.try_into().expect("3");
        let sigma: [f64; 9] = r.f32s(9)?.try_into().expect("9");
        let a = r.f32s(9 * causal(usize::from(order)).len())?;
        Ok(Self {
            order,
            a,
            sigma,
            mean,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::s;

    fn truth() -> Car3dModel {
        // Order 1: left and upper neighbours, with cross-channel terms.
        Car3dModel {
            order: 1,
            a: vec![
                0.30, 0.05, 0.00, 0.00, 0.25, 0.05, 0.05, 0.00, 0.20, // A_(0,1)
                0.25, 0.00, 0.05, 0.05, 0.30, 0.00, 0.00, 0.05, 0.30, // A_(1,0)
            ],
            sigma: [1.0, 0.5, 0.2, 0.5, 1.0, 0.3, 0.2, 0.3, 0.8],
            mean: [0.5, -0.2, 1.0],
        }
    }

    #[test]
    fn toroidal_synthesis_wraps() {
        // Channel 0: the correlation across the seams matches the interior one.
        let (mut inner, mut seams) = (0.0, 0.0);
        for seed in 0..8 {
            let y = truth().synthesize(48, 48, seed, true);
            let y0 = y.index_axis(ndarray::Axis(0), 0);
            let corr = |a: ndarray::ArrayView2<f64>, b: ndarray::ArrayView2<f64>| {
                crate::eval::correlation(&a.to_owned(), &b.to_owned()) / 8.0
            };
            inner += corr(y0.slice(s![.., 0..47]), y0.slice(s![.., 1..48]));
            seams += 0.5 * corr(y0.slice(s![.., 47..48]), y0.slice(s![.., 0..1]));
            seams += 0.5 * corr(y0.slice(s![47..48, ..]), y0.slice(s![0..1, ..]));
        }
        assert!(
            inner > 0.3 && (inner - seams).abs() < 0.1,
            "{inner} vs {seams}"
        );
    }

    #[test]
    fn estimates_recover_matrices_and_noise_covariance() {
        let y = truth().synthesize(300, 300, 4, false);
        let fit = Car3dModel::fit(y.view(), 4);
        assert_eq!(fit.model.order, 1, "{:?}", fit.candidates);
        for (e, t) in fit.model.a.iter().zip(&truth().a) {
            assert!((e - t).abs() < 0.03, "{:?}", fit.model.a);
        }
        for (e, t) in fit.model.sigma.iter().zip(&truth().sigma) {
            assert!((e - t).abs() < 0.06, "{:?}", fit.model.sigma);
        }
        assert!(fit.repairs.is_empty());
    }

    #[test]
    fn constant_and_tiny_bands_give_finite_models() {
        let flat = Array3::from_elem((3, 8, 8), 0.3);
        let fit = Car3dModel::fit(flat.view(), 4);
        assert_eq!(fit.model.order, 0);
        assert!(
            fit.model
                .synthesize(16, 16, 1, false)
                .iter()
                .all(|v| (v - 0.3).abs() < 1e-12)
        );
        let tiny = truth().synthesize(4, 4, 2, false);
        let fit = Car3dModel::fit(tiny.view(), 4);
        assert!(
            fit.model
                .synthesize(8, 8, 1, false)
                .iter()
                .all(|v| v.is_finite())
        );
    }
}
