//! The 2D causal autoregressive (CAR) model of one mono-spectral band (seed 001, sec. 5.3.2;
//! mrf_math.md sec. 2): `Y_r = gamma X_r + e_r`, `X_r` the causal neighbours, `e_r` white
//! Gaussian noise. Parameters and noise variance have analytic Bayesian estimates; the
//! neighbourhood is chosen by the Bayesian decision rule over the causal hierarchy; synthesis is
//! the exact toroidal field by the DFT (see [`torus`]), on the output's size (which tiles) or
//! cropped from a larger torus.

use super::neighbourhood::{MAX_ORDER, causal, reach};
use super::noise::require;
use super::{BandModel, Fit, Repair, choose_stable, is_flat};
use super::{spectrum, torus};
use crate::model::format::{Parse, Reader, Writer};
use nalgebra::{DMatrix, DVector};
use ndarray::{Array2, Array3, ArrayView3, Axis};


/// A fitted 2D CAR model of one band.
#[derive(Debug, Clone, PartialEq)]
pub struct Car2dModel {
    /// Causal neighbourhood order (0 = white noise, see [`causal`]).
    pub order: u8,
    /// Coefficients, one per offset of the order.
    pub gamma: Vec<f64>,
    /// Variance of the driving noise.
    pub sigma2: f64,
    /// Band mean (added back after synthesis).
    pub mean: f64,
}

/// Accumulates `sum [Y; X][Y; X]^T` over the sites where `offsets` fit.
fn statistics(y: &Array2<f64>, offsets: &[(isize, isize)]) -> (DMatrix<f64>, usize) {
    let (h, w) = y.dim();
    let (up, left, right) = reach(offsets);
    let n = offsets.len() + 1;
    let mut v = DMatrix::<f64>::zeros(n, n);
    let mut t = 0;
    let mut z = vec![0.0; n];
    for r in up..h {
        for c in left..w.saturating_sub(right) {
            z[0] = y[[r, c]];
            for (k, &(s1, s2)) in offsets.iter().enumerate() {
                z[k + 1] = y[[r - s1 as usize, (c as isize - s2) as usize]];
            }
            for i in 0..n {
                for j in 0..=i {
                    v[(i, j)] += z[i] * z[j];
                }
            }
            t += 1;
        }
    }
    for i in 0..n {
        for j in 0..i {
            v[(j, i)] = v[(i, j)];
        }
    }
    (v, t)
}

/// Number of sites where a neighbourhood fits in an `h` x `w` band.
fn site_count(h: usize, w: usize, offsets: &[(isize, isize)]) -> usize {
    let (up, left, right) = reach(offsets);
    h.saturating_sub(up) * w.saturating_sub(left + right)
}

/// Fewest data vectors per parameter accepted for an estimate (mrf_math.md sec. 7).
const MIN_SITES_PER_PARAMETER: usize = 20;

/// Estimates gamma and lambda for the first `eta` neighbours from the full statistics `v`
/// (index 0 is Y), with the ridge prior already added. Returns (gamma, lambda, ln|V_x|).
pub(crate) fn estimate(v: &DMatrix<f64>, eta: usize) -> Option<(Vec<f64>, f64, f64)> {
    let vx = v.view((1, 1), (eta, eta)).into_owned();
    let vxy = DVector::from_iterator(eta, (1..=eta).map(|i| v[(i, 0)]));
    let chol = vx.cholesky()?;
    let gamma = chol.solve(&vxy);
    let lambda = v[(0, 0)] - vxy.dot(&gamma);
    let ln_det: f64 = 2.0 * chol.l().diagonal().iter().map(|d| d.ln()).sum::<f64>();
    Some((gamma.iter().copied().collect(), lambda, ln_det))
}

/// The Bayesian decision function D of a d = 1 CAR candidate (mrf_math.md 2.3).
fn decision(ln_det_vx: f64, lambda: f64, eta: usize, beta0: f64, t: usize) -> f64 {
    let beta_t = beta0 + t as f64;
    let eta = eta as f64;
    -0.5 * ln_det_vx - 0.5 * (beta_t - eta + 2.0) * lambda.ln()
        + 0.5 * eta * std::f64::consts::PI.ln()
        + libm::lgamma(0.5 * (beta_t - eta + 2.0))
        - libm::lgamma(0.5 * (beta0 - eta + 2.0))
}

