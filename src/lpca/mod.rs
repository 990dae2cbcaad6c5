//! Local PCA compression of BTFs (Müller, Meseth and Klein 2003), with global PCA and
//! per-view PCA as two more baselines sharing the same code.
//!
//! Three methods, all stored in one [`LpcaModel`] (file format `.lpca`, [`format`]):
//!
//! | [`Method`] | arrangement ([`data`]) | clusters | per-texel or per-image data | survey |
//! |---|---|---|---|---|
//! | `Lpca` | BRDF-wise: one vector per texel, `views * lights * 3` values | `K` | cluster index + `C` weights per texel | 4.2.3 (LPCA BTF) |
//! | `PcaBtf` | image-wise: one vector per image, `3 * height * width` values | 1 | `C` weights per image | 4.2.2 (PCA BTF, eigen-textures) |
//! | `PcaRf` | per view, one vector per texel: `lights * 3` values | 1 per view | `C` weights per texel and view | 4.2.1 (PCA RF) |
//!
//! All are fitted by [`cluster::fit_rows`] (with `K = 1` for the two PCA baselines) and
//! [`pca::principal_directions`] (Gram-matrix PCA, never a `d x d` covariance for long
//! vectors). PCA RF follows the arrangement of Müller et al. (per-texel vectors, here one
//! factorization per view); the survey's PCA RF decomposes the same per-view matrix
//! transposed (eigen-images), which differs only in the centring and in what is stored.
//!
//! Every stored number is kept as an IEEE half float, as the paper does; the model in memory
//! is rounded the same way right after fitting, so errors reported by [`LpcaModel::fit`] are
//! the errors of the file.
//!
//! ```no_run
//! use btfmrf::btf::{Btf, synthetic::SyntheticMaterial};
//! use btfmrf::lpca::{LpcaModel, LpcaOptions, Method};
//! use btfmrf::progress::NoProgress;
//!
//! let btf = Btf::synthetic(SyntheticMaterial::Stones, 32, 7).unwrap();
//! let options = LpcaOptions { clusters: 8, components: 4, ..LpcaOptions::default() };
//! let (model, report) = LpcaModel::fit(&btf, &options, &NoProgress).unwrap();
//! println!("mean ΔE {:.2}, {} bytes", report.mean_delta_e, model.to_bytes().len());
//! let image = model.reconstruct(0, 10).unwrap(); // (3, 32, 32) linear RGB
//! ```

pub mod cluster;
pub mod data;
pub mod error;
pub mod format;
pub mod pca;

use std::sync::Arc;
use std::time::Instant;

use ndarray::Array3;
use rayon::prelude::*;

pub use cluster::{Factorization, FactorizationOptions, FitStats, fit_rows};
pub use error::{LpcaError, Result};

use data::Layout;

use crate::btf::{Btf, BtfError, Direction, DirectionSet, ImageSource};
use crate::color::{Srgb8Encoder, delta_e76, linear_to_lab, srgb8_to_linear_table};
use crate::progress::{NoProgress, Progress};

/// The most principal components per cluster accepted.
pub const MAX_COMPONENTS: usize = 1024;

/// Which factorization a model holds (see the table in the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Local PCA over BRDF-wise texel vectors (Müller et al. 2003; survey 4.2.3).
    Lpca,
    /// One global PCA over whole images, eigen-textures (survey 4.2.2).
    PcaBtf,
    /// One PCA per view over the texels' reflectance fields (survey 4.2.1).
    PcaRf,
}

impl Method {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::Lpca => "lpca",
            Method::PcaBtf => "pca-btf",
            Method::PcaRf => "pca-rf",
        }
    }
}

/// Parameters of [`LpcaModel::fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LpcaOptions {
    /// The factorization.
    pub method: Method,
    /// Clusters `K` (LPCA only; the PCA baselines use one cluster).
    pub clusters: usize,
    /// Principal components `C` per cluster (per view for PCA RF).
    pub components: usize,
    /// The most clustering updates (LPCA only).
    pub max_iterations: usize,
    /// Stop when the mean squared error changes by less than this fraction (LPCA only).
    pub tolerance: f64,
    /// Seed of the initial cluster centres and of randomized PCA.
    pub seed: u64,
    /// Whether to measure ΔE and PSNR of every image after fitting (fills the report's
    /// error fields; costs about one pass over the data).
    pub evaluate: bool,
}

