//! The material model: everything needed to synthesize a BTF, a few tens of kilobytes.

use ndarray::{Array2, Array3};

use super::{ModelError, Result};
use crate::btf::DirectionSet;
use crate::decompose::KlBasis;
use crate::decompose::colour_transfer::{CHROMA_LEVELS, ColourMarginals, DIRECTIONS};
use crate::decompose::marginals::BAND_QUANTILES;
use crate::decompose::marginals::{QUANTILES, QuantileGrid, Quantiles};
use crate::decompose::pyramid::{Taps, apply_separable, pyramid_step};
use crate::geometry::lattice::{Lattice, MIN_PERIOD};
use crate::geometry::relight::{Shading, Shadows};
use crate::mrf::{AnyLevels, ModelKind};

impl std::str::FromStr for ModelKind {
    type Err = super::ModelError;
    fn from_str(s: &str) -> super::Result<Self> {
        Self::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(ModelKind::name).collect();
                let (last, rest) = names.split_last().expect("at least one kind");
                super::ModelError::parameter(
                    "--model",
                    format!("'{s}' is not {} or {last}", rest.join(", ")),
                )
            })
    }
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
    /// Level models, finest first, all of one family.
    pub levels: AnyLevels,
    /// Quantile tables of the measured pyramid bands, if the model matches band marginals.
    pub band_marginals: Option<BandMarginals>,
    /// The measured colour marginals along fixed directions, if the model matches the joint
    /// colour distribution (format version 3).
    pub colour_marginals: Option<ColourMarginals>,
    /// The measured representative's CIE L* quantiles with its relief shading in
    /// (format version 8), if the model matches the synthesis relit for that light to them
    /// ([`LitMarginals`]); only beside a range map.
    pub lit_marginals: Option<LitMarginals>,
}

/// The lightness marginal of a subspace's representative as measured, relief shading and all:
/// the de-shaded colour tables fix the subspace image before bump mapping, but the synthesized
/// relief's shading meets it otherwise than the measured relief met the measured colours, so
/// the relit synthesis missed the measured L* quantiles by 1-5 Lab units where the
/// representative's own marginal was 0.0-0.2 away. Synthesis relights the subspace image for
/// the representative's light and scales each pixel (keeping its chromaticity) so that its L*
/// takes these quantiles (`crate::synthesis`): exact there, near it at the cluster's other
/// lights.
#[derive(Debug, Clone, PartialEq)]
pub struct LitMarginals {
    /// L* quantiles at
    /// [`band_probabilities`](crate::decompose::marginals::band_probabilities),
    /// non-decreasing.
    pub lightness: Vec<f64>,
}

/// The measured L* distribution under every light in the view the range map is registered with
/// (format version 12), relief shading and all. A cluster's lights share one subspace image,
/// relit by the synthesized relief; its lightness was matched to the representative's light
/// only ([`LitMarginals`]), so at the cluster's other lights the L* quantiles missed the
/// measured ones (the leather by 2-3 Lab units at 60-75 degrees). Synthesis maps the finished
/// image's L* (chromaticity kept) onto these tables, blended over the nearest lights with the
/// same barycentric weights as the images, in proportion to the registered view's weight
/// (`crate::synthesis`).
#[derive(Debug, Clone, PartialEq)]
pub struct LightLightness {
    /// The view the tables were measured in.
    pub view: usize,
    /// One table per light, in the order of the model's lights.
    pub tables: Vec<LitMarginals>,
    /// Per light, in the order of the model's lights, the standard deviation of the measured
    /// L* in each detail band of its Laplacian pyramid, finest first (Lab units; format
    /// version 16, `None` before): synthesis scales its bands to them after the table. The
    /// laid exemplar and the relit relief left the built-in leather's bands at 4-16 px 10-26 %
    /// too strong and its coarsest 30-40 % too weak.
    pub spreads: Option<Vec<[f32; LIGHTNESS_BANDS]>>,
    /// Per light, in the order of the model's lights, the measured a* and b* quantiles
    /// ([`LightChroma`]; format version 17, `None` before and for a grey material): synthesis
    /// maps the finished image's a* and b* onto them after the L* table. A cluster's lights
    /// share their representative's chroma: the built-in leather's b* missed the measured
    /// quantiles by 1.0-2.3 Lab units at five of nine lights, the knit's a* by 1.1-1.5 at eight.
    pub chroma: Option<Vec<LightChroma>>,
}

/// A light's measured a* quantiles, then its b* quantiles, each at the factor tables'
/// probabilities ([`QuantileGrid::NormalTails`], [`QUANTILES`] of them), non-decreasing.
pub type LightChroma = [[f32; QUANTILES]; 2];

/// Whether every light has a chroma table pair of finite, non-decreasing values.
fn chroma_fits(chroma: &[LightChroma], lights: usize) -> bool {
    chroma.len() == lights
        && chroma
            .iter()
            .flatten()
            .all(|t| t.iter().all(|v| v.is_finite()) && t.windows(2).all(|w| w[0] <= w[1]))
}

/// Detail bands of the L* pyramid whose spread [`LightLightness::spreads`] keeps: about 1 to
/// 16 px. The coarse rest is left out: an enlargement's rest holds scales the measured image
/// has no sample of.
pub const LIGHTNESS_BANDS: usize = 5;

impl LitMarginals {
    /// Whether the table holds [`BAND_QUANTILES`] non-decreasing finite values.
    fn is_table(&self) -> bool {
        let t = &self.lightness;
        t.len() == BAND_QUANTILES
            && t.iter().all(|v| v.is_finite())
            && t.windows(2).all(|w| w[0] <= w[1])
    }
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
    /// Heights in texels of the measured image, row-major, `rows * cols` samples: all of the
    /// image averaged over `step` x `step` blocks, or a window of it at every pixel (`step`
    /// 1), where an exemplar is cut too.
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
    /// Which shadows the relief casts when it relights an image (attached only in files from
    /// before cast shadows were stored).
    pub shadows: Shadows,
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

    /// How the relief shades measured light `light`: its fitted strength and the map's shadows.
    pub fn shading_of(&self, light: usize) -> Shading {
        self.shading_at(self.strength_of(light))
    }

    /// The map's shadows at bump strength `strength`.
    pub fn shading_at(&self, strength: f64) -> Shading {
        Shading {
            strength,
            shadows: self.shadows,
        }
    }
}

/// The parts of a [`MaterialModel`], checked by [`MaterialModel::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct MaterialParts {
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
    /// The structure exemplar, if stored (models without a range map).
    pub exemplar: Option<Exemplar>,
    /// The periodic part, if the material was found near-regular.
    pub periodic: Option<PeriodicPart>,
    /// Per measured (view, light), view-major like the cluster table, the gain (> 0) that
    /// brings the synthesis from its subspace image to the pair's measured mean luminance:
    /// the images of one subspace differ in brightness, and a relief's shadows that fall
    /// elsewhere in a synthesis than in the photograph change the mean. Empty: 1 for every
    /// pair (files before version 5).
    pub pair_gains: Vec<f32>,
    /// The measured L* quantiles under every light in the range map's view, if stored
    /// (format version 12; only beside a range map).
    pub light_lightness: Option<LightLightness>,
}

/// Most samples per lattice period and axis a periodic tile keeps (larger periods are
/// resampled to it).
pub const MAX_TILE_SAMPLES: usize = 32;

