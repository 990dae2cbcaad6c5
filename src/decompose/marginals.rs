//! Marginal (histogram) matching of synthesized factor planes. Gaussian MRFs reproduce only
//! second-order statistics, so a bimodal colour distribution (red and cream threads) comes out
//! as one pinkish hump; mapping the synthesized values through their own quantiles onto the
//! measured quantiles restores the marginal distribution (mrf_math.md sec. 7, last row).

use ndarray::Array2;

/// Quantiles stored per factor: the minimum, 15 inner ones, the maximum (17 values).
pub const QUANTILES: usize = 17;

/// Quantile table of a factor: values at the probabilities of a [`QuantileGrid`].
pub type Quantiles = [f64; QUANTILES];

/// Where a quantile table's probabilities lie.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum QuantileGrid {
    /// Evenly spaced, `k / (n - 1)` (format version 1 factor tables).
    Uniform,
    /// The minimum, the maximum, and between them the standard normal CDF at `n - 2` points
    /// evenly spaced over [-3, 3]. Measured factors and bands are heavy-tailed; an even grid
    /// leaves the outer `1 / (n - 1)` of each tail to one linear piece, which spreads the few
    /// extreme values (JPEG noise in the chroma of grey clay, edges in a band) over many pixels.
    #[default]
    NormalTails,
}

impl QuantileGrid {
    /// The `n` probabilities (n >= 3), increasing from 0 to 1.
    pub fn probabilities(self, n: usize) -> Vec<f64> {
        match self {
            QuantileGrid::Uniform => (0..n).map(|k| k as f64 / (n - 1) as f64).collect(),
            QuantileGrid::NormalTails => {
                let inner = n - 2;
                std::iter::once(0.0)
                    .chain(
                        (0..inner).map(|k| normal_cdf(-3.0 + 6.0 * k as f64 / (inner - 1) as f64)),
                    )
                    .chain(std::iter::once(1.0))
                    .collect()
            }
        }
    }
}

/// Quantiles per pyramid band table (mrf_math.md 1(f')), on the [`QuantileGrid::NormalTails`]
/// grid.
pub const BAND_QUANTILES: usize = 33;

/// Probabilities of the band tables.
pub fn band_probabilities() -> Vec<f64> {
    QuantileGrid::NormalTails.probabilities(BAND_QUANTILES)
}

/// The standard normal CDF (Abramowitz and Stegun 7.1.26 for erf, error below 1.5e-7).
fn normal_cdf(z: f64) -> f64 {
    let x = z.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erf = 1.0 - poly * (-x * x).exp();
    0.5 * (1.0 + erf.copysign(z))
}

/// About this many samples are sorted to estimate quantiles (a regular subsample).
const MAX_SAMPLES: usize = 16_384;

/// The quantiles of a plane's values (of a regular subsample of at most 16384 of them) at the
/// factor probabilities of `grid`.
pub fn quantiles(plane: &Array2<f64>, grid: QuantileGrid) -> Quantiles {
    quantiles_at(plane, &grid.probabilities(QUANTILES))
        .try_into()
        .expect("QUANTILES values")
}

/// The step between the samples [`quantiles_at`] takes from a plane of `len` values in rows
/// of `cols`: at least `len / MAX_SAMPLES`, and sharing no factor with `cols`, so the samples
/// move along the row from one row to the next. A step that divides the row length takes the
/// same columns in every row: 16 of a 1024^2 knit's, in step with its weave, whose quantiles
/// then came out of the threads alone (its lit synthesis twice as bright as at 64^2).
pub(crate) fn sample_step(len: usize, cols: usize) -> usize {
    let gcd = |mut a: usize, mut b: usize| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    let mut step = len.div_ceil(MAX_SAMPLES).max(1);
    while step > 1 && gcd(step, cols.max(1)) != 1 {
        step += 1;
    }
    step
}

/// The quantiles of a plane's values at `probabilities` (non-decreasing, in [0, 1]).
pub fn quantiles_at(plane: &Array2<f64>, probabilities: &[f64]) -> Vec<f64> {
    let stride = sample_step(plane.len(), plane.ncols());
    sample_quantiles(plane.iter().step_by(stride).copied(), probabilities)
}

