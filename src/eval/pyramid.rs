//! An oriented multi-scale pyramid for the texture judge: the steerable pyramid of Simoncelli
//! and Freeman (1995) as Portilla and Simoncelli (2000, sec. 2) use it, built in the frequency
//! domain and left undecimated (every band keeps the input's size; statistics at scale `s`
//! use lags of `2^s` pixels instead of a subsampled grid).
//!
//! The filters are polar-separable and form a tight frame: at every frequency the squared
//! gains of the high-pass residual, of every real oriented band and of the low-pass residual
//! sum to 1. So the bands split the image's energy exactly (Parseval) and filtering each band
//! once more by its own gain and summing gives the image back. Each band is returned as an
//! analytic (complex) image: its real part is the real steerable band, its modulus the local
//! amplitude that the judge's magnitude statistics use.

use std::f64::consts::PI;

use ndarray::Array2;
use rustfft::num_complex::Complex64;

/// The highest frequency of the first oriented scale's pass band, cycles per pixel: above
/// half of it the high-pass residual takes over.
const FIRST_EDGE: f64 = 0.25;

/// An image split into a high-pass residual, `scales x orientations` analytic oriented bands
/// and the low-pass images between the scales.
#[derive(Debug, Clone)]
pub struct OrientedPyramid {
    /// High-pass residual (frequencies from 0.25 cycles/pixel up), the input's shape.
    pub highpass: Array2<f64>,
    /// `bands[s][k]`: scale `s` (pass band centred near `0.25 * 2^-s` cycles/pixel),
    /// orientation `k` (frequency angle `pi * k / orientations`); analytic, so the real part
    /// is the real band and the modulus its local amplitude.
    pub bands: Vec<Vec<Array2<Complex64>>>,
    /// `lowpass[s]`: what remains for scales `s..` (`lowpass[0]` is the input without its
    /// high-pass residual; the last, index `scales`, is the low-pass residual).
    pub lowpass: Vec<Array2<f64>>,
}

impl OrientedPyramid {
    /// Decomposes a plane (treated as periodic) into `scales` scales of `orientations` bands.
    ///
    /// # Panics
    /// If `scales` or `orientations` is 0.
    pub fn new(plane: &Array2<f64>, scales: usize, orientations: usize) -> Self {
        assert!(scales > 0 && orientations > 0, "a pyramid needs bands");
        let spectrum = crate::fft::forward(plane);
        let (rows, cols) = plane.dim();
        let polar = Array2::from_shape_fn((rows, cols), |(i, j)| {
            let (fy, fx) = (frequency(i, rows), frequency(j, cols));
            ((fx * fx + fy * fy).sqrt(), fy.atan2(fx))
        });
        let filtered = |gain: &dyn Fn(f64, f64) -> f64| {
            let mut out = spectrum.clone();
            out.zip_mut_with(&polar, |x, &(r, a)| *x *= gain(r, a));
            crate::fft::inverse(&out)
        };
        let highpass = filtered(&|r, _| highpass_gain(r, 2.0 * FIRST_EDGE)).mapv(|c| c.re);
        let lowpass = (0..=scales)
            .map(|s| filtered(&|r, _| lowpass_radial(r, s)).mapv(|c| c.re))
            .collect();
        let bands = (0..scales)
            .map(|s| {
                (0..orientations)
                    .map(|k| {
                        filtered(&|r, a| {
                            // Most of the plane lies outside a scale's octave: no angle there.
                            let radial = band_radial(r, s);
                            if radial == 0.0 {
                                return 0.0;
                            }
                            let c = (a - PI * k as f64 / orientations as f64).cos();
                            // One-sided (analytic): twice the gain on the half plane the band
                            // points to, none on the other; the real part sees the gain itself.
                            let side = if c > 0.0 { 2.0 } else { 0.0 };
                            radial * orientation_gain(c, orientations) * side
                        })
                    })
                    .collect()
            })
            .collect();
        Self {
            highpass,
            bands,
            lowpass,
        }
    }

    /// Number of oriented scales.
    pub fn scales(&self) -> usize {
        self.bands.len()
    }

    /// Number of orientations per scale.
    pub fn orientations(&self) -> usize {
        self.bands.first().map_or(0, Vec::len)
    }
}

/// Signed frequency of DFT bin `i` of `n`, cycles per sample, in (-0.5, 0.5].
fn frequency(i: usize, n: usize) -> f64 {
    if 2 * i <= n {
        i as f64 / n as f64
    } else {
        i as f64 / n as f64 - 1.0
    }
}

/// Where radius `r` lies in the octave transition below `edge`: 0 at `edge / 2`, 1 at `edge`.
fn transition(r: f64, edge: f64) -> f64 {
    if r <= edge / 2.0 {
        0.0
    } else if r >= edge {
        1.0
    } else {
        (2.0 * r / edge).log2()
    }
}

/// Low-pass gain with a raised-cosine octave transition ending at `edge` cycles/pixel.
fn lowpass_gain(r: f64, edge: f64) -> f64 {
    (PI / 2.0 * transition(r, edge)).cos()
}

/// The complementary high-pass gain: `lowpass^2 + highpass^2 = 1`.
fn highpass_gain(r: f64, edge: f64) -> f64 {
    (PI / 2.0 * transition(r, edge)).sin()
}

/// Edge of scale `s`'s pass band, cycles/pixel.
fn edge(s: usize) -> f64 {
    FIRST_EDGE * 0.5f64.powi(s as i32)
}