impl Default for LpcaOptions {
    /// LPCA with 32 clusters and 8 components (the paper's typical setting), at most 20
    /// updates, tolerance 1e-3, seed 1, evaluated.
    fn default() -> Self {
        Self {
            method: Method::Lpca,
            clusters: 32,
            components: 8,
            max_iterations: 20,
            tolerance: 1e-3,
            seed: 1,
            evaluate: true,
        }
    }
}

/// What fitting measured. Errors are against the input BTF, both sides quantised to 8-bit
/// sRGB as a stored BTF is.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LpcaReport {
    /// The factorization fitted.
    pub method: Method,
    /// Clusters actually used (1 for the PCA baselines).
    pub clusters: usize,
    /// Components per cluster.
    pub components: usize,
    /// Clustering updates made (per view for PCA RF: the most of any view).
    pub iterations: usize,
    /// Whether the clustering met its tolerance before `max_iterations`.
    pub converged: bool,
    /// Mean squared reconstruction error per vector (linear RGB, summed over a vector's values)
    /// after each assignment; the last is the final model's, before half-float rounding.
    pub error_history: Vec<f64>,
    /// Seconds spent reading and arranging the images.
    pub load_seconds: f64,
    /// Seconds spent fitting (clustering, PCA, rounding).
    pub fit_seconds: f64,
    /// Seconds spent measuring the errors.
    pub evaluation_seconds: f64,
    /// Mean CIE76 ΔE over every pixel of every image (NaN when not evaluated).
    pub mean_delta_e: f64,
    /// PSNR over every 8-bit sample, dB (NaN when not evaluated).
    pub psnr_db: f64,
    /// Mean ΔE of each view over all its lights and pixels (the survey's Fig. 10 curve).
    pub per_view_delta_e: Vec<f64>,
    /// Mean ΔE of every image, index `view * lights + light`.
    pub per_image_delta_e: Vec<f64>,
}

/// A BTF compressed by local PCA, global PCA or per-view PCA; see the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct LpcaModel {
    method: Method,
    views: DirectionSet,
    lights: DirectionSet,
    width: usize,
    height: usize,
    /// One factorization (LPCA, PCA BTF) or one per view (PCA RF).
    parts: Vec<Factorization>,
}

impl LpcaModel {
    /// Fits a model to `btf`, reading every image once, and (with `options.evaluate`)
    /// measures its error against every image.
    ///
    /// Memory: the whole BTF as f32 for LPCA and PCA BTF (`width * height * views * lights *
    /// 12` bytes, 1.3 GB for 128 x 128 Bonn data), one view for PCA RF.
    ///
    /// # Errors
    /// Unreadable images, parameters out of range (more clusters than texels, more components
    /// than values per vector), not enough memory, or a failed eigen decomposition.
    pub fn fit(
        btf: &Btf,
        options: &LpcaOptions,
        progress: &dyn Progress,
    ) -> Result<(LpcaModel, LpcaReport)> {
        let job = Job::new(btf, options)?;
        match options.method {
            Method::Lpca => job.fit_lpca(btf, progress),
            Method::PcaBtf => job.fit_pca_btf(btf, progress),
            Method::PcaRf => job.fit_pca_rf(btf, progress),
        }
    }

    /// The factorization.
    pub fn method(&self) -> Method {
        self.method
    }

    /// The measured view directions (image index order).
    pub fn views(&self) -> &DirectionSet {
        &self.views
    }

    /// The measured light directions (image index order).
    pub fn lights(&self) -> &DirectionSet {
        &self.lights
    }

    /// Image width in texels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Image height in texels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Clusters per factorization (1 for the PCA baselines).
    pub fn clusters(&self) -> usize {
        self.parts.first().map_or(0, Factorization::clusters)
    }