/// Most principal deviations the subspace images' and lights' periods are stored with (8-bit
/// codes from format version 19, 3 KB each at 32 x 32 samples, 1 KB where grey from version
/// 20; at most 8 at 16 bits before, 20 before version 20). Measured (knit, 128^2, 20
/// clusters, nine frontal lights, x the another-crop level, seed 1, with the lattice's cubic
/// sampling): 8 deviations x3.58, 20 x2.41 (colour, shaped by the subspaces alone); grey and
/// shaped by the lights too, 20 x2.59, 32 x2.22, 48 x1.93 (the 0.1 % residual rule stopped
/// near there when 64 were allowed; 48 in colour x1.97 but a 191,611-byte file).
pub const MAX_PERIOD_COMPONENTS: usize = 48;

/// Fields of one length, one per subspace image, stored compactly: their mean and a few
/// principal deviations, with each subspace's weights on the deviations (the subspace images
/// of one surface differ mostly by light, so a few deviations hold most of their variety).
#[derive(Debug, Clone, PartialEq)]
pub struct Principal {
    /// The mean, then the principal deviations, all of one length.
    pub basis: Vec<Vec<f32>>,
    /// Per subspace, one weight per deviation.
    pub weights: Vec<Vec<f32>>,
}

impl Principal {
    /// Subspace `k`'s coefficients on the whole basis: 1 for the mean, then its weights.
    pub fn coefficients(&self, k: usize) -> Option<Vec<f64>> {
        let weights = self.weights.get(k)?;
        Some(
            std::iter::once(1.0)
                .chain(weights.iter().map(|&w| f64::from(w)))
                .collect(),
        )
    }

    /// Drops the last deviation and every weight on it; `false` where only the mean is left.
    fn drop_deviation(&mut self) -> bool {
        if self.basis.len() < 2 {
            return false;
        }
        self.basis.pop();
        for w in &mut self.weights {
            w.pop();
        }
        true
    }

    /// Subspace `k`'s field: the mean plus its weighted deviations.
    pub fn combined(&self, k: usize) -> Option<Vec<f64>> {
        self.combined_with(self.weights.get(k)?)
    }

    /// The mean plus the deviations with `weights` (one a deviation; missing ones are 0).
    pub fn combined_with(&self, weights: &[f32]) -> Option<Vec<f64>> {
        self.combined_by(weights.iter().map(|&w| f64::from(w)))
    }

    /// [`Principal::combined_with`] with weights in double precision (blends of weights).
    pub fn combined_by(&self, weights: impl IntoIterator<Item = f64>) -> Option<Vec<f64>> {
        let mut field = vec![0.0; self.basis.first()?.len()];
        let coefficients = std::iter::once(1.0).chain(weights);
        for (c, b) in coefficients.zip(&self.basis) {
            for (f, &v) in field.iter_mut().zip(b) {
                *f += c * f64::from(v);
            }
        }
        Some(field)
    }

    /// Whether it holds `clusters` subspaces' weights and 1 to `1 + max_deviations` basis
    /// fields of `len` values, every value finite.
    fn fits(&self, len: usize, clusters: usize, max_deviations: usize) -> bool {
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        (1..=1 + max_deviations).contains(&self.basis.len())
            && self.basis.iter().all(|b| b.len() == len && finite(b))
            && self.weights.len() == clusters
            && self
                .weights
                .iter()
                .all(|w| w.len() == self.basis.len() - 1 && finite(w))
    }
}

/// The periodic part of a near-regular material (issue 11; Haindl and Hatka's near-regular
/// textures): per subspace image the mean over its lattice periods, in linear RGB, whose
/// luminance the image was divided by before its MRF was fitted (the MRF models the stochastic
/// ratio, the period carries the weave); and the range map's mean period, which replaces the
/// quilted range map so relief and colour keep one lattice. The subspace images' periods differ
/// mostly by light, so they are stored as a mean period (16-bit codes, 6 KB at 32 x 32
/// samples) and principal deviations (8-bit codes; grey from format version 20, 1 KB each)
/// with per-subspace weights, not one period each.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodicPart {
    /// Periods along rows and columns, measured pixels.
    pub lattice: Lattice,
    /// Samples per period along rows (1..=[`MAX_TILE_SAMPLES`]).
    pub rows: usize,
    /// Samples per period along columns (1..=[`MAX_TILE_SAMPLES`]).
    pub cols: usize,
    /// The periods: their mean and up to [`MAX_PERIOD_COMPONENTS`] principal deviations, `3 *
    /// rows * cols` values each, natural logarithms of linear RGB (a light's gain is a shift
    /// there, and every period stays positive), channel-major then row-major.
    pub periods: Principal,
    /// The range map's heights over one period (texels of the measured image), `rows * cols`
    /// values, exactly when the model has a range map.
    pub heights: Option<Vec<f32>>,
    /// Every measured light's own weights on the period deviations in the range map's view,
    /// where stored (format version 16): a light's period (its cast shadows, the shading the
    /// relief leaves) differs from its cluster representative's, which may even be seen
    /// from another view.
    pub light_weights: Option<LightWeights>,
}

impl PeriodicPart {
    /// Subspace `k`'s period as (3, rows, cols), linear RGB: the exponential of the mean plus
    /// its weighted deviations (stored as logarithms).
    pub fn tile(&self, k: usize) -> Option<Array3<f64>> {
        self.tile_of(self.periods.combined(k)?)
    }

    /// Measured light `l`'s own period in the light weights' view, as [`PeriodicPart::tile`]
    /// gives a subspace's; `None` without light weights.
    pub fn light_tile(&self, l: usize) -> Option<Array3<f64>> {
        let weights = self.light_weights.as_ref()?.weights.get(l)?;
        self.tile_of(self.periods.combined_with(weights)?)
    }

    /// Whether every deviation is grey: its three channels' logarithms equal, as the shading
    /// and shadows a light changes are and as analysis stores them (format version 20 keeps
    /// one plane of such deviations). A period of no samples (no model holds one) is not.
    pub fn grey_deviations(&self) -> bool {
        let plane = self.rows * self.cols;
        plane > 0
            && self.periods.basis.iter().skip(1).all(|d| {
                let (first, rest) = d.split_at(plane.min(d.len()));
                rest.chunks(plane).all(|c| c == first)
            })
    }

    /// The period with `weights` on the deviations (a blend of lights' or subspaces' weights),
    /// as [`PeriodicPart::tile`] gives a subspace's.
    pub fn tile_with(&self, weights: impl IntoIterator<Item = f64>) -> Option<Array3<f64>> {
        self.tile_of(self.periods.combined_by(weights)?)
    }

    /// A period's logarithms as linear RGB, (3, rows, cols).
    fn tile_of(&self, logarithms: Vec<f64>) -> Option<Array3<f64>> {
        Array3::from_shape_vec((3, self.rows, self.cols), logarithms)
            .ok()
            .map(|t| t.mapv(f64::exp))
    }

    /// The range map's period as (rows, cols), if stored.
    pub fn height_tile(&self) -> Option<Array2<f64>> {
        let h = self.heights.as_ref()?;
        Some(Array2::from_shape_fn((self.rows, self.cols), |(y, x)| {
            f64::from(h[y * self.cols + x])
        }))
    }
}

