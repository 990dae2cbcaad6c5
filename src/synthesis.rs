//! Synthesis: a [`MaterialModel`] to images of any size, for any view and light (seed 001,
//! sec. 5.3). Lazy: only the subspace images that the requested (view, light) pairs touch are
//! synthesized, at the requested size.
//!
//! Coherence: the driving noise of a band depends only on the seed, the KL factor (or colour
//! band) and the pyramid level, never on the subspace. Every subspace image is therefore the
//! same random field filtered differently, and the same position shows corresponding structure
//! under every view and light, so a moving light does not make the texture boil.

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex, OnceLock};

use ndarray::{Array2, Array3, Axis, s};
use rayon::prelude::*;

use crate::btf::{Direction, Weighted};
use crate::decompose::colour_transfer::ChromaOrigin;
use crate::decompose::marginals::{self, MarginalMap, QUANTILES, QuantileGrid};
use crate::decompose::pyramid::{exact_levels, spread};
use crate::decompose::{Border, ColourSpace, Pyramid};
use crate::geometry::cells::LaidCells;
use crate::geometry::integrate::{Edges, normals_of, normals_of_periodic};
use crate::geometry::lattice::{self, Lattice};
use crate::geometry::parallax;
use crate::geometry::relight::{SHADING_FLOOR, Shading, shading_factor};
use crate::geometry::{
    CoarseScan, Phase, Placement, QuiltedRelief, coarse_part, detail_scale, patch_side, quilt,
    quilt_laid, quilt_placement, resample_periodic,
};
use crate::model::{
    CoarseSource, Exemplar, LIGHTNESS_BANDS, LightLightness, LightWeights, MaterialModel,
    ModelError, PeriodicPart, Principal, Result, SubspaceModel,
};
use crate::mrf::noise::standard_normal;
use crate::mrf::{BandModel, Levels, LevelsVisitor};
use crate::progress::{NoProgress, Progress};

/// The largest synthesized side, pixels (a 4096^2 image peaks near 2 GB; 8192^2 near 8 GB).
pub const MAX_SIDE: usize = 8192;

/// Size and randomness of a synthesis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SynthesisOptions {
    /// Output rows, pixels.
    pub rows: usize,
    /// Output columns, pixels.
    pub cols: usize,
    /// Seed of the driving noise: same seed, same bytes.
    pub seed: u64,
    /// Make the output tile seamlessly (every model is then sampled exactly on the torus: by
    /// FFT for the GMRF, by the DFT solution of the circulant recursion for the CAR models).
    /// Needs sizes divisible by the pyramid step
    /// ([`pyramid_step`](crate::decompose::pyramid::pyramid_step)).
    pub tileable: bool,
}

impl SynthesisOptions {
    /// How pyramids and blurs of the output treat its borders: wrapping around for a
    /// tileable output, mirrored otherwise.
    pub fn border(&self) -> Border {
        if self.tileable {
            Border::Periodic
        } else {
            Border::Mirror
        }
    }

    /// How differences of the output's relief treat its borders: wrapping around for a
    /// tileable output (its relief is periodic), edge samples repeated otherwise (a plain
    /// output's relief is cut from a larger torus, so its opposite edges do not meet).
    pub fn edges(&self) -> Edges {
        if self.tileable {
            Edges::Wrap
        } else {
            Edges::Clamp
        }
    }
}

/// Subspace images (made on first use) and the range map for one size and seed; see
/// [`MaterialModel::synthesis_cache`].
#[derive(Debug)]
pub struct SynthesisCache {
    options: SynthesisOptions,
    subspaces: Vec<OnceLock<Array3<f32>>>,
    heights: Option<Array2<f64>>,
    normals: OnceLock<Option<Array3<f64>>>,
    /// The exemplar's basis crops laid with one quilt's patches, made on first use; `None`
    /// without an exemplar.
    structure: OnceLock<Option<LaidExemplar>>,
    /// The measured pairs' finishes ([`MaterialModel::pair_finish`]) made so far.
    finishes: Mutex<HashMap<(usize, usize), Finish>>,
    noise: NoiseBank,
}

/// The relief's relighting of an image for one (view, light): the shading factor (rows, cols)
/// and the view's parallax warp, each where there is one ([`MaterialModel::relighting`]).
#[derive(Default)]
struct Relighting {
    factor: Option<Array2<f64>>,
    warp: Option<parallax::ViewWarp>,
}

impl Relighting {
    fn apply(&self, mut image: Array3<f32>) -> Array3<f32> {
        if let Some(factor) = &self.factor {
            scale_pixels(&mut image, factor);
        }
        match &self.warp {
            Some(warp) => warp.apply(&image),
            None => image,
        }
    }
}

/// A measured pair's finish, shape (3, rows, cols), shared by the cache and its users.
pub type Finish = Arc<Array3<f32>>;

/// An exemplar's basis fields copied onto the output with one quilt's patches.
#[derive(Debug)]
struct LaidExemplar {
    /// Where every output sample's exemplar sample lies (every torus sample's, for an
    /// exemplar at a step).
    placement: Placement,
    /// How the laid fields reach the output's texels.
    scale: Scale,
    /// The exemplar's basis as laid ([`exemplar_planes`]): the L* crops (the mean, then the
    /// deviations), then an (a*, b*) pair per chroma basis field.
    planes: Vec<Array2<f64>>,
    /// How many of `planes` are L* crops.
    lightness: usize,
    /// The relief's cells as laid, where one guided the quilt: every output cell's pieces
    /// take its major piece's mean.
    cells: Option<LaidCells>,
}

impl LaidExemplar {
    /// The L* detail of a subspace image with `coefficients` on the L* basis: the weighted
    /// sum of the crops, laid on the output.
    fn lightness(&self, coefficients: &[f64]) -> Array2<f64> {
        self.laid_sum(coefficients.iter().zip(&self.planes[..self.lightness]))
    }

    /// The a* (`channel` 0) or b* (1) detail of a subspace image with `coefficients` on the
    /// chroma basis.
    fn chroma(&self, coefficients: &[f64], channel: usize) -> Array2<f64> {
        let pairs = self.planes[self.lightness..].chunks_exact(2);
        self.laid_sum(coefficients.iter().zip(pairs.map(|pair| &pair[channel])))
    }

    /// A weighted sum of basis planes, summed at the exemplar's size and laid once (laying is
    /// linear, so this is the sum of the laid planes to the last bit).
    fn laid_sum<'a>(&self, terms: impl Iterator<Item = (&'a f64, &'a Array2<f64>)>) -> Array2<f64> {
        let mut sum = Array2::<f64>::zeros(self.placement.source());
        for (&c, plane) in terms {
            sum.scaled_add(c, plane);
        }
        let mut laid = self.placement.lay(&sum);
        if let Some(cells) = &self.cells {
            cells.even_out(&sum, &self.placement, &mut laid);
        }
        self.scale.apply(laid)
    }
}

/// How a quilt's torus of exemplar (or range-map) samples reaches the output's texels.
#[derive(Debug, Clone, Copy)]
enum Scale {
    /// A sample a texel: the output is the torus's top-left corner (already cut to it).
    Texels,
    /// Samples of several texels: the torus resampled (bilinear, wrapping) to `torus` texels,
    /// then its top-left `output` texels.
    Stepped {
        torus: (usize, usize),
        output: (usize, usize),
    },
}

impl Scale {
    /// For an output of `o` from samples of `step` texels with patches of `patch` samples:
    /// the scale and the torus's size in samples.
    fn new(o: &SynthesisOptions, step: usize, patch: usize) -> (Self, (usize, usize)) {
        let (tr, tc) = quilt_torus(o, patch * step);
        if step <= 1 {
            return (Self::Texels, (tr, tc));
        }
        let samples = |n: usize| ((n as f64 / step as f64).round() as usize).max(1);
        let scale = Self::Stepped {
            torus: (tr, tc),
            output: (o.rows, o.cols),
        };
        (scale, (samples(tr), samples(tc)))
    }

    /// A field laid on the torus's samples, on the output's texels.
    fn apply(&self, field: Array2<f64>) -> Array2<f64> {
        match *self {
            Self::Texels => field,
            Self::Stepped {
                torus: (tr, tc),
                output: (rows, cols),
            } => cropped(resample_periodic(&field, tr, tc), rows, cols),
        }
    }
}

/// The driving noise of the bands by band seed. Every subspace image uses the same noise for a
/// band (that is what keeps them coherent), so a cache draws it once and keeps it; a single
/// subspace image draws it and lets it go.
#[derive(Debug)]
struct NoiseBank {
    kept: Option<Mutex<HashMap<u64, Arc<Vec<f32>>>>>,
}

impl NoiseBank {
    fn kept() -> Self {
        Self {
            kept: Some(Mutex::new(HashMap::new())),
        }
    }

    fn transient() -> Self {
        Self { kept: None }
    }

    /// At least `len` unit Gaussian values for band `seed` (a longer draw from the same seed
    /// starts with the same values, so one kept draw serves every shorter request). No lock is
    /// held while drawing: concurrent first requests may both draw, and get the same values.
    fn draw(&self, seed: u64, len: usize) -> Arc<Vec<f32>> {
        let Some(kept) = &self.kept else {
            return Arc::new(standard_normal(seed, len));
        };
        let lock = || {
            kept.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
        };
        if let Some(values) = lock().get(&seed).filter(|v| v.len() >= len) {
            return Arc::clone(values);
        }
        let values = Arc::new(standard_normal(seed, len));
        let mut map = lock();
        let entry = map.entry(seed).or_insert_with(|| Arc::clone(&values));
        if entry.len() < len {
            *entry = Arc::clone(&values);
        }
        Arc::clone(entry)
    }
}

impl SynthesisCache {
    /// How many subspace images have been synthesized so far.
    pub fn synthesized(&self) -> usize {
        self.subspaces.iter().filter(|s| s.get().is_some()).count()
    }

    /// The size and seed of every image in this cache.
    pub fn options(&self) -> &SynthesisOptions {
        &self.options
    }

    /// Subspace image `k` if it has been synthesized already.
    pub fn get(&self, k: usize) -> Option<&Array3<f32>> {
        self.subspaces.get(k).and_then(|s| s.get())
    }