    /// Components per cluster.
    pub fn components(&self) -> usize {
        self.parts.first().map_or(0, Factorization::components)
    }

    /// The factorizations: one for LPCA and PCA BTF, one per view for PCA RF.
    pub fn parts(&self) -> &[Factorization] {
        &self.parts
    }

    /// Image (view, light) rebuilt from the model: planar `(3, height, width)` linear RGB,
    /// negative values clamped to 0.
    ///
    /// # Errors
    /// An index out of range.
    pub fn reconstruct(&self, view: usize, light: usize) -> Result<Array3<f32>> {
        let (nv, nl) = (self.views.len(), self.lights.len());
        if view >= nv || light >= nl {
            return Err(LpcaError::parameter(
                "image index",
                format!("(view {view}, light {light}) is outside {nv} views x {nl} lights"),
            ));
        }
        let (h, w) = (self.height, self.width);
        let npx = h * w;
        let mut out = vec![0.0f32; 3 * npx];
        match self.method {
            Method::Lpca | Method::PcaRf => {
                let (f, col) = if self.method == Method::Lpca {
                    (&self.parts[0], (view * nl + light) * 3)
                } else {
                    (&self.parts[view], light * 3)
                };
                // Per cluster, the (C + 1) x 3 numbers this image needs.
                let terms = f.components() + 1;
                let table: Vec<f32> = (0..f.clusters())
                    .flat_map(|j| f.rgb_terms(j, col))
                    .flatten()
                    .collect();
                let (r, rest) = out.split_at_mut(npx);
                let (g, b) = rest.split_at_mut(npx);
                r.par_iter_mut()
                    .zip(g.par_iter_mut())
                    .zip(b.par_iter_mut())
                    .enumerate()
                    .for_each(|(x, ((r, g), b))| {
                        let j = f.cluster_of(x);
                        let tab = &table[j * terms * 3..(j + 1) * terms * 3];
                        let mut acc = [tab[0], tab[1], tab[2]];
                        for (t, &wt) in f.weights_of(x).iter().enumerate() {
                            for ch in 0..3 {
                                acc[ch] += wt * tab[(1 + t) * 3 + ch];
                            }
                        }
                        *r = acc[0].max(0.0);
                        *g = acc[1].max(0.0);
                        *b = acc[2].max(0.0);
                    });
            }
            Method::PcaBtf => {
                // One row per image: the image is the row's reconstruction, planar.
                let f = &self.parts[0];
                let (mean, wts) = (f.mean(0), f.weights_of(view * nl + light));
                let basis: Vec<&[f32]> = (0..f.components()).map(|t| f.component(0, t)).collect();
                out.par_iter_mut().enumerate().for_each(|(i, o)| {
                    let mut v = mean[i];
                    for (&wt, e) in wts.iter().zip(&basis) {
                        v += wt * e[i];
                    }
                    *o = v.max(0.0);
                });
            }
        }
        Ok(Array3::from_shape_vec((3, h, w), out).expect("shape"))
    }

    /// The image for any view and light direction: the 3 nearest measured views times the 3
    /// nearest measured lights (barycentric weights, as in the paper's renderer, section 4.1),
    /// up to 9 reconstructed images blended, faded past the lowest light
    /// ([`DirectionSet::irradiance_beyond_lowest`]).
    ///
    /// # Errors
    /// A non-finite direction.
    pub fn reconstruct_direction(
        &self,
        view: &Direction,
        light: &Direction,
    ) -> Result<Array3<f32>> {
        let wv = self.views.interpolate(view)?;
        let wl = self.lights.interpolate(light)?;
        let fade = self.lights.irradiance_beyond_lowest(light) as f32;
        let mut out = Array3::<f32>::zeros((3, self.height, self.width));
        for a in wv {
            for b in wl {
                let weight = fade * (a.weight * b.weight) as f32;
                if weight > 0.0 {
                    let im = self.reconstruct(a.index, b.index)?;
                    out.scaled_add(weight, &im);
                }
            }
        }
        Ok(out)
    }

