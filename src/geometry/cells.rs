//! Cells of a relief, and one mean per cell in a quilt. A quilt chooses its patches and cuts on
//! the relief, where one flat stone top fits any other: a cut then crosses a stone, and the
//! fields laid with the relief (the stone's colour) change along it, a stone half grey, half
//! beige. Here a cell is a connected region where the relief's detail keeps one sign (a
//! stone, a pebble, a pit); an output cell laid from pieces of several source cells gives
//! every piece the mean of its largest piece, each keeping its own variation about it.

use ndarray::{Array2, Zip};

use super::quilt::{Placement, detail_scale, patch_side, split_detail};

/// The cells of a relief as a quilt laid them: which source cell every source sample lies in,
/// and per laid sample the source cell whose mean its output cell takes.
#[derive(Debug, Clone, PartialEq)]
pub struct LaidCells {
    /// Per source sample (row-major), its source cell.
    source: Vec<u32>,
    /// How many source cells there are.
    count: usize,
    /// Per laid sample, the source cell of its output cell's largest piece.
    major: Array2<u32>,
}

impl LaidCells {
    /// The cells of `relief` (the quilt's source: the sign of its detail finer than the
    /// quilt's [`detail_scale`]) as `placement` laid them; `wrap`: the laid samples are a
    /// whole torus. An output cell larger than a patch is a network (a sponge's walls, the
    /// mortar around stones), not a cell a cut crossed: its pieces stay as laid.
    ///
    /// # Panics
    /// `placement` was not made on a source of `relief`'s shape.
    pub fn new(relief: &Array2<f64>, placement: &Placement, wrap: bool) -> Self {
        assert_eq!(placement.source(), relief.dim(), "the quilt's own source");
        let (rows, cols) = relief.dim();
        let (_, detail) = split_detail(relief, detail_scale(rows, cols), false);
        let raised = detail.mapv(|v| v >= 0.0);
        let (source, count) = regions(&raised, false);
        let source: Vec<u32> = source.iter().copied().collect();
        let flags: Vec<bool> = raised.iter().copied().collect();
        let from = placement.sources();
        let (cells, n) = regions(&from.mapv(|i| flags[i as usize]), wrap);
        // Per output cell, the samples each source cell brought to it.
        let mut pieces: Vec<Vec<(u32, usize)>> = vec![Vec::new(); n];
        Zip::from(&cells).and(from).for_each(|&c, &i| {
            let (list, s) = (&mut pieces[c as usize], source[i as usize]);
            match list.iter_mut().find(|(k, _)| *k == s) {
                Some((_, m)) => *m += 1,
                None => list.push((s, 1)),
            }
        });
        let largest = patch_side(rows, cols).pow(2);
        let major_of: Vec<Option<u32>> = (pieces.iter())
            .map(|list| {
                let size: usize = list.iter().map(|p| p.1).sum();
                (list.len() > 1 && size <= largest)
                    .then(|| list.iter().max_by_key(|p| p.1).map(|p| p.0))
                    .flatten()
            })
            .collect();
        let major = Zip::from(&cells)
            .and(from)
            .map_collect(|&c, &i| major_of[c as usize].unwrap_or(source[i as usize]));
        Self {
            source,
            count,
            major,
        }
    }

    /// Moves `laid`, the copy of `field` (of the source's shape) by the placement these cells
    /// were made with, piece by piece: by the mean of `field` over its output cell's major
    /// source cell less its mean over the piece's own source cell.
    pub fn even_out(&self, field: &Array2<f64>, placement: &Placement, laid: &mut Array2<f64>) {
        let mut sums = vec![(0.0, 0usize); self.count];
        for (&c, &v) in self.source.iter().zip(field.iter()) {
            let s = &mut sums[c as usize];
            *s = (s.0 + v, s.1 + 1);
        }
        let means: Vec<f64> = sums.iter().map(|&(s, n)| s / n.max(1) as f64).collect();
        Zip::from(laid)
            .and(&self.major)
            .and(placement.sources())
            .par_for_each(|v, &m, &i| {
                *v += means[m as usize] - means[self.source[i as usize] as usize];
            });
    }
}

