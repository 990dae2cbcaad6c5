//! Gaussian-Laplacian pyramid (Burt and Adelson 1983), the survey's spatial factorisation of a
//! subspace image into band-limited factors (seed 001, sec. 5.3.1; mrf_math.md 1(d)).
//!
//! REDUCE blurs with the separable 5-tap kernel `[0.05, 0.25, 0.4, 0.25, 0.05]` (a = 0.4) and
//! keeps every other sample (sizes `ceil(n / 2)`, not necessarily powers of two); EXPAND inserts
//! zeros up to an explicit target size and blurs with twice the kernel. Band k is
//! `G_k - EXPAND(G_{k+1})` and the last band is the coarsest Gaussian level, so collapsing is
//! exact by construction. Borders are mirrored (without repeating the edge sample).

use ndarray::{Array2, Axis};
use rayon::prelude::*;

/// The generating kernel, a = 0.4.
const KERNEL: [f64; 5] = [0.05, 0.25, 0.4, 0.25, 0.05];

/// Mirror an index into [0, n) without repeating the edge: -1 -> 1, n -> n - 2.
fn mirror(i: isize, n: usize) -> usize {
    let n = n as isize;
    if n == 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    let m = i.rem_euclid(period);
    (if m < n { m } else { period - m }) as usize
}

/// How samples beyond the border are found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Border {
    /// Mirrored (measured images, which do not wrap).
    Mirror,
    /// Wrapped around (tileable synthesis).
    Periodic,
}

impl Border {
    fn index(self, i: isize, n: usize) -> usize {
        match self {
            Border::Mirror => mirror(i, n),
            Border::Periodic => i.rem_euclid(n as isize) as usize,
        }
    }
}

/// A 1D linear map as, for each output index, its (input index, weight) taps. Building it once
/// per axis keeps the border logic out of the per-pixel loops.
pub(crate) type Taps = Vec<Vec<(usize, f64)>>;

/// Taps of the blur along an axis of length `n`.
fn blur_taps(n: usize, border: Border) -> Taps {
    (0..n)
        .map(|i| {
            KERNEL
                .iter()
                .enumerate()
                .map(|(k, &w)| (border.index(i as isize + k as isize - 2, n), w))
                .collect()
        })
        .collect()
}

/// Taps of EXPAND from `n_in` samples to `target`: zero insertion, then twice the kernel.
fn expand_taps(n_in: usize, target: usize, border: Border) -> Taps {
    (0..target)
        .map(|i| {
            let mut taps: Vec<(usize, f64)> = Vec::with_capacity(3);
            for (k, &w) in KERNEL.iter().enumerate() {
                let j = border.index(i as isize + k as isize - 2, target);
                if j.is_multiple_of(2) && j / 2 < n_in {
                    match taps.iter_mut().find(|t| t.0 == j / 2) {
                        Some(t) => t.1 += 2.0 * w,
                        None => taps.push((j / 2, 2.0 * w)),
                    }
                }
            }
            taps
        })
        .collect()
}