    /// The model as a lazy [`Btf`] over its measured directions: every `image()` call
    /// reconstructs one image. Useful to write the whole reconstruction as a UBO2003 archive.
    ///
    /// # Errors
    /// Sizes that do not fit a BTF (never for a fitted or parsed model).
    pub fn into_btf(self) -> Result<Btf> {
        let (views, lights) = (self.views.clone(), self.lights.clone());
        let (w, h) = (self.width as u32, self.height as u32);
        let label = format!("{} reconstruction", self.method.name());
        Ok(Btf::from_source(
            label,
            views,
            lights,
            w,
            h,
            Box::new(Reconstruction(Arc::new(self))),
        )?)
    }

    /// Serialises the model as a `.lpca` file (see [`format`]).
    pub fn to_bytes(&self) -> Vec<u8> {
        format::to_bytes(self)
    }

    /// Parses a `.lpca` file's bytes; `path` is named in errors.
    ///
    /// # Errors
    /// See [`format::from_bytes`].
    pub fn from_bytes(bytes: &[u8], path: &std::path::Path) -> Result<Self> {
        format::from_bytes(bytes, path)
    }

    /// Builds a model from parts, checking that they fit together (used by the file reader):
    /// as many factorizations as `method` keeps for this shape, each of the row count and
    /// vector length the method arranges the BTF into ([`data`]), one component count, and one
    /// cluster each except for LPCA.
    ///
    /// # Errors
    /// The reason the parts do not fit.
    pub(crate) fn from_parts(
        method: Method,
        views: DirectionSet,
        lights: DirectionSet,
        (width, height): (usize, usize),
        parts: Vec<Factorization>,
    ) -> std::result::Result<Self, String> {
        let layout = Layout::of(method, width, height, views.len(), lights.len());
        if parts.len() != layout.parts {
            return Err(format!(
                "{} factorizations for a {} model of {} views (expected {})",
                parts.len(),
                method.name(),
                views.len(),
                layout.parts
            ));
        }
        let components = parts.first().map_or(0, Factorization::components);
        for (i, f) in parts.iter().enumerate() {
            if f.items() != layout.rows || f.dim() != layout.dim {
                return Err(format!(
                    "part {i}: {} vectors of {} values where a {} model of {width}x{height} \
                     texels, {} views and {} lights has {} of {}",
                    f.items(),
                    f.dim(),
                    method.name(),
                    views.len(),
                    lights.len(),
                    layout.rows,
                    layout.dim
                ));
            }
            if f.components() != components {
                return Err(format!(
                    "part {i}: {} components where part 0 has {components}",
                    f.components()
                ));
            }
            if method != Method::Lpca && f.clusters() != 1 {
                return Err(format!(
                    "part {i}: {} clusters in a {} model (one expected)",
                    f.clusters(),
                    method.name()
                ));
            }
        }
        Ok(Self {
            method,
            views,
            lights,
            width,
            height,
            parts,
        })
    }
}

/// One fit: the checked options, the model being built and the report being filled.
struct Job {
    options: LpcaOptions,
    factorization: FactorizationOptions,
    model: LpcaModel,
    report: LpcaReport,
}

