//! The artefact sweep (issue 13): every model, plain and tileable, at several sizes and seeds,
//! on the real RTI captures and the built-in materials, synthesized through the public API and
//! checked by every detector of `eval::artefacts` against references calibrated on the
//! material's own measured images. The fast part runs by default; the whole sweep is ignored
//! (`cargo test --release --test sweep -- --ignored --nocapture`) and writes a per-detector
//! count table (`counts.md`, `counts.json`) and a contact sheet of every flagged image
//! (`flagged.png`: measured photograph left, synthesis right) to `target/sweep/`.
//!
//! `images_from_a_folder_are_checked` applies the same detectors to images another build
//! wrote (the "before" counts of issue 13), see its comment.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use btfmrf::analysis::{AnalysisOptions, analyze};
use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, Direction};
use btfmrf::eval::artefacts::{Detector, Finding, Reference};
use btfmrf::eval::montage::montage;
use btfmrf::model::ModelKind;
use btfmrf::progress::NoProgress;
use btfmrf::synthesis::SynthesisOptions;
use ndarray::Array3;

const RTI: [&str; 5] = [
    "clay-leaf",
    "painted-door",
    "canvas-handheld",
    "coin",
    "loewenkopf",
];

fn shared(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(path)
}

/// A material of the sweep: its measured frontal images (the calibration) and the lights the
/// syntheses are checked at.
struct Material {
    name: String,
    btf: Btf,
    /// Measured lights of the frontal view, directions.
    lights: Vec<Direction>,
    /// Measured frontal images, one per light.
    images: Vec<Array3<f32>>,
    reference: Reference,
    /// Indices (into `lights`) checked: nearest the zenith, nearest 45 degrees, the lowest.
    checked: Vec<usize>,
}

impl Material {
    fn new(name: &str, btf: Btf) -> Self {
        let lights: Vec<Direction> = (0..btf.lights().len())
            .map(|l| *btf.lights().get(l).unwrap())
            .collect();
        let images: Vec<Array3<f32>> = (0..lights.len())
            .map(|l| btf.image(0, l).unwrap())
            .collect();
        let refs: Vec<&Array3<f32>> = images.iter().collect();
        let reference = Reference::calibrate(&refs, &lights);
        let nearest = |theta: f64| {
            (0..lights.len())
                .min_by(|&a, &b| {
                    (lights[a].theta_deg - theta)
                        .abs()
                        .total_cmp(&(lights[b].theta_deg - theta).abs())
                })
                .unwrap()
        };
        let mut checked = vec![nearest(0.0), nearest(45.0), nearest(90.0)];
        checked.dedup();
        Self {
            name: name.to_string(),
            btf,
            lights,
            images,
            reference,
            checked,
        }
    }

    fn rti(set: &str) -> Self {
        Self::new(set, Btf::open(shared(&format!("rti/{set}"))).unwrap())
    }

    /// A built-in material, 64^2, lights of the frontal view only (the Bonn sampling's 81).
    fn built_in(material: SyntheticMaterial) -> Self {
        Self::new(
            &material.to_string(),
            Btf::synthetic(material, 64, 5).unwrap(),
        )
    }
}

/// One synthesis setting.
#[derive(Clone, Copy)]
struct Case {
    tileable: bool,
    size: usize,
    seed: u64,
}

/// One checked image.
struct Checked {
    label: String,
    findings: Vec<Finding>,
    /// Thumbnails (measured, synthesized) of a flagged image.
    flagged: Option<(Array3<f32>, Array3<f32>)>,
}

/// The sweep's tally: checked images and flags per detector, and the flagged images.
#[derive(Default)]
struct Tally {
    checked: BTreeMap<Detector, usize>,
    flags: BTreeMap<Detector, usize>,
    /// Worst value over limit per detector, with its label.
    worst: BTreeMap<Detector, (f64, String)>,
    flagged: Vec<Checked>,
}

impl Tally {
    fn add(&mut self, mut c: Checked) {
        let mut any = false;
        for f in &c.findings {
            *self.checked.entry(f.detector).or_default() += 1;
            let ratio = f.value / f.limit;
            let worst = self
                .worst
                .entry(f.detector)
                .or_insert((f64::NEG_INFINITY, String::new()));
            if ratio.is_nan() || ratio > worst.0 {
                *worst = (ratio, c.label.clone());
            }
            if f.flagged() {
                *self.flags.entry(f.detector).or_default() += 1;
                any = true;
                println!(
                    "FLAG {}: {} {:.4} > limit {:.4} (reference {:.4})",
                    c.label, f.detector, f.value, f.limit, f.reference
                );
            }
        }
        if any {
            self.flagged.push(c);
        } else {
            c.flagged = None;
        }
    }

