//! The Gaussian Markov random field (non-causal, symmetric neighbourhood) model of one band
//! (seed 001, sec. 5.3.2; mrf_math.md sec. 3): `Y_r = sum_s gamma_s (Y_{r+s} + Y_{r-s}) + e_r`.
//! Least-squares (pseudo-likelihood) estimates on the torus choose the order and start the
//! maximum-likelihood estimate on the torus (Whittle's exact form), exact toroidal synthesis by FFT
//! (so the result tiles seamlessly), and a check that the spectral density
//! `sigma^2 / (1 - 2 sum_s gamma_s cos(omega . s))` stays positive, with a repair by shrinkage.

use nalgebra::{DMatrix, DVector};
use ndarray::{Array2, Array3, ArrayView3, Axis};
use rustfft::num_complex::Complex32;

use super::neighbourhood::{MAX_ORDER, causal};
use super::noise::require;
use super::{BandModel, Fit, Repair, is_flat};
use crate::fft;
use crate::model::format::{Parse, Reader, Writer};

/// (sin, cos) of `omega_k * s` for every frequency index k along one axis.
type SinCos = Vec<(f64, f64)>;

/// Side of the frequency grid a fitted model's validity and variance are checked on.
const CHECK_GRID: usize = 256;

/// Smallest spectral denominator accepted (the model is valid when it stays above 0).
const MU_FLOOR: f64 = 1e-3;

/// A fitted GMRF model of one band.
#[derive(Debug, Clone, PartialEq)]
pub struct GmrfModel {
    /// Neighbourhood order: the half-set is [`causal`]`(order)`, each offset paired with its
    /// mirror image.
    pub order: u8,
    /// One coefficient per half-set offset.
    pub gamma: Vec<f64>,
    /// Conditional variance.
    pub sigma2: f64,
    /// Band mean.
    pub mean: f64,
}

/// The validity repair (mrf_math.md 3.4): if the smallest denominator is below [`MU_FLOOR`],
/// shrink gamma by `kappa` so that it equals the floor. Since `1 - mu` is linear in gamma, the
/// shrunk model's denominators are `1 - kappa (1 - mu)`, updated in place. Returns
/// (old minimum, kappa) when a repair was needed.
fn floor_spectrum(mu: &mut Array2<f64>) -> Option<(f64, f64)> {
    let min = mu.iter().copied().fold(f64::INFINITY, f64::min);
    if min >= MU_FLOOR {
        return None;
    }
    let kappa = (1.0 - MU_FLOOR) / (1.0 - min);
    mu.mapv_inplace(|m| 1.0 - kappa * (1.0 - m));
    Some((min, kappa))
}

fn wrap(i: isize, n: usize) -> usize {
    i.rem_euclid(n as isize) as usize
}

/// Least squares for the first `eta` half-offsets on the torus: (gamma, sigma^2).
fn least_squares(y: &Array2<f64>, offsets: &[(isize, isize)]) -> Option<(Vec<f64>, f64)> {
    let (h, w) = y.dim();
    let eta = offsets.len();
    let mut xtx = DMatrix::<f64>::zeros(eta, eta);
    let mut xty = DVector::<f64>::zeros(eta);
    let mut x = vec![0.0; eta];
    let pair = |r: usize, c: usize, (s1, s2): (isize, isize)| {
        y[[wrap(r as isize + s1, h), wrap(c as isize + s2, w)]]
            + y[[wrap(r as isize - s1, h), wrap(c as isize - s2, w)]]
    };
    for r in 0..h {
        for c in 0..w {
            for (k, &s) in offsets.iter().enumerate() {
                x[k] = pair(r, c, s);
            }
            for i in 0..eta {
                xty[i] += x[i] * y[[r, c]];
                for j in 0..=i {
                    xtx[(i, j)] += x[i] * x[j];
                }
            }
        }
    }
    for i in 0..eta {
        for j in 0..i {
            xtx[(j, i)] = xtx[(i, j)];
        }
    }
    let ridge = 1e-9 * xtx.trace() / eta as f64 + 1e-300;
    for i in 0..eta {
        xtx[(i, i)] += ridge;
    }
    let gamma = xtx.cholesky()?.solve(&xty);
    let mut rss = 0.0;
    for r in 0..h {
        for c in 0..w {
            let pred: f64 = offsets
                .iter()
                .zip(gamma.iter())
                .map(|(&s, g)| g * pair(r, c, s))
                .sum();
            rss += (y[[r, c]] - pred).powi(2);
        }
    }
    Some((gamma.iter().copied().collect(), rss / (h * w) as f64))
}

