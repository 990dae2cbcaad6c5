//! The texture-fidelity measure must rank textures the way people would: another crop of the
//! same material close; a blurred copy, a pixel-shuffled copy and a different material far.
//! Then it is used to check that synthesized images are statistically like measured ones.

use btfmrf::analysis::{AnalysisOptions, analyze};
use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, Direction};
use btfmrf::eval::texture_fidelity;
use btfmrf::model::ModelKind;
use btfmrf::progress::NoProgress;
use btfmrf::synthesis::SynthesisOptions;
use ndarray::{Array3, s};
use rand::SeedableRng;
use rand::seq::SliceRandom;

fn blur(im: &Array3<f32>, radius: isize) -> Array3<f32> {
    let (_, h, w) = im.dim();
    Array3::from_shape_fn(im.dim(), |(c, y, x)| {
        let mut sum = 0.0;
        let mut n = 0.0;
        for dy in -radius..=radius {
            for dx in -radius..=radius {
                let (yy, xx) = (
                    (y as isize + dy).clamp(0, h as isize - 1),
                    (x as isize + dx).clamp(0, w as isize - 1),
                );
                sum += im[[c, yy as usize, xx as usize]];
                n += 1.0;
            }
        }
        sum / n
    })
}

fn shuffle(im: &Array3<f32>, seed: u64) -> Array3<f32> {
    let (_, h, w) = im.dim();
    let mut order: Vec<usize> = (0..h * w).collect();
    order.shuffle(&mut rand_pcg::Pcg64::seed_from_u64(seed));
    Array3::from_shape_fn(im.dim(), |(c, y, x)| {
        let k = order[y * w + x];
        im[[c, k / w, k % w]]
    })
}

#[test]
fn the_measure_ranks_crops_blur_shuffles_and_other_materials() {
    let images: Vec<Array3<f32>> = SyntheticMaterial::ALL
        .iter()
        .map(|&m| Btf::synthetic(m, 128, 2).unwrap().image(0, 20).unwrap())
        .collect();
    for (i, material) in SyntheticMaterial::ALL.iter().enumerate() {
        let a = images[i].slice(s![.., ..64, ..64]).to_owned();
        let b = images[i].slice(s![.., 64.., 64..]).to_owned();
        let same = texture_fidelity(&a, &b).score;
        let blurred = texture_fidelity(&a, &blur(&a, 2)).score;
        let shuffled = texture_fidelity(&a, &shuffle(&a, 1)).score;
        let nearest_other = (0..images.len())
            .filter(|&j| j != i)
            .map(|j| texture_fidelity(&a, &images[j].slice(s![.., ..64, ..64]).to_owned()).score)
            .fold(f64::INFINITY, f64::min);
        println!(
            "{material}: crop {same:.3}, blur {blurred:.3}, shuffle {shuffled:.3}, other material {nearest_other:.3}"
        );
        assert!(
            same < blurred && same < shuffled && same < nearest_other,
            "{material}"
        );
    }
}

/// Every model on every material: the synthesized image for a measured (view, light) must be
/// closer to the measured image than another material is. The printed table is the quality
/// report (`cargo test --release --test fidelity -- --nocapture`); a pixel-shuffled copy of
/// the measured image (perfect colours, no structure) is printed as a reference point.
#[test]
fn synthesized_images_are_statistically_like_the_measured_ones() {
    let (v, l) = (0, 20); // view straight down, light theta 45 phi 20
    for (i, &material) in SyntheticMaterial::ALL.iter().enumerate() {
        let btf = Btf::synthetic(material, 64, 5).unwrap();
        let other = Btf::synthetic(SyntheticMaterial::ALL[(i + 1) % 4], 64, 5).unwrap();
        let (view, light) = (*btf.views().get(v).unwrap(), *btf.lights().get(l).unwrap());
        assert_eq!(light, Direction::new(45.0, 20.0));
        let measured = btf.image(v, l).unwrap();
        let wrong = texture_fidelity(&other.image(v, l).unwrap(), &measured).score;
        let shuffled = texture_fidelity(&shuffle(&measured, 3), &measured).score;
        for kind in ModelKind::ALL {
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
            let synth = model.synthesize_image(&view, &light, &o).unwrap();
            let f = texture_fidelity(&synth, &measured);
            println!(
                "{material} {kind}: colour {:.2}, structure {:.3}, score {:.3} (other material {wrong:.3}, shuffled {shuffled:.3})",
                f.colour, f.structure, f.score
            );
            assert!(
                f.score < wrong,
                "{material} {kind}: {} vs another material {wrong}",
                f.score
            );
        }
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
            if model.cluster_of(0, lights[i]) == model.cluster_of(0, lights[j]) {
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