    /// Unit normals of the range map at the cache's size (periodic when the cache is
    /// tileable, see [`MaterialModel::range_heights`] and [`SynthesisOptions::edges`]), shape
    /// (3, rows, cols); `None` without a range map.
    pub fn normals(&self) -> Option<&Array3<f64>> {
        self.normals
            .get_or_init(|| {
                let heights = self.heights.as_ref()?;
                Some(match self.options.edges() {
                    Edges::Wrap => normals_of_periodic(heights),
                    Edges::Clamp => normals_of(heights),
                })
            })
            .as_ref()
    }

    /// The range map at the cache's size, texels ([`MaterialModel::range_heights`]); `None`
    /// without a range map.
    pub fn heights(&self) -> Option<&Array2<f64>> {
        self.heights.as_ref()
    }
}

/// A seed for one band: mixes the user's seed with the band's identity, the noise stream
/// (see [`noise_stream`]) and the pyramid level.
fn band_seed(seed: u64, stream: usize, level: usize) -> u64 {
    crate::mrf::noise::mix(seed, (stream as u64) << 32 | level as u64)
}

/// The noise stream of a model of `planes` planes starting at factor plane `first`: a model of
/// one plane draws the factor's own stream (0, 1, 2); a joint model of the colour channels
/// draws stream 3, apart from them.
fn noise_stream(planes: usize, first: usize) -> usize {
    if planes == 1 { first } else { 3 }
}

/// Synthesizes every band of a subspace image (in parallel), as `bands[factor][level]`.
struct SynthesizeBands<'a> {
    /// Band shapes, finest level first.
    shapes: &'a [(usize, usize)],
    options: &'a SynthesisOptions,
    noise: &'a NoiseBank,
}

impl LevelsVisitor for SynthesizeBands<'_> {
    type Output = Vec<Vec<Array2<f64>>>;
    fn visit<M: BandModel>(self, levels: &Levels<M>) -> Self::Output {
        let (o, n) = (self.options, levels.levels().len());
        let groups = Levels::<M>::PER_LEVEL;
        // Band i is group i / n (of M::PLANES factor planes) at level i % n.
        let samples: Vec<Array3<f64>> = (0..groups * n)
            .into_par_iter()
            .map(|i| {
                let (group, lv) = (i / n, i % n);
                let (r, c) = self.shapes[lv];
                let model = &levels.levels()[lv][group];
                if let Some(means) = model.flat_means() {
                    return Array3::from_shape_fn((M::PLANES, r, c), |(p, _, _)| means[p]);
                }
                let stream = noise_stream(M::PLANES, group * M::PLANES);
                let len = M::noise_len(r, c, o.tileable);
                let noise = self.noise.draw(band_seed(o.seed, stream, lv), len);
                model.synthesize_from(r, c, &noise, o.tileable)
            })
            .collect();
        let mut planes: Vec<Vec<Array2<f64>>> = (0..3).map(|_| Vec::with_capacity(n)).collect();
        for (i, sample) in samples.into_iter().enumerate() {
            let group = i / n;
            for (p, plane) in sample.outer_iter().enumerate() {
                planes[group * M::PLANES + p].push(plane.to_owned());
            }
        }
        planes
    }
}

fn check(model: &MaterialModel, o: &SynthesisOptions) -> Result<()> {
    if o.rows == 0 || o.cols == 0 || o.rows > MAX_SIDE || o.cols > MAX_SIDE {
        return Err(ModelError::parameter(
            "--size",
            format!(
                "{}x{} is outside 1..={MAX_SIDE} pixels a side",
                o.cols, o.rows
            ),
        ));
    }
    let step = model.min_synthesis_side();
    if o.rows < step || o.cols < step {
        return Err(ModelError::parameter(
            "--size",
            format!(
                "{}x{} is smaller than the model's {} pyramid levels allow: use at least {step}",
                o.cols,
                o.rows,
                model.levels()
            ),
        ));
    }
    if o.tileable && (!o.rows.is_multiple_of(step) || !o.cols.is_multiple_of(step)) {
        return Err(ModelError::parameter(
            "--size",
            format!(
                "a tileable synthesis with {} levels needs sides divisible by {step}",
                model.levels()
            ),
        ));
    }
    Ok(())
}

impl MaterialModel {
    /// Synthesizes subspace image `k` as planar `(3, rows, cols)` linear RGB (not clamped).
    ///
    /// # Errors
    /// `k` out of range, or a size of zero, beyond [`MAX_SIDE`], or not tileable.
    pub fn synthesize_subspace(&self, k: usize, o: &SynthesisOptions) -> Result<Array3<f32>> {
        let cache = self.synthesis_cache_for(&[k], o, &NoProgress)?;
        let mut slots = cache.subspaces.into_iter();
        slots
            .nth(k)
            .and_then(OnceLock::into_inner)
            .ok_or_else(|| ModelError::parameter("subspace", format!("{k}")))
    }

    /// Subspace `s`'s KL factors (or colour bands) at the pyramid `shapes` with band noise from
    /// `noise`: every band synthesized in parallel (and matched to its measured marginal when
    /// the model has band tables), the pyramid collapsed; each with the map of its values onto
    /// its measured marginal (not yet applied).
    fn factor_planes(
        &self,
        s: &SubspaceModel,
        shapes: &[(usize, usize)],
        o: &SynthesisOptions,
        noise: &NoiseBank,
    ) -> Vec<(Array2<f64>, MarginalMap)> {
        let bands = s.levels.visit(SynthesizeBands {
            shapes,
            options: o,
            noise,
        });
        let (band_probabilities, factor_probabilities) = (
            marginals::band_probabilities(),
            s.marginal_grid.probabilities(marginals::QUANTILES),
        );
        bands
            .into_par_iter()
            .zip(&s.marginals)
            .enumerate()
            .map(|(factor, (mut bands, target))| {
                if let Some(tables) = &s.band_marginals {
                    for (band, levels) in bands.iter_mut().zip(&tables.tables) {
                        let table = &levels[factor];
                        marginals::match_marginal(band, table, &band_probabilities);
                    }
                }
                let plane = Pyramid { bands }.collapse_with(o.border());
                let map = MarginalMap::new(&plane, target, &factor_probabilities);
                (plane, map)
            })
            .collect()
    }

    /// Subspace image `k` with band noise from `noise`: every band synthesized in parallel
    /// (and matched to its measured marginal when the model has band tables), then per KL
    /// factor (or colour band) the pyramid collapsed and the marginal matched, then the joint
    /// colour distribution matched when the model has colour tables.
    fn subspace_image(
        &self,
        k: usize,
        o: &SynthesisOptions,
        noise: &NoiseBank,
        (structure, heights): (&OnceLock<Option<LaidExemplar>>, Option<&Array2<f64>>),
    ) -> Result<Array3<f32>> {
        let s = self.subspaces().get(k).ok_or_else(|| {
            ModelError::parameter("subspace", format!("{k} of {}", self.subspaces().len()))
        })?;
        let shapes = Pyramid::shapes(o.rows, o.cols, s.levels.len());
        let border = o.border();
        // The exemplar's quilt does not depend on the factors: laid while they are drawn and
        // turned into colours.
        let (mut colours, laid) = rayon::join(
            || {
                let factors = self.factor_planes(s, &shapes, o, noise);
                let (factors, maps): (Vec<_>, Vec<_>) = factors.into_iter().unzip();
                let factors: [Array2<f64>; 3] = factors.try_into().expect("three factors");
                s.kl.coordinates_mapped(&factors, |f| {
                    [
                        maps[0].apply(f[0]),
                        maps[1].apply(f[1]),
                        maps[2].apply(f[2]),
                    ]
                })
            },
            || {
                (s.kl.space == ColourSpace::Lab)
                    .then(|| structure.get_or_init(|| self.exemplar_details(o)).as_ref())
                    .flatten()
            },
        );
        if let Some(e) = self.exemplar()
            && let Some(laid) = laid
        {
            // This subspace's laid crop (its weights on the laid basis) brings the structure
            // finer than the exemplar's patches to L* (and a*, b* where the exemplar stores
            // chroma); the coarser L* is the MRF's or the laid crop's own, the coarser chroma
            // the MRF's (see `CoarseSource`).
            let with_detail = |plane: &Array2<f64>, laid: Array2<f64>, coarse| {
                let offset = plane - &laid;
                match coarse {
                    // The plane's coarse part plus the laid crop's detail is the laid crop plus
                    // the coarse part of their difference (the split is linear): one blur. An
                    // exemplar at a step holds no detail finer than its samples, and the MRF's
                    // is not added there: it came out as salt-and-pepper specks over the
                    // built-in stones at 256^2 (x2.46 the another-crop level against x1.71).
                    CoarseSource::Mrf => {
                        let sigma = detail_scale(e.rows, e.cols) * e.step as f64;
                        laid + coarse_part(&offset, sigma, o.tileable)
                    }
                    CoarseSource::Laid => laid + offset.mean().unwrap_or(0.0),
                }
            };
            let lightness = e.lightness.coefficients(k);
            let chroma = e.chroma.as_ref().and_then(|c| c.fields.coefficients(k));
            // The three channels in parallel.
            colours
                .par_iter_mut()
                .enumerate()
                .for_each(|(channel, plane)| match (channel, &lightness, &chroma) {
                    (0, Some(coefficients), _) => {
                        *plane = with_detail(plane, laid.lightness(coefficients), e.coarse);
                    }
                    (1 | 2, _, Some(coefficients)) => {
                        let detail = laid.chroma(coefficients, channel - 1);
                        *plane = with_detail(plane, detail, CoarseSource::Mrf);
                    }
                    _ => {}
                });
        }
        if let Some(c) = &s.colour_marginals {
            c.transfer(&mut colours, border, s.kl.space, self.chroma_origin(k));
        }
        let mut image = s.kl.space.linear_image(&colours);
        if let Some(p) = self.periodic()
            && let Some(tile) = p.tile(k)
        {
            // The MRF made the stochastic ratio; the lattice's mean period brings the weave.
            let lattice = output_lattice(p, o);
            for (mut channel, tile) in image.axis_iter_mut(Axis(0)).zip(tile.outer_iter()) {
                let tiled = lattice::tiled(&tile.to_owned(), &lattice, o.rows, o.cols);
                channel.zip_mut_with(&tiled, |v, &t| *v = (f64::from(*v) * t) as f32);
            }
        }
        if let Some(heights) = heights {
            self.match_lit(k, &mut image, heights, o.edges());
        }
        Ok(image)
    }