/// The quantiles at `probabilities` of the finite values of `sample`: only the order
/// statistics they read are put in place ([`select_ranks`]), the same values a sort gives.
pub(crate) fn sample_quantiles(
    sample: impl Iterator<Item = f64>,
    probabilities: &[f64],
) -> Vec<f64> {
    let mut sample: Vec<f64> = sample.filter(|v| v.is_finite()).collect();
    if sample.is_empty() {
        return vec![0.0; probabilities.len()];
    }
    let last = (sample.len() - 1) as f64;
    let below = |p: f64| (last * p.clamp(0.0, 1.0)).floor() as usize;
    let mut ranks: Vec<usize> = probabilities
        .iter()
        .flat_map(|&p| [below(p), (below(p) + 1).min(sample.len() - 1)])
        .collect();
    ranks.sort_unstable();
    ranks.dedup();
    select_ranks(&mut sample, &ranks);
    // Interpolated as a + (b - a) f, exact where neighbours are equal, and made non-decreasing
    // against rounding (a flat plane gave tables decreasing in the last bit).
    let mut floor = f64::NEG_INFINITY;
    probabilities
        .iter()
        .map(|&p| {
            let pos = last * p.clamp(0.0, 1.0);
            let (i, f) = (pos.floor() as usize, pos - pos.floor());
            let next = (i + 1).min(sample.len() - 1);
            floor = floor.max(sample[i] + (sample[next] - sample[i]) * f);
            floor
        })
        .collect()
}

/// Puts the order statistics `ranks` (ascending, distinct, below `values.len()`) of `values`
/// in place, as a sort would (by `total_cmp`, under which equal values have the same bits):
/// a selection at the middle rank splits the values, and each side is done alike, so the
/// values between two wanted ranks are never ordered.
fn select_ranks(values: &mut [f64], ranks: &[usize]) {
    select_ranks_from(values, ranks, 0);
}

/// [`select_ranks`] on a run of the values that starts at rank `first`.
fn select_ranks_from(values: &mut [f64], ranks: &[usize], first: usize) {
    let Some(&rank) = ranks.get(ranks.len() / 2) else {
        return;
    };
    let (lower, higher) = ranks.split_at(ranks.len() / 2);
    let (left, _, right) = values.select_nth_unstable_by(rank - first, f64::total_cmp);
    select_ranks_from(left, lower, first);
    select_ranks_from(right, &higher[1..], rank + 1);
}

/// Maps `plane` so that its quantiles at `probabilities` become `target` (see
/// [`MarginalMap`]).
pub fn match_marginal(plane: &mut Array2<f64>, target: &[f64], probabilities: &[f64]) {
    let map = MarginalMap::new(plane, target, probabilities);
    plane.par_mapv_inplace(|v| map.apply(v));
}

/// The monotone map that gives a plane the quantiles `target`: piecewise linear between the
/// knots of the plane's own quantile table and the target's (flat stretches of the source map
/// to their knot). Large planes use it tabulated on a fine uniform grid over the source range,
/// one multiply-add per value instead of a search.
#[derive(Debug, Clone)]
pub struct MarginalMap {
    source: Vec<f64>,
    target: Vec<f64>,
    /// (lowest source value, grid steps per unit, map at the grid nodes) when tabulated.
    table: Option<(f64, f64, Box<[f64; LUT + 1]>)>,
}

impl MarginalMap {
    /// The map for `plane`'s values onto `target`, the quantiles at `probabilities`.
    pub fn new(plane: &Array2<f64>, target: &[f64], probabilities: &[f64]) -> Self {
        debug_assert_eq!(target.len(), probabilities.len());
        Self::between(quantiles_at(plane, probabilities), target, plane.len())
    }

    /// The piecewise-linear map from the non-decreasing `source` table onto `target` (of one
    /// length; e.g. from a value to its quantile), tabulated when it will map at least
    /// `4 LUT` values (`uses`, about how many it will).
    pub fn between(source: Vec<f64>, target: &[f64], uses: usize) -> Self {
        debug_assert_eq!(source.len(), target.len());
        let mut map = Self {
            source,
            target: target.to_vec(),
            table: None,
        };
        let (lo, hi) = (map.source[0], map.source[map.source.len() - 1]);
        if hi.partial_cmp(&lo) == Some(std::cmp::Ordering::Greater) && uses >= 4 * LUT {
            let step = (hi - lo) / LUT as f64;
            let nodes = Box::new(std::array::from_fn(|i| map.exact(lo + step * i as f64)));
            map.table = Some((lo, 1.0 / step, nodes));
        }
        map
    }

