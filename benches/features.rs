//! Speed of the illumination-invariant features (issue 6): one 256 x 256 image, against the
//! two baselines of the recognition experiment.
//!
//! Run: `cargo bench --bench features` (medians in target/criterion/). Target from the issue:
//! one 256^2 image well under 100 ms.

use std::hint::black_box;

use btfmrf::btf::Btf;
use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::features::baselines::{colour_histogram, lbp_histogram};
use btfmrf::features::{FeatureOptions, extract};
use criterion::{Criterion, criterion_group, criterion_main};

fn bench_features(c: &mut Criterion) {
    let image = Btf::synthetic(SyntheticMaterial::Stones, 256, 1)
        .expect("valid size")
        .image(20, 30)
        .expect("renders");
    let options = FeatureOptions::default();
    let mut group = c.benchmark_group("features_256");
    group.bench_function("mrf", |b| {
        b.iter(|| extract(black_box(&image), &options).expect("finite image"))
    });
    group.bench_function("colour_histogram", |b| {
        b.iter(|| colour_histogram(black_box(&image)))
    });
    group.bench_function("lbp", |b| b.iter(|| lbp_histogram(black_box(&image))));
    group.finish();
}

criterion_group!(benches, bench_features);
criterion_main!(benches);
