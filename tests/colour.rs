//! Colour fidelity of the synthesis (issue 11, item 3): the CIE Lab distribution of every
//! synthesized subspace image against the measured image it models. Targets per channel: mean
//! |Lab quantile difference| at most 1.0, chroma (a*, b*) standard deviation within 25 % and
//! kurtosis within 2x of the measured.

use std::path::PathBuf;

use btfmrf::analysis::{AnalysisOptions, analyze};
use btfmrf::btf::synthetic::{SyntheticBtf, SyntheticMaterial};
use btfmrf::btf::{Btf, Direction, DirectionSet};
use btfmrf::color::linear_to_lab;
use btfmrf::decompose::ColourSpace;
use btfmrf::eval::Yardstick;
use btfmrf::eval::bench::fidelity_pairs;
use btfmrf::model::{MaterialModel, ModelKind};
use btfmrf::progress::NoProgress;
use btfmrf::synthesis::SynthesisOptions;
use ndarray::Array3;

/// Options for a `rows` x `cols` image of seed `seed`, not tileable.
fn plain_options(rows: usize, cols: usize, seed: u64) -> SynthesisOptions {
    SynthesisOptions {
        rows,
        cols,
        seed,
        tileable: false,
    }
}

/// The shared data folder: `$BTFMRF_DATA`, else `../shared/data` beside the repository.
fn data(rel: &str) -> PathBuf {
    std::env::var_os("BTFMRF_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"))
        .join(rel)
}

/// L*, a*, b* planes of a planar linear RGB image, clamped to [0, 1] first as an LDR output is.
fn lab(image: &Array3<f32>) -> [Vec<f64>; 3] {
    let (_, h, w) = image.dim();
    let mut out: [Vec<f64>; 3] = std::array::from_fn(|_| Vec::with_capacity(h * w));
    for y in 0..h {
        for x in 0..w {
            let v = linear_to_lab([0, 1, 2].map(|c| image[[c, y, x]].clamp(0.0, 1.0)));
            for c in 0..3 {
                out[c].push(f64::from(v[c]));
            }
        }
    }
    out
}

/// Mean |difference| of the 1st..99th percentiles of two samples.
fn quantile_gap(a: &[f64], b: &[f64]) -> f64 {
    let sorted = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        s
    };
    let (a, b) = (sorted(a), sorted(b));
    let q = |s: &[f64], p: f64| s[((s.len() - 1) as f64 * p).round() as usize];
    (1..100)
        .map(|i| (q(&a, i as f64 / 100.0) - q(&b, i as f64 / 100.0)).abs())
        .sum::<f64>()
        / 99.0
}

/// (standard deviation, kurtosis m4 / m2^2) of a sample.
fn spread(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let m2 = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    let m4 = v.iter().map(|x| (x - mean).powi(4)).sum::<f64>() / n;
    (m2.sqrt(), m4 / (m2 * m2).max(1e-30))
}

/// Colour figures of a synthesized image against the measured one.
#[derive(Debug, Clone, Copy, Default)]
struct Colour {
    /// Mean |Lab quantile difference| per channel, Lab units.
    gap: [f64; 3],
    /// Synthesized / measured standard deviation of a* and b*.
    std_ratio: [f64; 2],
    /// Synthesized / measured kurtosis of a* and b*.
    kurt_ratio: [f64; 2],
}

impl Colour {
    fn of(synth: &Array3<f32>, measured: &Array3<f32>) -> Self {
        let (s, m) = (lab(synth), lab(measured));
        let mut out = Self::default();
        for c in 0..3 {
            out.gap[c] = quantile_gap(&s[c], &m[c]);
        }
        for c in 0..2 {
            let ((ss, sk), (ms, mk)) = (spread(&s[c + 1]), spread(&m[c + 1]));
            out.std_ratio[c] = ss / ms.max(1e-9);
            out.kurt_ratio[c] = sk / mk.max(1e-9);
        }
        out
    }

    /// Worst case over subspaces: largest gap, ratios farthest from 1 (as a factor).
    fn worst(all: &[Colour]) -> Self {
        let far = |a: f64, b: f64| {
            let f = |r: f64| r.max(1.0 / r.max(1e-9));
            if f(a) >= f(b) { a } else { b }
        };
        all.iter().fold(
            Colour {
                gap: [0.0; 3],
                std_ratio: [1.0; 2],
                kurt_ratio: [1.0; 2],
            },
            |w, c| Colour {
                gap: std::array::from_fn(|i| w.gap[i].max(c.gap[i])),
                std_ratio: std::array::from_fn(|i| far(w.std_ratio[i], c.std_ratio[i])),
                kurt_ratio: std::array::from_fn(|i| far(w.kurt_ratio[i], c.kurt_ratio[i])),
            },
        )
    }

    /// Mean over subspaces (ratios averaged in the log domain).
    fn mean(all: &[Colour]) -> Self {
        let n = all.len() as f64;
        let gm =
            |f: &dyn Fn(&Colour) -> f64| (all.iter().map(|c| f(c).ln()).sum::<f64>() / n).exp();
        Colour {
            gap: std::array::from_fn(|i| all.iter().map(|c| c.gap[i]).sum::<f64>() / n),
            std_ratio: std::array::from_fn(|i| gm(&|c: &Colour| c.std_ratio[i])),
            kurt_ratio: std::array::from_fn(|i| gm(&|c: &Colour| c.kurt_ratio[i])),
        }
    }

