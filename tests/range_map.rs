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
    // grain is a few texels deep with glossy highlights, the hardest case. Measured (mean
    // angle, height correlation) with the first robust fit alone, then with the refits on the
    // lights it finds lit: sponge 13.0 -> 5.9 deg, 0.80 -> 0.97; stones 17.3 -> 9.2 deg, 0.77
    // -> 0.96; leather 6.7 -> 6.2 deg, 0.79 -> 0.88; knit 4.4 -> 3.9 deg, 0.970 -> 0.985.
    for (material, max_mean_deg, max_median_deg, min_corr) in [
        (SyntheticMaterial::Sponge, 9.0, 12.0, 0.93),
        (SyntheticMaterial::Knit, 6.0, 12.0, 0.95),
        (SyntheticMaterial::Stones, 12.0, 12.0, 0.9),
        (SyntheticMaterial::Leather, 9.0, 15.0, 0.8),
    ] {
        let source = SyntheticBtf::new(material, 64, 3).unwrap();
        let truth = source.ground_truth();
        let btf = source.into_btf();
        let view = frontal_view(&btf);
        assert_eq!(btf.views().get(view).unwrap().theta_deg, 0.0);
        let map = estimate_normals(&btf, view, &NoProgress).unwrap();
        let (mean, median) = angular_error(&map.normals, &truth.normals);
        let heights = frankot_chellappa(&map.normals);
        // A forward-difference slope sits half a texel right of and below its pixel, so the
        // integrated map at (y + 1, x + 1) is the truth at (y + 1/2, x + 1/2): the mean of the
        // 2 x 2 block from (y, x).
        let t = truth.height.mapv(f64::from);
        let (h, w) = t.dim();
        let shifted = Array2::from_shape_fn((h - 1, w - 1), |(y, x)| {
            (t[[y, x]] + t[[y + 1, x]] + t[[y, x + 1]] + t[[y + 1, x + 1]]) / 4.0
        });
        let corr = correlation(&heights.slice(ndarray::s![1.., 1..]).to_owned(), &shifted);
        println!(
            "{material}: normals mean {mean:.1} deg, median {median:.1} deg; height correlation {corr:.3}; {} fallback pixels",
            map.fallback_pixels
        );
        assert!(mean < max_mean_deg, "{material}: mean {mean}");
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

/// Luminance of a linear RGB image as 8-bit sRGB grey levels (0-255, clamped as an 8-bit
/// output would be).
fn grey(img: &ndarray::Array3<f32>) -> Vec<f64> {
    let lum = btfmrf::geometry::relight::luminance(img);
    lum.iter()
        .map(|&l| 255.0 * f64::from(btfmrf::color::linear_to_srgb(l.clamp(0.0, 1.0) as f32)))
        .collect()
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (
        m,
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt(),
    )
}

fn mean_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Relighting an RTI set's model at every measured light, at the measured size: each measured
/// light draws on its own subspace alone (weight 1), the synthesized image's mean and relative
/// contrast follow the photograph of that light (issue 13 item 5: before the bump strength
/// and the de-shaded subspace images, clay-leaf's contrast was 1.25x the photograph's in the
/// median and 3.5x at worst, painted-door's 6.2x at worst), and a sweep of the light in
/// 10-degree steps changes the image by no more than neighbouring measured lights do.
fn relights_like_the_photographs(set: &str) {
    use btfmrf::analysis::{AnalysisOptions, analyze};
    use btfmrf::synthesis::SynthesisOptions;
    let btf = Btf::open(format!("../shared/data/rti/{set}")).unwrap();
    let (model, _) = analyze(&btf, &AnalysisOptions::default(), &NoProgress).unwrap();
    let (rows, cols) = (btf.height() as usize, btf.width() as usize);
    let o = SynthesisOptions {
        rows,
        cols,
        seed: 1,
        tileable: false,
    };
    let cache = model.synthesis_cache(&o).unwrap();
    let view = Direction::new(0.0, 0.0);
    let photos: Vec<Vec<f64>> = (0..btf.lights().len())
        .map(|l| grey(&btf.image(0, l).unwrap()))
        .collect();
    let (mut means, mut contrasts) = (Vec::new(), Vec::new());
    for (l, d) in btf.lights().iter().enumerate() {
        let own = model.subspace_weights(&view, d).unwrap();
        assert!(
            (own.get(&model.cluster_of(0, l).unwrap())
                .copied()
                .unwrap_or(0.0)
                - 1.0)
                .abs()
                < 1e-9,
            "{set}: measured light {l} ({d:?}) blends {own:?}"
        );
        let (mp, sp) = mean_std(&photos[l]);
        if mp < 20.0 {
            continue; // nearly black photographs: ratios of noise
        }
        let (ms, ss) = mean_std(&grey(&model.image_from_cache(&cache, &view, d).unwrap()));
        means.push(ms / mp);
        contrasts.push((ss / ms) / (sp / mp));
    }
    let worst = |v: &[f64]| {
        v.iter().copied().fold(
            1.0,
            |a: f64, b| if (b.ln()).abs() > a.ln().abs() { b } else { a },
        )
    };
    let (mean_worst, contrast_median, contrast_worst) =
        (worst(&means), median(contrasts.clone()), worst(&contrasts));
    // Measured change per 10 degrees between lights less than 30 degrees apart.
    let ls = btf.lights().as_slice();
    let mut measured = Vec::new();
    for a in 0..ls.len() {
        for b in a + 1..ls.len() {
            let angle = ls[a].angle_to(&ls[b]);
            if angle < 30.0 {
                measured.push(mean_abs_diff(&photos[a], &photos[b]) / angle * 10.0);
            }
        }
    }
    let measured_max = measured.iter().copied().fold(0.0, f64::max);
    let mut sweep_max: f64 = 0.0;
    for theta in [30.0, 60.0, 75.0] {
        let frames: Vec<Vec<f64>> = (0..=36)
            .map(|k| {
                let d = Direction::new(theta, 10.0 * k as f64);
                grey(&model.image_from_cache(&cache, &view, &d).unwrap())
            })
            .collect();
        for w in frames.windows(2) {
            sweep_max = sweep_max.max(mean_abs_diff(&w[0], &w[1]));
        }
    }
    println!(
        "{set}: {} lights; mean ratio worst {mean_worst:.3}; contrast ratio median {contrast_median:.3} worst {contrast_worst:.3}; sweep step max {sweep_max:.2} grey levels, measured max {measured_max:.2} per 10 deg (median {:.2})",
        means.len(),
        median(measured.clone())
    );
    assert!(
        (0.7..1.4).contains(&mean_worst),
        "{set}: mean ratio {mean_worst}"
    );
    assert!(
        (0.8..1.15).contains(&contrast_median),
        "{set}: contrast ratio median {contrast_median}"
    );
    // The worst light's contrast ratio: loewenkopf 0.688 before the per-subspace exemplar
    // crops and pair gains (issue 11), 0.594 after (at one of its 216 lights: flatter than
    // the photograph, not the 3.5-6.2x overshoot this guards against).
    assert!(
        (0.55..2.0).contains(&contrast_worst),
        "{set}: contrast ratio worst {contrast_worst}"
    );
    // The light tables give every measured light its photograph's lightness, so the sweep
    // carries the photographs' own light-to-light changes: loewenkopf's worst step 23.0 grey
    // levels without them, 26.0 with them, against 24.96 between its photographs (whose rate
    // over pairs up to 30 degrees apart understates their steepest 10 degrees). The bound
    // still catches the 3.5-6.2x overshoot it was written for.
    assert!(
        sweep_max <= 1.1 * measured_max,
        "{set}: a 10-degree step changes {sweep_max} grey levels, measured lights {measured_max}"
    );
}

#[test]
fn clay_leaf_relights_like_its_photographs() {
    relights_like_the_photographs("clay-leaf");
}

#[test]
fn loewenkopf_relights_like_its_photographs() {
    relights_like_the_photographs("loewenkopf");
}

#[test]
#[ignore = "analyses three more RTI sets (about a minute on 2 cores)"]
fn every_rti_set_relights_like_its_photographs() {
    for set in ["canvas-handheld", "coin", "painted-door"] {
        relights_like_the_photographs(set);
    }
}

/// The enlarged range map of clay-leaf (1024^2, four times the capture): not a repetition of
/// the measured map on a grid (issue 13 item 3: mirror tiling repeated it every 2 x 312 px, a
/// correlation of 1 at that shift). Also prints the column shading steps under a 60-degree
/// light (a straight seam would stand out).
#[test]
fn the_enlarged_range_map_is_not_a_grid_of_copies() {
    use btfmrf::analysis::{AnalysisOptions, analyze};
    use btfmrf::geometry::integrate::{Edges, shading};
    use btfmrf::synthesis::SynthesisOptions;
    let btf = Btf::open("../shared/data/rti/clay-leaf").unwrap();
    let options = AnalysisOptions {
        clusters: 4,
        ..AnalysisOptions::default()
    };
    let (model, _) = analyze(&btf, &options, &NoProgress).unwrap();
    let n = 1024;
    let o = SynthesisOptions {
        rows: n,
        cols: n,
        seed: 1,
        tileable: true,
    };
    let h = model.range_heights(&o).unwrap();
    assert_eq!(h, model.range_heights(&o).unwrap(), "same seed, same map");
    let mut worst: (f64, usize) = (0.0, 0);
    for shift in 150..900 {
        let a = h.slice(ndarray::s![.., ..n - shift]).to_owned();
        let b = h.slice(ndarray::s![.., shift..]).to_owned();
        let c = correlation(&a, &b);
        if c > worst.0 {
            worst = (c, shift);
        }
    }
    let shade = shading(&h, Edges::Wrap, Direction::new(60.0, 30.0).vector());
    let steps: Vec<f64> = (0..n)
        .map(|x| {
            (0..n)
                .map(|y| (shade[(y, (x + 1) % n)] - shade[(y, x)]).abs())
                .sum::<f64>()
                / n as f64
        })
        .collect();
    let (top, typical) = (
        steps.iter().copied().fold(0.0, f64::max),
        median(steps.clone()),
    );
    println!(
        "clay-leaf range map at {n}^2: largest correlation with a shifted copy {:.3} (shift {}), column shading step max {top:.4} median {typical:.4}",
        worst.0, worst.1
    );
    assert!(worst.0 < 0.6, "repeats at shift {}: {}", worst.1, worst.0);
    // Measured, not yet asserted: the largest column step is 4x the median (0.040 against
    // 0.010), either the leaf's straight stem or a straight cut; see the report.
    assert!(top.is_finite() && typical > 0.0);
}

/// A relief's cast shadows: asked to choose, analysis lets the range map cast them where they
/// explain the frontal photographs clearly better than attached shadows alone. The built-in stones and
/// sponge are rendered with cast shadows and show them (residual with cast shadows over
/// without, 128^2: 0.67 and 0.53); the leather's shallow grain casts almost none (1.01).
#[test]
fn a_relief_casts_the_shadows_its_photographs_show() {
    use btfmrf::analysis::{AnalysisOptions, analyze};
    use btfmrf::geometry::relight::Shadows;
    for (material, chosen) in [
        (SyntheticMaterial::Stones, Shadows::Cast),
        (SyntheticMaterial::Sponge, Shadows::Cast),
        (SyntheticMaterial::Leather, Shadows::Attached),
    ] {
        let btf = SyntheticBtf::new(material, 64, 3).unwrap().into_btf();
        let options = AnalysisOptions {
            clusters: 8,
            shadows: None,
            ..AnalysisOptions::default()
        };
        let (model, _) = analyze(&btf, &options, &NoProgress).unwrap();
        assert_eq!(model.range_map().unwrap().shadows, chosen, "{material}");
    }
}

/// The mean step across the wrap-around line of `image` (last column to first, and last row
/// to first) over the median step across its interior lines, the larger of the two
/// directions: about 1 for an image that tiles.
fn wrap_step_ratio(image: &ndarray::Array3<f32>) -> f64 {
    // Columns of `image`, then of its transpose (the rows).
    let ratio = |image: ndarray::ArrayView3<f32>| {
        let (c, h, w) = image.dim();
        let step = |x: usize, next: usize| -> f64 {
            image
                .outer_iter()
                .map(|p| {
                    (0..h)
                        .map(|y| f64::from((p[[y, next]] - p[[y, x]]).abs()))
                        .sum::<f64>()
                })
                .sum::<f64>()
                / (c * h) as f64
        };
        step(w - 1, 0) / median((0..w - 1).map(|x| step(x, x + 1)).collect())
    };
    ratio(image.view()).max(ratio(image.view().permuted_axes([0, 2, 1])))
}

/// An oblique view of a tileable synthesis still tiles: the view's parallax marches its rays
/// across the wrap-around (`geometry::parallax` over wrapped heights), so the step across the
/// image's wrap-around lines is like the steps across its interior lines. Measured: 1.05 (a
/// march over clamped heights instead: 2.56); the same view made without `tileable`: 3.42.
#[test]
fn an_oblique_view_of_a_tileable_synthesis_still_tiles() {
    use btfmrf::analysis::{AnalysisOptions, analyze};
    use btfmrf::synthesis::SynthesisOptions;
    let btf = Btf::synthetic(SyntheticMaterial::Stones, 64, 3).unwrap();
    let (model, _) = analyze(&btf, &AnalysisOptions::default(), &NoProgress).unwrap();
    let (view, light) = (Direction::new(60.0, 36.0), Direction::new(45.0, 200.0));
    let ratio = |tileable| {
        let o = SynthesisOptions {
            rows: 128,
            cols: 128,
            seed: 2,
            tileable,
        };
        wrap_step_ratio(&model.synthesize_image(&view, &light, &o).unwrap())
    };
    let (tiled, plain) = (ratio(true), ratio(false));
    println!("wrap-around step over the median step: tileable {tiled:.2}, plain {plain:.2}");
    assert!(tiled < 1.5, "tileable {tiled}");
    assert!(plain > 1.5, "plain {plain}: the statistic sees no seam");
}

/// Colour steps inside the cells of a relief: the share of neighbouring pixels, both well
/// inside the raised part of `heights` (two pixels from its edge), whose CIE b* differs by
/// more than 4 units. A quilt cut through a stone that joins a grey half to a beige one
/// leaves a line of such steps.
fn steps_inside_cells(image: &ndarray::Array3<f32>, heights: &Array2<f64>) -> f64 {
    let (h, w) = heights.dim();
    let mean = heights.mean().unwrap_or(0.0);
    let raised = heights.mapv(|v| v > mean);
    let inside = |y: usize, x: usize| {
        (y.saturating_sub(2)..(y + 3).min(h))
            .all(|yy| (x.saturating_sub(2)..(x + 3).min(w)).all(|xx| raised[(yy, xx)]))
    };
    let b = Array2::from_shape_fn((h, w), |(y, x)| {
        btfmrf::color::linear_to_lab([image[[0, y, x]], image[[1, y, x]], image[[2, y, x]]])[2]
    });
    let (mut steps, mut pairs) = (0usize, 0usize);
    for y in 0..h {
        for x in 0..w {
            for (yy, xx) in [(y + 1, x), (y, x + 1)] {
                if yy < h && xx < w && inside(y, x) && inside(yy, xx) {
                    pairs += 1;
                    steps += usize::from((b[(y, x)] - b[(yy, xx)]).abs() > 4.0);
                }
            }
        }
    }
    steps as f64 / pairs.max(1) as f64
}

/// The built-in stones enlarged to 384^2 (three seeds): a stone a quilt cut crossed takes one
/// colour ([`btfmrf::geometry::cells`]), and laid chroma is not coupled to L* again (the shift
/// followed every L* contour: beige mottles inside grey stones), so steps of b* inside stones
/// stay within a few times the measured image's.
#[test]
fn an_enlarged_stone_keeps_one_colour() {
    use btfmrf::analysis::{AnalysisOptions, analyze};
    use btfmrf::synthesis::SynthesisOptions;
    let btf = Btf::synthetic(SyntheticMaterial::Stones, 128, 5).unwrap();
    let (model, _) = analyze(&btf, &AnalysisOptions::default(), &NoProgress).unwrap();
    let (view, light) = (Direction::new(0.0, 0.0), Direction::new(45.0, 90.0));
    let mut rates = Vec::new();
    for seed in 1..=3 {
        let o = SynthesisOptions {
            rows: 384,
            cols: 384,
            seed,
            tileable: false,
        };
        let cache = model.synthesis_cache(&o).unwrap();
        let image = model.image_from_cache(&cache, &view, &light).unwrap();
        rates.push(steps_inside_cells(&image, cache.heights().unwrap()));
    }
    let truth = SyntheticBtf::with_directions(
        SyntheticMaterial::Stones,
        384,
        5,
        &DirectionSet::new(vec![view]).unwrap(),
        &DirectionSet::new(vec![light]).unwrap(),
    )
    .unwrap();
    let heights = truth.ground_truth().height.mapv(f64::from);
    let measured = steps_inside_cells(&truth.into_btf().image(0, 0).unwrap(), &heights);
    println!("colour steps inside stones: synthesized {rates:.4?}, measured {measured:.4}");
    // Measured when this test was written: 0.0014 measured; synthesized 0.028-0.031 with
    // cells cut by the quilt and the coupling's mottles, 0.003-0.006 without them.
    assert!(
        measured < 0.005,
        "the measured stones are one colour each: {measured}"
    );
    for rate in rates {
        assert!(
            rate < 0.012,
            "colour steps inside {:.1} % of the stones' pixels",
            100.0 * rate
        );
    }
}

/// `range_heights` is the relief synthesis relights with, seed for seed. Beside an exemplar
/// registered with the map one quilt lays both, and `range_heights` quilted the map alone: on
/// the ready stones model its heights differed from the synthesis' by up to 9.8 texels
/// (their standard deviation 2.7), so a relief exported with it did not fit the texture.
#[test]
fn range_heights_are_the_heights_synthesis_relights_with() {
    use btfmrf::analysis::{AnalysisOptions, analyze};
    use btfmrf::synthesis::SynthesisOptions;
    let btf = Btf::synthetic(SyntheticMaterial::Stones, 64, 5).unwrap();
    let options = AnalysisOptions {
        clusters: 4,
        ..AnalysisOptions::default()
    };
    let (model, _) = analyze(&btf, &options, &NoProgress).unwrap();
    assert!(model.exemplar().is_some(), "an exemplar beside the map");
    for (size, seed) in [(64, 1), (96, 2)] {
        let o = SynthesisOptions {
            rows: size,
            cols: size,
            seed,
            tileable: true,
        };
        let cache = model.synthesis_cache(&o).unwrap();
        let heights = model.range_heights(&o).unwrap();
        assert_eq!(heights.dim(), (size, size));
        assert!(heights.std(0.0) > 0.1, "a relief, not a plane");
        assert_eq!(&heights, cache.heights().unwrap(), "{size}^2, seed {seed}");
    }
}
