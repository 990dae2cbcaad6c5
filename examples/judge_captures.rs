//! Real captures judged at six of their lights: the setup behind the RTI rows of
//! docs/BENCHMARKS.md (issue 11). Each capture (a folder with `dirs.lp`, or a photograph) is
//! analysed at 8 clusters (or `--clusters N`), and its 256^2 synthesis (seed 1, or `--seed N`) is judged
//! against the measured image at six lights spread over the capture's list; the reference
//! levels come from the measured image itself (`Yardstick::new`: another crop, random phase).
//! Prints one line per light and, per capture, the mean structure over the random-phase level
//! and over the another-crop level, and the mean colour distance.
//!
//! Run: `cargo run --release --example judge_captures -- CAPTURE... [--clusters N]
//! [--model KIND] [--seed N] [--no-lit-tables] [--no-light-tables] [--no-light-chroma] [--no-light-weights] [--exemplar N]`, e.g.
//! `../shared/data/rti/*`; `--exemplar N` sets the exemplar's side (0: none).

use btfmrf::analysis::{AnalysisOptions, analyze};
use btfmrf::btf::Btf;
use btfmrf::eval::Yardstick;
use btfmrf::progress::NoProgress;
use btfmrf::synthesis::SynthesisOptions;

/// Lights judged per capture.
const LIGHTS: usize = 6;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut captures = Vec::new();
    let mut options = AnalysisOptions {
        clusters: 8,
        ..AnalysisOptions::default()
    };
    let mut seed = 1;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seed" => seed = args.next().ok_or("--seed N")?.parse()?,
            "--clusters" => options.clusters = args.next().ok_or("--clusters N")?.parse()?,
            "--model" => options.kind = args.next().ok_or("--model KIND")?.parse()?,
            "--no-lit-tables" => options.lit_matching = false,
            "--no-light-tables" => options.light_tables = false,
            "--no-light-chroma" => options.light_chroma = false,
            "--no-light-weights" => options.light_weights = false,
            "--exemplar" => {
                options.exemplar_side = Some(args.next().ok_or("--exemplar N")?.parse()?)
            }
            path => captures.push(path.to_string()),
        }
    }
    let o = SynthesisOptions {
        rows: 256,
        cols: 256,
        seed,
        tileable: false,
    };
    for path in captures {
        let btf = Btf::open(&path)?;
        let (model, _) = analyze(&btf, &options, &NoProgress)?;
        let view = *btf.views().get(0).ok_or("no view")?;
        let cache = model.synthesis_cache(&o)?;
        let n = btf.lights().len();
        let picks: Vec<usize> = (0..LIGHTS.min(n)).map(|i| i * n / LIGHTS.min(n)).collect();
        let (mut vs_random, mut vs_crop, mut colour) = (0.0, 0.0, 0.0);
        for &l in &picks {
            let light = *btf.lights().get(l).ok_or("light")?;
            let measured = btf.image(0, l)?;
            let y = Yardstick::new(&measured, None, 1)?;
            let v = y.judge(&model.image_from_cache(&cache, &view, &light)?)?;
            let [cl, ca, cb] = v.judgement.colour_lab_channels;
            println!(
                "{path} light {l} ({:.0}/{:.0}): x{:.2} random phase, x{:.2} crop, colour {:.2} Lab (L* {cl:.2}, a* {ca:.2}, b* {cb:.2})",
                light.theta_deg,
                light.phi_deg,
                v.structure_vs_random_phase,
                v.structure_vs_crop,
                v.judgement.colour_lab
            );
            vs_random += v.structure_vs_random_phase;
            vs_crop += v.structure_vs_crop;
            colour += v.judgement.colour_lab;
        }
        let k = picks.len().max(1) as f64;
        println!(
            "{path} {} ({} bytes): x{:.2} the random-phase level, x{:.2} the crop level, {:.2} Lab (means over {} lights)",
            options.kind,
            btfmrf::model::format::to_bytes(&model).len(),
            vs_random / k,
            vs_crop / k,
            colour / k,
            picks.len()
        );
    }
    Ok(())
}