/// Radial gain of everything left for scales `s..` (the product of the low-passes above).
fn lowpass_radial(r: f64, s: usize) -> f64 {
    (0..s).fold(lowpass_gain(r, 2.0 * FIRST_EDGE), |g, j| {
        g * lowpass_gain(r, edge(j))
    })
}

/// Radial gain of scale `s`'s oriented bands.
fn band_radial(r: f64, s: usize) -> f64 {
    lowpass_radial(r, s) * highpass_gain(r, edge(s))
}

/// Angular gain `alpha |cos|^(K-1)` for `K` orientations, `c` the cosine of the angle to the
/// band's direction; `alpha` makes the squared gains of the `K` bands sum to 1 at every angle
/// (the mean of `cos^(2K-2)` over K equally spaced angles is `C(2K-2, K-1) / 4^(K-1)`).
fn orientation_gain(c: f64, orientations: usize) -> f64 {
    let n = orientations - 1;
    let mean_power =
        (0..n).fold(1.0, |acc, i| acc * (n + 1 + i) as f64 / (i + 1) as f64) / 4f64.powi(n as i32);
    c.abs().powi(n as i32) / (orientations as f64 * mean_power).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_plane(rows: usize, cols: usize) -> Array2<f64> {
        Array2::from_shape_fn((rows, cols), |(y, x)| {
            let (y, x) = (y as f64, x as f64);
            (0.3 * x + 0.1 * y).sin() + 0.5 * (0.05 * x * y).cos() + ((x * 7.0 + y * 13.0) % 5.0)
        })
    }

    fn energy(p: &Array2<f64>) -> f64 {
        p.iter().map(|v| v * v).sum()
    }

    #[test]
    fn angular_gains_partition_unity_at_every_angle() {
        for k in [1, 2, 3, 4, 6] {
            for step in 0..37 {
                let a = step as f64 * 0.17;
                let sum: f64 = (0..k)
                    .map(|i| orientation_gain((a - PI * i as f64 / k as f64).cos(), k).powi(2))
                    .sum();
                assert!((sum - 1.0).abs() < 1e-12, "K={k} angle {a}: {sum}");
            }
        }
    }

    #[test]
    fn the_bands_split_the_energy_exactly() {
        let plane = test_plane(48, 64);
        let p = OrientedPyramid::new(&plane, 3, 4);
        let bands: f64 = p
            .bands
            .iter()
            .flatten()
            .map(|b| energy(&b.mapv(|c| c.re)))
            .sum();
        let total = energy(&p.highpass) + bands + energy(&p.lowpass[3]);
        assert!(
            (total - energy(&plane)).abs() < 1e-9 * energy(&plane),
            "{total} vs {}",
            energy(&plane)
        );
    }

    #[test]
    fn filtering_each_band_again_and_summing_reconstructs_the_image() {
        let plane = test_plane(40, 36);
        let (scales, k) = (3, 4);
        let p = OrientedPyramid::new(&plane, scales, k);
        let (rows, cols) = plane.dim();
        let refilter = |part: &Array2<f64>, gain: &dyn Fn(f64, f64) -> f64| {
            let mut spectrum = crate::fft::forward(part);
            for ((i, j), x) in spectrum.indexed_iter_mut() {
                let (fy, fx) = (frequency(i, rows), frequency(j, cols));
                *x *= gain((fx * fx + fy * fy).sqrt(), fy.atan2(fx));
            }
            crate::fft::inverse_real(&spectrum)
        };
        let mut sum = refilter(&p.highpass, &|r, _| highpass_gain(r, 0.5));
        sum += &refilter(&p.lowpass[scales], &|r, _| lowpass_radial(r, scales));
        for (s, scale) in p.bands.iter().enumerate() {
            for (o, band) in scale.iter().enumerate() {
                sum += &refilter(&band.mapv(|c| c.re), &|r, a| {
                    band_radial(r, s) * orientation_gain((a - PI * o as f64 / k as f64).cos(), k)
                });
            }
        }
        let err = (&sum - &plane).iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(err < 1e-9, "max reconstruction error {err}");
    }

    /// A grating along orientation 1 puts its energy in band 1 of the scale matching its
    /// frequency; transposed (rotated a quarter turn, mirrored), it moves to band 3.
    #[test]
    fn a_grating_lands_in_its_orientation_and_moves_when_rotated() {
        let n = 64;
        // 6 cycles across along x and along y: radius 0.13 cycles/pixel at angle pi/4, inside
        // scale 1's pass band (which peaks at 0.125).
        let f = 6.0 / n as f64;
        let grating = Array2::from_shape_fn((n, n), |(y, x)| {
            (2.0 * PI * f * (x as f64 + y as f64)).cos()
        });
        let share = |plane: &Array2<f64>| -> Vec<f64> {
            let p = OrientedPyramid::new(plane, 3, 4);
            p.bands[1]
                .iter()
                .map(|b| energy(&b.mapv(|c| c.re)) / energy(plane))
                .collect()
        };
        // At its own angle a band takes alpha^2 = 0.8 of the energy, its neighbours 0.1 each.
        let along = share(&grating);
        assert!(along[1] > 0.75 && along[3] < 1e-6, "{along:?}");
        let across = share(&grating.t().slice(ndarray::s![.., ..;-1]).to_owned());
        assert!(across[3] > 0.75 && across[1] < 1e-6, "{across:?}");
        // The analytic band's modulus is the grating's (constant) amplitude.
        let p = OrientedPyramid::new(&grating, 3, 4);
        let m = p.bands[1][1].mapv(|c| c.norm());
        let (lo, hi) = m
            .iter()
            .fold((f64::MAX, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
        assert!(hi - lo < 0.05 * hi, "amplitude {lo}..{hi}");
    }
}
