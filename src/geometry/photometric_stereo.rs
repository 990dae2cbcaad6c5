//! Over-determined photometric stereo on the frontal (or only) view of a BTF (seed 001,
//! sec. 5.3; mrf_math.md 1(b)): per pixel, a robust least-squares fit of
//! `I_j = g . l_j + c` over the lights j, giving the normal `g / |g|` and the albedo `|g|`.
//! The constant c absorbs ambient light. A first fit drops the darkest 20 % of a pixel's
//! samples (shadows) and the brightest 10 % (highlights), as well as grazing lights; refits
//! then keep the lights that fit says are lit: facing the normal and not far darker than it
//! predicts (a cast shadow). On steep relief a fixed share is not enough: a pit's wall is in
//! attached or cast shadow under half the lights, and the first fit alone flattened the
//! built-in sponge's and stones' normals (heights 0.64-0.68 of the true relief, correlation
//! 0.73-0.78; with the refits 0.76-0.88 and 0.93-0.97). A pixel whose lights are too few or too
//! coplanar falls back to the straight-up normal.

use nalgebra::{Matrix4, Vector4};
use ndarray::{Array2, Array3};
use rayon::prelude::*;

use crate::btf::{Btf, BtfError};
use crate::progress::Progress;

/// Lights more grazing than this are not used (degrees from the normal).
pub const MAX_LIGHT_THETA_DEG: f64 = 80.0;
/// Fraction of each pixel's darkest samples treated as shadowed.
const SHADOW_FRACTION: f64 = 0.2;
/// Fraction of each pixel's brightest samples treated as specular.
const HIGHLIGHT_FRACTION: f64 = 0.1;

/// Normals and albedo estimated from the lights of one view.
#[derive(Debug, Clone)]
pub struct NormalMap {
    /// Unit normals (x right, y up in the image, z out of the surface), shape (3, h, w).
    pub normals: Array3<f64>,
    /// Luminance albedo, shape (h, w).
    pub albedo: Array2<f64>,
    /// Pixels that fell back to the straight-up normal (too few usable lights).
    pub fallback_pixels: usize,
    /// The number of lights used.
    pub lights_used: usize,
}

/// The index of the view closest to straight down.
pub fn frontal_view(btf: &Btf) -> usize {
    (0..btf.views().len())
        .min_by(|&a, &b| {
            let t = |i: usize| btf.views().get(i).map_or(f64::MAX, |d| d.theta_deg);
            t(a).total_cmp(&t(b))
        })
        .unwrap_or(0)
}

/// Estimates normals from every light of view `view` up to [`MAX_LIGHT_THETA_DEG`].
///
/// # Errors
/// An image cannot be read, or fewer than 3 usable lights (the error names the BTF).
pub fn estimate_normals(
    btf: &Btf,
    view: usize,
    progress: &dyn Progress,
) -> Result<NormalMap, BtfError> {
    let lights: Vec<(usize, [f64; 3])> = btf
        .lights()
        .iter()
        .enumerate()
        .filter(|(_, d)| d.theta_deg <= MAX_LIGHT_THETA_DEG)
        .map(|(i, d)| (i, d.vector()))
        .collect();
    if lights.len() < 3 {
        return Err(BtfError::layout(
            btf.label(),
            format!(
                "photometric stereo needs at least 3 lights within {MAX_LIGHT_THETA_DEG} degrees of the normal; {} found",
                lights.len()
            ),
        ));
    }
    progress.start("photometric stereo", lights.len() as u64);
    let (h, w) = (btf.height() as usize, btf.width() as usize);
    // Luminance of every light's image: lights x pixels.
    let luminance: Vec<Vec<f32>> = lights
        .par_iter()
        .map(|&(l, _)| {
            let im = btf.image(view, l)?;
            progress.advance(1);
            Ok((0..h * w)
                .map(|k| {
                    let (y, x) = (k / w, k % w);
                    0.2126 * im[[0, y, x]] + 0.7152 * im[[1, y, x]] + 0.0722 * im[[2, y, x]]
                })
                .collect())
        })
        .collect::<Result<_, BtfError>>()?;
    progress.finish();
    let fits: Vec<Option<([f64; 3], f64)>> = (0..h * w)
        .into_par_iter()
        .map(|k| fit_pixel(&lights, |j| f64::from(luminance[j][k])))
        .collect();
    let mut normals = Array3::<f64>::zeros((3, h, w));
    let mut albedo = Array2::<f64>::zeros((h, w));
    let mut fallback_pixels = 0;
    for (k, fit) in fits.into_iter().enumerate() {
        let (y, x) = (k / w, k % w);
        let (n, rho) = fit.unwrap_or_else(|| {
            fallback_pixels += 1;
            ([0.0, 0.0, 1.0], 0.0)
        });
        for c in 0..3 {
            normals[[c, y, x]] = n[c];
        }
        albedo[[y, x]] = rho;
    }
    Ok(NormalMap {
        normals,
        albedo,
        fallback_pixels,
        lights_used: lights.len(),
    })
}

