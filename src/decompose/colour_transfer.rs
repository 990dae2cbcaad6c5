//! Joint colour matching by sliced transport (Pitie, Kokaram and Dahyot 2005, "N-dimensional
//! probability density function transfer"): the KL factors of a subspace image are synthesized
//! independently, so combinations the material never shows appear (a dark pixel with the
//! chroma of a bright one is a saturated speck outside the measured colours) although each
//! factor's marginal is right. Matching the marginals of the pixel colours along several fixed
//! rotations of the colour axes, in turn, moves the joint distribution towards the measured one
//! (each step is a monotone map per axis, so it costs one pass over the pixels and keeps
//! tileability and spatial structure). The model stores one quantile table per direction.

use ndarray::{Array2, Zip};

use super::marginals::{self, MarginalMap, band_probabilities, quantiles_at};

/// Orthonormal colour bases the marginals are matched along: the colour axes themselves
/// (last at synthesis, so the L*, a*, b* marginals end exact) and three fixed rotations.
pub const ROTATIONS: usize = 4;

/// Quantile tables stored per subspace image: three axes per rotation.
pub const DIRECTIONS: usize = 3 * ROTATIONS;

/// Passes over the rotations at synthesis (the transfer converges in a few).
const PASSES: usize = 3;

/// Unit quaternions (w, x, y, z) of the three fixed rotations: axes far from the colour axes
/// and from each other, angles of 50 to 70 degrees.
const QUATERNIONS: [[f64; 4]; 3] = [
    [0.866, 0.289, 0.289, 0.289],
    [0.819, -0.409, 0.330, 0.234],
    [0.906, 0.122, -0.287, 0.289],
];