    /// The mapped value of `v`.
    #[inline]
    pub fn apply(&self, v: f64) -> f64 {
        match &self.table {
            Some((lo, per_step, nodes)) => {
                let x = ((v - lo) * per_step).clamp(0.0, LUT as f64);
                // x is in 0..=LUT: the signed 32-bit conversion is exact and the cheapest.
                let i = (x as i32 as usize).min(LUT - 1);
                nodes[i] + (nodes[i + 1] - nodes[i]) * (x - i as f64)
            }
            None => self.exact(v),
        }
    }

    /// Maps every value of `values` in place: [`MarginalMap::apply`] on each (the same
    /// arithmetic, so the same values), for a tabulated map in blocks of two loops that
    /// vectorise, the grid positions and then the lookups.
    #[inline(always)]
    pub fn apply_in_place(&self, values: &mut [f64]) {
        const BLOCK: usize = 256;
        const TWO_TO_52: f64 = 4_503_599_627_370_496.0;
        let Some((lo, per_step, nodes)) = &self.table else {
            values.iter_mut().for_each(|v| *v = self.exact(*v));
            return;
        };
        let nodes: &[f64; LUT + 1] = nodes;
        let mut index = [0u32; BLOCK];
        for block in values.chunks_mut(BLOCK) {
            for (v, i) in block.iter_mut().zip(&mut index) {
                let x = ((*v - lo) * per_step).clamp(0.0, LUT as f64);
                // The same node as `apply`'s (a NaN's 0), read from the low bits of the
                // whole number plus 2^52 (exact below 2^52): a conversion that vectorises.
                let node = x.max(0.0).min((LUT - 1) as f64).floor();
                *i = (node + TWO_TO_52).to_bits() as u32;
                *v = x;
            }
            for (v, &i) in block.iter_mut().zip(&index) {
                let i = (i as usize).min(LUT - 1);
                *v = nodes[i] + (nodes[i + 1] - nodes[i]) * (*v - i as f64);
            }
        }
    }

    fn exact(&self, v: f64) -> f64 {
        let (source, target) = (&self.source, &self.target);
        let n = source.len();
        let k = source.partition_point(|&q| q < v);
        if k == 0 {
            target[0]
        } else if k >= n {
            target[n - 1]
        } else {
            let (a, b) = (source[k - 1], source[k]);
            let t = if b > a { (v - a) / (b - a) } else { 1.0 };
            target[k - 1] + (target[k] - target[k - 1]) * t
        }
    }
}

