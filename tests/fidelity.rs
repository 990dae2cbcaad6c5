//! The texture judge (`eval::judge`) must rank references the way people would: another crop
//! of the same material closest, then the material's random-phase noise (its exact power
//! spectrum, no structure), then a pixel-shuffled copy, a blurred copy and a different
//! material. Proved on the built-in materials, the texture photographs and the RTI captures;
//! then the judge reports how far each model's synthesis is from the measured material.

use std::path::PathBuf;

mod common;

use btfmrf::analysis::{AnalysisOptions, ReliefLayout, analyze};
use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, Direction};
use btfmrf::decompose::ColourSpace;
use btfmrf::decompose::pyramid::detail_spreads;
use btfmrf::eval::{JUDGED_LIGHTS, Levels, Verdict, Yardstick};
use btfmrf::model::{CoarseSource, Exemplar, LIGHTNESS_BANDS, MaterialModel, ModelKind};
use btfmrf::progress::NoProgress;
use btfmrf::synthesis::SynthesisOptions;
use ndarray::{Array3, s};

const PHOTOS: [&str; 3] = ["brick", "grass", "gravel"];
const RTI: [&str; 4] = ["clay-leaf", "painted-door", "canvas-handheld", "coin"];

fn shared(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(path)
}

fn photo(name: &str) -> Array3<f32> {
    btfmrf::btf::io::read_image(&shared(&format!("textures/{name}.png"))).unwrap()
}

/// The image of the RTI set's light nearest to 45 degrees elevation.
fn rti_image(set: &str) -> Array3<f32> {
    let btf = Btf::open(shared(&format!("rti/{set}"))).unwrap();
    let light = (0..btf.lights().len())
        .min_by(|&a, &b| {
            let d = |l: usize| (btf.lights().get(l).unwrap().theta_deg - 45.0).abs();
            d(a).total_cmp(&d(b))
        })
        .unwrap();
    btf.image(0, light).unwrap()
}

/// The top-left `side` x `2 side` window (two crops of `side` for the yardstick).
fn window(image: &Array3<f32>, side: usize) -> Array3<f32> {
    let (_, h, w) = image.dim();
    image
        .slice(s![.., ..side.min(h), ..(2 * side).min(w)])
        .to_owned()
}

fn print_levels(name: &str, l: &Levels) {
    let rows: Vec<String> = l
        .rows()
        .iter()
        .map(|(n, v)| format!("{n} {:.4}", v.judgement.structure))
        .collect();
    println!("{name}: {}", rows.join(", "));
}

/// Asserts the ranking crop < random phase < shuffled, blurred (and other material where
/// `other_beyond_random_phase`; otherwise the other material only beyond the crop).
fn assert_ranking(name: &str, l: &Levels, other_beyond_random_phase: bool) {
    print_levels(name, l);
    let crop = l.crop.judgement.structure;
    let rp = l.random_phase.judgement.structure;
    assert!(crop < rp, "{name}: crop {crop} vs random phase {rp}");
    for (level, v) in l.rows().into_iter().skip(2) {
        let floor = if level == "other material" && !other_beyond_random_phase {
            crop
        } else {
            rp
        };
        assert!(
            floor < v.judgement.structure,
            "{name}: {level} {} not beyond {floor}",
            v.judgement.structure
        );
    }
}

#[test]
fn the_judge_ranks_the_reference_levels_on_the_built_in_materials() {
    let images: Vec<Array3<f32>> = SyntheticMaterial::ALL
        .iter()
        .map(|&m| {
            window(
                &Btf::synthetic(m, 256, 2).unwrap().image(0, 20).unwrap(),
                128,
            )
        })
        .collect();
    for (i, material) in SyntheticMaterial::ALL.iter().enumerate() {
        let other = &images[(i + 1) % images.len()];
        let y = Yardstick::new(&images[i], Some(other), 1).unwrap();
        assert_ranking(&material.to_string(), y.levels(), true);
    }
}

