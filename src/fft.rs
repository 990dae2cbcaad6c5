//! Two-dimensional FFTs over `ndarray` planes with rustfft: rows, transpose, rows, transpose
//! (the `transpose` crate does the cache-friendly transposes). rustfft does not normalise: the
//! inverse here divides by `rows * cols`, so `inverse_real(forward(x)) == x`.

use ndarray::Array2;
use rayon::prelude::*;
use rustfft::FftPlanner;
use rustfft::num_complex::{Complex32, Complex64};

/// In-place 2D transform of a row-major `rows x cols` buffer; the 1D transforms of each pass
/// run in parallel batches.
fn transform(data: &mut Vec<Complex64>, rows: usize, cols: usize, inverse: bool) {
    if data.is_empty() {
        return;
    }
    let mut planner = FftPlanner::<f64>::new();
    let mut scratch = vec![Complex64::new(0.0, 0.0); data.len()];
    for (n, m) in [(cols, rows), (rows, cols)] {
        // `data` holds m rows of length n: transform each, then transpose to n x m.
        let fft = if inverse {
            planner.plan_fft_inverse(n)
        } else {
            planner.plan_fft_forward(n)
        };
        data.par_chunks_mut(batch(n))
            .for_each(|chunk| fft.process(chunk));
        transpose::transpose(data, &mut scratch, n, m);
        std::mem::swap(data, &mut scratch);
    }
}

/// Forward 2D DFT of a real plane (unnormalised).
pub(crate) fn forward(real: &Array2<f64>) -> Array2<Complex64> {
    forward_complex(&real.mapv(|v| Complex64::new(v, 0.0)))
}

/// Forward 2D DFT of a complex plane (unnormalised).
pub(crate) fn forward_complex(plane: &Array2<Complex64>) -> Array2<Complex64> {
    let (rows, cols) = plane.dim();
    // In logical (row-major) order whatever the plane's memory layout (a transposed plane's
    // raw buffer runs by columns).
    let mut data: Vec<Complex64> = plane.iter().copied().collect();
    transform(&mut data, rows, cols, false);
    Array2::from_shape_vec((rows, cols), data).expect("rows x cols values")
}

/// Inverse 2D DFT, normalised by `1 / (rows * cols)`, complex (for analytic, one-sided
/// spectra such as oriented pyramid bands).
pub(crate) fn inverse(spectrum: &Array2<Complex64>) -> Array2<Complex64> {
    let (rows, cols) = spectrum.dim();
    let mut data: Vec<Complex64> = spectrum.iter().copied().collect();
    transform(&mut data, rows, cols, true);
    let n = data.len() as f64;
    Array2::from_shape_vec((rows, cols), data.into_iter().map(|c| c / n).collect())
        .expect("rows x cols values")
}

/// Inverse 2D DFT, normalised by `1 / (rows * cols)`; the real part.
pub(crate) fn inverse_real(spectrum: &Array2<Complex64>) -> Array2<f64> {
    let (rows, cols) = spectrum.dim();
    let mut data: Vec<Complex64> = spectrum.iter().copied().collect();
    transform(&mut data, rows, cols, true);
    let n = data.len() as f64;
    Array2::from_shape_vec((rows, cols), data.into_iter().map(|c| c.re / n).collect())
        .expect("rows x cols values")
}

/// Inverse 2D DFT of a spectrum given column by column (`cols` runs of `rows` bins), normalised
/// by `1 / (rows * cols)`: the real part, mapped by `f`, as a row-major `rows x cols` plane.
/// Starting from columns saves one of the two transposes; the 1D transforms run in parallel,
/// in single precision (twice the vector width; about 1e-6 relative error, far below the
/// sampling noise of the fields this synthesizes).
pub(crate) fn inverse_real_by_columns(
    mut data: Vec<Complex32>,
    rows: usize,
    cols: usize,
    f: impl Fn(f64) -> f64 + Sync,
) -> Array2<f64> {
    assert_eq!(data.len(), rows * cols, "a rows x cols spectrum");
    if data.is_empty() {
        return Array2::zeros((rows, cols));
    }
    let mut planner = FftPlanner::<f32>::new();
    let (by_rows, by_cols) = (
        planner.plan_fft_inverse(rows),
        planner.plan_fft_inverse(cols),
    );
    data.par_chunks_mut(batch(rows))
        .for_each(|chunk| by_rows.process(chunk));
    let mut out = vec![Complex32::new(0.0, 0.0); data.len()];
    transpose::transpose(&data, &mut out, rows, cols);
    out.par_chunks_mut(batch(cols))
        .for_each(|chunk| by_cols.process(chunk));
    let n = out.len() as f64;
    let values: Vec<f64> = out.par_iter().map(|c| f(f64::from(c.re) / n)).collect();
    Array2::from_shape_vec((rows, cols), values).expect("rows x cols values")
}

