//! Parallax and masking: the relief seen from an oblique view, the view's counterpart of the
//! cast shadows in [`super::relight`].
//!
//! A BTF image is rectified onto the sample's plane, so from an oblique view the texel at `x`
//! shows the first surface point that the view ray through `x` (at the relief's mean height)
//! meets, not the point below `x`. Bump mapping alone shows every texel's own point: slopes
//! turned away from the camera stay in view, and near the light's direction (the hot spot)
//! the shadows do too, where the measured image has them hidden behind the bumps. Relit
//! texture-space images are warped to what the view sees ([`ViewWarp`]).

use ndarray::{Array2, Array3, Axis};
use rayon::prelude::*;

use super::integrate::Edges;

/// Length of one march step along the view ray, texels (horizontal).
const VIEW_STEP: f64 = 0.5;
/// Bisection steps refining a hit between two march steps (to 1/128 texel).
const REFINE_STEPS: usize = 6;
/// The longest stretch of a view ray marched, texels (horizontal): a grazing view over a tall
/// relief is cut short, as [`super::relight::MAX_SHADOW_STEPS`] cuts shadow rays.
pub const MAX_VIEW_SPAN: f64 = 256.0;

/// Where each texel of an image seen from one view looks on the relief: fractional (row,
/// col) of the surface point its view ray meets first.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewWarp {
    rows: usize,
    cols: usize,
    border: Edges,
    /// Row-major, one (row, col) per texel.
    points: Vec<[f64; 2]>,
}

/// The bilinearly interpolated value at fractional (`r`, `c`) of a `rows` x `cols` field read
/// by `at(row, col)`, borders as `border` says.
pub(crate) fn bilinear(
    (rows, cols): (usize, usize),
    border: Edges,
    r: f64,
    c: f64,
    at: impl Fn(usize, usize) -> f64,
) -> f64 {
    let (r0, c0) = (r.floor(), c.floor());
    let (fr, fc) = (r - r0, c - c0);
    let (r0, c0) = (r0 as isize, c0 as isize);
    let (ra, rb) = (border.index(r0, rows), border.index(r0 + 1, rows));
    let (ca, cb) = (border.index(c0, cols), border.index(c0 + 1, cols));
    (at(ra, ca) * (1.0 - fc) + at(ra, cb) * fc) * (1.0 - fr)
        + (at(rb, ca) * (1.0 - fc) + at(rb, cb) * fc) * fr
}

/// The highest and the lowest of `heights` (texels): where a view ray starts and where it
/// must have met the relief (infinite for an empty field).
pub fn height_span(heights: &Array2<f64>) -> (f64, f64) {
    heights
        .iter()
        .fold((f64::NEG_INFINITY, f64::INFINITY), |(t, b), &h| {
            (t.max(h), b.min(h))
        })
}