#[test]
fn the_judge_ranks_the_reference_levels_on_the_photographs() {
    let images: Vec<Array3<f32>> = PHOTOS.iter().map(|p| window(&photo(p), 128)).collect();
    for (i, name) in PHOTOS.iter().enumerate() {
        let other = &images[(i + 1) % images.len()];
        let y = Yardstick::new(&images[i], Some(other), 1).unwrap();
        assert_ranking(name, y.levels(), true);
    }
}

/// The RTI captures are objects and paintings rather than stationary textures. On the clay
/// relief, the door panel and the coin the ranking holds, except that the door panel is closer
/// to the canvas (another painting: 0.33) than to its own random-phase noise (0.38), so there
/// the other material is only required to be beyond the crop level. The handheld canvas is
/// printed, not asserted: its two halves show different parts of a painting under a handheld
/// light's falloff (crop level 0.40 against random phase 0.28 when written), so "another crop"
/// is not "the same material" there.
#[test]
fn the_judge_ranks_the_reference_levels_on_the_rti_captures() {
    let images: Vec<Array3<f32>> = RTI.iter().map(|set| window(&rti_image(set), 128)).collect();
    for (i, name) in RTI.iter().enumerate() {
        let other = &images[(i + 1) % images.len()];
        let y = Yardstick::new(&images[i], Some(other), 1).unwrap();
        if *name != "canvas-handheld" {
            assert_ranking(name, y.levels(), false);
        } else {
            print_levels(
                &format!("{name} (not stationary, not asserted)"),
                y.levels(),
            );
        }
    }
}

/// Judges each model's synthesis (128^2, frontal view, light at theta 45 phi 20) against the
/// measured image of a 128^2 material (seed 5); the another-crop level is the same material
/// generated with seed 6, so every crop is 128^2. Prints one line per model.
fn judge_models(material: SyntheticMaterial, kinds: &[ModelKind]) -> Vec<(ModelKind, Verdict)> {
    let (v, l) = (0, 20);
    let i = SyntheticMaterial::ALL
        .iter()
        .position(|&m| m == material)
        .unwrap();
    let btf = Btf::synthetic(material, 128, 5).unwrap();
    let another = Btf::synthetic(material, 128, 6)
        .unwrap()
        .image(v, l)
        .unwrap();
    let other = Btf::synthetic(SyntheticMaterial::ALL[(i + 1) % 4], 128, 5).unwrap();
    let (view, light) = (*btf.views().get(v).unwrap(), *btf.lights().get(l).unwrap());
    assert_eq!(light, Direction::new(45.0, 20.0));
    let measured = btf.image(v, l).unwrap();
    let other = other.image(v, l).unwrap();
    let y = Yardstick::from_samples(&measured, &another, Some(&other), 1).unwrap();
    print_levels(&material.to_string(), y.levels());
    kinds
        .iter()
        .map(|&kind| {
            let options = AnalysisOptions {
                kind,
                clusters: 10,
                ..AnalysisOptions::default()
            };
            let (model, _) = analyze(&btf, &options, &NoProgress).unwrap();
            let o = SynthesisOptions {
                rows: 128,
                cols: 128,
                seed: 1,
                tileable: false,
            };
            let f = y
                .judge(&model.synthesize_image(&view, &light, &o).unwrap())
                .unwrap();
            println!(
                "{material} {kind}: structure {:.4} (x{:.2} crop, x{:.2} random phase), colour {:.2} Lab, a* std {:.2} kurtosis {:.1}",
                f.judgement.structure,
                f.structure_vs_crop,
                f.structure_vs_random_phase,
                f.judgement.colour_lab,
                f.judgement.chroma_std[0],
                f.judgement.chroma_kurtosis[0],
            );
            (kind, f)
        })
        .collect()
}

