//! The command line as a user drives it: generate, info, convert.

mod common;

use common::*;

#[test]
fn generate_writes_6561_bonn_named_jpegs_that_an_independent_reader_opens() {
    let dir = temp();
    let zip = dir.path().join("s.zip");
    let out = ok(&[
        "generate",
        "sponge",
        "--size",
        "32",
        "--out",
        s(&zip),
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(report["images"], 6561);

    // Read it back the way the btf-extractor package (Python) does: the angles sit at fixed
    // offsets from the end of each name ending in ".jpg"; decode with the image crate
    // directly, not through our reader.
    let members = read_zip(&zip);
    assert_eq!(members.len(), 6561);
    let mut angles = std::collections::HashSet::new();
    for (name, bytes) in &members {
        assert!(name.ends_with(".jpg"), "{name}");
        let n = name.len();
        let field = |a: usize, b: usize| name[n - a..n - b].parse::<u32>().unwrap();
        let key = (field(25, 22), field(19, 16), field(13, 10), field(7, 4));
        assert!(angles.insert(key), "duplicate {key:?}");
        assert!([0, 15, 30, 45, 60, 75].contains(&key.0) && key.1 < 360);
        let img = image::load_from_memory(bytes).unwrap();
        assert_eq!((img.width(), img.height()), (32, 32));
    }
    assert_eq!(angles.len(), 6561);

    let info: serde_json::Value = serde_json::from_str(&ok(&["info", s(&zip), "--json"])).unwrap();
    assert_eq!(info["views"], 81);
    assert_eq!(info["lights"], 81);
    assert_eq!(info["width"], 32);
    assert_eq!(info["height"], 32);
    assert_eq!(info["images"], 6561);
    assert_eq!(info["raw_bytes"], 6561 * 32 * 32 * 3);
}

#[test]
fn generate_is_deterministic_in_its_seed() {
    let dir = temp();
    let run = |name: &str, seed: &str| {
        let p = dir.path().join(name);
        ok(&[
            "generate",
            "leather",
            "--size",
            "8",
            "--seed",
            seed,
            "--out",
            s(&p),
            "--format",
            "png",
        ]);
        std::fs::read(p).unwrap()
    };
    let (a, b, c) = (run("a.zip", "5"), run("b.zip", "5"), run("c.zip", "6"));
    assert_eq!(a, b, "same seed, same bytes");
    assert_ne!(a, c, "another seed, another material");
}

#[test]
fn generate_exports_the_ground_truth() {
    let dir = temp();
    let truth = dir.path().join("truth");
    ok(&[
        "generate",
        "stones",
        "--size",
        "16",
        "--out",
        s(&dir.path().join("x.zip")),
        "--truth",
        s(&truth),
    ]);
    let names = entries(&truth);
    for f in [
        "albedo.exr",
        "height.exr",
        "normals.exr",
        "shininess.exr",
        "specular.exr",
    ] {
        assert!(names.contains(&f.to_string()), "{names:?}");
    }
    let normals = btfmrf::btf::io::read_image(&truth.join("normals.exr")).unwrap();
    assert_eq!(normals.dim(), (3, 16, 16));
    assert!(
        normals
            .index_axis(ndarray::Axis(0), 2)
            .iter()
            .all(|&z| z > 0.0)
    );
    let height = btfmrf::btf::io::read_image(&truth.join("height.exr")).unwrap();
    let max = height.iter().copied().fold(0.0f32, f32::max);
    assert!(
        (max - 0.09 * 16.0).abs() < 1e-3,
        "stones relief is 9% of the tile: {max}"
    );
}

#[test]
fn info_reads_the_real_rti_sets() {
    for (set, lights, w, h) in [("clay-leaf", 48, 310, 310), ("loewenkopf", 240, 64, 43)] {
        let path = rti(set);
        let info: serde_json::Value =
            serde_json::from_str(&ok(&["info", &path, "--json"])).unwrap();
        assert_eq!(info["views"], 1, "{set}");
        assert_eq!(info["lights"], lights, "{set}");
        assert_eq!(
            (info["width"].clone(), info["height"].clone()),
            (w.into(), h.into())
        );
    }
    let human = ok(&["info", &rti("clay-leaf")]);
    assert!(human.contains("lights: 48"), "{human}");
}

#[test]
fn convert_between_zip_folder_exr_and_png() {
    let dir = temp();
    let zip = tiny_btf(&dir.path().join("a.zip"), 8, btfmrf::btf::ImageFormat::Png);
    let exr = dir.path().join("a-exr");
    ok(&[
        "convert",
        s(&zip),
        "--out",
        s(&exr),
        "--format",
        "exr",
        "--quiet",
    ]);
    let names = entries(&exr);
    assert_eq!(names.len(), 6561);
    assert!(names.iter().all(|n| n.ends_with(".exr")));
    let back = dir.path().join("b.zip");
    ok(&["convert", s(&exr), "--out", s(&back), "--format", "png"]);
    // PNG -> EXR -> PNG is lossless at 8 bits.
    let (a, b) = (read_zip(&zip), read_zip(&back));
    let decode = |bytes: &[u8]| image::load_from_memory(bytes).unwrap().to_rgb8().into_raw();
    for ((na, ba), (nb, bb)) in a.iter().zip(&b) {
        assert_eq!(na, nb);
        assert_eq!(decode(ba), decode(bb), "{na}");
    }
}

/// The light directions of a BTF or model as `info --json` reports them, (theta, phi) in
/// degrees.
fn lights_of(btf: &str) -> Vec<(f64, f64)> {
    let info: serde_json::Value = serde_json::from_str(&ok(&["info", btf, "--json"])).unwrap();
    assert_eq!(info["views"], 1, "{info}");
    info["light_directions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| {
            (
                d["theta_deg"].as_f64().unwrap(),
                d["phi_deg"].as_f64().unwrap(),
            )
        })
        .collect()
}

/// Light directions equal to within `tol` degrees, in order.
fn assert_same_lights(a: &[(f64, f64)], b: &[(f64, f64)], tol: f64) {
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x.0 - y.0).abs() <= tol && (x.1 - y.1).abs() <= tol,
            "light {i}: {x:?} vs {y:?}"
        );
    }
}