/// The robust fit of one pixel: a first fit on the lights left after dropping shadows and
/// highlights by rank, then [`REFINEMENTS`] refits on the lights the previous fit says are
/// lit ([`lit_by_fit`]).
fn fit_pixel(
    lights: &[(usize, [f64; 3])],
    intensity: impl Fn(usize) -> f64,
) -> Option<([f64; 3], f64)> {
    let mut order: Vec<usize> = (0..lights.len()).collect();
    order.sort_by(|&a, &b| intensity(a).total_cmp(&intensity(b)));
    let n = order.len();
    let lo = ((n as f64 * SHADOW_FRACTION) as usize).min(n.saturating_sub(3));
    let hi = (n - (n as f64 * HIGHLIGHT_FRACTION) as usize)
        .max(lo + 3)
        .min(n);
    let mut fit = solve(lights, &order[lo..hi], &intensity)?;
    // The brightest (order[hi..]) stay out as highlights.
    for _ in 0..REFINEMENTS {
        let kept: Vec<usize> = order[..hi]
            .iter()
            .copied()
            .filter(|&j| lit_by_fit(&fit, lights[j].1, intensity(j)))
            .collect();
        match solve(lights, &kept, &intensity) {
            Some(refined) => fit = refined,
            None => break,
        }
    }
    normal_of(fit)
}

/// Refits of [`fit_pixel`] on the lights its previous fit explains.
const REFINEMENTS: usize = 3;
/// A light is left out of a refit where the previous fit's `n . l` is below this (attached
/// shadow and grazing light, where the clamped cosine is not the linear model's) ...
const MIN_COSINE: f64 = 0.1;
/// ... or where the sample is darker than the ambient plus this share of the fit's direct
/// term (a cast shadow: the relief hides the light the normal faces).
const CAST_SHADOW_SHARE: f64 = 0.5;

/// Whether a light `l` with measured `intensity` is lit as the fit `[g, c]` (`g` = albedo
/// times normal, `c` the constant) sees it: facing it by [`MIN_COSINE`] and not darker than a
/// cast shadow would make it.
fn lit_by_fit(fit: &[f64; 4], l: [f64; 3], intensity: f64) -> bool {
    let rho = fit[..3].iter().map(|v| v * v).sum::<f64>().sqrt();
    let direct = fit[0] * l[0] + fit[1] * l[1] + fit[2] * l[2];
    direct > MIN_COSINE * rho && intensity >= fit[3] + CAST_SHADOW_SHARE * direct
}

/// Least squares of `I_j = g . l_j + c` over the lights `used`; `None` where the system is
/// singular or ill-conditioned (too few or too coplanar lights).
fn solve(
    lights: &[(usize, [f64; 3])],
    used: &[usize],
    intensity: &impl Fn(usize) -> f64,
) -> Option<[f64; 4]> {
    if used.len() < 4 {
        return None;
    }
    let mut ata = Matrix4::<f64>::zeros();
    let mut atb = Vector4::<f64>::zeros();
    for &j in used {
        let l = lights[j].1;
        let row = Vector4::new(l[0], l[1], l[2], 1.0);
        ata += row * row.transpose();
        atb += row * intensity(j);
    }
    let eig = ata.symmetric_eigenvalues();
    let (min, max) = eig
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), &e| (a.min(e), b.max(e.abs())));
    if min.is_nan() || min <= 0.0 || max / min > 1e6 {
        return None;
    }
    let sol = ata.cholesky()?.solve(&atb);
    Some([sol[0], sol[1], sol[2], sol[3]])
}

