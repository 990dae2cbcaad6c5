//! Puts images side by side in one PNG (each scaled to the height of the tallest by pixel
//! repetition), for eyeballing synthesized images against measured ones.
//!
//! Run: `cargo run --release --example montage -- out.png a.png b.jpg c.exr ...`

use std::path::Path;

use btfmrf::btf::io;
use btfmrf::eval::montage::montage;
use ndarray::Array3;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (out, inputs) = args
        .split_first()
        .filter(|(_, inputs)| !inputs.is_empty())
        .ok_or("usage: montage OUT.png IN...")?;
    let images: Vec<Array3<f32>> = inputs
        .iter()
        .map(|p| io::read_image(Path::new(p)))
        .collect::<Result<_, _>>()?;
    let sheet = montage(&[images.iter().collect()], 4);
    io::write_image(Path::new(out), &sheet)?;
    Ok(())
}