/// Most principal deviations the subspace images' exemplar crops are stored with (8 before
/// format version 21).
pub const MAX_EXEMPLAR_COMPONENTS: usize = 16;

/// The largest [`Exemplar::step`].
pub const MAX_EXEMPLAR_STEP: usize = 16;

/// A compact exemplar of the material's structure (issue 11: a photograph has no range map to
/// carry it): the CIE L* of the same crop of every subspace image, at the measured pixel
/// scale, stored as their mean and a few principal deviations. At synthesis the crops are
/// quilted ([`crate::geometry::quilt`]) to the output size, every one with the same patches,
/// and subspace `k`'s detail finer than a patch replaces the MRF's in its L*; the variation
/// coarser than a patch comes from where [`CoarseSource`] says, and the quilt repeats on no
/// grid either way. One layout for all subspaces keeps
/// the structure the same surface under every light, and each subspace keeps its own detail
/// (the shading of a relief, its shadows and highlights, differ from light to light).
#[derive(Debug, Clone, PartialEq)]
pub struct Exemplar {
    /// Rows of the crop, samples.
    pub rows: usize,
    /// Columns of the crop, samples.
    pub cols: usize,
    /// Texels per sample along each axis (1..=[`MAX_EXEMPLAR_STEP`]; format version 14, older
    /// files 1): a capture too large for a crop at every texel keeps all of it, averaged over
    /// `step` x `step` blocks like its range map, so its structures fit the quilt's patches.
    pub step: usize,
    /// The crops' L*: mean and up to [`MAX_EXEMPLAR_COMPONENTS`] principal deviations,
    /// `rows * cols` values each, row-major.
    pub lightness: Principal,
    /// How finely the L* deviations are stored (the mean always has 8-bit codes).
    pub deviation_codes: DeviationCodes,
    /// The crops' chroma at a coarser sampling, if stored (format version 6).
    pub chroma: Option<ExemplarChroma>,
    /// Where the synthesis takes the L* variation coarser than a patch from (format version
    /// 11; older files: the MRF).
    pub coarse: CoarseSource,
    /// Every measured light's own weights on the L* deviations, where stored.
    pub light_weights: Option<LightWeights>,
}

/// Every measured light in one view as weights on the principal deviations of a
/// [`Principal`] (the exemplar's L* crops, or the periods): a light's de-shaded detail (its
/// cast shadows, highlights and what the relief's shading leaves) differs from its cluster
/// representative's.
#[derive(Debug, Clone, PartialEq)]
pub struct LightWeights {
    /// The view the fields were measured in (the range map's registered view).
    pub view: usize,
    /// One row per light, in the order of the model's lights: a weight per deviation.
    pub weights: Vec<Vec<f32>>,
}

impl LightWeights {
    /// Whether it holds a view of `views`, a row for each of `lights` lights and, in each, one
    /// finite weight per deviation of `fields`.
    fn fits(&self, views: usize, lights: usize, fields: &Principal) -> bool {
        self.view < views
            && self.weights.len() == lights
            && self
                .weights
                .iter()
                .all(|w| w.len() + 1 == fields.basis.len() && w.iter().all(|v| v.is_finite()))
    }
}

/// Where a synthesis with an exemplar takes the L* variation coarser than the exemplar's
/// patches (the Gaussian split at [`crate::geometry::detail_scale`]; the coarser chroma is
/// always the MRF's). Analysis chooses ([`crate::analysis::AnalysisOptions::coarse`]); on
/// the built-in leather the MRF's coarse L* drew blotches the measured leather lacks (nine
/// frontal lights, seeds 1-4: x1.44 / 1.31 / 1.39 / 1.62 the another-crop level with it,
/// x1.20 / 1.30 / 1.29 / 1.27 without). The laid crops' coarse chroma as well put colour
/// steps at the quilt's cuts through the built-in stones (a* fine share up to a quarter
/// further from the measured at 128^2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CoarseSource {
    /// The MRF's bands: the laid crops bring only the detail finer than a patch.
    Mrf,
    /// The laid crops' own L*, shifted to the MRF plane's mean.
    Laid,
}

/// Code width of an exemplar's stored L* deviations. The file keeps the values as quantised,
/// so a model read and written again stays the same; analysis quantises to what it will write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviationCodes {
    /// 8-bit codes (format versions 5 to 8).
    Byte,
    /// 4-bit codes, two a byte (format version 9): twice the deviations in the same bytes.
    /// Measured on the built-in materials (128^2, 20 subspaces, the relit representative
    /// quilted and judged): eight deviations at 16 levels score as eight unquantised ones,
    /// and six 4-bit deviations beat three 8-bit ones.
    Nibble,
}

/// The CIE a* and b* of an exemplar's crops, averaged over `step` x `step` blocks (chroma
/// needs less resolution than lightness; the L* detail carries the edges), stored like the
/// lightness as a mean and principal deviations. Laid with the lightness' patches at
/// synthesis, it keeps a stone's or a thread's own colour together with its shape, where the
/// MRF's independent chroma factors mottle it.
#[derive(Debug, Clone, PartialEq)]
pub struct ExemplarChroma {
    /// Crop pixels per stored sample along each axis (1..=16).
    pub step: usize,
    /// Stored samples along the rows: `ceil(exemplar rows / step)`.
    pub rows: usize,
    /// Stored samples along the columns: `ceil(exemplar cols / step)`.
    pub cols: usize,
    /// Mean and principal deviations of the crops' chroma, `2 * rows * cols` values each:
    /// the a* plane, then the b* plane, row-major.
    pub fields: Principal,
}

/// The largest block side [`ExemplarChroma`] averages over.
pub const MAX_CHROMA_STEP: usize = 16;

impl ExemplarChroma {
    /// Basis field `j`'s (a*, b*) planes at the crop's `rows` x `cols` pixels: the block means
    /// interpolated bilinearly between the blocks' centres (held flat beyond the outer ones).
    pub fn crop_planes(&self, j: usize, rows: usize, cols: usize) -> Option<[Array2<f64>; 2]> {
        let step = self.step as f64;
        // Fractional stored index of pixel p, and its two neighbours with the second's weight.
        let axis = |p: usize, n: usize| {
            let u = ((p as f64 + 0.5) / step - 0.5).clamp(0.0, (n - 1) as f64);
            let i = (u.floor() as usize).min(n - 1);
            (i, (i + 1).min(n - 1), u - i as f64)
        };
        let ys: Vec<_> = (0..rows).map(|y| axis(y, self.rows)).collect();
        let xs: Vec<_> = (0..cols).map(|x| axis(x, self.cols)).collect();
        let [a, b] = self.planes(j)?;
        Some([a, b].map(|plane| {
            Array2::from_shape_fn((rows, cols), |(y, x)| {
                let ((y0, y1, fy), (x0, x1, fx)) = (ys[y], xs[x]);
                let top = plane[(y0, x0)] * (1.0 - fx) + plane[(y0, x1)] * fx;
                let bottom = plane[(y1, x0)] * (1.0 - fx) + plane[(y1, x1)] * fx;
                top * (1.0 - fy) + bottom * fy
            })
        }))
    }

