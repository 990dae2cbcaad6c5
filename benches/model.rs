//! Speed of the MRF model: analysis of a generated 81 x 81 BTF at 128 x 128, synthesis of one
//! 1024 x 1024 BTF image (plain and tileable) and of all subspace images, one 1024 x 1024
//! enlargement of a photograph, and the band synthesizers alone.
//!
//! Run: `cargo bench --bench model` (medians in target/criterion/). Targets from the MRF issue:
//! analysis under 10 s, one 1024^2 image in 25 ms, all 20 subspaces at 1024^2 under 1 s.

#[path = "../crates/cli/src/allocator.rs"]
mod allocator;

use std::hint::black_box;
use std::time::Duration;

use btfmrf::analysis::{AnalysisOptions, analyze};
use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, Direction};
use btfmrf::model::{MaterialModel, ModelKind};
use btfmrf::mrf::{BandModel, Car2dModel, GmrfModel};
use btfmrf::progress::NoProgress;
use btfmrf::synthesis::SynthesisOptions;
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

/// The allocator of the `btfmrf` binary (crates/cli/src/main.rs), so that these figures are the
/// binary's.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn fitted(kind: ModelKind) -> MaterialModel {
    allocator::keep_freed_memory();
    let btf = Btf::synthetic(SyntheticMaterial::Sponge, 128, 1).expect("valid size");
    let options = AnalysisOptions {
        kind,
        ..AnalysisOptions::default()
    };
    analyze(&btf, &options, &NoProgress).expect("analysis").0
}

fn bench_analysis(c: &mut Criterion) {
    let mut group = c.benchmark_group("analyze_81x81_128");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(30));
    let btf = Btf::synthetic(SyntheticMaterial::Sponge, 128, 1).expect("valid size");
    for kind in ModelKind::ALL {
        group.bench_with_input(
            BenchmarkId::from_parameter(kind.name()),
            &kind,
            |b, &kind| {
                let options = AnalysisOptions {
                    kind,
                    ..AnalysisOptions::default()
                };
                b.iter(|| black_box(analyze(&btf, &options, &NoProgress).expect("analysis")))
            },
        );
    }
    group.finish();
}

fn bench_synthesis(c: &mut Criterion) {
    let mut group = c.benchmark_group("synthesize_1024");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(15));
    let o = SynthesisOptions {
        rows: 1024,
        cols: 1024,
        seed: 1,
        tileable: false,
    };
    let tiled = SynthesisOptions {
        tileable: true,
        ..o
    };
    for kind in ModelKind::ALL {
        let model = fitted(kind);
        // A measured pair: exactly one subspace image is needed.
        let (view, light) = (Direction::new(0.0, 0.0), Direction::new(45.0, 80.0));
        group.bench_function(BenchmarkId::new("one_image", kind.name()), |b| {
            b.iter(|| {
                black_box(
                    model
                        .synthesize_image(&view, &light, &o)
                        .expect("synthesis"),
                )
            })
        });
        // The same light from an oblique measured view: the relit image is warped by the
        // view's parallax and masking.
        let oblique = Direction::new(60.0, 36.0);
        group.bench_function(BenchmarkId::new("one_image_oblique", kind.name()), |b| {
            b.iter(|| {
                black_box(
                    model
                        .synthesize_image(&oblique, &light, &o)
                        .expect("synthesis"),
                )
            })
        });
        // The same image made tileable (the CAR models solved on the torus by the DFT).
        group.bench_function(BenchmarkId::new("one_image_tileable", kind.name()), |b| {
            b.iter(|| {
                black_box(
                    model
                        .synthesize_image(&view, &light, &tiled)
                        .expect("synthesis"),
                )
            })
        });
        // Every subspace image through one cache, as `render` and `synthesize` make them: the
        // bands' driving noise is drawn once and shared.
        let all: Vec<usize> = (0..model.subspaces().len()).collect();
        group.bench_function(BenchmarkId::new("all_subspaces", kind.name()), |b| {
            b.iter(|| {
                black_box(
                    model
                        .synthesis_cache_for(&all, &o, &NoProgress)
                        .expect("synthesis"),
                )
            })
        });
    }
    group.finish();
}

/// One 1024 x 1024 enlargement of a photograph (gravel.png, 2D CAR) with the structure
/// exemplar (the default: its quilt) and without it.
fn bench_photograph(c: &mut Criterion) {
    let mut group = c.benchmark_group("photograph_1024");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20));
    allocator::keep_freed_memory();
    let btf = Btf::open("../shared/data/textures/gravel.png").expect("the shared photograph");
    let o = SynthesisOptions {
        rows: 1024,
        cols: 1024,
        seed: 1,
        tileable: false,
    };
    let zenith = Direction::new(0.0, 0.0);
    for (name, exemplar_side) in [("exemplar", None), ("mrf_only", Some(0))] {
        let options = AnalysisOptions {
            exemplar_side,
            ..AnalysisOptions::default()
        };
        let model = analyze(&btf, &options, &NoProgress).expect("analysis").0;
        group.bench_function(name, |b| {
            b.iter(|| {
                black_box(
                    model
                        .synthesize_image(&zenith, &zenith, &o)
                        .expect("synthesis"),
                )
            })
        });
    }
    group.finish();
}

fn bench_bands(c: &mut Criterion) {
    let mut group = c.benchmark_group("band");
    group.sample_size(10);
    let car = Car2dModel {
        order: 5, // 12 neighbours, as in the performance anchor
        gamma: vec![
            0.3, 0.3, -0.1, 0.05, 0.05, 0.02, -0.02, 0.01, 0.01, -0.01, 0.01, 0.01,
        ],
        sigma2: 1.0,
        mean: 0.0,
    };
    group.bench_function("car2d_12_neighbours_4096", |b| {
        b.iter(|| black_box(car.synthesize(4096, 4096, 1, false)))
    });
    let gmrf = GmrfModel {
        order: 2,
        gamma: vec![0.2, 0.15, 0.05, -0.04],
        sigma2: 1.0,
        mean: 0.0,
    };
    group.bench_function("gmrf_1024", |b| {
        b.iter(|| black_box(gmrf.synthesize(1024, 1024, 1, true)))
    });
    group.finish();
}

criterion_group!(
    benches,
    bench_analysis,
    bench_synthesis,
    bench_photograph,
    bench_bands
);
criterion_main!(benches);
