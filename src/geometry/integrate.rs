//! From normals to a range map (height field) and back: the least-squares integration of a
//! normal field (Frankot and Chellappa's projection onto integrable surfaces, mrf_math.md
//! 1(b)) solved with FFTs on the mirror-padded field, and the normals of a height field. Both
//! use one derivative, the forward difference (a pixel's slope is the step to its right and
//! lower neighbours), so integrating a height field's normals gives the field back exactly,
//! steps included. With the band-limited derivative `i w` of the textbook method, a
//! one-texel grout wall rang into a 2-3 texel ripple beside it, and with central differences
//! for the normals the relief's shading sat half a texel off the photographs it was measured
//! from, so dividing it out left ridges in the de-shaded images.

use ndarray::{Array2, Array3, s};
use rayon::prelude::*;
use rustfft::num_complex::Complex64;

use crate::fft;

/// Heights (texel units, minimum 0) whose forward differences best match the normals' slopes
/// in least squares.
///
/// `normals` is (3, h, w) with x right, y up in the image and z out of the surface; pixels with
/// `n_z` near 0 get zero slope. A pixel's slope is the step to its right (and lower)
/// neighbour, so the last column's x slope and the last row's y slope have no step to give
/// and are unused. The steps are mirrored to (2h, 2w) before the FFT so that the integration
/// does not wrap one border into the other.
pub fn frankot_chellappa(normals: &Array3<f64>) -> Array2<f64> {
    let (_, h, w) = normals.dim();
    // Slopes along columns (x) and rows (down = -y).
    let slope = |y: usize, x: usize, c: usize| {
        let nz = normals[[2, y, x]];
        if nz > 1e-3 {
            let sign = if c == 0 { -1.0 } else { 1.0 };
            sign * normals[[c, y, x]] / nz
        } else {
            0.0
        }
    };
    // The mirror image of the step from sample i to i + 1 (i < n - 1) is the step from
    // 2n - 2 - i to 2n - 1 - i, negated; the steps across the mirror lines (n - 1 to n, and
    // 2n - 1 around to 0) join a sample to its own copy: zero.
    let mirrored = |i: usize, n: usize| -> Option<(usize, f64)> {
        if i + 1 < n {
            Some((i, 1.0))
        } else if i + 1 == n || i + 1 == 2 * n {
            None
        } else {
            Some((2 * n - 2 - i, -1.0))
        }
    };
    let reflect = |i: usize, n: usize| if i < n { i } else { 2 * n - 1 - i };
    let right = Array2::from_shape_fn((2 * h, 2 * w), |(y, x)| {
        mirrored(x, w).map_or(0.0, |(xx, sign)| sign * slope(reflect(y, h), xx, 0))
    });
    let down = Array2::from_shape_fn((2 * h, 2 * w), |(y, x)| {
        mirrored(y, h).map_or(0.0, |(yy, sign)| sign * slope(yy, reflect(x, w), 1))
    });
    let full = integrate_on_torus(&right, &down);
    let heights = full.slice(s![..h, ..w]).to_owned();
    let min = heights.iter().copied().fold(f64::INFINITY, f64::min);
    heights.mapv(|v| v - min)
}

/// The zero-mean periodic field whose forward differences best match `right` (sample to its
/// right neighbour) and `down` (sample to the one below) in least squares, both wrapping
/// around the torus: the discrete Poisson equation, diagonal in the DFT. A consistent pair of
/// differences gives its field back exactly; an inconsistent one (joins of patches that do not
/// quite fit) has its mismatch spread smoothly instead of left as steps.
///
/// # Panics
/// Shapes that differ.
pub fn integrate_on_torus(right: &Array2<f64>, down: &Array2<f64>) -> Array2<f64> {
    solve_on_torus(fft::forward(right), fft::forward(down), |_| 1.0).mapv(|c| c.re)
}

/// [`integrate_on_torus`] less the result's Gaussian blur of standard deviation `sigma`
/// samples (wrapping around): only the detail finer than about `sigma`, the blur applied in the
/// same DFT as the integration (the transfer `1 - exp(-2 pi^2 sigma^2 |f|^2)`, `f` in cycles a
/// sample) instead of as a separate convolution.
///
/// # Panics
/// Shapes that differ.
pub fn integrate_detail_on_torus(
    right: &Array2<f64>,
    down: &Array2<f64>,
    sigma: f64,
) -> Array2<f64> {
    solve_on_torus(fft::forward(right), fft::forward(down), detail_gain(sigma)).mapv(|c| c.re)
}

