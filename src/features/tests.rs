//! Invariance proofs by experiment: a random per-channel gain leaves every feature unchanged,
//! a random regular 3x3 colour transform leaves the `ColourTransform` features unchanged, and
//! the quantities that are not invariant do change (so the tests can fail).

use nalgebra::{DMatrix, Matrix3};

use crate::mrf::BandModel;
use ndarray::Array3;
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;

use super::baselines::{colour_histogram, intersection_distance};
use super::recognition::relight;
use super::*;
use crate::btf::Btf;
use crate::btf::synthetic::SyntheticMaterial;
use crate::mrf::Car3dModel;

/// A full-rank colour texture: a 3D CAR sample with cross-channel terms, positive.
fn colour_field(size: usize, seed: u64) -> Array3<f32> {
    let model = Car3dModel {
        order: 2,
        a: vec![
            0.35, 0.05, 0.00, 0.02, 0.30, 0.05, 0.05, 0.00, 0.25, // (0,1)
            0.25, 0.00, 0.05, 0.05, 0.30, 0.00, 0.00, 0.05, 0.35, // (1,0)
            -0.10, 0.02, 0.00, 0.00, -0.05, 0.00, 0.02, 0.00, -0.08, // (1,1)
            0.05, 0.00, 0.00, 0.00, 0.08, 0.02, 0.00, 0.00, 0.05, // (1,-1)
        ],
        sigma: [1.0, 0.5, 0.2, 0.5, 1.0, 0.3, 0.2, 0.3, 0.8],
        mean: [0.0; 3],
    };
    let y = model.synthesize(size, size, seed, false);
    y.mapv(|v| (0.4 + 0.05 * v) as f32)
}

fn material_image() -> Array3<f32> {
    Btf::synthetic(SyntheticMaterial::Stones, 64, 3)
        .unwrap()
        .image(20, 30)
        .unwrap()
}

/// Largest `|a - b| / (1 + |a|)` over the features selected by `keep`.
fn worst(a: &Features, b: &Features, keep: impl Fn(Invariance) -> bool) -> (f64, String) {
    let options = FeatureOptions::default();
    let names = options.names();
    a.values
        .iter()
        .zip(&b.values)
        .zip(options.invariances())
        .zip(names)
        .filter(|(((_, _), inv), _)| keep(*inv))
        .map(|(((x, y), _), n)| ((x - y).abs() / (1.0 + x.abs()), n))
        .fold((0.0, String::new()), |m, v| if v.0 > m.0 { v } else { m })
}

fn transformed(image: &Array3<f32>, b: &Matrix3<f64>) -> Array3<f32> {
    let (_, h, w) = image.dim();
    Array3::from_shape_fn((3, h, w), |(k, r, c)| {
        (0..3)
            .map(|j| b[(k, j)] * image[[j, r, c]] as f64)
            .sum::<f64>() as f32
    })
}

fn random_gain(rng: &mut Pcg64Mcg) -> Matrix3<f64> {
    Matrix3::from_diagonal(&nalgebra::Vector3::from_fn(|_, _| {
        rng.random_range(0.2..=3.0)
    }))
}

fn random_regular(rng: &mut Pcg64Mcg) -> Matrix3<f64> {
    loop {
        let b = Matrix3::from_fn(|_, _| rng.random_range(-1.0..=1.0)) + Matrix3::identity();
        let s = b.singular_values();
        if s.min() > 0.2 * s.max() {
            return b;
        }
    }
}

#[test]
fn names_match_the_vector_and_the_documented_length() {
    let options = FeatureOptions::default();
    let f = extract(&colour_field(64, 1), &options).unwrap();
    assert_eq!(f.values.len(), options.len());
    assert_eq!(options.invariances().len(), options.len());
    // 4 levels x (eta (2 + d) + 1 + d + d eta) + 12 with eta = 4, d = 3.
    assert_eq!(options.len(), 4 * (4 * 5 + 1 + 3 + 12) + 12);
    let names = options.names();
    let unique: std::collections::HashSet<_> = names.iter().collect();
    assert_eq!(unique.len(), names.len());
    assert!(f.values.iter().all(|v| v.is_finite()));
}

#[test]
fn a_random_per_channel_gain_leaves_every_feature_unchanged() {
    let mut rng = Pcg64Mcg::seed_from_u64(11);
    for image in [colour_field(96, 2), material_image()] {
        let a = extract(&image, &FeatureOptions::default()).unwrap();
        for _ in 0..3 {
            let b = random_gain(&mut rng);
            let relit = transformed(&image, &b);
            let f = extract(&relit, &FeatureOptions::default()).unwrap();
            let (err, name) = worst(&a, &f, |_| true);
            assert!(err < 1e-4, "{name} moved by {err} under gain {b}");
            // ... while the colours themselves, and so the colour histogram, change.
            let moved = intersection_distance(&colour_histogram(&image), &colour_histogram(&relit));
            assert!(moved > 0.1, "colour histogram distance {moved}");
        }
    }
}

