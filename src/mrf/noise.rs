//! The driving noise of a band: unit Gaussian values in the order a synthesizer consumes them.
//! Drawing it apart from the recursion lets every subspace image of one synthesis reuse the
//! same values (they share their noise by design, see `synthesis`), so it is drawn once.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;

/// Values drawn from one generator: blocks are seeded independently, so they are drawn in
/// parallel and the values do not depend on the number of threads.
const BLOCK: usize = 8192;

/// A seed derived from `seed` and an index (splitmix64 finaliser): distinct indices give
/// unrelated seeds.
pub fn mix(seed: u64, index: u64) -> u64 {
    let mut z = seed ^ index.wrapping_add(1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// `len` independent N(0, 1) values from `seed` (xoshiro256++ per block of 8192, ziggurat),
/// in single precision (half the memory of a kept draw; far finer than the sampling noise);
/// a longer draw from the same seed starts with the same values.
pub fn standard_normal(seed: u64, len: usize) -> Vec<f32> {
    let mut out = vec![0.0; len];
    out.par_chunks_mut(BLOCK)
        .enumerate()
        .for_each(|(block, chunk)| {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(mix(seed, block as u64));
            for v in chunk {
                *v = StandardNormal.sample(&mut rng);
            }
        });
    out
}

/// Panics unless `noise` holds at least `needed` values: a synthesizer was handed a draw for a
/// smaller sample (a programming error, never user input).
pub(crate) fn require(noise: &[f32], needed: usize) {
    assert!(
        noise.len() >= needed,
        "{} noise values for {needed}",
        noise.len()
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefixes_agree_and_moments_are_standard() {
        let long = standard_normal(3, 100_000);
        assert_eq!(standard_normal(3, 10)[..], long[..10]);
        assert_eq!(standard_normal(3, 3 * BLOCK + 5)[..], long[..3 * BLOCK + 5]);
        assert_ne!(standard_normal(4, 10)[..], long[..10]);
        let long: Vec<f64> = long.into_iter().map(f64::from).collect();
        let mean = long.iter().sum::<f64>() / long.len() as f64;
        let var = long.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / long.len() as f64;
        assert!(
            mean.abs() < 0.01 && (var - 1.0).abs() < 0.02,
            "{mean} {var}"
        );
        // Neighbouring blocks are not correlated.
        let (a, b) = (&long[..BLOCK], &long[BLOCK..2 * BLOCK]);
        let r = a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>() / BLOCK as f64;
        assert!(r.abs() < 0.05, "{r}");
    }
}
