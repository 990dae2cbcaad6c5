//! The cheap second-order criterion of mrf_math.md sec. 6 (the project's score before issue
//! 11; the headline figure is now the structure-aware judge, [`super::judge`]): colour
//! histograms and power spectra only, so a Gaussian noise with the right spectrum scores like
//! the material. Kept as what a Gaussian MRF is supposed to reproduce.
//!
//! - **Colour**: the 1-Wasserstein distance between the CIE Lab marginals, per channel
//!   (`sum_b |F_a[b] - F_b[b]| * bin width`, in Lab units), summed over L*, a*, b*.
//! - **Structure**: the mean absolute difference of the log power spectra of the normalised
//!   L* planes, Welch-averaged over Hann-windowed 32 x 32 tiles (so images of different sizes
//!   compare at the same frequency resolution) and pooled into 6 radial x 8 angular bins.
//!
//! The score is `colour / 10 + structure`: 0 for identical statistics. Tests show that another
//! crop of the same material scores close, and blurred, pixel-shuffled and different materials
//! far.

use ndarray::{Array2, Array3, s};

use crate::color::{fit_to_gamut, linear_to_lab};

/// Welch tile size, pixels.
const TILE: usize = 32;
const RADIAL: usize = 6;
const ANGULAR: usize = 8;
const BINS: usize = 64;

/// The two parts of a texture comparison and their combination.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Fidelity {
    /// Sum over L*, a*, b* of the 1-Wasserstein distance of the marginals (Lab units).
    pub colour: f64,
    /// Mean |difference| of log power spectra of the normalised L* planes.
    pub structure: f64,
    /// `colour / 10 + structure`; lower is closer, 0 is identical statistics.
    pub score: f64,
}

/// Statistics of one texture, computed once and compared many times.
#[derive(Debug, Clone)]
pub struct TextureStats {
    cdfs: [Vec<f64>; 3],
    log_spectrum: Vec<f64>,
}

const RANGES: [(f64, f64); 3] = [(0.0, 100.0), (-128.0, 128.0), (-128.0, 128.0)];

impl TextureStats {
    /// Statistics of a planar `(3, h, w)` linear RGB image (brought into [0, 1] as our
    /// display does, [`crate::color::fit_to_gamut`]). Images smaller than 32 x 32 are compared by colour only.
    pub fn of(image: &Array3<f32>) -> Self {
        let (_, h, w) = image.dim();
        let lab = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            f64::from(linear_to_lab(fit_to_gamut([0, 1, 2].map(|k| image[[k, y, x]])))[c])
        });
        let cdfs = std::array::from_fn(|c| {
            let (lo, hi) = RANGES[c];
            let mut hist = vec![0.0; BINS];
            for &v in lab.index_axis(ndarray::Axis(0), c) {
                let b =
                    (((v - lo) / (hi - lo)) * BINS as f64).clamp(0.0, BINS as f64 - 1.0) as usize;
                hist[b] += 1.0;
            }
            let n = (h * w).max(1) as f64;
            let mut acc = 0.0;
            hist.iter()
                .map(|c| {
                    acc += c / n;
                    acc
                })
                .collect()
        });
        let l = lab.index_axis(ndarray::Axis(0), 0).to_owned();
        Self {
            cdfs,
            log_spectrum: log_spectrum(&l),
        }
    }

    /// Compares two textures.
    pub fn compare(&self, other: &TextureStats) -> Fidelity {
        let colour: f64 = (0..3)
            .map(|c| {
                let width = (RANGES[c].1 - RANGES[c].0) / BINS as f64;
                self.cdfs[c]
                    .iter()
                    .zip(&other.cdfs[c])
                    .map(|(a, b)| (a - b).abs())
                    .sum::<f64>()
                    * width
            })
            .sum();
        let structure = if self.log_spectrum.is_empty() || other.log_spectrum.is_empty() {
            0.0
        } else {
            self.log_spectrum
                .iter()
                .zip(&other.log_spectrum)
                .map(|(a, b)| (a - b).abs())
                .sum::<f64>()
                / self.log_spectrum.len() as f64
        };
        Fidelity {
            colour,
            structure,
            score: colour / 10.0 + structure,
        }
    }
}

