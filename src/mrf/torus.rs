//! Exact toroidal (tileable) synthesis of the causal models by the DFT (mrf_math.md 2.4): on an
//! `H x W` torus the recursion `Y_r - sum_s A_s Y_{r-s} = e_r` (indices wrapped) is a circulant
//! system, which the 2D DFT diagonalises: `Y^(w) = M(w)^-1 e^(w)` with
//! `M(w) = I - sum_s A_s exp(-i <w, s>)` (a scalar `A(e^iw)` for the 2D CAR, 3 x 3 for the 3D
//! CAR). One forward and one inverse real FFT per channel replace raster sweeps; the result is
//! the fixed point those sweeps converge to, for the same noise.

use ndarray::Array2;
use rayon::prelude::*;
use rustfft::num_complex::{Complex32, Complex64};

use crate::fft;

/// Below this modulus of `A(e^iw)` (or of `det M(w)`), a frequency is dropped from a toroidal
/// field instead of amplified without bound: only a model with a unit root on the DFT grid
/// reaches it, and the repaired estimates of the analysis keep well clear of it.
const SINGULAR: f64 = 1e-9;

/// `exp(-i x)`.
pub(super) fn phase(x: f64) -> Complex64 {
    Complex64::new(x.cos(), -x.sin())
}

/// Per column frequency `w2 = 2 pi k / cols` (`k` in `0..=cols / 2`) and per row offset `s1`
/// in `0..=max s1`: `sum over s = (s1, s2) of coef(s) exp(-i w2 s2)`, with `coef` generic
/// (a scalar or a 3 x 3 block). The transfer function at `(w1, w2)` is then a polynomial of
/// degree `max s1` in `exp(-i w1)` with these coefficients.
pub(super) fn column_terms<
    T: Copy + Default + std::ops::AddAssign + std::ops::Mul<Complex64, Output = T>,
>(
    cols: usize,
    offsets: &[(isize, isize)],
    coef: impl Fn(usize) -> T,
) -> Vec<Vec<T>> {
    let depth = offsets
        .iter()
        .map(|s| s.0.max(0) as usize)
        .max()
        .unwrap_or(0)
        + 1;
    (0..=cols / 2)
        .map(|k| {
            let w2 = 2.0 * std::f64::consts::PI * k as f64 / cols as f64;
            let mut t = vec![T::default(); depth];
            for (n, &(s1, s2)) in offsets.iter().enumerate() {
                t[s1 as usize] += coef(n) * phase(w2 * s2 as f64);
            }
            t
        })
        .collect()
}

/// `sum_p t[p] z^p` (Horner).
pub(super) fn polynomial<
    T: Copy + std::ops::Add<Output = T> + std::ops::Mul<Complex64, Output = T>,
>(
    t: &[T],
    z: Complex64,
) -> T {
    let mut acc = t[t.len() - 1];
    for &c in t[..t.len() - 1].iter().rev() {
        acc = acc * z + c;
    }
    acc
}

/// `exp(-i 2 pi j / rows)` for every row frequency `j`.
pub(super) fn row_phases(rows: usize) -> Vec<Complex64> {
    (0..rows)
        .map(|j| phase(2.0 * std::f64::consts::PI * j as f64 / rows as f64))
        .collect()
}

/// Margin of a plain (non-tileable) field on every side of the torus it is cut from, pixels:
/// beyond the correlation length of the repaired models, so the cut edges are unrelated.
pub const MARGIN: usize = 32;

/// The torus a `rows x cols` field is solved on: its own size when `tileable`, else
/// [`padded`] on both axes.
pub(crate) fn shape(rows: usize, cols: usize, tileable: bool) -> (usize, usize) {
    if tileable {
        (rows, cols)
    } else {
        (padded(rows), padded(cols))
    }
}

/// Side of the torus a plain field of `n` samples is cut from: `n + 2 MARGIN` rounded up to a
/// size whose prime factors are at most 7, which the FFT handles fast (0 for 0).
fn padded(n: usize) -> usize {
    if n == 0 {
        return 0;
    }
    let smooth = |mut m: usize| {
        for p in [2, 3, 5, 7] {
            while m.is_multiple_of(p) {
                m /= p;
            }
        }
        m == 1
    };
    (n + 2 * MARGIN..)
        .find(|&m| smooth(m))
        .expect("smooth numbers are unbounded")
}