/// The transfer that keeps the detail finer than a Gaussian of standard deviation `sigma`.
fn detail_gain(sigma: f64) -> impl Fn(f64) -> f64 {
    let k = -2.0 * std::f64::consts::PI.powi(2) * sigma * sigma;
    move |f2| 1.0 - (k * f2).exp()
}

/// The Poisson solve of [`integrate_on_torus`] from the DFTs `fx`, `fy` of the differences to
/// the right and downward (of one real field, or of two packed as real and imaginary parts),
/// each frequency's result multiplied by `gain(|f|^2)` (`f` in cycles a sample, folded into
/// -1/2..1/2 on each axis).
fn solve_on_torus(
    fx: Array2<Complex64>,
    fy: Array2<Complex64>,
    gain: impl Fn(f64) -> f64,
) -> Array2<Complex64> {
    assert_eq!(fx.dim(), fy.dim(), "difference planes of one shape");
    let (h, w) = fx.dim();
    if h == 0 || w == 0 {
        return Array2::zeros((h, w));
    }
    let tau = 2.0 * std::f64::consts::PI;
    // Per axis and bin k of n: the DFT of a forward difference, e^(i tau k / n) - 1, and the
    // squared frequency folded into -1/2..1/2 cycles a sample.
    let axis = |n: usize| -> Vec<(Complex64, f64)> {
        (0..n)
            .map(|k| {
                let f = k as f64 / n as f64;
                let folded = if f > 0.5 { f - 1.0 } else { f };
                (Complex64::from_polar(1.0, tau * f) - 1.0, folded * folded)
            })
            .collect()
    };
    let (rows, cols) = (axis(h), axis(w));
    let spectrum = Array2::from_shape_fn((h, w), |(kr, kc)| {
        let ((dy, fy2), (dx, fx2)) = (rows[kr], cols[kc]);
        let denom = dx.norm_sqr() + dy.norm_sqr();
        if denom < 1e-12 {
            Complex64::new(0.0, 0.0)
        } else {
            (dx.conj() * fx[[kr, kc]] + dy.conj() * fy[[kr, kc]]) * (gain(fy2 + fx2) / denom)
        }
    });
    fft::inverse(&spectrum)
}

/// Unit normals of a height field by forward differences (x right, y up; a sample's slope is
/// the step to its right and lower neighbours, zero past the last column and row), shape
/// (3, rows, cols): the derivative [`frankot_chellappa`] inverts.
pub fn normals_of(heights: &Array2<f64>) -> Array3<f64> {
    normals(heights, Edges::Clamp)
}

/// Unit normals of a periodic height field (forward differences wrapping around the borders).
pub fn normals_of_periodic(heights: &Array2<f64>) -> Array3<f64> {
    normals(heights, Edges::Wrap)
}

/// How differences treat the borders of a height field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edges {
    /// Edge samples repeated ([`normals_of`]).
    Clamp,
    /// The field wraps around ([`normals_of_periodic`]).
    Wrap,
}

impl Edges {
    pub(crate) fn index(self, i: isize, n: usize) -> usize {
        match self {
            Edges::Clamp => i.clamp(0, n as isize - 1) as usize,
            Edges::Wrap => i.rem_euclid(n as isize) as usize,
        }
    }
}

fn normals(heights: &Array2<f64>, border: Edges) -> Array3<f64> {
    let (h, w) = heights.dim();
    let interleaved = map_normals(heights, border, |n| n);
    Array3::from_shape_vec((h, w, 3), interleaved.concat())
        .expect("rows x cols x 3 values")
        .permuted_axes([2, 0, 1])
        .as_standard_layout()
        .into_owned()
}

/// `max(0, n . l)` for the unit normals `n` of a height field (as [`normals_of`] or
/// [`normals_of_periodic`] make them) and the unit light vector `l`, without storing the
/// normals; shape (rows, cols).
pub fn shading(heights: &Array2<f64>, border: Edges, l: [f64; 3]) -> Array2<f64> {
    let values = map_normals(heights, border, |n| {
        (n[0] * l[0] + n[1] * l[1] + n[2] * l[2]).max(0.0)
    });
    Array2::from_shape_vec(heights.dim(), values).expect("rows x cols values")
}