    /// Where subspace image `k`'s chroma comes from: laid from the exemplar's crops with their
    /// lightness where the exemplar holds chroma for it, else the MRF's.
    fn chroma_origin(&self, k: usize) -> ChromaOrigin {
        let laid = self
            .subspaces()
            .get(k)
            .is_some_and(|s| s.kl.space == ColourSpace::Lab)
            && (self.exemplar())
                .and_then(|e| e.chroma.as_ref())
                .is_some_and(|c| c.fields.coefficients(k).is_some());
        if laid {
            ChromaOrigin::Laid
        } else {
            ChromaOrigin::Independent
        }
    }

    /// Scales each pixel of `image` so that, relit by `heights` for subspace `k`'s
    /// representative's light, its L* marginal is that light's measured one (the subspace's
    /// [`LitMarginals`](crate::model::LitMarginals)); nothing without a table or a range map.
    /// The chromaticity is kept: matching a* and b* on their own made colours the material
    /// does not have, and pushed the leather's frontal representatives off-chroma.
    fn match_lit(&self, k: usize, image: &mut Array3<f32>, heights: &Array2<f64>, edges: Edges) {
        let Some(s) = self.subspaces().get(k) else {
            return;
        };
        let lit_light = usize::from(s.representative.1);
        if let (Some(lit), Some(map)) = (&s.lit_marginals, self.range_map())
            && let Some(light) = self.lights().get(lit_light)
            && let Some(factor) = relief_factor(heights, edges, light, map.shading_of(lit_light))
        {
            match_lightness(image, Some(&factor), &lit.lightness, 1.0);
        }
    }

    /// The measured (view, light) pairs around a requested pair and their weights: the 3
    /// nearest views times the 3 nearest lights (barycentric), at most 9 pairs.
    ///
    /// # Errors
    /// A non-finite direction.
    pub fn neighbouring_pairs(
        &self,
        view: &Direction,
        light: &Direction,
    ) -> Result<Vec<(usize, usize, f64)>> {
        let wv = self.views().interpolate(view)?;
        let wl = self.lights().interpolate(light)?;
        let mut pairs = Vec::with_capacity(9);
        for Weighted {
            index: v,
            weight: a,
        } in wv
        {
            for Weighted {
                index: l,
                weight: b,
            } in wl
            {
                if a * b > 0.0 {
                    pairs.push((v, l, a * b));
                }
            }
        }
        Ok(pairs)
    }

    /// The subspace images (and their total weights) a requested (view, light) draws on.
    ///
    /// # Errors
    /// A non-finite direction.
    pub fn subspace_weights(
        &self,
        view: &Direction,
        light: &Direction,
    ) -> Result<BTreeMap<usize, f64>> {
        self.weights_by_cluster(view, light, false)
    }

    /// The pairs' weights summed per cluster, each times its pair's gain when `gained`.
    fn weights_by_cluster(
        &self,
        view: &Direction,
        light: &Direction,
        gained: bool,
    ) -> Result<BTreeMap<usize, f64>> {
        let mut weights = BTreeMap::new();
        for (v, l, w) in self.neighbouring_pairs(view, light)? {
            let gain = if gained { self.pair_gain(v, l) } else { 1.0 };
            *weights.entry(self.cluster_of(v, l)?).or_insert(0.0) += w * gain;
        }
        Ok(weights)
    }

    /// The BTF image for (view, light): the subspace images of the nearest measured pairs,
    /// blended by their barycentric weights times the pairs' gains, then relit by bump mapping
    /// with the range map and seen from the view with its parallax and masking
    /// ([`parallax::view_warp`]) when the model has one, and given the requested light's
    /// measured lightness where the model stores light tables ([`LightLightness`]). Only the
    /// subspaces needed are synthesized.
    ///
    /// # Errors
    /// A non-finite direction or an invalid size.
    pub fn synthesize_image(
        &self,
        view: &Direction,
        light: &Direction,
        o: &SynthesisOptions,
    ) -> Result<Array3<f32>> {
        let clusters: Vec<usize> = self.subspace_weights(view, light)?.into_keys().collect();
        self.image_from_cache(
            &self.synthesis_cache_for(&clusters, o, &NoProgress)?,
            view,
            light,
        )
    }

    /// An empty cache for synthesizing many images of one size and seed: each subspace image
    /// is made once, on first use, and the range map once, here.
    ///
    /// # Errors
    /// An invalid size.
    pub fn synthesis_cache(&self, o: &SynthesisOptions) -> Result<SynthesisCache> {
        check(self, o)?;
        Ok(self.relief_cache(o, NoiseBank::kept()))
    }

    /// An empty cache holding the range map's heights (`None` without a range map), and the
    /// exemplar's details where the quilt or lattice that lays the relief decides them: one
    /// quilt for both where the exemplar is registered with the map
    /// ([`MaterialModel::laid_together`]), the lattice for a near-regular material
    /// ([`MaterialModel::lattice_relief`]), else the map quilted alone
    /// ([`MaterialModel::quilted_heights`]) and the details laid when first needed.
    fn relief_cache(&self, o: &SynthesisOptions, noise: NoiseBank) -> SynthesisCache {
        let (heights, details) = if let Some((relief, details)) = self.laid_together(o) {
            // The heights are integrated here from the quilted relief's differences.
            let heights = cropped(details.scale.apply(relief.integrate()), o.rows, o.cols);
            (heights, Some(details))
        } else if let Some((heights, details)) = self.lattice_relief(o) {
            (heights, details)
        } else {
            return self.empty_cache(o, self.quilted_heights(o), noise);
        };
        let cache = self.empty_cache(o, Some(heights), noise);
        cache
            .structure
            .set(details)
            .expect("a new cache has no structure yet");
        cache
    }

    fn empty_cache(
        &self,
        o: &SynthesisOptions,
        heights: Option<Array2<f64>>,
        noise: NoiseBank,
    ) -> SynthesisCache {
        SynthesisCache {
            options: *o,
            subspaces: (0..self.subspaces().len())
                .map(|_| OnceLock::new())
                .collect(),
            heights,
            normals: OnceLock::new(),
            structure: OnceLock::new(),
            finishes: Mutex::new(HashMap::new()),
            noise,
        }
    }

    /// The BTF image for (view, light) as [`MaterialModel::synthesize_image`] makes it, drawing
    /// subspace images from (and adding them to) `cache`, which must come from this model.
    ///
    /// # Errors
    /// A non-finite direction.
    pub fn image_from_cache(
        &self,
        cache: &SynthesisCache,
        view: &Direction,
        light: &Direction,
    ) -> Result<Array3<f32>> {
        let out = self.relit_image(cache, view, light)?;
        let mut out = self.with_light_tables(out, cache, view, light)?;
        let fade = self.lights().irradiance_beyond_lowest(light) as f32;
        if fade < 1.0 {
            out.mapv_inplace(|v| fade * v);
        }
        Ok(out)
    }

    /// `out`, relit for (`view`, `light`), given the requested light's measured lightness and
    /// colours where the model stores light tables: the cluster's subspace image was matched
    /// at its representative's light only.
    fn with_light_tables(
        &self,
        mut out: Array3<f32>,
        cache: &SynthesisCache,
        view: &Direction,
        light: &Direction,
    ) -> Result<Array3<f32>> {
        if let Some(tables) = self.light_lightness()
            && let Some(target) = light_target(self, tables, view, light)?
        {
            if let Some(spreads) = &target.spreads {
                let finest = finest_held_band(self.range_map().map_or(1, |m| m.step));
                let border = cache.options.border();
                respread_lightness(&mut out, spreads, (target.share, finest), border);
            }
            match_lightness(&mut out, None, &target.lightness, target.share);
            if let Some(chroma) = &target.chroma {
                match_chroma(&mut out, chroma, target.share);
            }
        }
        Ok(out)
    }

    /// [`MaterialModel::image_from_cache`] before the light tables: the subspace images
    /// blended with their pairs' gains, given the lights' own detail, relit and seen from
    /// the view.
    pub(crate) fn relit_image(
        &self,
        cache: &SynthesisCache,
        view: &Direction,
        light: &Direction,
    ) -> Result<Array3<f32>> {
        let weights = self.weights_by_cluster(view, light, true)?;
        let blend = self.blend(cache, &weights)?;
        let own = self.with_own_parts(blend, cache, (view, light), &weights)?;
        Ok(self.relighting(cache, view, light)?.apply(own))
    }

    /// The subspace images blended by `weights` (per cluster, the pairs' weights times their
    /// gains: each measured pair brings its subspace image at its own brightness).
    fn blend(&self, cache: &SynthesisCache, weights: &BTreeMap<usize, f64>) -> Result<Array3<f32>> {
        let o = &cache.options;
        let mut out: Option<Array3<f32>> = None;
        for (&k, &w) in weights {
            let part = self.subspace_from_cache(cache, k)?;
            match &mut out {
                None => out = Some(part.mapv(|v| w as f32 * v)),
                Some(out) => out.scaled_add(w as f32, part),
            }
        }
        Ok(out.unwrap_or_else(|| Array3::zeros((3, o.rows, o.cols))))
    }