/// The shared test of a probe synthesis: finite, no growth down the rows, variance within 4x
/// the data's (`sample` is (.., rows, cols) with rows last but one).
pub(crate) fn bounded_sample<D: ndarray::Dimension>(
    sample: &ndarray::Array<f64, D>,
    data_var: f64,
) -> bool {
    if sample.iter().any(|v| !v.is_finite()) {
        return false;
    }
    let rows_axis = ndarray::Axis(sample.ndim() - 2);
    let rows = sample.len_of(rows_axis);
    let energy = |range: std::ops::Range<usize>| {
        let part = sample.slice_axis(rows_axis, range.into());
        part.iter().map(|v| v * v).sum::<f64>() / part.len().max(1) as f64
    };
    let (top, bottom) = (energy(0..rows / 2), energy(rows / 2..rows));
    let all = 0.5 * (top + bottom);
    bottom <= 4.0 * top.max(1e-300) && all <= 4.0 * data_var
}

impl Car2dModel {
    /// A model that reproduces a constant band.
    pub fn constant(mean: f64) -> Self {
        Self {
            order: 0,
            gamma: Vec::new(),
            sigma2: 0.0,
            mean,
        }
    }

    /// [`BandModel::fit`] of one plane.
    fn fit_plane(band: &Array2<f64>, max_order: usize) -> Fit<Self> {
        let (h, w) = band.dim();
        let n = (h * w).max(1) as f64;
        let mean = band.iter().sum::<f64>() / n;
        let y = band.mapv(|v| v - mean);
        let var = y.iter().map(|v| v * v).sum::<f64>() / n;
        if is_flat(mean.abs(), var) {
            return Fit {
                model: Self::constant(mean),
                candidates: Vec::new(),
                repairs: Vec::new(),
            };
        }
        let feasible = (1..=max_order.min(MAX_ORDER))
            .filter(|&k| site_count(h, w, causal(k)) >= MIN_SITES_PER_PARAMETER * causal(k).len())
            .max()
            .unwrap_or(0);
        let white = Self {
            order: 0,
            gamma: Vec::new(),
            sigma2: var,
            mean,
        };
        if feasible == 0 {
            return Fit {
                model: white,
                candidates: Vec::new(),
                repairs: vec![Repair::TooSmall],
            };
        }
        let offsets = causal(feasible);
        let (mut v, t) = statistics(&y, offsets);
        let eta_max = offsets.len();
        let ridge = 1e-6 * (1..=eta_max).map(|i| v[(i, i)]).sum::<f64>() / eta_max as f64 + 1e-300;
        for i in 0..=eta_max {
            v[(i, i)] += ridge;
        }
        let beta0 = eta_max as f64 + 1.0;
        let mut scored: Vec<(u8, f64, Vec<f64>, f64)> = Vec::new();
        for k in 1..=feasible {
            let eta = causal(k).len();
            if let Some((gamma, lambda, ln_det)) = estimate(&v, eta) {
                let lambda = lambda.max(ridge);
                let d = decision(ln_det, lambda, eta, beta0, t);
                scored.push((k as u8, d, gamma, lambda / (beta0 + t as f64)));
            }
        }
        let candidates: Vec<(u8, f64)> = scored.iter().map(|s| (s.0, s.1)).collect();
        scored.sort_by(|a, b| b.1.total_cmp(&a.1));
        let sorted = scored
            .into_iter()
            .map(|(order, _, gamma, sigma2)| {
                let model = Self {
                    order,
                    gamma,
                    sigma2,
                    mean,
                };
                (order, model)
            })
            .collect();
        choose_stable(
            sorted,
            candidates,
            white,
            |m| m.is_stable(var),
            Self::shrunk,
        )
    }

    fn shrunk(&self, kappa: f64) -> Self {
        Self {
            gamma: self.gamma.iter().map(|g| g * kappa).collect(),
            ..self.clone()
        }
    }

    /// Stable in the sense synthesis at any size needs (mrf_math.md 2.5): the causal model is a
    /// stationary process (exact half-plane conditions, see [`spectrum`]), its stationary
    /// variance over the whole frequency plane (what the toroidal synthesis has) stays within
    /// 4x the data's, and a 128 x 128 test sample is finite, does not grow from its top half to
    /// its bottom half and has a variance within 4x the data's. The variance bounds also reject
    /// near-unit-root estimates, which are formally stable but fill an enlargement with huge
    /// low-frequency blotches.
    pub fn is_stable(&self, data_var: f64) -> bool {
        let offsets = causal(self.order as usize);
        if !spectrum::causally_stable(offsets, &self.gamma) {
            return false;
        }
        let stationary =
            spectrum::stationary_variance(offsets, &self.gamma, self.sigma2, spectrum::GRID);
        if stationary.is_nan() || stationary > 4.0 * data_var {
            return false;
        }
        let probe = Self {
            mean: 0.0,
            ..self.clone()
        };
        let sample = probe.synthesize(128, 128, 0x5eed, false);
        bounded_sample(&sample, data_var)
    }