#[test]
fn a_random_regular_colour_transform_leaves_the_3d_car_invariants_unchanged() {
    let mut rng = Pcg64Mcg::seed_from_u64(12);
    let image = colour_field(96, 3);
    let a = extract(&image, &FeatureOptions::default()).unwrap();
    for _ in 0..3 {
        let b = random_regular(&mut rng);
        let f = extract(&transformed(&image, &b), &FeatureOptions::default()).unwrap();
        let (err, name) = worst(&a, &f, |i| i == Invariance::ColourTransform);
        assert!(err < 1e-4, "{name} moved by {err} under B = {b}");
        // The per-channel features are not invariant to mixing the channels: they move.
        let (moved, name) = worst(&a, &f, |i| i == Invariance::ChannelGain);
        assert!(
            moved > 1e-2,
            "{name} should move under a full B, moved {moved}"
        );
    }
}

#[test]
fn the_invariants_are_not_constants() {
    // Different materials give different 3D CAR invariants, by far more than rounding.
    let a = extract(&colour_field(96, 4), &FeatureOptions::default()).unwrap();
    let b = extract(&material_image(), &FeatureOptions::default()).unwrap();
    let (err, _) = worst(&a, &b, |i| i == Invariance::ColourTransform);
    assert!(err > 0.05, "{err}");
    // The trace of the left neighbour's matrix at level 0 recovers the model's (0.35+0.30+0.25).
    let names = FeatureOptions::default().names();
    let i = names.iter().position(|n| n == "L0.tr(0,1)").unwrap();
    let big = extract(&colour_field(256, 5), &FeatureOptions::default()).unwrap();
    assert!((big.values[i] - 0.9).abs() < 0.05, "{}", big.values[i]);
}

#[test]
fn a_grey_image_has_rank_one_colour_and_keeps_its_features_under_any_illuminant() {
    let stones = material_image();
    let grey = Array3::from_shape_fn(stones.dim(), |(_, r, c)| {
        (stones[[0, r, c]] + stones[[1, r, c]] + stones[[2, r, c]]) / 3.0
    });
    let a = extract(&grey, &FeatureOptions::default()).unwrap();
    let names = FeatureOptions::default().names();
    // Two of the three colour directions are absent: white-noise values.
    let share = |f: &Features, n: &str| f.values[names.iter().position(|m| m == n).unwrap()];
    assert_eq!(share(&a, "L0.innovation#1"), 1.0);
    assert_eq!(share(&a, "L0.innovation#2"), 1.0);
    assert!(share(&a, "L0.innovation#3") < 0.9);
    let mut rng = Pcg64Mcg::seed_from_u64(13);
    for _ in 0..3 {
        let b = random_regular(&mut rng).abs();
        let f = extract(&transformed(&grey, &b), &FeatureOptions::default()).unwrap();
        let (err, name) = worst(&a, &f, |_| true);
        assert!(err < 1e-4, "{name} moved by {err}");
    }
    // Stored at 8 bits, the relit copy is no longer exactly rank one; the features stay close.
    let b = Matrix3::from_diagonal(&nalgebra::Vector3::new(0.9, 0.6, 0.4));
    let f = extract(&relight(&grey, &b, true), &FeatureOptions::default()).unwrap();
    let (err, name) = worst(&a, &f, |i| i == Invariance::ColourTransform);
    assert!(err < 0.2, "{name} moved by {err}");
}

#[test]
fn one_imaginary_part_per_matrix_holds_the_complex_pair() {
    // A rotation-scaling block (eigenvalues 0.3 +- 0.4i) beside a real eigenvalue 0.5: the real
    // parts sorted descending, and the pair's |imaginary part| once (issue 13: three sorted
    // imaginary parts repeated it and ended in a zero that never varied).
    let a = DMatrix::from_row_slice(3, 3, &[0.3, -0.4, 0.0, 0.4, 0.3, 0.0, 0.0, 0.0, 0.5]);
    let (re, im) = super::invariants::sorted_eigenvalues(&a);
    for (got, want) in re.iter().zip([0.5, 0.3, 0.3]) {
        assert!((got - want).abs() < 1e-12, "{re:?}");
    }
    assert!((im - 0.4).abs() < 1e-12, "{im}");
    let (_, im) = super::invariants::sorted_eigenvalues(&DMatrix::identity(3, 3));
    assert_eq!(im, 0.0);
}
