//! Two-dimensional FFTs over `ndarray` planes with rustfft (rows, transpose, rows, transpose).
//! rustfft does not normalise: the inverse here divides by `rows * cols`, so
//! `inverse(forward(x)) == x`.

use ndarray::Array2;
use rustfft::FftPlanner;
use rustfft::num_complex::Complex64;

fn transform(data: &mut Array2<Complex64>, inverse: bool) {
    let mut planner = FftPlanner::<f64>::new();
    for _ in 0..2 {
        let (rows, cols) = data.dim();
        let fft = if inverse {
            planner.plan_fft_inverse(cols)
        } else {
            planner.plan_fft_forward(cols)
        };
        let mut flat: Vec<Complex64> = data.iter().copied().collect();
        fft.process(&mut flat);
        // Transpose so that the second pass runs along the other axis.
        let t = Array2::from_shape_vec((rows, cols), flat).expect("same size");
        *data = t.reversed_axes().as_standard_layout().to_owned();
    }
}

/// Forward 2D DFT of a real plane (unnormalised).
pub(crate) fn forward(real: &Array2<f64>) -> Array2<Complex64> {
    let mut data = real.mapv(|v| Complex64::new(v, 0.0));
    transform(&mut data, false);
    data
}

/// Inverse 2D DFT, normalised by `1 / (rows * cols)`; the real part.
pub(crate) fn inverse_real(spectrum: &Array2<Complex64>) -> Array2<f64> {
    let mut data = spectrum.clone();
    transform(&mut data, true);
    let n = data.len() as f64;
    data.mapv(|c| c.re / n)
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
    }
}
