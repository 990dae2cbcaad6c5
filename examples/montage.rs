//! Puts images side by side in one PNG (each scaled to the height of the tallest by pixel
//! repetition), for eyeballing synthesized images against measured ones.
//!
//! Run: `cargo run --release --example montage -- out.png a.png b.jpg c.exr ...`

use std::path::Path;

use btfmrf::btf::io;
use ndarray::{Array3, s};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (out, inputs) = args.split_first().ok_or("usage: montage OUT.png IN...")?;
    let images: Vec<Array3<f32>> = inputs
        .iter()
        .map(|p| io::read_image(Path::new(p)))
        .collect::<Result<_, _>>()?;
    let height = images.iter().map(|i| i.dim().1).max().ok_or("no inputs")?;
    let scaled: Vec<Array3<f32>> = images
        .iter()
        .map(|im| {
            let (_, h, w) = im.dim();
            let f = height / h;
            Array3::from_shape_fn((3, h * f, w * f), |(c, y, x)| im[[c, y / f, x / f]])
        })
        .collect();
    let gap = 4;
    let width: usize = scaled.iter().map(|i| i.dim().2 + gap).sum();
    let mut sheet = Array3::<f32>::ones((3, height, width));
    let mut x = 0;
    for im in &scaled {
        let (_, h, w) = im.dim();
        sheet.slice_mut(s![.., ..h, x..x + w]).assign(im);
        x += w + gap;
    }
    io::write_image(Path::new(out), &sheet)?;
    Ok(())
}
