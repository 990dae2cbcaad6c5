//! Two-dimensional FFTs over `ndarray` planes with rustfft: rows, transpose, rows, transpose
//! (the `transpose` crate does the cache-friendly transposes). rustfft does not normalise: the
//! inverse here divides by `rows * cols`, so `inverse_real(forward(x)) == x`.

use ndarray::Array2;
use rayon::prelude::*;
use rustfft::FftPlanner;
use rustfft::num_complex::{Complex32, Complex64};

/// In-place 2D transform of a row-major `rows x cols` buffer.
fn transform(data: &mut Vec<Complex64>, rows: usize, cols: usize, inverse: bool) {
    let mut planner = FftPlanner::<f64>::new();
    let mut scratch = vec![Complex64::new(0.0, 0.0); data.len()];
    for (n, m) in [(cols, rows), (rows, cols)] {
        // `data` holds m rows of length n: transform each, then transpose to n x m.
        let fft = if inverse {
            planner.plan_fft_inverse(n)
        } else {
            planner.plan_fft_forward(n)
        };
        fft.process(data);
        transpose::transpose(data, &mut scratch, n, m);
        std::mem::swap(data, &mut scratch);
    }
}

/// Forward 2D DFT of a real plane (unnormalised).
pub(crate) fn forward(real: &Array2<f64>) -> Array2<Complex64> {
    let (rows, cols) = real.dim();
    let mut data: Vec<Complex64> = real.iter().map(|&v| Complex64::new(v, 0.0)).collect();
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
    // Batches of whole transforms, about 64 Ki values each.
    let batch = |n: usize| n * (65_536 / n).max(1);
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
}