/// The 4-connected regions of equal value in `mask` (across its edges too when `wrap`): each
/// sample's region, numbered from 0 in row-major order of their first samples, and how many.
fn regions(mask: &Array2<bool>, wrap: bool) -> (Array2<u32>, usize) {
    let (h, w) = mask.dim();
    let mut label = Array2::<u32>::from_elem((h, w), u32::MAX);
    let mut count = 0u32;
    let mut stack = Vec::new();
    // A neighbour one step back or forward along an axis of length n, if any.
    let step = |i: usize, n: usize, forward: bool| match (forward, wrap) {
        (true, _) if i + 1 < n => Some(i + 1),
        (false, _) if i > 0 => Some(i - 1),
        (true, true) => Some(0),
        (false, true) => Some(n - 1),
        _ => None,
    };
    for ((y0, x0), &value) in mask.indexed_iter() {
        if label[(y0, x0)] != u32::MAX {
            continue;
        }
        label[(y0, x0)] = count;
        stack.push((y0, x0));
        while let Some((y, x)) = stack.pop() {
            let neighbours = [
                step(y, h, false).map(|y| (y, x)),
                step(y, h, true).map(|y| (y, x)),
                step(x, w, false).map(|x| (y, x)),
                step(x, w, true).map(|x| (y, x)),
            ];
            for p in neighbours.into_iter().flatten() {
                if label[p] == u32::MAX && mask[p] == value {
                    label[p] = count;
                    stack.push(p);
                }
            }
        }
        count += 1;
    }
    (label, count as usize)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::quilt_laid;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn regions_join_equal_neighbours_and_wrap_only_when_asked() {
        // Two columns of `true` at the edges, `false` between.
        let mask = Array2::from_shape_fn((3, 4), |(_, x)| x == 0 || x == 3);
        let (label, n) = regions(&mask, false);
        assert_eq!(n, 3);
        assert_eq!(label.column(0).to_vec(), vec![0; 3]);
        assert_eq!(label.column(1), label.column(2));
        assert_ne!(label[(0, 0)], label[(0, 3)]);
        let (label, n) = regions(&mask, true);
        assert_eq!(n, 2);
        assert_eq!(label[(0, 0)], label[(2, 3)]);
    }

    /// A relief of raised cells (Voronoi cells about `sites`, flat tops) parted by sunken
    /// mortar two samples wide, and a field giving each cell its own level.
    fn cobbles(side: usize, sites: usize, seed: u64) -> (Array2<f64>, Array2<f64>) {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let points: Vec<(f64, f64, f64)> = (0..sites)
            .map(|_| {
                let level = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                (
                    rng.random_range(0.0..side as f64),
                    rng.random_range(0.0..side as f64),
                    level,
                )
            })
            .collect();
        let nearest = |y: usize, x: usize| {
            let mut d: Vec<(f64, f64)> = (points.iter())
                .map(|&(py, px, level)| ((py - y as f64).hypot(px - x as f64), level))
                .collect();
            d.sort_by(|a, b| a.0.total_cmp(&b.0));
            (d[1].0 - d[0].0, d[0].1)
        };
        let relief =
            Array2::from_shape_fn(
                (side, side),
                |(y, x)| {
                    if nearest(y, x).0 < 2.0 { 0.0 } else { 1.0 }
                },
            );
        let level = Array2::from_shape_fn((side, side), |(y, x)| nearest(y, x).1);
        (relief, level)
    }

    /// The share of the output cells of at most `largest` samples whose laid `field` is not
    /// one value.
    fn mixed_share(relief_laid: &Array2<f64>, field: &Array2<f64>, largest: usize) -> f64 {
        let (label, n) = regions(&relief_laid.mapv(|v| v > 0.5), false);
        let mut seen: Vec<(f64, f64, usize)> = vec![(f64::INFINITY, f64::NEG_INFINITY, 0); n];
        Zip::from(&label).and(field).for_each(|&c, &v| {
            let s = &mut seen[c as usize];
            *s = (s.0.min(v), s.1.max(v), s.2 + 1);
        });
        let small: Vec<_> = seen.iter().filter(|s| s.2 <= largest).collect();
        small.iter().filter(|s| s.1 - s.0 > 1e-9).count() as f64 / small.len() as f64
    }

    #[test]
    fn cut_cells_take_one_level_and_whole_ones_keep_theirs() {
        let (relief, level) = cobbles(96, 40, 3);
        let (_, placement) = quilt_laid(&relief, &[], &[], (192, 192), 7, None);
        let cells = LaidCells::new(&relief, &placement, false);
        let laid_relief = placement.lay(&relief);
        let mut laid = placement.lay(&level);
        let largest = patch_side(96, 96).pow(2);
        let before = mixed_share(&laid_relief, &laid, largest);
        let copy = laid.clone();
        cells.even_out(&level, &placement, &mut laid);
        let after = mixed_share(&laid_relief, &laid, largest);
        println!("cells of two levels: {before:.3} of the output's before, {after:.3} after");
        assert!(before > 0.05, "the quilt cut no cell: {before}");
        assert!(after < 0.2 * before, "{before} -> {after}");
        // A cell laid from one source cell is left as it was.
        let (label, n) = regions(&laid_relief.mapv(|v| v > 0.5), false);
        let mut sources = vec![Vec::new(); n];
        Zip::from(&label)
            .and(placement.sources())
            .for_each(|&c, &i| sources[c as usize].push(cells.source[i as usize]));
        let whole = |c: u32| {
            sources[c as usize]
                .iter()
                .all(|&s| s == sources[c as usize][0])
        };
        Zip::from(&label)
            .and(&laid)
            .and(&copy)
            .for_each(|&c, &a, &b| assert!(!whole(c) || a == b));
    }

    #[test]
    fn a_relief_without_cells_lays_its_fields_as_they_are() {
        let relief = Array2::from_elem((48, 48), 2.0);
        let field = Array2::from_shape_fn((48, 48), |(y, x)| (y * 48 + x) as f64);
        let (_, placement) = quilt_laid(&relief, &[], &[], (80, 80), 1, None);
        let cells = LaidCells::new(&relief, &placement, false);
        let mut laid = placement.lay(&field);
        let copy = laid.clone();
        cells.even_out(&field, &placement, &mut laid);
        assert_eq!(laid, copy);
    }
}
