//! Local PCA and the PCA baselines, through the public API and the command line.

mod common;

use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, Direction};
use btfmrf::lpca::{LpcaModel, LpcaOptions, Method, format};
use btfmrf::progress::NoProgress;
use common::*;

fn options(method: Method, clusters: usize, components: usize) -> LpcaOptions {
    LpcaOptions {
        method,
        clusters,
        components,
        max_iterations: 10,
        tolerance: 1e-3,
        seed: 5,
        evaluate: true,
    }
}

#[test]
fn eight_clusters_beat_one_at_four_components() {
    let btf = Btf::synthetic(SyntheticMaterial::Stones, 32, 7).unwrap();
    let (m8, r8) = LpcaModel::fit(&btf, &options(Method::Lpca, 8, 4), &NoProgress).unwrap();
    let (m1, r1) = LpcaModel::fit(&btf, &options(Method::Lpca, 1, 4), &NoProgress).unwrap();
    assert_eq!((m8.clusters(), m1.clusters()), (8, 1));
    let (e8, e1) = (
        *r8.error_history.last().unwrap(),
        *r1.error_history.last().unwrap(),
    );
    assert!(
        e8 < 0.9 * e1,
        "squared error: 8 clusters {e8}, 1 cluster {e1}"
    );
    assert!(
        r8.mean_delta_e < r1.mean_delta_e,
        "ΔE: 8 clusters {}, 1 cluster {}",
        r8.mean_delta_e,
        r1.mean_delta_e
    );
    assert!(r8.psnr_db > r1.psnr_db);
    // The clustering never made the error worse.
    for w in r8.error_history.windows(2) {
        assert!(w[1] <= w[0] * 1.001, "{:?}", r8.error_history);
    }
    // The per-view curve averages to the mean (every view has the same number of lights).
    let curve: f64 = r8.per_view_delta_e.iter().sum::<f64>() / 81.0;
    assert!((curve - r8.mean_delta_e).abs() < 1e-9);
    // More components help the global baselines too.
    let (_, b2) = LpcaModel::fit(&btf, &options(Method::PcaBtf, 1, 2), &NoProgress).unwrap();
    let (_, b6) = LpcaModel::fit(&btf, &options(Method::PcaBtf, 1, 6), &NoProgress).unwrap();
    assert!(
        b6.mean_delta_e < b2.mean_delta_e,
        "{} vs {}",
        b6.mean_delta_e,
        b2.mean_delta_e
    );
}

