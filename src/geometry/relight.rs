//! Bump shading of a range map under a light, with a measured strength (mrf_math.md 1(g)).
//!
//! The Lambertian ratio `s = max(0, n . l) / mean(max(0, n . l))` overstates how much a real
//! relief modulates a photograph at low lights: ambient light, interreflection and soft
//! shadows fill what the model leaves black (on the clay-leaf capture the ratio's relative
//! contrast reaches 2.4 at a 90 degree light, the photograph's 0.8). The shading factor used
//! here is `1 + k (s - 1)`, whose mean is still 1 (it moves no brightness), with a strength
//! `k` per measured light fitted to the photographs that the range map is registered with.

use ndarray::{Array2, Array3, Axis};

use super::integrate::{Edges, shading};

/// The smallest shading factor divided out of a photograph (deeper shadow is left as it is,
/// not amplified into noise), and so the smallest one synthesis multiplies back
/// ([`crate::synthesis::bump_relight`], the renderer's shader): a measured shadow divided by
/// it must come back at the measured light, not black.
pub const SHADING_FLOOR: f64 = 0.1;
/// Below this mean `max(0, n . l)` a light leaves the relief unlit and the ratio undefined.
const DARK: f64 = 1e-3;
/// Largest fitted strength (the plain Lambertian ratio).
pub const MAX_STRENGTH: f64 = 1.0;

/// The shading factor `1 + strength (s - 1)` of `heights` (texels, differences as `border`
/// says) under the unit light `l`, where `s` is the Lambertian ratio above; `None` when the
/// light leaves (almost) nothing lit. Shape of `heights`; mean 1.
pub fn shading_factor(
    heights: &Array2<f64>,
    border: Edges,
    l: [f64; 3],
    strength: f64,
) -> Option<Array2<f64>> {
    let shade = shading(heights, border, l);
    let mean = shade.mean()?;
    if mean < DARK {
        return None;
    }
    let a = strength / mean;
    Some(shade.mapv(|s| 1.0 - strength + a * s))
}

/// The strength `k` in `[0, MAX_STRENGTH]` that best explains `luminance` (linear, registered
/// with `heights`) as `mean * (1 + k (s - 1))` plus variation unrelated to the relief: the
/// least-squares slope of the photograph's relative deviation on the ratio's. 0 where the
/// light leaves the relief unlit or the relief does not vary under it.
pub fn fit_strength(luminance: &Array2<f64>, heights: &Array2<f64>, l: [f64; 3]) -> f64 {
    let Some(s) = shading_factor(heights, Edges::Clamp, l, 1.0) else {
        return 0.0;
    };
    let mean = luminance.mean().unwrap_or(0.0);
    if mean <= 0.0 {
        return 0.0;
    }
    let (mut sp, mut ss) = (0.0, 0.0);
    for (&p, &s) in luminance.iter().zip(&s) {
        let (dp, ds) = (p / mean - 1.0, s - 1.0);
        sp += dp * ds;
        ss += ds * ds;
    }
    if ss <= 1e-12 * s.len() as f64 {
        return 0.0;
    }
    (sp / ss).clamp(0.0, MAX_STRENGTH)
}

/// Linear luminance (Rec. 709 weights) of a planar (3, rows, cols) linear RGB image.
pub fn luminance(image: &Array3<f32>) -> Array2<f64> {
    let c = |k: usize| image.index_axis(Axis(0), k).mapv(f64::from);
    c(0) * 0.2126 + c(1) * 0.7152 + c(2) * 0.0722
}

/// Linear luminance below which a pixel's chromaticity is mostly quantisation and compression
/// noise: 10 of 255 sRGB levels, where one level moves a channel by 10 % or more.
const CHROMA_NOISE: f64 = 0.003;

/// Divides a measured image (registered with `heights`) by its shading factor under `l`
/// (floored at 0.1), leaving what the relief does not explain: the texture that bump mapping
/// is later applied to, so the measured relief shading is not applied twice. An unlit light
/// leaves the image as it is.
///
/// A pixel brightened by `g = 1 / factor > 1` that was darker than [`CHROMA_NOISE`] keeps its
/// luminance times `g`, but its chromaticity is drawn towards the image's mean chromaticity
/// (own share `r + (1 - r) / g`, `r = (Y / CHROMA_NOISE)^2`): the noise of a deep shadow's
/// colour would otherwise be lifted to a visible lightness (blue specks on a capture at a
/// grazing light).
pub fn remove_shading(image: &mut Array3<f32>, heights: &Array2<f64>, l: [f64; 3], strength: f64) {
    if let Some(factor) = shading_factor(heights, Edges::Clamp, l, strength) {
        divide_shading(image, &factor);
    }
}