/// Entries of the tabulated marginal map (the error against the exact map is below
/// (range / LUT)^2 times its curvature, which is zero inside each linear piece).
const LUT: usize = 4096;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn selected_quantiles_are_the_sorted_ones() {
        // Ties, a constant run and values of both signs; every sample size from 1 to 300.
        for n in 1..300 {
            let values: Vec<f64> = (0..n)
                .map(|i| (((i * 7919) % 257) as f64 - 128.0) / 16.0)
                .map(|v| {
                    if (40..60).contains(&(v as i64 + 128)) {
                        1.5
                    } else {
                        v
                    }
                })
                .collect();
            let probabilities = band_probabilities();
            let selected = sample_quantiles(values.iter().copied(), &probabilities);
            let mut sorted = values.clone();
            sorted.sort_unstable_by(f64::total_cmp);
            let last = (n - 1) as f64;
            let mut floor = f64::NEG_INFINITY;
            for (p, got) in probabilities.iter().zip(&selected) {
                let pos = last * p;
                let (i, f) = (pos.floor() as usize, pos - pos.floor());
                let next = (i + 1).min(n - 1);
                floor = floor.max(sorted[i] + (sorted[next] - sorted[i]) * f);
                assert_eq!(got.to_bits(), floor.to_bits(), "n {n}, p {p}");
            }
        }
    }

    #[test]
    fn a_slice_is_mapped_as_value_by_value() {
        let source: Vec<f64> = (0..17)
            .map(|i| (f64::from(i) - 8.0).powi(3) / 50.0)
            .collect();
        let target: Vec<f64> = (0..17).map(|i| f64::from(i).sqrt() * 3.0 - 1.0).collect();
        // Values below, inside and beyond the table's range, on its nodes, and a NaN.
        let values: Vec<f64> = (0..3000)
            .map(|i| f64::from(i) / 100.0 - 15.0)
            .chain([f64::NAN, -1e300, 1e300, source[0], source[16]])
            .collect();
        for uses in [10, 4 * LUT] {
            let map = MarginalMap::between(source.clone(), &target, uses);
            assert_eq!(map.table.is_some(), uses == 4 * LUT);
            let mut mapped = values.clone();
            map.apply_in_place(&mut mapped);
            for (&v, &m) in values.iter().zip(&mapped) {
                let want = map.apply(v);
                assert!(
                    m.to_bits() == want.to_bits() || (m.is_nan() && want.is_nan()),
                    "{v}: {m} against {want}"
                );
            }
        }
    }

    #[test]
    fn a_subsample_takes_every_column_of_a_large_plane() {
        // One bright column in 64, as a weave's thread edges: a step of 64 on rows of 1024
        // sampled the bright column alone.
        let plane = Array2::from_shape_fn((1024, 1024), |(_, x)| f64::from(u8::from(x % 64 == 0)));
        let q = quantiles_at(&plane, &[0.5, 0.97, 0.99]);
        assert_eq!(q, vec![0.0, 0.0, 1.0], "{q:?}");
        assert_eq!(sample_step(1024 * 1024, 1024), 65);
        assert_eq!(sample_step(100, 10), 1);
    }

    #[test]
    fn matching_transfers_a_bimodal_distribution() {
        let target_plane =
            Array2::from_shape_fn(
                (64, 64),
                |(y, x)| if (x / 8 + y / 8) % 2 == 0 { -1.0 } else { 1.0 },
            );
        let uniform = QuantileGrid::Uniform;
        let target = quantiles(&target_plane, uniform);
        let mut plane =
            Array2::from_shape_fn((64, 64), |(y, x)| ((x * 31 + y * 17) % 97) as f64 / 97.0);
        match_marginal(&mut plane, &target, &uniform.probabilities(QUANTILES));
        let high = plane.iter().filter(|&&v| v > 0.5).count() as f64 / plane.len() as f64;
        assert!((high - 0.5).abs() < 0.05, "{high}");
        assert!(plane.iter().all(|&v| (-1.0..=1.0).contains(&v)));
        // Matching to one's own quantiles changes little.
        let mut same = target_plane.clone();
        let probs = uniform.probabilities(QUANTILES);
        match_marginal(&mut same, &quantiles(&target_plane, uniform), &probs);
        assert_eq!(quantiles(&same, uniform), target);
    }

    #[test]
    fn constant_planes_stay_finite() {
        let mut flat = Array2::from_elem((5, 5), 2.0);
        let probs = QuantileGrid::NormalTails.probabilities(QUANTILES);
        match_marginal(&mut flat, &[3.0; QUANTILES], &probs);
        assert!(flat.iter().all(|&v| v == 3.0));
    }

    #[test]
    fn band_probabilities_resolve_the_tails() {
        let p = band_probabilities();
        assert_eq!(p.len(), BAND_QUANTILES);
        assert!(p.windows(2).all(|w| w[1] > w[0]));
        assert!((p[16] - 0.5).abs() < 1e-7);
        // Phi(-3) and Phi(-1) to the table's accuracy.
        assert!((p[1] - 0.001_349_9).abs() < 1e-6, "{}", p[1]);
        assert!((normal_cdf(-1.0) - 0.158_655_3).abs() < 1e-6);
        assert!((normal_cdf(1.0) + normal_cdf(-1.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_sparse_heavy_tailed_band_is_restored_with_its_tail() {
        // The target: mostly near zero, 1 % large values (edges). A Gaussian matched to its
        // table keeps about 1 % beyond half the maximum, not the 3 % an even 33-quantile
        // table spreads linearly towards it.
        let target_plane = Array2::from_shape_fn((128, 128), |(y, x)| {
            let i = y * 128 + x;
            if i % 100 == 0 {
                10.0
            } else {
                ((i * 37 % 101) as f64 - 50.0) / 500.0
            }
        });
        let probs = band_probabilities();
        let target = quantiles_at(&target_plane, &probs);
        let mut plane = Array2::from_shape_fn((128, 128), |(y, x)| {
            ((y * 128 + x) as f64 * 0.618_034).fract() - 0.5
        });
        match_marginal(&mut plane, &target, &probs);
        let big = plane.iter().filter(|&&v| v > 5.0).count() as f64 / plane.len() as f64;
        assert!((0.005..0.015).contains(&big), "{big}");
    }
}