/// Applies taps along rows (each output row a weighted sum of whole input rows, so the inner
/// loop runs over contiguous memory) and then along columns; output rows in parallel (each
/// computed alone, so the values do not depend on the threads).
pub(crate) fn apply_separable(
    input: &Array2<f64>,
    row_taps: &Taps,
    col_taps: &Taps,
) -> Array2<f64> {
    let cols_in = input.ncols();
    let mut tmp = Array2::<f64>::zeros((row_taps.len(), cols_in));
    tmp.axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(row_taps)
        .with_min_len(MIN_PARALLEL_ROWS)
        .for_each(|(mut out_row, taps)| {
            for &(j, w) in taps {
                out_row.scaled_add(w, &input.row(j));
            }
        });
    // The column taps flattened once (start offsets, then index/weight pairs), so the
    // per-pixel loop reads contiguous memory instead of one small vector per output column.
    let mut starts = Vec::with_capacity(col_taps.len() + 1);
    let mut flat: Vec<(usize, f64)> = Vec::new();
    for taps in col_taps {
        starts.push(flat.len());
        flat.extend_from_slice(taps);
    }
    starts.push(flat.len());
    let mut out = Array2::<f64>::zeros((row_taps.len(), col_taps.len()));
    out.axis_iter_mut(Axis(0))
        .into_par_iter()
        .zip(tmp.axis_iter(Axis(0)))
        .with_min_len(MIN_PARALLEL_ROWS)
        .for_each(|(mut dst, src)| {
            let src = src.as_slice().expect("standard layout");
            let dst = dst.as_slice_mut().expect("standard layout");
            for (d, span) in dst.iter_mut().zip(starts.windows(2)) {
                // Unrolled for the common tap counts (2 and 3 when expanding, 2 when resampling).
                *d = match flat[span[0]..span[1]] {
                    [(a, wa), (b, wb)] => wa * src[a] + wb * src[b],
                    [(a, wa), (b, wb), (c, wc)] => wa * src[a] + wb * src[b] + wc * src[c],
                    ref taps => taps.iter().map(|&(j, w)| w * src[j]).sum(),
                };
            }
        });
    out
}

/// Fewest rows [`apply_separable`] hands a thread at once: a small level is not split into
/// tasks that cost more to schedule than to run.
const MIN_PARALLEL_ROWS: usize = 32;

/// REDUCE: blur and keep every other row and column; shape `(ceil(h/2), ceil(w/2))`, mirrored
/// borders.
pub fn reduce(image: &Array2<f64>) -> Array2<f64> {
    reduce_with(image, Border::Mirror)
}

/// REDUCE with a chosen border rule.
fn reduce_with(image: &Array2<f64>, border: Border) -> Array2<f64> {
    let (rows, cols) = image.dim();
    // Only every other output sample is kept, so only those taps are built.
    let keep = |taps: Taps| taps.into_iter().step_by(2).collect::<Taps>();
    apply_separable(
        image,
        &keep(blur_taps(rows, border)),
        &keep(blur_taps(cols, border)),
    )
}

/// EXPAND to an explicit `(rows, cols)` (the size of the finer level), mirrored borders.
pub fn expand(image: &Array2<f64>, rows: usize, cols: usize) -> Array2<f64> {
    expand_with(image, rows, cols, Border::Mirror)
}

/// EXPAND with a chosen border rule.
pub fn expand_with(image: &Array2<f64>, rows: usize, cols: usize, border: Border) -> Array2<f64> {
    let (r_in, c_in) = image.dim();
    apply_separable(
        image,
        &expand_taps(r_in, rows, border),
        &expand_taps(c_in, cols, border),
    )
}

/// The standard deviation of `plane`'s values, in two passes (the mean, then the squared
/// deviations) that the compiler vectorises: ndarray's one-pass `std` updates a running mean
/// per value and took about 5 % of a 1024^2 synthesis's processor time.
pub fn spread(plane: &Array2<f64>) -> f64 {
    let n = plane.len();
    if n == 0 {
        return 0.0;
    }
    let mean = plane.sum() / n as f64;
    let squares = plane.fold(0.0, |acc, &v| acc + (v - mean) * (v - mean));
    (squares / n as f64).sqrt()
}

/// The most pyramid levels `(rows, cols)` halves exactly for (a tileable plane's bands wrap
/// around only then), capped at `cap`.
pub fn exact_levels(rows: usize, cols: usize, cap: usize) -> usize {
    let mut levels = 1;
    let (mut r, mut c) = (rows, cols);
    while levels < cap && r.is_multiple_of(2) && c.is_multiple_of(2) && r >= 2 && c >= 2 {
        (r, c) = (r / 2, c / 2);
        levels += 1;
    }
    levels
}

