//! A contact sheet of a synthetic material: rows are views, columns are lights.
//!
//! Run: `cargo run --release --example contact_sheet -- stones 128 sheet.png`
//! (arguments: material, tile size in texels, output PNG; defaults: stones 128 sheet.png).

use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, Direction, io};
use btfmrf::eval::montage::montage;
use ndarray::Array3;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let material: SyntheticMaterial = args.first().map_or("stones", String::as_str).parse()?;
    let size: u32 = args.get(1).map_or(Ok(128), |s| s.parse())?;
    let out = args.get(2).map_or("sheet.png", String::as_str);

    let btf = Btf::synthetic(material, size, 1)?;
    // (theta, phi) of the views (rows) and lights (columns), all Bonn directions.
    let views = [(0.0, 0.0), (45.0, 0.0), (75.0, 0.0)];
    let lights = [
        (0.0, 0.0),
        (45.0, 0.0),
        (45.0, 180.0),
        (75.0, 90.0),
        (75.0, 270.0),
    ];
    let find = |set: &btfmrf::btf::DirectionSet, (t, p): (f64, f64)| {
        set.find(&Direction::new(t, p), 0.01)
            .ok_or("not a Bonn direction")
    };
    let mut rows = Vec::new();
    for &v in &views {
        let mut row = Vec::new();
        for &l in &lights {
            row.push(btf.image(find(btf.views(), v)?, find(btf.lights(), l)?)?);
        }
        rows.push(row);
    }
    let rows: Vec<Vec<&Array3<f32>>> = rows.iter().map(|r| r.iter().collect()).collect();
    let sheet = montage(&rows, 4);
    io::write_image(std::path::Path::new(out), &sheet)?;
    println!("{out}: rows = views {views:?}, columns = lights {lights:?}");
    Ok(())
}