/// Maximum likelihood of the GMRF on the torus from the start `gamma` (valid: `mu > 0` on the
/// band's DFT grid), for the same offsets: (gamma, sigma^2). The precision matrix is
/// circulant, so the exact likelihood is Whittle's, `sum_w log S(w) + I(w) / S(w)` with
/// `S = sigma^2 / mu` and `I` the periodogram: alternately sigma^2 in closed form and Newton
/// steps on gamma (convex for a fixed sigma^2), kept inside `mu > 0`. The least-squares
/// (pseudo-likelihood) estimate, which does not weigh the spectrum, can put a near-zero `mu`
/// where the data have little power (the knit's 2-pixel barcode, 7x the measured Nyquist
/// energy); the likelihood pays for every frequency's power.
fn torus_likelihood(
    y: &Array2<f64>,
    offsets: &[(isize, isize)],
    gamma: Vec<f64>,
) -> (Vec<f64>, f64) {
    let (h, w) = y.dim();
    let n = (h * w) as f64;
    let eta = offsets.len();
    let periodogram: Vec<f64> = fft::forward(y).iter().map(|c| c.norm_sqr() / n).collect();
    let tau = 2.0 * std::f64::consts::PI;
    // Per bin, 2 cos(w . s) for every offset.
    let features: Vec<f64> = (0..h)
        .flat_map(|k1| (0..w).map(move |k2| (k1, k2)))
        .flat_map(|(k1, k2)| {
            offsets.iter().map(move |&(s1, s2)| {
                2.0 * (tau * (k1 as f64 * s1 as f64 / h as f64 + k2 as f64 * s2 as f64 / w as f64))
                    .cos()
            })
        })
        .collect();
    let mus = |g: &[f64]| -> Vec<f64> {
        features
            .chunks_exact(eta)
            .map(|c| 1.0 - c.iter().zip(g).map(|(a, b)| a * b).sum::<f64>())
            .collect()
    };
    // -log-likelihood for a fixed precision t = 1 / sigma^2, up to constants.
    let objective = |mu: &[f64], t: f64| -> f64 {
        mu.iter()
            .zip(&periodogram)
            .map(|(&m, &i)| -m.ln() + t * i * m)
            .sum()
    };
    let mut gamma = DVector::from_vec(gamma);
    let mut mu = mus(gamma.as_slice());
    if mu.iter().any(|&m| m <= 0.0) {
        return (gamma.iter().copied().collect(), 0.0);
    }
    let precision = |mu: &[f64]| {
        n / mu
            .iter()
            .zip(&periodogram)
            .map(|(m, i)| m * i)
            .sum::<f64>()
            .max(1e-300)
    };
    for _ in 0..30 {
        let t = precision(&mu);
        let mut grad = DVector::<f64>::zeros(eta);
        let mut hess = DMatrix::<f64>::zeros(eta, eta);
        for ((c, &m), &i) in features.chunks_exact(eta).zip(&mu).zip(&periodogram) {
            let weight = 1.0 / m - t * i;
            for a in 0..eta {
                grad[a] += weight * c[a];
                for b in 0..=a {
                    hess[(a, b)] += c[a] * c[b] / (m * m);
                }
            }
        }
        for a in 0..eta {
            for b in 0..a {
                hess[(b, a)] = hess[(a, b)];
            }
        }
        let Some(step) = hess.cholesky().map(|c| c.solve(&-&grad)) else {
            break;
        };
        let before = objective(&mu, t);
        let mut alpha = 1.0;
        let mut moved = false;
        for _ in 0..30 {
            let trial = &gamma + &step * alpha;
            let trial_mu = mus(trial.as_slice());
            if trial_mu.iter().all(|&m| m > 0.0) && objective(&trial_mu, t) <= before {
                gamma = trial;
                mu = trial_mu;
                moved = true;
                break;
            }
            alpha *= 0.5;
        }
        if !moved || step.norm() * alpha < 1e-9 {
            break;
        }
    }
    let sigma2 = 1.0 / precision(&mu);
    (gamma.iter().copied().collect(), sigma2)
}

impl GmrfModel {
    /// A model of a constant band.
    pub fn constant(mean: f64) -> Self {
        Self {
            order: 0,
            gamma: Vec::new(),
            sigma2: 0.0,
            mean,
        }
    }