/// Batches of whole transforms of length `n`, about 64 Ki values each (rayon work items).
fn batch(n: usize) -> usize {
    n * (65_536 / n.max(1)).max(1)
}

/// The half spectrum of a real row-major `rows x cols` plane: the 2D DFT (unnormalised, f32)
/// at column frequencies `0..=cols / 2` and every row frequency, column by column (`cols / 2 +
/// 1` runs of `rows` bins); the other half is its complex conjugate mirror. Rows are packed in
/// pairs as the real and imaginary parts of one complex row, so the work is about half a
/// complex 2D transform.
///
/// # Panics
/// If `real` does not hold `rows * cols` values.
pub(crate) fn forward_half(real: &[f32], rows: usize, cols: usize) -> Vec<Complex32> {
    assert_eq!(real.len(), rows * cols, "a rows x cols plane");
    let bins = cols / 2 + 1;
    if real.is_empty() {
        return Vec::new();
    }
    let mut planner = FftPlanner::<f32>::new();
    let (by_rows, by_cols) = (
        planner.plan_fft_forward(cols),
        planner.plan_fft_forward(rows),
    );
    // Rows 2j and 2j + 1 as one complex row (an odd last row pairs with zeros).
    let mut packed = vec![Complex32::new(0.0, 0.0); rows.div_ceil(2) * cols];
    packed
        .par_chunks_mut(cols)
        .zip(real.par_chunks(2 * cols))
        .for_each(|(z, two)| {
            let (even, odd) = two.split_at(cols);
            for (c, v) in z.iter_mut().enumerate() {
                *v = Complex32::new(even[c], odd.get(c).copied().unwrap_or(0.0));
            }
        });
    packed
        .par_chunks_mut(batch(cols))
        .for_each(|chunk| by_rows.process(chunk));
    // Separate the pair: X0[k] = (Z[k] + conj Z[-k]) / 2, X1[k] = (Z[k] - conj Z[-k]) / 2i.
    let mut half = vec![Complex32::new(0.0, 0.0); rows * bins];
    half.par_chunks_mut(2 * bins)
        .zip(packed.par_chunks(cols))
        .for_each(|(out, z)| {
            let (even, odd) = out.split_at_mut(bins);
            for k in 0..bins {
                let (a, b) = (z[k], z[(cols - k) % cols].conj());
                even[k] = (a + b) * 0.5;
                if let Some(o) = odd.get_mut(k) {
                    let d = (a - b) * 0.5;
                    *o = Complex32::new(d.im, -d.re);
                }
            }
        });
    let mut by_columns = vec![Complex32::new(0.0, 0.0); rows * bins];
    transpose::transpose(&half, &mut by_columns, bins, rows);
    by_columns
        .par_chunks_mut(batch(rows))
        .for_each(|chunk| by_cols.process(chunk));
    by_columns
}