    fn total_flags(&self) -> usize {
        self.flags.values().sum()
    }

    fn table(&self) -> String {
        let mut md = String::from(
            "| detector | checked | flagged | worst value / limit | where |\n|---|---|---|---|---|\n",
        );
        for d in Detector::ALL {
            let (w, at) = self
                .worst
                .get(&d)
                .cloned()
                .unwrap_or((f64::NAN, "-".into()));
            md += &format!(
                "| {d} | {} | {} | {w:.2} | {at} |\n",
                self.checked.get(&d).copied().unwrap_or(0),
                self.flags.get(&d).copied().unwrap_or(0),
            );
        }
        md
    }

    /// Writes `counts.md`, `counts.json` and `flagged.png` (when anything was flagged; else
    /// an old sheet is removed) to `dir`.
    fn write(&self, dir: &Path, title: &str) {
        std::fs::create_dir_all(dir).unwrap();
        let mut md = format!("# {title}\n\n{}\n", self.table());
        if !self.flagged.is_empty() {
            md += "\n## Flagged images (contact sheet order: left to right, top to bottom)\n\n";
            for (i, c) in self.flagged.iter().enumerate() {
                let why: Vec<String> = c
                    .findings
                    .iter()
                    .filter(|f| f.flagged())
                    .map(|f| format!("{} {:.3} > {:.3}", f.detector, f.value, f.limit))
                    .collect();
                md += &format!("{}. {}: {}\n", i + 1, c.label, why.join(", "));
            }
        }
        std::fs::write(dir.join("counts.md"), md).unwrap();
        let json = serde_json::json!({
            "title": title,
            "detectors": Detector::ALL.iter().map(|d| serde_json::json!({
                "detector": d.name(),
                "factor": d.factor(),
                "floor": d.floor(),
                "checked": self.checked.get(d).copied().unwrap_or(0),
                "flagged": self.flags.get(d).copied().unwrap_or(0),
            })).collect::<Vec<_>>(),
            "flagged_images": self.flagged.iter().map(|c| c.label.clone()).collect::<Vec<_>>(),
        });
        std::fs::write(
            dir.join("counts.json"),
            serde_json::to_string_pretty(&json).unwrap(),
        )
        .unwrap();
        let pairs: Vec<&Array3<f32>> = self
            .flagged
            .iter()
            .filter_map(|c| c.flagged.as_ref())
            .flat_map(|(m, s)| [m, s])
            .collect();
        if pairs.is_empty() {
            // A sheet from an earlier run would read as this run's.
            let _ = std::fs::remove_file(dir.join("flagged.png"));
        } else {
            let rows: Vec<Vec<&Array3<f32>>> = pairs.chunks(8).map(<[_]>::to_vec).collect();
            let sheet = montage(&rows, 4);
            btfmrf::btf::io::write_image(&dir.join("flagged.png"), &sheet).unwrap();
        }
    }
}

/// A box-averaged copy at most 128 pixels a side, for the contact sheet.
fn thumbnail(image: &Array3<f32>) -> Array3<f32> {
    let (_, h, w) = image.dim();
    let f = h.max(w).div_ceil(128).max(1);
    let (th, tw) = (h / f, w / f);
    Array3::from_shape_fn((3, th.max(1), tw.max(1)), |(c, y, x)| {
        let mut sum = 0.0;
        for dy in 0..f {
            for dx in 0..f {
                sum += image[[c, (y * f + dy).min(h - 1), (x * f + dx).min(w - 1)]];
            }
        }
        sum / (f * f) as f32
    })
}

fn check_image(
    material: &Material,
    label: String,
    image: &Array3<f32>,
    light: usize,
    tileable: bool,
) -> Checked {
    let measured = &material.images[light];
    let findings = material.reference.check(image, measured, tileable);
    Checked {
        label,
        findings,
        flagged: Some((thumbnail(measured), thumbnail(image))),
    }
}

/// The light sweep: azimuth 0..350 in 10 degree steps at 45 degrees elevation.
fn sweep_lights() -> Vec<Direction> {
    (0..36)
        .map(|k| Direction::new(45.0, f64::from(k) * 10.0))
        .collect()
}