    fn row(&self) -> String {
        format!(
            "gap L {:5.2} a {:5.2} b {:5.2} | std a {:5.2} b {:5.2} | kurt a {:6.2} b {:6.2}",
            self.gap[0],
            self.gap[1],
            self.gap[2],
            self.std_ratio[0],
            self.std_ratio[1],
            self.kurt_ratio[0],
            self.kurt_ratio[1]
        )
    }
}

/// The global gradient structure tensor of an image's luminance after `halvings` 2x2 box
/// averages: (coherence in [0, 1], dominant gradient angle in degrees in [0, 180)). Coherence 0
/// is isotropic energy; round cells give little, streaks much.
fn orientation(image: &Array3<f32>, halvings: usize) -> (f64, f64) {
    let (_, h, w) = image.dim();
    let mut lum = ndarray::Array2::from_shape_fn((h, w), |(y, x)| {
        f64::from(0.2126 * image[[0, y, x]] + 0.7152 * image[[1, y, x]] + 0.0722 * image[[2, y, x]])
    });
    for _ in 0..halvings {
        let (h, w) = (lum.nrows() / 2, lum.ncols() / 2);
        lum = ndarray::Array2::from_shape_fn((h, w), |(y, x)| {
            (lum[[2 * y, 2 * x]]
                + lum[[2 * y + 1, 2 * x]]
                + lum[[2 * y, 2 * x + 1]]
                + lum[[2 * y + 1, 2 * x + 1]])
                / 4.0
        });
    }
    let (h, w) = lum.dim();
    let (mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let gx = (lum[[y, x + 1]] - lum[[y, x - 1]]) / 2.0;
            let gy = (lum[[y + 1, x]] - lum[[y - 1, x]]) / 2.0;
            (xx, yy, xy) = (xx + gx * gx, yy + gy * gy, xy + gx * gy);
        }
    }
    let coherence = ((xx - yy).powi(2) + 4.0 * xy * xy).sqrt() / (xx + yy).max(1e-30);
    let angle = (0.5 * (2.0 * xy).atan2(xx - yy))
        .to_degrees()
        .rem_euclid(180.0);
    (coherence, angle)
}

/// `compare(synthesized, measured)` for every subspace image of `model`, synthesized at the
/// measured size (seed 7), against its measured representative.
fn per_subspace<T>(
    btf: &Btf,
    model: &MaterialModel,
    compare: impl Fn(&Array3<f32>, &Array3<f32>) -> T,
) -> Vec<T> {
    let o = plain_options(btf.height() as usize, btf.width() as usize, 7);
    model
        .subspaces()
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let (v, l) = s.representative;
            let measured = btf.image(usize::from(v), usize::from(l)).unwrap();
            compare(&model.synthesize_subspace(k, &o).unwrap(), &measured)
        })
        .collect()
}

/// The colour figures of every subspace image of `model` against its representative.
fn subspace_colours(btf: &Btf, model: &MaterialModel) -> Vec<Colour> {
    per_subspace(btf, model, Colour::of)
}

/// Whole relit images of `model` (seed 7, measured size) against the measured images of the
/// frontal view under every `stride`-th light.
fn image_colours(btf: &Btf, model: &MaterialModel, stride: usize) -> Vec<Colour> {
    let o = plain_options(btf.height() as usize, btf.width() as usize, 7);
    let view = btfmrf::geometry::frontal_view(btf);
    let cache = model.synthesis_cache(&o).unwrap();
    (0..btf.lights().len())
        .step_by(stride)
        .map(|l| {
            let measured = btf.image(view, l).unwrap();
            let (vd, ld) = (&btf.views().as_slice()[view], &btf.lights().as_slice()[l]);
            let synth = model.image_from_cache(&cache, vd, ld).unwrap();
            Colour::of(&synth, &measured)
        })
        .collect()
}

/// Structure-tensor coherence (mean over subspaces) of measured and synthesized subspace
/// images at full, half and quarter resolution, and the mean absolute angle difference where
/// the measured coherence exceeds 0.1.
fn orientation_row(btf: &Btf, model: &MaterialModel) -> String {
    let o = plain_options(btf.height() as usize, btf.width() as usize, 7);
    let mut out = String::new();
    for halvings in 0..3 {
        let (mut cm, mut cs, mut da, mut n, mut na) = (0.0, 0.0, 0.0, 0.0, 0.0f64);
        for (k, s) in model.subspaces().iter().enumerate() {
            let (v, l) = s.representative;
            let measured = btf.image(usize::from(v), usize::from(l)).unwrap();
            let synth = model.synthesize_subspace(k, &o).unwrap();
            let (m, ma) = orientation(&measured, halvings);
            let (y, ya) = orientation(&synth, halvings);
            (cm, cs, n) = (cm + m, cs + y, n + 1.0);
            if m > 0.1 {
                let d = (ma - ya).abs();
                (da, na) = (da + d.min(180.0 - d), na + 1.0);
            }
        }
        out += &format!(
            "| x{} coh meas {:.3} synth {:.3} dangle {:4.1} ({na}) ",
            1 << halvings,
            cm / n,
            cs / n,
            da / na.max(1.0)
        );
    }
    out
}

fn fit(btf: &Btf, kind: ModelKind, space: ColourSpace, band_marginals: bool) -> MaterialModel {
    let options = AnalysisOptions {
        kind,
        clusters: 20,
        colour_space: space,
        band_marginals,
        ..AnalysisOptions::default()
    };
    analyze(btf, &options, &NoProgress).unwrap().0
}