    /// The sample of [`BandModel::synthesize_from`] as one plane.
    fn plane_from(
        &self,
        rows: usize,
        cols: usize,
        noise: &[f32],
        tileable: bool,
    ) -> Array2<f64> {
        let offsets = causal(self.order as usize);
        let sigma = self.sigma2.max(0.0).sqrt();
        let needed = Self::noise_len(rows, cols, tileable);
        require(noise, needed);
        if needed == 0 {
            return Array2::zeros((rows, cols));
        }
        let field = torus::car2d(
            torus::shape(rows, cols, tileable),
            noise,
            sigma,
            (offsets, &self.gamma),
            self.mean,
        );
        torus::cut(field, rows, cols, tileable)
    }
}

/// Both syntheses solve the model exactly on a torus by the DFT (see [`torus`]): `tileable` on
/// the output's own size, so the result wraps seamlessly; otherwise on a torus [`torus::MARGIN`]
/// larger on every side, cropped, so opposite edges are independent. Not the causal recursion
/// row by row: on a finite row the recursion's row-to-row operator is a non-normal Toeplitz
/// section, which can grow along wide rows for a model whose half-plane conditions hold (a
/// blown-up right edge of a 1024-wide painting), where the circulant solution cannot.
impl BandModel for Car2dModel {
    const NAME: &'static str = "2dcar";
    const PLANES: usize = 1;

    /// Subtracts the band's mean, evaluates every causal order up to `max_order` that the band
    /// has enough sites for, on the same sites and with the same prior, picks the order of
    /// largest D, and repairs it if unstable (next-best order, then shrinkage).
    fn fit(band: ArrayView3<f64>, max_order: usize) -> Fit<Self> {
        Self::fit_plane(&band.index_axis(Axis(0), 0).to_owned(), max_order)
    }

    fn noise_len(rows: usize, cols: usize, tileable: bool) -> usize {
        let (height, width) = torus::shape(rows, cols, tileable);
        height * width
    }

    fn synthesize_from(
        &self,
        rows: usize,
        cols: usize,
        noise: &[f32],
        tileable: bool,
    ) -> Array3<f64> {
        self.plane_from(rows, cols, noise, tileable)
            .insert_axis(Axis(0))
    }

    fn flat_means(&self) -> Option<Vec<f64>> {
        (self.sigma2 <= 0.0).then(|| vec![self.mean])
    }

    fn write(&self, w: &mut Writer) {
        super::write_plane_record(w, self.order, self.mean, self.sigma2, &self.gamma);
    }