/// The `rows x cols` field from one solved on [`shape`]: the whole torus when `tileable`,
/// else its middle.
pub(crate) fn cut(field: Array2<f64>, rows: usize, cols: usize, tileable: bool) -> Array2<f64> {
    if tileable {
        return field;
    }
    field
        .slice(ndarray::s![MARGIN..MARGIN + rows, MARGIN..MARGIN + cols])
        .to_owned()
}

/// The exact toroidal field of the 2D CAR `Y_r = sum_s gamma_s Y_{r-s} + sigma w_r` for the
/// row-major unit noise `noise` (`rows * cols` values): `Y^ = sigma w^ / A(e^iw)`. Frequencies
/// where `|A| <` [`SINGULAR`] are dropped. `mean` is added to every value.
pub(crate) fn car2d(
    (rows, cols): (usize, usize),
    noise: &[f32],
    sigma: f64,
    (offsets, gamma): (&[(isize, isize)], &[f64]),
    mean: f64,
) -> Array2<f64> {
    let mut spectrum = fft::forward_half(&noise[..rows * cols], rows, cols);
    let terms = column_terms(cols, offsets, |n| Complex64::new(gamma[n], 0.0));
    let z = row_phases(rows);
    spectrum
        .par_chunks_mut(rows.max(1))
        .zip(&terms)
        .for_each(|(column, t)| {
            for (bin, &zj) in column.iter_mut().zip(&z) {
                let a = Complex64::new(1.0, 0.0) - polynomial(t, zj);
                // |A|^2 against SINGULAR^2: libm's hypot in |A| cost a few percent of a
                // 1024^2 synthesis's processor time.
                let gain = if a.norm_sqr() < SINGULAR * SINGULAR {
                    Complex64::new(0.0, 0.0)
                } else {
                    sigma / a
                };
                let g = Complex32::new(gain.re as f32, gain.im as f32);
                *bin *= g;
            }
        });
    fft::inverse_half(spectrum, rows, cols, |v| v + mean)
}

/// A 3 x 3 complex matrix, row-major.
type Matrix = [[Complex64; 3]; 3];

/// A 3 x 3 block as a generic coefficient of [`column_terms`].
#[derive(Clone, Copy, Default)]
struct Block(Matrix);

impl std::ops::AddAssign for Block {
    fn add_assign(&mut self, o: Self) {
        for (r, o) in self.0.iter_mut().zip(o.0) {
            for (v, w) in r.iter_mut().zip(o) {
                *v += w;
            }
        }
    }
}

impl std::ops::Add for Block {
    type Output = Self;
    fn add(mut self, o: Self) -> Self {
        self += o;
        self
    }
}

impl std::ops::Mul<Complex64> for Block {
    type Output = Self;
    fn mul(self, z: Complex64) -> Self {
        Self(self.0.map(|r| r.map(|v| v * z)))
    }
}

/// Solves `m y = e` by Cramer's rule; `None` when `|det m|` is below [`SINGULAR`] times the
/// product of the row norms (numerically singular).
fn solve3(m: &Matrix, e: [Complex64; 3]) -> Option<[Complex64; 3]> {
    let det3 = |a: [Complex64; 3], b: [Complex64; 3], c: [Complex64; 3]| {
        a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0])
    };
    let det = det3(m[0], m[1], m[2]);
    let scale: f64 = m
        .iter()
        .map(|r| r.iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt())
        .product();
    if det.norm().is_nan() || det.norm() < SINGULAR * scale {
        return None;
    }
    // Column q of m replaced by e.
    let with = |q: usize| {
        let row = |i: usize| {
            let mut r = m[i];
            r[q] = e[i];
            r
        };
        det3(row(0), row(1), row(2)) / det
    };
    Some([with(0), with(1), with(2)])
}