    /// `out`, the blend of the subspace images by `weights`, given what the measured lights
    /// around (`view`, `light`) have of their own: their period on a lattice, their exemplar
    /// detail.
    fn with_own_parts(
        &self,
        mut out: Array3<f32>,
        cache: &SynthesisCache,
        (view, light): (&Direction, &Direction),
        weights: &BTreeMap<usize, f64>,
    ) -> Result<Array3<f32>> {
        let o = &cache.options;
        if let Some(factor) = self.light_period(o, view, light)? {
            out.zip_mut_with(&factor, |v, &f| *v = (f64::from(*v) * f) as f32);
        }
        let lattice_exemplar = self.exemplar().filter(|_| self.periodic().is_some());
        match (self.light_detail(cache, view, light)?, lattice_exemplar) {
            (None, _) => {}
            // On a lattice the exemplar holds the L* of the stochastic ratio, which the tile
            // multiplies: the lights' own detail scales each pixel as it would the ratio at
            // its mean lightness (chromaticity kept), and the colour tables, which are the
            // ratio's, are not matched again.
            (Some(detail), Some(e)) => {
                scale_pixels(&mut out, &ratio_detail_factor(&detail, e.mean_lightness()));
            }
            (Some(detail), None) => {
                // Chromaticity kept, as a shadow darkens; the colours then go back to the
                // leading cluster's joint distribution, which the subspace image had before the
                // detail changed (without it the built-in leather's b* spread grew 20 %), and to
                // its lit lightness (the subspace image's last step, which the transfer undoes);
                // the pairs' gains scale them as they scaled the blend.
                shift_lightness(&mut out, &detail);
                if let Some((&k, _)) = weights.iter().max_by(|a, b| a.1.total_cmp(b.1))
                    && let Some(c) = &self.subspaces()[k].colour_marginals
                {
                    let mut planes = ColourSpace::Lab.planes(&out);
                    c.transfer(
                        &mut planes,
                        o.border(),
                        ColourSpace::Lab,
                        self.chroma_origin(k),
                    );
                    out = ColourSpace::Lab.linear_image(&planes);
                    if let Some(heights) = &cache.heights {
                        self.match_lit(k, &mut out, heights, o.edges());
                    }
                    let plain: f64 = self.weights_by_cluster(view, light, false)?.values().sum();
                    let gain = weights.values().sum::<f64>() / plain;
                    if gain.is_finite() && gain > 0.0 {
                        out.mapv_inplace(|v| v * gain as f32);
                    }
                }
            }
        }
        Ok(out)
    }

    /// How the cache's relief relights an image for `light` ([`bump_relight`]'s factor) and
    /// shows it from `view` (its parallax); nothing without a range map.
    fn relighting(
        &self,
        cache: &SynthesisCache,
        view: &Direction,
        light: &Direction,
    ) -> Result<Relighting> {
        let Some(heights) = &cache.heights else {
            return Ok(Relighting::default());
        };
        let edges = cache.options.edges();
        Ok(Relighting {
            factor: relief_factor(heights, edges, light, self.bump_shading(light)?),
            warp: parallax::view_warp(heights, edges, view.vector()),
        })
    }

    /// Whether the measured pair (`view`, `light`) has parts of its own beyond its cluster's
    /// subspace image: its view's light tables, its light's own exemplar detail or period
    /// (see [`MaterialModel::pair_finish`]).
    pub fn has_own_parts(&self, view: usize, light: usize) -> bool {
        let tables = self
            .light_lightness()
            .is_some_and(|t| t.view == view && light < t.tables.len());
        let weighed =
            |w: Option<&LightWeights>| w.is_some_and(|w| w.view == view && light < w.weights.len());
        tables
            || weighed(self.exemplar().and_then(|e| e.light_weights.as_ref()))
            || weighed(self.periodic().and_then(|p| p.light_weights.as_ref()))
    }

    /// Every measured pair with parts of its own ([`MaterialModel::has_own_parts`]), view-major.
    pub fn pairs_with_own_parts(&self) -> Vec<(usize, usize)> {
        let lights = self.lights().len();
        (0..self.views().len() * lights)
            .map(|i| (i / lights, i % lights))
            .filter(|&(v, l)| self.has_own_parts(v, l))
            .collect()
    }

    /// What the measured pair (`view`, `light`)'s own parts (its light's period and exemplar
    /// detail, its light tables) add to its image, at its measured directions, shape (3, rows,
    /// cols) of the cache: [`MaterialModel::image_from_cache`] less its subspace image at its
    /// gain, relit and seen as there. A renderer that blends subspace images and relights them
    /// per fragment adds the finishes of the same pairs with the same weights: exact at a
    /// measured pair, a blend of the nearest pairs' finishes between them. Made once per
    /// cache; `None` where the pair has no own parts ([`MaterialModel::has_own_parts`]).
    ///
    /// # Errors
    /// `view` or `light` out of range.
    pub fn pair_finish(
        &self,
        cache: &SynthesisCache,
        view: usize,
        light: usize,
    ) -> Result<Option<Finish>> {
        let (Some(&v), Some(&l)) = (
            self.views().as_slice().get(view),
            self.lights().as_slice().get(light),
        ) else {
            return Err(ModelError::parameter(
                "pair",
                format!(
                    "({view}, {light}) is not a measured pair of {} views and {} lights",
                    self.views().len(),
                    self.lights().len()
                ),
            ));
        };
        if !self.has_own_parts(view, light) {
            return Ok(None);
        }
        let lock = || {
            cache
                .finishes
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
        };
        if let Some(done) = lock().get(&(view, light)) {
            return Ok(Some(Arc::clone(done)));
        }
        // One blend and one relighting serve the plain image and the finished one.
        let weights = self.weights_by_cluster(&v, &l, true)?;
        let blend = self.blend(cache, &weights)?;
        let relighting = self.relighting(cache, &v, &l)?;
        let plain = relighting.apply(blend.clone());
        let own = self.with_own_parts(blend, cache, (&v, &l), &weights)?;
        let finished = self.with_light_tables(relighting.apply(own), cache, &v, &l)?;
        let finish = Arc::new(finished - plain);
        let mut done = lock();
        Ok(Some(Arc::clone(
            done.entry((view, light)).or_insert(finish),
        )))
    }

    /// The L* detail the measured lights around `light` have of their own beyond their
    /// clusters' ([`LightWeights`](crate::model::LightWeights)): the exemplar's deviations
    /// laid with the lights' weights less their subspaces', kept finer than a patch where
    /// the MRF brings the coarse L*; `None` where there is nothing to add.
    fn light_detail(
        &self,
        cache: &SynthesisCache,
        view: &Direction,
        light: &Direction,
    ) -> Result<Option<Array2<f64>>> {
        let (Some(e), Some(Some(laid))) = (self.exemplar(), cache.structure.get()) else {
            return Ok(None);
        };
        let Some((own, cluster)) =
            self.own_light_coefficients(e.light_weights.as_ref(), &e.lightness, view, light)?
        else {
            return Ok(None);
        };
        let delta: Vec<f64> = own.iter().zip(&cluster).map(|(a, b)| a - b).collect();
        let detail = laid.lightness(&delta);
        Ok(Some(match e.coarse {
            CoarseSource::Mrf => {
                let sigma = detail_scale(e.rows, e.cols) * e.step as f64;
                let coarse = coarse_part(&detail, sigma, cache.options.tileable);
                detail - coarse
            }
            CoarseSource::Laid => detail,
        }))
    }

    /// What the measured lights around `light` in `lights`' view have of their own beyond
    /// their clusters, as two sets of coefficients on `fields`' basis (0 on the mean): the
    /// neighbouring pairs' own weights and their subspaces' weights, each by the pair's
    /// weight; `None` without light weights or where the two are the same.
    fn own_light_coefficients(
        &self,
        lights: Option<&LightWeights>,
        fields: &Principal,
        view: &Direction,
        light: &Direction,
    ) -> Result<Option<(Vec<f64>, Vec<f64>)>> {
        let Some(lights) = lights else {
            return Ok(None);
        };
        let mut own = vec![0.0; fields.basis.len()];
        let mut cluster = own.clone();
        for (v, l, w) in self.neighbouring_pairs(view, light)? {
            if v != lights.view {
                continue;
            }
            let k = self.cluster_of(v, l)?;
            if let (Some(a), Some(b)) = (lights.weights.get(l), fields.weights.get(k)) {
                for (sums, weights) in [(&mut own, a), (&mut cluster, b)] {
                    for (s, &x) in sums[1..].iter_mut().zip(weights) {
                        *s += w * f64::from(x);
                    }
                }
            }
        }
        Ok((own != cluster).then_some((own, cluster)))
    }

    /// The factor (3, rows, cols) on linear RGB that turns the subspaces' periods laid on
    /// the output's lattice into those of the measured lights around `light`
    /// ([`PeriodicPart::light_weights`]): the lights' period laid over the subspaces' period
    /// laid, each whole (mean and deviations); `None` where nothing changes. Laying the two
    /// periods' quotient instead put bright specks where a subspace's period is in deep
    /// shadow and the light's is not: the cubic spread the quotient's peak onto lit pixels
    /// (the knit at a 75 degree light: 25 pixels over 20 L* brighter than all their
    /// neighbours, 0 laid whole; measured 2), and judged further (x1.93 against x1.76 the
    /// another-crop level, seed 1). The subspaces' period is floored where it is deep in
    /// shadow ([`LIGHT_PERIOD_FLOOR`]).
    fn light_period(
        &self,
        o: &SynthesisOptions,
        view: &Direction,
        light: &Direction,
    ) -> Result<Option<Array3<f64>>> {
        let Some(p) = self.periodic() else {
            return Ok(None);
        };
        let Some((own, cluster)) =
            self.own_light_coefficients(p.light_weights.as_ref(), &p.periods, view, light)?
        else {
            return Ok(None);
        };
        let lattice = output_lattice(p, o);
        // The coefficients' first entry is the mean's, which the tile takes whole.
        let laid = |coefficients: &[f64]| {
            let tile = p
                .tile_with(coefficients[1..].iter().copied())
                .ok_or_else(|| ModelError::parameter("period", "no mean period"))?;
            let mut out = Array3::zeros((3, o.rows, o.cols));
            for (mut out, tile) in out.outer_iter_mut().zip(tile.outer_iter()) {
                out.assign(&lattice::tiled(&tile.to_owned(), &lattice, o.rows, o.cols));
            }
            Ok::<_, ModelError>(out)
        };
        let (mut factor, under) = (laid(&own)?, laid(&cluster)?);
        for (mut f, u) in factor.outer_iter_mut().zip(under.outer_iter()) {
            let floor = LIGHT_PERIOD_FLOOR * u.mean().unwrap_or(0.0) + f64::MIN_POSITIVE;
            f.zip_mut_with(&u, |f, &u| *f /= u.max(floor));
        }
        Ok(Some(factor))
    }

