//! The speed-against-error benchmark of every method on one BTF (issue "speed vs error"):
//! analysis time, synthesis time of one 1024 x 1024 image, model size, compression ratio,
//! pixelwise error where it means something, and the texture judge for all.
//!
//! Pixelwise error (mean CIE76 ΔE) is reported only for the compression methods, which
//! reproduce the measured pixels; a stochastic MRF synthesis is a new sample of the material,
//! so its ΔE against the measurement would only measure that it is another sample. The texture
//! judge ([`Yardstick`]: structure and colour statistics, with reference levels from the
//! measured image) applies to every method: it is averaged over a fixed set of measured
//! (view, light) pairs, each method's image for the pair against the measured one, and the
//! reference levels are averaged over the same pairs.

use std::path::Path;
use std::time::Instant;

use ndarray::{Array3, s};

use crate::analysis::{AnalysisOptions, analyze};
use crate::btf::io::write_image;
use crate::btf::{Btf, Direction};
use crate::eval::judge::{Verdict, Yardstick};
use crate::eval::montage::montage;
use crate::eval::plot::benchmark_plots;
use crate::io::{publish_dir, temp_dir_beside, write_file_atomic};
use crate::lpca::{LpcaModel, LpcaOptions, Method};
use crate::model::{MaterialModel, ModelKind, format};
use crate::progress::Progress;
use crate::synthesis::SynthesisOptions;

use super::Result;

/// What the benchmark runs and how.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchOptions {
    /// Subspace images of the MRF models.
    pub clusters: usize,
    /// Side of the synthesized image that is timed, pixels (the issue asks for 1024).
    pub synthesis_side: usize,
    /// Measured (view, light) pairs over which the judge's figures are averaged.
    pub fidelity_pairs: usize,
    /// Seed of every random step.
    pub seed: u64,
    /// The pixelwise baselines: (method, clusters, components) each.
    pub baselines: Vec<Baseline>,
    /// An image of a different material (any size), for the judge's other-material level.
    pub other_material: Option<Array3<f32>>,
}

/// One pixelwise baseline of the benchmark: a PCA factorization and its size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Baseline {
    /// Local PCA, global PCA of images, or per-view PCA.
    pub method: Method,
    /// Clusters (local PCA only; the others use one).
    pub clusters: usize,
    /// Principal components per cluster (per view for PCA RF).
    pub components: usize,
}

impl Baseline {
    /// The baselines the issue asks for: LPCA at two sizes, PCA BTF and PCA RF.
    pub fn defaults() -> Vec<Baseline> {
        let b = |method, clusters, components| Baseline {
            method,
            clusters,
            components,
        };
        vec![
            b(Method::Lpca, 8, 4),
            b(Method::Lpca, 32, 8),
            b(Method::PcaBtf, 1, 8),
            b(Method::PcaRf, 1, 4),
        ]
    }
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            clusters: 20,
            synthesis_side: 1024,
            fidelity_pairs: 8,
            seed: 1,
            baselines: Baseline::defaults(),
            other_material: None,
        }
    }
}

/// Which method a row of the report measured, with the settings that tell two runs of one
/// method apart (LPCA 8x4 is not LPCA 32x8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MethodId {
    /// An MRF model.
    Mrf {
        /// GMRF, 2D CAR or 3D CAR.
        kind: ModelKind,
        /// Subspace images of the fitted model.
        clusters: usize,
        /// Pyramid levels of the fitted model.
        levels: usize,
    },
    /// A pixelwise PCA baseline.
    Baseline(Baseline),
}

/// A method's settings as `report.json` writes them (`parameters`): only those it has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Parameters {
    /// Subspace images (MRF) or clusters (local PCA).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clusters: Option<usize>,
    /// Principal components per cluster (per view for PCA RF).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub components: Option<usize>,
    /// Pyramid levels (MRF).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub levels: Option<usize>,
}

impl MethodId {
    /// `gmrf`, `2dcar`, `3dcar`, `lpca`, `pca-btf` or `pca-rf`.
    pub fn name(&self) -> &'static str {
        match self {
            MethodId::Mrf { kind, .. } => kind.name(),
            MethodId::Baseline(b) => b.method.name(),
        }
    }

    /// Whether the method synthesizes new texture (MRF) rather than reproducing pixels.
    pub fn is_mrf(&self) -> bool {
        matches!(self, MethodId::Mrf { .. })
    }

    /// The settings that matter for this method.
    pub fn parameters(&self) -> Parameters {
        match *self {
            MethodId::Mrf {
                clusters, levels, ..
            } => Parameters {
                clusters: Some(clusters),
                components: None,
                levels: Some(levels),
            },
            MethodId::Baseline(b) => Parameters {
                clusters: (b.method == Method::Lpca).then_some(b.clusters),
                components: Some(b.components),
                levels: None,
            },
        }
    }
}

