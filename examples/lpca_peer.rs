//! Exports the data of the local-PCA peer check as `.npy` and times our LPCA on it.
//!
//! A generated 64 x 64 material (4096 texels) seen from every third Bonn view under every
//! third Bonn light (27 x 27 x RGB = 2187 values per texel, BRDF-wise), as float32. Writes
//! `DIR/data.npy` and prints one JSON line: our fit time (median of `RUNS` runs, the data
//! already in memory, as the peer times it) and the final mean squared reconstruction error
//! per texel vector, for K = 32 clusters, C = 8 components and exactly 10 iterations.
//!
//! Run: `cargo run --release --example lpca_peer -- DIR [RUNS] [SEED]`
//! (`scripts/peers/lpca_peer.sh` runs it beside the numpy reference.)

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, BtfError, DirectionSet, ImageSource};
use btfmrf::lpca::{FactorizationOptions, data, fit_rows};
use btfmrf::progress::NoProgress;
use ndarray::Array3;

/// Every `step`-th view and light of another BTF.
struct Subsampled {
    btf: Btf,
    step: usize,
}

impl ImageSource for Subsampled {
    fn load(&self, view: usize, light: usize) -> Result<Array3<f32>, BtfError> {
        self.btf.image(view * self.step, light * self.step)
    }

    fn describe(&self, view: usize, light: usize) -> String {
        self.btf.describe(view * self.step, light * self.step)
    }
}

/// Writes a 2D little-endian float32 array in the NumPy `.npy` format (version 1.0).
fn write_npy(path: &Path, rows: usize, cols: usize, data: &[f32]) -> std::io::Result<()> {
    let mut header =
        format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    // Magic (6) + version (2) + length (2) + header + '\n' is a multiple of 64.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    out.write_all(b"\x93NUMPY\x01\x00")?;
    out.write_all(&(header.len() as u16).to_le_bytes())?;
    out.write_all(header.as_bytes())?;
    for v in data {
        out.write_all(&v.to_le_bytes())?;
    }
    out.flush()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = Path::new(args.first().ok_or("usage: lpca_peer DIR [RUNS] [SEED]")?);
    let runs: usize = args.get(1).map_or(Ok(3), |s| s.parse())?;
    let seed: u64 = args.get(2).map_or(Ok(1), |s| s.parse())?;
    std::fs::create_dir_all(dir)?;

    let full = Btf::synthetic(SyntheticMaterial::Stones, 64, 7)?;
    let step = 3;
    let pick = |set: &DirectionSet| -> Result<DirectionSet, BtfError> {
        DirectionSet::new(set.iter().step_by(step).copied().collect())
    };
    let (views, lights) = (pick(full.views())?, pick(full.lights())?);
    let (nv, nl) = (views.len(), lights.len());
    let btf = Btf::from_source(
        "subsampled",
        views,
        lights,
        64,
        64,
        Box::new(Subsampled { btf: full, step }),
    )?;
    let x = data::brdf_matrix(&btf, &NoProgress)?;
    let (n, d) = (64 * 64, nv * nl * 3);
    write_npy(&dir.join("data.npy"), n, d, &x)?;

    let options = FactorizationOptions {
        clusters: 32,
        components: 8,
        max_iterations: 10,
        tolerance: 0.0,
        seed,
    };
    let mut times = Vec::new();
    let mut result = None;
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        let (f, stats) = fit_rows(&x, n, d, &options, &NoProgress)?;
        times.push(t.elapsed().as_secs_f64());
        result = Some((f, stats));
    }
    times.sort_by(f64::total_cmp);
    let (f, stats) = result.expect("one run");
    let sizes = {
        let mut s = vec![0usize; f.clusters()];
        f.assignment().iter().for_each(|&k| s[usize::from(k)] += 1);
        s
    };
    println!(
        "{}",
        serde_json::json!({
            "side": "rust (faer)",
            "n": n, "d": d, "clusters": 32, "components": 8,
            "iterations": stats.iterations,
            "seconds_median": times[times.len() / 2],
            "seconds_all": times,
            "mean_squared_error": stats.final_error(),
            "error_history": stats.error_history,
            "largest_cluster": sizes.iter().max(),
            "threads": rayon::current_num_threads(),
        })
    );
    Ok(())
}