/// The warp of `heights` (texels, borders as `border` says) seen from the unit view `v`
/// (x right, y up, z out of the surface); `None` for a frontal view (nothing moves), a view
/// at or below the horizon, or an empty field.
///
/// Each texel's ray starts where it is as high as the highest height, and steps of
/// [`VIEW_STEP`] texels go down it until the bilinear heights reach it; the hit is refined by
/// bisection. A ray that meets nothing ends at the lowest height.
pub fn view_warp(heights: &Array2<f64>, border: Edges, v: [f64; 3]) -> Option<ViewWarp> {
    let horizontal = v[0].hypot(v[1]);
    if v[2] <= 0.0 || horizontal < 1e-6 || heights.is_empty() {
        return None;
    }
    let (rows, cols) = heights.dim();
    let (top, bottom) = height_span(heights);
    let reference = heights.mean()?;
    // Per texel towards the camera: columns right, rows down (y is up), height gained.
    let (dc, dr, rise) = (v[0] / horizontal, -v[1] / horizontal, v[2] / horizontal);
    let first = ((top - reference) / rise).min(MAX_VIEW_SPAN);
    let last = ((bottom - reference) / rise).max(-MAX_VIEW_SPAN);
    let height = |r: f64, c: f64| bilinear((rows, cols), border, r, c, |i, j| heights[[i, j]]);
    let mut points = vec![[0.0; 2]; rows * cols];
    points
        .par_chunks_mut(cols)
        .enumerate()
        .for_each(|(row, out)| {
            for (col, point) in out.iter_mut().enumerate() {
                let at = |s: f64| [row as f64 + s * dr, col as f64 + s * dc];
                let below = |s: f64| {
                    let [r, c] = at(s);
                    height(r, c) >= reference + s * rise
                };
                let (mut above, mut s) = (first, first);
                let hit = loop {
                    if below(s) {
                        break s;
                    }
                    if s <= last {
                        break last;
                    }
                    above = s;
                    s = (s - VIEW_STEP).max(last);
                };
                // The surface lies between `above` (ray over it) and `hit` (under it).
                let (mut lo, mut hi) = (hit, above);
                for _ in 0..REFINE_STEPS {
                    let mid = 0.5 * (lo + hi);
                    if below(mid) {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                *point = at(lo);
            }
        });
    Some(ViewWarp {
        rows,
        cols,
        border,
        points,
    })
}

impl ViewWarp {
    /// `image` (planar `(3, rows, cols)`, registered with the heights) as the view sees it:
    /// each texel takes the bilinear value at its surface point.
    pub fn apply(&self, image: &Array3<f32>) -> Array3<f32> {
        let mut out = Array3::zeros(image.raw_dim());
        let size = (self.rows, self.cols);
        out.axis_iter_mut(Axis(0))
            .into_par_iter()
            .zip(image.axis_iter(Axis(0)))
            .for_each(|(mut o, plane)| {
                for (v, &[r, c]) in o.iter_mut().zip(&self.points) {
                    *v = bilinear(size, self.border, r, c, |i, j| f64::from(plane[[i, j]])) as f32;
                }
            });
        out
    }

    /// How much of the seen image each texel of the relief fills (the bilinear weights of all
    /// the texels' surface points, summed): mean 1; the mean of a warped field is the mean of
    /// the field times this.
    pub fn coverage(&self) -> Array2<f64> {
        let mut cover = Array2::zeros((self.rows, self.cols));
        for &[r, c] in &self.points {
            let (r0, c0) = (r.floor(), c.floor());
            let (fr, fc) = (r - r0, c - c0);
            let (r0, c0) = (r0 as isize, c0 as isize);
            for (dr, wr) in [(0, 1.0 - fr), (1, fr)] {
                for (dc, wc) in [(0, 1.0 - fc), (1, fc)] {
                    let i = self.border.index(r0 + dr, self.rows);
                    let j = self.border.index(c0 + dc, self.cols);
                    cover[[i, j]] += wr * wc;
                }
            }
        }
        cover
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat field moves nothing: every texel sees its own point.
    #[test]
    fn a_flat_relief_is_seen_where_it_lies() {
        let heights = Array2::from_elem((8, 10), 2.0);
        let warp = view_warp(&heights, Edges::Clamp, [0.6, 0.0, 0.8]).unwrap();
        for (i, &[r, c]) in warp.points.iter().enumerate() {
            assert!((r - (i / 10) as f64).abs() < 1e-9 && (c - (i % 10) as f64).abs() < 1e-2);
        }
        assert!(view_warp(&heights, Edges::Clamp, [0.0, 0.0, 1.0]).is_none());
    }

    /// A plateau of height 2 (columns 10-19) on a floor of 0 (mean 0.5), seen from 45 degrees
    /// with the camera towards +x: a texel's ray rises one texel per texel towards the camera
    /// from height 0.5, so the top is seen 1.5 texels towards the camera and the floor 0.5
    /// texel away from it; the floor just behind the plateau (columns 8-10) is hidden, and
    /// the wall facing the camera (columns 19-20) fills more texels than its width.
    #[test]
    fn a_plateau_hides_the_floor_behind_it_and_shows_its_front_wall_wide() {
        let (rows, cols) = (4, 40);
        let heights = Array2::from_shape_fn((rows, cols), |(_, c)| {
            if (10..20).contains(&c) { 2.0f64 } else { 0.0 }
        });
        assert!((heights.mean().unwrap() - 0.5).abs() < 1e-12);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let warp = view_warp(&heights, Edges::Wrap, [s, 0.0, s]).unwrap();
        let seen = |c: usize| warp.points[cols + c][1];
        let near = |a: f64, b: f64| (a - b).abs() < 0.02;
        assert!(near(seen(12), 13.5), "{}", seen(12));
        assert!(near(seen(30), 29.5), "{}", seen(30));
        // Texel 8 sees the floor, texel 9 already the top: the floor in between is hidden.
        assert!(
            near(seen(8), 7.5) && near(seen(9), 10.5),
            "{} {}",
            seen(8),
            seen(9)
        );
        // The front wall: rays meet it at 19 + 1/6, 19.5 and 20 - 1/6.
        for (c, x) in [(18, 19.0 + 1.0 / 6.0), (19, 19.5), (20, 20.0 - 1.0 / 6.0)] {
            assert!(near(seen(c), x), "{c}: {}", seen(c));
        }
        let cover = warp.coverage();
        assert!((cover.mean().unwrap() - 1.0).abs() < 1e-9);
        assert_eq!(cover[[1, 9]], 0.0);
        assert!(cover[[1, 19]] > 1.5, "{}", cover[[1, 19]]);
    }

    #[test]
    fn warping_a_flat_image_keeps_it_and_follows_the_points() {
        let heights = Array2::from_shape_fn((6, 6), |(r, c)| ((r * 7 + c * 3) % 5) as f64);
        let warp = view_warp(&heights, Edges::Clamp, [0.5, 0.5, 0.707]).unwrap();
        let flat = Array3::from_elem((3, 6, 6), 0.25f32);
        assert!(warp.apply(&flat).iter().all(|&v| (v - 0.25).abs() < 1e-6));
        let ramp = Array3::from_shape_fn((3, 6, 6), |(_, _, c)| c as f32);
        let seen = warp.apply(&ramp);
        for (i, &[_, c]) in warp.points.iter().enumerate() {
            let expect = c.clamp(0.0, 5.0);
            assert!((f64::from(seen[[0, i / 6, i % 6]]) - expect).abs() < 1e-4);
        }
    }
}