impl Parameters {
    /// (name, value) of each setting present, in `report.json`'s order.
    pub fn entries(&self) -> Vec<(&'static str, usize)> {
        [
            ("clusters", self.clusters),
            ("components", self.components),
            ("levels", self.levels),
        ]
        .into_iter()
        .filter_map(|(k, v)| Some((k, v?)))
        .collect()
    }
}

impl std::fmt::Display for MethodId {
    /// `lpca clusters=8 components=4`: the name and settings, as the report's text names a
    /// row.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {}", self.name(), compact(&self.parameters()))
    }
}

impl serde::Serialize for MethodId {
    /// As `report.json`'s `name` and `parameters` fields.
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = s.serialize_map(Some(2))?;
        map.serialize_entry("name", self.name())?;
        map.serialize_entry("parameters", &self.parameters())?;
        map.end()
    }
}

/// One method's row of the report (the fields of `report.json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MethodResult {
    /// The method and its settings (`name` and `parameters` in `report.json`).
    #[serde(flatten)]
    pub method: MethodId,
    /// Wall time of the analysis (fit), seconds.
    pub analysis_seconds: f64,
    /// Wall time to make one `synthesis_side`^2 image for one (view, light), seconds.
    pub synthesis_seconds: f64,
    /// Size of the model file, bytes.
    pub model_bytes: u64,
    /// Raw 8-bit BTF bytes / model bytes.
    pub compression_ratio: f64,
    /// Mean CIE76 ΔE over all measured images; `None` where pixelwise error is meaningless.
    pub mean_delta_e: Option<f64>,
    /// The texture judge's figures, averaged over the judged pairs.
    #[serde(flatten)]
    pub judge: Verdict,
    /// How the synthesis time was measured (e.g. "reconstructed at 128^2, tiled").
    pub note: String,
}

/// The measured (view, light) pairs over which the judge is averaged: `n` pairs whose views
/// are spread evenly over the view list (the middle of each of `n` equal stretches, frontal to
/// grazing) and whose lights follow the golden-ratio sequence over the light list, so views
/// and lights vary independently. Spread evenly over the view-major pair index instead, every
/// pair of the Bonn sampling's 81 x 81 at n = 8 had its light in its view's direction (index
/// 410 (2i + 1) is view 5 (2i + 1) and light 5 (2i + 1)): the bench judged the hot spot alone,
/// where nothing shades, and at grazing views its colour distance was 14-18 L* units.
pub fn fidelity_pairs(btf: &Btf, n: usize) -> Vec<(usize, usize)> {
    let (views, lights) = (btf.views().len(), btf.lights().len());
    let n = n.clamp(1, (views * lights).max(1));
    let golden = (5f64.sqrt() - 1.0) / 2.0;
    (0..n)
        .map(|i| {
            let v = ((2 * i + 1) * views / (2 * n)).min(views.saturating_sub(1));
            let l = (((i as f64 + 0.5) * golden).fract() * lights as f64) as usize;
            (v, l.min(lights.saturating_sub(1)))
        })
        .collect()
}

/// The judged (view, light) pairs, each with the yardstick of its measured image.
pub type JudgedPairs = Vec<((usize, usize), Yardstick)>;

/// Builds the yardstick of each measured pair (reference crops and levels).
///
/// # Errors
/// Reading a measured image failed, or it is too small for the judge.
pub fn judged_pairs(btf: &Btf, options: &BenchOptions) -> Result<JudgedPairs> {
    fidelity_pairs(btf, options.fidelity_pairs)
        .into_iter()
        .map(|(v, l)| {
            let measured = btf.image(v, l)?;
            let y = Yardstick::new(&measured, options.other_material.as_ref(), options.seed)?;
            Ok(((v, l), y))
        })
        .collect()
}

/// The judge's mean verdict on `image_for(view, light)` over the judged pairs.
///
/// # Errors
/// Making the method's image failed, or it is too small for the judge.
pub fn mean_verdict(
    pairs: &JudgedPairs,
    mut image_for: impl FnMut(usize, usize) -> Result<Array3<f32>>,
) -> Result<Verdict> {
    let verdicts = pairs
        .iter()
        .map(|&((v, l), ref y)| y.judge(&image_for(v, l)?))
        .collect::<Result<Vec<_>>>()?;
    Ok(Verdict::mean(&verdicts).expect("at least one judged pair"))
}