/// The default model (2D CAR) on two materials: a regression guard at today's level with a
/// margin, not the goal. Measured when written: sponge x1.27, stones x0.97 the random-phase
/// level; colour 3.15 and 2.91 Lab. After the colour (KL in Lab), relighting (measured bump
/// strength, shading divided out of the frontal images) and CAR stability changes were merged
/// together, sponge measures x1.64 and stones x1.11 (colour 3.22 and 1.80 Lab): a structure
/// regression on the relit image that issue 11 must explain. Issue 11's target is x1.0 random
/// phase, then the crop level.
#[test]
fn the_default_model_stays_near_the_random_phase_level() {
    for material in [SyntheticMaterial::Sponge, SyntheticMaterial::Stones] {
        for (kind, f) in judge_models(material, &[ModelKind::Car2d]) {
            assert!(
                f.structure_vs_random_phase < 1.8,
                "{material} {kind}: {f:?}"
            );
            assert!(f.judgement.colour_lab < 4.0, "{material} {kind}: {f:?}");
        }
    }
}

/// Every model on every built-in material at 128^2: the "before" table of issue 11
/// (`cargo test --release --test fidelity -- --ignored --nocapture`).
#[test]
#[ignore = "about 3 minutes on 2 cores: 12 analyses of 128^2 materials"]
fn every_model_on_every_material_is_judged() {
    for material in SyntheticMaterial::ALL {
        let verdicts = judge_models(material, &ModelKind::ALL);
        assert_eq!(verdicts.len(), 3);
    }
}

fn luminance_correlation(a: &Array3<f32>, b: &Array3<f32>) -> f64 {
    let lum = |im: &Array3<f32>| -> Vec<f64> {
        let (_, h, w) = im.dim();
        (0..h * w)
            .map(|k| {
                let (y, x) = (k / w, k % w);
                f64::from(0.2126 * im[[0, y, x]] + 0.7152 * im[[1, y, x]] + 0.0722 * im[[2, y, x]])
            })
            .collect()
    };
    btfmrf::eval::correlation(&lum(a), &lum(b))
}

/// Coherence across lights: in the measured BTF the same texel shows the same surface under
/// every light, so the images of two lights correlate pixel by pixel in a way set by the
/// geometry (nearby lights strongly, opposite lights even negatively). Synthesized images of
/// different subspaces must reproduce that pattern rather than boil into unrelated textures.
/// Over pairs of lights from different clusters, the synthesized correlations (shared noise)
/// must track the measured ones better than images synthesized with unrelated noise do.
#[test]
fn synthesized_images_stay_the_same_surface_under_different_lights() {
    let btf = Btf::synthetic(SyntheticMaterial::Sponge, 64, 2).unwrap();
    let options = AnalysisOptions {
        kind: ModelKind::Car2d,
        clusters: 12,
        ..AnalysisOptions::default()
    };
    let (model, _) = analyze(&btf, &options, &NoProgress).unwrap();
    let view = *btf.views().get(0).unwrap();
    let lights: Vec<usize> = (1..61).step_by(5).collect(); // 12 lights up to theta 60
    let synth = |l: usize, seed: u64| {
        let light = *btf.lights().get(l).unwrap();
        model
            .synthesize_image(
                &view,
                &light,
                &SynthesisOptions {
                    rows: 64,
                    cols: 64,
                    seed,
                    tileable: false,
                },
            )
            .unwrap()
    };
    let measured: Vec<_> = lights.iter().map(|&l| btf.image(0, l).unwrap()).collect();
    let shared: Vec<_> = lights.iter().map(|&l| synth(l, 4)).collect();
    let unrelated: Vec<_> = lights
        .iter()
        .enumerate()
        .map(|(k, &l)| synth(l, 100 + k as u64))
        .collect();
    let (mut err_shared, mut err_unrelated, mut pairs) = (0.0, 0.0, 0);
    let (mut sum_measured, mut sum_shared) = (0.0, 0.0);
    for i in 0..lights.len() {
        for j in i + 1..lights.len() {
            if model.cluster_of(0, lights[i]).unwrap() == model.cluster_of(0, lights[j]).unwrap() {
                continue;
            }
            let m = luminance_correlation(&measured[i], &measured[j]);
            let s = luminance_correlation(&shared[i], &shared[j]);
            let u = luminance_correlation(&unrelated[i], &unrelated[j]);
            err_shared += (s - m).abs();
            err_unrelated += (u - m).abs();
            sum_measured += m;
            sum_shared += s;
            pairs += 1;
        }
    }
    let n = f64::from(pairs);
    println!(
        "coherence over {pairs} light pairs: mean correlation measured {:.3}, synthesized {:.3}; mean |error| shared noise {:.3}, unrelated noise {:.3}",
        sum_measured / n,
        sum_shared / n,
        err_shared / n,
        err_unrelated / n
    );
    assert!(pairs >= 10);
    assert!(
        err_shared < err_unrelated,
        "{err_shared} vs {err_unrelated}"
    );
}