/// Analyses `material` with `kind`, synthesizes every case at every checked light (and a
/// light sweep at `sweep_size` when given), and adds every image's findings to `tally`.
fn sweep_material(
    material: &Material,
    kind: ModelKind,
    cases: &[Case],
    sweep_size: Option<usize>,
    tally: &mut Tally,
) {
    let options = AnalysisOptions {
        kind,
        ..AnalysisOptions::default()
    };
    let (model, _) = analyze(&material.btf, &options, &NoProgress).unwrap();
    let view = *material.btf.views().get(0).unwrap();
    for case in cases {
        let o = SynthesisOptions {
            rows: case.size,
            cols: case.size,
            seed: case.seed,
            tileable: case.tileable,
        };
        let cache = model.synthesis_cache(&o).unwrap();
        for &l in &material.checked {
            let image = model
                .image_from_cache(&cache, &view, &material.lights[l])
                .unwrap();
            let label = format!(
                "{} {kind} {} {}^2 seed {} light {l} (theta {:.0})",
                material.name,
                if case.tileable { "tileable" } else { "plain" },
                case.size,
                case.seed,
                material.lights[l].theta_deg
            );
            tally.add(check_image(material, label, &image, l, case.tileable));
        }
    }
    if let Some(size) = sweep_size {
        let o = SynthesisOptions {
            rows: size,
            cols: size,
            seed: 1,
            tileable: false,
        };
        let cache = model.synthesis_cache(&o).unwrap();
        let lights = sweep_lights();
        let frames: Vec<Array3<f32>> = lights
            .iter()
            .map(|light| model.image_from_cache(&cache, &view, light).unwrap())
            .collect();
        let finding = material.reference.check_sweep(&frames, &lights);
        let worst = frames
            .windows(2)
            .enumerate()
            .max_by(|a, b| {
                btfmrf::eval::artefacts::change(&a.1[0], &a.1[1])
                    .total_cmp(&btfmrf::eval::artefacts::change(&b.1[0], &b.1[1]))
            })
            .map_or(0, |(i, _)| i);
        tally.add(Checked {
            label: format!(
                "{} {kind} light sweep {size}^2 (worst step phi {}..{})",
                material.name,
                worst * 10,
                worst * 10 + 10
            ),
            findings: vec![finding],
            flagged: Some((thumbnail(&frames[worst]), thumbnail(&frames[worst + 1]))),
        });
    }
}

/// The default part: issue 13's first two reproductions at a small size on a real capture
/// (the clay relief: tileable 3D CAR, tileable and plain 2D CAR, and a light sweep), the
/// painted door's plain relief at its edges, and the two defects the whole sweep found on the built-in materials (off-chroma specks of the
/// independent colour factors, flagged on leather with every model; the GMRF's 2-pixel
/// barcode on the knit), every detector, zero flags.
#[test]
fn the_fast_sweep_flags_nothing() {
    let mut tally = Tally::default();
    let clay = Material::rti("clay-leaf");
    let small = |tileable| Case {
        tileable,
        size: 64,
        seed: 1,
    };
    sweep_material(&clay, ModelKind::Car3d, &[small(true)], None, &mut tally);
    sweep_material(
        &clay,
        ModelKind::Car2d,
        &[small(true), small(false)],
        Some(64),
        &mut tally,
    );
    // A plain synthesis's relief is cut from a larger torus: its normals must not wrap
    // around (with wrapped differences the painted door's edges came out at 16.9x the
    // interior's detail against a limit of 3.6).
    let door = Material::rti("painted-door");
    sweep_material(&door, ModelKind::Car2d, &[small(false)], None, &mut tally);
    let leather = Material::built_in(SyntheticMaterial::Leather);
    sweep_material(
        &leather,
        ModelKind::Car2d,
        &[small(false)],
        None,
        &mut tally,
    );
    let knit = Material::built_in(SyntheticMaterial::Knit);
    sweep_material(&knit, ModelKind::Gmrf, &[small(true)], None, &mut tally);
    println!("{}", tally.table());
    assert_eq!(tally.checked[&Detector::Seam], 18);
    assert_eq!(tally.total_flags(), 0, "{}", tally.table());
}

