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

pub use cluster::{ClusterOptions, Factorization, FitStats, fit_rows};
pub use error::{LpcaError, Result};

use crate::btf::{Btf, BtfError, Direction, DirectionSet, ImageSource};
use crate::color::{Srgb8Encoder, delta_e76, linear_to_lab, srgb8_to_linear_table};
use crate::progress::Progress;

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
        let (w, h) = (btf.width() as usize, btf.height() as usize);
        let (nv, nl) = (btf.views().len(), btf.lights().len());
        let n = w * h;
        let mut report = LpcaReport {
            method: options.method,
            clusters: if options.method == Method::Lpca {
                options.clusters
            } else {
                1
            },
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
        if report.clusters > limit {
            return Err(LpcaError::parameter(
                "--clusters",
                format!("{} is above {limit}", report.clusters),
            ));
        }
        let payload = |clusters| {
            format::payload_len(options.method, w, h, nv, nl, clusters, options.components)
        };
        let bytes = payload(report.clusters);
        if bytes > u64::from(format::MAX_PAYLOAD) {
            // Blame the option that alone would make it fit, if one does.
            let option = if report.clusters > 1 && payload(1) <= u64::from(format::MAX_PAYLOAD) {
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
        let cluster_options = ClusterOptions {
            clusters: report.clusters,
            components: options.components,
            max_iterations: options.max_iterations,
            tolerance: options.tolerance,
            seed: options.seed,
        };
        let mut model = LpcaModel {
            method: options.method,
            views: btf.views().clone(),
            lights: btf.lights().clone(),
            width: w,
            height: h,
            parts: Vec::new(),
        };
        let mut scores = Scores::new(nv * nl);
        match options.method {
            Method::Lpca | Method::PcaBtf => {
                let t = Instant::now();
                let (x, rows, d) = if options.method == Method::Lpca {
                    (data::brdf_matrix(btf, progress)?, n, nv * nl * 3)
                } else {
                    (data::image_matrix(btf, progress)?, nv * nl, 3 * n)
                };
                report.load_seconds = t.elapsed().as_secs_f64();
                let t = Instant::now();
                let (mut f, stats) = fit_rows(&x, rows, d, &cluster_options, progress)?;
                f.round_to_half();
                report.fit_seconds = t.elapsed().as_secs_f64();
                report.iterations = stats.iterations;
                report.converged = stats.converged;
                report.error_history = stats.error_history;
                model.parts.push(f);
                if options.evaluate {
                    let t = Instant::now();
                    progress.start("measuring error", nv as u64);
                    for v in 0..nv {
                        let inputs = if options.method == Method::Lpca {
                            data::gather_view(&x, d, v * nl * 3, nl, h, w)
                        } else {
                            (0..nl)
                                .map(|l| {
                                    let a = v * nl + l;
                                    Array3::from_shape_vec(
                                        (3, h, w),
                                        x[a * d..(a + 1) * d].to_vec(),
                                    )
                                    .expect("shape")
                                })
                                .collect()
                        };
                        scores.view(&model, v, &inputs)?;
                        progress.advance(1);
                    }
                    progress.finish();
                    report.evaluation_seconds = t.elapsed().as_secs_f64();
                }
            }
            Method::PcaRf => {
                progress.start("per-view PCA", nv as u64);
                let mut errors = Vec::with_capacity(nv);
                for v in 0..nv {
                    let t = Instant::now();
                    let x = data::view_matrix(btf, v)?;
                    report.load_seconds += t.elapsed().as_secs_f64();
                    let t = Instant::now();
                    let (mut f, stats) = fit_rows(
                        &x,
                        n,
                        nl * 3,
                        &cluster_options,
                        &crate::progress::NoProgress,
                    )?;
                    f.round_to_half();
                    report.fit_seconds += t.elapsed().as_secs_f64();
                    report.iterations = report.iterations.max(stats.iterations);
                    errors.push(stats.final_error());
                    model.parts.push(f);
                    if options.evaluate {
                        let t = Instant::now();
                        let inputs = data::gather_view(&x, nl * 3, 0, nl, h, w);
                        scores.view(&model, v, &inputs)?;
                        report.evaluation_seconds += t.elapsed().as_secs_f64();
                    }
                    progress.advance(1);
                }
                progress.finish();
                // Per-view errors summed: the error of a whole texel vector across views.
                report.error_history = vec![errors.iter().sum()];
            }
        }
        if options.evaluate {
            scores.finish(&mut report, nv, nl);
        }
        Ok((model, report))
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
        self.parts.first().map_or(0, |f| f.components)
    }

    /// The factorizations: one for LPCA and PCA BTF, one per view for PCA RF.
    pub fn parts(&self) -> &[Factorization] {
        &self.parts
    }

    /// The cluster of every texel, row-major `height x width` (LPCA; all zero otherwise).
    pub fn cluster_map(&self) -> Vec<u16> {
        match self.method {
            Method::Lpca => self.parts[0].assignment.clone(),
            _ => vec![0; self.width * self.height],
        }
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
                let (d, c, k) = (f.dim, f.components, f.clusters());
                // Per cluster, the (C + 1) x 3 numbers this image needs.
                let mut table = vec![0.0f32; k * (c + 1) * 3];
                for j in 0..k {
                    for ch in 0..3 {
                        table[(j * (c + 1)) * 3 + ch] = f.means[j * d + col + ch];
                        for t in 0..c {
                            table[(j * (c + 1) + 1 + t) * 3 + ch] =
                                f.bases[(j * c + t) * d + col + ch];
                        }
                    }
                }
                let (r, rest) = out.split_at_mut(npx);
                let (g, b) = rest.split_at_mut(npx);
                r.par_iter_mut()
                    .zip(g.par_iter_mut())
                    .zip(b.par_iter_mut())
                    .enumerate()
                    .for_each(|(x, ((r, g), b))| {
                        let j = usize::from(f.assignment[x]);
                        let tab = &table[j * (c + 1) * 3..(j + 1) * (c + 1) * 3];
                        let mut acc = [tab[0], tab[1], tab[2]];
                        for (t, &wt) in f.weights[x * c..(x + 1) * c].iter().enumerate() {
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
                let f = &self.parts[0];
                let (d, c) = (f.dim, f.components);
                let a = view * nl + light;
                let wts = &f.weights[a * c..(a + 1) * c];
                out.par_iter_mut().enumerate().for_each(|(i, o)| {
                    let mut v = f.means[i];
                    for (t, &wt) in wts.iter().enumerate() {
                        v += wt * f.bases[t * d + i];
                    }
                    *o = v.max(0.0);
                });
            }
        }
        Ok(Array3::from_shape_vec((3, h, w), out).expect("shape"))
    }

    /// The image for any view and light direction: the 3 nearest measured views times the 3
    /// nearest measured lights (barycentric weights, as in the paper's renderer, section 4.1),
    /// up to 9 reconstructed images blended.
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
        let mut out = Array3::<f32>::zeros((3, self.height, self.width));
        for a in wv {
            for b in wl {
                let weight = (a.weight * b.weight) as f32;
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
            Box::new(ModelSource(Arc::new(self))),
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

    /// Builds a model from parts, checking that they fit together (used by the file reader).
    pub(crate) fn from_parts(
        method: Method,
        views: DirectionSet,
        lights: DirectionSet,
        width: usize,
        height: usize,
        parts: Vec<Factorization>,
    ) -> Self {
        Self {
            method,
            views,
            lights,
            width,
            height,
            parts,
        }
    }
}

struct ModelSource(Arc<LpcaModel>);

impl ImageSource for ModelSource {
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
        let nl = model.lights.len();
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
        self.samples += (inputs.len() * 3 * model.width * model.height) as f64;
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