/// Every model on each texture photograph (opened as a one-light BTF), synthesized at the
/// photograph's size and judged against it: the photographs' rows of issue 11's "before"
/// table (`cargo test --release --test fidelity -- --ignored --nocapture`).
#[test]
#[ignore = "about a minute on 2 cores: 9 analyses and 512^2 syntheses"]
fn every_model_on_every_photograph_is_judged() {
    for (i, name) in PHOTOS.iter().enumerate() {
        let path = shared(&format!("textures/{name}.png"));
        let btf = Btf::open(&path).unwrap();
        let measured = btf.image(0, 0).unwrap();
        let other = photo(PHOTOS[(i + 1) % PHOTOS.len()]);
        let y = Yardstick::new(&measured, Some(&other), 1).unwrap();
        print_levels(name, y.levels());
        let (_, h, w) = measured.dim();
        let zenith = Direction::new(0.0, 0.0);
        // With the structure exemplar (the default for a photograph) and without it.
        for (kind, exemplar_side) in ModelKind::ALL
            .into_iter()
            .flat_map(|k| [(k, None), (k, Some(0))])
        {
            let options = AnalysisOptions {
                kind,
                exemplar_side,
                ..AnalysisOptions::default()
            };
            let (model, _) = analyze(&btf, &options, &NoProgress).unwrap();
            let o = SynthesisOptions {
                rows: h,
                cols: w,
                seed: 1,
                tileable: false,
            };
            let f = y
                .judge(&model.synthesize_image(&zenith, &zenith, &o).unwrap())
                .unwrap();
            println!(
                "{name} {kind} exemplar {exemplar_side:?}: {} bytes, structure {:.4} (x{:.2} crop, x{:.2} random phase), colour {:.2} Lab",
                btfmrf::model::format::to_bytes(&model).len(),
                f.judgement.structure,
                f.structure_vs_crop,
                f.structure_vs_random_phase,
                f.judgement.colour_lab,
            );
            assert!(f.judgement.structure.is_finite());
        }
    }
}

/// Issue 11: on the built-in leather the MRF's L* variation coarser than the exemplar's
/// patches drew blotches the measured leather lacks (nine frontal lights, seeds 1-4: x1.44 the
/// another-crop level, x1.26 with the laid crops' own coarse L*), so analysis judges where the
/// exemplar's coarse variation comes from, at seed 1; the judge must agree at other seeds and
/// lights. Measured when written: the laid crops chosen, their structure distance x0.938 the
/// MRF's (geometric mean of eight); since the quilt holds back repeated patches, the MRF's
/// chosen, x0.942 the laid crops'.
#[test]
fn the_leathers_coarse_variation_comes_from_where_analysis_judged_it_best() {
    let btf = Btf::synthetic(SyntheticMaterial::Leather, 128, 5).unwrap();
    let (model, _) = analyze(&btf, &AnalysisOptions::default(), &NoProgress).unwrap();
    let exemplar = model
        .exemplar()
        .expect("the leather keeps an exemplar")
        .clone();
    let chosen = exemplar.coarse;
    let mut parts = model.clone().into_parts();
    parts.exemplar = Some(Exemplar {
        coarse: match chosen {
            CoarseSource::Laid => CoarseSource::Mrf,
            CoarseSource::Mrf => CoarseSource::Laid,
        },
        light_weights: None,
        ..exemplar
    });
    let other = MaterialModel::new(parts).unwrap();
    let view = Direction::new(0.0, 0.0);
    let mut log_ratios = Vec::new();
    for (theta, phi) in [(30.0, 90.0), (45.0, 160.0), (60.0, 90.0), (75.0, 45.0)] {
        let light = Direction::new(theta, phi);
        let l = btf.lights().find(&light, 0.5).unwrap();
        let y = Yardstick::new(&btf.image(0, l).unwrap(), None, 1).unwrap();
        for seed in [2, 3] {
            let o = SynthesisOptions {
                rows: 128,
                cols: 128,
                seed,
                tileable: false,
            };
            let structure = |m: &MaterialModel| {
                let image = m.synthesize_image(&view, &light, &o).unwrap();
                y.judge(&image).unwrap().judgement.structure
            };
            log_ratios.push((structure(&model) / structure(&other)).ln());
        }
    }
    let ratio = (log_ratios.iter().sum::<f64>() / log_ratios.len() as f64).exp();
    println!(
        "leather, {chosen:?} over the other coarse variation: structure x{ratio:.3} (geometric mean)"
    );
    assert!(ratio < 1.0, "{ratio}");
}