/// The inverse of [`forward_half`], normalised by `1 / (rows * cols)`: from a half spectrum
/// given column by column whose full spectrum is conjugate symmetric (the DFT of a real plane,
/// possibly filtered by a real kernel), the real plane, mapped by `f`, row-major.
///
/// # Panics
/// If `spectrum` does not hold `(cols / 2 + 1) * rows` bins.
pub(crate) fn inverse_half(
    mut spectrum: Vec<Complex32>,
    rows: usize,
    cols: usize,
    f: impl Fn(f64) -> f64 + Sync,
) -> Array2<f64> {
    let bins = cols / 2 + 1;
    if rows == 0 || cols == 0 {
        return Array2::zeros((rows, cols));
    }
    assert_eq!(spectrum.len(), rows * bins, "a half spectrum");
    let mut planner = FftPlanner::<f32>::new();
    let (by_rows, by_cols) = (
        planner.plan_fft_inverse(cols),
        planner.plan_fft_inverse(rows),
    );
    spectrum
        .par_chunks_mut(batch(rows))
        .for_each(|chunk| by_cols.process(chunk));
    let mut half = vec![Complex32::new(0.0, 0.0); rows * bins];
    transpose::transpose(&spectrum, &mut half, rows, bins);
    // Each row's spectrum is conjugate symmetric in the column frequency: rebuild the whole
    // row, and pack rows 2j and 2j + 1 as Z = X0 + i X1 (one inverse gives both).
    let mut packed = vec![Complex32::new(0.0, 0.0); rows.div_ceil(2) * cols];
    packed
        .par_chunks_mut(cols)
        .zip(half.par_chunks(2 * bins))
        .for_each(|(z, two)| {
            let (even, odd) = two.split_at(bins);
            let full = |row: &[Complex32], k: usize| {
                if k < bins {
                    row[k]
                } else {
                    row[cols - k].conj()
                }
            };
            for (k, v) in z.iter_mut().enumerate() {
                let x0 = full(even, k);
                let x1 = if odd.is_empty() {
                    Complex32::new(0.0, 0.0)
                } else {
                    full(odd, k)
                };
                *v = Complex32::new(x0.re - x1.im, x0.im + x1.re);
            }
        });
    packed
        .par_chunks_mut(batch(cols))
        .for_each(|chunk| by_rows.process(chunk));
    let n = (rows * cols) as f64;
    let mut out = vec![0.0; rows * cols];
    out.par_chunks_mut(2 * cols)
        .zip(packed.par_chunks(cols))
        .for_each(|(two, z)| {
            let (even, odd) = two.split_at_mut(cols);
            for (c, v) in z.iter().enumerate() {
                even[c] = f(f64::from(v.re) / n);
                if let Some(o) = odd.get_mut(c) {
                    *o = f(f64::from(v.im) / n);
                }
            }
        });
    Array2::from_shape_vec((rows, cols), out).expect("rows x cols values")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_dc_term() {
        let x = Array2::from_shape_fn((6, 10), |(i, j)| (i * 3 + j) as f64 * 0.1 - 1.0);
        let f = forward(&x);
        assert!((f[[0, 0]].re - x.sum()).abs() < 1e-9);
        let back = inverse_real(&f);
        assert!((&back - &x).iter().all(|d| d.abs() < 1e-12));
        // A pure cosine along columns lands in bins (0, 1) and (0, cols - 1).
        let c = Array2::from_shape_fn((4, 8), |(_, j)| {
            (2.0 * std::f64::consts::PI * j as f64 / 8.0).cos()
        });
        let fc = forward(&c);
        assert!((fc[[0, 1]].re - 16.0).abs() < 1e-9 && (fc[[0, 7]].re - 16.0).abs() < 1e-9);
        // And along rows.
        let r = Array2::from_shape_fn((8, 4), |(i, _)| {
            (2.0 * std::f64::consts::PI * i as f64 / 8.0).cos()
        });
        let fr = forward(&r);
        assert!((fr[[1, 0]].re - 16.0).abs() < 1e-9);
        // The column-major inverse agrees with the row-major one.
        let spectrum = forward(&x);
        let by_columns: Vec<Complex32> = spectrum
            .t()
            .iter()
            .map(|c| Complex32::new(c.re as f32, c.im as f32))
            .collect();
        let back = inverse_real_by_columns(by_columns, 6, 10, |v| 2.0 * v);
        assert!((&back - &(2.0 * &x)).iter().all(|d| d.abs() < 1e-5));
    }

    #[test]
    fn half_spectrum_matches_the_full_one_and_round_trips() {
        for (rows, cols) in [(6, 10), (7, 9), (1, 5), (5, 1), (8, 8)] {
            let x = Array2::from_shape_fn((rows, cols), |(i, j)| {
                ((i * 7 + j * 3) % 11) as f64 * 0.2 - 1.0 + (i as f64 * 0.3).sin()
            });
            let full = forward(&x);
            let values: Vec<f32> = x.iter().map(|&v| v as f32).collect();
            let half = forward_half(&values, rows, cols);
            let bins = cols / 2 + 1;
            assert_eq!(half.len(), rows * bins);
            for k in 0..bins {
                for j in 0..rows {
                    let (a, b) = (half[k * rows + j], full[[j, k]]);
                    let err = (f64::from(a.re) - b.re).abs() + (f64::from(a.im) - b.im).abs();
                    assert!(err < 1e-4, "{rows}x{cols} bin ({j}, {k}): {a} vs {b}");
                }
            }
            let back = inverse_half(half, rows, cols, |v| v + 1.0);
            assert!(
                (&back - &(&x + 1.0)).iter().all(|d| d.abs() < 1e-5),
                "{rows}x{cols}"
            );
        }
    }
}
