//! Numerical edge cases: degenerate directions, extreme colours, the smallest tiles, flat
//! relief. Each must give finite, sensible numbers or a clear error, never NaN or a panic.

use btfmrf::btf::synthetic::{SyntheticBtf, SyntheticMaterial};
use btfmrf::btf::{Btf, Direction, DirectionSet, ImageSource};
use btfmrf::color::{
    Srgb8Encoder, delta_e76, lab_to_linear, linear_to_lab, linear_to_srgb, srgb_to_linear,
};

fn weights_ok(set: &DirectionSet, d: &Direction) {
    let w = set.interpolate(d).unwrap();
    let sum: f64 = w.iter().map(|x| x.weight).sum();
    assert!((sum - 1.0).abs() < 1e-9, "{d:?}: {w:?}");
    assert!(
        w.iter()
            .all(|x| x.weight.is_finite() && x.weight >= 0.0 && x.index < set.len())
    );
}

#[test]
fn interpolation_at_the_pole_the_horizon_and_below_it() {
    let bonn = DirectionSet::bonn();
    for d in [
        Direction::new(0.0, 0.0),
        Direction::new(0.0, 359.999),
        Direction::new(1e-12, 77.0),
        Direction::new(74.999, 7.5),
        Direction::new(75.0, 7.5),
        Direction::new(89.9, 200.0),
        Direction::new(90.0, 0.0),
        Direction::new(120.0, 45.0),
        Direction::new(180.0, 0.0),
        Direction::new(30.0, -720.0),
        Direction::new(30.0, 1e9),
    ] {
        weights_ok(&bonn, &d);
    }
    // Beyond the last ring the weights fall on ring-75 samples only.
    let w = bonn.interpolate(&Direction::new(89.0, 100.0)).unwrap();
    for x in w.iter().filter(|x| x.weight > 0.0) {
        assert_eq!(bonn.get(x.index).unwrap().theta_deg, 75.0);
    }
    assert!(
        bonn.interpolate(&Direction::new(f64::INFINITY, 0.0))
            .is_err()
    );
}

#[test]
fn degenerate_direction_sets() {
    // Two directions (collinear in projection) and three on a line: no triangles.
    let two = DirectionSet::new(vec![Direction::new(0.0, 0.0), Direction::new(30.0, 0.0)]).unwrap();
    weights_ok(&two, &Direction::new(20.0, 0.0));
    let line = DirectionSet::new(vec![
        Direction::new(10.0, 0.0),
        Direction::new(20.0, 0.0),
        Direction::new(30.0, 0.0),
    ])
    .unwrap();
    let w = line.interpolate(&Direction::new(19.0, 0.0)).unwrap();
    assert_eq!(w[0].index, 1);
    // Duplicated directions do not break the triangulation.
    let dup = DirectionSet::new(vec![
        Direction::new(0.0, 0.0),
        Direction::new(0.0, 90.0),
        Direction::new(40.0, 0.0),
        Direction::new(40.0, 120.0),
        Direction::new(40.0, 240.0),
    ])
    .unwrap();
    weights_ok(&dup, &Direction::new(20.0, 60.0));
    assert!(Direction::from_vector([1e-300, 0.0, 0.0]).is_none());
    assert!(Direction::from_vector([0.0, 0.0, -1.0]).unwrap().theta_deg == 180.0);
}

#[test]
fn colour_conversions_stay_finite_on_extreme_values() {
    for v in [0.0f32, 1e-30, -1e-30, -0.5, 1.0, 1e6, f32::MAX / 4.0] {
        // Decoding raises to the power 2.4, so only encoded values up to ~1e15 stay finite;
        // encoding and Lab must cope with any finite linear value.
        if v.abs() <= 1e6 {
            assert!(srgb_to_linear(v).is_finite(), "{v}");
        }
        assert!(linear_to_srgb(v).is_finite(), "{v}");
        let lab = linear_to_lab([v, v, v]);
        assert!(lab.iter().all(|c| c.is_finite()), "{v}: {lab:?}");
    }
    // Black and near-black: the linear part of Lab's cube root.
    assert_eq!(linear_to_lab([0.0; 3]), [0.0, 0.0, 0.0]);
    let tiny = lab_to_linear(linear_to_lab([1e-6, 2e-6, 5e-7]));
    assert!((tiny[1] - 2e-6).abs() < 1e-8, "{tiny:?}");
    // Saturated primaries round-trip through Lab.
    for rgb in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
        let back = lab_to_linear(linear_to_lab(rgb));
        assert!(delta_e76(linear_to_lab(back), linear_to_lab(rgb)) < 1e-3);
    }
    let enc = Srgb8Encoder::new();
    assert_eq!(enc.encode(f32::INFINITY), 255);
    assert_eq!(enc.encode(f32::NEG_INFINITY), 0);
}

#[test]
fn smallest_tiles_render_finite_non_negative_images() {
    for m in SyntheticMaterial::ALL {
        let btf = Btf::synthetic(m, 4, 9).unwrap();
        for (v, l) in [(0, 0), (80, 80), (80, 0), (0, 80), (45, 66)] {
            let im = btf.image(v, l).unwrap();
            assert!(
                im.iter().all(|x| x.is_finite() && *x >= 0.0),
                "{m} ({v},{l})"
            );
        }
    }
}

#[test]
fn lights_below_the_horizon_give_ambient_only_and_views_below_it_do_not_break() {
    let views =
        DirectionSet::new(vec![Direction::new(0.0, 0.0), Direction::new(90.0, 0.0)]).unwrap();
    let lights =
        DirectionSet::new(vec![Direction::new(100.0, 30.0), Direction::new(0.0, 0.0)]).unwrap();
    let s =
        SyntheticBtf::with_directions(SyntheticMaterial::Sponge, 16, 1, &views, &lights).unwrap();
    let dark = s.load(0, 0).unwrap();
    let lit = s.load(0, 1).unwrap();
    assert!(dark.iter().all(|x| x.is_finite()));
    assert!(
        dark.sum() < 0.1 * lit.sum(),
        "no direct light from below the horizon"
    );
    let grazing_view = s.load(1, 1).unwrap();
    assert!(grazing_view.iter().all(|x| x.is_finite() && *x >= 0.0));
}
