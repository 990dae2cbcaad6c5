//! Two classical baselines for the recognition experiment, with their distances:
//!
//! - [`colour_histogram`]: the joint RGB histogram of the sRGB-encoded colours, 8 bins per
//!   channel (512 bins), compared by histogram intersection (Swain & Ballard 1991). Invariant
//!   to nothing colour-related: any gain moves colours between bins.
//! - [`lbp_histogram`]: uniform local binary patterns LBP(8, 1) (Ojala, Pietikäinen & Mäenpää,
//!   TPAMI 2002; 58 uniform codes + 1 bin for all others) of the linear luminance, on 3 levels
//!   of the Gaussian pyramid (multi-scale), compared by L1. Invariant to any monotonic change of
//!   the luminance (brightness), but a colour change that alters luminance differently in
//!   different places (a coloured texture under a coloured light) changes it.

use ndarray::{Array2, Array3, Axis};

use crate::color::linear_to_srgb;
use crate::decompose::pyramid::reduce;

/// Bins per channel of the colour histogram.
pub const COLOUR_BINS: usize = 8;

/// Pyramid levels of the LBP histogram.
pub const LBP_SCALES: usize = 3;

/// Bins of one uniform LBP(8, 1) histogram.
pub const LBP_BINS: usize = 59;

/// Joint RGB histogram of a `(3, h, w)` linear image, colours sRGB-encoded (as stored in an
/// 8-bit file) and clamped to [0, 1], `COLOUR_BINS^3` bins summing to 1 (all zero for an
/// empty image).
pub fn colour_histogram(image: &Array3<f32>) -> Vec<f64> {
    let (_, h, w) = image.dim();
    let mut hist = vec![0.0; COLOUR_BINS.pow(3)];
    let bin = |v: f32| {
        let e = linear_to_srgb(v).clamp(0.0, 1.0);
        if e.is_finite() {
            ((e * COLOUR_BINS as f32) as usize).min(COLOUR_BINS - 1)
        } else {
            0
        }
    };
    for r in 0..h {
        for c in 0..w {
            let i = bin(image[[0, r, c]]) * COLOUR_BINS * COLOUR_BINS
                + bin(image[[1, r, c]]) * COLOUR_BINS
                + bin(image[[2, r, c]]);
            hist[i] += 1.0;
        }
    }
    let n = (h * w).max(1) as f64;
    hist.iter_mut().for_each(|v| *v /= n);
    hist
}

/// Histogram-intersection distance `1 - sum_i min(a_i, b_i)` of two normalised histograms.
pub fn intersection_distance(a: &[f64], b: &[f64]) -> f64 {
    1.0 - a.iter().zip(b).map(|(x, y)| x.min(*y)).sum::<f64>()
}

/// L1 distance.
pub fn l1_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum()
}

/// The uniform-pattern index (0..58) of every 8-bit code; non-uniform codes (more than two
/// 0/1 transitions around the circle) map to 58.
fn uniform_table() -> [u8; 256] {
    let mut table = [58u8; 256];
    let mut next = 0u8;
    for code in 0..256u32 {
        let rotated = (code >> 1) | ((code & 1) << 7);
        if (code ^ rotated).count_ones() <= 2 {
            table[code as usize] = next;
            next += 1;
        }
    }
    debug_assert_eq!(next, 58);
    table
}

/// Uniform LBP(8, 1) histogram of one plane (59 bins summing to 1; borders skipped; all zero
/// when the plane is smaller than 3 x 3). Neighbour `p` contributes bit `p` when it is at
/// least the centre value.
pub fn lbp_plane(plane: &Array2<f64>) -> Vec<f64> {
    const RING: [(isize, isize); 8] = [
        (0, 1),
        (-1, 1),
        (-1, 0),
        (-1, -1),
        (0, -1),
        (1, -1),
        (1, 0),
        (1, 1),
    ];
    let table = uniform_table();
    let (h, w) = plane.dim();
    let mut hist = vec![0.0; LBP_BINS];
    if h < 3 || w < 3 {
        return hist;
    }
    for r in 1..h - 1 {
        for c in 1..w - 1 {
            let centre = plane[[r, c]];
            let mut code = 0usize;
            for (p, &(dr, dc)) in RING.iter().enumerate() {
                let v = plane[[(r as isize + dr) as usize, (c as isize + dc) as usize]];
                if v >= centre {
                    code |= 1 << p;
                }
            }
            hist[table[code] as usize] += 1.0;
        }
    }
    let n = ((h - 2) * (w - 2)) as f64;
    hist.iter_mut().for_each(|v| *v /= n);
    hist
}

/// Multi-scale uniform LBP of the linear luminance (Rec. 709 weights) of a `(3, h, w)` image:
/// `LBP_SCALES` histograms of 59 bins, one per Gaussian pyramid level, concatenated.
pub fn lbp_histogram(image: &Array3<f32>) -> Vec<f64> {
    let weights = [0.2126, 0.7152, 0.0722];
    let mut lum = Array2::<f64>::zeros((image.len_of(Axis(1)), image.len_of(Axis(2))));
    for (c, wgt) in weights.iter().enumerate() {
        lum.zip_mut_with(&image.index_axis(Axis(0), c), |l, &v| *l += wgt * v as f64);
    }
    let mut out = Vec::with_capacity(LBP_SCALES * LBP_BINS);
    for s in 0..LBP_SCALES {
        if s > 0 && lum.nrows() > 0 && lum.ncols() > 0 {
            lum = reduce(&lum);
        }
        out.extend(lbp_plane(&lum));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_table_has_58_patterns_and_lbp_of_a_ramp_is_one_code() {
        let t = uniform_table();
        assert_eq!(t.iter().filter(|&&v| v < 58).count(), 58);
        assert_eq!(t[0], 0);
        assert_eq!(t[255] as usize, 57);
        // A horizontal ramp: the same code everywhere.
        let ramp = Array2::from_shape_fn((10, 10), |(_, c)| c as f64);
        let h = lbp_plane(&ramp);
        assert_eq!(h.iter().filter(|&&v| v > 0.0).count(), 1);
        assert!((h.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn colour_histogram_sums_to_one_and_moves_under_a_gain() {
        let img = Array3::from_shape_fn((3, 16, 16), |(c, r, x)| {
            ((c + 1) * (r * 16 + x)) as f32 / 800.0
        });
        let a = colour_histogram(&img);
        assert!((a.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let b = colour_histogram(&img.mapv(|v| v * 0.3));
        assert!(intersection_distance(&a, &b) > 0.5);
        assert!(intersection_distance(&a, &a).abs() < 1e-12);
        // LBP of luminance does not see a uniform brightness change.
        let la = lbp_histogram(&img);
        let lb = lbp_histogram(&img.mapv(|v| v * 0.3));
        assert!(l1_distance(&la, &lb) < 1e-9);
    }
}
