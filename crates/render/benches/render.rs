//! Frame times of the renderer at 800 x 800: MRF bump mapping, MRF displacement mapping, and
//! a plain textured render of the same sphere (the ratio's baseline), then the ready stones
//! bump mapped with and without the pairs' finishes (light tables and each light's own
//! detail). Each frame includes the readback of the 800 x 800 float target. On a machine without a GPU this measures Mesa's
//! lavapipe (see docs/BENCHMARKS.md, "Rendering").

use std::hint::black_box;
use std::path::Path;

use btfmrf::btf::Direction;
use btfmrf::model::format;
use btfmrf::progress::NoProgress;
use btfmrf::synthesis::SynthesisOptions;
use btfmrf_render::lut::DirectionLut;
use btfmrf_render::mrf::{GpuMaterial, MaterialTables};
use btfmrf_render::pipeline::GpuMesh;
use btfmrf_render::plan::plan_scene;
use btfmrf_render::{Camera, Light, Mapping, MeshKind, Renderer, Scene};
use criterion::{Criterion, criterion_group, criterion_main};

fn frames(c: &mut Criterion) {
    let renderer = match Renderer::new() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("skipping the render benchmarks: {e}");
            return;
        }
    };
    eprintln!("adapter: {}", renderer.ctx.describe());
    let model = format::read(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/golden/sponge64.btfm"),
    )
    .expect("the golden model");
    let tile = SynthesisOptions {
        rows: 512,
        cols: 512,
        seed: 1,
        tileable: true,
    };
    let all: Vec<usize> = (0..model.subspaces().len()).collect();
    let cache = model.synthesis_cache_for(&all, &tile, &NoProgress).unwrap();
    let tables = MaterialTables::new(&model, &cache, None, &[], &NoProgress).unwrap();
    let material = GpuMaterial::new(&renderer.ctx, &renderer.mrf, &cache, &tables).unwrap();
    let scene = Scene {
        camera: Camera::orbit(Direction::new(30.0, 270.0), 3.2),
        light: Light {
            direction: Direction::new(45.0, 300.0),
            distance: Some(4.0),
        },
        width: 800,
        height: 800,
    };
    let coarse = GpuMesh::new(&renderer.ctx, &MeshKind::Sphere.build(64, 1.0).unwrap());
    let fine = GpuMesh::new(&renderer.ctx, &MeshKind::Sphere.build(384, 1.0).unwrap());
    let mut group = c.benchmark_group("render 800x800 sphere");
    group.sample_size(10);
    for (name, mapping, mesh) in [
        ("plain texture", Mapping::Plain, &coarse),
        ("mrf bump", Mapping::Bump, &coarse),
        ("mrf bump (384x192 grid)", Mapping::Bump, &fine),
        (
            "mrf displacement (384x192 grid)",
            Mapping::Displacement,
            &fine,
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| black_box(renderer.render(&material, mesh, &scene, mapping).unwrap()))
        });
    }
    // The ready stones on the coarse sphere: the clusters and finishes this scene plans.
    let stones =
        format::read(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/stones.btfm"))
            .expect("the ready stones");
    let luts = (
        DirectionLut::new(stones.views()).unwrap(),
        DirectionLut::new(stones.lights()).unwrap(),
    );
    let sphere = MeshKind::Sphere.build(64, 1.0).unwrap();
    let plan = plan_scene(&stones, &sphere, &scene, (&luts.0, &luts.1), (512, 512));
    let cache = stones
        .synthesis_cache_for(&plan.clusters, &tile, &NoProgress)
        .unwrap();
    for finishes in [&plan.finishes[..], &[]] {
        let tables = MaterialTables::new(&stones, &cache, None, finishes, &NoProgress).unwrap();
        let material = GpuMaterial::new(&renderer.ctx, &renderer.mrf, &cache, &tables).unwrap();
        let name = format!("mrf bump, ready stones, {} pair finishes", finishes.len());
        group.bench_function(name, |b| {
            b.iter(|| {
                black_box(
                    renderer
                        .render(&material, &coarse, &scene, Mapping::Bump)
                        .unwrap(),
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, frames);
criterion_main!(benches);