    /// Basis field `j` as its (a*, b*) planes at the stored sampling.
    pub fn planes(&self, j: usize) -> Option<[Array2<f64>; 2]> {
        let b = self.fields.basis.get(j)?;
        let n = self.rows * self.cols;
        let plane = |c: usize| {
            Array2::from_shape_vec(
                (self.rows, self.cols),
                b.get(c * n..(c + 1) * n)?
                    .iter()
                    .map(|&v| f64::from(v))
                    .collect(),
            )
            .ok()
        };
        Some([plane(0)?, plane(1)?])
    }
}

impl Exemplar {
    /// The mean L* of the mean crop (0 without one).
    pub fn mean_lightness(&self) -> f64 {
        self.lightness.basis.first().map_or(0.0, |b| {
            b.iter().map(|&v| f64::from(v)).sum::<f64>() / b.len().max(1) as f64
        })
    }

    /// Basis field `j` (0: the mean crop, then the deviations) as a (rows, cols) plane.
    pub fn plane(&self, j: usize) -> Option<Array2<f64>> {
        let b = self.lightness.basis.get(j)?;
        Array2::from_shape_vec(
            (self.rows, self.cols),
            b.iter().map(|&v| f64::from(v)).collect(),
        )
        .ok()
    }

    /// Subspace `k`'s crop as a (rows, cols) plane.
    pub fn crop(&self, k: usize) -> Option<Array2<f64>> {
        Array2::from_shape_vec((self.rows, self.cols), self.lightness.combined(k)?).ok()
    }

    /// Drops the last L* deviation (with every subspace's and light's weight on it) or, with
    /// none left, the last chroma deviation; `false` where neither has one.
    pub fn drop_deviation(&mut self) -> bool {
        if self.lightness.drop_deviation() {
            for w in self.light_weights.iter_mut().flat_map(|l| &mut l.weights) {
                w.pop();
            }
            return true;
        }
        self.chroma
            .as_mut()
            .is_some_and(|c| c.fields.drop_deviation())
    }
}

/// A whole material: clustering, subspace models and range map. Written as `.btfm`. Only
/// consistent models exist (see [`MaterialModel::new`]); the band model family is that of the
/// subspaces' levels.
#[derive(Debug, Clone, PartialEq)]
pub struct MaterialModel {
    parts: MaterialParts,
}

/// The most views, lights or clusters a model holds (they are 16-bit in the file).
const MAX_COUNT: usize = u16::MAX as usize;