/// `f` of the unit normal at every sample, in raster order, rows in parallel.
fn map_normals<T: Send + Copy + Default>(
    heights: &Array2<f64>,
    border: Edges,
    f: impl Fn([f64; 3]) -> T + Sync,
) -> Vec<T> {
    let (h, w) = heights.dim();
    // Right-hand neighbour columns, shared by every row.
    let right: Vec<usize> = (0..w as isize).map(|x| border.index(x + 1, w)).collect();
    let mut out = vec![T::default(); h * w];
    if w == 0 {
        return out;
    }
    out.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let (row, down) = (heights.row(y), heights.row(border.index(y as isize + 1, h)));
        for ((x, &right), o) in right.iter().enumerate().zip(out) {
            let dx = row[right] - row[x];
            let dr = down[x] - row[x];
            // y is up: dh/dy = -dh/drow.
            let len = (dx * dx + dr * dr + 1.0).sqrt();
            *o = f([-dx / len, dr / len, 1.0 / len]);
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::correlation;

    #[test]
    fn a_smooth_bump_is_recovered_from_its_normals() {
        let (h, w) = (48, 40);
        let truth = Array2::from_shape_fn((h, w), |(y, x)| {
            let (dy, dx) = (y as f64 - 20.0, x as f64 - 22.0);
            6.0 * (-(dx * dx + dy * dy) / 60.0).exp() + 0.05 * x as f64
        });
        let est = frankot_chellappa(&normals_of(&truth));
        let c = correlation(&est, &truth);
        assert!(c > 0.98, "correlation {c}");
        // The sign is right: the peak stays a peak.
        let peak = est[[20, 22]];
        assert!(peak > est[[2, 2]] + 3.0, "{peak}");
    }

    #[test]
    fn a_relief_with_one_texel_walls_comes_back_exactly() {
        // Plateaus 20 texels apart in height, joined by one-texel walls (stones and their
        // grout), a wall that ends inside the image, and a gentle slope. The band-limited
        // derivative rang beside every wall (a 2-3 texel ripple that grazing light turned
        // into hatching) and central-difference normals blurred each wall over two texels.
        let (h, w) = (40, 48);
        let truth = Array2::from_shape_fn((h, w), |(y, x)| {
            let cell = ((x / 12) + 2 * (y / 10)) % 3;
            let wall = if (10..30).contains(&y) && x > 30 {
                5.0
            } else {
                0.0
            };
            20.0 * cell as f64 + wall + 0.1 * x as f64
        });
        let est = frankot_chellappa(&normals_of(&truth));
        let min = truth.iter().copied().fold(f64::INFINITY, f64::min);
        let worst = est
            .iter()
            .zip(&truth)
            .map(|(e, t)| (e - (t - min)).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "largest height error {worst} texels");
    }

    #[test]
    fn torus_integration_inverts_forward_differences() {
        let (h, w) = (12, 17);
        let field = Array2::from_shape_fn((h, w), |(y, x)| {
            ((y * 7 + x * 3) % 11) as f64 + (0.3 * x as f64).sin()
        });
        let right = Array2::from_shape_fn((h, w), |(y, x)| field[[y, (x + 1) % w]] - field[[y, x]]);
        let down = Array2::from_shape_fn((h, w), |(y, x)| field[[(y + 1) % h, x]] - field[[y, x]]);
        let back = integrate_on_torus(&right, &down);
        let mean = field.mean().unwrap();
        for (a, b) in back.iter().zip(&field) {
            assert!((a - (b - mean)).abs() < 1e-9, "{a} vs {}", b - mean);
        }
        // One inconsistent difference (a step that does not close around the torus) is
        // spread: no single step of the result carries it.
        let mut bad = right.clone();
        bad[[5, 8]] += 6.0;
        let spread = integrate_on_torus(&bad, &down);
        let worst = (0..h)
            .flat_map(|y| (0..w).map(move |x| (y, x)))
            .map(|(y, x)| (spread[[y, (x + 1) % w]] - spread[[y, x]] - right[[y, x]]).abs())
            .fold(0.0, f64::max);
        assert!(worst < 3.0, "{worst}");
    }

    #[test]
    fn flat_normals_give_a_flat_map() {
        let mut n = Array3::zeros((3, 8, 8));
        n.slice_mut(s![2, .., ..]).fill(1.0);
        assert!(frankot_chellappa(&n).iter().all(|v| v.abs() < 1e-9));
    }
}
