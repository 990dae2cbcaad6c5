//! Karhunen-Loeve (principal component) decorrelation of the three colour channels of a
//! subspace image (seed 001, sec. 5.3.1; mrf_math.md 1(c)), so that each factor can be modelled
//! by its own mono-spectral MRF.
//!
//! The decorrelation works in CIE Lab by default, not in linear RGB. Measured colour is
//! multiplicative (albedo times shading): in linear RGB a pixel's chroma excursion scales with
//! its brightness, so the chroma factors depend on the luminance factor although they are
//! uncorrelated with it. Synthesized independently, they put bright-pixel excursions on dark
//! pixels, which become saturated outliers (the blue and orange specks on grey clay; stones'
//! a* spread 2.3x the measured). In Lab, chroma is already separated from lightness, and the
//! factor marginals constrain the Lab marginals directly.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use ndarray::{Array2, Array3, Axis, Zip, s};

use crate::color::{lab_to_linear, lab_to_linear_in_gamut, linear_to_lab};

/// The colour coordinates the basis decorrelates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ColourSpace {
    /// Linear RGB as measured (format version 1 models).
    LinearRgb,
    /// CIE L*a*b* (D65) of the linear RGB.
    #[default]
    Lab,
}

impl ColourSpace {
    /// Coordinates of a linear RGB pixel in this space.
    #[inline]
    pub fn from_linear(self, rgb: [f32; 3]) -> [f32; 3] {
        match self {
            ColourSpace::LinearRgb => rgb,
            ColourSpace::Lab => linear_to_lab(rgb),
        }
    }

    /// Linear RGB of coordinates in this space.
    #[inline]
    pub fn to_linear(self, c: [f32; 3]) -> [f32; 3] {
        match self {
            ColourSpace::LinearRgb => c,
            ColourSpace::Lab => lab_to_linear(c),
        }
    }

    /// The planar `(3, h, w)` linear RGB image of colour planes in this space; Lab colours
    /// outside the RGB gamut lose chroma at their lightness ([`lab_to_linear_in_gamut`]).
    pub fn linear_image(self, planes: &[Array2<f64>; 3]) -> Array3<f32> {
        let (h, w) = planes[0].dim();
        let mut out = Array3::<f32>::zeros((3, h, w));
        let (mut r, mut g, mut b) =
            out.multi_slice_mut((s![0, .., ..], s![1, .., ..], s![2, .., ..]));
        Zip::from(&mut r)
            .and(&mut g)
            .and(&mut b)
            .and(&planes[0])
            .and(&planes[1])
            .and(&planes[2])
            .par_for_each(|r, g, b, &x, &y, &z| {
                let c = [x as f32, y as f32, z as f32];
                [*r, *g, *b] = match self {
                    ColourSpace::LinearRgb => c,
                    ColourSpace::Lab => lab_to_linear_in_gamut(c),
                };
            });
        out
    }

    /// The least variation (largest minus smallest value, in this space's units) a colour
    /// coordinate or a KL factor needs to be visible: a hundredth of a Lab unit (an 8-bit sRGB
    /// step is 0.2 to 1.2 units), in linear RGB a thirtieth of the darkest 8-bit step. The
    /// rounding of the Lab conversion alone gives a grey photograph's a* and b* a range of
    /// about 3e-5 units (the gravel photograph's).
    pub fn visible_range(self) -> f64 {
        match self {
            ColourSpace::LinearRgb => 1e-5,
            ColourSpace::Lab => 0.01,
        }
    }

    /// Colour planes of a planar `(3, h, w)` linear RGB image in this space, `(h, w)` each.
    pub fn planes(self, image: &Array3<f32>) -> [Array2<f64>; 3] {
        let image = self.convert(image);
        std::array::from_fn(|c| image.index_axis(Axis(0), c).mapv(f64::from))
    }

    /// A planar `(3, h, w)` linear RGB image in this space.
    pub fn convert(self, image: &Array3<f32>) -> Array3<f32> {
        let mut out = image.clone();
        if self == ColourSpace::LinearRgb {
            return out;
        }
        let (mut a, mut b, mut c) =
            out.multi_slice_mut((s![0, .., ..], s![1, .., ..], s![2, .., ..]));
        Zip::from(&mut a)
            .and(&mut b)
            .and(&mut c)
            .par_for_each(|a, b, c| {
                [*a, *b, *c] = self.from_linear([*a, *b, *c]);
            });
        out
    }
}

/// Whether the largest and smallest of `values` are less than `range` apart (`true` for none).
pub fn varies_less_than<'a>(values: impl IntoIterator<Item = &'a f64>, range: f64) -> bool {
    let (low, high) = values
        .into_iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    high - low < range || low > high
}