    /// Subspace image `k` from `cache` (which must come from this model), synthesized on
    /// first use.
    ///
    /// # Errors
    /// `k` out of range.
    pub fn subspace_from_cache<'a>(
        &self,
        cache: &'a SynthesisCache,
        k: usize,
    ) -> Result<&'a Array3<f32>> {
        let slot = cache.subspaces.get(k).ok_or_else(|| {
            ModelError::parameter("subspace", format!("{k} of {}", cache.subspaces.len()))
        })?;
        match slot.get() {
            Some(part) => Ok(part),
            None => {
                // On a pool thread: called from outside the pool, each of the synthesis's many
                // parallel steps would hand its work to the pool and wait (the knit's 1024^2
                // image took 0.15 s longer).
                let made = rayon::scope(|_| {
                    self.subspace_image(
                        k,
                        &cache.options,
                        &cache.noise,
                        (&cache.structure, cache.heights.as_ref()),
                    )
                })?;
                Ok(slot.get_or_init(|| made))
            }
        }
    }

    /// A cache (see [`MaterialModel::synthesis_cache`]) holding exactly the subspace images
    /// `clusters`, synthesized now, in parallel; the others stay unsynthesized. `progress`
    /// counts the images as they are done (task "synthesizing").
    ///
    /// # Errors
    /// An invalid size or a cluster index out of range.
    pub fn synthesis_cache_for(
        &self,
        clusters: &[usize],
        o: &SynthesisOptions,
        progress: &dyn Progress,
    ) -> Result<SynthesisCache> {
        check(self, o)?;
        progress.start("synthesizing", clusters.len() as u64);
        let made = self.synthesized_now(clusters, o, progress);
        progress.finish();
        made
    }

    /// [`MaterialModel::synthesis_cache_for`] between its progress's start and finish.
    fn synthesized_now(
        &self,
        clusters: &[usize],
        o: &SynthesisOptions,
        progress: &dyn Progress,
    ) -> Result<SynthesisCache> {
        // One image alone draws its noise and lets it go (at 4096^2 a GMRF's noise is over
        // 500 MB); more than one keep it to share.
        let noise = if clusters.len() > 1 {
            NoiseBank::kept()
        } else {
            NoiseBank::transient()
        };
        let made = |cache: &SynthesisCache, k: usize| -> Result<()> {
            self.subspace_from_cache(cache, k)?;
            progress.advance(1);
            Ok(())
        };
        // The exemplar detail every image needs comes with the heights where one quilt lays
        // both; the first image draws every band's noise, the others reuse it, in parallel.
        let cache = self.relief_cache(o, noise);
        if let Some((&first, rest)) = clusters.split_first() {
            made(&cache, first)?;
            rest.par_iter().try_for_each(|&k| made(&cache, k))?;
        }
        Ok(cache)
    }

    /// The range map over the output's rows x cols texels, in texels: the heights synthesis
    /// relights its images with, seed for seed; `None` without a range map. The stored map is
    /// quilted (seeded by the synthesis seed) onto a torus of about `rows / step` x `cols /
    /// step` samples and resampled to the output, so the relief keeps its measured structure,
    /// repeats on no grid, and the result tiles exactly at any size; where the exemplar is
    /// registered with the map, by the quilt that lays both (so this lays the exemplar too). A
    /// near-regular material's relief is its mean period laid on the output lattice instead,
    /// in step with the colour's, with the threads' own relief around it
    /// ([`MaterialModel::lattice_relief`]).
    pub fn range_heights(&self, o: &SynthesisOptions) -> Option<Array2<f64>> {
        self.relief_cache(o, NoiseBank::transient()).heights
    }

    /// The range map quilted alone ([`quilt`]) over the output: the heights where no exemplar
    /// or lattice lays them ([`MaterialModel::relief_cache`]).
    fn quilted_heights(&self, o: &SynthesisOptions) -> Option<Array2<f64>> {
        let map = self.range_map()?;
        let (rows, cols, seed) = (o.rows, o.cols, o.seed);
        let side = |n: usize| ((n as f64 / map.step as f64).round() as usize).max(1);
        let (tr, tc) = quilt_torus(o, patch_side(map.rows, map.cols) * map.step);
        let torus = quilt(
            &map.samples(),
            side(tr),
            side(tc),
            crate::mrf::noise::mix(seed, RANGE_SEED),
        );
        Some(cropped(resample_periodic(&torus, tr, tc), rows, cols))
    }

    /// A near-regular material's relief ([`MaterialModel::range_heights`]) and its laid
    /// exemplar: the range map's mean period laid on the output lattice, plus, where the
    /// exemplar was cut from the map's own texels (a map of the whole measured tile at a texel
    /// a sample; the exemplar is cut at the lattice's origin), the map's deviation from its
    /// period laid by the exemplar's quilt. Each thread then keeps the tilts and bulges of the
    /// measured thread its fibres come from, which every light shades its own way; the mean
    /// period alone shaded every thread alike (the knit: x1.76 against x1.46 the another-crop
    /// level at seed 1). `None` without a lattice's height period.
    fn lattice_relief(&self, o: &SynthesisOptions) -> Option<(Array2<f64>, Option<LaidExemplar>)> {
        let (map, p) = (self.range_map()?, self.periodic()?);
        let period = p.height_tile()?;
        let mut heights = lattice::tiled(&period, &output_lattice(p, o), o.rows, o.cols);
        let details = self.exemplar_details(o);
        let measured = (self.height() as usize, self.width() as usize);
        if let (Some(laid), Some(e)) = (&details, self.exemplar())
            && (map.step, e.step) == (1, 1)
            && (map.rows, map.cols) == measured
        {
            let (rows, cols) = laid.placement.source();
            if rows <= map.rows && cols <= map.cols {
                let own = map.samples() - lattice::tiled(&period, &p.lattice, map.rows, map.cols);
                let crop = own.slice(s![..rows, ..cols]).to_owned();
                // At a texel a sample the placement is already the output's size.
                heights += &laid.scale.apply(laid.placement.lay(&crop));
            }
        }
        Some((heights, details))
    }

    /// The exemplar's basis crops with one placement on the output (a quilt chosen on the
    /// first subspace's crop, seeded by the synthesis seed); `None` without an
    /// exemplar. An exemplar registered with the range map is laid with the relief's own
    /// patches instead ([`MaterialModel::laid_together`]).
    fn exemplar_details(&self, o: &SynthesisOptions) -> Option<LaidExemplar> {
        if let Some((_, details)) = self.laid_together(o) {
            return Some(details);
        }
        let e = self.exemplar()?;
        let seed = crate::mrf::noise::mix(o.seed, EXEMPLAR_SEED);
        // A near-regular material's exemplar is cut at the lattice's phase origin; its patches
        // keep their phase, so a thread's fibres stay on the threads the tile lays.
        let phase = self.periodic().map(|p| {
            let out = output_lattice(p, o);
            Phase {
                output: [out.rows, out.cols],
                source: [p.lattice.rows, p.lattice.cols],
            }
        });
        // In phase the cuts matter little (few candidates fit a patch's phase): the mean crop
        // guides. The guide's own quilt is not integrated: only the laid crops are used.
        let guide = if phase.is_some() {
            e.plane(0)?
        } else {
            e.crop(0)?
        };
        // Only the laid crops are used: the guide's own quilt is not kept. The guide is the
        // lightness: its chroma judges the shortlist and the cuts only, but on a tileable
        // torus, whose last patches must fit the first ones on three or four sides, it scans
        // too (a canvas capture's tileable 3D CAR: the wrap's neighbour correlation 3.1
        // standard deviations off the interior's with the lightness alone).
        let scan = if o.tileable {
            CoarseScan::WithCompanions
        } else {
            CoarseScan::GuideAlone
        };
        let placement_only = |g: &_, p: &_, m: &_, size, seed, phase: Option<&Phase>| {
            ((), quilt_placement(g, p, m, size, seed, phase, scan))
        };
        Some(laid_exemplar(&guide, e, o, (seed, phase.as_ref(), true), placement_only).1)
    }

    /// The range map's heights ([`MaterialModel::range_heights`]) and the exemplar's zero-mean
    /// basis details from one quilt ([`quilt_laid`]), when the exemplar is registered with a map
    /// sampled at every pixel and no lattice lays the relief: a pit in the relief and its dark
    /// colour then stay together, and a cell a cut crossed takes one mean colour ([`LaidCells`]).
    /// `None` otherwise.
    fn laid_together(&self, o: &SynthesisOptions) -> Option<(QuiltedRelief, LaidExemplar)> {
        let (map, e) = (self.range_map()?, self.exemplar()?);
        if map.step != e.step
            || (map.rows, map.cols) != (e.rows, e.cols)
            || self.periodic().is_some()
        {
            return None;
        }
        let seed = crate::mrf::noise::mix(o.seed, RANGE_SEED);
        let samples = map.samples();
        let (relief, mut laid) = laid_exemplar(&samples, e, o, (seed, None, false), quilt_laid);
        // At a step the laid samples are the whole torus; at texels, only when tileable.
        let whole_torus = matches!(laid.scale, Scale::Stepped { .. }) || o.tileable;
        laid.cells = Some(LaidCells::new(&samples, &laid.placement, whole_torus));
        Some((relief, laid))
    }

    /// How the relief shades `light`: the measured lights' fitted strengths
    /// ([`crate::geometry::relight`]) blended with the same barycentric weights as the images,
    /// so it changes continuously with the light (1 without stored strengths), and the range
    /// map's shadows.
    ///
    /// # Errors
    /// A non-finite direction.
    pub fn bump_shading(&self, light: &Direction) -> Result<Shading> {
        let Some(map) = self.range_map() else {
            return Ok(Shading::LAMBERT);
        };
        Ok(map.shading_at(
            self.lights()
                .interpolate(light)?
                .iter()
                .map(|w| w.weight * map.strength_of(w.index))
                .sum(),
        ))
    }
}

/// Scales each pixel of `image`, chromaticity kept, so that its L* (seen through the shading
/// `factor` when given) moves `share` (0..=1) of the way to the L* that gives the image the
/// quantiles `lightness` (at [`marginals::band_probabilities`]).
fn match_lightness(
    image: &mut Array3<f32>,
    factor: Option<&Array2<f64>>,
    lightness: &[f64],
    share: f64,
) {
    let mut relit = crate::geometry::relight::luminance(image);
    if let Some(factor) = factor {
        relit.zip_mut_with(factor, |y, &f| *y *= f);
    }
    let current = relit.mapv(|y| f64::from(crate::color::lightness(y as f32)));
    let map = MarginalMap::new(&current, lightness, &marginals::band_probabilities());
    let mut ratio = relit;
    ndarray::Zip::from(&mut ratio)
        .and(&current)
        .par_for_each(|r, &l| {
            let wanted = l + share * (map.apply(l) - l);
            *r = luminance_ratio(*r, wanted);
        });
    scale_pixels(image, &ratio);
}