/// Divides `image` by `factor` (same rows and columns, floored at [`SHADING_FLOOR`]), drawing the
/// chromaticity of brightened noise-dark pixels towards the mean as [`remove_shading`] says.
fn divide_shading(image: &mut Array3<f32>, factor: &Array2<f64>) {
    let lum = luminance(image);
    let mean = mean_chromaticity(image, &lum);
    let (_, h, w) = image.dim();
    for y in 0..h {
        for x in 0..w {
            let g = 1.0 / factor[[y, x]].max(SHADING_FLOOR);
            let own = match mean {
                Some(_) if g > 1.0 => {
                    let r = (lum[[y, x]] / CHROMA_NOISE).powi(2).min(1.0);
                    r + (1.0 - r) / g
                }
                _ => 1.0,
            };
            for c in 0..3 {
                let v = f64::from(image[[c, y, x]]);
                let toward = mean.map_or(v, |m| m[c] * lum[[y, x]]);
                image[[c, y, x]] = (g * (own * v + (1.0 - own) * toward)) as f32;
            }
        }
    }
}

/// The image's mean chromaticity as linear RGB of unit luminance: channel sums over the
/// luminance sum of the pixels brighter than [`CHROMA_NOISE`] (of all pixels when none is);
/// `None` for a black image.
fn mean_chromaticity(image: &Array3<f32>, lum: &Array2<f64>) -> Option<[f64; 3]> {
    let sums = |threshold: f64| {
        let mut s = [0.0f64; 4];
        for ((y, x), &l) in lum.indexed_iter() {
            if l >= threshold {
                for c in 0..3 {
                    s[c] += f64::from(image[[c, y, x]]);
                }
                s[3] += l;
            }
        }
        s
    };
    let mut s = sums(CHROMA_NOISE);
    if s[3] <= 0.0 {
        s = sums(f64::NEG_INFINITY);
    }
    (s[3] > 0.0).then(|| [s[0] / s[3], s[1] / s[3], s[2] / s[3]])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn relief() -> Array2<f64> {
        Array2::from_shape_fn((40, 50), |(y, x)| {
            2.0 * ((x as f64) / 3.0).sin() + 1.5 * ((y as f64) / 4.0 + 0.3 * x as f64).cos()
        })
    }

    fn light(theta_deg: f64, phi_deg: f64) -> [f64; 3] {
        let (st, ct) = theta_deg.to_radians().sin_cos();
        let (sp, cp) = phi_deg.to_radians().sin_cos();
        [st * cp, st * sp, ct]
    }

    #[test]
    fn factor_has_mean_one_and_interpolates_the_strength() {
        let h = relief();
        let l = light(60.0, 30.0);
        let full = shading_factor(&h, Edges::Clamp, l, 1.0).unwrap();
        let none = shading_factor(&h, Edges::Clamp, l, 0.0).unwrap();
        let half = shading_factor(&h, Edges::Clamp, l, 0.5).unwrap();
        assert!((full.mean().unwrap() - 1.0).abs() < 1e-12);
        assert!(none.iter().all(|&v| (v - 1.0).abs() < 1e-12));
        for ((f, h), n) in full.iter().zip(&half).zip(&none) {
            assert!((h - 0.5 * (f + n)).abs() < 1e-12);
        }
        // A light below the horizon of a flat map lights nothing.
        let flat = Array2::zeros((8, 8));
        assert!(shading_factor(&flat, Edges::Clamp, light(95.0, 0.0), 1.0).is_none());
    }

    #[test]
    fn removing_the_shading_undoes_it() {
        let h = relief();
        let l = light(50.0, 200.0);
        let f = shading_factor(&h, Edges::Clamp, l, 0.7).unwrap();
        assert!(f.iter().all(|&v| v > SHADING_FLOOR));
        let albedo = Array3::from_shape_fn((3, 40, 50), |(c, y, x)| {
            0.2 + 0.1 * c as f32 + 0.01 * ((x + y) % 5) as f32
        });
        let mut shaded = albedo.clone();
        for mut ch in shaded.axis_iter_mut(Axis(0)) {
            ch.zip_mut_with(&f, |v, s| *v *= *s as f32);
        }
        let lum = luminance(&shaded);
        assert!(
            (lum[(3, 4)]
                - (0.2126 * shaded[[0, 3, 4]] as f64
                    + 0.7152 * shaded[[1, 3, 4]] as f64
                    + 0.0722 * shaded[[2, 3, 4]] as f64))
                .abs()
                < 1e-6
        );
        remove_shading(&mut shaded, &h, l, 0.7);
        for (a, b) in shaded.iter().zip(&albedo) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    #[test]
    fn brightened_shadows_lose_their_noise_chroma_not_their_lightness() {
        // Yellowish lit pixels, one bright and one noise-dark blue pixel in shadow (factor
        // 0.2, brightened 5x) and one noise-dark blue pixel in the light (factor 1.5).
        let mut image = Array3::from_shape_fn((3, 2, 4), |(c, _, _)| [0.5f32, 0.45, 0.2][c]);
        let blue = [0.0004f32, 0.0004, 0.004];
        for c in 0..3 {
            image[[c, 1, 0]] = blue[c];
            image[[c, 1, 1]] = blue[c];
            image[[c, 1, 2]] = [0.3f32, 0.1, 0.05][c];
        }
        let mut factor = Array2::from_elem((2, 4), 1.0);
        factor[[1, 0]] = 0.2;
        factor[[1, 1]] = 1.5;
        factor[[1, 2]] = 0.2;
        let before = luminance(&image);
        let mut out = image.clone();
        divide_shading(&mut out, &factor);
        let after = luminance(&out);
        for ((y, x), &f) in factor.indexed_iter() {
            let want = before[[y, x]] / f;
            assert!(
                (after[[y, x]] - want).abs() < 1e-6 * want.max(1e-3),
                "{y},{x}"
            );
        }
        let chroma = |im: &Array3<f32>, x: usize| {
            let s: f32 = (0..3).map(|c| im[[c, 1, x]]).sum();
            [im[[0, 1, x]] / s, im[[2, 1, x]] / s]
        };
        // The shadowed dark pixel moves over half the way to the mean chromaticity (its own
        // share, 0.24 of its luminance, is a blue with a large channel sum).
        let m = mean_chromaticity(&image, &before).unwrap();
        let lit = [m[0] / m.iter().sum::<f64>(), m[2] / m.iter().sum::<f64>()].map(|v| v as f32);
        let (was, now) = (chroma(&image, 0), chroma(&out, 0));
        assert!(
            (now[1] - lit[1]).abs() < 0.6 * (was[1] - lit[1]).abs(),
            "{now:?}"
        );
        // Not brightened, or bright enough to trust: chromaticity kept.
        for x in [1, 2] {
            let (was, now) = (chroma(&image, x), chroma(&out, x));
            assert!((was[0] - now[0]).abs() < 1e-5 && (was[1] - now[1]).abs() < 1e-5);
        }
    }

    #[test]
    fn fitted_strength_recovers_the_generating_one() {
        let h = relief();
        let l = light(70.0, 120.0);
        let albedo = Array2::from_shape_fn(h.dim(), |(y, x)| {
            0.4 + 0.05 * (((y * 7 + x * 13) % 11) as f64 / 11.0 - 0.5)
        });
        for k in [0.0, 0.35, 0.8] {
            let f = shading_factor(&h, Edges::Clamp, l, k).unwrap();
            let photo = &albedo * &f;
            let fit = fit_strength(&photo, &h, l);
            assert!((fit - k).abs() < 0.05, "{k}: fitted {fit}");
        }
        // Out of range is clamped; unlit gives 0.
        let f = shading_factor(&h, Edges::Clamp, l, 1.0).unwrap();
        let steep = f.mapv(|v| 1.0 + 2.0 * (v - 1.0));
        assert_eq!(fit_strength(&steep, &h, l), MAX_STRENGTH);
        let flat = Array2::zeros((8, 8));
        assert_eq!(
            fit_strength(&Array2::ones((8, 8)), &flat, light(95.0, 0.0)),
            0.0
        );
    }
}