/// A colour mean and orthonormal basis in a colour space: `factor = T^T (x - mean)`,
/// `x = T factor + mean`, with `x` the pixel's coordinates in `space`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KlBasis {
    /// The space of the coordinates (and of `mean`).
    pub space: ColourSpace,
    /// Mean colour, in `space`.
    pub mean: [f64; 3],
    /// Columns are the eigenvectors of the colour covariance, by decreasing variance.
    pub basis: [[f64; 3]; 3],
    /// The variance of each factor (the eigenvalues), decreasing.
    pub variances: [f64; 3],
}

impl KlBasis {
    /// No change of basis and zero mean (for models that take the channels of `space` as they
    /// are).
    pub fn identity(space: ColourSpace) -> Self {
        Self {
            space,
            mean: [0.0; 3],
            basis: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            variances: [0.0; 3],
        }
    }

    /// Fits the basis to a planar `(3, h, w)` linear RGB image, in `space`.
    pub fn fit(image: &Array3<f32>, space: ColourSpace) -> Self {
        let image = &space.convert(image);
        let n = (image.len() / 3).max(1) as f64;
        let mean: [f64; 3] = std::array::from_fn(|c| {
            image
                .index_axis(Axis(0), c)
                .iter()
                .map(|&v| f64::from(v))
                .sum::<f64>()
                / n
        });
        let mut cov = Matrix3::<f64>::zeros();
        let (_, h, w) = image.dim();
        for y in 0..h {
            for x in 0..w {
                let d = Vector3::from_fn(|c, _| f64::from(image[[c, y, x]]) - mean[c]);
                cov += d * d.transpose();
            }
        }
        cov /= n;
        let eig = SymmetricEigen::new(cov);
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let basis =
            std::array::from_fn(|row| std::array::from_fn(|k| eig.eigenvectors[(row, order[k])]));
        let variances = std::array::from_fn(|k| eig.eigenvalues[order[k]].max(0.0));
        Self {
            space,
            mean,
            basis,
            variances,
        }
    }

    /// The three factor planes of a linear RGB image, `(h, w)` each.
    pub fn forward(&self, image: &Array3<f32>) -> [Array2<f64>; 3] {
        let image = &self.space.convert(image);
        let (_, h, w) = image.dim();
        std::array::from_fn(|k| {
            Array2::from_shape_fn((h, w), |(y, x)| {
                (0..3)
                    .map(|c| self.basis[c][k] * (f64::from(image[[c, y, x]]) - self.mean[c]))
                    .sum()
            })
        })
    }

    /// [`KlBasis::forward`] with every factor that varies by less than the space's
    /// [`ColourSpace::visible_range`] set to its mean: a grey image's chroma factors (rounding
    /// noise of a few 1e-5 Lab units) are then fitted as constant bands, whose synthesis draws
    /// no noise, instead of as textures no one can see.
    pub fn visible_factors(&self, image: &Array3<f32>) -> [Array2<f64>; 3] {
        self.forward(image).map(|factor| {
            if varies_less_than(&factor, self.space.visible_range()) {
                Array2::from_elem(factor.dim(), factor.mean().unwrap_or(0.0))
            } else {
                factor
            }
        })
    }

    /// The linear RGB image from its factor planes (all of one shape): planar (3, rows, cols).
    pub fn inverse(&self, factors: &[Array2<f64>; 3]) -> Array3<f32> {
        self.space
            .linear_image(&self.coordinates_mapped(factors, |f| f))
    }

