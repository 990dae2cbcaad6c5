//! Speed of the procedural BTF generator: all 81 x 81 Bonn images of a material.
//!
//! Run: `cargo bench --bench generate` (medians are in target/criterion/). The goal is
//! the 128x128 case, written as a zip of JPEGs, under 30 s on the 2-core machine.

use std::hint::black_box;
use std::time::Duration;

use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, ImageFormat, io};
use btfmrf::progress::NoProgress;
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use rayon::prelude::*;

/// Renders every image into memory (no encoding): the ray marching and shading alone.
fn render_all(material: SyntheticMaterial, size: u32) -> f32 {
    let btf = Btf::synthetic(material, size, 1).expect("valid size");
    let lights = btf.lights().len();
    (0..btf.image_count())
        .into_par_iter()
        .map(|i| btf.image(i / lights, i % lights).expect("renders")[[0, 0, 0]])
        .sum()
}

fn bench_generate(c: &mut Criterion) {
    let mut group = c.benchmark_group("generate_81x81");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20));
    for size in [32u32, 64, 128] {
        group.bench_with_input(
            BenchmarkId::new("render_stones", size),
            &size,
            |b, &size| b.iter(|| black_box(render_all(SyntheticMaterial::Stones, size))),
        );
    }
    let dir = tempfile::tempdir().expect("temporary folder");
    for material in [SyntheticMaterial::Stones, SyntheticMaterial::Knit] {
        group.bench_with_input(
            BenchmarkId::new(format!("zip_jpeg_{material}"), 128),
            &material,
            |b, &material| {
                b.iter(|| {
                    let btf = Btf::synthetic(material, 128, 1).expect("valid size");
                    let out = dir.path().join("bench.zip");
                    io::write_ubo2003(&btf, &out, ImageFormat::Jpeg { quality: 90 }, &NoProgress)
                        .expect("written");
                })
            },
        );
    }
    group.finish();
}

criterion_group!(benches, bench_generate);
criterion_main!(benches);
