//! `btfmrf demo`: the main job end to end, at a small size.

mod common;

use common::{fails, ok, s, temp};

#[test]
fn demo_writes_the_report_with_its_images_models_and_benchmark() {
    let dir = temp();
    let out = dir.path().join("demo");
    let stdout = ok(&[
        "demo",
        "--out",
        s(&out),
        "--material",
        "knit",
        "--size",
        "32",
        "--enlarge",
        "96",
        "--render-size",
        "64",
    ]);
    assert!(stdout.contains("report.md"), "{stdout}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    // Every image the report links exists and is a real image.
    let links: Vec<&str> = md
        .split("](")
        .skip(1)
        .filter_map(|rest| rest.split(')').next())
        .collect();
    assert!(links.len() >= 4 + 15, "{links:?}");
    let renders = links.iter().filter(|l| l.starts_with("renders/")).count();
    assert_eq!(
        renders, 15,
        "sphere and cloth x bump and displacement x 3 lights, and the LPCA sphere x 3 lights"
    );
    assert!(md.contains("| sphere | lpca |"), "{md}");
    // The benchmark's report is embedded one level down, without its own title.
    assert!(
        md.contains("## Speed against error\n\n81 views x 81 lights"),
        "{md}"
    );
    assert!(!md.contains("# Speed against error:"), "{md}");
    assert!(md.contains("(8 clusters x 4 components, tiled)"), "{md}");
    for link in &links {
        let path = out.join(link);
        assert!(path.exists(), "{link} is linked but missing");
        if link.ends_with(".png") {
            let image =
                btfmrf::btf::io::read_image(&path).unwrap_or_else(|e| panic!("{link}: {e}"));
            let lit = image.iter().filter(|&&x| x > 0.01).count();
            assert!(lit > image.len() / 100, "{link} is black");
        }
    }
    // The enlargement is seamless-sized (a multiple of the pyramid step) and at least as large
    // as asked; the comparison holds 3 lights x (measured + 3 models + LPCA).
    let big = image::open(out.join("enlarged-2dcar-96x96.png")).unwrap();
    assert_eq!((big.width(), big.height()), (96, 96));
    let sheet = image::open(out.join("comparison.png")).unwrap();
    assert_eq!(
        sheet.width(),
        5 * 64 + 4 * 6,
        "measured, 3 MRF models, LPCA"
    );
    assert_eq!(sheet.height(), 3 * 64 + 2 * 6);
    for model in [
        "gmrf.btfm",
        "2dcar.btfm",
        "3dcar.btfm",
        "lpca.lpca",
        "pca-btf.lpca",
        "pca-rf.lpca",
    ] {
        let m = out.join("models").join(model);
        let model = model.split('.').next().unwrap();
        assert!(std::fs::metadata(&m).unwrap().len() > 100, "{model}");
        assert!(md.contains(&format!("| {model} |")), "table row {model}");
    }
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("bench/report.json")).unwrap()).unwrap();
    assert_eq!(report["shape"], serde_json::json!([81, 81, 32, 32]));

    // An existing folder is refused and left alone.
    let line = fails(&["demo", "--out", s(&out), "--size", "32"]);
    assert!(line.contains("already exists"), "{line}");
    assert!(out.join("report.md").exists());
}