/// The whole sweep: 5 RTI sets and 4 built-in materials x 3 models x plain/tileable x sizes
/// 64 (seeds 1, 2), 256 and 1024 (seed 1) x 3 lights, plus a 36-frame light
/// sweep per material and model at 128^2. Writes `target/sweep/`.
#[test]
#[ignore = "tens of minutes on 2 cores: 27 analyses and 648 checked images up to 1024^2"]
fn the_whole_sweep_flags_nothing() {
    let mut cases = Vec::new();
    for tileable in [false, true] {
        for (size, seeds) in [(64, &[1u64, 2][..]), (256, &[1]), (1024, &[1])] {
            for &seed in seeds {
                cases.push(Case {
                    tileable,
                    size,
                    seed,
                });
            }
        }
    }
    let mut tally = Tally::default();
    let materials = RTI
        .iter()
        .map(|set| Material::rti(set))
        .chain(SyntheticMaterial::ALL.into_iter().map(Material::built_in));
    for material in materials {
        for kind in ModelKind::ALL {
            let start = std::time::Instant::now();
            sweep_material(&material, kind, &cases, Some(128), &mut tally);
            println!(
                "{} {kind}: {:.0} s, {} flags so far",
                material.name,
                start.elapsed().as_secs_f64(),
                tally.total_flags()
            );
            // Written after every model, so an interrupted sweep still leaves its counts.
            tally.write(
                &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/sweep"),
                "Artefact sweep",
            );
        }
    }
    println!("{}", tally.table());
    assert_eq!(tally.total_flags(), 0, "{}", tally.table());
}

/// Applies the detectors to images another build of btfmrf wrote (issue 13's "before"
/// counts): `BTFMRF_SWEEP_DIR` names a folder of linear EXR files called
/// `SET__MODEL__plain|tileable__SIZE__SEED__LIGHT.exr` (LIGHT the measured light's index in
/// the set's `.lp` file) and `SET__MODEL__sweep__K.exr` (frame K of the 36-frame light sweep
/// of [`sweep_lights`]); SET is a folder of `../shared/data/rti`. Writes its counts to
/// `target/sweep/before/`. Without the variable there is nothing to check and it returns.
#[test]
#[ignore = "needs BTFMRF_SWEEP_DIR: images written by another build"]
fn images_from_a_folder_are_checked() {
    let Some(dir) = std::env::var_os("BTFMRF_SWEEP_DIR") else {
        println!("BTFMRF_SWEEP_DIR is not set: nothing to check");
        return;
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "exr"))
        .collect();
    files.sort();
    let mut by_set: BTreeMap<String, Vec<(Vec<String>, PathBuf)>> = BTreeMap::new();
    for path in files {
        let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
        let parts: Vec<String> = stem.split("__").map(str::to_string).collect();
        by_set
            .entry(parts[0].clone())
            .or_default()
            .push((parts, path));
    }
    let mut tally = Tally::default();
    for (set, files) in by_set {
        let material = Material::rti(&set);
        let mut sweeps: BTreeMap<String, Vec<(usize, Array3<f32>)>> = BTreeMap::new();
        for (parts, path) in files {
            let image = btfmrf::btf::io::read_image(&path).unwrap();
            if parts[2] == "sweep" {
                let k: usize = parts[3].parse().unwrap();
                sweeps.entry(parts[1].clone()).or_default().push((k, image));
                continue;
            }
            let light: usize = parts[5].parse().unwrap();
            let label = format!(
                "{set} {} {} {}^2 seed {} light {light} (theta {:.0})",
                parts[1], parts[2], parts[3], parts[4], material.lights[light].theta_deg
            );
            tally.add(check_image(
                &material,
                label,
                &image,
                light,
                parts[2] == "tileable",
            ));
        }
        for (model, mut frames) in sweeps {
            frames.sort_by_key(|f| f.0);
            let lights: Vec<Direction> = frames.iter().map(|f| sweep_lights()[f.0]).collect();
            let images: Vec<Array3<f32>> = frames.into_iter().map(|f| f.1).collect();
            let finding = material.reference.check_sweep(&images, &lights);
            tally.add(Checked {
                label: format!("{set} {model} light sweep"),
                findings: vec![finding],
                flagged: Some((thumbnail(&images[0]), thumbnail(&images[1]))),
            });
        }
    }
    println!("{}", tally.table());
    tally.write(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/sweep/before"),
        "Artefact sweep of the images in BTFMRF_SWEEP_DIR",
    );
}
