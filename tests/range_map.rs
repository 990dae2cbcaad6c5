//! Photometric stereo and range maps against the synthetic materials' ground truth, and on the
//! real RTI sets (relighting the estimate and comparing with the photographs).

use btfmrf::btf::synthetic::{SyntheticBtf, SyntheticMaterial};
use btfmrf::btf::{Btf, Direction, DirectionSet};
use btfmrf::eval::correlation;
use btfmrf::geometry::{estimate_normals, frankot_chellappa, frontal_view};
use btfmrf::progress::NoProgress;
use ndarray::{Array2, Axis};

/// Mean and median angle between estimated and true normals, degrees.
fn angular_error(est: &ndarray::Array3<f64>, truth: &ndarray::Array3<f32>) -> (f64, f64) {
    let (_, h, w) = est.dim();
    let mut angles: Vec<f64> = (0..h * w)
        .map(|k| {
            let (y, x) = (k / w, k % w);
            let dot: f64 = (0..3)
                .map(|c| est[[c, y, x]] * f64::from(truth[[c, y, x]]))
                .sum();
            dot.clamp(-1.0, 1.0).acos().to_degrees()
        })
        .collect();
    angles.sort_by(f64::total_cmp);
    (
        angles.iter().sum::<f64>() / angles.len() as f64,
        angles[angles.len() / 2],
    )
}

#[test]
fn normals_and_heights_of_the_synthetic_materials() {
    // Thresholds set from measured results (printed below) with some margin; the leather's
    // grain is a few texels deep with glossy highlights, the hardest case.
    for (material, max_median_deg, min_corr) in [
        (SyntheticMaterial::Sponge, 12.0, 0.75),
        (SyntheticMaterial::Knit, 12.0, 0.75),
        (SyntheticMaterial::Stones, 12.0, 0.65),
        (SyntheticMaterial::Leather, 15.0, 0.5),
    ] {
        let source = SyntheticBtf::new(material, 64, 3).unwrap();
        let truth = source.ground_truth();
        let btf = source.into_btf();
        let view = frontal_view(&btf);
        assert_eq!(btf.views().get(view).unwrap().theta_deg, 0.0);
        let map = estimate_normals(&btf, view, &NoProgress).unwrap();
        let (mean, median) = angular_error(&map.normals, &truth.normals);
        let heights = frankot_chellappa(&map.normals);
        let corr = correlation(&heights, &truth.height.mapv(f64::from));
        println!(
            "{material}: normals mean {mean:.1} deg, median {median:.1} deg; height correlation {corr:.3}; {} fallback pixels",
            map.fallback_pixels
        );
        assert!(median < max_median_deg, "{material}: median {median}");
        assert!(corr > min_corr, "{material}: correlation {corr}");
    }
}

#[test]
fn relighting_the_rti_estimate_resembles_the_photographs() {
    for set in ["clay-leaf", "loewenkopf"] {
        let btf = Btf::open(format!("../shared/data/rti/{set}")).unwrap();
        let map = estimate_normals(&btf, 0, &NoProgress).unwrap();
        // Relight with the Lambertian model and compare with held-in photographs.
        let mut corrs = Vec::new();
        for l in (0..btf.lights().len()).step_by(btf.lights().len() / 8) {
            let d = btf.lights().get(l).unwrap();
            if d.theta_deg > 70.0 {
                continue;
            }
            let v = d.vector();
            let photo = btf.image(0, l).unwrap();
            let lum = (&photo.index_axis(Axis(0), 0) * 0.2126
                + &photo.index_axis(Axis(0), 1) * 0.7152
                + &photo.index_axis(Axis(0), 2) * 0.0722)
                .mapv(f64::from);
            let relit = Array2::from_shape_fn(lum.dim(), |(y, x)| {
                let ndl: f64 = (0..3).map(|c| map.normals[[c, y, x]] * v[c]).sum();
                map.albedo[[y, x]] * ndl.max(0.0)
            });
            corrs.push(correlation(&relit, &lum));
        }
        let mean = corrs.iter().sum::<f64>() / corrs.len() as f64;
        println!(
            "{set}: relit vs photographed correlation {mean:.3} over {} lights",
            corrs.len()
        );
        assert!(mean > 0.6, "{set}: {mean}");
    }
}

#[test]
fn too_few_or_grazing_lights_are_a_clear_error() {
    let views = DirectionSet::zenith();
    let grazing = DirectionSet::new(
        (0..8)
            .map(|k| Direction::new(85.0, 45.0 * k as f64))
            .collect(),
    )
    .unwrap();
    let btf = SyntheticBtf::with_directions(SyntheticMaterial::Knit, 16, 1, &views, &grazing)
        .unwrap()
        .into_btf();
    let e = estimate_normals(&btf, 0, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(e.contains("at least 3 lights"), "{e}");
    // Exactly three good lights still work.
    let three = DirectionSet::new(vec![
        Direction::new(30.0, 0.0),
        Direction::new(30.0, 120.0),
        Direction::new(30.0, 240.0),
    ])
    .unwrap();
    let btf = SyntheticBtf::with_directions(SyntheticMaterial::Knit, 16, 1, &views, &three)
        .unwrap()
        .into_btf();
    let map = estimate_normals(&btf, 0, &NoProgress).unwrap();
    assert!(map.normals.iter().all(|v| v.is_finite()));
}
