//! `btfmrf bench`: every method on one BTF, its report, JSON and plots, driven as a user would.

mod common;

use btfmrf::btf::ImageFormat;
use common::{fails, ok, s, temp, tiny_btf};

#[test]
fn bench_writes_the_table_the_json_and_the_plots() {
    let dir = temp();
    let btf = tiny_btf(&dir.path().join("knit.zip"), 32, ImageFormat::Png);
    let out = dir.path().join("bench");
    let stdout = ok(&[
        "bench",
        s(&btf),
        "--out",
        s(&out),
        "--clusters",
        "4",
        "--synthesis-size",
        "64",
        "--fidelity-pairs",
        "3",
        "--lpca",
        "4x2",
        "--lpca",
        "1x2",
        "--pca-btf",
        "3",
        "--pca-rf",
        "2",
        "--json",
    ]);
    let printed: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON object");
    let written: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(printed, written, "stdout and report.json agree");

    let methods = written["methods"].as_array().expect("a list of methods");
    let names: Vec<&str> = methods
        .iter()
        .map(|m| m["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "gmrf", "2dcar", "3dcar", "lpca", "lpca", "pca-btf", "pca-rf"
        ],
        "every method, in order"
    );
    let raw = written["raw_bytes"].as_f64().unwrap();
    assert_eq!(raw, 81.0 * 81.0 * 32.0 * 32.0 * 3.0);
    for m in methods {
        let bytes = m["model_bytes"].as_f64().unwrap();
        assert!(bytes > 100.0, "{m}");
        let ratio = m["compression_ratio"].as_f64().unwrap();
        assert!((ratio - raw / bytes).abs() < 1e-6 * ratio, "{m}");
        // Reported as a number; a time is not asserted.
        assert!(
            m["analysis_seconds"].as_f64().is_some_and(f64::is_finite),
            "{m}"
        );
        assert!(
            m["synthesis_seconds"].as_f64().is_some_and(f64::is_finite),
            "{m}"
        );
        // The judge's figures, and the ratios are the structure over the levels.
        let structure = m["structure"].as_f64().unwrap();
        assert!(structure.is_finite() && structure > 0.0, "{m}");
        let vs_crop = m["structure_vs_crop"].as_f64().unwrap();
        let vs_rp = m["structure_vs_random_phase"].as_f64().unwrap();
        assert!(vs_crop > 0.0 && vs_rp > 0.0, "{m}");
        assert!(m["colour_lab"].as_f64().unwrap() >= 0.0, "{m}");
        assert_eq!(m["colour_lab_channels"].as_array().unwrap().len(), 3, "{m}");
        // MRF synthesis is a new sample: no pixelwise error; the PCA methods have one.
        let is_mrf = ["gmrf", "2dcar", "3dcar"].contains(&m["name"].as_str().unwrap());
        assert_eq!(m["mean_delta_e"].is_null(), is_mrf, "{m}");
    }
    // Local PCA: 4 clusters beat 1 at the same number of components (the paper's claim).
    let delta_e = |i: usize| methods[i]["mean_delta_e"].as_f64().unwrap();
    assert!(
        delta_e(3) < delta_e(4),
        "4x2 {} vs 1x2 {}",
        delta_e(3),
        delta_e(4)
    );
    assert_eq!(methods[3]["parameters"]["clusters"], 4);

    // The reference levels, as rows of the JSON and of the table.
    let levels: Vec<&str> = written["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        levels,
        [
            "measured",
            "another crop",
            "random phase",
            "shuffled",
            "blurred"
        ]
    );
    let level = |i: usize, key: &str| written["levels"][i][key].as_f64().unwrap();
    assert_eq!(level(0, "structure"), 0.0, "the reference against itself");
    assert!((level(1, "structure_vs_crop") - 1.0).abs() < 1e-9);
    assert!((level(2, "structure_vs_random_phase") - 1.0).abs() < 1e-9);

    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    for level in &levels {
        assert!(md.contains(&format!("| *{level}* |")), "level row {level}");
    }
    // The side-by-side sheet: measured + 7 methods of 32 px on top, 3 enlargements of 64 below.
    let sheet = image::open(out.join("sheet.png")).expect("a PNG sheet");
    assert_eq!(
        (sheet.width(), sheet.height()),
        (8 * 32 + 7 * 4, 32 + 4 + 64)
    );
    assert!(md.contains("(sheet.png)"), "report links the sheet");
    for name in names {
        assert!(md.contains(&format!("| {name} |")), "table row for {name}");
        assert!(md.contains(&format!("**{name} ")), "verdict for {name}");
    }
    for plot in [
        "structure_vs_size.png",
        "structure_vs_time.png",
        "delta_e_vs_size.png",
    ] {
        assert!(md.contains(plot), "report links {plot}");
        let img = image::open(out.join(plot)).expect("a PNG plot");
        assert_eq!(img.width(), 900);
    }

    // The folder exists now: a second run refuses it and leaves it as it was.
    let line = fails(&["bench", s(&btf), "--out", s(&out)]);
    assert!(line.contains("already exists"), "{line}");
    assert!(out.join("report.md").exists());
}