#[test]
fn same_seed_same_bytes_and_files_round_trip() {
    let btf = Btf::synthetic(SyntheticMaterial::Knit, 16, 3).unwrap();
    let mut o = options(Method::Lpca, 6, 3);
    o.evaluate = false;
    let (a, _) = LpcaModel::fit(&btf, &o, &NoProgress).unwrap();
    let (b, _) = LpcaModel::fit(&btf, &o, &NoProgress).unwrap();
    assert_eq!(a.to_bytes(), b.to_bytes());
    o.seed = 6;
    let (c, _) = LpcaModel::fit(&btf, &o, &NoProgress).unwrap();
    assert_ne!(a.to_bytes(), c.to_bytes(), "the seed should matter");

    let dir = temp();
    for method in [Method::Lpca, Method::PcaBtf, Method::PcaRf] {
        o.method = method;
        let (m, _) = LpcaModel::fit(&btf, &o, &NoProgress).unwrap();
        let path = dir.path().join(format!("{}.lpca", method.name()));
        format::write(&m, &path).unwrap();
        let back = format::read(&path).unwrap();
        assert_eq!(back, m);
        assert_eq!(back.method(), method);
        // Measured directions reconstruct exactly; others blend their neighbours.
        let (v, l) = (&m.views().as_slice()[20], &m.lights().as_slice()[33]);
        assert_eq!(
            back.reconstruct_direction(v, l).unwrap(),
            m.reconstruct(20, 33).unwrap()
        );
        let between = back
            .reconstruct_direction(&Direction::new(20.0, 10.0), &Direction::new(50.0, 100.0))
            .unwrap();
        assert_eq!(between.dim(), (3, 16, 16));
        assert!(between.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
    // Nothing half-written is left beside the files.
    assert!(entries(dir.path()).iter().all(|e| !e.starts_with('.')));
}

/// 8-bit sRGB to CIE Lab (D65), written here independently of the library.
fn lab(rgb: [u8; 3]) -> [f64; 3] {
    let lin = rgb.map(|c| {
        let v = f64::from(c) / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    });
    let x = 0.4124564 * lin[0] + 0.3575761 * lin[1] + 0.1804375 * lin[2];
    let y = 0.2126729 * lin[0] + 0.7151522 * lin[1] + 0.0721750 * lin[2];
    let z = 0.0193339 * lin[0] + 0.1191920 * lin[1] + 0.9503041 * lin[2];
    let f = |t: f64| {
        if t > (6.0f64 / 29.0).powi(3) {
            t.cbrt()
        } else {
            t / (3.0 * (6.0f64 / 29.0).powi(2)) + 4.0 / 29.0
        }
    };
    let (fx, fy, fz) = (f(x / 0.95047), f(y), f(z / 1.08883));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

fn mean_delta_e(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let sum: f64 = a
        .pixels()
        .zip(b.pixels())
        .map(|(p, q)| {
            let (l1, l2) = (lab(p.0), lab(q.0));
            ((l1[0] - l2[0]).powi(2) + (l1[1] - l2[1]).powi(2) + (l1[2] - l2[2]).powi(2)).sqrt()
        })
        .sum();
    sum / f64::from(a.width() * a.height())
}

#[test]
fn reported_error_matches_an_independent_delta_e_of_a_synthesized_image() {
    let dir = temp();
    let zip = dir.path().join("stones.zip");
    ok(&[
        "generate",
        "stones",
        "--size",
        "32",
        "--out",
        s(&zip),
        "--quiet",
    ]);
    let model = dir.path().join("stones.lpca");
    let out = ok(&[
        "lpca",
        s(&zip),
        "--clusters",
        "8",
        "--components",
        "4",
        "--iterations",
        "6",
        "--out",
        s(&model),
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(report["method"], "lpca");
    assert_eq!(report["per_view_delta_e"].as_array().unwrap().len(), 81);
    let bytes = std::fs::metadata(&model).unwrap().len();
    assert_eq!(report["model_bytes"].as_u64().unwrap(), bytes);
    let ratio = report["raw_bytes"].as_f64().unwrap() / bytes as f64;
    assert!((report["compression_ratio"].as_f64().unwrap() - ratio).abs() < 1e-9);
    assert_eq!(report["raw_bytes"].as_u64().unwrap(), 81 * 81 * 32 * 32 * 3);

    let worst = &report["worst_image"];
    let direction = |t: &str, p: &str| {
        format!(
            "{},{}",
            worst[t].as_f64().unwrap(),
            worst[p].as_f64().unwrap()
        )
    };
    let png = dir.path().join("worst.png");
    ok(&[
        "synthesize",
        s(&model),
        "--view",
        &direction("view_theta", "view_phi"),
        "--light",
        &direction("light_theta", "light_phi"),
        "--out",
        s(&png),
    ]);
    let rebuilt = image::open(&png).unwrap().to_rgb8();
    // The same image in the input archive, decoded by the image crate directly.
    let (vt, vp, lt, lp) = (
        worst["view_theta"].as_f64().unwrap() as u32,
        worst["view_phi"].as_f64().unwrap() as u32,
        worst["light_theta"].as_f64().unwrap() as u32,
        worst["light_phi"].as_f64().unwrap() as u32,
    );
    let suffix = format!("tl{lt:03} pl{lp:03} tv{vt:03} pv{vp:03}.jpg");
    let members = read_zip(&zip);
    let (_, jpeg) = members.iter().find(|(n, _)| n.ends_with(&suffix)).unwrap();
    let input = image::load_from_memory(jpeg).unwrap().to_rgb8();
    let ours = mean_delta_e(&input, &rebuilt);
    let reported = worst["delta_e"].as_f64().unwrap();
    assert!(
        ours > 0.5,
        "a 4-component model should not be exact: {ours}"
    );
    assert!(
        (ours - reported).abs() <= 0.01 * reported,
        "independent ΔE {ours} vs reported {reported}"
    );

    // The magic bytes decide, not the extension; --size must match the model.
    let renamed = dir.path().join("model.btfm");
    std::fs::copy(&model, &renamed).unwrap();
    let again = dir.path().join("again.png");
    ok(&[
        "synthesize",
        s(&renamed),
        "--view",
        "0,0",
        "--light",
        "30,0",
        "--size",
        "32",
        "--out",
        s(&again),
    ]);
    let e = fails(&[
        "synthesize",
        s(&model),
        "--size",
        "64",
        "--view",
        "0,0",
        "--light",
        "0,0",
        "--out",
        s(&again),
    ]);
    assert!(e.contains("stones.lpca") && e.contains("size"), "{e}");
}

#[test]
fn broken_model_files_fail_with_one_line_naming_the_file() {
    let dir = temp();
    let btf = Btf::synthetic(SyntheticMaterial::Sponge, 8, 1).unwrap();
    let mut o = options(Method::PcaRf, 1, 2);
    o.evaluate = false;
    let (m, _) = LpcaModel::fit(&btf, &o, &NoProgress).unwrap();
    let bytes = m.to_bytes();
    let mut too_many = o;
    too_many.components = 5000;
    assert!(LpcaModel::fit(&btf, &too_many, &NoProgress).is_err());
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("truncated.lpca", bytes[..bytes.len() / 2].to_vec()),
        ("flipped.lpca", {
            let mut b = bytes.clone();
            let at = b.len() - 100;
            b[at] ^= 1;
            b
        }),
        ("huge.lpca", {
            let mut b = bytes.clone();
            b[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
            b
        }),
    ];
    let png = dir.path().join("x.png");
    for (name, b) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, b).unwrap();
        assert!(format::read(&path).is_err());
        let e = fails(&[
            "synthesize",
            s(&path),
            "--view",
            "0,0",
            "--light",
            "0,0",
            "--out",
            s(&png),
        ]);
        assert!(e.contains(name), "{e}");
    }
    assert!(!png.exists());
    // Bad parameters are errors, not panics.
    let dir2 = temp();
    let zip = dir2.path().join("k.zip");
    tiny_btf(&zip, 8, btfmrf::btf::ImageFormat::Png);
    let out = dir2.path().join("k.lpca");
    let e = fails(&["lpca", s(&zip), "--clusters", "1000", "--out", s(&out)]);
    assert!(e.contains("clusters"), "{e}");
    let e = fails(&["lpca", s(&zip), "--components", "0", "--out", s(&out)]);
    assert!(e.contains("components"), "{e}");
    assert!(!out.exists());
}