/// Runs one MRF model (analysis, file size, timed synthesis, the judge).
///
/// # Errors
/// Analysis or synthesis failed.
pub fn bench_mrf(
    btf: &Btf,
    kind: ModelKind,
    options: &BenchOptions,
    pairs: &JudgedPairs,
    progress: &dyn Progress,
) -> Result<(MethodResult, MaterialModel)> {
    let analysis = AnalysisOptions {
        kind,
        clusters: options.clusters,
        seed: options.seed,
        ..AnalysisOptions::default()
    };
    let start = Instant::now();
    let (model, _) = analyze(btf, &analysis, progress)?;
    let analysis_seconds = start.elapsed().as_secs_f64();
    let model_bytes = format::to_bytes(&model).len() as u64;

    let side = options.synthesis_side;
    let (view, light) = pair_directions(btf, 0, 0);
    let big = SynthesisOptions {
        rows: side,
        cols: side,
        seed: options.seed,
        tileable: false,
    };
    let start = Instant::now();
    model.synthesize_image(&view, &light, &big)?;
    let synthesis_seconds = start.elapsed().as_secs_f64();

    let native = SynthesisOptions {
        rows: btf.height() as usize,
        cols: btf.width() as usize,
        ..big
    };
    let cache = model.synthesis_cache(&native)?;
    let judge = mean_verdict(pairs, |v, l| {
        let (view, light) = pair_directions(btf, v, l);
        Ok(model.image_from_cache(&cache, &view, &light)?)
    })?;
    let result = MethodResult {
        method: MethodId::Mrf {
            kind,
            clusters: model.subspaces().len(),
            levels: model.levels(),
        },
        analysis_seconds,
        synthesis_seconds,
        model_bytes,
        compression_ratio: btf.raw_bytes() as f64 / model_bytes as f64,
        mean_delta_e: None,
        judge,
        note: format!("one {side}x{side} image, all subspaces it needs, relit"),
    };
    Ok((result, model))
}

/// The directions of a measured (view, light) pair (indices in range).
fn pair_directions(btf: &Btf, view: usize, light: usize) -> (Direction, Direction) {
    (
        btf.views().iter().as_slice()[view],
        btf.lights().iter().as_slice()[light],
    )
}

/// Runs one pixelwise baseline (fit, file size, timed reconstruction tiled to the synthesis
/// size, ΔE over all images, the judge).
///
/// # Errors
/// Fitting or reconstruction failed.
pub fn bench_baseline(
    btf: &Btf,
    baseline: &Baseline,
    options: &BenchOptions,
    pairs: &JudgedPairs,
    progress: &dyn Progress,
) -> Result<(MethodResult, LpcaModel)> {
    let fit_options = LpcaOptions {
        method: baseline.method,
        clusters: baseline.clusters,
        components: baseline.components,
        seed: options.seed,
        evaluate: true,
        ..LpcaOptions::default()
    };
    let (model, report) = LpcaModel::fit(btf, &fit_options, progress)?;
    let model_bytes = model.to_bytes().len() as u64;
    let side = options.synthesis_side;
    let start = Instant::now();
    tile(&model.reconstruct(0, 0)?, side, side);
    let synthesis_seconds = start.elapsed().as_secs_f64();
    let judge = mean_verdict(pairs, |v, l| Ok(model.reconstruct(v, l)?))?;
    let result = MethodResult {
        method: MethodId::Baseline(*baseline),
        analysis_seconds: report.load_seconds + report.fit_seconds,
        synthesis_seconds,
        model_bytes,
        compression_ratio: btf.raw_bytes() as f64 / model_bytes as f64,
        mean_delta_e: Some(report.mean_delta_e).filter(|e| e.is_finite()),
        judge,
        note: format!(
            "one {}x{} image reconstructed, tiled to {side}x{side} (cannot enlarge)",
            btf.width(),
            btf.height()
        ),
    };
    Ok((result, model))
}

/// Tiles an image periodically to `rows` x `cols` (how a method that cannot enlarge covers a
/// large surface).
pub fn tile(image: &Array3<f32>, rows: usize, cols: usize) -> Array3<f32> {
    let (c, h, w) = image.dim();
    Array3::from_shape_fn((c, rows, cols), |(k, y, x)| image[[k, y % h, x % w]])
}