/// The exact toroidal field of the 3D CAR `Y_r = sum_s A_s Y_{r-s} + e_r` for the innovation
/// planes `e` (three row-major `rows * cols` planes, `e_r = L_Sigma w_r`): per frequency,
/// `Y^ = (I - sum_s A_s exp(-i <w, s>))^-1 e^`. `a[n]` is `A_s` for `offsets[n]`, row-major.
/// Frequencies where the matrix is numerically singular are dropped. `mean[p]` is added to
/// channel `p`.
pub(crate) fn car3d(
    (rows, cols): (usize, usize),
    e: &[Vec<f32>; 3],
    (offsets, a): (&[(isize, isize)], &[[f64; 9]]),
    mean: [f64; 3],
) -> [Array2<f64>; 3] {
    let mut spectra: Vec<Vec<Complex32>> = e
        .par_iter()
        .map(|plane| fft::forward_half(plane, rows, cols))
        .collect();
    let terms = column_terms(cols, offsets, |n| {
        Block(std::array::from_fn(|p| {
            std::array::from_fn(|q| Complex64::new(a[n][3 * p + q], 0.0))
        }))
    });
    let z = row_phases(rows);
    let bins = cols / 2 + 1;
    let [s0, s1, s2] = &mut spectra[..] else {
        unreachable!("three channels")
    };
    let chunk = rows.max(1);
    s0.par_chunks_mut(chunk)
        .zip(s1.par_chunks_mut(chunk))
        .zip(s2.par_chunks_mut(chunk))
        .zip(&terms[..bins])
        .for_each(|(((c0, c1), c2), t)| {
            for (j, &zj) in z.iter().enumerate() {
                let g = polynomial(t, zj).0;
                let m: Matrix =
                    std::array::from_fn(|p| std::array::from_fn(|q| f64::from(p == q) - g[p][q]));
                let wide = |v: Complex32| Complex64::new(f64::from(v.re), f64::from(v.im));
                let y = solve3(&m, [wide(c0[j]), wide(c1[j]), wide(c2[j])])
                    .unwrap_or([Complex64::new(0.0, 0.0); 3]);
                let narrow = |v: Complex64| Complex32::new(v.re as f32, v.im as f32);
                (c0[j], c1[j], c2[j]) = (narrow(y[0]), narrow(y[1]), narrow(y[2]));
            }
        });
    let mut out = spectra
        .into_par_iter()
        .zip(mean)
        .map(|(s, m)| fft::inverse_half(s, rows, cols, |v| v + m))
        .collect::<Vec<_>>()
        .into_iter();
    std::array::from_fn(|_| out.next().expect("three channels"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mrf::neighbourhood::causal;

    /// The naive twin: Gauss-Seidel sweeps of the wrapped recursion, in raster order with the
    /// same noise every sweep, until nothing moves (a stable model converges geometrically).
    fn sweeps(
        rows: usize,
        cols: usize,
        d: usize,
        step: impl Fn(usize, usize, &[Vec<f64>]) -> Vec<f64>,
    ) -> Vec<Vec<f64>> {
        let mut y = vec![vec![0.0; d]; rows * cols];
        for _ in 0..2000 {
            let mut change = 0.0f64;
            for r in 0..rows {
                for c in 0..cols {
                    let v = step(r, c, &y);
                    for (new, old) in v.iter().zip(&y[r * cols + c]) {
                        change = change.max((new - old).abs());
                    }
                    y[r * cols + c] = v;
                }
            }
            if change < 1e-13 {
                return y;
            }
        }
        panic!("sweeps did not converge");
    }

    fn wrapped(r: usize, c: usize, (s1, s2): (isize, isize), rows: usize, cols: usize) -> usize {
        let rr = (r as isize - s1).rem_euclid(rows as isize) as usize;
        let cc = (c as isize - s2).rem_euclid(cols as isize) as usize;
        rr * cols + cc
    }

    fn relative_error(a: impl Iterator<Item = f64>, b: impl Iterator<Item = f64>) -> f64 {
        let (mut err, mut norm) = (0.0f64, 0.0f64);
        for (x, y) in a.zip(b) {
            err = err.max((x - y).abs());
            norm = norm.max(y.abs());
        }
        err / norm
    }

    #[test]
    fn car2d_dft_equals_the_converged_sweeps() {
        let offsets = causal(5);
        let gamma = [
            0.35, 0.3, -0.1, 0.1, 0.05, -0.05, 0.02, 0.03, -0.02, 0.01, 0.02, -0.01,
        ];
        for (rows, cols) in [(16, 16), (12, 20), (9, 7), (1, 8), (5, 1)] {
            let noise = crate::mrf::noise::standard_normal(7, rows * cols);
            let sigma = 1.7;
            let fast = car2d((rows, cols), &noise, sigma, (offsets, &gamma), 0.0);
            let naive = sweeps(rows, cols, 1, |r, c, y| {
                let mut acc = sigma * f64::from(noise[r * cols + c]);
                for (g, &s) in gamma.iter().zip(offsets) {
                    acc += g * y[wrapped(r, c, s, rows, cols)][0];
                }
                vec![acc]
            });
            let err = relative_error(fast.iter().copied(), naive.iter().map(|v| v[0]));
            assert!(err < 2e-6, "{rows}x{cols}: {err}");
        }
    }

    #[test]
    fn car3d_dft_equals_the_converged_sweeps() {
        let offsets = causal(2);
        let a: Vec<[f64; 9]> = vec![
            [0.30, 0.05, 0.00, 0.00, 0.25, 0.05, 0.05, 0.00, 0.20],
            [0.25, 0.00, 0.05, 0.05, 0.30, 0.00, 0.00, 0.05, 0.30],
            [-0.1, 0.02, 0.0, 0.0, -0.05, 0.0, 0.03, 0.0, -0.1],
            [0.1, 0.0, 0.02, 0.0, 0.1, 0.0, 0.0, 0.0, 0.05],
        ];
        for (rows, cols) in [(12, 12), (10, 7), (3, 9)] {
            let w = crate::mrf::noise::standard_normal(3, 3 * rows * cols);
            let e: [Vec<f32>; 3] = std::array::from_fn(|p| {
                (0..rows * cols)
                    .map(|i| w[3 * i + p] * (p + 1) as f32)
                    .collect()
            });
            let fast = car3d((rows, cols), &e, (offsets, &a), [0.0; 3]);
            let naive = sweeps(rows, cols, 3, |r, c, y| {
                let mut acc: Vec<f64> = (0..3).map(|p| f64::from(e[p][r * cols + c])).collect();
                for (ak, &s) in a.iter().zip(offsets) {
                    let prev = &y[wrapped(r, c, s, rows, cols)];
                    for p in 0..3 {
                        acc[p] += (0..3).map(|q| ak[3 * p + q] * prev[q]).sum::<f64>();
                    }
                }
                acc
            });
            for p in 0..3 {
                let err = relative_error(fast[p].iter().copied(), naive.iter().map(|v| v[p]));
                assert!(err < 2e-6, "{rows}x{cols} channel {p}: {err}");
            }
        }
    }

    #[test]
    fn cramer_solves_and_refuses_singular_matrices() {
        let c = |re: f64, im: f64| Complex64::new(re, im);
        let m: Matrix = [
            [c(2.0, 0.5), c(0.3, -0.1), c(0.0, 0.2)],
            [c(-0.4, 0.0), c(1.5, 0.0), c(0.1, 0.1)],
            [c(0.2, 0.3), c(0.0, -0.2), c(1.0, -0.3)],
        ];
        let y = [c(1.0, -1.0), c(0.5, 2.0), c(-0.3, 0.0)];
        let e: [Complex64; 3] = std::array::from_fn(|p| (0..3).map(|q| m[p][q] * y[q]).sum());
        let x = solve3(&m, e).expect("regular");
        for (a, b) in x.iter().zip(&y) {
            assert!((a - b).norm() < 1e-12, "{a} vs {b}");
        }
        let mut singular = m;
        singular[2] = m[0].map(|v| v * 2.0);
        assert!(solve3(&singular, e).is_none());
    }

    #[test]
    fn a_unit_root_on_the_grid_gives_a_finite_field() {
        let noise = crate::mrf::noise::standard_normal(1, 64);
        let y = car2d((8, 8), &noise, 1.0, (causal(1), &[0.5, 0.5]), 0.0);
        assert!(y.iter().all(|v| v.is_finite()));
    }
}
