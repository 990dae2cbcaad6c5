//! Illumination-invariant texture features from causal autoregressive models (Vácha & Haindl,
//! ICPR 2008; Vácha's thesis 2010, sec. 4.2; mrf_math.md sec. 5), for recognising a material
//! under an unknown illuminant colour and brightness.
//!
//! An image is a planar `(3, h, w)` linear RGB array. A change of illumination spectrum and
//! brightness is modelled as `Y'_r = B Y_r` at every pixel, with a regular 3x3 matrix `B`
//! (diagonal for a per-channel gain, full for e.g. a von Kries adaptation done in another
//! colour space). [`extract`] builds a K-level Gaussian pyramid (K = 4 by default) and fits at
//! every level, by least squares:
//!
//! - a **3D CAR** model of the colour channels jointly, `Y_r = sum_s A_s Y_{r-s} + e_r`,
//!   `e_r ~ N(0, Sigma)`, on the small causal neighbourhood of [`FeatureOptions::order`]
//!   (order 2: left, up, up-left, up-right). Under `B`, `A_s -> B A_s B^-1` and
//!   `Sigma -> B Sigma B^T`, so every similarity invariant of `A_s` is a feature;
//! - a **2D CAR** model of each colour channel on its own; its coefficients `gamma` do not
//!   change when the channel is multiplied by a gain (only its noise variance does).
//!
//! ## Features
//!
//! Per pyramid level `l` (`eta` = number of neighbours, 4 at order 2):
//!
//! | feature | count | invariant to | source |
//! |---|---|---|---|
//! | `tr A_s` | `eta` | any regular 3x3 `B` | Vácha & Haindl ICPR 2008; thesis 4.2 (mrf_math 5, item 1) |
//! | eigenvalues of `A_s`, real parts sorted descending | `3 eta` | any regular `B` | same (item 2) |
//! | eigenvalues of `A_s`, absolute imaginary parts sorted descending | `3 eta` | any regular `B` | same (item 2) |
//! | `alpha3 = sqrt(mean_r (Y_r - mu)^T Sigma^-1 (Y_r - mu))` | 1 | any regular `B` | same (item 5; per site, so it does not grow with the image) |
//! | eigenvalues of `Sigma Phi^-1` (innovation share of each colour direction, `Phi` the level's colour covariance), sorted descending | 3 | any regular `B` | this crate: `Sigma Phi^-1 -> B Sigma Phi^-1 B^-1` under `B`; `alpha3^2` is the sum of their inverses |
//! | 2D CAR `gamma` of channel R, G, B | `3 eta` | per-channel gain (diagonal `B`) | Vácha & Haindl, the 2D CAR variant (mrf_math 5, last list) |
//!
//! Once per image (linear RGB, before the pyramid):
//!
//! | feature | count | invariant to | source |
//! |---|---|---|---|
//! | coefficient of variation `std / mean` of R, G, B | 3 | per-channel gain | grey-world normalisation: each channel divided by its mean (Finlayson et al., comprehensive colour normalisation, ECCV 1998) |
//! | skewness and excess kurtosis of R, G, B | 6 | per-channel gain (any affine change of a channel) | standard moments |
//! | correlation coefficients RG, RB, GB | 3 | per-channel positive gain | standard |
//!
//! Nothing here is invariant to the illumination **direction** (shadows move); the features are
//! only robust to it, as the recognition benchmark measures (docs/BENCHMARKS.md).
//! The baselines in [`baselines`] are a joint colour histogram (invariant to nothing) and
//! uniform LBP histograms of luminance (invariant to monotonic brightness changes only).
//!
//! ## How invariance is kept exact
//!
//! - Every fit is least squares. α1 and α2 of the thesis are not used: with whole-image LS
//!   statistics they are the constants `d eta` and `sqrt(d)` (mrf_math 5, warning).
//! - Before fitting, the colour channels are **whitened** with the image's colour covariance
//!   (`W = Lambda^-1/2 U^T`). Two whitened images related by `B` differ by an orthogonal `Q`
//!   (`W' B W^-1` maps unit covariance to unit covariance), so the small ridge `delta I` that
//!   keeps the normal equations regular commutes with `Q` and invariance stays exact, not
//!   approximate (a ridge on raw colours would break it). The 2D CAR ridge is proportional to
//!   the channel's own energy, so a gain cancels.
//! - **Rank-deficient colour** (a grey photograph: R = G = B; any `B` keeps it rank 1): only
//!   the colour directions with a variance above `1e-6` of the largest are modelled, and, in
//!   an image whose values are all 8-bit sRGB codes, above ten times the variance of 8-bit
//!   rounding too (a grey photograph relit and stored at 8 bits has rounding noise in the
//!   other two directions, which must not count as texture; the floor is absolute, so it is
//!   used only where the storage is known); the missing ones are filled with the
//!   values of independent white noise (eigenvalue 0, share of innovation 1), so the vector
//!   keeps its length. The colour moments are computed on the image projected onto the kept
//!   directions, so a near-grey image's channel correlations are exactly +-1 and its
//!   per-channel moments equal, whatever the gains. The rank decision is not itself
//!   invariant near these thresholds; grey and clearly colourful images are far from them.
//! - Levels with too few sites for the neighbourhood (fewer than `2 d eta` equations, e.g. the
//!   coarse levels of an 8x8 image), and flat or saturated (constant) images, give the same
//!   white-noise values: finite, never NaN.

pub mod baselines;
mod invariants;
pub mod recognition;

use ndarray::Array3;

use crate::decompose::pyramid::reduce;
use crate::mrf::neighbourhood::causal;