/// The before/after table of the closing note: every built-in material and RTI set, every
/// model kind, mean and worst subspace.
#[test]
#[ignore = "measurement: minutes of analysis over all materials; run with --nocapture"]
fn colour_table() {
    let size: u32 = std::env::var("COLOUR_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(64);
    let mut sets: Vec<(String, Btf)> = [
        SyntheticMaterial::Sponge,
        SyntheticMaterial::Knit,
        SyntheticMaterial::Stones,
        SyntheticMaterial::Leather,
    ]
    .into_iter()
    .map(|m| (format!("{m:?} {size}"), Btf::synthetic(m, size, 3).unwrap()))
    .collect();
    for set in [
        "clay-leaf",
        "loewenkopf",
        "painted-door",
        "canvas-handheld",
        "coin",
    ] {
        sets.push((
            set.to_string(),
            Btf::open(data(&format!("rti/{set}"))).unwrap(),
        ));
    }
    let configs = [
        ("rgb", ColourSpace::LinearRgb, false),
        ("lab", ColourSpace::Lab, false),
        ("lab+bm", ColourSpace::Lab, true),
    ];
    // COLOUR_SETS / COLOUR_CONFIGS: comma-separated name fragments to restrict the table.
    let only: Option<String> = std::env::var("COLOUR_SETS").ok();
    let configs_only: Option<String> = std::env::var("COLOUR_CONFIGS").ok();
    let configs: Vec<_> = configs
        .into_iter()
        .filter(|(l, ..)| {
            configs_only
                .as_ref()
                .is_none_or(|o| o.split(',').any(|w| w == *l))
        })
        .collect();
    for (name, btf) in sets.iter().filter(|(n, _)| {
        only.as_ref()
            .is_none_or(|o| o.split(',').any(|w| n.contains(w)))
    }) {
        for kind in ModelKind::ALL {
            for &(label, space, bands) in &configs {
                let model = fit(btf, kind, space, bands);
                let tag = format!("{name:14} {kind:5} {label:6}");
                let all = subspace_colours(btf, &model);
                println!("{tag} sub mean  {}", Colour::mean(&all).row());
                println!("{tag} sub worst {}", Colour::worst(&all).row());
                let stride = btf.lights().len().div_ceil(12);
                let all = image_colours(btf, &model, stride);
                println!("{tag} img mean  {}", Colour::mean(&all).row());
                println!("{tag} orient    {}", orientation_row(btf, &model));
            }
        }
    }
}

/// Fraction of the synthesized pixels whose chroma lies farther from the measured median
/// chroma than 99.9 % of the measured pixels do: the isolated saturated specks.
fn speck_fraction(synth: &Array3<f32>, measured: &Array3<f32>) -> f64 {
    let (s, m) = (lab(synth), lab(measured));
    let median = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let centre = [median(&m[1]), median(&m[2])];
    let radius = |lab: &[Vec<f64>; 3]| -> Vec<f64> {
        (0..lab[1].len())
            .map(|i| (lab[1][i] - centre[0]).hypot(lab[2][i] - centre[1]))
            .collect()
    };
    let mut measured_radius = radius(&m);
    measured_radius.sort_by(f64::total_cmp);
    let limit = measured_radius[(measured_radius.len() - 1) * 999 / 1000];
    let synth_radius = radius(&s);
    synth_radius.iter().filter(|&&r| r > limit).count() as f64 / synth_radius.len() as f64
}

/// Issue 11 item 3: KL in linear RGB let chroma excursions of bright pixels land on dark ones
/// (stones: a* spread 2.3x the measured). In Lab the chroma spread of every kind's subspace
/// images is within 25 % of the measured on average; linear RGB (the old models) is not.
#[test]
fn chroma_spread_follows_the_measured_in_lab() {
    let btf = Btf::synthetic(SyntheticMaterial::Stones, 32, 4).unwrap();
    for kind in ModelKind::ALL {
        let ratios = |space| {
            let options = AnalysisOptions {
                kind,
                clusters: 8,
                range_map: false,
                colour_space: space,
                ..AnalysisOptions::default()
            };
            let model = analyze(&btf, &options, &NoProgress).unwrap().0;
            Colour::mean(&subspace_colours(&btf, &model))
        };
        let (rgb, lab) = (ratios(ColourSpace::LinearRgb), ratios(ColourSpace::Lab));
        println!("{kind}: rgb {}\n{kind}: lab {}", rgb.row(), lab.row());
        for c in 0..2 {
            assert!(
                (0.75..=1.25).contains(&lab.std_ratio[c]),
                "{kind} lab {}",
                lab.row()
            );
            assert!(
                (0.5..=2.0).contains(&lab.kurt_ratio[c]),
                "{kind} lab {}",
                lab.row()
            );
        }
        if kind != ModelKind::Car3d {
            assert!(rgb.std_ratio[0] > 1.5, "{kind} rgb {}", rgb.row());
        }
    }
}

/// Issue 11 item 3: the grey clay relief was synthesized with blue and orange specks. Count
/// the synthesized pixels beyond the measured 99.9 % chroma radius (0.1 % expected). The old
/// models (linear RGB KL, 17 evenly spaced factor quantiles) had up to 5.2 % of them in a
/// subspace image, 2.1 % on average; now at most 1.6 %, 0.34 % on average (one dark subspace
/// image still has 16x the expected share).
#[test]
fn grey_clay_has_no_coloured_specks() {
    let btf = Btf::open(data("rti/clay-leaf")).unwrap();
    let options = AnalysisOptions {
        clusters: 6,
        range_map: false,
        ..AnalysisOptions::default()
    };
    let model = analyze(&btf, &options, &NoProgress).unwrap().0;
    let fractions: Vec<f64> = per_subspace(&btf, &model, speck_fraction);
    println!("speck fractions: {fractions:.4?}");
    let worst = fractions.iter().fold(0.0f64, |m, &f| m.max(f));
    assert!(worst < SPECK_LIMIT, "{fractions:.4?}");
}

/// The most specks a subspace image may have (see [`grey_clay_has_no_coloured_specks`]).
const SPECK_LIMIT: f64 = 0.02;

/// Format version 2 keeps the colour space and the band tables; version 1 files (the golden
/// model) still read, as linear RGB without band tables.
#[test]
fn band_marginals_round_trip_and_version_1_models_still_read() {
    use btfmrf::model::format;
    let old =
        format::read(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/sponge64.btfm"))
            .unwrap();
    assert!(
        old.subspaces()
            .iter()
            .all(|s| s.kl.space == ColourSpace::LinearRgb)
    );
    assert!(old.subspaces().iter().all(|s| s.band_marginals.is_none()));
    let btf = Btf::synthetic(SyntheticMaterial::Sponge, 32, 2).unwrap();
    let options = AnalysisOptions {
        clusters: 3,
        range_map: false,
        band_marginals: true,
        ..AnalysisOptions::default()
    };
    let model = analyze(&btf, &options, &NoProgress).unwrap().0;
    let bytes = format::to_bytes(&model);
    let back = format::from_bytes(&bytes, std::path::Path::new("m.btfm")).unwrap();
    assert_eq!(back.cluster_table(), model.cluster_table());
    assert_eq!(
        format::band_marginal_bytes(&back),
        3 * model.levels() * 3 * 74
    );
    // Per subspace: 12 colour tables, 8 coupling pairs and a spread pair per chroma band (five
    // at 32^2, the coarsest 2 x 2).
    let bands = 5;
    assert_eq!(
        format::colour_marginal_bytes(&back),
        3 * (12 * 74 + 4 * (16 + 2 * bands))
    );
    for (a, b) in model.subspaces().iter().zip(back.subspaces()) {
        assert_eq!(b.kl.space, ColourSpace::Lab);
        // The chroma-lightness coupling (version 7) comes back to single precision.
        let coupling = |s: &btfmrf::model::SubspaceModel| {
            s.colour_marginals
                .as_ref()
                .and_then(|c| c.coupling)
                .unwrap()
        };
        for (ca, cb) in coupling(a)
            .iter()
            .flatten()
            .zip(coupling(b).iter().flatten())
        {
            assert!((ca - cb).abs() <= 1e-5 * ca.abs().max(1.0), "{ca} vs {cb}");
        }
        // So do the chroma spreads (version 13): one (a*, b*) pair per band, as measured.
        let spread = |s: &btfmrf::model::SubspaceModel| {
            s.colour_marginals
                .as_ref()
                .and_then(|c| c.chroma_spread.clone())
                .unwrap()
        };
        let (sa, sb) = (spread(a), spread(b));
        assert_eq!(sa.len(), sb.len());
        assert!(
            !sa.is_empty() && sa.iter().flatten().all(|v| *v > 0.0),
            "{sa:?}"
        );
        for (x, y) in sa.iter().flatten().zip(sb.iter().flatten()) {
            assert!((x - y).abs() <= 1e-6 * x.max(1.0), "{x} vs {y}");
        }
        let (ta, tb) = (
            a.band_marginals.as_ref().unwrap(),
            b.band_marginals.as_ref().unwrap(),
        );
        for (la, lb) in ta.tables.iter().zip(&tb.tables) {
            for (qa, qb) in la.iter().zip(lb) {
                let span = qa[qa.len() - 1] - qa[0];
                let err = qa
                    .iter()
                    .zip(qb)
                    .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
                assert!(
                    err <= span / 65535.0 + 1e-6 * span.max(1.0),
                    "{err} of {span}"
                );
            }
        }
    }
    // Matching the bands changes the synthesis, deterministically.
    let o = plain_options(48, 48, 3);
    let mut parts = model.clone().into_parts();
    for s in &mut parts.subspaces {
        s.band_marginals = None;
    }
    let plain = MaterialModel::new(parts).unwrap();
    let with = model.synthesize_subspace(0, &o).unwrap();
    assert_eq!(with, model.synthesize_subspace(0, &o).unwrap());
    let stored = back.synthesize_subspace(0, &o).unwrap();
    let gap = (&with - &stored).fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(gap < 1e-3, "stored model synthesizes {gap} away");
    let without = plain.synthesize_subspace(0, &o).unwrap();
    assert!((&with - &without).fold(0.0f32, |m, v| m.max(v.abs())) > 1e-3);
}

/// Every measured pair's synthesis comes back at the pair's measured brightness (issue 11): a
/// subspace image stands for images of other brightness (its members under other lights), and
/// a relief's shadows that fall elsewhere in a synthesis than in the photograph change the
/// mean. The pair gains bring the frontal view's mean linear luminance within 3 % of the
/// measured at every light that leaves it lit; without them the worst light is far off.
#[test]
fn measured_pairs_come_back_at_their_measured_brightness() {
    use btfmrf::geometry::relight::luminance;
    let btf = Btf::synthetic(SyntheticMaterial::Sponge, 64, 5).unwrap();
    let options = AnalysisOptions {
        clusters: 8,
        ..AnalysisOptions::default()
    };
    let (model, _) = analyze(&btf, &options, &NoProgress).unwrap();
    // Without the light tables, which give every frontal light its measured lightness anyway.
    let mut parts = model.into_parts();
    parts.light_lightness = None;
    let model = MaterialModel::new(parts).unwrap();
    let mut parts = model.clone().into_parts();
    parts.pair_gains.clear();
    let plain = MaterialModel::new(parts).unwrap();
    let o = plain_options(64, 64, 1);
    let view = *btf.views().get(0).unwrap();
    let worst = |m: &MaterialModel| {
        let cache = m.synthesis_cache(&o).unwrap();
        btf.lights()
            .iter()
            .enumerate()
            .filter(|(_, d)| d.theta_deg <= 75.0)
            .map(|(l, d)| {
                let measured = luminance(&btf.image(0, l).unwrap()).mean().unwrap();
                let synth = luminance(&m.image_from_cache(&cache, &view, d).unwrap())
                    .mean()
                    .unwrap();
                (synth / measured).ln().abs()
            })
            .fold(0.0f64, f64::max)
            .exp()
    };
    let (with, without) = (worst(&model), worst(&plain));
    println!("worst mean ratio (or its inverse): {with:.3} with the gains, {without:.3} without");
    assert!(with < 1.03, "{with}");
    assert!(without > 1.1, "{without}");
}

/// The share of a chroma plane's variance in differences between horizontal neighbours
/// (`mean (p[x+1] - p[x])^2 / (2 var)`): near 0 for colours constant over regions, 1 for
/// white noise.
fn fine_share(plane: &[f64], cols: usize) -> f64 {
    let n = plane.len() as f64;
    let mean = plane.iter().sum::<f64>() / n;
    let var = plane.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let steps: Vec<f64> = plane
        .chunks(cols)
        .flat_map(|row| row.windows(2).map(|w| (w[1] - w[0]).powi(2)))
        .collect();
    steps.iter().sum::<f64>() / steps.len() as f64 / (2.0 * var.max(1e-12))
}

/// Issue 11: the MRF's chroma factors are independent of the structure, so a stone's colour
/// came out as fine mottling across every stone (a* fine share 7.5x the measured at 128^2,
/// nine lights). The exemplar's chroma, laid with the relief's patches, keeps each stone's
/// colour with its shape. Measured at 64^2 when written: a* fine share x1.65 / x2.64 / x2.43
/// the measured at the lights below, mean x2.24 (x2.85 / x3.94 / x4.07, mean x3.62, with the
/// exemplar chroma left out of the synthesis). With the laid crops' coarse L* (format 11):
/// x1.80 / 2.87 / 2.85, mean x2.51; with their coarse chroma too it was x3.10, so the coarse
/// chroma stays the MRF's.
#[test]
fn a_stone_keeps_its_own_colour() {
    let btf = Btf::synthetic(SyntheticMaterial::Stones, 64, 5).unwrap();
    let model = fit(&btf, ModelKind::Car2d, ColourSpace::Lab, false);
    assert!(
        model.exemplar().is_some_and(|e| e.chroma.is_some()),
        "the stones keep an exemplar with chroma"
    );
    let file = btfmrf::model::format::to_bytes(&model);
    let back = btfmrf::model::format::from_bytes(&file, std::path::Path::new("s.btfm")).unwrap();
    assert_eq!(
        back.exemplar(),
        model.exemplar(),
        "the file holds the exemplar as analysed"
    );
    assert_eq!(btfmrf::model::format::to_bytes(&back), file);
    let o = plain_options(64, 64, 1);
    let cache = model.synthesis_cache(&o).unwrap();
    let view = *btf.views().get(0).unwrap();
    let mut ratios = Vec::new();
    for (theta, phi) in [(15.0, 120.0), (45.0, 20.0), (60.0, 234.0)] {
        let light = btfmrf::btf::Direction::new(theta, phi);
        let l = btf.lights().find(&light, 0.5).unwrap();
        let measured = lab(&btf.image(0, l).unwrap());
        let synthesized = lab(&model.image_from_cache(&cache, &view, &light).unwrap());
        let ratio = fine_share(&synthesized[1], 64) / fine_share(&measured[1], 64);
        println!("light {theta}/{phi}: a* fine share x{ratio:.2} the measured");
        ratios.push(ratio);
    }
    let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
    assert!(
        mean < 3.0,
        "a* fine share x{mean:.2} the measured: {ratios:.2?}"
    );
}

/// A relief's shading meets the synthesized colours otherwise than the measured ones (issue
/// 11): de-shaded colour tables and pair gains left the relit sponge's L* quantiles 1-4 Lab
/// units from the measured image at lights whose representative's own marginal is within 0.2
/// of it. With the lit lightness tables, the synthesis at each frontal representative's own
/// light has its measured L* distribution up to the tables' 33 knots and the pair gains'
/// steps (measured worst 0.59 Lab units); without them it is far off at some light (1.73).
#[test]
fn a_relit_synthesis_has_its_representatives_lightness() {
    let btf = Btf::synthetic(SyntheticMaterial::Sponge, 64, 5).unwrap();
    let view = *btf.views().get(0).unwrap();
    let o = plain_options(64, 64, 1);
    let worst = |lit_matching: bool| {
        // Without the light tables, which would give every light its measured lightness.
        let options = AnalysisOptions {
            clusters: 8,
            lit_matching,
            light_tables: false,
            ..AnalysisOptions::default()
        };
        let (model, _) = analyze(&btf, &options, &NoProgress).unwrap();
        assert_eq!(
            model.subspaces().iter().all(|s| s.lit_marginals.is_some()),
            lit_matching
        );
        let cache = model.synthesis_cache(&o).unwrap();
        model
            .subspaces()
            .iter()
            .filter(|s| s.representative.0 == 0)
            .map(|s| {
                let l = usize::from(s.representative.1);
                let light = *btf.lights().get(l).unwrap();
                let measured = lab(&btf.image(0, l).unwrap());
                let synth = lab(&model.image_from_cache(&cache, &view, &light).unwrap());
                quantile_gap(&measured[0], &synth[0])
            })
            .fold(0.0f64, f64::max)
    };
    let (with, without) = (worst(true), worst(false));
    println!(
        "worst L* quantile gap at a representative's light: {with:.2} with the lit tables, {without:.2} without"
    );
    assert!(with < 0.8, "{with}");
    assert!(without > 1.2, "{without}");
}

/// The built-in leather (128^2, seed 5) rendered by the generator in the frontal view under
/// `lights` (theta, phi in degrees): references between the measured lights.
fn leather_under(lights: &[(f64, f64)]) -> Btf {
    SyntheticBtf::with_directions(
        SyntheticMaterial::Leather,
        128,
        5,
        &DirectionSet::new(vec![Direction::new(0.0, 0.0)]).unwrap(),
        &DirectionSet::new(lights.iter().map(|&(t, p)| Direction::new(t, p)).collect()).unwrap(),
    )
    .unwrap()
    .into_btf()
}

/// Issue 11 item 3: a cluster's lights share one subspace image, whose lightness is matched
/// at its representative's light only, so at the cluster's other lights the leather's L*
/// missed the measured by 2-3 Lab units (60-75 degree lights). With the light tables the
/// finished image takes each light's measured L* quantiles, blended over the nearest measured
/// lights: checked at measured lights, where the colour target (1.0) must now hold, and
/// at lights halfway between measured ones, rendered by the generator for the reference, where
/// the blend must still bring the colour closer and cost no structure (measured: colour 0.85
/// against 1.62 Lab at the measured lights, 1.11 against 1.22 halfway; structure 0.4 % closer
/// halfway).
#[test]
fn every_light_gets_its_measured_lightness_also_between_the_measured_ones() {
    let btf = Btf::synthetic(SyntheticMaterial::Leather, 128, 5).unwrap();
    let (model, _) = analyze(&btf, &AnalysisOptions::default(), &NoProgress).unwrap();
    assert!(model.light_lightness().is_some());
    let mut parts = model.clone().into_parts();
    parts.light_lightness = None;
    let without = MaterialModel::new(parts).unwrap();
    let view = Direction::new(0.0, 0.0);
    let between = [(37.5, 100.0), (52.5, 170.0), (67.5, 120.0), (67.5, 250.0)];
    let halfway = leather_under(&between);
    // Per model: mean colour distance and geometric-mean structure over the lights and seeds.
    let judged = |lights: &[(f64, f64)], reference: &dyn Fn(usize, &Direction) -> Array3<f32>| {
        let mut scores = [(0.0, 0.0); 2];
        for (i, &(theta, phi)) in lights.iter().enumerate() {
            let light = Direction::new(theta, phi);
            let y = Yardstick::new(&reference(i, &light), None, 1).unwrap();
            for seed in [2, 3] {
                let o = plain_options(128, 128, seed);
                for (score, m) in scores.iter_mut().zip([&model, &without]) {
                    let j = y
                        .judge(&m.synthesize_image(&view, &light, &o).unwrap())
                        .unwrap()
                        .judgement;
                    score.0 += j.colour_lab;
                    score.1 += j.structure.ln();
                }
            }
        }
        let n = 2.0 * lights.len() as f64;
        scores.map(|(c, s)| (c / n, (s / n).exp()))
    };
    let measured = [(30.0, 90.0), (60.0, 90.0), (75.0, 45.0), (75.0, 195.0)];
    let [at, at_without] = judged(&measured, &|_, light| {
        btf.image(0, btf.lights().find(light, 0.5).unwrap())
            .unwrap()
    });
    let [mid, mid_without] = judged(&between, &|i, _| halfway.image(0, i).unwrap());
    println!(
        "leather, with / without light tables: measured lights colour {:.2} / {:.2} Lab, \
         structure {:.4} / {:.4}; halfway lights colour {:.2} / {:.2} Lab, structure {:.4} / {:.4}",
        at.0, at_without.0, at.1, at_without.1, mid.0, mid_without.0, mid.1, mid_without.1
    );
    assert!(at.0 <= 1.0 && at.0 < at_without.0, "{at:?} {at_without:?}");
    assert!(mid.0 < mid_without.0, "{mid:?} {mid_without:?}");
    assert!(mid.1 < 1.02 * mid_without.1, "{mid:?} {mid_without:?}");
}

/// The light chroma tables are kept only where the chroma can be seen: the frontal images of
/// the built-in leather made grey (each pixel its luminance in every channel) give a model
/// with light lightness tables and no chroma tables; in colour, a chroma table pair a light.
#[test]
fn a_grey_capture_keeps_no_light_chroma() {
    let leather = Btf::synthetic(SyntheticMaterial::Leather, 48, 5).unwrap();
    let lights = leather.lights().clone();
    let frontal = |grey: bool| {
        let images = (0..lights.len())
            .map(|l| {
                let mut image = leather.image(0, l).unwrap();
                if grey {
                    let y = btfmrf::geometry::relight::luminance(&image);
                    for mut channel in image.outer_iter_mut() {
                        channel.zip_mut_with(&y, |v, &y| *v = y as f32);
                    }
                }
                image
            })
            .collect();
        Btf::from_images(DirectionSet::zenith(), lights.clone(), images).unwrap()
    };
    let options = AnalysisOptions {
        clusters: 6,
        ..AnalysisOptions::default()
    };
    for (grey, kept) in [(true, None), (false, Some(lights.len()))] {
        let (model, _) = analyze(&frontal(grey), &options, &NoProgress).unwrap();
        let tables = model
            .light_lightness()
            .expect("light tables beside a range map");
        assert_eq!(tables.chroma.as_ref().map(Vec::len), kept, "grey {grey}");
    }
}

/// Issue 11's colour target is per channel: at most 1.0 Lab units of mean |quantile
/// difference| in each of L*, a* and b*. A cluster's lights share their representative's
/// chroma, so the leather's b* missed it at five of nine measured frontal lights (1.05-2.29 at
/// seed 1; another crop of the same material: 0.03-0.08). With every light's a* and b*
/// quantiles stored beside its L* table, each channel holds the target at every measured
/// light, and the a* and b* come closer halfway between measured lights too (tables blended).
/// Measured: see the printed line and docs/BENCHMARKS.md.
#[test]
fn every_light_gets_its_measured_chroma() {
    let btf = Btf::synthetic(SyntheticMaterial::Leather, 128, 5).unwrap();
    let (model, _) = analyze(&btf, &AnalysisOptions::default(), &NoProgress).unwrap();
    let chroma = model.light_lightness().and_then(|t| t.chroma.as_ref());
    assert_eq!(chroma.map(Vec::len), Some(btf.lights().len()));
    // The same model without the chroma tables (analysis makes everything else alike).
    let mut parts = model.clone().into_parts();
    if let Some(t) = parts.light_lightness.as_mut() {
        t.chroma = None;
    }
    let without = MaterialModel::new(parts).unwrap();
    let view = Direction::new(0.0, 0.0);
    let o = plain_options(128, 128, 1);
    // Per model, the worst per-channel gap over the lights, a* and b* apart.
    let worst = |m: &MaterialModel,
                 lights: &[(f64, f64)],
                 reference: &dyn Fn(&Direction) -> Array3<f32>| {
        let cache = m.synthesis_cache(&o).unwrap();
        let mut worst = [0.0f64; 2];
        for &(theta, phi) in lights {
            let light = Direction::new(theta, phi);
            let (measured, synth) = (
                lab(&reference(&light)),
                lab(&m.image_from_cache(&cache, &view, &light).unwrap()),
            );
            for c in 0..2 {
                worst[c] = worst[c].max(quantile_gap(&measured[c + 1], &synth[c + 1]));
            }
        }
        worst
    };
    let measured = btfmrf::eval::JUDGED_LIGHTS;
    let at_measured = |light: &Direction| {
        btf.image(0, btf.lights().find(light, 0.5).unwrap())
            .unwrap()
    };
    let (with, with_out) = (
        worst(&model, &measured, &at_measured),
        worst(&without, &measured, &at_measured),
    );
    let between = [(37.5, 100.0), (52.5, 170.0), (67.5, 120.0)];
    let halfway = leather_under(&between);
    let at_between = |light: &Direction| {
        halfway
            .image(0, halfway.lights().find(light, 0.5).unwrap())
            .unwrap()
    };
    let (mid, mid_out) = (
        worst(&model, &between, &at_between),
        worst(&without, &between, &at_between),
    );
    println!(
        "leather, worst a* / b* gap over {} measured lights: {:.2} / {:.2} with the chroma \
         tables, {:.2} / {:.2} without; halfway {:.2} / {:.2} against {:.2} / {:.2}",
        measured.len(),
        with[0],
        with[1],
        with_out[0],
        with_out[1],
        mid[0],
        mid[1],
        mid_out[0],
        mid_out[1]
    );
    assert!(with.iter().all(|&g| g <= 1.0), "{with:?}");
    assert!(with_out.iter().any(|&g| g > 1.0), "{with_out:?}");
    assert!(mid[1] < mid_out[1], "{mid:?} {mid_out:?}");
}

/// Issue 11 item 3: the demo's sponge (64^2, seed 1), judged over the bench's eight pairs,
/// had a* kurtosis 40 against the measured 3.1. Cause: relit highlights above 1 (0.55 % of the
/// values, where the view's masking should have hidden the shadows: near the light's
/// direction the relief showed its full contrast) clipped channel by channel for display,
/// which turns their hue. Now the view's parallax keeps them in range (0.003 %), and
/// over-range pixels are brought into range whole ([`btfmrf::color::fit_to_gamut`]): the
/// same images pushed 1.5x brighter keep their chroma's kurtosis, where clipping each channel
/// does not.
#[test]
fn relit_highlights_stay_in_range_and_keep_their_colour() {
    let btf = Btf::synthetic(SyntheticMaterial::Sponge, 64, 1).unwrap();
    let options = AnalysisOptions {
        seed: 1,
        ..AnalysisOptions::default()
    };
    let model = analyze(&btf, &options, &NoProgress).unwrap().0;
    let o = plain_options(64, 64, 1);
    let cache = model.synthesis_cache(&o).unwrap();
    let (mut sums, mut over, mut values) = ([[0.0; 2]; 4], 0, 0);
    for (v, l) in fidelity_pairs(&btf, 8) {
        let (view, light) = (btf.views().get(v).unwrap(), btf.lights().get(l).unwrap());
        let image = model.image_from_cache(&cache, view, light).unwrap();
        over += image.iter().filter(|&&x| x > 1.0).count();
        values += image.len();
        let y = Yardstick::new(&btf.image(v, l).unwrap(), None, 1).unwrap();
        let kurtosis = |image: &Array3<f32>| y.judge(image).unwrap().judgement.chroma_kurtosis;
        let bright = image.mapv(|x| 1.5 * x);
        let rows = [
            y.levels().measured.judgement.chroma_kurtosis,
            kurtosis(&image),
            kurtosis(&bright),
            kurtosis(&bright.mapv(|x| x.clamp(0.0, 1.0))),
        ];
        for (sum, row) in sums.iter_mut().zip(rows) {
            for k in 0..2 {
                sum[k] += row[k];
            }
        }
    }
    let [measured, synthesized, fitted, clipped] = sums;
    println!(
        "a*, b* kurtosis (sums over 8 pairs): measured {measured:.1?}, synthesized \
         {synthesized:.1?}, 1.5x brighter fitted {fitted:.1?}, clipped per channel \
         {clipped:.1?}; {over} of {values} values over 1"
    );
    assert!(over * 1000 <= values, "{over} of {values} values over 1");
    for k in 0..2 {
        for (what, sum) in [("synthesized", synthesized), ("fitted", fitted)] {
            let ratio = sum[k] / measured[k];
            assert!(
                (0.5..=2.0).contains(&ratio),
                "{what} channel {k}: x{ratio:.2}"
            );
        }
    }
    assert!(clipped[0] / measured[0] > 2.0, "{clipped:.1?}");
}

/// Standard deviation of `plane`'s Gaussian blur at `sigma` px, `2 sigma` px of border cut.
fn coarse_spread(plane: &ndarray::Array2<f64>, sigma: f64) -> f64 {
    let (coarse, _) = btfmrf::geometry::split_detail(plane, sigma, false);
    let cut = (2.0 * sigma) as usize;
    let (h, w) = coarse.dim();
    coarse
        .slice(ndarray::s![cut..h - cut, cut..w - cut])
        .std(0.0)
}

/// Issue 11 item 3, found by looking at a 512^2 leather: orange and dark-brown patches 50-100
/// px across that the measured leather lacks. Cause (docs/BENCHMARKS.md, "Diagnosis: the
/// leather's orange blotches"): the exemplar's 2 x 2 chroma blocks drop the chroma's
/// pixel-scale part, and the joint colour transfer made up the variance by stretching the
/// coarser chroma: on the generator's float images the chroma blurred at 4 px varied 1.57x
/// (a*) and 1.68x (b*) as much as the measured; from the JPEG frames of `btfmrf generate` (as
/// `models/leather.btfm` is made) about 4x. The chroma spreads (format version 13) scale each
/// of the chroma's pyramid bands to the measured spread within the transfer: now 1.17x and
/// 1.17x. The bound is the 25 % for the chroma's spread, either way. (At 12 px the
/// chroma spread 1.3x the measured with the first version of the scaling, as the L* did,
/// which the chroma follows.)
#[test]
fn an_enlarged_leather_has_the_measured_chroma_at_coarse_scales() {
    let btf = Btf::synthetic(SyntheticMaterial::Leather, 128, 5).unwrap();
    let (model, _) = analyze(&btf, &AnalysisOptions::default(), &NoProgress).unwrap();
    let light = Direction::new(45.0, 160.0);
    let l = btf.lights().find(&light, 0.5).unwrap();
    let measured = ColourSpace::Lab.planes(&btf.image(0, l).unwrap());
    let synth = ColourSpace::Lab.planes(
        &model
            .synthesize_image(
                &Direction::new(0.0, 0.0),
                &light,
                &plain_options(512, 512, 1),
            )
            .unwrap(),
    );
    let ratios: Vec<f64> = (0..3)
        .map(|c| coarse_spread(&synth[c], 4.0) / coarse_spread(&measured[c], 4.0))
        .collect();
    println!("L*, a*, b* spread blurred at 4 px, synthesized over measured: {ratios:.2?}");
    assert!(ratios[0] < 1.25, "the lightness: {ratios:.2?}");
    assert!(
        ratios[1..].iter().all(|r| (0.75..1.25).contains(r)),
        "the chroma: {ratios:.2?}"
    );
}

/// A grey photograph's a* and b* vary by the Lab conversion's rounding alone (by 3e-5 units
/// on this crop): its model keeps no texture of them (flat chroma factors, no exemplar
/// chroma), so its synthesis draws, lays and transfers no chroma, and comes out grey. The same
/// photograph with a faint blue cast in its shadows keeps both and comes out tinted.
#[test]
fn a_grey_photograph_models_no_chroma_and_a_tinted_one_does() {
    let photo = btfmrf::btf::io::read_image(&data("textures/gravel.png")).unwrap();
    let grey = photo.slice(ndarray::s![.., ..160, ..160]).to_owned();
    let mut tinted = grey.clone();
    tinted
        .index_axis_mut(ndarray::Axis(0), 2)
        .mapv_inplace(|v| v + 0.02 * (1.0 - v));
    let zenith = Direction::new(0.0, 0.0);
    for (image, has_chroma) in [(grey, false), (tinted, true)] {
        let btf =
            Btf::from_images(DirectionSet::zenith(), DirectionSet::zenith(), vec![image]).unwrap();
        let model = analyze(&btf, &AnalysisOptions::default(), &NoProgress)
            .unwrap()
            .0;
        let exemplar = model.exemplar().expect("a photograph keeps an exemplar");
        assert_eq!(exemplar.chroma.is_some(), has_chroma);
        let synth = model
            .synthesize_image(&zenith, &zenith, &plain_options(128, 128, 1))
            .unwrap();
        let [_, a, b] = lab(&synth);
        let (a_spread, b_spread) = (spread(&a).0, spread(&b).0);
        println!("chroma {has_chroma}: a* std {a_spread:.5}, b* std {b_spread:.5}");
        if has_chroma {
            assert!(b_spread > 0.3, "{b_spread}");
        } else {
            assert!(a_spread < 0.01 && b_spread < 0.01, "{a_spread} {b_spread}");
        }
    }
}