/// Maps the a* and b* of each pixel of `image` `share` of the way onto the quantiles `wanted`
/// (a* then b*, at the factor probabilities), each on its own, L* kept. A cluster's lights
/// share its representative's chroma: under the built-in leather's near-frontal light the b*
/// quantiles missed the measured ones by 2.3 Lab units. A mapped coordinate per unit of
/// lightness ([`crate::color::chroma_per_lightness`], a function of the chromaticity) is held
/// within the range the image had: mapped on their own, dark pixels took the a* of lit ones,
/// and 8 % of a 64^2 knit's pixels under a 75-degree light left the measured chromaticities.
/// Colours the mapping takes out of the gamut keep their L* and hue
/// ([`crate::color::lab_to_linear_in_gamut`]).
fn match_chroma(image: &mut Array3<f32>, wanted: &[Vec<f64>; 2], share: f64) {
    use crate::color::{chroma_of, chroma_per_lightness};
    let (_, rows, cols) = image.dim();
    let pixel = |image: &Array3<f32>, i: usize| {
        let (y, x) = (i / cols, i % cols);
        [0, 1, 2].map(|c| image[[c, y, x]])
    };
    // The maps come from the regular subsample `quantiles_at` would take of a plane.
    let probabilities = QuantileGrid::NormalTails.probabilities(QUANTILES);
    let stride = marginals::sample_step(rows * cols, cols);
    let sample: Vec<[f32; 3]> = (0..rows * cols)
        .step_by(stride)
        .map(|i| crate::color::linear_to_lab(pixel(image, i)))
        .collect();
    let per_lightness =
        |lab: &[f32; 3], c: usize| chroma_per_lightness(f64::from(lab[c + 1]), f64::from(lab[0]));
    let [map_a, map_b] = [0, 1].map(|c| {
        let have = marginals::sample_quantiles(
            sample.iter().map(|lab| f64::from(lab[c + 1])),
            &probabilities,
        );
        MarginalMap::between(have, &wanted[c], rows * cols)
    });
    // The range of each coordinate per unit of lightness the image already has (none where
    // no sampled value is a number: `min` and `max` skip NaN).
    let [range_a, range_b] = [0, 1].map(|c| {
        let (lo, hi) = sample
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), lab| {
                let v = per_lightness(lab, c);
                (lo.min(v), hi.max(v))
            });
        (lo <= hi).then_some((lo, hi))
    });
    let moved = |c: f32, l: f64, map: &MarginalMap, range: Option<(f64, f64)>| {
        let v = f64::from(c);
        let to = chroma_per_lightness(v + share * (map.apply(v) - v), l);
        let held = range.map_or(to, |(lo, hi)| to.clamp(lo, hi));
        chroma_of(held, l) as f32
    };
    let (mut r, mut g, mut b) =
        image.multi_slice_mut((s![0, .., ..], s![1, .., ..], s![2, .., ..]));
    ndarray::Zip::from(&mut r)
        .and(&mut g)
        .and(&mut b)
        .par_for_each(|r, g, b| {
            let [l, a, bb] = crate::color::linear_to_lab([*r, *g, *b]);
            let lf = f64::from(l);
            [*r, *g, *b] = crate::color::lab_to_linear_in_gamut([
                l,
                moved(a, lf, &map_a, range_a),
                moved(bb, lf, &map_b, range_b),
            ]);
        });
}

/// Adds `delta` to the L* of each pixel of `image`, chromaticity kept (as shading would
/// darken or brighten it).
fn shift_lightness(image: &mut Array3<f32>, delta: &Array2<f64>) {
    let mut ratio = crate::geometry::relight::luminance(image);
    ndarray::Zip::from(&mut ratio)
        .and(delta)
        .par_for_each(|r, &d| {
            let l = f64::from(crate::color::lightness(*r as f32));
            *r = luminance_ratio(*r, (l + d).max(0.0));
        });
    scale_pixels(image, &ratio);
}

/// The factor that takes a pixel of luminance `y` to the lightness `wanted` (1 for a pixel
/// too dark to scale).
fn luminance_ratio(y: f64, wanted: f64) -> f64 {
    let target = f64::from(crate::color::luminance_of_lightness(wanted as f32));
    if y > LIT_DARK { target / y } else { 1.0 }
}

/// The luminance factor that adds `detail` (L* units) to a ratio of lightness `mean`:
/// `Y(mean + d) / Y(mean)` per pixel ([`luminance_ratio`]; 0 where `mean + d` is not above
/// black).
fn ratio_detail_factor(detail: &Array2<f64>, mean: f64) -> Array2<f64> {
    let base = f64::from(crate::color::luminance_of_lightness(mean.max(0.0) as f32));
    detail.mapv(|d| luminance_ratio(base, (mean + d).max(0.0)))
}

/// Multiplies every channel of `image` by `ratio`, pixel by pixel.
fn scale_pixels(image: &mut Array3<f32>, ratio: &Array2<f64>) {
    image
        .axis_iter_mut(Axis(0))
        .into_par_iter()
        .for_each(|mut channel| channel.zip_mut_with(ratio, |v, &r| *v *= r as f32));
}

/// What the light tables ask of an image under (`view`, `light`): the L* table and detail
/// band spreads and a* and b* tables blended over the nearest lights (the images' barycentric
/// weights), and the share the tables' view has in `view` (its barycentric weight, at most 1).
struct LightTarget {
    /// L* quantiles at the band probabilities.
    lightness: Vec<f64>,
    /// Spread of each L* detail band, finest first, where the model stores them.
    spreads: Option<Vec<f64>>,
    /// a* and b* quantiles at the factor probabilities, where the model stores them.
    chroma: Option<[Vec<f64>; 2]>,
    /// How far the image is taken to them (0..=1).
    share: f64,
}

/// The [`LightTarget`] of `tables` for (`view`, `light`); `None` away from the tables' view.
fn light_target(
    model: &MaterialModel,
    tables: &LightLightness,
    view: &Direction,
    light: &Direction,
) -> Result<Option<LightTarget>> {
    let share: f64 = model
        .views()
        .interpolate(view)?
        .iter()
        .filter(|w| w.index == tables.view)
        .map(|w| w.weight)
        .sum();
    if share <= 0.0 {
        return Ok(None);
    }
    let mut lightness = vec![0.0; marginals::BAND_QUANTILES];
    let mut spreads = tables.spreads.as_ref().map(|_| vec![0.0; LIGHTNESS_BANDS]);
    let mut chroma = (tables.chroma.as_ref()).map(|_| [(); 2].map(|_| vec![0.0; QUANTILES]));
    for w in model.lights().interpolate(light)? {
        if let (Some(blend), Some(c)) = (
            &mut chroma,
            tables.chroma.as_ref().and_then(|c| c.get(w.index)),
        ) {
            for (b, &v) in blend.iter_mut().flatten().zip(c.iter().flatten()) {
                *b += w.weight * f64::from(v);
            }
        }
        if let Some(t) = tables.tables.get(w.index) {
            for (b, v) in lightness.iter_mut().zip(&t.lightness) {
                *b += w.weight * v;
            }
        }
        if let (Some(blend), Some(s)) = (
            &mut spreads,
            tables.spreads.as_ref().and_then(|s| s.get(w.index)),
        ) {
            for (b, &v) in blend.iter_mut().zip(s) {
                *b += w.weight * f64::from(v);
            }
        }
    }
    Ok(Some(LightTarget {
        lightness,
        spreads,
        chroma,
        share: share.min(1.0),
    }))
}

/// The finest Laplacian band (band `k` holds periods of 2^(k+1) to 2^(k+2) pixels) that a
/// structure sampled every `step` pixels holds: one whose periods all lie at or below its
/// Nyquist period (`2 * step`) holds no content of its own, and scaling it to the measured
/// spread only amplifies noise (the painted-door capture, sampled every 4 pixels: x0.71 the
/// another-crop level with its two finest bands left alone, x1.00 with every band scaled).
fn finest_held_band(step: usize) -> usize {
    (0..LIGHTNESS_BANDS)
        .find(|&k| (2usize << k) > step)
        .unwrap_or(LIGHTNESS_BANDS)
}

/// The largest factor by which [`respread_lightness`] scales an L* band: a band the synthesis
/// nearly lacks is not blown up from rounding noise.
const MAX_LIGHTNESS_GAIN: f64 = 4.0;

/// Scales each detail band of `image`'s L* pyramid from band `finest` on, `share` of the way
/// to its spread in `wanted` (finest first; chromaticity kept, as [`shift_lightness`]);
/// `border` as the output's. A tileable image is split only as far as it halves exactly.
fn respread_lightness(
    image: &mut Array3<f32>,
    wanted: &[f64],
    (share, finest): (f64, usize),
    border: Border,
) {
    let (_, rows, cols) = image.dim();
    let levels = match border {
        Border::Periodic => exact_levels(rows, cols, LIGHTNESS_BANDS + 1),
        Border::Mirror => LIGHTNESS_BANDS + 1,
    };
    let lightness = ndarray::Zip::from(&crate::geometry::relight::luminance(image))
        .par_map_collect(|&y| f64::from(crate::color::lightness(y as f32)));
    let mut pyramid = Pyramid::decompose_with(&lightness, levels, border);
    let details = pyramid.bands.len() - 1;
    for (band, &want) in pyramid.bands[..details].iter_mut().zip(wanted).skip(finest) {
        let have = spread(band);
        if have > 1e-9 {
            let gain = 1.0 + share * ((want / have).min(MAX_LIGHTNESS_GAIN) - 1.0);
            band.mapv_inplace(|v| gain * v);
        }
    }
    let delta = pyramid.collapse_with(border) - &lightness;
    shift_lightness(image, &delta);
}

/// Share of the subspaces' laid period's mean (per channel) below which [`light_period`]
/// divides by that share instead: where the subspaces' period is deep in shadow their image
/// holds noise and lifted darks rather than the ratio times the period, which the quotient
/// turned into bright specks at the threads' corners (the knit at 512^2 under four lights
/// from 45 to 75 degrees: 105 pixels over 20 L* brighter than all their neighbours, 0 with
/// the floor; the judge at 128^2 unchanged, x1.46). The analysis' ratio is floored alike.
///
/// [`light_period`]: MaterialModel::light_period
const LIGHT_PERIOD_FLOOR: f64 = 0.05;