/// Issue 11: a capture larger than 128^2 kept its range map averaged down to 128 samples a
/// side and no exemplar, so its enlargement was filtered noise with a relief (the built-in
/// sponge at 256^2, enlarged to 1024^2 at light 45/0: x2.93 the another-crop level, where
/// `texture-synthesis` reached x1.02). Then the map kept its centred 128^2 window at every
/// pixel, with the exemplar cut there; but the built-in stones at 256^2 are larger than that
/// window's quilt patches, which cut them into blocks. Now analysis keeps the whole capture,
/// averaged, where the relief varies more at the scales a window's patches cut through than
/// finer than the averaged samples (`choose_layout`'s unit test: the leather keeps the
/// window). Here the stones at 256^2 (8 clusters, nine frontal lights, synthesized at twice the
/// side): the layout chosen (whole) against the window; measured when written: x1.57 against
/// x2.97 the another-crop level (geometric means; 0.53 of it).
#[test]
fn a_capture_larger_than_the_window_keeps_its_structures_whole_with_its_relief() {
    let side = 256;
    let stones = Btf::synthetic(SyntheticMaterial::Stones, side, 5).unwrap();
    let another = Btf::synthetic(SyntheticMaterial::Stones, side, 6).unwrap();
    let model = |exemplar_side: Option<usize>, relief_layout| {
        let options = AnalysisOptions {
            clusters: 8,
            exemplar_side,
            relief_layout,
            ..AnalysisOptions::default()
        };
        analyze(&stones, &options, &NoProgress).unwrap().0
    };
    let chosen = model(None, None);
    let window = model(None, Some(ReliefLayout::Window));
    let map = chosen.range_map().expect("a range map");
    assert_eq!((map.step, map.rows, map.cols), (2, 128, 128));
    let exemplar = chosen.exemplar().expect("an exemplar beside the whole map");
    assert_eq!((exemplar.step, exemplar.rows, exemplar.cols), (2, 128, 128));
    let map = window.range_map().expect("a range map");
    assert_eq!((map.step, map.rows, map.cols), (1, 128, 128));
    let exemplar = window.exemplar().expect("an exemplar beside the window");
    assert_eq!((exemplar.step, exemplar.rows, exemplar.cols), (1, 128, 128));
    // An exemplar side asked for below the window would shrink the relief to it: the map
    // stays whole and no exemplar is cut.
    let small = model(Some(64), None);
    assert!(small.range_map().expect("a range map").step > 1);
    assert!(small.exemplar().is_none());
    let ratio = common::judged_ratio(
        &stones,
        &another,
        [&chosen, &window],
        ["whole", "window"],
        2,
    );
    println!("whole over window: {ratio:.3}");
    assert!(ratio < 0.85, "whole over window {ratio:.3}");
}