impl Job {
    /// Checks `options` against `btf` and the `.lpca` limits before any image is read.
    fn new(btf: &Btf, options: &LpcaOptions) -> Result<Self> {
        let (w, h) = (btf.width() as usize, btf.height() as usize);
        let (nv, nl) = (btf.views().len(), btf.lights().len());
        let clusters = if options.method == Method::Lpca {
            options.clusters
        } else {
            1
        };
        if options.components > MAX_COMPONENTS {
            return Err(LpcaError::parameter(
                "--components",
                format!("{} is above {MAX_COMPONENTS}", options.components),
            ));
        }
        let limit = usize::from(u16::MAX);
        if nv > limit || nl > limit {
            return Err(LpcaError::parameter(
                "btf",
                format!("{nv} views x {nl} lights: a .lpca model holds at most {limit} of each"),
            ));
        }
        if clusters > limit {
            return Err(LpcaError::parameter(
                "--clusters",
                format!("{clusters} is above {limit}"),
            ));
        }
        let payload = |clusters| {
            format::payload_len(options.method, w, h, nv, nl, clusters, options.components)
        };
        let bytes = payload(clusters);
        if bytes > u64::from(format::MAX_PAYLOAD) {
            // Blame the option that alone would make it fit, if one does.
            let option = if clusters > 1 && payload(1) <= u64::from(format::MAX_PAYLOAD) {
                "--clusters"
            } else {
                "--components"
            };
            return Err(LpcaError::parameter(
                option,
                format!(
                    "the model would take {bytes} bytes, above the .lpca limit of {} bytes; \
                     use fewer clusters or components",
                    format::MAX_PAYLOAD
                ),
            ));
        }
        Ok(Self {
            options: *options,
            factorization: FactorizationOptions {
                clusters,
                components: options.components,
                max_iterations: options.max_iterations,
                tolerance: options.tolerance,
                seed: options.seed,
            },
            model: LpcaModel {
                method: options.method,
                views: btf.views().clone(),
                lights: btf.lights().clone(),
                width: w,
                height: h,
                parts: Vec::new(),
            },
            report: LpcaReport {
                method: options.method,
                clusters,
                components: options.components,
                iterations: 0,
                converged: true,
                error_history: Vec::new(),
                load_seconds: 0.0,
                fit_seconds: 0.0,
                evaluation_seconds: 0.0,
                mean_delta_e: f64::NAN,
                psnr_db: f64::NAN,
                per_view_delta_e: Vec::new(),
                per_image_delta_e: Vec::new(),
            },
        })
    }

    /// (views, lights, height, width) of the model.
    fn shape(&self) -> (usize, usize, usize, usize) {
        let m = &self.model;
        (m.views.len(), m.lights.len(), m.height, m.width)
    }

    /// Local PCA: one factorization of the BRDF-wise matrix (one row per texel).
    fn fit_lpca(mut self, btf: &Btf, progress: &dyn Progress) -> Result<(LpcaModel, LpcaReport)> {
        let (nv, nl, h, w) = self.shape();
        let t = Instant::now();
        let x = data::brdf_matrix(btf, progress)?;
        self.report.load_seconds = t.elapsed().as_secs_f64();
        let d = nv * nl * 3;
        self.fit_whole(&x, (h * w, d), progress, |v| {
            data::gather_view(&x, d, v * nl * 3, nl, h, w)
        })
    }

    /// PCA BTF: one factorization of the image-wise matrix (one row per image).
    fn fit_pca_btf(
        mut self,
        btf: &Btf,
        progress: &dyn Progress,
    ) -> Result<(LpcaModel, LpcaReport)> {
        let (nv, nl, h, w) = self.shape();
        let t = Instant::now();
        let x = data::image_matrix(btf, progress)?;
        self.report.load_seconds = t.elapsed().as_secs_f64();
        let d = 3 * h * w;
        self.fit_whole(&x, (nv * nl, d), progress, |v| {
            data::gather_images(&x, v, nl, h, w)
        })
    }

    /// The shared tail of [`Self::fit_lpca`] and [`Self::fit_pca_btf`]: factorizes the `rows x
    /// d` matrix `x` whole, then measures every view against `inputs(view)`, the view's
    /// measured images taken back out of `x`.
    fn fit_whole(
        mut self,
        x: &[f32],
        (rows, d): (usize, usize),
        progress: &dyn Progress,
        inputs: impl Fn(usize) -> Vec<Array3<f32>>,
    ) -> Result<(LpcaModel, LpcaReport)> {
        let t = Instant::now();
        let (mut f, stats) = fit_rows(x, rows, d, &self.factorization, progress)?;
        f.round_to_half();
        self.report.fit_seconds = t.elapsed().as_secs_f64();
        self.report.iterations = stats.iterations;
        self.report.converged = stats.converged;
        self.report.error_history = stats.error_history;
        self.model.parts.push(f);
        if self.options.evaluate {
            let (nv, nl, _, _) = self.shape();
            let t = Instant::now();
            let mut scores = Scores::new(nv * nl);
            progress.start("measuring error", nv as u64);
            for v in 0..nv {
                scores.view(&self.model, v, &inputs(v))?;
                progress.advance(1);
            }
            progress.finish();
            self.report.evaluation_seconds = t.elapsed().as_secs_f64();
            scores.finish(&mut self.report, nv, nl);
        }
        Ok((self.model, self.report))
    }