/// Relit luminance below which [`match_lit`] leaves a pixel as it is (a ratio of noise).
const LIT_DARK: f64 = 1e-6;

/// The lattice on the output: the measured periods, on a torus the nearest ones that fit a
/// whole number of times (so the weave wraps without a seam).
fn output_lattice(p: &PeriodicPart, o: &SynthesisOptions) -> Lattice {
    Lattice {
        rows: lattice::output_period(p.lattice.rows, o.rows, o.tileable),
        cols: lattice::output_period(p.lattice.cols, o.cols, o.tileable),
    }
}

/// The torus (rows, cols) a quilt is laid on for an output of `o`: the output itself when it
/// must tile; else `margin` texels (a patch) larger each way, so that the wrap-around joins,
/// where the last patches must fit the first ones again and their seams show (measured: a
/// straight line of broken mortar across a 512^2 brick wall), fall outside the output.
fn quilt_torus(o: &SynthesisOptions, margin: usize) -> (usize, usize) {
    let grown = |n: usize| if o.tileable { n } else { n + margin }.max(1);
    (grown(o.rows), grown(o.cols))
}

/// The top-left `rows` x `cols` of `field` (at least one sample each way).
fn cropped(field: Array2<f64>, rows: usize, cols: usize) -> Array2<f64> {
    let (r, c) = (
        rows.max(1).min(field.nrows()),
        cols.max(1).min(field.ncols()),
    );
    if (r, c) == field.dim() {
        return field;
    }
    field.slice(s![..r, ..c]).to_owned()
}

/// Mixed into the synthesis seed for the range map's quilt (the bands use their own indices).
const RANGE_SEED: u64 = 0x7261_6e67_655f_6d61;
/// `guide` quilted for the output of `o` (on [`quilt_torus`]) with the exemplar's basis crops
/// laid by the same patches: what `quilt` keeps of the guide's own quilt ([`quilt_laid`]: its
/// differences, not yet integrated; [`quilt_placement`]: nothing), and the crops with their
/// placement on the output; with a phase, every patch keeps the lattice's phase. The mean crop's colour (its a* and b*, and its L* when the guide
/// is not itself a lightness) helps the guide choose the patches and cuts, so fewer cuts join two
/// colours on one flat surface.
fn laid_exemplar<R>(
    guide: &Array2<f64>,
    e: &Exemplar,
    o: &SynthesisOptions,
    (seed, phase, guide_is_lightness): (u64, Option<&Phase>, bool),
    quilt: impl FnOnce(
        &Array2<f64>,
        &[Array2<f64>],
        &[usize],
        (usize, usize),
        u64,
        Option<&Phase>,
    ) -> (R, Placement),
) -> (R, LaidExemplar) {
    let (scale, torus) = Scale::new(o, e.step, patch_side(e.rows, e.cols));
    let (planes, matched) = exemplar_planes(e, guide_is_lightness);
    let (relief, placement) = quilt(guide, &planes, &matched, torus, seed, phase);
    let placement = match scale {
        Scale::Texels => placement.cropped(o.rows, o.cols),
        Scale::Stepped { .. } => placement,
    };
    (
        relief,
        LaidExemplar {
            placement,
            scale,
            planes,
            lightness: e.lightness.basis.len(),
            cells: None,
        },
    )
}

/// The exemplar's basis crops as planes at the crop's pixels: the L* mean and deviations, then
/// each chroma basis field's a* and b*; and the indices of the mean crop's planes that help
/// choose the quilt's patches (its a* and b*, and its L* unless `guide_is_lightness`).
fn exemplar_planes(e: &Exemplar, guide_is_lightness: bool) -> (Vec<Array2<f64>>, Vec<usize>) {
    let mut planes: Vec<Array2<f64>> = (0..e.lightness.basis.len())
        .filter_map(|j| e.plane(j))
        .collect();
    let mut matched = Vec::new();
    if !guide_is_lightness && !planes.is_empty() {
        matched.push(0);
    }
    let first_chroma = planes.len();
    planes.extend(e.chroma.iter().flat_map(|c| {
        (0..c.fields.basis.len())
            .filter_map(|j| c.crop_planes(j, e.rows, e.cols))
            .flatten()
    }));
    if planes.len() >= first_chroma + 2 {
        matched.extend([first_chroma, first_chroma + 1]);
    }
    (planes, matched)
}

/// Mixed into the synthesis seed for the exemplar's quilt.
const EXEMPLAR_SEED: u64 = 0x6578_656d_706c_6172;

/// Bump mapping (mrf_math.md 1(g)): multiplies an image by the shading factor
/// `1 + strength (s - 1)`, `s = max(0, n . l) / mean(max(0, n . l))`, of the unit normals `n`
/// of `heights` (range-map texels, differences as `border` says); see
/// [`crate::geometry::relight`]. The factor's mean is 1, so the subspace image's own average
/// shading is not applied twice; it is floored at [`SHADING_FLOOR`], the floor the analysis
/// divided out (without it, full-strength attached shadows came out black: 5 % of a
/// synthesized sponge's pixels, where the measured one's darkest is 0.12). Lights so low that
/// almost nothing is lit leave the image as it is.
pub fn bump_relight(
    image: &mut Array3<f32>,
    heights: &Array2<f64>,
    border: Edges,
    light: &Direction,
    shading: Shading,
) {
    let Some(factor) = relief_factor(heights, border, light, shading) else {
        return;
    };
    scale_pixels(image, &factor);
}

