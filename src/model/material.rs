//! The material model: everything needed to synthesize a BTF, a few tens of kilobytes.

use ndarray::Array2;

use crate::btf::DirectionSet;
use crate::decompose::KlBasis;
#[cfg(doc)]
use crate::decompose::marginals::BAND_QUANTILES;
use crate::decompose::marginals::{QuantileGrid, Quantiles};
use crate::decompose::pyramid::{Taps, apply_separable};
use crate::mrf::{Car2dModel, Car3dModel, GmrfModel};

/// Which MRF models the bands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum ModelKind {
    /// Gaussian MRF per KL factor and pyramid level (exactly tileable synthesis by FFT).
    Gmrf,
    /// 2D causal autoregressive model per KL factor and pyramid level.
    Car2d,
    /// 3D causal autoregressive model per pyramid level on the colour channels jointly.
    Car3d,
}

impl ModelKind {
    /// Every kind, in file-code order.
    pub const ALL: [ModelKind; 3] = [ModelKind::Gmrf, ModelKind::Car2d, ModelKind::Car3d];

    /// The name on the command line and in reports.
    pub fn name(&self) -> &'static str {
        match self {
            ModelKind::Gmrf => "gmrf",
            ModelKind::Car2d => "2dcar",
            ModelKind::Car3d => "3dcar",
        }
    }
}

impl std::str::FromStr for ModelKind {
    type Err = super::ModelError;
    fn from_str(s: &str) -> super::Result<Self> {
        Self::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                super::ModelError::parameter(
                    "--model",
                    format!("'{s}' is not gmrf, 2dcar or 3dcar"),
                )
            })
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A mono-spectral band model.
#[derive(Debug, Clone, PartialEq)]
pub enum BandModel {
    /// A 2D CAR band.
    Car2d(Car2dModel),
    /// A GMRF band.
    Gmrf(GmrfModel),
}

/// The model of one pyramid level of one subspace image.
#[derive(Debug, Clone, PartialEq)]
pub enum LevelModel {
    /// One model per KL factor (2D CAR, GMRF).
    Factors([BandModel; 3]),
    /// One joint colour model (3D CAR).
    Joint(Car3dModel),
}

/// The model of one subspace image (one cluster of the view x light space).
#[derive(Debug, Clone, PartialEq)]
pub struct SubspaceModel {
    /// (view, light) of the measured image that represents the cluster.
    pub representative: (u16, u16),
    /// The colour basis (identity for the 3D CAR, which needs none).
    pub kl: KlBasis,
    /// Quantiles of the three factor planes (KL factors, or colour channels for the 3D CAR)
    /// of the measured image, for marginal matching after synthesis.
    pub marginals: [Quantiles; 3],
    /// The probabilities of `marginals` (uniform in version 1 files).
    pub marginal_grid: QuantileGrid,
    /// Level models, finest first.
    pub levels: Vec<LevelModel>,
    /// Quantile tables of the measured pyramid bands, if the model matches band marginals.
    pub band_marginals: Option<BandMarginals>,
}

/// The measured marginal distribution of every pyramid band of a subspace image (format
/// version 2; mrf_math.md 1(f')): each synthesized band is mapped onto it before the pyramid
/// is collapsed, so sparse, heavy-tailed bands (edges, pores) are not left Gaussian.
#[derive(Debug, Clone, PartialEq)]
pub struct BandMarginals {
    /// `tables[level][factor]`: [`BAND_QUANTILES`] values at
    /// [`band_probabilities`](crate::decompose::marginals::band_probabilities), finest level
    /// first.
    pub tables: Vec<[Vec<f64>; 3]>,
}

/// A range map (height field) for bump or displacement mapping, estimated by photometric
/// stereo on the measured images. Larger areas are covered by quilting it seamlessly
/// ([`crate::geometry::quilt`]), not by repeating it.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeMap {
    /// Heights in texels of the measured image, row-major, `rows * cols` samples.
    pub heights: Vec<f32>,
    /// Rows of the stored map.
    pub rows: usize,
    /// Columns of the stored map.
    pub cols: usize,
    /// Measured texels per stored sample (1 = full resolution; larger maps are averaged down
    /// to keep models small).
    pub step: usize,
    /// Bump strength per measured light ([`crate::geometry::relight`]), fitted to the frontal
    /// images; empty in files from before it was stored, which means 1 for every light.
    pub strength: Vec<f32>,
}

impl RangeMap {
    /// The stored samples as an array, (rows, cols).
    pub fn samples(&self) -> Array2<f64> {
        Array2::from_shape_fn((self.rows, self.cols), |(r, c)| {
            f64::from(self.heights[r * self.cols + c])
        })
    }

    /// The map on the measured images' pixel grid, `rows` x `cols` texels (bilinear, edges
    /// repeated): registered with the images it was estimated from.
    pub fn registered(&self, rows: usize, cols: usize) -> Array2<f64> {
        let taps = |out: usize, n: usize| -> Taps {
            (0..out)
                .map(|i| {
                    let u = ((i as f64 + 0.5) / self.step as f64 - 0.5).clamp(0.0, (n - 1) as f64);
                    let i0 = (u.floor() as usize).min(n - 1);
                    let f = u - i0 as f64;
                    vec![(i0, 1.0 - f), ((i0 + 1).min(n - 1), f)]
                })
                .collect()
        };
        apply_separable(
            &self.samples(),
            &taps(rows, self.rows),
            &taps(cols, self.cols),
        )
    }

    /// The bump strength fitted for measured light `light` (1 where none was stored).
    pub fn strength_of(&self, light: usize) -> f64 {
        self.strength.get(light).map_or(1.0, |&k| f64::from(k))
    }
}

/// A whole material: clustering, subspace models and range map. Written as `.btfm`.
#[derive(Debug, Clone, PartialEq)]
pub struct MaterialModel {
    /// The band model family.
    pub kind: ModelKind,
    /// The measured view directions.
    pub views: DirectionSet,
    /// The measured light directions.
    pub lights: DirectionSet,
    /// Width of the measured images, pixels.
    pub width: u32,
    /// Height of the measured images, pixels.
    pub height: u32,
    /// Cluster of every measured (view, light), view-major.
    pub cluster_table: Vec<u16>,
    /// One model per cluster.
    pub subspaces: Vec<SubspaceModel>,
    /// The surface relief, if estimated.
    pub range_map: Option<RangeMap>,
}

impl MaterialModel {
    /// Number of pyramid levels.
    pub fn levels(&self) -> usize {
        self.subspaces.first().map_or(0, |s| s.levels.len())
    }

    /// The smallest side, pixels, a synthesis of this model can have: `2^(levels - 1)`, so
    /// that every pyramid level keeps at least one pixel a side (and a tileable size divisible
    /// by it halves exactly). The one size rule for synthesis, tiling and rendering.
    pub fn min_synthesis_side(&self) -> usize {
        let levels = self.subspaces.iter().map(|s| s.levels.len()).max();
        1 << levels
            .unwrap_or(1)
            .max(1)
            .saturating_sub(1)
            .min(usize::BITS as usize - 2)
    }

    /// The cluster of measured pair (view, light).
    pub fn cluster_of(&self, view: usize, light: usize) -> usize {
        usize::from(self.cluster_table[view * self.lights.len() + light])
    }
}
