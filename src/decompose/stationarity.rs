//! A check that an image looks like a stationary texture, the assumption behind every MRF
//! model here: the same statistics everywhere. An object on a background, a painting or a
//! relief with one large motif is not one, and enlarging it repeats its content as wallpaper.
//!
//! The measure is the share of the luminance variance held by the means of a 4 x 4 grid of
//! blocks. In a stationary texture whose features are small against a block, block means
//! differ little (a few % of the variance); where the content changes across the image (a
//! bright object on a dark ground, a shading gradient over a relief) they carry much of it.
//! Measured on the shared data: the three texture photographs 0.1-1 % whole and 1-10 % for
//! 128^2 crops; the five RTI captures of objects 8-86 % per light, medians 18-60 %.

use ndarray::{Array2, Array3};

/// Blocks per side of the grid.
const GRID: usize = 4;

/// Share above which [`block_mean_share`] calls an image non-stationary: above the textures
/// measured (at most 10 %), below the objects' medians (at least 18 %).
pub const NON_STATIONARY_SHARE: f64 = 0.15;

/// Share of the luminance variance of a `(3, h, w)` linear RGB image held by the means of a
/// 4 x 4 grid of equal blocks (the last rows and columns that do not fill a block are left
/// out), in [0, 1]; 0 for an image under 4 pixels a side or a flat one.
pub fn block_mean_share(image: &Array3<f32>) -> f64 {
    let (_, h, w) = image.dim();
    let (bh, bw) = (h / GRID, w / GRID);
    if bh == 0 || bw == 0 {
        return 0.0;
    }
    let luminance = Array2::from_shape_fn((bh * GRID, bw * GRID), |(r, c)| {
        0.2126 * f64::from(image[[0, r, c]])
            + 0.7152 * f64::from(image[[1, r, c]])
            + 0.0722 * f64::from(image[[2, r, c]])
    });
    let n = luminance.len() as f64;
    let mean = luminance.sum() / n;
    let total = luminance.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let mut between = 0.0;
    for i in 0..GRID {
        for j in 0..GRID {
            let block = luminance.slice(ndarray::s![i * bh..(i + 1) * bh, j * bw..(j + 1) * bw]);
            let m = block.sum() / block.len() as f64;
            between += (m - mean).powi(2);
        }
    }
    let between = between / (GRID * GRID) as f64;
    if total > 1e-20 {
        (between / total).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(h: usize, w: usize, f: impl Fn(usize, usize) -> f32) -> Array3<f32> {
        Array3::from_shape_fn((3, h, w), |(_, r, c)| f(r, c))
    }

    #[test]
    fn a_fine_periodic_texture_is_stationary_and_a_bright_object_is_not() {
        // A checkerboard of 2-pixel cells: every block has the same mean.
        let fine = grey(
            64,
            64,
            |r, c| if (r / 2 + c / 2) % 2 == 0 { 0.2 } else { 0.8 },
        );
        assert!(block_mean_share(&fine) < 1e-12);
        // A bright disc on a dark ground: the block means carry most of the variance.
        let disc = grey(64, 64, |r, c| {
            let (y, x) = (r as f32 - 31.5, c as f32 - 31.5);
            if x * x + y * y < 400.0 { 0.9 } else { 0.1 }
        });
        let share = block_mean_share(&disc);
        assert!(share > NON_STATIONARY_SHARE, "{share}");
        // A linear ramp: between-block variance is (1 - 1/16) of the total for a 4x4 grid.
        let ramp = grey(64, 64, |_, c| c as f32 / 64.0);
        let share = block_mean_share(&ramp);
        assert!((share - 0.9375).abs() < 0.01, "{share}");
    }

    #[test]
    fn tiny_and_flat_images_give_zero() {
        assert_eq!(block_mean_share(&grey(3, 64, |_, c| c as f32)), 0.0);
        assert_eq!(block_mean_share(&grey(16, 16, |_, _| 0.5)), 0.0);
    }
}
