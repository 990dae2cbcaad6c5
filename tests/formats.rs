//! Reading and writing BTFs through the library API: the real RTI sets, UBO2003 round trips in
//! every image format and both containers, lazy access.

mod common;

use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, Direction, DirectionSet, ImageFormat, io};
use btfmrf::progress::NoProgress;
use common::*;
use ndarray::Array3;

#[test]
fn real_rti_sets_open_with_unit_lights_and_sane_pixels() {
    for (set, lights, w, h) in [("clay-leaf", 48, 310, 310), ("loewenkopf", 240, 64, 43)] {
        let btf = Btf::open(format!("../shared/data/rti/{set}")).unwrap();
        assert_eq!(btf.views().len(), 1);
        assert_eq!(btf.views().get(0), Some(&Direction::new(0.0, 0.0)));
        assert_eq!(btf.lights().len(), lights);
        assert_eq!((btf.width(), btf.height()), (w, h));
        for l in [0, lights / 2, lights - 1] {
            let im = btf.image(0, l).unwrap();
            assert_eq!(im.dim(), (3, h as usize, w as usize));
            assert!(im.iter().all(|v| (0.0..=1.0).contains(v)));
            let mean = im.mean().unwrap();
            assert!(mean > 0.005, "{set} light {l} is black: {mean}");
        }
        // Lights far apart give different images (it is a relighting set, not one photo).
        let (a, b) = (btf.image(0, 0).unwrap(), btf.image(0, lights / 2).unwrap());
        let diff = (&a - &b).mapv(f32::abs).mean().unwrap();
        assert!(diff > 0.01, "{set}: {diff}");
    }
    // The .lp file itself opens the same set.
    let via_lp = Btf::open("../shared/data/rti/clay-leaf/dirs.lp").unwrap();
    assert_eq!(via_lp.lights().len(), 48);
}

#[test]
fn the_grazing_clay_leaf_light_is_kept_and_reported() {
    let btf = Btf::open("../shared/data/rti/clay-leaf").unwrap();
    let grazing = btf.lights().iter().filter(|d| d.theta_deg >= 90.0).count();
    assert!(grazing >= 1);
    assert!(
        btf.warnings().iter().any(|w| w.contains("horizon")),
        "{:?}",
        btf.warnings()
    );
}

#[test]
fn ubo2003_round_trips_in_every_format_and_container() {
    let dir = temp();
    let source = Btf::synthetic(SyntheticMaterial::Stones, 8, 2).unwrap();
    for (format, tolerance) in [
        (ImageFormat::Exr, 0.0),
        (ImageFormat::Png, 0.0045),
        (ImageFormat::Jpeg { quality: 95 }, 0.2),
    ] {
        for container in ["x.zip", "x-folder"] {
            let path = dir
                .path()
                .join(format!("{}-{container}", format.extension()));
            io::write_ubo2003(&source, &path, format, &NoProgress).unwrap();
            let back = Btf::open(&path).unwrap();
            assert_eq!(back.views(), source.views());
            assert_eq!(back.lights(), source.lights());
            assert_eq!((back.width(), back.height()), (8, 8));
            for (v, l) in [(0, 0), (40, 17), (80, 80)] {
                let (a, b) = (source.image(v, l).unwrap(), back.image(v, l).unwrap());
                // 8-bit formats clip highlights above 1; EXR keeps them.
                let expected = if format == ImageFormat::Exr {
                    a
                } else {
                    a.mapv(|x| x.min(1.0))
                };
                let err = (&expected - &b)
                    .mapv(f32::abs)
                    .fold(0.0f32, |m, &x| m.max(x));
                assert!(err <= tolerance, "{path:?} ({v},{l}): {err}");
            }
        }
    }
}

#[test]
fn in_memory_btfs_with_other_samplings_round_trip() {
    let views =
        DirectionSet::new(vec![Direction::new(0.0, 0.0), Direction::new(30.0, 90.0)]).unwrap();
    let lights = DirectionSet::new(vec![
        Direction::new(10.0, 0.0),
        Direction::new(20.0, 120.0),
        Direction::new(40.0, 240.0),
    ])
    .unwrap();
    let images: Vec<Array3<f32>> = (0..6)
        .map(|k| Array3::from_shape_fn((3, 5, 7), |(c, y, x)| (k * 10 + c + y + x) as f32 / 100.0))
        .collect();
    let btf = Btf::from_images(views.clone(), lights.clone(), images.clone()).unwrap();
    let dir = temp();
    let path = dir.path().join("odd.zip");
    io::write_ubo2003(&btf, &path, ImageFormat::Exr, &NoProgress).unwrap();
    let back = Btf::open(&path).unwrap();
    assert_eq!(back.views(), &views);
    assert_eq!(back.lights(), &lights);
    assert_eq!(back.image(1, 2).unwrap(), images[5]);
    // Bad in-memory input is refused.
    assert!(Btf::from_images(views.clone(), lights.clone(), images[..5].to_vec()).is_err());
    let mut nan = images.clone();
    nan[2][[0, 0, 0]] = f32::NAN;
    assert!(Btf::from_images(views, lights, nan).is_err());
}

#[test]
fn out_of_range_indices_are_errors() {
    let btf = Btf::synthetic(SyntheticMaterial::Knit, 4, 1).unwrap();
    assert!(btf.image(81, 0).is_err());
    assert!(btf.image(0, 81).is_err());
    assert_eq!(btf.raw_bytes(), 6561 * 4 * 4 * 3);
}