/// The whole benchmark's result: what was measured on what.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchReport {
    /// The input, as given by the user.
    pub input: String,
    /// Views x lights x height x width of the input.
    pub shape: [usize; 4],
    /// Raw 8-bit bytes of the input.
    pub raw_bytes: u64,
    /// Measured (view, light) pairs over which the judge's figures were averaged.
    pub fidelity_pairs: usize,
    /// The judge's reference levels, averaged over the pairs: `measured` (the reference crop
    /// itself: its chroma statistics), `another crop`, `random phase`, `shuffled`, `blurred`
    /// and, where a different material was given, `other material`.
    pub levels: Vec<LevelRow>,
    /// One row per method.
    pub methods: Vec<MethodResult>,
}

/// One reference level of the judge.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LevelRow {
    /// What the reference is.
    pub name: String,
    /// Its figures against the reference crop.
    #[serde(flatten)]
    pub verdict: Verdict,
}

/// The reference levels of every pair, averaged level by level.
fn mean_levels(pairs: &JudgedPairs) -> Vec<LevelRow> {
    let Some((_, first)) = pairs.first() else {
        return Vec::new();
    };
    let mut names = vec!["measured"];
    names.extend(first.levels().rows().iter().map(|(n, _)| *n));
    names
        .into_iter()
        .enumerate()
        .filter_map(|(i, name)| {
            let verdicts: Vec<Verdict> = pairs
                .iter()
                .filter_map(|(_, y)| {
                    let l = y.levels();
                    if i == 0 {
                        Some(l.measured)
                    } else {
                        l.rows().get(i - 1).map(|r| r.1)
                    }
                })
                .collect();
            Some(LevelRow {
                name: name.to_string(),
                verdict: Verdict::mean(&verdicts)?,
            })
        })
        .collect()
}

/// A column of the table on which a method can beat the others (lower is better on each).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    /// Model file size.
    ModelSize,
    /// Analysis (fit) time.
    AnalysisTime,
    /// Synthesis time of the timed image.
    SynthesisTime,
    /// The judge's structure distance.
    Structure,
    /// Mean CIE76 ΔE (pixelwise methods only).
    PixelError,
}

impl Axis {
    /// Every axis, in the order the verdicts name them.
    pub const ALL: [Axis; 5] = [
        Axis::ModelSize,
        Axis::AnalysisTime,
        Axis::SynthesisTime,
        Axis::Structure,
        Axis::PixelError,
    ];

    /// What winning on the axis means, e.g. "smallest model".
    pub fn phrase(self) -> &'static str {
        match self {
            Axis::ModelSize => "smallest model",
            Axis::AnalysisTime => "fastest analysis",
            Axis::SynthesisTime => "fastest synthesis",
            Axis::Structure => "closest structure",
            Axis::PixelError => "lowest pixelwise error",
        }
    }

    /// The row's value on this axis and its cell as the table prints it; `None` where the
    /// row has none (ΔE of an MRF model).
    pub fn cell(self, m: &MethodResult) -> Option<(f64, String)> {
        match self {
            Axis::ModelSize => Some((m.model_bytes as f64, human(m.model_bytes))),
            Axis::AnalysisTime => Some((m.analysis_seconds, format!("{:.2}", m.analysis_seconds))),
            Axis::SynthesisTime => {
                Some((m.synthesis_seconds, format!("{:.3}", m.synthesis_seconds)))
            }
            Axis::Structure => {
                let v = m.judge.judgement.structure;
                Some((v, format!("{v:.3}")))
            }
            Axis::PixelError => m.mean_delta_e.map(|e| (e, format!("{e:.2}"))),
        }
    }
}

/// A method's first place on one axis of the table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Win {
    /// The axis.
    pub axis: Axis,
    /// The other methods whose cell on the axis reads the same (a tie as the table shows it).
    pub tied_with: Vec<MethodId>,
}

impl BenchReport {
    /// The report as Markdown: a heading naming the input, then [`Self::markdown_body`].
    pub fn markdown(&self, plots: &[(&str, &str)]) -> String {
        format!(
            "# Speed against error: {}\n\n{}",
            self.input,
            self.markdown_body(plots, "")
        )
    }