/// The unit normal and albedo of a fit; `None` where it is degenerate or faces away.
fn normal_of(fit: [f64; 4]) -> Option<([f64; 3], f64)> {
    let g = [fit[0], fit[1], fit[2]];
    let rho = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
    if !rho.is_finite() || rho < 1e-9 || g[2] <= 0.05 * rho {
        return None;
    }
    Some((g.map(|v| v / rho), rho))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_lambertian_data_gives_the_exact_normal() {
        let n = [0.3f64, -0.2, (1.0f64 - 0.09 - 0.04).sqrt()];
        let lights: Vec<(usize, [f64; 3])> = (0..12)
            .map(|k| {
                let (t, p) = (20f64 + 4.0 * k as f64, 30.0 * k as f64);
                let d = crate::btf::Direction::new(t, p).vector();
                (k, d)
            })
            .collect();
        let shade = |j: usize| {
            0.7 * (lights[j].1.iter().zip(&n).map(|(a, b)| a * b).sum::<f64>()).max(0.0) + 0.02
        };
        let (est, rho) = fit_pixel(&lights, shade).unwrap();
        let angle = est
            .iter()
            .zip(&n)
            .map(|(a, b)| a * b)
            .sum::<f64>()
            .acos()
            .to_degrees();
        assert!(angle < 0.5, "{angle}");
        assert!((rho - 0.7).abs() < 0.02, "{rho}");
    }

    #[test]
    fn a_steep_facet_in_attached_and_cast_shadow_gets_its_normal_from_the_lights_that_reach_it() {
        // A facet tilted 40 degrees towards +x, with ambient light; lights on the -x side
        // graze or miss it (attached shadow) and a wall on its +y side hides the lights from
        // around +y below 50 degrees of elevation (cast shadow).
        let t = 40f64.to_radians();
        let n = [t.sin(), 0.0, t.cos()];
        let lights: Vec<(usize, [f64; 3])> = (0..48)
            .map(|k| {
                let d = crate::btf::Direction::new(10.0 + 10.0 * (k % 7) as f64, 7.5 * k as f64);
                (k, d.vector())
            })
            .collect();
        let hidden = |l: [f64; 3]| l[1] > 0.4 && l[2] < 0.77;
        let shade = |j: usize| {
            let l = lights[j].1;
            let cosine = l.iter().zip(&n).map(|(a, b)| a * b).sum::<f64>().max(0.0);
            0.6 * (0.15 + if hidden(l) { 0.0 } else { cosine })
        };
        let angle = |est: [f64; 3]| {
            est.iter()
                .zip(&n)
                .map(|(a, b)| a * b)
                .sum::<f64>()
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees()
        };
        let (est, rho) = fit_pixel(&lights, shade).unwrap();
        assert!(angle(est) < 1.0, "{}", angle(est));
        assert!((rho - 0.6).abs() < 0.02, "{rho}");
        // The first fit alone (the darkest fifth and brightest tenth dropped) is 7 degrees off.
        let mut order: Vec<usize> = (0..lights.len()).collect();
        order.sort_by(|&a, &b| shade(a).total_cmp(&shade(b)));
        let first = normal_of(solve(&lights, &order[9..44], &shade).unwrap()).unwrap();
        assert!(angle(first.0) > 5.0, "{}", angle(first.0));
    }

    #[test]
    fn coplanar_lights_fall_back() {
        // All lights in the x-z plane: the y component is undetermined.
        let lights: Vec<(usize, [f64; 3])> = (0..6)
            .map(|k| {
                let t = (k as f64 * 10.0 - 25.0).to_radians();
                (k, [t.sin(), 0.0, t.cos()])
            })
            .collect();
        assert!(fit_pixel(&lights, |j| 0.5 + 0.1 * j as f64).is_none());
    }
}