    /// PCA RF: one single-cluster factorization per view of its reflectance fields, one view
    /// in memory at a time.
    fn fit_pca_rf(mut self, btf: &Btf, progress: &dyn Progress) -> Result<(LpcaModel, LpcaReport)> {
        let (nv, nl, h, w) = self.shape();
        let mut scores = Scores::new(nv * nl);
        progress.start("per-view PCA", nv as u64);
        let mut errors = Vec::with_capacity(nv);
        for v in 0..nv {
            let t = Instant::now();
            let x = data::view_matrix(btf, v)?;
            self.report.load_seconds += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let (mut f, stats) = fit_rows(&x, h * w, nl * 3, &self.factorization, &NoProgress)?;
            f.round_to_half();
            self.report.fit_seconds += t.elapsed().as_secs_f64();
            self.report.iterations = self.report.iterations.max(stats.iterations);
            errors.push(stats.final_error());
            self.model.parts.push(f);
            if self.options.evaluate {
                let t = Instant::now();
                let inputs = data::gather_view(&x, nl * 3, 0, nl, h, w);
                scores.view(&self.model, v, &inputs)?;
                self.report.evaluation_seconds += t.elapsed().as_secs_f64();
            }
            progress.advance(1);
        }
        progress.finish();
        // Per-view errors summed: the error of a whole texel vector across views.
        self.report.error_history = vec![errors.iter().sum()];
        if self.options.evaluate {
            scores.finish(&mut self.report, nv, nl);
        }
        Ok((self.model, self.report))
    }
}

/// The images a model rebuilds, as a [`Btf`] source ([`LpcaModel::into_btf`]).
struct Reconstruction(Arc<LpcaModel>);

impl ImageSource for Reconstruction {
    fn load(&self, view: usize, light: usize) -> std::result::Result<Array3<f32>, BtfError> {
        self.0
            .reconstruct(view, light)
            .map_err(|e| BtfError::Image {
                file: self.describe(view, light),
                reason: e.to_string(),
            })
    }

    fn describe(&self, view: usize, light: usize) -> String {
        format!("reconstructed image (view {view}, light {light})")
    }
}

/// Error of one image against its reconstruction, both quantised to 8-bit sRGB first:
/// (mean CIE76 ΔE, sum of squared 8-bit differences over all samples).
pub fn image_error(
    input: &Array3<f32>,
    reconstruction: &Array3<f32>,
) -> std::result::Result<(f64, f64), String> {
    if input.dim() != reconstruction.dim() || input.dim().0 != 3 {
        return Err(format!(
            "shapes {:?} and {:?} differ",
            input.dim(),
            reconstruction.dim()
        ));
    }
    let enc = Srgb8Encoder::new();
    let table = srgb8_to_linear_table();
    let (_, h, w) = input.dim();
    let mut de = 0.0f64;
    let mut sq = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            let a = [0, 1, 2].map(|c| enc.encode(input[(c, y, x)]));
            let b = [0, 1, 2].map(|c| enc.encode(reconstruction[(c, y, x)]));
            if a != b {
                for c in 0..3 {
                    sq += (f64::from(a[c]) - f64::from(b[c])).powi(2);
                }
                let la = linear_to_lab(a.map(|v| table[usize::from(v)]));
                let lb = linear_to_lab(b.map(|v| table[usize::from(v)]));
                de += f64::from(delta_e76(la, lb));
            }
        }
    }
    Ok((de / (h * w).max(1) as f64, sq))
}