    /// The report without its heading, for embedding in a larger document: the table, a
    /// sentence per method on where it wins, the side-by-side sheet and the `plots` ((title,
    /// file) each). `prefix` is put before the sheet's and the plots' file names (e.g.
    /// `bench/` when the report's files lie in that folder).
    pub fn markdown_body(&self, plots: &[(&str, &str)], prefix: &str) -> String {
        let [v, l, h, w] = self.shape;
        let mut md = format!(
            "{v} views x {l} lights, {h}x{w} texels, {} raw \
             (8-bit RGB).\n\nΔE: mean CIE76 ΔE over all measured images (only for methods that \
             reproduce pixels). The texture judge, averaged over {} fixed measured (view, light) \
             pairs, compares each method's image with a crop of the measured one: structure \
             (steerable-pyramid statistics of L*, 0 = identical, lower is better), the same \
             over the another-crop level (x crop: 1 = as close as the same material) and over \
             the random-phase level (x RP: 1 = as close as Gaussian noise with the measured \
             spectrum), colour (mean |Lab quantile difference|, Lab units), and the std and \
             kurtosis of a* of the image. The reference levels are rows in italics. Synthesis: \
             see the notes under the table.\n\n",
            human(self.raw_bytes),
            self.fidelity_pairs,
        );
        md.push_str(
            "| method | parameters | analysis s | synthesis s | model | ratio | ΔE | structure \
             | x crop | x RP | colour Lab | a* std | a* kurtosis |\n\
             |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        let cell = |axis: Axis, m: &MethodResult| axis.cell(m).map_or("-".into(), |c| c.1);
        for m in &self.methods {
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | 1:{:.0} | {} | {} |\n",
                m.method.name(),
                compact(&m.method.parameters()),
                cell(Axis::AnalysisTime, m),
                cell(Axis::SynthesisTime, m),
                cell(Axis::ModelSize, m),
                m.compression_ratio,
                cell(Axis::PixelError, m),
                judge_cells(&m.judge),
            ));
        }
        for level in &self.levels {
            md.push_str(&format!(
                "| *{}* | reference level | - | - | - | - | - | {} |\n",
                level.name,
                judge_cells(&level.verdict)
            ));
        }
        md.push('\n');
        let mut notes: Vec<(&str, &str)> = Vec::new();
        for m in &self.methods {
            if !notes.contains(&(m.method.name(), m.note.as_str())) {
                notes.push((m.method.name(), &m.note));
            }
        }
        for (name, note) in notes {
            md.push_str(&format!("Synthesis of {name}: {note}.  \n"));
        }
        md.push('\n');
        for line in self.verdicts() {
            md.push_str(&format!("- {line}\n"));
        }
        md.push('\n');
        md.push_str(&format!(
            "![side by side]({prefix}sheet.png)\n\nTop: the measured image of the first judged \
             pair, each MRF model's synthesis and each baseline's reconstruction; below: each \
             MRF model's synthesis at twice the size.\n\n"
        ));
        for (title, file) in plots {
            md.push_str(&format!("![{title}]({prefix}{file})\n\n"));
        }
        md
    }

    /// Each method's first places, row by row: on each axis the rows whose table cell reads
    /// like the best row's. An axis on which every row reads the same is nobody's win (unless
    /// there is only one row).
    pub fn wins(&self) -> Vec<Vec<Win>> {
        let mut wins: Vec<Vec<Win>> = vec![Vec::new(); self.methods.len()];
        for axis in Axis::ALL {
            let cells: Vec<Option<(f64, String)>> =
                self.methods.iter().map(|m| axis.cell(m)).collect();
            let Some(best) = cells
                .iter()
                .flatten()
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map(|c| c.1.clone())
            else {
                continue;
            };
            let first: Vec<usize> = (0..cells.len())
                .filter(|&i| cells[i].as_ref().is_some_and(|c| c.1 == best))
                .collect();
            let valued = cells.iter().flatten().count();
            if first.len() == valued && valued > 1 {
                continue;
            }
            for &i in &first {
                wins[i].push(Win {
                    axis,
                    tied_with: first
                        .iter()
                        .filter(|&&j| j != i)
                        .map(|&j| self.methods[j].method)
                        .collect(),
                });
            }
        }
        wins
    }

    /// One sentence per method on where it wins ([`Self::wins`]), derived from the table.
    pub fn verdicts(&self) -> Vec<String> {
        self.methods
            .iter()
            .zip(self.wins())
            .map(|(m, wins)| {
                let what = if m.method.is_mrf() {
                    "synthesizes new texture of any size (no pixelwise fidelity)"
                } else {
                    "reproduces the measured pixels (no enlargement beyond tiling)"
                };
                let wins: Vec<String> = wins
                    .iter()
                    .map(|w| {
                        if w.tied_with.is_empty() {
                            w.axis.phrase().to_string()
                        } else {
                            let others: Vec<String> =
                                w.tied_with.iter().map(|o| o.to_string()).collect();
                            format!("{} (tied with {})", w.axis.phrase(), others.join(", "))
                        }
                    })
                    .collect();
                let wins = if wins.is_empty() {
                    "wins on no single axis here".to_string()
                } else {
                    format!("wins on: {}", wins.join(", "))
                };
                format!(
                    "**{}**: {what}; {wins} ({} at 1:{:.0}, structure {:.3} = {:.2}x the \
                     another-crop level, {:.2}x the random-phase level; colour {:.2} Lab).",
                    m.method,
                    human(m.model_bytes),
                    m.compression_ratio,
                    m.judge.judgement.structure,
                    m.judge.structure_vs_crop,
                    m.judge.structure_vs_random_phase,
                    m.judge.judgement.colour_lab,
                )
            })
            .collect()
    }
}