#[test]
fn every_light_brings_its_own_exemplar_detail() {
    // A cluster shares one subspace image among lights whose cast shadows and highlights
    // differ (the built-in sponge's 15/120 light is represented by 15/0 and others); each
    // light's own weights on the exemplar's deviations bring its own detail back.
    let side = 128;
    let sponge = Btf::synthetic(SyntheticMaterial::Sponge, side, 5).unwrap();
    let another = Btf::synthetic(SyntheticMaterial::Sponge, side, 6).unwrap();
    let model = |light_weights: bool| {
        let options = AnalysisOptions {
            clusters: 8,
            light_weights,
            ..AnalysisOptions::default()
        };
        analyze(&sponge, &options, &NoProgress).unwrap().0
    };
    let (own, shared) = (model(true), model(false));
    let weights = own.exemplar().and_then(|e| e.light_weights.as_ref());
    assert_eq!(
        weights.map(|w| w.weights.len()),
        Some(sponge.lights().len())
    );
    assert!(shared.exemplar().is_some_and(|e| e.light_weights.is_none()));
    let ratio = common::judged_ratio(&sponge, &another, [&own, &shared], ["own", "shared"], 1);
    println!("own over shared: {ratio:.3}");
    assert!(ratio < 0.95, "own over shared {ratio:.3}");
}

#[test]
fn every_light_keeps_its_measured_band_spreads() {
    // The laid exemplar and the relit relief leave an image's L* detail bands off the
    // measured ones (the built-in leather's 4-16 px bands up to a quarter too strong, its
    // coarser ones weak); the light tables' band spreads bring them back at each light.
    let side = 128;
    let leather = Btf::synthetic(SyntheticMaterial::Leather, side, 5).unwrap();
    let another = Btf::synthetic(SyntheticMaterial::Leather, side, 6).unwrap();
    let options = AnalysisOptions {
        clusters: 8,
        ..AnalysisOptions::default()
    };
    let spread = analyze(&leather, &options, &NoProgress).unwrap().0;
    let tables = spread
        .light_lightness()
        .expect("light tables beside a range map");
    assert_eq!(
        tables.spreads.as_ref().map(Vec::len),
        Some(leather.lights().len())
    );
    let plain = {
        let mut parts = spread.clone().into_parts();
        if let Some(t) = &mut parts.light_lightness {
            t.spreads = None;
        }
        MaterialModel::new(parts).unwrap()
    };
    let ratio = common::judged_ratio(
        &leather,
        &another,
        [&spread, &plain],
        ["with", "without"],
        1,
    );
    // Mean |log| of each band's spread over the measured, over the nine lights.
    let bands = |image: &Array3<f32>| {
        let [l, _, _] = ColourSpace::Lab.planes(image);
        detail_spreads(&l, LIGHTNESS_BANDS)
    };
    let o = SynthesisOptions {
        rows: side as usize,
        cols: side as usize,
        seed: 1,
        tileable: false,
    };
    let view = *leather.views().get(0).unwrap();
    let band_error = [&spread, &plain].map(|m| {
        let mut error = 0.0;
        for (theta, phi) in JUDGED_LIGHTS {
            let light = Direction::new(theta, phi);
            let l = leather.lights().find(&light, 0.5).unwrap();
            let want = bands(&leather.image(0, l).unwrap());
            let have = bands(&m.synthesize_image(&view, &light, &o).unwrap());
            error += have
                .iter()
                .zip(&want)
                .map(|(h, w)| (h / w).ln().abs())
                .sum::<f64>();
        }
        error / (LIGHTNESS_BANDS * JUDGED_LIGHTS.len()) as f64
    });
    println!(
        "with over without: {ratio:.3}; band spreads off by {:.3} with, {:.3} without (mean |log|)",
        band_error[0], band_error[1]
    );
    // Measured: 0.038 against 0.054, and x0.966 (the final table match moves the bands a
    // little again).
    assert!(band_error[0] < 0.8 * band_error[1], "{band_error:?}");
    assert!(ratio < 0.98, "with over without {ratio:.3}");
}