    /// Fits a band: mean removed, every order up to `max_order` estimated by least squares on
    /// the torus, the best by `t ln sigma^2 + eta ln t` kept, and shrunk if its spectrum is not
    /// positive on a fine frequency grid.
    fn fit_plane(band: &Array2<f64>, max_order: usize) -> Fit<Self> {
        let (h, w) = band.dim();
        let t = (h * w).max(1);
        let mean = band.iter().sum::<f64>() / t as f64;
        let y = band.mapv(|v| v - mean);
        let var = y.iter().map(|v| v * v).sum::<f64>() / t as f64;
        if is_flat(mean.abs(), var) {
            return Fit {
                model: Self::constant(mean),
                candidates: Vec::new(),
                repairs: Vec::new(),
            };
        }
        let mut candidates = Vec::new();
        let mut best: Option<(f64, Self)> = None;
        for k in 1..=max_order.min(MAX_ORDER) {
            let offsets = causal(k);
            // Offsets must fit in the band without wrapping onto themselves, with data to spare.
            let (up, side) = offsets.iter().fold((0, 0), |(u, s), &(s1, s2)| {
                (u.max(s1.unsigned_abs()), s.max(s2.unsigned_abs()))
            });
            if 2 * up >= h || 2 * side >= w || t < 20 * offsets.len() {
                break;
            }
            let Some((gamma, sigma2)) = least_squares(&y, offsets) else {
                continue;
            };
            let score = t as f64 * sigma2.max(1e-300).ln() + offsets.len() as f64 * (t as f64).ln();
            candidates.push((k as u8, score));
            if best.as_ref().is_none_or(|b| score < b.0) {
                best = Some((
                    score,
                    Self {
                        order: k as u8,
                        gamma,
                        sigma2,
                        mean,
                    },
                ));
            }
        }
        let Some((_, model)) = best else {
            return Fit {
                model: Self {
                    order: 0,
                    gamma: Vec::new(),
                    sigma2: var,
                    mean,
                },
                candidates,
                repairs: vec![Repair::TooSmall],
            };
        };
        // The least-squares estimate picks the order and starts the likelihood, which sets the
        // parameters; a fine grid checks validity (a coarse one misses a dip between bins,
        // which a large synthesis samples).
        let start = model.made_valid(h, w).0;
        let (gamma, sigma2) = torus_likelihood(&y, causal(start.order as usize), start.gamma.clone());
        let model = if sigma2 > 0.0 && sigma2.is_finite() {
            Self {
                gamma,
                sigma2,
                ..start
            }
        } else {
            start
        };
        let (model, repair) = model.made_valid(CHECK_GRID, CHECK_GRID);
        let mut repairs: Vec<Repair> = repair.into_iter().collect();
        // A valid spectrum can still be nearly singular at low frequencies (a near-unit-root
        // estimate), which paints huge blotches over an enlargement: shrink until the model's
        // variance is within 4x the data's.
        let model = if model.variance(CHECK_GRID, CHECK_GRID) > 4.0 * var {
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..30 {
                let mid = 0.5 * (lo + hi);
                if model.scaled(mid).variance(CHECK_GRID, CHECK_GRID) <= 4.0 * var {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            repairs.push(Repair::VarianceShrunk {
                ratio: model.variance(CHECK_GRID, CHECK_GRID) / var,
                factor: lo,
            });
            model.scaled(lo)
        } else {
            model
        };
        Fit {
            model,
            candidates,
            repairs,
        }
    }

    fn scaled(&self, kappa: f64) -> Self {
        Self {
            gamma: self.gamma.iter().map(|g| g * kappa).collect(),
            ..self.clone()
        }
    }

    /// `mu(omega) = 1 - 2 sum_s gamma_s cos(omega . s)` on the `rows` x `cols` DFT grid, stored
    /// column by column: shape (cols, rows), bin (k1, k2) at `[k2, k1]`. The cosine of a sum
    /// is expanded into per-axis tables, and the offsets sharing a row offset `s1` into one pair
    /// of column tables, so no trigonometry runs per bin and at most four terms do.
    fn denominators(&self, rows: usize, cols: usize) -> Array2<f64> {
        let tau = 2.0 * std::f64::consts::PI;
        let angles = |n: usize, s: isize| {
            (0..n).map(move |k| (tau * k as f64 * s as f64 / n as f64).sin_cos())
        };
        // Per row offset s1 (0..=3, the reach of the causal hierarchy), made when it occurs: the
        // column tables 2 sum_s2 gamma cos(omega2 s2) and 2 sum_s2 gamma sin(omega2 s2).
        let mut groups: [Option<(Vec<f64>, Vec<f64>)>; 4] = Default::default();
        for (&(s1, s2), &g) in causal(self.order as usize).iter().zip(&self.gamma) {
            let (cosines, sines) =
                groups[s1 as usize].get_or_insert_with(|| (vec![0.0; cols], vec![0.0; cols]));
            for ((sum_c, sum_s), (sin, cos)) in cosines
                .iter_mut()
                .zip(sines.iter_mut())
                .zip(angles(cols, s2))
            {
                *sum_c += 2.0 * g * cos;
                *sum_s += 2.0 * g * sin;
            }
        }
        // s1 = 0 has cosine 1 and sine 0 along the rows: a constant per column.
        let constant = groups[0].take().map(|(cosines, _)| cosines);
        let shifted: Vec<(SinCos, Vec<f64>, Vec<f64>)> = groups
            .into_iter()
            .enumerate()
            .filter_map(|(s1, group)| {
                group.map(|(cosines, sines)| (angles(rows, s1 as isize).collect(), cosines, sines))
            })
            .collect();
        let mut mu = Array2::zeros((cols, rows));
        for (k2, mut column) in mu.rows_mut().into_iter().enumerate() {
            column.fill(1.0 - constant.as_ref().map_or(0.0, |c| c[k2]));
            for (row_angles, cosines, sines) in &shifted {
                let (gc, gs) = (cosines[k2], sines[k2]);
                for (m, &(sin, cos)) in column.iter_mut().zip(row_angles) {
                    *m -= cos * gc - sin * gs;
                }
            }
        }
        mu
    }

    /// The model with its spectrum positive on a `rows` x `cols` grid: unchanged if it is,
    /// else gamma shrunk so that the smallest denominator is [`MU_FLOOR`], with that repair.
    pub fn made_valid(&self, rows: usize, cols: usize) -> (Self, Option<Repair>) {
        let mut mu = self.denominators(rows.max(1), cols.max(1));
        match floor_spectrum(&mut mu) {
            None => (self.clone(), None),
            Some((min, factor)) => (
                self.scaled(factor),
                Some(Repair::SpectrumFloored { min, factor }),
            ),
        }
    }

    /// The stationary variance of the model on a `rows` x `cols` torus:
    /// `(1 / MN) sum_k sigma^2 / mu_k`.
    pub fn variance(&self, rows: usize, cols: usize) -> f64 {
        let mu = self.made_valid(rows, cols).0.denominators(rows, cols);
        mu.iter().map(|m| self.sigma2 / m).sum::<f64>() / mu.len() as f64
    }
}

/// Always an exact sample on the torus (it tiles seamlessly, `tileable` or not): white noise
/// shaped by `sqrt(sigma^2 / mu)` in the frequency domain; the noise is frequency-domain pairs
/// in raster order of the bins.
impl BandModel for GmrfModel {
    const NAME: &'static str = "gmrf";
    const PLANES: usize = 1;

    fn fit(band: ArrayView3<f64>, max_order: usize) -> Fit<Self> {
        Self::fit_plane(&band.index_axis(Axis(0), 0).to_owned(), max_order)
    }

    /// Two values (real and imaginary part) per frequency bin.
    fn noise_len(rows: usize, cols: usize, _tileable: bool) -> usize {
        2 * rows * cols
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
            return Array3::zeros((1, rows, cols));
        }
        // Positivity is checked on this very grid, which a different size samples differently.
        let mut mu = self.denominators(rows, cols);
        floor_spectrum(&mut mu);
        // White noise is drawn directly in the frequency domain (circular complex Gaussian,
        // unit power per bin) instead of transforming a real noise field: one FFT instead of
        // two. The real part of the inverse transform, scaled by sqrt(2 M N), has exactly the
        // model's covariance (1/MN) sum_k S_k cos(omega_k . lag).
        // Amplitudes in single precision, as the transform runs: sqrt(sigma^2 / (2 mu)).
        let half_sigma2 = (0.5 * self.sigma2.max(0.0)) as f32;
        let spectrum: Vec<Complex32> = mu
            .iter()
            .zip(noise.chunks_exact(2))
            .map(|(&m, w)| {
                let amplitude = (half_sigma2 / m as f32).sqrt();
                Complex32::new(w[0] * amplitude, w[1] * amplitude)
            })
            .collect();
        let scale = (2.0 * (rows * cols) as f64).sqrt();
        fft::inverse_real_by_columns(spectrum, rows, cols, |v| v * scale + self.mean)
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

    fn truth() -> GmrfModel {
        GmrfModel {
            order: 2,
            gamma: vec![0.2, 0.15, 0.05, -0.04],
            sigma2: 2.0,
            mean: -1.0,
        }
    }

    #[test]
    fn the_likelihood_estimate_recovers_parameters_and_does_not_lower_the_likelihood() {
        let m = truth();
        let offsets = causal(2);
        for seed in 0..4 {
            let y = m
                .synthesize(96, 96, seed, true)
                .index_axis_move(Axis(0), 0)
                .mapv(|v| v + 1.0);
            let (ls, _) = least_squares(&y, offsets).unwrap();
            let (ml, sigma2) = torus_likelihood(&y, offsets, ls.clone());
            for (g, t) in ml.iter().zip(&m.gamma) {
                assert!((g - t).abs() < 0.03, "{ml:?}");
            }
            assert!((sigma2 / m.sigma2 - 1.0).abs() < 0.1, "{sigma2}");
            // Whittle's -log-likelihood, profiled over sigma^2, is no larger at the estimate.
            let nll = |g: &[f64]| {
                let model = GmrfModel {
                    order: 2,
                    gamma: g.to_vec(),
                    sigma2: 1.0,
                    mean: 0.0,
                };
                let mu = model.denominators(96, 96);
                let spectrum = fft::forward(&y);
                let n = 96.0 * 96.0;
                // mu is stored column by column: bin (k1, k2) at [k2, k1].
                let weighted: f64 = spectrum
                    .indexed_iter()
                    .map(|((k1, k2), c)| c.norm_sqr() / n * mu[[k2, k1]])
                    .sum();
                n * (weighted / n).ln() - mu.iter().map(|m| m.ln()).sum::<f64>()
            };
            assert!(nll(&ml) <= nll(&ls) + 1e-6, "{} > {}", nll(&ml), nll(&ls));
        }
    }

    #[test]
    fn least_squares_recovers_parameters_on_average() {
        let m = truth();
        let mut mean_gamma = [0.0; 4];
        let mut mean_sigma = 0.0;
        let runs = 6;
        for seed in 0..runs {
            let fit = GmrfModel::fit(m.synthesize(128, 128, seed, true).view(), 2).model;
            assert_eq!(fit.order, 2);
            for (a, g) in mean_gamma.iter_mut().zip(&fit.gamma) {
                *a += g / runs as f64;
            }
            mean_sigma += fit.sigma2 / runs as f64;
        }
        for (a, t) in mean_gamma.iter().zip(&m.gamma) {
            assert!((a - t).abs() < 0.015, "{mean_gamma:?}");
        }
        assert!((mean_sigma - 2.0).abs() < 0.1, "{mean_sigma}");
    }

    #[test]
    fn sample_variance_matches_the_spectral_formula() {
        let m = GmrfModel {
            mean: 0.0,
            ..truth()
        };
        let expected = m.variance(256, 256);
        let y = m.synthesize(256, 256, 42, true);
        let var = y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64;
        assert!((var / expected - 1.0).abs() < 0.05, "{var} vs {expected}");
    }

    #[test]
    fn invalid_spectra_are_repaired() {
        let bad = GmrfModel {
            order: 1,
            gamma: vec![0.4, 0.3],
            sigma2: 1.0,
            mean: 0.0,
        };
        let (fixed, note) = bad.made_valid(64, 64);
        assert!(note.is_some());
        let min = fixed
            .denominators(64, 64)
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        assert!(min >= MU_FLOOR * 0.999, "{min}");
        assert!(bad.synthesize(32, 32, 1, true).iter().all(|v| v.is_finite()));
        assert!(truth().made_valid(64, 64).1.is_none());
    }

    #[test]
    fn synthesis_is_deterministic_and_tiles() {
        let m = truth();
        assert_eq!(m.synthesize(20, 30, 3, true), m.synthesize(20, 30, 3, true));
        // The torus is the only sample: `tileable` changes nothing.
        assert_eq!(m.synthesize(20, 30, 3, false), m.synthesize(20, 30, 3, true));
        let y = m.synthesize(64, 64, 3, true).index_axis_move(Axis(0), 0);
        // Difference across the wrap is like a difference inside.
        let inner: f64 = (0..64).map(|r| (y[[r, 31]] - y[[r, 32]]).powi(2)).sum();
        let seam: f64 = (0..64).map(|r| (y[[r, 63]] - y[[r, 0]]).powi(2)).sum();
        assert!(
            seam < 2.5 * inner && inner < 2.5 * seam,
            "{inner} vs {seam}"
        );
    }
}