/// Issue 13 item 7: an RTI set, whose light angles are not whole degrees, is written as an
/// RTI capture (images and dirs.lp with the exact light vectors), zipped or as a folder, and
/// our reader opens both with the same lights and pixels.
#[test]
fn an_rti_set_converts_to_an_rti_zip_and_folder_and_reads_back() {
    use btfmrf::btf::Btf;
    let dir = temp();
    let set = rti("clay-leaf");
    let lights = lights_of(&set);
    assert!(lights.iter().any(|l| (l.0 - l.0.round()).abs() > 0.01));
    let original = Btf::open(&set).unwrap();
    for out in ["r.zip", "r-folder"] {
        let out = dir.path().join(out);
        ok(&[
            "convert",
            &set,
            "--out",
            s(&out),
            "--format",
            "png",
            "--quiet",
        ]);
        if out.is_dir() {
            let names = entries(&out);
            assert_eq!(names.len(), 49, "{names:?}");
            assert!(
                names.contains(&"dirs.lp".to_string()) && names.contains(&"047.png".to_string())
            );
        } else {
            let members = read_zip(&out);
            assert_eq!(members.len(), 49);
            assert_eq!(members.last().unwrap().0, "dirs.lp");
        }
        assert_same_lights(&lights_of(s(&out)), &lights, 1e-9);
        let back = Btf::open(&out).unwrap();
        assert_eq!((back.width(), back.height()), (310, 310));
        // JPEG decoded to linear and re-encoded as 8-bit PNG: the same 8-bit values.
        for l in [0, 17, 47] {
            let (a, b) = (original.image(0, l).unwrap(), back.image(0, l).unwrap());
            let worst = a
                .iter()
                .zip(b.iter())
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            assert!(worst < 1e-6, "light {l}: pixels differ by {worst}");
        }
    }
    // A whole-degree BTF keeps its UBO2003 names.
    let zip = tiny_btf(&dir.path().join("a.zip"), 8, btfmrf::btf::ImageFormat::Png);
    let again = dir.path().join("again.zip");
    ok(&["convert", s(&zip), "--out", s(&again), "--format", "png"]);
    let names: Vec<String> = read_zip(&again).into_iter().map(|m| m.0).collect();
    assert_eq!(names.len(), 6561);
    assert!(names[0].contains("tl000") && !names.iter().any(|n| n.ends_with(".lp")));
}

/// Issue 13 item 7: a model of an RTI set synthesizes the whole BTF (every measured light,
/// no --light) as an RTI zip that reads back with the model's lights.
#[test]
fn a_model_of_an_rti_set_synthesizes_a_whole_rti_zip() {
    let dir = temp();
    let set = rti("clay-leaf");
    let model = dir.path().join("leaf.btfm");
    ok(&[
        "analyze",
        &set,
        "--clusters",
        "4",
        "--out",
        s(&model),
        "--quiet",
    ]);
    let out = dir.path().join("leaf.zip");
    let report: serde_json::Value = serde_json::from_str(&ok(&[
        "synthesize",
        s(&model),
        "--size",
        "32",
        "--out",
        s(&out),
        "--json",
    ]))
    .unwrap();
    assert_eq!(report["images"], 48, "{report}");
    // The model stores its directions in single precision: exactly those come back.
    let written = lights_of(s(&out));
    assert_same_lights(&written, &lights_of(s(&model)), 1e-9);
    assert_same_lights(&written, &lights_of(&set), 1e-4);
    let info: serde_json::Value = serde_json::from_str(&ok(&["info", s(&out), "--json"])).unwrap();
    assert_eq!(
        (info["width"].clone(), info["height"].clone()),
        (32.into(), 32.into())
    );
}

