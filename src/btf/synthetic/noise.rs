//! Periodic procedural noise on the unit tile [0, 1)^2: value noise, fractal sums of it, and
//! cellular (Worley) noise. Everything wraps at the tile border, so the materials built from it
//! tile seamlessly, and everything is drawn from a seeded PCG generator.

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;

/// A seeded generator for one named part of a material (so parts do not share random streams).
pub(crate) fn rng(seed: u64, salt: u64) -> Pcg64 {
    Pcg64::seed_from_u64(seed ^ salt.wrapping_mul(0x9e37_79b9_7f4a_7c15))
}

/// Quintic fade: C2-continuous interpolation weight.
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// Value noise with a `px` x `py` lattice of random values in [0, 1) across the tile
/// (different periods along u and v give streaky, anisotropic noise).
#[derive(Debug, Clone)]
pub(crate) struct ValueNoise {
    px: usize,
    py: usize,
    values: Vec<f32>,
}

impl ValueNoise {
    pub(crate) fn new(period: usize, rng: &mut Pcg64) -> Self {
        Self::anisotropic(period, period, rng)
    }

    pub(crate) fn anisotropic(px: usize, py: usize, rng: &mut Pcg64) -> Self {
        let (px, py) = (px.max(1), py.max(1));
        let values = (0..px * py).map(|_| rng.random::<f32>()).collect();
        Self { px, py, values }
    }

    /// Smoothly interpolated value in [0, 1) at tile coordinates (u, v), any real numbers.
    pub(crate) fn sample(&self, u: f32, v: f32) -> f32 {
        let (x, y) = (
            u.rem_euclid(1.0) * self.px as f32,
            v.rem_euclid(1.0) * self.py as f32,
        );
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (fade(x - x0), fade(y - y0));
        let (nx, ny) = (self.px, self.py);
        let (i0, j0) = (x0 as usize % nx, y0 as usize % ny);
        let (i1, j1) = ((i0 + 1) % nx, (j0 + 1) % ny);
        let at = |i: usize, j: usize| self.values[j * nx + i];
        let top = at(i0, j0) + (at(i1, j0) - at(i0, j0)) * fx;
        let bottom = at(i0, j1) + (at(i1, j1) - at(i0, j1)) * fx;
        top + (bottom - top) * fy
    }
}

/// Fractal sum of value noise: octave k has period `base * 2^k` and amplitude `gain^k`,
/// normalised to [0, 1).
#[derive(Debug, Clone)]
pub(crate) struct Fbm {
    octaves: Vec<ValueNoise>,
    gain: f32,
}

impl Fbm {
    pub(crate) fn new(base_period: usize, octaves: usize, gain: f32, rng: &mut Pcg64) -> Self {
        let octaves = (0..octaves)
            .map(|k| ValueNoise::new(base_period << k, rng))
            .collect();
        Self { octaves, gain }
    }

    pub(crate) fn sample(&self, u: f32, v: f32) -> f32 {
        let (mut sum, mut amp, mut norm) = (0.0, 1.0, 0.0);
        for o in &self.octaves {
            sum += amp * o.sample(u, v);
            norm += amp;
            amp *= self.gain;
        }
        sum / norm
    }
}

/// Distances to the nearest and second-nearest feature point, in units of one cell, and the
/// index of the nearest point's cell (a stable id for per-cell colours).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Cell {
    pub f1: f32,
    pub f2: f32,
    pub id: usize,
}

/// Periodic cellular noise: one jittered feature point per cell of a `cells` x `cells` grid.
#[derive(Debug, Clone)]
pub(crate) struct Worley {
    cells: usize,
    points: Vec<[f32; 2]>,
}

impl Worley {
    /// `jitter` in [0, 1]: 0 gives a regular grid, 1 fully random points within each cell.
    pub(crate) fn new(cells: usize, jitter: f32, rng: &mut Pcg64) -> Self {
        let cells = cells.max(1);
        let points = (0..cells * cells)
            .map(|_| {
                [
                    0.5 + jitter * (rng.random::<f32>() - 0.5),
                    0.5 + jitter * (rng.random::<f32>() - 0.5),
                ]
            })
            .collect();
        Self { cells, points }
    }

    pub(crate) fn sample(&self, u: f32, v: f32) -> Cell {
        let n = self.cells as i64;
        let (x, y) = (u.rem_euclid(1.0) * n as f32, v.rem_euclid(1.0) * n as f32);
        let (cx, cy) = (x.floor() as i64, y.floor() as i64);
        let mut best = Cell {
            f1: f32::MAX,
            f2: f32::MAX,
            id: 0,
        };
        for dy in -2..=2 {
            for dx in -2..=2 {
                let (gx, gy) = (cx + dx, cy + dy);
                let id = (gy.rem_euclid(n) * n + gx.rem_euclid(n)) as usize;
                let p = self.points[id];
                let d = ((gx as f32 + p[0] - x).powi(2) + (gy as f32 + p[1] - y).powi(2)).sqrt();
                if d < best.f1 {
                    best.f2 = best.f1;
                    best.f1 = d;
                    best.id = id;
                } else if d < best.f2 {
                    best.f2 = d;
                }
            }
        }
        best
    }

    /// A pseudo-random value in [0, 1) attached to a cell id (stable for a given seed).
    pub(crate) fn cell_value(&self, id: usize, salt: u32) -> f32 {
        let mut h = (id as u64) ^ (u64::from(salt) << 32) ^ 0x2545_f491_4f6c_dd1d;
        h = (h ^ (h >> 33)).wrapping_mul(0xff51_afd7_ed55_8ccd);
        h = (h ^ (h >> 33)).wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^= h >> 33;
        // Mix in the cell's own point so that different seeds give different values.
        let p = self.points[id % self.points.len()];
        ((h >> 40) as f32 / (1u64 << 24) as f32 + p[0] * 7.31 + p[1] * 3.17).fract()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_tiles_seamlessly_and_stays_in_range() {
        let mut r = rng(3, 1);
        let vn = ValueNoise::new(7, &mut r);
        let fbm = Fbm::new(4, 4, 0.5, &mut r);
        let w = Worley::new(5, 1.0, &mut r);
        for k in 0..50 {
            let (u, v) = (k as f32 * 0.0173, k as f32 * 0.0311);
            assert!((vn.sample(u, v) - vn.sample(u + 1.0, v - 1.0)).abs() < 1e-5);
            let f = fbm.sample(u, v);
            assert!((0.0..1.0).contains(&f));
            let (a, b) = (w.sample(u, v), w.sample(u + 1.0, v + 2.0));
            assert!((a.f1 - b.f1).abs() < 1e-4 && a.id == b.id);
            assert!(a.f1 <= a.f2);
        }
    }

    #[test]
    fn same_seed_same_values() {
        let a = ValueNoise::new(9, &mut rng(11, 2));
        let b = ValueNoise::new(9, &mut rng(11, 2));
        let c = ValueNoise::new(9, &mut rng(12, 2));
        assert_eq!(a.values, b.values);
        assert_ne!(a.values, c.values);
    }
}
