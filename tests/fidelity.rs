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