impl MaterialModel {
    /// Checks that the parts fit together: non-zero image size; at most 65535 views, lights
    /// and clusters; one cluster table entry per (view, light), each naming a subspace; every
    /// subspace of the same family and the same number of levels (1..=16), with its
    /// representative among the directions and band tables (if any) for every level; a
    /// range map with `rows * cols` samples, rows, columns and step in 1..=65535, and no
    /// strength or one per light. (So the file's 8- and 16-bit counts never truncate.)
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] (named `model`) saying which part does not fit.
    pub fn new(parts: MaterialParts) -> Result<Self> {
        let bad = |reason: String| Err(ModelError::parameter("model", reason));
        let (nv, nl) = (parts.views.len(), parts.lights.len());
        if parts.width == 0 || parts.height == 0 {
            return bad(format!("image size {}x{}", parts.width, parts.height));
        }
        if nv == 0 || nl == 0 || nv > MAX_COUNT || nl > MAX_COUNT {
            return bad(format!("{nv} views x {nl} lights (1..={MAX_COUNT} each)"));
        }
        let clusters = parts.subspaces.len();
        if clusters == 0 || clusters > MAX_COUNT {
            return bad(format!("{clusters} subspaces (1..={MAX_COUNT})"));
        }
        if parts.cluster_table.len() != nv * nl {
            return bad(format!(
                "{} cluster table entries for {nv} x {nl} pairs",
                parts.cluster_table.len()
            ));
        }
        if let Some(c) = parts
            .cluster_table
            .iter()
            .find(|&&c| usize::from(c) >= clusters)
        {
            return bad(format!("cluster table names cluster {c} of {clusters}"));
        }
        let first = &parts.subspaces[0].levels;
        let (kind, levels) = (first.kind(), first.len());
        if levels > usize::from(super::format::MAX_LEVELS) {
            return bad(format!(
                "{levels} pyramid levels (1..={} accepted)",
                super::format::MAX_LEVELS
            ));
        }
        let coloured = parts.subspaces[0].colour_marginals.is_some();
        let lit = parts.subspaces[0].lit_marginals.is_some();
        if lit && parts.range_map.is_none() {
            return bad("lit lightness tables without a range map to light them".to_string());
        }
        for (k, s) in parts.subspaces.iter().enumerate() {
            if s.colour_marginals.is_some() != coloured {
                return bad(format!(
                    "subspace {k} {} colour tables, subspace 0 {}",
                    if coloured { "lacks" } else { "has" },
                    if coloured { "has them" } else { "not" }
                ));
            }
            if s.levels.kind() != kind || s.levels.len() != levels {
                return bad(format!(
                    "subspace {k} has {} {} levels, subspace 0 {levels} {kind} levels",
                    s.levels.len(),
                    s.levels.kind()
                ));
            }
            let (v, l) = s.representative;
            if usize::from(v) >= nv || usize::from(l) >= nl {
                return bad(format!(
                    "subspace {k}: representative ({v}, {l}) outside the direction sets"
                ));
            }
            if let Some(c) = &s.colour_marginals
                && (c.tables.len() != DIRECTIONS
                    || c.tables.iter().any(|t| {
                        t.len() != BAND_QUANTILES
                            || t.iter().any(|v| !v.is_finite())
                            || t.windows(2).any(|w| w[1] < w[0])
                    }))
            {
                return bad(format!(
                    "subspace {k}: colour tables are not {DIRECTIONS} non-decreasing tables of {BAND_QUANTILES} finite values"
                ));
            }
            if let Some(c) = &s.colour_marginals {
                let first = parts.subspaces[0].colour_marginals.as_ref();
                // A file holds couplings for every subspace or for none (format::couplings).
                if c.coupling.is_some() != first.is_some_and(|f| f.coupling.is_some()) {
                    return bad(format!(
                        "subspace {k}: a chroma-lightness coupling where subspace 0 has none, or none where it has one"
                    ));
                }
                if c.coupling
                    .iter()
                    .flatten()
                    .flatten()
                    .any(|v| !v.is_finite())
                {
                    return bad(format!(
                        "subspace {k}: a chroma-lightness coupling is not finite"
                    ));
                }
                let spread = c.chroma_spread.as_ref();
                let first = first.and_then(|c| c.chroma_spread.as_ref()).map(Vec::len);
                if spread.map(Vec::len) != first
                    || spread.is_some_and(|s| {
                        s.is_empty()
                            || s.len() > CHROMA_LEVELS
                            || s.iter().flatten().any(|v| !(v.is_finite() && *v >= 0.0))
                    })
                {
                    return bad(format!(
                        "subspace {k}: chroma spreads are not as many bands (1 to {CHROMA_LEVELS}) as subspace 0's, or not finite and non-negative"
                    ));
                }
            }
            if s.lit_marginals.is_some() != lit {
                return bad(format!(
                    "subspace {k} {} a lit lightness table, subspace 0 {}",
                    if lit { "lacks" } else { "has" },
                    if lit { "has one" } else { "not" }
                ));
            }
            if let Some(t) = &s.lit_marginals
                && !t.is_table()
            {
                return bad(format!(
                    "subspace {k}: its lit lightness table is not {BAND_QUANTILES} non-decreasing finite values"
                ));
            }
            if let Some(b) = &s.band_marginals
                && b.tables.len() != levels
            {
                return bad(format!(
                    "subspace {k}: band tables for {} of {levels} levels",
                    b.tables.len()
                ));
            }
        }
        if let Some(e) = &parts.exemplar
            && !(1..=MAX_EXEMPLAR_STEP).contains(&e.step)
        {
            return bad(format!(
                "exemplar step of {} texels (1..={MAX_EXEMPLAR_STEP})",
                e.step
            ));
        }
        if let Some(e) = &parts.exemplar
            && (e.rows == 0
                || e.cols == 0
                || e.rows > MAX_COUNT
                || e.cols > MAX_COUNT
                || !e
                    .lightness
                    .fits(e.rows * e.cols, clusters, MAX_EXEMPLAR_COMPONENTS))
        {
            return bad(format!(
                "exemplar of {} x {} samples with {} basis crops (1..={}, rows x cols finite values each) and {} weight rows for {clusters} subspaces",
                e.rows,
                e.cols,
                e.lightness.basis.len(),
                1 + MAX_EXEMPLAR_COMPONENTS,
                e.lightness.weights.len()
            ));
        }
        if let Some(e) = &parts.exemplar
            && let Some(c) = &e.chroma
            && !((1..=MAX_CHROMA_STEP).contains(&c.step)
                && c.rows == e.rows.div_ceil(c.step)
                && c.cols == e.cols.div_ceil(c.step)
                && c.fields
                    .fits(2 * c.rows * c.cols, clusters, MAX_EXEMPLAR_COMPONENTS))
        {
            return bad(format!(
                "exemplar chroma of {} x {} samples at step {} (1..={MAX_CHROMA_STEP}, covering the {} x {} crop) with {} basis fields (1..={}, 2 x rows x cols finite values each) and {} weight rows for {clusters} subspaces",
                c.rows,
                c.cols,
                c.step,
                e.rows,
                e.cols,
                c.fields.basis.len(),
                1 + MAX_EXEMPLAR_COMPONENTS,
                c.fields.weights.len()
            ));
        }
        if let Some(p) = &parts.periodic {
            let period_ok = |v: f64| v.is_finite() && (MIN_PERIOD..=MAX_COUNT as f64).contains(&v);
            let samples = 1..=MAX_TILE_SAMPLES;
            let values = 3 * p.rows * p.cols;
            let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
            if !(period_ok(p.lattice.rows)
                && period_ok(p.lattice.cols)
                && samples.contains(&p.rows)
                && samples.contains(&p.cols)
                && p.periods.fits(values, clusters, MAX_PERIOD_COMPONENTS)
                && p.heights.is_some() == parts.range_map.is_some()
                && p.heights
                    .as_ref()
                    .is_none_or(|h| h.len() == p.rows * p.cols && finite(h))
                && p.light_weights
                    .as_ref()
                    .is_none_or(|l| p.heights.is_some() && l.fits(nv, nl, &p.periods)))
            {
                return bad(format!(
                    "periodic part: periods {} x {} ({MIN_PERIOD}..={MAX_COUNT}), {} x {} samples (1..={MAX_TILE_SAMPLES}), {} basis periods (1..={}) of 3 x samples finite values, {} weight rows for {clusters} subspaces (one finite weight per deviation), heights {} with range map {}, light weights only with heights (a view of {nv}, {nl} rows of one finite weight per deviation)",
                    p.lattice.rows,
                    p.lattice.cols,
                    p.rows,
                    p.cols,
                    p.periods.basis.len(),
                    1 + MAX_PERIOD_COMPONENTS,
                    p.periods.weights.len(),
                    p.heights.is_some(),
                    parts.range_map.is_some()
                ));
            }
        }
        if !parts.pair_gains.is_empty()
            && (parts.pair_gains.len() != nv * nl
                || parts
                    .pair_gains
                    .iter()
                    .any(|g| !(g.is_finite() && *g > 0.0)))
        {
            return bad(format!(
                "{} pair gains for {nv} x {nl} pairs (all finite and positive)",
                parts.pair_gains.len()
            ));
        }
        if let Some(t) = &parts.light_lightness
            && (parts.range_map.is_none()
                || t.view >= nv
                || t.tables.len() != nl
                || !t.tables.iter().all(LitMarginals::is_table)
                || t.spreads.as_ref().is_some_and(|s| {
                    s.len() != nl || !s.iter().flatten().all(|v| v.is_finite() && *v >= 0.0)
                })
                || t.chroma.as_ref().is_some_and(|c| !chroma_fits(c, nl)))
        {
            return bad(format!(
                "light lightness tables for view {} of {nv}, {} tables for {nl} lights (each {BAND_QUANTILES} non-decreasing finite values), {} band spreads (one row a light, finite, not negative), {} chroma table pairs (one a light, {QUANTILES} non-decreasing finite values each), range map {}",
                t.view,
                t.tables.len(),
                t.spreads.as_ref().map_or(0, Vec::len),
                t.chroma.as_ref().map_or(0, Vec::len),
                parts.range_map.is_some()
            ));
        }
        if let Some(e) = &parts.exemplar
            && let Some(l) = &e.light_weights
            && !l.fits(nv, nl, &e.lightness)
        {
            return bad(format!(
                "exemplar light weights for view {} of {nv}, {} rows for {nl} lights (one finite weight per L* deviation)",
                l.view,
                l.weights.len()
            ));
        }
        if let Some(r) = &parts.range_map {
            let sides = [r.rows, r.cols, r.step];
            if sides.iter().any(|&n| n == 0 || n > MAX_COUNT) || r.heights.len() != r.rows * r.cols
            {
                return bad(format!(
                    "range map of {} samples as {}x{} with step {}",
                    r.heights.len(),
                    r.rows,
                    r.cols,
                    r.step
                ));
            }
            if !r.strength.is_empty() && r.strength.len() != nl {
                return bad(format!(
                    "{} bump strengths for {nl} lights",
                    r.strength.len()
                ));
            }
        }
        Ok(Self { parts })
    }

    /// The parts, to change and check again with [`MaterialModel::new`].
    pub fn into_parts(self) -> MaterialParts {
        self.parts
    }

    /// The band model family.
    pub fn kind(&self) -> ModelKind {
        self.parts.subspaces[0].levels.kind()
    }

    /// The measured view directions.
    pub fn views(&self) -> &DirectionSet {
        &self.parts.views
    }

    /// The measured light directions.
    pub fn lights(&self) -> &DirectionSet {
        &self.parts.lights
    }

    /// Width of the measured images, pixels.
    pub fn width(&self) -> u32 {
        self.parts.width
    }

    /// Height of the measured images, pixels.
    pub fn height(&self) -> u32 {
        self.parts.height
    }

    /// Cluster of every measured (view, light), view-major; each entry names a subspace.
    pub fn cluster_table(&self) -> &[u16] {
        &self.parts.cluster_table
    }

    /// The gain of measured pair (`view`, `light`) (see [`MaterialParts::pair_gains`]); 1 for
    /// a model without gains or a pair outside the sets.
    pub fn pair_gain(&self, view: usize, light: usize) -> f64 {
        let index = view * self.parts.lights.len() + light;
        self.parts
            .pair_gains
            .get(index)
            .map_or(1.0, |&g| f64::from(g))
    }

    /// Every pair's gain, view-major (empty: 1 for every pair).
    pub fn pair_gains(&self) -> &[f32] {
        &self.parts.pair_gains
    }

    /// The measured L* quantiles under every light in the range map's view, if stored.
    pub fn light_lightness(&self) -> Option<&LightLightness> {
        self.parts.light_lightness.as_ref()
    }

    /// One model per cluster (at least one).
    pub fn subspaces(&self) -> &[SubspaceModel] {
        &self.parts.subspaces
    }

    /// The surface relief, if estimated.
    pub fn range_map(&self) -> Option<&RangeMap> {
        self.parts.range_map.as_ref()
    }

    /// The structure exemplar, if the model stores one.
    pub fn exemplar(&self) -> Option<&Exemplar> {
        self.parts.exemplar.as_ref()
    }

    /// The periodic part, if the material was found near-regular.
    pub fn periodic(&self) -> Option<&PeriodicPart> {
        self.parts.periodic.as_ref()
    }

    /// Number of pyramid levels (the same in every subspace).
    pub fn levels(&self) -> usize {
        self.parts.subspaces[0].levels.len()
    }

    /// The smallest side, pixels, a synthesis of this model can have: the pyramid step
    /// ([`pyramid_step`]), so that every level keeps at least one pixel a side (and a
    /// tileable size divisible by it halves exactly). The one size rule for synthesis, tiling
    /// and rendering.
    pub fn min_synthesis_side(&self) -> usize {
        pyramid_step(self.levels())
    }

    /// The cluster of measured pair (view, light).
    ///
    /// # Errors
    /// `view` or `light` is not a measured direction's index.
    pub fn cluster_of(&self, view: usize, light: usize) -> Result<usize> {
        let (nv, nl) = (self.parts.views.len(), self.parts.lights.len());
        if view >= nv || light >= nl {
            return Err(ModelError::parameter(
                "direction",
                format!("pair ({view}, {light}) of {nv} views x {nl} lights"),
            ));
        }
        Ok(usize::from(self.parts.cluster_table[view * nl + light]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::Direction;
    use crate::decompose::ColourSpace;
    use crate::decompose::colour_transfer::{Coupling, LIGHTNESS_BINS};
    use crate::mrf::{BandModel, Car2dModel, Car3dModel, GmrfModel, Levels};

    /// A subspace of `levels` constant levels of model `M`.
    fn flat<M: BandModel>(levels: usize, model: M) -> SubspaceModel
    where
        Levels<M>: Into<AnyLevels>,
    {
        let per_level = vec![model; Levels::<M>::PER_LEVEL];
        SubspaceModel {
            representative: (0, 1),
            kl: KlBasis::identity(ColourSpace::LinearRgb),
            marginals: [[0.0; QUANTILES]; 3],
            marginal_grid: QuantileGrid::Uniform,
            levels: Levels::new(vec![per_level; levels]).unwrap().into(),
            band_marginals: None,
            colour_marginals: None,
            lit_marginals: None,
        }
    }

    /// Two views, three lights, two 2D CAR subspaces of two levels; pair i in cluster i % 2.
    fn parts() -> MaterialParts {
        let dirs = |n: usize| {
            DirectionSet::new(
                (0..n)
                    .map(|i| Direction::new(10.0 * i as f64, 0.0))
                    .collect(),
            )
            .unwrap()
        };
        MaterialParts {
            views: dirs(2),
            lights: dirs(3),
            width: 8,
            height: 8,
            cluster_table: (0..6).map(|i| i % 2).collect(),
            subspaces: vec![flat(2, Car2dModel::constant(0.5)); 2],
            range_map: None,
            exemplar: None,
            periodic: None,
            pair_gains: Vec::new(),
            light_lightness: None,
        }
    }

    fn refused(change: impl FnOnce(&mut MaterialParts)) -> String {
        let mut p = parts();
        change(&mut p);
        match MaterialModel::new(p) {
            Ok(_) => panic!("inconsistent parts accepted"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn chroma_blocks_interpolate_a_ramp_back_between_their_centres() {
        // A linear ramp: block means are the ramp at the block centres, and bilinear
        // interpolation between centres is exact for it, up to half a block from the edge.
        let (rows, cols, step) = (12, 10, 2);
        let ramp = Array2::from_shape_fn((rows, cols), |(y, x)| 3.0 * y as f64 - 2.0 * x as f64);
        let means = crate::geometry::downsample(&ramp, step);
        assert_eq!(means.dim(), (6, 5));
        assert!((means[(1, 2)] - (3.0 * 2.5 - 2.0 * 4.5)).abs() < 1e-12);
        let chroma = ExemplarChroma {
            step,
            rows: 6,
            cols: 5,
            fields: Principal {
                basis: vec![
                    means
                        .iter()
                        .chain(means.mapv(|v| -v).iter())
                        .map(|&v| v as f32)
                        .collect(),
                ],
                weights: vec![vec![]],
            },
        };
        let [a, b] = chroma.crop_planes(0, rows, cols).unwrap();
        for y in 1..rows - 1 {
            for x in 1..cols - 1 {
                assert!((a[(y, x)] - ramp[(y, x)]).abs() < 1e-4, "({y}, {x})");
                assert!((b[(y, x)] + ramp[(y, x)]).abs() < 1e-4, "({y}, {x})");
            }
        }
        // Beyond the outer centres the values are held flat.
        assert!((a[(0, 0)] - means[(0, 0)]).abs() < 1e-4);
        assert!(chroma.crop_planes(1, rows, cols).is_none());
    }

    #[test]
    fn consistent_parts_make_a_model_of_their_levels_kind() {
        let model = MaterialModel::new(parts()).unwrap();
        assert_eq!(model.kind(), ModelKind::Car2d);
        assert_eq!((model.levels(), model.min_synthesis_side()), (2, 2));
        let mut p = parts();
        p.subspaces = vec![
            flat(
                2,
                Car3dModel::fit(ndarray::Array3::zeros((3, 4, 4)).view(), 1).model
            );
            2
        ];
        assert_eq!(MaterialModel::new(p).unwrap().kind(), ModelKind::Car3d);
    }

    #[test]
    fn inconsistent_parts_are_refused_with_the_reason() {
        let e = refused(|p| p.cluster_table[4] = 2);
        assert!(e.contains("names cluster 2 of 2"), "{e}");
        let e = refused(|p| p.cluster_table.truncate(5));
        assert!(e.contains("5 cluster table entries for 2 x 3"), "{e}");
        let e = refused(|p| p.pair_gains = vec![1.0; 5]);
        assert!(e.contains("5 pair gains for 2 x 3 pairs"), "{e}");
        let e = refused(|p| p.pair_gains = vec![1.0, 0.0, 1.0, 1.0, 1.0, 1.0]);
        assert!(e.contains("6 pair gains"), "{e}");
        let gained = MaterialModel::new(MaterialParts {
            pair_gains: vec![1.0, 2.0, 1.0, 1.0, 1.0, 0.5],
            ..parts()
        })
        .unwrap();
        assert_eq!(gained.pair_gain(0, 1), 2.0);
        assert_eq!(gained.pair_gain(1, 2), 0.5);
        assert_eq!(MaterialModel::new(parts()).unwrap().pair_gain(0, 1), 1.0);
        let e = refused(|p| p.subspaces[1] = flat(2, GmrfModel::constant(0.5)));
        assert!(e.contains("subspace 1 has 2 gmrf levels"), "{e}");
        let e = refused(|p| p.subspaces[1] = flat(3, Car2dModel::constant(0.5)));
        assert!(e.contains("subspace 1 has 3 2dcar levels"), "{e}");
        let e = refused(|p| p.subspaces[0].representative = (2, 0));
        assert!(e.contains("representative (2, 0)"), "{e}");
        let e = refused(|p| p.subspaces.clear());
        assert!(e.contains("0 subspaces"), "{e}");
        let e = refused(|p| p.width = 0);
        assert!(e.contains("image size 0x8"), "{e}");
        // A flat 2 x 3 range map of `samples` heights.
        let flat_map = |samples: usize| RangeMap {
            heights: vec![0.0; samples],
            rows: 2,
            cols: 3,
            step: 1,
            strength: Vec::new(),
            shadows: Shadows::Attached,
        };
        let e = refused(|p| p.range_map = Some(flat_map(5)));
        assert!(e.contains("range map of 5 samples as 2x3"), "{e}");
        let table: Vec<f64> = (0..BAND_QUANTILES).map(|i| i as f64).collect();
        let colours = ColourMarginals {
            tables: vec![table.clone(); DIRECTIONS],
            coupling: None,
            chroma_spread: None,
        };
        let e = refused(|p| p.subspaces[1].colour_marginals = Some(colours.clone()));
        assert!(e.contains("subspace 1 has colour tables"), "{e}");
        let e = refused(|p| {
            for s in &mut p.subspaces {
                s.colour_marginals = Some(colours.clone());
            }
            p.subspaces[0].colour_marginals.as_mut().unwrap().tables[3][7] = f64::NAN;
        });
        assert!(e.contains("subspace 0: colour tables are not"), "{e}");
        // Spreads: every subspace as many bands, finite and non-negative; couplings finite.
        let coloured = |spreads: [Option<Vec<[f64; 2]>>; 2]| {
            let colours = colours.clone();
            move |p: &mut MaterialParts| {
                for (s, spread) in p.subspaces.iter_mut().zip(spreads.clone()) {
                    s.colour_marginals = Some(ColourMarginals {
                        chroma_spread: spread,
                        ..colours.clone()
                    });
                }
            }
        };
        let e = refused(coloured([Some(vec![[1.0, 2.0]]), None]));
        assert!(e.contains("subspace 1: chroma spreads are not"), "{e}");
        let e = refused(coloured([Some(vec![[1.0, 2.0]]), Some(vec![[1.0, -2.0]])]));
        assert!(e.contains("subspace 1: chroma spreads are not"), "{e}");
        let e = refused(coloured([Some(Vec::new()), Some(Vec::new())]));
        assert!(e.contains("subspace 0: chroma spreads are not"), "{e}");
        let long = Some(vec![[0.5, 0.5]; CHROMA_LEVELS + 1]);
        let e = refused(coloured([long.clone(), long]));
        assert!(e.contains("subspace 0: chroma spreads are not"), "{e}");
        let mut spread = parts();
        coloured([Some(vec![[1.0, 2.0]]), Some(vec![[3.0, 0.0]])])(&mut spread);
        assert!(MaterialModel::new(spread).is_ok());
        // Couplings: every subspace or none (the file's layout), each finite.
        let coupled = |couplings: [Option<Coupling>; 2]| {
            move |p: &mut MaterialParts| {
                coloured([None, None])(p);
                for (s, coupling) in p.subspaces.iter_mut().zip(couplings) {
                    s.colour_marginals.as_mut().unwrap().coupling = coupling;
                }
            }
        };
        let even = Some([[0.5, -0.5]; LIGHTNESS_BINS]);
        let e = refused(coupled([None, even]));
        assert!(
            e.contains("subspace 1: a chroma-lightness coupling where"),
            "{e}"
        );
        let e = refused(coupled([even, None]));
        assert!(
            e.contains("subspace 1: a chroma-lightness coupling where"),
            "{e}"
        );
        let mut both = parts();
        coupled([even, even])(&mut both);
        assert!(MaterialModel::new(both).is_ok());
        let e = refused(coupled([
            even,
            Some([[f64::INFINITY, 0.0]; LIGHTNESS_BINS]),
        ]));
        assert!(
            e.contains("subspace 1: a chroma-lightness coupling is not finite"),
            "{e}"
        );
        let lit = LitMarginals {
            lightness: table.clone(),
        };
        let e = refused(|p| {
            for s in &mut p.subspaces {
                s.lit_marginals = Some(lit.clone());
            }
        });
        assert!(e.contains("without a range map"), "{e}");
        let e = refused(|p| {
            p.range_map = Some(flat_map(6));
            p.subspaces[1].lit_marginals = Some(lit.clone());
        });
        assert!(e.contains("subspace 1 has a lit lightness table"), "{e}");
        let e = refused(|p| {
            p.range_map = Some(flat_map(6));
            for s in &mut p.subspaces {
                s.lit_marginals = Some(lit.clone());
            }
            p.subspaces[0].lit_marginals.as_mut().unwrap().lightness[3] = 0.5;
        });
        assert!(
            e.contains("subspace 0: its lit lightness table is not"),
            "{e}"
        );
        // Light tables: one per light of a view the model has, beside a range map.
        let lights = |view: usize, count: usize| LightLightness {
            view,
            tables: vec![lit.clone(); count],
            spreads: Some(vec![[1.0; LIGHTNESS_BANDS]; count]),
            chroma: Some(vec![[[0.0; QUANTILES]; 2]; count]),
        };
        let with_map = |p: &mut MaterialParts| p.range_map = Some(flat_map(6));
        assert!(
            MaterialModel::new(MaterialParts {
                light_lightness: Some(lights(1, 3)),
                range_map: Some(flat_map(6)),
                ..parts()
            })
            .is_ok()
        );
        for (view, count, map) in [(0, 3, false), (2, 3, true), (0, 2, true)] {
            let e = refused(|p| {
                if map {
                    with_map(p);
                }
                p.light_lightness = Some(lights(view, count));
            });
            assert!(e.contains("light lightness tables"), "{e}");
        }
        let e = refused(|p| {
            with_map(p);
            let mut t = lights(0, 3);
            t.tables[2].lightness[5] = f64::NAN;
            p.light_lightness = Some(t);
        });
        assert!(e.contains("light lightness tables"), "{e}");
        // Band spreads: a row a light, none negative or not finite.
        for broken in [
            vec![[1.0; LIGHTNESS_BANDS]; 2],
            vec![[-1.0; LIGHTNESS_BANDS]; 3],
        ] {
            let e = refused(|p| {
                with_map(p);
                let mut t = lights(0, 3);
                t.spreads = Some(broken.clone());
                p.light_lightness = Some(t);
            });
            assert!(e.contains("band spreads"), "{e}");
        }
        // Chroma tables: a pair a light, finite and non-decreasing.
        let rising: [f32; QUANTILES] = std::array::from_fn(|k| k as f32);
        let mut falling = rising;
        falling.reverse();
        let mut not_finite = rising;
        not_finite[3] = f32::NAN;
        for broken in [
            vec![[rising; 2]; 2],
            vec![[rising, falling]; 3],
            vec![[not_finite, rising]; 3],
        ] {
            let e = refused(|p| {
                with_map(p);
                let mut t = lights(0, 3);
                t.chroma = Some(broken.clone());
                p.light_lightness = Some(t);
            });
            assert!(e.contains("chroma table pairs"), "{e}");
        }
        let e = refused(|p| {
            p.exemplar = Some(Exemplar {
                rows: 2,
                cols: 2,
                step: 1,
                lightness: Principal {
                    basis: vec![vec![50.0; 4]],
                    weights: vec![vec![]],
                },
                deviation_codes: DeviationCodes::Byte,
                chroma: None,
                coarse: CoarseSource::Mrf,
                light_weights: None,
            })
        });
        assert!(e.contains("1 weight rows for 2 subspaces"), "{e}");
        // Two subspaces on a mean crop and one deviation: each rebuilds its own crop.
        let exemplar = Exemplar {
            rows: 2,
            cols: 2,
            step: 1,
            lightness: Principal {
                basis: vec![vec![50.0; 4], vec![1.0, -1.0, 2.0, 0.0]],
                weights: vec![vec![0.0], vec![3.0]],
            },
            deviation_codes: DeviationCodes::Byte,
            chroma: None,
            coarse: CoarseSource::Laid,
            light_weights: None,
        };
        let model = MaterialModel::new(MaterialParts {
            exemplar: Some(exemplar.clone()),
            ..parts()
        })
        .unwrap();
        let e = model.exemplar().unwrap();
        assert_eq!(e.crop(0).unwrap(), Array2::from_elem((2, 2), 50.0));
        assert_eq!(
            e.crop(1).unwrap().into_raw_vec_and_offset().0,
            vec![53.0, 47.0, 56.0, 50.0]
        );
        assert!(e.crop(2).is_none());
        let e = refused(|p| {
            let mut broken = exemplar.clone();
            broken.lightness.basis[1][2] = f32::NAN;
            p.exemplar = Some(broken);
        });
        assert!(e.contains("exemplar of 2 x 2 samples"), "{e}");
        // Light weights: a row a light, for a view the model has, a weight a deviation.
        let with_lights = |view: usize, rows: usize, per_row: usize| {
            let mut e = exemplar.clone();
            e.light_weights = Some(LightWeights {
                view,
                weights: vec![vec![0.5; per_row]; rows],
            });
            e
        };
        let lit = MaterialParts {
            exemplar: Some(with_lights(1, 3, 1)),
            ..parts()
        };
        assert!(MaterialModel::new(lit).is_ok());
        for (view, rows, per_row) in [(2, 3, 1), (0, 2, 1), (0, 3, 2)] {
            let e = refused(|p| p.exemplar = Some(with_lights(view, rows, per_row)));
            assert!(e.contains("exemplar light weights"), "{e}");
        }
        // Dropping a deviation drops every weight on it, the lights' too.
        let mut dropped = with_lights(0, 3, 1);
        assert!(dropped.drop_deviation());
        assert_eq!(dropped.lightness.basis.len(), 1);
        assert!(dropped.lightness.weights.iter().all(Vec::is_empty));
        let rows = dropped.light_weights.as_ref().map(|l| &l.weights);
        assert!(rows.is_some_and(|w| w.iter().all(Vec::is_empty)));
        assert!(!dropped.drop_deviation(), "only the mean is left");
        // Chroma must cover the crop at its block side: 2 x 2 crop at step 2 is one sample.
        let with_chroma = |rows: usize, step: usize| {
            let mut e = exemplar.clone();
            e.chroma = Some(ExemplarChroma {
                step,
                rows,
                cols: rows,
                fields: Principal {
                    basis: vec![vec![1.0; 2 * rows * rows]],
                    weights: vec![vec![], vec![]],
                },
            });
            e
        };
        assert!(
            MaterialModel::new(MaterialParts {
                exemplar: Some(with_chroma(1, 2)),
                ..parts()
            })
            .is_ok()
        );
        for (rows, step) in [(2, 2), (1, 0), (1, MAX_CHROMA_STEP + 1)] {
            let e = refused(|p| p.exemplar = Some(with_chroma(rows, step)));
            assert!(e.contains("exemplar chroma of"), "{e}");
        }
        for step in [0, MAX_EXEMPLAR_STEP + 1] {
            let e = refused(|p| {
                p.exemplar = Some(Exemplar {
                    step,
                    ..exemplar.clone()
                })
            });
            assert!(e.contains("exemplar step of"), "{e}");
        }
        let periodic = PeriodicPart {
            lattice: Lattice {
                rows: 8.0,
                cols: 6.5,
            },
            rows: 2,
            cols: 3,
            periods: Principal {
                basis: vec![vec![0.5; 18], vec![0.1; 18]],
                weights: vec![vec![1.0], vec![-6.0]],
            },
            heights: None,
            light_weights: None,
        };
        let model = MaterialModel::new(MaterialParts {
            periodic: Some(periodic.clone()),
            ..parts()
        })
        .unwrap();
        let p = model.periodic().unwrap();
        // The exponential of the mean plus the weighted deviation.
        assert!(
            p.tile(0)
                .unwrap()
                .iter()
                .all(|&v| (v - 0.6f64.exp()).abs() < 1e-6)
        );
        assert!(
            p.tile(1)
                .unwrap()
                .iter()
                .all(|&v| (v - (-0.1f64).exp()).abs() < 1e-6)
        );
        assert!(p.tile(2).is_none());
        for broken in [
            PeriodicPart {
                periods: Principal {
                    weights: vec![vec![1.0]],
                    ..periodic.periods.clone()
                },
                ..periodic.clone()
            },
            PeriodicPart {
                periods: Principal {
                    weights: vec![vec![1.0], vec![f32::NAN]],
                    ..periodic.periods.clone()
                },
                ..periodic.clone()
            },
            PeriodicPart {
                periods: Principal {
                    basis: vec![vec![0.5; 18], vec![0.1; 17]],
                    ..periodic.periods.clone()
                },
                ..periodic.clone()
            },
            PeriodicPart {
                lattice: Lattice {
                    rows: 2.0,
                    cols: 6.5,
                },
                ..periodic.clone()
            },
            PeriodicPart {
                rows: MAX_TILE_SAMPLES + 1,
                ..periodic.clone()
            },
            PeriodicPart {
                heights: Some(vec![0.0; 6]),
                ..periodic.clone()
            },
            // Light weights need the range map's heights (none here).
            PeriodicPart {
                light_weights: Some(LightWeights {
                    view: 0,
                    weights: vec![vec![0.5]; 3],
                }),
                ..periodic.clone()
            },
        ] {
            let e = refused(|p| p.periodic = Some(broken.clone()));
            assert!(e.contains("periodic part"), "{e}");
        }
    }

    #[test]
    fn cluster_of_is_checked() {
        let model = MaterialModel::new(parts()).unwrap();
        assert_eq!(model.cluster_of(1, 2).unwrap(), 1);
        assert_eq!(model.cluster_of(1, 0).unwrap(), 1);
        assert_eq!(model.cluster_of(0, 2).unwrap(), 0);
        assert!(model.cluster_of(2, 0).is_err());
        assert!(model.cluster_of(0, 3).is_err());
    }
}