    fn read(r: &mut Reader) -> Parse<Self> {
        let (order, mean, sigma2, gamma) = super::read_plane_record(r)?;
        Ok(Self {
            order,
            gamma,
            sigma2,
            mean,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::s;
    use crate::eval::correlation;

    fn truth() -> Car2dModel {
        // Order 2 (4 neighbours), stable (sum |a| = 0.85).
        Car2dModel {
            order: 2,
            gamma: vec![0.35, 0.3, -0.1, 0.1],
            sigma2: 1.0,
            mean: 2.0,
        }
    }

    #[test]
    fn estimates_recover_known_parameters_and_order() {
        let sample = truth().synthesize(400, 400, 11, false);
        let fit = Car2dModel::fit(sample.view(), 6);
        assert_eq!(fit.model.order, 2, "{:?}", fit.candidates);
        assert_eq!(fit.model.gamma.len(), truth().gamma.len());
        for (g, t) in fit.model.gamma.iter().zip(&truth().gamma) {
            assert!((g - t).abs() < 0.02, "{:?}", fit.model.gamma);
        }
        assert!(
            (fit.model.sigma2 - 1.0).abs() < 0.03,
            "{}",
            fit.model.sigma2
        );
        assert!((fit.model.mean - 2.0).abs() < 0.2);
        assert!(fit.repairs.is_empty());
    }

    #[test]
    fn decision_differences_do_not_depend_on_data_scale() {
        let sample = truth().synthesize(128, 128, 3, false);
        let a = Car2dModel::fit(sample.view(), 4).candidates;
        let b = Car2dModel::fit(sample.mapv(|v| v * 1000.0).view(), 4).candidates;
        // Every order up to 4 is scored at both scales, in the same order.
        let orders = |c: &[(u8, f64)]| c.iter().map(|s| s.0).collect::<Vec<_>>();
        assert_eq!(orders(&a), [1, 2, 3, 4]);
        assert_eq!(orders(&b), orders(&a));
        let diffs = |c: &[(u8, f64)]| c.windows(2).map(|w| w[1].1 - w[0].1).collect::<Vec<_>>();
        for (x, y) in diffs(&a).iter().zip(diffs(&b)) {
            assert!((x - y).abs() < 1e-3 * x.abs().max(1.0), "{x} vs {y}");
        }
    }

    #[test]
    fn synthesis_is_seed_deterministic_and_noise_is_shared() {
        let m = truth();
        assert_eq!(
            m.synthesize(50, 60, 5, false),
            m.synthesize(50, 60, 5, false)
        );
        assert_ne!(
            m.synthesize(50, 60, 5, false),
            m.synthesize(50, 60, 6, false)
        );
        // Two different models driven by the same seed are correlated (coherent subspaces).
        let other = Car2dModel {
            gamma: vec![0.3, 0.3, 0.0, 0.0],
            ..m.clone()
        };
        let (a, b) = (
            m.synthesize(64, 64, 9, false).index_axis_move(Axis(0), 0),
            other.synthesize(64, 64, 9, false).index_axis_move(Axis(0), 0),
        );
        let corr = correlation(&a, &b);
        assert!(corr > 0.8, "{corr}");
    }

    #[test]
    fn plain_synthesis_is_stationary_and_does_not_wrap() {
        // A strongly correlated model, 48 rows x 1024 columns: the left and right strips have
        // the interior's variance (no growth along wide rows), and the opposite edges of a plain
        // field are unrelated (it is cut from a larger torus), unlike a tileable one.
        let m = Car2dModel {
            order: 2,
            gamma: vec![0.6, 0.5, -0.25, 0.1],
            sigma2: 1.0,
            mean: 0.0,
        };
        assert!(m.is_stable(1e9));
        let (mut left, mut right, mut middle, mut wrap) = (0.0, 0.0, 0.0, 0.0);
        for seed in 0..8 {
            let y = m.synthesize(48, 1024, seed, false).index_axis_move(Axis(0), 0);
            left += y.slice(s![.., ..32]).var(0.0);
            right += y.slice(s![.., 1024 - 32..]).var(0.0);
            middle += y.slice(s![.., 496..528]).var(0.0);
            wrap += correlation(
                &y.slice(s![.., 1023..]).to_owned(),
                &y.slice(s![.., ..1]).to_owned(),
            ) / 8.0;
        }
        assert!((left / middle - 1.0).abs() < 0.3, "{left} vs {middle}");
        assert!((right / middle - 1.0).abs() < 0.3, "{right} vs {middle}");
        assert!(wrap.abs() < 0.2, "{wrap}");
    }

    #[test]
    fn toroidal_synthesis_wraps() {
        // Across the wrap the lag-1 correlations (left-right and top-bottom) match the interior
        // ones, on average over several samples (one 64-pixel seam alone is too noisy).
        let (mut inner, mut wrap_cols, mut wrap_rows) = (0.0, 0.0, 0.0);
        let seeds = 12;
        for seed in 0..seeds {
            let y = truth().synthesize(64, 64, seed, true).index_axis_move(Axis(0), 0);
            let corr = |a: ndarray::ArrayView2<f64>, b: ndarray::ArrayView2<f64>| {
                correlation(&a.to_owned(), &b.to_owned()) / seeds as f64
            };
            inner += corr(y.slice(s![.., 0..63]), y.slice(s![.., 1..64]));
            wrap_cols += corr(y.slice(s![.., 63..64]), y.slice(s![.., 0..1]));
            wrap_rows += corr(y.slice(s![63..64, ..]), y.slice(s![0..1, ..]));
        }
        assert!(inner > 0.3, "{inner}");
        assert!((inner - wrap_cols).abs() < 0.1, "{inner} vs {wrap_cols}");
        assert!((inner - wrap_rows).abs() < 0.1, "{inner} vs {wrap_rows}");
    }

    #[test]
    fn unstable_estimates_are_repaired() {
        let wild = Car2dModel {
            order: 1,
            gamma: vec![0.9, 0.9],
            sigma2: 1.0,
            mean: 0.0,
        };
        assert!(!wild.is_stable(1.0));
        assert!(truth().is_stable(1.0));
        // A ramp has singular statistics and a near-unit-root fit; the result must be stable.
        let ramp = Array2::from_shape_fn((40, 40), |(i, j)| i as f64 + 2.0 * j as f64);
        let fit = Car2dModel::fit(ramp.view().insert_axis(Axis(0)), 6);
        assert!(fit.model.is_stable(ramp.var(0.0)));
        assert!(
            fit.model
                .synthesize(64, 64, 1, false)
                .iter()
                .all(|v| v.is_finite())
        );
    }
}
