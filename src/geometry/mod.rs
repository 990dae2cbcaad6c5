//! Surface geometry: normals by photometric stereo, the range map (height field) they
//! integrate to, its seamless enlargement, and the bump shading it gives under a light.

pub mod cells;
pub mod integrate;
pub mod lattice;
pub mod parallax;
pub mod photometric_stereo;
pub mod quilt;
pub mod relight;

pub use integrate::{frankot_chellappa, integrate_on_torus, normals_of};
pub use photometric_stereo::{NormalMap, estimate_normals, frontal_view};
pub use quilt::{
    CoarseScan, Phase, Placement, QuiltedRelief, coarse_part, detail_scale, patch_side, quilt,
    quilt_laid, quilt_placement, resample_periodic, split_detail,
};

use ndarray::Array2;

/// Averages a height field down by an integer `step` (blocks of step x step; partial blocks at
/// the border average what they hold). Heights keep their units.
pub fn downsample(heights: &Array2<f64>, step: usize) -> Array2<f64> {
    let step = step.max(1);
    let (h, w) = heights.dim();
    let (rows, cols) = (h.div_ceil(step), w.div_ceil(step));
    Array2::from_shape_fn((rows, cols), |(r, c)| {
        let block = heights.slice(ndarray::s![
            r * step..((r + 1) * step).min(h),
            c * step..((c + 1) * step).min(w)
        ]);
        block.sum() / block.len() as f64
    })
}
