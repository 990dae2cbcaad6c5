//! Causal (non-symmetric half-plane) neighbourhoods, ordered by distance (mrf_math.md 2.1).
//!
//! An offset `s = (s1, s2)` names the neighbour `Y[r1 - s1, r2 - s2]`: (0, 1) is the left
//! neighbour, (1, 0) the one above, (1, -1) the upper right one. Every offset comes earlier in
//! raster order, so a causal recursion can use it. The same half-sets define the symmetric GMRF
//! neighbourhoods (each `s` together with `-s`).

/// The hierarchy of causal offsets; order k uses the first `ORDER_SIZES[k - 1]` of them.
pub const CAUSAL_OFFSETS: [(isize, isize); 14] = [
    (0, 1),
    (1, 0),
    (1, 1),
    (1, -1),
    (0, 2),
    (2, 0),
    (1, 2),
    (1, -2),
    (2, 1),
    (2, -1),
    (2, 2),
    (2, -2),
    (0, 3),
    (3, 0),
];

/// Neighbour counts of orders 1..=6.
pub const ORDER_SIZES: [usize; 6] = [2, 4, 6, 10, 12, 14];

/// The largest order.
pub const MAX_ORDER: usize = ORDER_SIZES.len();

/// The offsets of causal order `order` (1..=6; 0 gives the empty neighbourhood).
pub fn causal(order: usize) -> &'static [(isize, isize)] {
    match order {
        0 => &[],
        k => &CAUSAL_OFFSETS[..ORDER_SIZES[k.min(MAX_ORDER) - 1]],
    }
}

/// How far a neighbourhood reaches: (rows above, columns to the left, columns to the right).
pub fn reach(offsets: &[(isize, isize)]) -> (usize, usize, usize) {
    offsets
        .iter()
        .fold((0, 0, 0), |(up, left, right), &(s1, s2)| {
            (
                up.max(s1.max(0) as usize),
                left.max(s2.max(0) as usize),
                right.max((-s2).max(0) as usize),
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_offset_is_causal_and_orders_nest() {
        for &(s1, s2) in &CAUSAL_OFFSETS {
            assert!(s1 > 0 || (s1 == 0 && s2 > 0), "({s1}, {s2})");
        }
        for k in 1..MAX_ORDER {
            assert!(causal(k + 1).starts_with(causal(k)));
        }
        assert_eq!(reach(causal(6)), (3, 3, 2));
        assert_eq!(causal(0).len(), 0);
    }
}
