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
        assert!(m["analysis_seconds"].as_f64().unwrap() > 0.0, "{m}");
        assert!(m["synthesis_seconds"].as_f64().unwrap() > 0.0, "{m}");
        let fidelity = m["fidelity"].as_f64().unwrap();
        assert!(fidelity.is_finite() && fidelity >= 0.0, "{m}");
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

    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    for name in names {
        assert!(md.contains(&format!("| {name} |")), "table row for {name}");
        assert!(md.contains(&format!("**{name} ")), "verdict for {name}");
    }
    for plot in [
        "fidelity_vs_size.png",
        "fidelity_vs_time.png",
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