#[test]
fn help_teaches() {
    let top = ok(&["--help"]);
    for word in ["generate", "info", "convert", "Examples"] {
        assert!(top.contains(word), "{top}");
    }
    let generate = ok(&["generate", "--help"]);
    for word in [
        "sponge", "knit", "stones", "leather", "--seed", "--truth", "Example",
    ] {
        assert!(generate.contains(word), "{generate}");
    }
}

/// Issue 13 item 8: an object on a background (the lion-head relief) is analysed, with a
/// warning that it is not a stationary texture; a texture gets no such warning. An oblique
/// view of a single-view model is synthesized with a warning that it is extrapolated.
#[test]
fn analyze_warns_when_the_input_is_not_a_stationary_texture() {
    let dir = temp();
    let run = |btf: &str, out: &str| {
        let out = btfmrf(&[
            "analyze",
            btf,
            "--clusters",
            "4",
            "--json",
            "--out",
            s(&dir.path().join(out)),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        (String::from_utf8_lossy(&out.stderr).into_owned(), report)
    };
    let (stderr, report) = run(&rti("loewenkopf"), "lion.btfm");
    assert!(
        stderr.contains("warning: the input does not look like a stationary texture"),
        "{stderr}"
    );
    assert_eq!(report["warnings"].as_array().unwrap().len(), 1, "{report}");
    // The relief was photographed from straight above only: an oblique view is extrapolated,
    // and synthesize says so; the measured view is not.
    let lion = dir.path().join("lion.btfm");
    let synthesize = |view: &str| {
        let out = btfmrf(&[
            "synthesize",
            s(&lion),
            "--size",
            "32",
            "--view",
            view,
            "--light",
            "45,90",
            "--out",
            s(&dir.path().join("lion.png")),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let stderr = synthesize("60,0");
    assert!(
        stderr.contains("warning: view 60,0 is 60 deg from the nearest measured view (0,0)"),
        "{stderr}"
    );
    assert!(!synthesize("0,0").contains("warning"));
    let knit = tiny_btf(&dir.path().join("k.zip"), 32, btfmrf::btf::ImageFormat::Png);
    let (stderr, report) = run(s(&knit), "knit.btfm");
    assert!(!stderr.contains("stationary"), "{stderr}");
    assert!(
        report["warnings"].as_array().unwrap().is_empty(),
        "{report}"
    );
}

/// `info` on a model file describes the model (its kind told by the first bytes).
#[test]
fn info_describes_a_model_file() {
    let model = repo().join("models/stones.btfm");
    let info: serde_json::Value =
        serde_json::from_str(&ok(&["info", s(&model), "--json"])).unwrap();
    assert_eq!(info["format"], "btfm", "{info}");
    assert_eq!(info["model"], "2dcar");
    assert_eq!(
        (info["views"].clone(), info["lights"].clone()),
        (81.into(), 81.into())
    );
    assert_eq!(
        (info["width"].clone(), info["height"].clone()),
        (128.into(), 128.into())
    );
    let text = ok(&["info", s(&model)]);
    assert!(
        text.contains("2dcar model (.btfm)") && text.contains("lights: 81"),
        "{text}"
    );
    // The optional parts, each with what it holds: on these frames analysis kept the colour
    // tables on the stones (judged at the byte budget) and on the leather, and left them out
    // of the sponge (models/README.md).
    let parts = |info: &serde_json::Value| -> Vec<String> {
        info["parts"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["part"].as_str().unwrap().to_string())
            .collect()
    };
    let every_part = [
        "colour tables",
        "lit tables",
        "light tables",
        "exemplar",
        "range map",
    ];
    assert_eq!(parts(&info), every_part, "{info}");
    let sponge = repo().join("models/sponge.btfm");
    let info: serde_json::Value =
        serde_json::from_str(&ok(&["info", s(&sponge), "--json"])).unwrap();
    assert_eq!(parts(&info), every_part[1..], "{info}");
    let leather = repo().join("models/leather.btfm");
    let info: serde_json::Value =
        serde_json::from_str(&ok(&["info", s(&leather), "--json"])).unwrap();
    assert_eq!(parts(&info), every_part, "{info}");
    let exemplar = &info["parts"][3];
    assert!(
        exemplar["holds"]
            .as_str()
            .is_some_and(|h| h.contains("coarse L* from the MRF")
                || h.contains("coarse L* from the laid crops")),
        "{info}"
    );
    assert!(
        exemplar["bytes"].as_u64().is_some_and(|b| b > 1000),
        "{info}"
    );
    let knit = ok(&["info", s(&repo().join("models/knit.btfm"))]);
    assert!(
        knit.contains("    lattice (") && knit.contains("coarse L* from the MRF"),
        "{knit}"
    );
    // The knit's period keeps more deviations than the 20 of format version 19, grey
    // (models/README.md).
    let lattice = knit
        .lines()
        .find(|l| l.trim_start().starts_with("lattice ("))
        .and_then(|l| l.split("(mean and ").nth(1));
    let deviations = lattice
        .filter(|rest| rest.contains(" grey deviations)"))
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse::<usize>().ok());
    assert!(deviations.is_some_and(|d| d > 20), "{knit}");
}