    /// The colour planes (coordinates in `space`) of factor planes, each pixel's factor values
    /// passed through `map` first.
    pub fn coordinates_mapped(
        &self,
        factors: &[Array2<f64>; 3],
        map: impl Fn([f64; 3]) -> [f64; 3] + Sync,
    ) -> [Array2<f64>; 3] {
        let dim = factors[0].dim();
        let [mut x, mut y, mut z] = std::array::from_fn(|_| Array2::<f64>::zeros(dim));
        let (k, mean) = (&self.basis, &self.mean);
        Zip::from(&mut x)
            .and(&mut y)
            .and(&mut z)
            .and(&factors[0])
            .and(&factors[1])
            .and(&factors[2])
            .par_for_each(|x, y, z, &f0, &f1, &f2| {
                let f = map([f0, f1, f2]);
                let channel = |c: usize| k[c][0] * f[0] + k[c][1] * f[1] + k[c][2] * f[2] + mean[c];
                [*x, *y, *z] = [channel(0), channel(1), channel(2)];
            });
        [x, y, z]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_is_orthonormal_and_round_trips() {
        let img = Array3::from_shape_fn((3, 9, 11), |(c, y, x)| {
            let t = (x as f32 * 0.7 + y as f32 * 0.3).sin();
            [
                0.5 + 0.3 * t,
                0.4 + 0.2 * t + 0.01 * x as f32,
                0.2 + 0.05 * (y as f32).cos(),
            ][c]
        });
        for space in [ColourSpace::LinearRgb, ColourSpace::Lab] {
            round_trip(&img, space);
        }
    }

    fn round_trip(img: &Array3<f32>, space: ColourSpace) {
        let kl = KlBasis::fit(img, space);
        for a in 0..3 {
            for b in 0..3 {
                let dot: f64 = (0..3).map(|c| kl.basis[c][a] * kl.basis[c][b]).sum();
                assert!((dot - if a == b { 1.0 } else { 0.0 }).abs() < 1e-10);
            }
        }
        assert!(kl.variances[0] >= kl.variances[1] && kl.variances[1] >= kl.variances[2]);
        let f = kl.forward(img);
        // Factors are uncorrelated.
        let n = f[0].len() as f64;
        let c01: f64 = f[0]
            .iter()
            .zip(f[1].iter())
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / n;
        assert!(c01.abs() < 1e-9);
        let back = kl.inverse(&f);
        let err = (&back - img).mapv(f32::abs).fold(0.0f32, |m, &v| m.max(v));
        assert!(err < 1e-5, "{space:?}: {err}");
    }

    #[test]
    fn lab_chroma_factors_depend_less_on_shading() {
        // Two albedos (orange and a duller orange, a checker) under a shading ramp from 0.05
        // to 1: the chroma excursion of a pixel scales with its shading in linear RGB (20x
        // over the ramp), with the cube root of it in Lab (under 3x).
        let img = Array3::from_shape_fn((3, 32, 32), |(c, y, x)| {
            let shade = 0.05 + 0.95 * x as f32 / 31.0;
            let albedo = if (x + y) % 2 == 0 {
                [0.8, 0.5, 0.2]
            } else {
                [0.7, 0.5, 0.3]
            };
            albedo[c] * shade
        });
        let spread = |space| {
            let f = KlBasis::fit(&img, space).forward(&img);
            let std = |cols: std::ops::Range<usize>| {
                let v: Vec<f64> = cols.flat_map(|x| f[1].column(x).to_vec()).collect();
                let m = v.iter().sum::<f64>() / v.len() as f64;
                (v.iter().map(|a| (a - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
            };
            std(24..32) / std(0..8)
        };
        let (linear, lab) = (spread(ColourSpace::LinearRgb), spread(ColourSpace::Lab));
        assert!(linear > 5.0 && lab < 3.0, "linear {linear}, lab {lab}");
    }

    #[test]
    fn a_grey_image_keeps_its_lightness_factor_and_flattens_its_chroma_factors() {
        let grey = Array3::from_shape_fn((3, 16, 16), |(_, y, x)| {
            0.05 + 0.9 * (((x * 7 + y * 3) % 16) as f32 / 15.0)
        });
        let kl = KlBasis::fit(&grey, ColourSpace::Lab);
        let raw = kl.forward(&grey);
        // The conversion's rounding alone leaves the chroma factors a little spread, which a
        // relative flatness test would take for a texture.
        let spread = |f: &Array2<f64>| {
            f.fold(f64::NEG_INFINITY, |m, &v| m.max(v)) - f.fold(f64::INFINITY, |m, &v| m.min(v))
        };
        assert!(spread(&raw[0]) > 50.0, "{}", spread(&raw[0]));
        let visible = kl.visible_factors(&grey);
        assert_eq!(visible[0], raw[0]);
        for k in 1..3 {
            assert!(
                spread(&raw[k]) < ColourSpace::Lab.visible_range(),
                "{}",
                spread(&raw[k])
            );
            assert_eq!(spread(&visible[k]), 0.0, "factor {k}");
        }
        // A faint tint a display shows (a tenth of a unit of b*) stays a texture.
        let tinted = Array3::from_shape_fn((3, 16, 16), |(c, y, x)| {
            grey[[c, y, x]] * if c == 2 && x % 2 == 0 { 0.999 } else { 1.0 }
        });
        let kl = KlBasis::fit(&tinted, ColourSpace::Lab);
        let visible = kl.visible_factors(&tinted);
        assert!(spread(&visible[1]) > 0.05, "{}", spread(&visible[1]));
    }

    #[test]
    fn variation_is_the_largest_minus_the_smallest_value() {
        assert!(varies_less_than(&[1.0, 1.004, 0.997], 0.01));
        assert!(!varies_less_than(&[1.0, 1.006, 0.996], 0.01));
        assert!(varies_less_than(&[], 0.01));
    }

    #[test]
    fn grey_and_constant_images_do_not_break() {
        let flat = Array3::from_elem((3, 4, 4), 0.25f32);
        for space in [ColourSpace::LinearRgb, ColourSpace::Lab] {
            let kl = KlBasis::fit(&flat, space);
            assert!(kl.basis.iter().flatten().all(|v| v.is_finite()));
            let back = kl.inverse(&kl.forward(&flat));
            assert!(back.iter().all(|v| (v - 0.25).abs() < 1e-5), "{space:?}");
        }
    }
}