/// Error sums over the images, filled view by view.
struct Scores {
    per_image: Vec<f64>,
    squared: Vec<f64>,
    samples: f64,
}

impl Scores {
    fn new(images: usize) -> Self {
        Self {
            per_image: vec![f64::NAN; images],
            squared: vec![0.0; images],
            samples: 0.0,
        }
    }

    fn view(&mut self, model: &LpcaModel, v: usize, inputs: &[Array3<f32>]) -> Result<()> {
        let nl = model.lights().len();
        let results: Vec<(f64, f64)> = inputs
            .par_iter()
            .enumerate()
            .map(|(l, input)| {
                let rec = model.reconstruct(v, l)?;
                image_error(input, &rec).map_err(LpcaError::Numerical)
            })
            .collect::<Result<_>>()?;
        for (l, (de, sq)) in results.into_iter().enumerate() {
            self.per_image[v * nl + l] = de;
            self.squared[v * nl + l] = sq;
        }
        self.samples += (inputs.len() * 3 * model.width() * model.height()) as f64;
        Ok(())
    }

    fn finish(self, report: &mut LpcaReport, nv: usize, nl: usize) {
        let count = self.per_image.len().max(1) as f64;
        report.mean_delta_e = self.per_image.iter().sum::<f64>() / count;
        let mse = self.squared.iter().sum::<f64>() / self.samples.max(1.0);
        report.psnr_db = if mse > 0.0 {
            10.0 * (255.0f64 * 255.0 / mse).log10()
        } else {
            f64::INFINITY
        };
        report.per_view_delta_e = (0..nv)
            .map(|v| self.per_image[v * nl..(v + 1) * nl].iter().sum::<f64>() / nl as f64)
            .collect();
        report.per_image_delta_e = self.per_image;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(n: usize) -> DirectionSet {
        DirectionSet::new(
            (0..n)
                .map(|i| Direction::new(10.0 * i as f64, 0.0))
                .collect(),
        )
        .unwrap()
    }

    /// A zero factorization of `rows` vectors of `dim` values, `k` clusters of `c` components.
    fn part(rows: usize, dim: usize, k: usize, c: usize) -> Factorization {
        let assignment = (0..rows).map(|i| (i % k) as u16).collect();
        let (means, bases) = (vec![0.0; k * dim], vec![0.0; k * c * dim]);
        Factorization::new(dim, c, means, bases, assignment, vec![0.0; rows * c]).unwrap()
    }

    #[test]
    fn from_parts_refuses_parts_that_do_not_fit_together() {
        // 3 x 2 texels, 2 views, 4 lights: LPCA is 6 rows of 24 values, PCA BTF 8 rows of 18,
        // PCA RF 2 factorizations of 6 rows of 12.
        let make = |method, parts| LpcaModel::from_parts(method, set(2), set(4), (3, 2), parts);
        let lpca = make(Method::Lpca, vec![part(6, 24, 3, 2)]).unwrap();
        assert_eq!((lpca.clusters(), lpca.components()), (3, 2));
        make(Method::PcaBtf, vec![part(8, 18, 1, 2)]).unwrap();
        make(Method::PcaRf, vec![part(6, 12, 1, 2), part(6, 12, 1, 2)]).unwrap();
        let err = |method, parts| make(method, parts).unwrap_err();
        assert!(err(Method::PcaRf, vec![part(6, 12, 1, 2)]).contains("expected 2"));
        assert!(err(Method::Lpca, vec![]).contains("expected 1"));
        // A PCA BTF factorization read as LPCA, and texel vectors one view short.
        assert!(err(Method::Lpca, vec![part(8, 18, 1, 2)]).contains("8 vectors of 18"));
        assert!(err(Method::Lpca, vec![part(6, 12, 2, 2)]).contains("has 6 of 24"));
        let mixed = vec![part(6, 12, 1, 2), part(6, 12, 1, 3)];
        assert!(err(Method::PcaRf, mixed).contains("3 components where part 0 has 2"));
        assert!(err(Method::PcaBtf, vec![part(8, 18, 2, 2)]).contains("one expected"));
    }
}
