//! Spectral stability tests of the 2D CAR (mrf_math.md 2.5), exact where the empirical probe
//! only samples: a causal (non-symmetric half-plane) recursion `A(z) Y = e` is stable when
//! (a) its in-row part `1 - sum_{s2} a_(0,s2) v^s2` has no root with `|v| <= 1` (else every row
//! grows from left to right: the right-edge blow-up of a wide synthesis), and (b) for every
//! column frequency `w2` the recursion down the rows, `sum_{s1} c_s1(w2) u^s1` with
//! `c_s1(w2) = [s1 = 0] - sum_{s2} a_(s1,s2) exp(-i w2 s2)`, has no root with `|u| <= 1`
//! (Ekstrom and Woods' conditions for half-plane filters). Both are checked by the Schur-Cohn
//! test on polynomials of degree at most 3.

use rustfft::num_complex::Complex64;

use super::torus::{column_terms, polynomial, row_phases};

/// Column frequencies sampled by condition (b) and grid side of [`stationary_variance`].
pub(crate) const GRID: usize = 256;

/// True when every root of `sum_k p[k] x^k` lies strictly inside the circle of `radius`
/// (Schur-Cohn: with `q(x) = p(radius x)` of degree n, all roots of `q` are inside the unit
/// disk iff `|q_0| < |q_n|` and the same holds for `(conj(q_n) q - q_0 q*) / x`, `q*` the
/// conjugate reversal).
fn roots_within(p: &[Complex64], radius: f64) -> bool {
    let mut q: Vec<Complex64> = p
        .iter()
        .enumerate()
        .map(|(k, &c)| c * radius.powi(k as i32))
        .collect();
    while q.last().is_some_and(|c| c.norm() == 0.0) {
        q.pop();
    }
    while q.len() > 1 {
        let n = q.len() - 1;
        let (lead, last) = (q[n], q[0]);
        if last.norm() >= lead.norm() {
            return false;
        }
        q = (1..=n)
            .map(|k| lead.conj() * q[k] - last * q[n - k].conj())
            .collect();
    }
    !q.is_empty()
}

/// Conditions (a) and (b) of the module note: the causal recursion of `gamma` on `offsets`
/// decays in every direction (roots of the reversed polynomials strictly inside the unit
/// circle), checked at [`GRID`] column frequencies.
pub(crate) fn causally_stable(offsets: &[(isize, isize)], gamma: &[f64]) -> bool {
    // (a) x^3 - sum_s2 a_(0,s2) x^(3 - s2): reversed, so roots inside mean roots of the
    // in-row polynomial outside.
    let mut in_row = [Complex64::new(0.0, 0.0); 4];
    in_row[3] = Complex64::new(1.0, 0.0);
    for (&g, &(s1, s2)) in gamma.iter().zip(offsets) {
        if s1 == 0 {
            in_row[3 - s2 as usize] -= g;
        }
    }
    if !roots_within(&in_row, 1.0) {
        return false;
    }
    // (b) per column frequency: reversed polynomial of c_0 + c_1 u + ... + c_D u^D.
    column_terms(2 * GRID, offsets, |k| Complex64::new(gamma[k], 0.0))
        .iter()
        .all(|t| {
            let d = t.len() - 1;
            let reversed: Vec<Complex64> = (0..=d)
                .map(|k| {
                    let c = -t[d - k];
                    if k == d { c + 1.0 } else { c }
                })
                .collect();
            roots_within(&reversed, 1.0)
        })
}

/// The stationary variance of the 2D CAR, `sigma2 (1 / n^2) sum_w 1 / |A(e^iw)|^2` on an
/// `n x n` frequency grid: what the exact toroidal field has (and a causal one, started far
/// enough away). Infinite at a unit root on the grid.
pub(crate) fn stationary_variance(
    offsets: &[(isize, isize)],
    gamma: &[f64],
    sigma2: f64,
    n: usize,
) -> f64 {
    let z = row_phases(n);
    let sum: f64 = column_terms(n, offsets, |k| Complex64::new(gamma[k], 0.0))
        .iter()
        .enumerate()
        .map(|(k, t)| {
            // Columns 1..n/2 stand for their mirror images too.
            let weight = if k == 0 || 2 * k == n { 1.0 } else { 2.0 };
            weight
                * z.iter()
                    .map(|&zj| 1.0 / (Complex64::new(1.0, 0.0) - polynomial(t, zj)).norm_sqr())
                    .sum::<f64>()
        })
        .sum();
    sigma2 * sum / (n * n) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mrf::neighbourhood::causal;

    #[test]
    fn schur_cohn_counts_roots_against_the_circle() {
        let c = |re: f64| Complex64::new(re, 0.0);
        // (x - 0.5)(x + 0.9) = x^2 + 0.4 x - 0.45: inside; (x - 1.1)(x - 0.2): not.
        assert!(roots_within(&[c(-0.45), c(0.4), c(1.0)], 1.0));
        assert!(!roots_within(&[c(0.22), c(-1.3), c(1.0)], 1.0));
        // Radius: 0.9 is inside 0.95 but not 0.85.
        assert!(roots_within(&[c(-0.9), c(1.0)], 0.95));
        assert!(!roots_within(&[c(-0.9), c(1.0)], 0.85));
        // A complex pair at modulus 0.99 and one on the circle.
        let pair = |r: f64| [c(r * r), c(-2.0 * r * 0.6), c(1.0)];
        assert!(roots_within(&pair(0.99), 1.0));
        assert!(!roots_within(&pair(1.0), 1.0));
    }

    #[test]
    fn stability_conditions_separate_rows_and_columns() {
        let offsets = causal(1); // (0, 1), (1, 0)
        assert!(causally_stable(offsets, &[0.45, 0.45]));
        // Growth along each row (in-row root inside the unit circle).
        assert!(!causally_stable(offsets, &[1.004, -0.5]));
        // Growth down the rows at w2 = pi: 1 + 0.3 - 1.4 u.
        assert!(!causally_stable(offsets, &[-0.3, 1.4]));
        // A unit root at w = 0.
        assert!(!causally_stable(offsets, &[0.5, 0.5]));
    }

    #[test]
    fn stationary_variance_matches_the_closed_form() {
        // A separable-free case: Y = a Y_left + e has variance sigma2 / (1 - a^2).
        let v = stationary_variance(causal(1), &[0.6, 0.0], 2.0, 256);
        assert!((v - 2.0 / (1.0 - 0.36)).abs() < 1e-9, "{v}");
    }
}