/// What a feature is invariant to (see the table in the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Invariance {
    /// Any regular 3x3 colour transform `Y' = B Y` (includes per-channel gains and brightness).
    ColourTransform,
    /// Per-channel positive gains (diagonal `B`), hence brightness too.
    ChannelGain,
}

/// Options of [`extract`].
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureOptions {
    /// Levels of the Gaussian pyramid (1..=8). Vácha & Haindl use K = 4.
    pub levels: usize,
    /// Causal neighbourhood order of every CAR fit (1..=6, see
    /// [`crate::mrf::neighbourhood::causal`]); 2 = left, up, up-left, up-right.
    pub order: usize,
}

impl Default for FeatureOptions {
    fn default() -> Self {
        Self {
            levels: 4,
            order: 2,
        }
    }
}

/// Colour directions (3D CAR) and channels (2D CAR) per level.
const D: usize = 3;
const CHANNELS: [&str; 3] = ["R", "G", "B"];

impl FeatureOptions {
    fn offsets(&self) -> &'static [(isize, isize)] {
        causal(self.order.clamp(1, 6))
    }

    fn level_count(&self) -> usize {
        self.levels.clamp(1, 8)
    }

    /// Number of features: `levels (eta (2 + d) + 1 + d + d eta) + 12`.
    pub fn len(&self) -> usize {
        self.names().len()
    }

    /// Never empty; present for the `len` convention.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// A name for every feature, in vector order (e.g. `L0.tr(0,1)`, `L2.eig_re(1,0)#1`,
    /// `L2.eig_im(1,0)`, `L1.g2d.G(1,-1)`, `cv.R`, `corr.GB`).
    pub fn names(&self) -> Vec<String> {
        self.described().into_iter().map(|(n, _)| n).collect()
    }

    /// The invariance of every feature, in vector order.
    pub fn invariances(&self) -> Vec<Invariance> {
        self.described().into_iter().map(|(_, i)| i).collect()
    }

    fn described(&self) -> Vec<(String, Invariance)> {
        let offsets = self.offsets();
        let s = |&(a, b): &(isize, isize)| format!("({a},{b})");
        let mut out = Vec::new();
        let full = Invariance::ColourTransform;
        let gain = Invariance::ChannelGain;
        for l in 0..self.level_count() {
            for o in offsets {
                out.push((format!("L{l}.tr{}", s(o)), full));
            }
            for o in offsets {
                for j in 1..=D {
                    out.push((format!("L{l}.eig_re{}#{j}", s(o)), full));
                }
            }
            for o in offsets {
                out.push((format!("L{l}.eig_im{}", s(o)), full));
            }
            out.push((format!("L{l}.alpha3"), full));
            for j in 1..=D {
                out.push((format!("L{l}.innovation#{j}"), full));
            }
            for ch in CHANNELS {
                for o in offsets {
                    out.push((format!("L{l}.g2d.{ch}{}", s(o)), gain));
                }
            }
        }
        for stat in ["cv", "skew", "kurt"] {
            for ch in CHANNELS {
                out.push((format!("{stat}.{ch}"), gain));
            }
        }
        for pair in ["RG", "RB", "GB"] {
            out.push((format!("corr.{pair}"), gain));
        }
        out
    }
}

/// A feature vector; `values[i]` is named by `FeatureOptions::names()[i]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Features {
    /// The features, all finite.
    pub values: Vec<f64>,
}

/// Why features could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeatureError {
    /// The array is not `(3, h, w)` with `h, w >= 1`.
    #[error("image has shape {0:?}; features need (3, h, w) with h, w >= 1")]
    Shape((usize, usize, usize)),
    /// A pixel is NaN or infinite.
    #[error("image has a non-finite value at channel {0}, row {1}, column {2}")]
    NotFinite(usize, usize, usize),
}

/// Extracts the feature vector of a planar `(3, h, w)` linear RGB image (see the module docs
/// for the list). Deterministic; about 20 ms for 256 x 256 (docs/BENCHMARKS.md).
///
/// # Errors
/// A wrong shape (not 3 channels, or zero rows or columns) or a non-finite pixel.
pub fn extract(image: &Array3<f32>, options: &FeatureOptions) -> Result<Features, FeatureError> {
    let (c, h, w) = image.dim();
    if c != D || h == 0 || w == 0 {
        return Err(FeatureError::Shape((c, h, w)));
    }
    if let Some((idx, _)) = image.indexed_iter().find(|(_, v)| !v.is_finite()) {
        return Err(FeatureError::NotFinite(idx.0, idx.1, idx.2));
    }
    let eight_bit = invariants::looks_8bit(image);
    let image = image.mapv(f64::from);
    let offsets = options.offsets();
    let whitening = invariants::Whitening::of(&image, eight_bit);
    let mut values = Vec::with_capacity(options.len());
    let mut level = image.clone();
    for l in 0..options.level_count() {
        if l > 0 {
            level = reduce3(&level);
        }
        values.extend(invariants::level_features(&level, &whitening, offsets));
    }
    values.extend(invariants::colour_statistics(&whitening.project(&image)));
    debug_assert_eq!(values.len(), options.len());
    debug_assert!(values.iter().all(|v| v.is_finite()));
    Ok(Features { values })
}

/// REDUCE on every channel of a `(d, h, w)` array.
fn reduce3(image: &Array3<f64>) -> Array3<f64> {
    let planes: Vec<_> = image.outer_iter().map(|p| reduce(&p.to_owned())).collect();
    let (h, w) = planes[0].dim();
    Array3::from_shape_fn((planes.len(), h, w), |(c, r, x)| planes[c][[r, x]])
}

#[cfg(test)]
mod tests;