/// The [`spread`] of the first `bands` detail bands of `plane`'s Laplacian pyramid (of
/// `bands + 1` levels, mirrored borders), finest first; fewer where the plane halves fewer
/// times.
pub fn detail_spreads(plane: &Array2<f64>, bands: usize) -> Vec<f64> {
    let pyramid = Pyramid::decompose(plane, bands + 1);
    let details = pyramid.bands.len() - 1;
    pyramid.bands[..details].iter().map(spread).collect()
}

/// A Laplacian pyramid: band 0 is the finest, the last band the coarse Gaussian residual.
#[derive(Debug, Clone, PartialEq)]
pub struct Pyramid {
    /// The bands, finest first; band k has shape about `(h / 2^k, w / 2^k)`.
    pub bands: Vec<Array2<f64>>,
}

impl Pyramid {
    /// Splits `image` into `levels` bands (at least 1; fewer if the image gets smaller than
    /// 2x2 first).
    pub fn decompose(image: &Array2<f64>, levels: usize) -> Self {
        Self::decompose_with(image, levels, Border::Mirror)
    }

    /// Splits with a chosen border rule: [`Border::Periodic`] for a tileable image (of even
    /// sizes down the pyramid), whose bands then wrap around like it.
    pub fn decompose_with(image: &Array2<f64>, levels: usize, border: Border) -> Self {
        let mut bands = Vec::with_capacity(levels);
        let mut current = image.clone();
        for _ in 1..levels.max(1) {
            if current.nrows() < 2 || current.ncols() < 2 {
                break;
            }
            let coarse = reduce_with(&current, border);
            let up = expand_with(&coarse, current.nrows(), current.ncols(), border);
            bands.push(&current - &up);
            current = coarse;
        }
        bands.push(current);
        Self { bands }
    }

    /// Sums the bands back into one image: the inverse of [`Pyramid::decompose`] (exact up to
    /// rounding). Bands may be synthesized ones, of any consistent sizes.
    pub fn collapse(&self) -> Array2<f64> {
        self.collapse_with(Border::Mirror)
    }

    /// Collapses with a chosen border rule: [`Border::Periodic`] keeps tileable bands (of even
    /// sizes down the pyramid) tileable.
    pub fn collapse_with(&self, border: Border) -> Array2<f64> {
        let mut iter = self.bands.iter().rev();
        let mut current = iter
            .next()
            .cloned()
            .unwrap_or_else(|| Array2::zeros((0, 0)));
        for band in iter {
            let mut up = expand_with(&current, band.nrows(), band.ncols(), border);
            up += band;
            current = up;
        }
        current
    }

    /// Band shapes for an image of `rows` x `cols` with `levels` levels.
    pub fn shapes(rows: usize, cols: usize, levels: usize) -> Vec<(usize, usize)> {
        let mut shapes = vec![(rows, cols)];
        while shapes.len() < levels.max(1) {
            let (r, c) = shapes[shapes.len() - 1];
            if r < 2 || c < 2 {
                break;
            }
            shapes.push((r.div_ceil(2), c.div_ceil(2)));
        }
        shapes
    }
}

/// The size step of a pyramid of `levels` levels, `2^(levels - 1)` (1 for zero levels): the
/// coarsest band's pixel covers that many pixels a side, so an image needs at least this side
/// for every level to keep a pixel, and a multiple of it to halve exactly at every level (a
/// tileable synthesis). The one place this rule is written. (Models have at most 16 levels;
/// the shift is capped only so that no argument overflows it.)
pub fn pyramid_step(levels: usize) -> usize {
    1 << levels.saturating_sub(1).min(usize::BITS as usize - 2)
}

