//! Marginal (histogram) matching of synthesized factor planes. Gaussian MRFs reproduce only
//! second-order statistics, so a bimodal colour distribution (red and cream threads) comes out
//! as one pinkish hump; mapping the synthesized values through their own quantiles onto the
//! measured quantiles restores the marginal distribution (mrf_math.md sec. 7, last row).

use ndarray::Array2;

/// Quantiles stored per factor: the minimum, 15 inner ones, the maximum (17 values).
pub const QUANTILES: usize = 17;

/// Quantile table of a factor: values at probabilities `k / (QUANTILES - 1)`.
pub type Quantiles = [f64; QUANTILES];

/// At most this many samples are sorted to estimate quantiles (a regular subsample).
const MAX_SAMPLES: usize = 16_384;

/// The quantiles of a plane's values (of a regular subsample of at most 16384 of them).
pub fn quantiles(plane: &Array2<f64>) -> Quantiles {
    let stride = plane.len().div_ceil(MAX_SAMPLES).max(1);
    let mut sample: Vec<f64> = plane
        .iter()
        .step_by(stride)
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    if sample.is_empty() {
        return [0.0; QUANTILES];
    }
    sample.sort_by(f64::total_cmp);
    let last = (sample.len() - 1) as f64;
    std::array::from_fn(|k| {
        let pos = last * k as f64 / (QUANTILES - 1) as f64;
        let (i, f) = (pos.floor() as usize, pos - pos.floor());
        let next = (i + 1).min(sample.len() - 1);
        sample[i] * (1.0 - f) + sample[next] * f
    })
}

/// Maps `plane` so that its quantiles become `target` (see [`MarginalMap`]).
pub fn match_marginal(plane: &mut Array2<f64>, target: &Quantiles) {
    let map = MarginalMap::new(plane, target);
    plane.par_mapv_inplace(|v| map.apply(v));
}

/// The monotone map that gives a plane the quantiles `target`: piecewise linear between the
/// knots of the plane's own quantile table and the target's (flat stretches of the source map
/// to their knot). Large planes use it tabulated on a fine uniform grid over the source range,
/// one multiply-add per value instead of a search.
#[derive(Debug, Clone)]
pub struct MarginalMap {
    source: Quantiles,
    target: Quantiles,
    /// (lowest source value, grid steps per unit, map at the grid nodes) when tabulated.
    table: Option<(f64, f64, Vec<f64>)>,
}

impl MarginalMap {
    /// The map for `plane`'s values onto `target`.
    pub fn new(plane: &Array2<f64>, target: &Quantiles) -> Self {
        let mut map = Self {
            source: quantiles(plane),
            target: *target,
            table: None,
        };
        let (lo, hi) = (map.source[0], map.source[QUANTILES - 1]);
        if hi.partial_cmp(&lo) == Some(std::cmp::Ordering::Greater) && plane.len() >= 4 * LUT {
            let step = (hi - lo) / LUT as f64;
            let nodes = (0..=LUT).map(|i| map.exact(lo + step * i as f64)).collect();
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

    fn exact(&self, v: f64) -> f64 {
        let (source, target) = (&self.source, &self.target);
        let k = source.partition_point(|&q| q < v);
        if k == 0 {
            target[0]
        } else if k >= QUANTILES {
            target[QUANTILES - 1]
        } else {
            let (a, b) = (source[k - 1], source[k]);
            let t = if b > a { (v - a) / (b - a) } else { 1.0 };
            target[k - 1] + (target[k] - target[k - 1]) * t
        }
    }
}

/// Entries of the tabulated marginal map (the error against the exact map is below
/// (range / LUT)^2 times its curvature, which is zero inside each of the 16 linear pieces).
const LUT: usize = 4096;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matching_transfers_a_bimodal_distribution() {
        let target_plane =
            Array2::from_shape_fn(
                (64, 64),
                |(y, x)| if (x / 8 + y / 8) % 2 == 0 { -1.0 } else { 1.0 },
            );
        let target = quantiles(&target_plane);
        let mut plane =
            Array2::from_shape_fn((64, 64), |(y, x)| ((x * 31 + y * 17) % 97) as f64 / 97.0);
        match_marginal(&mut plane, &target);
        let high = plane.iter().filter(|&&v| v > 0.5).count() as f64 / plane.len() as f64;
        assert!((high - 0.5).abs() < 0.05, "{high}");
        assert!(plane.iter().all(|&v| (-1.0..=1.0).contains(&v)));
        // Matching to one's own quantiles changes little.
        let mut same = target_plane.clone();
        match_marginal(&mut same, &quantiles(&target_plane));
        assert_eq!(quantiles(&same), target);
    }

    #[test]
    fn constant_planes_stay_finite() {
        let mut flat = Array2::from_elem((5, 5), 2.0);
        match_marginal(&mut flat, &[3.0; QUANTILES]);
        assert!(flat.iter().all(|&v| v == 3.0));
    }
}