/// The judge's cells of a table row: structure, x crop, x RP, colour, a* std, a* kurtosis.
fn judge_cells(v: &Verdict) -> String {
    let j = &v.judgement;
    format!(
        "{:.3} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1}",
        j.structure,
        v.structure_vs_crop,
        v.structure_vs_random_phase,
        j.colour_lab,
        j.chroma_std[0],
        j.chroma_kurtosis[0]
    )
}

/// Parameters as `clusters=20 levels=3`.
fn compact(p: &Parameters) -> String {
    p.entries()
        .iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn human(bytes: u64) -> String {
    if bytes >= 1 << 20 {
        format!("{:.1} MiB", bytes as f64 / f64::from(1 << 20))
    } else {
        format!("{:.1} KiB", bytes as f64 / 1024.0)
    }
}

/// The benchmark's report and the models it fitted (for callers that go on to use them).
#[derive(Debug)]
pub struct BenchRun {
    /// The measurements.
    pub report: BenchReport,
    /// The MRF models, in the order of [`ModelKind::ALL`].
    pub mrf_models: Vec<MaterialModel>,
    /// The baselines' models, in the order of [`BenchOptions::baselines`].
    pub baseline_models: Vec<LpcaModel>,
    /// The side-by-side sheet ([`side_by_side`]).
    pub sheet: Array3<f32>,
}

/// The side-by-side sheet of the first judged pair: the measured image, each MRF model's
/// synthesis and each baseline's reconstruction at the measured size, then each MRF model's
/// enlargement (a synthesis at twice the size, shown at full resolution below).
///
/// # Errors
/// Reading, synthesis or reconstruction failed.
pub fn side_by_side(
    btf: &Btf,
    pairs: &JudgedPairs,
    mrf_models: &[MaterialModel],
    baseline_models: &[LpcaModel],
    seed: u64,
) -> Result<Array3<f32>> {
    let (v, l) = pairs.first().map_or((0, 0), |p| p.0);
    let (view, light) = pair_directions(btf, v, l);
    let (h, w) = (btf.height() as usize, btf.width() as usize);
    let at = |rows, cols| SynthesisOptions {
        rows,
        cols,
        seed,
        tileable: false,
    };
    let mut top = vec![btf.image(v, l)?];
    for m in mrf_models {
        top.push(m.synthesize_image(&view, &light, &at(h, w))?);
    }
    for m in baseline_models {
        top.push(m.reconstruct(v, l)?);
    }
    let mut enlarged = Vec::new();
    for m in mrf_models {
        enlarged.push(m.synthesize_image(&view, &light, &at(2 * h, 2 * w))?);
    }
    let top: Vec<&Array3<f32>> = top.iter().collect();
    let bottom: Vec<&Array3<f32>> = enlarged.iter().collect();
    let first = montage(&[top], 4);
    if bottom.is_empty() {
        return Ok(first);
    }
    // Stacked by hand: a montage would enlarge the top row to the bottom row's height.
    let second = montage(&[bottom], 4);
    let (h1, h2) = (first.dim().1, second.dim().1);
    let width = first.dim().2.max(second.dim().2);
    let mut sheet = Array3::ones((3, h1 + 4 + h2, width));
    sheet
        .slice_mut(s![.., ..h1, ..first.dim().2])
        .assign(&first);
    sheet
        .slice_mut(s![.., h1 + 4.., ..second.dim().2])
        .assign(&second);
    Ok(sheet)
}

/// Runs every method this build knows on `btf` and gathers the report. `input` names the BTF
/// in the report.
///
/// # Errors
/// A method failed on this input.
pub fn run(
    btf: &Btf,
    input: &str,
    options: &BenchOptions,
    progress: &dyn Progress,
) -> Result<BenchRun> {
    let pairs = judged_pairs(btf, options)?;
    let mut methods = Vec::new();
    let mut mrf_models = Vec::new();
    for kind in ModelKind::ALL {
        let (result, model) = bench_mrf(btf, kind, options, &pairs, progress)?;
        methods.push(result);
        mrf_models.push(model);
    }
    let mut baseline_models = Vec::new();
    for baseline in &options.baselines {
        let (result, model) = bench_baseline(btf, baseline, options, &pairs, progress)?;
        methods.push(result);
        baseline_models.push(model);
    }
    let sheet = side_by_side(btf, &pairs, &mrf_models, &baseline_models, options.seed)?;
    let report = BenchReport {
        input: input.to_string(),
        shape: [
            btf.views().len(),
            btf.lights().len(),
            btf.height() as usize,
            btf.width() as usize,
        ],
        raw_bytes: btf.raw_bytes(),
        fidelity_pairs: pairs.len(),
        levels: mean_levels(&pairs),
        methods,
    };
    Ok(BenchRun {
        report,
        sheet,
        mrf_models,
        baseline_models,
    })
}

impl BenchReport {
    /// Writes `dir/report.json`, `dir/report.md`, the side-by-side `dir/sheet.png` and the
    /// plots; `dir` must not exist and appears complete or not at all. Returns the (title,
    /// file name) of each plot.
    ///
    /// # Errors
    /// `dir` exists, or writing failed.
    pub fn write(&self, dir: &Path, sheet: &Array3<f32>) -> Result<Vec<(String, String)>> {
        let tmp = temp_dir_beside(dir)?;
        let plots = benchmark_plots(self, tmp.path())?;
        let json = serde_json::to_string_pretty(self).expect("the report serializes");
        write_file_atomic(&tmp.path().join("report.json"), json.as_bytes())?;
        write_image(&tmp.path().join("sheet.png"), sheet)?;
        let titles: Vec<(&str, &str)> = plots
            .iter()
            .map(|(t, f)| (t.as_str(), f.as_str()))
            .collect();
        write_file_atomic(
            &tmp.path().join("report.md"),
            self.markdown(&titles).as_bytes(),
        )?;
        publish_dir(tmp, dir)?;
        Ok(plots)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::judge::Judgement;

    #[test]
    fn judged_pairs_vary_view_and_light_independently() {
        let btf = Btf::synthetic(crate::btf::synthetic::SyntheticMaterial::Sponge, 8, 1).unwrap();
        let pairs = fidelity_pairs(&btf, 8);
        assert_eq!(pairs.len(), 8);
        assert!(pairs.iter().all(|&(v, l)| v < 81 && l < 81));
        // Not the hot spot alone: most pairs light from elsewhere than the view.
        let hot = pairs.iter().filter(|&&(v, l)| v == l).count();
        assert!(hot <= 1, "{pairs:?}");
        // Frontal to grazing views, and as many lights as pairs.
        let views: std::collections::BTreeSet<_> = pairs.iter().map(|p| p.0).collect();
        let lights: std::collections::BTreeSet<_> = pairs.iter().map(|p| p.1).collect();
        assert_eq!((views.len(), lights.len()), (8, 8), "{pairs:?}");
        assert_eq!(fidelity_pairs(&btf, 8), pairs);
    }

    fn verdict(structure: f64) -> Verdict {
        Verdict {
            judgement: Judgement {
                structure,
                groups: [structure; 7],
                colour_lab: 1.0,
                colour_lab_channels: [1.0; 3],
                chroma_std: [2.0; 2],
                chroma_kurtosis: [3.0; 2],
                colour_coupling: 1.0,
            },
            structure_vs_crop: 1.0,
            structure_vs_random_phase: 1.0,
        }
    }

    fn lpca(clusters: usize, components: usize) -> MethodId {
        MethodId::Baseline(Baseline {
            method: Method::Lpca,
            clusters,
            components,
        })
    }

    /// A row: (method, model bytes, analysis s, synthesis s, structure, ΔE).
    fn row(method: MethodId, bytes: u64, fit: f64, synth: f64, structure: f64) -> MethodResult {
        MethodResult {
            method,
            analysis_seconds: fit,
            synthesis_seconds: synth,
            model_bytes: bytes,
            compression_ratio: 1e6 / bytes as f64,
            mean_delta_e: (!method.is_mrf()).then_some(structure * 10.0),
            judge: verdict(structure),
            note: "n".into(),
        }
    }

    fn report(methods: Vec<MethodResult>) -> BenchReport {
        BenchReport {
            input: "x".into(),
            shape: [1, 1, 8, 8],
            raw_bytes: 1_000_000,
            fidelity_pairs: 1,
            levels: Vec::new(),
            methods,
        }
    }

    fn axes(wins: &[Win]) -> Vec<Axis> {
        wins.iter().map(|w| w.axis).collect()
    }

    #[test]
    fn the_better_of_two_runs_of_one_method_gets_the_wins() {
        let car = MethodId::Mrf {
            kind: ModelKind::Car2d,
            clusters: 20,
            levels: 3,
        };
        // LPCA 32x8 beats 8x4 on structure, ΔE and analysis time; 8x4 is smaller; the MRF
        // model is the smallest and the slowest.
        let r = report(vec![
            row(car, 10_000, 9.0, 0.9, 0.5),
            row(lpca(8, 4), 200_000, 5.0, 0.1, 0.3),
            row(lpca(32, 8), 900_000, 4.0, 0.1, 0.2),
        ]);
        let wins = r.wins();
        assert_eq!(axes(&wins[0]), [Axis::ModelSize]);
        // Synthesis: 8x4 and 32x8 tie (same cell); everything else 32x8.
        assert_eq!(axes(&wins[1]), [Axis::SynthesisTime]);
        assert_eq!(wins[1][0].tied_with, [lpca(32, 8)]);
        assert_eq!(
            axes(&wins[2]),
            [
                Axis::AnalysisTime,
                Axis::SynthesisTime,
                Axis::Structure,
                Axis::PixelError
            ]
        );
        let text = r.verdicts();
        assert!(
            text[1].starts_with("**lpca clusters=8 components=4**"),
            "{}",
            text[1]
        );
        assert!(
            text[1]
                .contains("wins on: fastest synthesis (tied with lpca clusters=32 components=8)"),
            "{}",
            text[1]
        );
        assert!(!text[1].contains("closest structure"), "{}", text[1]);
        assert!(text[2].contains("closest structure"), "{}", text[2]);
        // What each sentence claims holds in the table: the winning cell is the column's least.
        let md = r.markdown(&[]);
        assert!(
            md.contains("| lpca | clusters=32 components=8 | 4.00 | 0.100 | 878.9 KiB |"),
            "{md}"
        );
    }

    #[test]
    fn a_tie_is_called_a_tie_and_a_column_all_alike_is_nobodys_win() {
        let a = lpca(8, 4);
        let b = lpca(16, 4);
        // Sizes differ by 20 bytes: the table shows both as 9.8 KiB, a tie.
        let r = report(vec![
            row(a, 10_000, 1.0, 0.1, 0.3),
            row(b, 10_020, 2.0, 0.1, 0.4),
            row(lpca(32, 8), 50_000, 3.0, 0.1, 0.5),
        ]);
        let wins = r.wins();
        let size_a = wins[0].iter().find(|w| w.axis == Axis::ModelSize).unwrap();
        assert_eq!(size_a.tied_with, [b]);
        assert!(wins[1].iter().any(|w| w.axis == Axis::ModelSize));
        // Synthesis reads 0.100 in every row: nobody wins it.
        assert!(wins.iter().flatten().all(|w| w.axis != Axis::SynthesisTime));
        assert!(r.verdicts()[0].contains("smallest model (tied with lpca clusters=16"));
        // One row wins what it has; an MRF row has no ΔE to win on.
        let car = MethodId::Mrf {
            kind: ModelKind::Gmrf,
            clusters: 4,
            levels: 2,
        };
        let solo = report(vec![row(car, 1, 1.0, 1.0, 1.0)]);
        assert_eq!(
            axes(&solo.wins()[0]),
            [
                Axis::ModelSize,
                Axis::AnalysisTime,
                Axis::SynthesisTime,
                Axis::Structure
            ]
        );
    }

    #[test]
    fn method_rows_serialize_as_name_and_parameters() {
        let r = row(lpca(8, 4), 1000, 1.0, 1.0, 1.0);
        let v = serde_json::to_value(&r).unwrap();
        assert_eq!(v["name"], "lpca");
        assert_eq!(
            v["parameters"],
            serde_json::json!({"clusters": 8, "components": 4})
        );
        let pca = MethodId::Baseline(Baseline {
            method: Method::PcaBtf,
            clusters: 1,
            components: 8,
        });
        let v = serde_json::to_value(row(pca, 1000, 1.0, 1.0, 1.0)).unwrap();
        assert_eq!(v["name"], "pca-btf");
        assert_eq!(v["parameters"], serde_json::json!({"components": 8}));
        assert_eq!(v["structure"], 1.0);
    }
}
