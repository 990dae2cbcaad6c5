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
use crate::btf::io::{publish_dir, temp_dir_beside, write_file_atomic, write_image};
use crate::btf::{Btf, Direction};
use crate::eval::judge::{Verdict, Yardstick};
use crate::eval::montage::montage;
use crate::eval::plot::benchmark_plots;
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
#[derive(Debug, Clone, Copy, PartialEq)]
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

/// One method's row of the report (the fields of `report.json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MethodResult {
    /// `gmrf`, `2dcar`, `3dcar`, `lpca`, `pca-btf` or `pca-rf`.
    pub name: String,
    /// The method's settings, e.g. `{"clusters": 20}`.
    pub parameters: serde_json::Value,
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

/// The measured (view, light) pairs over which the judge is averaged: `n` pairs spread evenly
/// over the (view-major) pair index, so they cover frontal to grazing views and many lights.
pub fn fidelity_pairs(btf: &Btf, n: usize) -> Vec<(usize, usize)> {
    let (views, lights) = (btf.views().len(), btf.lights().len());
    let total = views * lights;
    let n = n.clamp(1, total.max(1));
    (0..n)
        .map(|i| {
            // The middle of each of n equal stretches, so the set is symmetric in the order.
            let k = (2 * i + 1) * total / (2 * n);
            (k / lights, k % lights)
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
        name: kind.name().to_string(),
        parameters: serde_json::json!({
            "clusters": model.subspaces().len(),
            "levels": model.levels(),
        }),
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
    let parameters = match baseline.method {
        Method::Lpca => serde_json::json!({
            "clusters": baseline.clusters,
            "components": baseline.components,
        }),
        _ => serde_json::json!({ "components": baseline.components }),
    };
    let result = MethodResult {
        name: baseline.method.name().to_string(),
        parameters,
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

impl BenchReport {
    /// The report as Markdown: the table and a sentence per method on where it wins.
    pub fn markdown(&self, plots: &[(&str, &str)]) -> String {
        let [v, l, h, w] = self.shape;
        let mut md = format!(
            "# Speed against error: {}\n\n{v} views x {l} lights, {h}x{w} texels, {} raw \
             (8-bit RGB).\n\nΔE: mean CIE76 ΔE over all measured images (only for methods that \
             reproduce pixels). The texture judge, averaged over {} fixed measured (view, light) \
             pairs, compares each method's image with a crop of the measured one: structure \
             (steerable-pyramid statistics of L*, 0 = identical, lower is better), the same \
             over the another-crop level (x crop: 1 = as close as the same material) and over \
             the random-phase level (x RP: 1 = as close as Gaussian noise with the measured \
             spectrum), colour (mean |Lab quantile difference|, Lab units), and the std and \
             kurtosis of a* of the image. The reference levels are rows in italics. Synthesis: \
             see the notes under the table.\n\n",
            self.input,
            human(self.raw_bytes),
            self.fidelity_pairs,
        );
        md.push_str(
            "| method | parameters | analysis s | synthesis s | model | ratio | ΔE | structure \
             | x crop | x RP | colour Lab | a* std | a* kurtosis |\n\
             |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for m in &self.methods {
            md.push_str(&format!(
                "| {} | {} | {:.2} | {:.3} | {} | 1:{:.0} | {} | {} |\n",
                m.name,
                compact(&m.parameters),
                m.analysis_seconds,
                m.synthesis_seconds,
                human(m.model_bytes),
                m.compression_ratio,
                m.mean_delta_e
                    .map_or("-".to_string(), |e| format!("{e:.2}")),
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
            if !notes.contains(&(m.name.as_str(), m.note.as_str())) {
                notes.push((&m.name, &m.note));
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
        md.push_str(
            "![side by side](sheet.png)\n\nTop: the measured image of the first judged pair, \
             each MRF model's synthesis and each baseline's reconstruction; below: each MRF \
             model's synthesis at twice the size.\n\n",
        );
        for (title, file) in plots {
            md.push_str(&format!("![{title}]({file})\n\n"));
        }
        md
    }

    /// One sentence per method on where it wins, derived from the measured rows.
    pub fn verdicts(&self) -> Vec<String> {
        let best = |key: fn(&MethodResult) -> f64| {
            self.methods
                .iter()
                .min_by(|a, b| key(a).total_cmp(&key(b)))
                .map(|m| m.name.clone())
        };
        let smallest = best(|m| m.model_bytes as f64);
        let fastest_fit = best(|m| m.analysis_seconds);
        let fastest_synth = best(|m| m.synthesis_seconds);
        let most_faithful = best(|m| m.judge.judgement.structure);
        let least_error = best(|m| m.mean_delta_e.unwrap_or(f64::INFINITY));
        self.methods
            .iter()
            .map(|m| {
                let mut wins = Vec::new();
                let is = |b: &Option<String>| b.as_deref() == Some(m.name.as_str());
                if is(&smallest) {
                    wins.push("smallest model");
                }
                if is(&fastest_fit) {
                    wins.push("fastest analysis");
                }
                if is(&fastest_synth) {
                    wins.push("fastest synthesis");
                }
                if is(&most_faithful) {
                    wins.push("closest structure");
                }
                if m.mean_delta_e.is_some() && is(&least_error) {
                    wins.push("lowest pixelwise error");
                }
                let what = if m.mean_delta_e.is_some() {
                    "reproduces the measured pixels (no enlargement beyond tiling)"
                } else {
                    "synthesizes new texture of any size (no pixelwise fidelity)"
                };
                let wins = if wins.is_empty() {
                    "wins on no single axis here".to_string()
                } else {
                    format!("wins on: {}", wins.join(", "))
                };
                format!(
                    "**{} {}**: {what}; {wins} ({} at 1:{:.0}, structure {:.3} = {:.2}x the \
                     another-crop level, {:.2}x the random-phase level; colour {:.2} Lab).",
                    m.name,
                    compact(&m.parameters),
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

/// `{"clusters":20,"levels":3}` as `clusters=20 levels=3`.
fn compact(v: &serde_json::Value) -> String {
    match v.as_object() {
        Some(map) => map
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(" "),
        None => v.to_string(),
    }
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