/// Rotation `i` as rows (the axes): the identity for 0, else from [`QUATERNIONS`].
fn rotation(i: usize) -> [[f64; 3]; 3] {
    if i == 0 {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let q = QUATERNIONS[i - 1];
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|v| v / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// The three projections of colour planes on the axes of `basis` (rows).
fn project(planes: &[Array2<f64>; 3], basis: &[[f64; 3]; 3]) -> [Array2<f64>; 3] {
    basis.map(|axis| {
        let mut p = Array2::zeros(planes[0].dim());
        Zip::from(&mut p)
            .and(&planes[0])
            .and(&planes[1])
            .and(&planes[2])
            .par_for_each(|p, &a, &b, &c| *p = dot(axis, [a, b, c]));
        p
    })
}

/// `axis . colour`, summed in coordinate order.
#[inline]
fn dot(axis: [f64; 3], colour: [f64; 3]) -> f64 {
    axis[0] * colour[0] + axis[1] * colour[1] + axis[2] * colour[2]
}

/// Equal-count bins of the first colour coordinate (L*) over which [`ColourMarginals`] keeps
/// the mean of the other two.
pub const LIGHTNESS_BINS: usize = 8;

/// How the second and third colour coordinates (a*, b*) follow the first (L*): per
/// equal-count bin of the first, darkest first, their mean less their overall mean.
pub type Coupling = [[f64; 2]; LIGHTNESS_BINS];

/// The measured colour marginals of a subspace image: `tables[3 r + k]` holds the quantiles
/// (at [`band_probabilities`]) of the colours projected on axis `k` of rotation `r`.
#[derive(Debug, Clone, PartialEq)]
pub struct ColourMarginals {
    /// [`DIRECTIONS`] non-decreasing tables.
    pub tables: Vec<Vec<f64>>,
    /// The chroma's dependence on lightness ([`Coupling`]); `None` in model files before
    /// version 7. Sliced matching along a few rotations leaves much of it out: the darkest
    /// synthesized pixels kept the material's mean chroma, saturated specks that a relief
    /// brightened into view (1.5 % of the leather's pixels under a 75-degree light).
    pub coupling: Option<Coupling>,
}

/// The [`Coupling`] of colour planes: pixels ranked by the first plane, cut into
/// [`LIGHTNESS_BINS`] runs of equal count.
fn coupling_of(planes: &[Array2<f64>; 3]) -> Coupling {
    let [first, a, b] = planes
        .each_ref()
        .map(|p| p.iter().copied().collect::<Vec<f64>>());
    let n = first.len();
    let mut coupling = [[0.0; 2]; LIGHTNESS_BINS];
    if n < LIGHTNESS_BINS {
        return coupling;
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| first[i].total_cmp(&first[j]));
    let mean = |v: &[f64]| v.iter().sum::<f64>() / n as f64;
    let (ma, mb) = (mean(&a), mean(&b));
    for (k, bin) in coupling.iter_mut().enumerate() {
        let run = &order[k * n / LIGHTNESS_BINS..(k + 1) * n / LIGHTNESS_BINS];
        let len = run.len() as f64;
        *bin = [
            run.iter().map(|&i| a[i]).sum::<f64>() / len - ma,
            run.iter().map(|&i| b[i]).sum::<f64>() / len - mb,
        ];
    }
    coupling
}

/// The coupling's shift at the lightness quantile `u` (0..1): linear between bin centres,
/// constant beyond the outer ones.
fn coupling_at(coupling: &Coupling, u: f64) -> [f64; 2] {
    let t = (u * LIGHTNESS_BINS as f64 - 0.5).clamp(0.0, (LIGHTNESS_BINS - 1) as f64);
    let k = (t as usize).min(LIGHTNESS_BINS - 2);
    let f = t - k as f64;
    [0, 1].map(|c| coupling[k][c] + (coupling[k + 1][c] - coupling[k][c]) * f)
}

impl ColourMarginals {
    /// The marginals of colour planes (the model's colour space, `(h, w)` each).
    pub fn measure(planes: &[Array2<f64>; 3]) -> Self {
        let probabilities = band_probabilities();
        let tables = (0..ROTATIONS)
            .flat_map(|r| project(planes, &rotation(r)))
            .map(|p| quantiles_at(&p, &probabilities))
            .collect();
        Self {
            tables,
            coupling: Some(coupling_of(planes)),
        }
    }

    /// Shifts the second and third coordinates of `planes` by the coupling at each pixel's
    /// lightness quantile (in the measured first table): independently synthesized factors
    /// regain the measured chroma of their lightness. Nothing without a coupling.
    fn couple(&self, planes: &mut [Array2<f64>; 3]) {
        let Some(coupling) = &self.coupling else {
            return;
        };
        let [first, a, b] = planes;
        let rank = MarginalMap::between(self.tables[0].clone(), &band_probabilities(), first.len());
        Zip::from(&*first).and(a).and(b).par_for_each(|&l, a, b| {
            let [da, db] = coupling_at(coupling, rank.apply(l));
            *a += da;
            *b += db;
        });
    }

    /// Moves the colours of `planes` towards these marginals: the coupling first
    /// ([`ColourMarginals::couple`]), then [`PASSES`] passes over the rotations, each axis
    /// matched in turn, the colour axes last.
    ///
    /// Each rotation is one pass over the pixels, in place; its three maps come from the
    /// projected colours of the regular subsample that
    /// [`quantiles_at`](crate::decompose::marginals::quantiles_at) takes of a plane.
    pub fn transfer(&self, planes: &mut [Array2<f64>; 3]) {
        self.couple(planes);
        let probabilities = band_probabilities();
        let (len, cols) = (planes[0].len(), planes[0].ncols());
        let stride = marginals::sample_step(len, cols);
        let order = (1..ROTATIONS).chain([0]);
        for r in std::iter::repeat_n(order, PASSES).flatten() {
            let basis = rotation(r);
            let [l, a, b] = planes;
            let subsample: Vec<[f64; 3]> = (l.iter().step_by(stride))
                .zip(a.iter().step_by(stride))
                .zip(b.iter().step_by(stride))
                .map(|((&l, &a), &b)| [l, a, b])
                .collect();
            let maps: [MarginalMap; 3] = std::array::from_fn(|k| {
                let axis = basis[k];
                let projected = subsample.iter().map(|c| dot(axis, *c));
                let quantiles = marginals::sample_quantiles(projected, &probabilities);
                MarginalMap::between(quantiles, &self.tables[3 * r + k], len)
            });
            Zip::from(l).and(a).and(b).par_for_each(|l, a, b| {
                let colour = [*l, *a, *b];
                let p: [f64; 3] = std::array::from_fn(|k| maps[k].apply(dot(basis[k], colour)));
                // Back to the colour axes: the basis is orthonormal, so its transpose inverts it.
                let back = |c: usize| dot([basis[0][c], basis[1][c], basis[2][c]], p);
                (*l, *a, *b) = (back(0), back(1), back(2));
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotations_are_orthonormal() {
        for i in 0..ROTATIONS {
            let r = rotation(i);
            for a in 0..3 {
                for b in 0..3 {
                    let dot: f64 = (0..3).map(|c| r[a][c] * r[b][c]).sum();
                    assert!((dot - f64::from(u8::from(a == b))).abs() < 1e-12, "{i}");
                }
            }
        }
    }

    /// Colours that depend on each other: the second and third coordinates scale with the
    /// first (chroma proportional to lightness), as in a measured material.
    fn dependent(n: usize, shift: usize) -> [Array2<f64>; 3] {
        let l = Array2::from_shape_fn((n, n), |(y, x)| {
            (((x * 7 + y * 13 + shift) % 101) as f64) / 100.0 * 60.0 + 20.0
        });
        let a = l.mapv(|v| 0.4 * v);
        let b = l.mapv(|v| 0.3 * v);
        [l, a, b]
    }

    #[test]
    fn independent_factors_regain_the_measured_dependence() {
        // Measured: a* = 0.4 L*, b* = 0.3 L*. The synthesis has the right marginals, each
        // shuffled independently, so a* no longer follows L*: the transfer restores it.
        let measured = dependent(64, 0);
        let marginals = ColourMarginals::measure(&measured);
        let [l, a, b] = dependent(64, 0);
        let shuffle = |p: &Array2<f64>, k: usize| {
            let v: Vec<f64> = p.iter().copied().collect();
            let n = v.len();
            Array2::from_shape_fn(p.dim(), |(y, x)| v[((y * 64 + x) * k + 11) % n])
        };
        let mut synth = [l, shuffle(&a, 37), shuffle(&b, 53)];
        let error = |s: &[Array2<f64>; 3]| {
            Zip::from(&s[0])
                .and(&s[1])
                .fold(0.0, |acc, &l, &a| acc + (a - 0.4 * l).abs())
                / s[0].len() as f64
        };
        let before = error(&synth);
        marginals.transfer(&mut synth);
        let after = error(&synth);
        assert!(before > 3.0, "{before}");
        // Three passes remove about 70% of it on this degenerate (one-dimensional) target.
        assert!(after < 0.35 * before, "{before} -> {after}");
        // The marginals along the colour axes end matched.
        let probabilities = band_probabilities();
        for (k, plane) in synth.iter().enumerate() {
            let q = quantiles_at(plane, &probabilities);
            for (got, want) in q.iter().zip(&marginals.tables[k]) {
                assert!((got - want).abs() < 0.5, "axis {k}: {got} vs {want}");
            }
        }
    }

    #[test]
    fn the_darkest_pixels_regain_the_chroma_of_the_darkest_measured() {
        // Measured: a* = 0.4 L*. Synthesized: the right L*, a* constant at its mean. The
        // coupling alone (bin means, linear between bin centres) brings the darkest eighth's
        // a* down near its measured mean.
        let measured = dependent(64, 0);
        let marginals = ColourMarginals::measure(&measured);
        let coupling = marginals.coupling.unwrap();
        // Bin means rise with lightness and sum to zero (deviations from the overall mean).
        assert!(coupling.windows(2).all(|w| w[1][0] > w[0][0]));
        assert!(coupling.iter().map(|c| c[0]).sum::<f64>().abs() < 1e-9);
        let mean_a = measured[1].mean().unwrap();
        let mut synth = [
            measured[0].clone(),
            measured[1].mapv(|_| mean_a),
            measured[2].clone(),
        ];
        marginals.couple(&mut synth);
        let dark: Vec<(f64, f64)> = synth[1]
            .iter()
            .zip(&measured[1])
            .zip(&measured[0])
            .filter(|(_, l)| **l < 27.0)
            .map(|((s, m), _)| (*s, *m))
            .collect();
        let n = dark.len() as f64;
        let (s, m) = dark
            .iter()
            .fold((0.0, 0.0), |(a, b), (s, m)| (a + s / n, b + m / n));
        assert!(
            (s - m).abs() < 0.1 * (mean_a - m),
            "{s} vs measured {m} (mean {mean_a})"
        );
        // Between bin centres the shift is linear; beyond the outer centres, constant.
        assert_eq!(coupling_at(&coupling, 0.0), coupling[0]);
        assert_eq!(coupling_at(&coupling, 1.0), coupling[LIGHTNESS_BINS - 1]);
        let mid = coupling_at(&coupling, 1.0 / LIGHTNESS_BINS as f64);
        assert!((mid[0] - 0.5 * (coupling[0][0] + coupling[1][0])).abs() < 1e-12);
    }

    #[test]
    fn measured_colours_are_left_almost_unchanged() {
        let measured = dependent(48, 5);
        let marginals = ColourMarginals::measure(&measured);
        let mut same = measured.clone();
        marginals.transfer(&mut same);
        for (a, b) in same.iter().zip(&measured) {
            let worst = Zip::from(a)
                .and(b)
                .fold(0.0f64, |m, &x, &y| m.max((x - y).abs()));
            assert!(worst < 0.5, "{worst}");
        }
    }
}