/// Pearson correlation of two equally long sequences (pixelwise agreement of two registered
/// images; 0 when either is constant).
pub fn correlation<'a>(
    a: impl IntoIterator<Item = &'a f64> + Clone,
    b: impl IntoIterator<Item = &'a f64> + Clone,
) -> f64 {
    let (mut n, mut sa, mut sb) = (0.0f64, 0.0, 0.0);
    for (x, y) in a.clone().into_iter().zip(b.clone()) {
        n += 1.0;
        sa += x;
        sb += y;
    }
    let (ma, mb) = (sa / n.max(1.0), sb / n.max(1.0));
    let (mut cov, mut va, mut vb) = (0.0, 0.0, 0.0);
    for (x, y) in a.into_iter().zip(b) {
        cov += (x - ma) * (y - mb);
        va += (x - ma).powi(2);
        vb += (y - mb).powi(2);
    }
    if va > 0.0 && vb > 0.0 {
        cov / (va * vb).sqrt()
    } else {
        0.0
    }
}

/// Compares two images (any sizes): see the module documentation.
pub fn texture_fidelity(a: &Array3<f32>, b: &Array3<f32>) -> Fidelity {
    TextureStats::of(a).compare(&TextureStats::of(b))
}

/// Welch-averaged, radially and angularly pooled log power spectrum of a plane normalised to
/// zero mean and unit variance; empty for planes smaller than one tile.
fn log_spectrum(plane: &Array2<f64>) -> Vec<f64> {
    let (h, w) = plane.dim();
    if h < TILE || w < TILE {
        return Vec::new();
    }
    let n = plane.len() as f64;
    let mean = plane.sum() / n;
    let std = (plane.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n)
        .sqrt()
        .max(1e-9);
    let hann: Vec<f64> = (0..TILE)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * (i as f64 + 0.5) / TILE as f64).cos())
        .collect();
    let mut power = Array2::<f64>::zeros((TILE, TILE));
    let mut tiles = 0;
    let step = TILE / 2;
    for y in (0..=h - TILE).step_by(step) {
        for x in (0..=w - TILE).step_by(step) {
            let tile = plane.slice(s![y..y + TILE, x..x + TILE]);
            let windowed = Array2::from_shape_fn((TILE, TILE), |(i, j)| {
                (tile[[i, j]] - mean) / std * hann[i] * hann[j]
            });
            let spectrum = crate::fft::forward(&windowed);
            power.zip_mut_with(&spectrum, |p, c| *p += c.norm_sqr());
            tiles += 1;
        }
    }
    let mut sums = vec![0.0; RADIAL * ANGULAR];
    let mut counts = vec![0usize; RADIAL * ANGULAR];
    let half = TILE as f64 / 2.0;
    for ((i, j), p) in power.indexed_iter() {
        let fy = if i as f64 <= half {
            i as f64
        } else {
            i as f64 - TILE as f64
        };
        let fx = if j as f64 <= half {
            j as f64
        } else {
            j as f64 - TILE as f64
        };
        let r = (fx * fx + fy * fy).sqrt() / half;
        if r == 0.0 || r > 1.0 {
            continue; // the mean, and corners beyond the Nyquist circle
        }
        let radial = ((r * RADIAL as f64) as usize).min(RADIAL - 1);
        let angle = fy.atan2(fx).rem_euclid(std::f64::consts::PI);
        let angular = ((angle / std::f64::consts::PI * ANGULAR as f64) as usize).min(ANGULAR - 1);
        sums[radial * ANGULAR + angular] += p / tiles as f64;
        counts[radial * ANGULAR + angular] += 1;
    }
    sums.iter()
        .zip(&counts)
        .map(|(s, &c)| (s / c.max(1) as f64 + 1e-9).ln())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_images_score_zero_and_the_score_is_symmetric() {
        let im = Array3::from_shape_fn((3, 40, 48), |(c, y, x)| {
            ((x * 7 + y * 3 + c) % 11) as f32 / 11.0
        });
        let other = Array3::from_shape_fn((3, 40, 48), |(c, y, x)| {
            ((x * 5 + y * 2 + c) % 13) as f32 / 13.0
        });
        assert_eq!(texture_fidelity(&im, &im).score, 0.0);
        let (ab, ba) = (texture_fidelity(&im, &other), texture_fidelity(&other, &im));
        assert!((ab.score - ba.score).abs() < 1e-12);
        assert!(ab.score > 0.0);
    }

    #[test]
    fn tiny_images_compare_by_colour_only() {
        let a = Array3::from_elem((3, 4, 4), 0.2f32);
        let b = Array3::from_elem((3, 4, 4), 0.6f32);
        let f = texture_fidelity(&a, &b);
        assert_eq!(f.structure, 0.0);
        assert!(f.colour > 10.0);
    }
}