/// A sensible number of levels: the coarsest band keeps at least `min_side` pixels a side.
pub fn auto_levels(rows: usize, cols: usize, min_side: usize, max_levels: usize) -> usize {
    let mut levels = 1;
    let (mut r, mut c) = (rows, cols);
    while levels < max_levels && r.div_ceil(2) >= min_side && c.div_ceil(2) >= min_side {
        r = r.div_ceil(2);
        c = c.div_ceil(2);
        levels += 1;
    }
    levels
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pyramid_step_halves_once_per_level_below_the_finest() {
        assert_eq!(pyramid_step(0), 1);
        assert_eq!(pyramid_step(1), 1);
        assert_eq!(pyramid_step(4), 8);
        // Each level of a side that is a multiple of the step halves exactly.
        assert_eq!(Pyramid::shapes(40, 24, 4).last(), Some(&(5, 3)));
        assert_eq!(pyramid_step(usize::MAX), 1 << (usize::BITS - 2));
    }

    fn field(h: usize, w: usize) -> Array2<f64> {
        Array2::from_shape_fn((h, w), |(i, j)| {
            ((i * 7 + j * 13) % 17) as f64 + (i as f64 * 0.3).sin()
        })
    }

    #[test]
    fn collapse_is_exact_for_odd_and_even_sizes() {
        for (h, w, levels) in [(64, 64, 4), (37, 50, 3), (5, 3, 5), (1, 9, 3), (2, 2, 2)] {
            let x = field(h, w);
            let p = Pyramid::decompose(&x, levels);
            let shapes: Vec<_> = p.bands.iter().map(|b| b.dim()).collect();
            assert_eq!(
                shapes,
                Pyramid::shapes(h, w, levels)[..shapes.len()].to_vec()
            );
            let back = p.collapse();
            let err = (&back - &x).mapv(f64::abs).fold(0.0f64, |m, &v| m.max(v));
            assert!(err < 1e-12, "{h}x{w}: {err}");
        }
    }

    #[test]
    fn a_periodic_pyramid_shifts_with_its_image() {
        // On a torus whose sides halve at every level, shifting the image by a multiple of the
        // coarsest step shifts every band by its share: no band knows where the edges are.
        let (h, w, levels) = (32, 48, 4);
        let x = field(h, w);
        let shifted = Array2::from_shape_fn((h, w), |(i, j)| x[((i + 8) % h, (j + 16) % w)]);
        let (p, q) = (
            Pyramid::decompose_with(&x, levels, Border::Periodic),
            Pyramid::decompose_with(&shifted, levels, Border::Periodic),
        );
        for (k, (a, b)) in p.bands.iter().zip(&q.bands).enumerate() {
            let (bh, bw) = a.dim();
            let (di, dj) = (8 >> k, 16 >> k);
            let err = Array2::from_shape_fn((bh, bw), |(i, j)| {
                (a[((i + di) % bh, (j + dj) % bw)] - b[(i, j)]).abs()
            })
            .fold(0.0f64, |m, &v| m.max(v));
            assert!(err < 1e-12, "band {k}: {err}");
        }
        let back = p.collapse_with(Border::Periodic);
        assert!((&back - &x).mapv(f64::abs).fold(0.0f64, |m, &v| m.max(v)) < 1e-12);
        // Mirrored borders do know: the same shift changes the finest band near the edges.
        let (m, n) = (
            Pyramid::decompose(&x, levels),
            Pyramid::decompose(&shifted, levels),
        );
        assert!((m.bands[0][(0, 0)] - n.bands[0][(h - 8, w - 16)]).abs() > 1e-6);
    }

    #[test]
    fn kernel_preserves_constants() {
        let c = Array2::from_elem((9, 12), 3.5);
        let r = reduce(&c);
        assert!(r.iter().all(|v| (v - 3.5).abs() < 1e-12));
        let e = expand(&r, 9, 12);
        assert!(e.iter().all(|v| (v - 3.5).abs() < 1e-12), "{e:?}");
        // A constant image has all its energy in the last band.
        let p = Pyramid::decompose(&c, 3);
        assert!(p.bands[0].iter().all(|v| v.abs() < 1e-12));
    }

    #[test]
    fn auto_levels_keeps_the_coarsest_band_large_enough() {
        assert_eq!(auto_levels(128, 128, 16, 8), 4);
        assert_eq!(auto_levels(64, 64, 16, 8), 3);
        assert_eq!(auto_levels(10, 10, 16, 8), 1);
        assert_eq!(auto_levels(1024, 1024, 16, 4), 4);
    }
}