/// The factor [`bump_relight`] multiplies every channel by: the relief's shading factor
/// under `light` at `strength` ([`shading_factor`]), floored at [`SHADING_FLOOR`]; `None`
/// where the light leaves the relief unlit (the image is left as it is).
pub fn relief_factor(
    heights: &Array2<f64>,
    border: Edges,
    light: &Direction,
    shading: Shading,
) -> Option<Array2<f64>> {
    let l = light.vector();
    shading_factor(heights, border, [l[0], l[1], l[2]], shading)
        .map(|f| f.mapv(|s| s.max(SHADING_FLOOR)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::LitMarginals;

    #[test]
    fn a_pairs_finish_is_what_its_own_parts_add_to_its_relit_subspace_image() {
        // The ready stones: light tables and each light's own detail in view 0.
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/stones.btfm");
        let model = crate::model::format::read(&path).unwrap();
        let o = SynthesisOptions {
            rows: 64,
            cols: 64,
            seed: 3,
            tileable: true,
        };
        let cache = model.synthesis_cache(&o).unwrap();
        let (view, light) = (0, 30);
        assert!(model.has_own_parts(view, light));
        let finish = model.pair_finish(&cache, view, light).unwrap().unwrap();
        // Its subspace image at its gain, relit by the public pieces, plus the finish is the
        // finished image.
        let (v, l) = (
            model.views().as_slice()[view],
            model.lights().as_slice()[light],
        );
        let k = model.cluster_of(view, light).unwrap();
        let gain = model.pair_gain(view, light) as f32;
        let mut plain = model
            .subspace_from_cache(&cache, k)
            .unwrap()
            .mapv(|x| gain * x);
        let shading = model.bump_shading(&l).unwrap();
        bump_relight(&mut plain, cache.heights().unwrap(), o.edges(), &l, shading);
        let finished = model.image_from_cache(&cache, &v, &l).unwrap();
        let apart = (&plain + &*finish - &finished)
            .iter()
            .fold(0.0f32, |m, x| m.max(x.abs()));
        assert!(apart < 1e-5, "{apart}");
        // The parts change the image, and the finish is made once per cache.
        assert!(finish.iter().any(|x| x.abs() > 0.01));
        let again = model.pair_finish(&cache, view, light).unwrap().unwrap();
        assert!(Arc::ptr_eq(&finish, &again));
        // Another view has no parts of its own; a pair beyond the set is an error.
        assert!(!model.has_own_parts(1, light));
        assert!(model.pair_finish(&cache, 1, light).unwrap().is_none());
        assert!(model.pair_finish(&cache, 0, 81).is_err());
    }

    #[test]
    fn a_ratio_at_its_mean_lightness_moves_by_the_detail() {
        let detail = Array2::from_shape_vec((1, 4), vec![-12.0, -2.5, 0.0, 7.5]).unwrap();
        let mean = 61.0;
        let factor = ratio_detail_factor(&detail, mean);
        let y = crate::color::luminance_of_lightness(mean as f32);
        for (d, f) in detail.iter().zip(&factor) {
            let moved = f64::from(crate::color::lightness(y * *f as f32));
            assert!((moved - (mean + d)).abs() < 1e-3, "{d}: {moved}");
        }
        // Detail that would take the ratio below black (a hostile file's) darkens to black.
        let below = Array2::from_elem((1, 1), -80.0);
        assert_eq!(ratio_detail_factor(&below, mean)[[0, 0]], 0.0);
    }

    #[test]
    fn bands_finer_than_the_samples_are_left_alone() {
        // Band k holds periods of 2^(k+1) to 2^(k+2) pixels; samples every `step` pixels hold
        // periods from 2 * step.
        for (step, finest) in [(1, 0), (2, 1), (3, 1), (4, 2), (7, 2), (8, 3), (64, 5)] {
            assert_eq!(finest_held_band(step), finest, "step {step}");
        }
    }

    #[test]
    fn respread_bands_take_the_wanted_spreads_and_the_rest_stays() {
        // A mid-grey image with detail at every scale, colour kept per pixel.
        let (rows, cols) = (96, 80);
        let image = Array3::from_shape_fn((3, rows, cols), |(c, y, x)| {
            let v = 0.25
                + 0.05 * ((x as f64) * 1.7).sin()
                + 0.04 * ((y as f64) * 0.45).cos()
                + 0.03 * ((x + 2 * y) as f64 * 0.13).sin();
            (v * (0.9 + 0.1 * c as f64)) as f32
        });
        let bands = |image: &Array3<f32>| {
            let [l, _, _] = ColourSpace::Lab.planes(image);
            crate::decompose::pyramid::detail_spreads(&l, LIGHTNESS_BANDS)
        };
        let before = bands(&image);
        let wanted: Vec<f64> = before.iter().map(|s| 1.3 * s).collect();
        let mut out = image.clone();
        respread_lightness(&mut out, &wanted, (1.0, 1), Border::Mirror);
        let after = bands(&out);
        // The finest band is left as it was (up to what the others leak into it: scaled bands
        // are not a Laplacian pyramid of anything, so the image they collapse to splits into
        // slightly different ones), every other one comes most of the way to its wanted spread
        // (from 23 % below it).
        assert!(
            (after[0] / before[0] - 1.0).abs() < 0.05,
            "{after:?} {before:?}"
        );
        for k in 1..LIGHTNESS_BANDS {
            assert!(
                (after[k] / wanted[k] - 1.0).abs() < 0.1,
                "band {k}: {after:?} {wanted:?}"
            );
        }
        // Halfway: about half the gain.
        let mut half = image.clone();
        respread_lightness(&mut half, &wanted, (0.5, 0), Border::Mirror);
        for (k, (a, b)) in bands(&half).iter().zip(&before).enumerate() {
            assert!((a / b - 1.15).abs() < 0.06, "band {k}: {a} from {b}");
        }
        // Chromaticity kept: the channels' ratios do not move.
        for (o, i) in out.lanes(Axis(0)).into_iter().zip(image.lanes(Axis(0))) {
            assert!((o[2] / o[0] - i[2] / i[0]).abs() < 1e-4);
        }
    }

    #[test]
    fn relighting_at_the_measured_light_undoes_the_de_shading_even_in_deep_shadow() {
        // Steep ridges under a low light: full strength leaves the far slopes at a factor
        // below the floor (0 where they face away).
        let heights = Array2::from_shape_fn((32, 40), |(y, x)| {
            6.0 * ((x as f64) / 2.0).sin() + y as f64 * 0.1
        });
        let light = Direction::new(70.0, 0.0);
        let l = light.vector();
        let factor = shading_factor(&heights, Edges::Clamp, l, Shading::LAMBERT).unwrap();
        assert!(
            factor.iter().any(|&f| f < SHADING_FLOOR),
            "no deep shadow to test"
        );
        // A photograph whose shadows are not black (ambient light), bright enough that the
        // de-shading keeps every pixel's colour.
        let photo = Array3::from_shape_fn((3, 32, 40), |(c, y, x)| {
            (0.05 + 0.1 * c as f64 + 0.3 * factor[[y, x]] + 0.002 * ((x * 7 + y) % 5) as f64) as f32
        });
        let mut texture = photo.clone();
        crate::geometry::relight::remove_shading(&mut texture, &heights, l, Shading::LAMBERT);
        bump_relight(
            &mut texture,
            &heights,
            Edges::Clamp,
            &light,
            Shading::LAMBERT,
        );
        for (a, b) in texture.iter().zip(&photo) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    #[test]
    fn lit_matching_gives_the_relit_image_the_tables_lightness_and_keeps_chromaticity() {
        let (h, w) = (48, 40);
        // A coloured texture and a shading factor that does not follow it.
        let mut image = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            let t = 0.3 + 0.1 * ((x as f32 * 0.7).sin() + (y as f32 * 0.4).cos());
            t * [1.0, 0.8, 0.5][c]
        });
        let factor =
            Array2::from_shape_fn((h, w), |(y, x)| 0.4 + ((x * 3 + y * 5) % 11) as f64 / 8.0);
        // The wanted lightness: a wider, brighter spread than the relit image's.
        let probabilities = marginals::band_probabilities();
        let lit = LitMarginals {
            lightness: probabilities.iter().map(|p| 30.0 + 50.0 * p).collect(),
        };
        let before = image.clone();
        match_lightness(&mut image, Some(&factor), &lit.lightness, 1.0);
        // Each pixel scaled as a whole: its chromaticity is kept.
        for y in 0..h {
            for x in 0..w {
                let r = image[[0, y, x]] / before[[0, y, x]];
                for c in 1..3 {
                    assert!((image[[c, y, x]] / before[[c, y, x]] - r).abs() < 1e-4 * r);
                }
            }
        }
        // Relit, its L* quantiles are the table's.
        let mut relit = image.clone();
        for mut channel in relit.axis_iter_mut(Axis(0)) {
            channel.zip_mut_with(&factor, |v, &f| *v = (f64::from(*v) * f) as f32);
        }
        let [lightness, _, _] = ColourSpace::Lab.planes(&relit);
        let got = marginals::quantiles_at(&lightness, &probabilities);
        for (g, t) in got.iter().zip(&lit.lightness) {
            assert!((g - t).abs() < 0.5, "{got:?}");
        }
    }

    #[test]
    fn a_share_of_the_lightness_match_moves_each_quantile_that_share_of_the_way() {
        let (h, w) = (40, 48);
        let image = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            let t = 0.2 + 0.15 * ((x as f32 * 0.9).sin() + (y as f32 * 0.5).cos()).abs();
            t * [0.9, 1.0, 0.6][c]
        });
        let probabilities = marginals::band_probabilities();
        let quantiles = |image: &Array3<f32>| {
            let [lightness, _, _] = ColourSpace::Lab.planes(image);
            marginals::quantiles_at(&lightness, &probabilities)
        };
        let before = quantiles(&image);
        let table: Vec<f64> = probabilities.iter().map(|p| 20.0 + 60.0 * p).collect();
        for share in [1.0, 0.5, 0.0] {
            let mut matched = image.clone();
            match_lightness(&mut matched, None, &table, share);
            for ((got, b), t) in quantiles(&matched).iter().zip(&before).zip(&table) {
                let wanted = b + share * (t - b);
                assert!(
                    (got - wanted).abs() < 0.5,
                    "share {share}: {got} vs {wanted}"
                );
            }
            // Every pixel scaled as a whole: its chromaticity is kept.
            for (a, b) in matched.lanes(Axis(0)).into_iter().zip(image.lanes(Axis(0))) {
                let r = a[1] / b[1];
                assert!((a[0] / b[0] - r).abs() < 1e-4 * r && (a[2] / b[2] - r).abs() < 1e-4 * r);
            }
        }
    }

    #[test]
    fn a_share_of_the_chroma_match_moves_each_quantile_that_share_of_the_way_at_fixed_lightness() {
        // A brownish texture whose chroma follows its own pattern, not its lightness.
        let (h, w) = (40, 48);
        let image = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            let t = 0.2 + 0.1 * ((x as f32 * 0.9).sin() + (y as f32 * 0.5).cos()).abs();
            let tint = 0.08 * ((x + 3 * y) as f32 * 0.31).sin();
            t * [0.9 + tint, 0.7, 0.45 - tint][c]
        });
        let probabilities = QuantileGrid::NormalTails.probabilities(QUANTILES);
        let quantiles = |plane: &Array2<f64>| marginals::quantiles_at(plane, &probabilities);
        let before = ColourSpace::Lab.planes(&image);
        // Wanted: both narrowed about their means (inside the chroma the image has).
        let narrowed = |p: &Array2<f64>| {
            let m = p.mean().unwrap();
            quantiles(&p.mapv(|v| m + 0.6 * (v - m)))
        };
        let wanted = [narrowed(&before[1]), narrowed(&before[2])];
        for share in [1.0, 0.5, 0.0] {
            let mut matched = image.clone();
            match_chroma(&mut matched, &wanted, share);
            let after = ColourSpace::Lab.planes(&matched);
            for c in 0..2 {
                let (had, got) = (quantiles(&before[c + 1]), quantiles(&after[c + 1]));
                for ((g, b), t) in got.iter().zip(&had).zip(&wanted[c]) {
                    let expected = b + share * (t - b);
                    assert!(
                        (g - expected).abs() < 0.05,
                        "share {share}, channel {c}: {g} vs {expected}"
                    );
                }
            }
            for (a, b) in after[0].iter().zip(&before[0]) {
                assert!((a - b).abs() < 1e-3, "L* moved: {a} vs {b}");
            }
        }
    }

    #[test]
    fn the_chroma_match_adds_no_chroma_per_unit_of_lightness_the_image_lacks() {
        // Dark and bright pixels of one colour, and a wanted a* far beyond it: the dark
        // pixels would take the bright ones' a* (a saturated speck), but no pixel's a* per
        // unit of lightness leaves the image's own range.
        let (h, w) = (32, 32);
        let image = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            let t = if (x + y) % 4 == 0 {
                0.03
            } else {
                0.4 + 0.01 * (x % 5) as f32
            };
            t * [0.8, 0.5, 0.4][c]
        });
        let per_lightness = |image: &Array3<f32>| -> Vec<f64> {
            let [l, a, _] = ColourSpace::Lab.planes(image);
            (l.iter().zip(&a))
                .map(|(&l, &a)| crate::color::chroma_per_lightness(a, l))
                .collect()
        };
        let had = per_lightness(&image);
        let (lo, hi) = had
            .iter()
            .fold((f64::MAX, f64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        let [_, a, b] = ColourSpace::Lab.planes(&image);
        let probabilities = QuantileGrid::NormalTails.probabilities(QUANTILES);
        let wanted = [
            marginals::quantiles_at(&a.mapv(|v| 3.0 * v + 20.0), &probabilities),
            marginals::quantiles_at(&b, &probabilities),
        ];
        let mut matched = image.clone();
        match_chroma(&mut matched, &wanted, 1.0);
        for v in per_lightness(&matched) {
            assert!(v >= lo - 1e-4 && v <= hi + 1e-4, "{v} outside {lo}..{hi}");
        }
    }

    #[test]
    fn band_seeds_differ_for_every_seed_stream_and_level() {
        let mut seen = std::collections::HashSet::new();
        for seed in 0..4 {
            for stream in 0..4 {
                for level in 0..16 {
                    let s = band_seed(seed, stream, level);
                    assert!(seen.insert(s), "{seed} {stream} {level} repeats {s}");
                }
            }
        }
    }

    #[test]
    fn one_plane_models_draw_their_factor_stream_and_joint_models_their_own() {
        let streams: Vec<usize> = (0..3).map(|f| noise_stream(1, f)).collect();
        assert_eq!(streams, [0, 1, 2]);
        assert_eq!(noise_stream(3, 0), 3);
    }
}
