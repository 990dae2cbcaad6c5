//! The texture judge (`eval::judge`) of images against a measured reference image:
//! `cargo run --release --example fidelity REFERENCE IMAGE...` prints the reference levels made
//! from REFERENCE (another crop, random phase, shuffled, blurred), then for each IMAGE its
//! structure distance, the same over the another-crop and random-phase levels, and its colour
//! distance (mean |Lab quantile difference|). Used by scripts/peers/texture_synthesis.sh.

use std::path::Path;

use btfmrf::eval::{Verdict, Yardstick};

fn line(name: &str, v: &Verdict) -> String {
    format!(
        "{name}: structure {:.4} (x{:.2} crop, x{:.2} random phase), colour {:.2} Lab, a* std {:.2}",
        v.judgement.structure,
        v.structure_vs_crop,
        v.structure_vs_random_phase,
        v.judgement.colour_lab,
        v.judgement.chroma_std[0]
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((reference, images)) = args.split_first() else {
        return Err("usage: fidelity REFERENCE IMAGE...".into());
    };
    let reference = btfmrf::btf::io::read_image(Path::new(reference))?;
    let yardstick = Yardstick::new(&reference, None, 1)?;
    for (name, v) in yardstick.levels().rows() {
        println!("{}", line(&format!("level: {name}"), &v));
    }
    for path in images {
        let image = btfmrf::btf::io::read_image(Path::new(path))?;
        println!("{}", line(path, &yardstick.judge(&image)?));
    }
    Ok(())
}
