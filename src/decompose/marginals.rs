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

/// Maps `plane` so that its quantiles become `target`: piecewise-linear between the knots of
/// its own quantile table and the target's. Flat stretches of the source map to their knot.
pub fn match_marginal(plane: &mut Array2<f64>, target: &Quantiles) {
    let source = quantiles(plane);
    let map = |v: f64| {
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
    };
    let (lo, hi) = (source[0], source[QUANTILES - 1]);
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) || plane.len() < 4 * LUT {
        plane.mapv_inplace(map);
        return;
    }
    // The map is monotone and piecewise linear: tabulate it on a fine uniform grid over the
    // source range and interpolate, one multiply-add per pixel instead of a search.
    let step = (hi - lo) / LUT as f64;
    let table: Vec<f64> = (0..=LUT).map(|i| map(lo + step * i as f64)).collect();
    let per_step = 1.0 / step;
    plane.par_mapv_inplace(|v| {
        let x = ((v - lo) * per_step).clamp(0.0, LUT as f64);
        let i = (x as usize).min(LUT - 1);
        table[i] + (table[i + 1] - table[i]) * (x - i as f64)
    });
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
