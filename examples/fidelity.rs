//! Texture fidelity (`eval::metrics::texture_fidelity`) of images against a reference image:
//! `cargo run --release --example fidelity REFERENCE IMAGE...` prints the colour, structure and
//! overall score of each (0 is identical statistics). Used by scripts/peers/texture_synthesis.sh.

use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((reference, images)) = args.split_first() else {
        return Err("usage: fidelity REFERENCE IMAGE...".into());
    };
    let reference = btfmrf::btf::io::read_image(Path::new(reference))?;
    for path in images {
        let image = btfmrf::btf::io::read_image(Path::new(path))?;
        let f = btfmrf::eval::metrics::texture_fidelity(&reference, &image);
        println!(
            "{path}: colour {:.2}, structure {:.3}, score {:.3}",
            f.colour, f.structure, f.score
        );
    }
    Ok(())
}
