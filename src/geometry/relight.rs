//! Bump shading of a range map under a light, with a measured strength (mrf_math.md 1(g)).
//!
//! The Lambertian ratio `s = max(0, n . l) / mean(max(0, n . l))` overstates how much a real
//! relief modulates a photograph at low lights: ambient light, interreflection and soft
//! shadows fill what the model leaves black (on the clay-leaf capture the ratio's relative
//! contrast reaches 2.4 at a 90 degree light, the photograph's 0.8). The shading factor used
//! here is `1 + k (s - 1)`, whose mean is still 1 (it moves no brightness), with a strength
//! `k` per measured light fitted to the photographs that the range map is registered with.

use ndarray::{Array2, Array3, Axis};

use rayon::prelude::*;

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

/// Which shadows the relief's shading holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Shadows {
    /// Only attached shadows: facets turned away from the light (`max(0, n . l)`).
    #[default]
    Attached,
    /// Attached and cast shadows: a texel whose way to the light the relief blocks is unlit
    /// ([`cast_light`]).
    Cast,
}

/// How a relief shades an image under one light: the strength `k` of the factor
/// `1 + k (s - 1)` and which shadows `s` holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shading {
    /// The bump strength in `[0, MAX_STRENGTH]`.
    pub strength: f64,
    /// Which shadows the ratio `s` holds.
    pub shadows: Shadows,
}

impl Shading {
    /// The plain Lambertian ratio with attached shadows only.
    pub const LAMBERT: Shading = Shading {
        strength: MAX_STRENGTH,
        shadows: Shadows::Attached,
    };
}

/// The shading factor `1 + strength (s - 1)` of `heights` (texels, differences as `border`
/// says) under the unit light `l`, where `s` is the Lambertian ratio above (times the cast
/// light where `shading.shadows` says); `None` when the light leaves (almost) nothing lit.
/// Shape of `heights`; mean 1.
pub fn shading_factor(
    heights: &Array2<f64>,
    border: Edges,
    l: [f64; 3],
    shading: Shading,
) -> Option<Array2<f64>> {
    let cast = (shading.shadows == Shadows::Cast).then(|| cast_light(heights, border, l));
    factor_of(
        lit_shading(heights, border, l, cast.as_ref()),
        shading.strength,
    )
}

/// The factor `1 + strength (s / mean(s) - 1)` of the lit shading `shade` (`s`); `None` when
/// (almost) nothing is lit.
fn factor_of(shade: Array2<f64>, strength: f64) -> Option<Array2<f64>> {
    let mean = shade.mean()?;
    if mean < DARK {
        return None;
    }
    let a = strength / mean;
    Some(shade.mapv(|s| 1.0 - strength + a * s))
}

/// `max(0, n . l)`, times the cast light `cast` where the relief casts shadows.
fn lit_shading(
    heights: &Array2<f64>,
    border: Edges,
    l: [f64; 3],
    cast: Option<&Array2<f64>>,
) -> Array2<f64> {
    let mut shade = shading(heights, border, l);
    if let Some(cast) = cast {
        shade *= cast;
    }
    shade
}

/// Height (texels) a sample must rise above the ray towards the light to block it: keeps a
/// smooth slope, sampled bilinearly, from shadowing itself.
const SHADOW_TOLERANCE: f64 = 0.05;

/// Most one-texel steps a shadow ray takes (the renderer's shader marches as many): a
/// grazing light over a tall relief is cut short rather than marched across a large texture.
pub const MAX_SHADOW_STEPS: usize = 256;

/// A height field (texels; rows down, y up, borders as `border` says) ready to cast shadows
/// ([`ShadowField::towards`]).
#[derive(Debug, Clone, Copy)]
pub struct ShadowField<'a> {
    heights: &'a Array2<f64>,
    border: Edges,
    /// The highest height: a ray above it is free.
    top: f64,
    /// Steps marched at most.
    steps: usize,
}

impl<'a> ShadowField<'a> {
    /// The field of `heights`.
    pub fn new(heights: &'a Array2<f64>, border: Edges) -> Self {
        let (h, w) = heights.dim();
        Self {
            heights,
            border,
            top: super::parallax::height_span(heights).0,
            // Beyond the field's size a clamped ray sees only the repeated edge; a wrapped
            // one has crossed every height it can meet.
            steps: h.max(w).min(MAX_SHADOW_STEPS),
        }
    }

    /// The shadows of unit light `l`; `None` for a light at the zenith (nothing is cast), at
    /// or below the horizon (everything is, see [`cast_light`]) or an empty field.
    pub fn towards(&self, l: [f64; 3]) -> Option<ShadowMarch<'a>> {
        let horizontal = l[0].hypot(l[1]);
        if l[2] <= 0.0 || horizontal < 1e-9 || self.heights.is_empty() {
            return None;
        }
        Some(ShadowMarch {
            field: *self,
            step: [l[0] / horizontal, -l[1] / horizontal, l[2] / horizontal],
        })
    }
}

/// Hard cast shadows of one light over a [`ShadowField`]: the ray from a sample towards the
/// light, marched one texel at a time over the bilinearly interpolated heights, is blocked
/// where a height rises above it.
#[derive(Debug, Clone, Copy)]
pub struct ShadowMarch<'a> {
    field: ShadowField<'a>,
    /// Per texel along the ray: columns right, rows down, height gained.
    step: [f64; 3],
}

impl ShadowMarch<'_> {
    /// Whether sample (`row`, `col`) sees the light.
    pub fn lit(&self, row: usize, col: usize) -> bool {
        let f = &self.field;
        let z = f.heights[[row, col]] + SHADOW_TOLERANCE;
        let [dc, dr, rise] = self.step;
        for t in 1..=f.steps {
            let t = t as f64;
            let ray = z + t * rise;
            if ray >= f.top {
                return true;
            }
            if self.at(row as f64 + t * dr, col as f64 + t * dc) > ray {
                return false;
            }
        }
        true
    }

    /// The bilinearly interpolated height at fractional (row, col).
    fn at(&self, r: f64, c: f64) -> f64 {
        let f = &self.field;
        super::parallax::bilinear(f.heights.dim(), f.border, r, c, |i, j| f.heights[[i, j]])
    }
}

/// Hard cast-shadow visibility (1 lit, 0 shadowed) of the unit light `l` at every sample of
/// `heights` ([`ShadowMarch`]); lights at or below the horizon light nothing. Shape of
/// `heights`.
pub fn cast_light(heights: &Array2<f64>, border: Edges, l: [f64; 3]) -> Array2<f64> {
    let (h, w) = heights.dim();
    if l[2] <= 0.0 {
        return Array2::zeros((h, w));
    }
    let Some(march) = ShadowField::new(heights, border).towards(l) else {
        return Array2::ones((h, w));
    };
    let mut out = vec![1.0; h * w];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            if !march.lit(y, x) {
                *o = 0.0;
            }
        }
    });
    Array2::from_shape_vec((h, w), out).expect("rows x cols values")
}

/// A bump strength fitted to one photograph ([`fit_strength`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StrengthFit {
    /// The strength `k` in `[0, MAX_STRENGTH]`.
    pub strength: f64,
    /// What the fit leaves unexplained: the sum over pixels of the squared relative deviation
    /// of the photograph from `mean * (1 + k (s - 1))`.
    pub residual: f64,
}

/// The strength `k` in `[0, MAX_STRENGTH]` that best explains `luminance` (linear, registered
/// with `heights`) as `mean * (1 + k (s - 1))` plus variation unrelated to the relief, `s`
/// holding the given `shadows`: the least-squares slope of the photograph's relative
/// deviation on the ratio's. 0 where the light leaves the relief unlit or the relief does not
/// vary under it.
pub fn fit_strength(
    luminance: &Array2<f64>,
    heights: &Array2<f64>,
    l: [f64; 3],
    shadows: Shadows,
) -> StrengthFit {
    let mean = luminance.mean().unwrap_or(0.0);
    let deviation = luminance.mapv(|p| if mean > 0.0 { p / mean - 1.0 } else { 0.0 });
    let unexplained = StrengthFit {
        strength: 0.0,
        residual: deviation.iter().map(|d| d * d).sum(),
    };
    let full = Shading {
        strength: 1.0,
        shadows,
    };
    let Some(s) = shading_factor(heights, Edges::Clamp, l, full) else {
        return unexplained;
    };
    if mean <= 0.0 {
        return unexplained;
    }
    let (mut sp, mut ss) = (0.0, 0.0);
    for (&dp, &s) in deviation.iter().zip(&s) {
        let ds = s - 1.0;
        sp += dp * ds;
        ss += ds * ds;
    }
    if ss <= 1e-12 * s.len() as f64 {
        return unexplained;
    }
    let k = (sp / ss).clamp(0.0, MAX_STRENGTH);
    StrengthFit {
        strength: k,
        // sum (dp - k ds)^2 = sum dp^2 - 2 k sum dp ds + k^2 sum ds^2
        residual: (unexplained.residual - 2.0 * k * sp + k * k * ss).max(0.0),
    }
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
/// leaves the image as it is. With cast shadows, a pixel the relief shadows is filled from its
/// lit neighbours instead ([`fill_shadowed`]): what it shows is mostly the shadow's ambient
/// light, and a shadow the march misplaces by a texel would be lifted into a bright speck.
///
/// A pixel brightened by `g = 1 / factor > 1` that was darker than [`CHROMA_NOISE`] keeps its
/// luminance times `g`, but its chromaticity is drawn towards the image's mean chromaticity
/// (own share `r + (1 - r) / g`, `r = (Y / CHROMA_NOISE)^2`): the noise of a deep shadow's
/// colour would otherwise be lifted to a visible lightness (blue specks on a capture at a
/// grazing light).
pub fn remove_shading(
    image: &mut Array3<f32>,
    heights: &Array2<f64>,
    l: [f64; 3],
    shading: Shading,
) {
    // The cast light is marched once, for the factor and for the fill.
    let cast = (shading.shadows == Shadows::Cast).then(|| cast_light(heights, Edges::Clamp, l));
    let shade = lit_shading(heights, Edges::Clamp, l, cast.as_ref());
    if let Some(factor) = factor_of(shade, shading.strength) {
        divide_shading(image, &factor);
        if let Some(cast) = cast.filter(|_| shading.strength > 0.0) {
            fill_shadowed(image, &cast);
        }
    }
}

/// Replaces every pixel of `image` where `lit` is 0 by the mean of its lit 3 x 3 neighbours,
/// ring by ring inwards from the lit ones (an image with no lit pixel is left as it is).
fn fill_shadowed(image: &mut Array3<f32>, lit: &Array2<f64>) {
    let (_, h, w) = image.dim();
    let mut known = lit.mapv(|v| v > 0.5);
    if !known.iter().any(|&k| k) {
        return;
    }
    loop {
        let mut filled = Vec::new();
        for y in 0..h {
            for x in 0..w {
                if known[[y, x]] {
                    continue;
                }
                let mut sum = [0.0f64; 3];
                let mut n = 0usize;
                for yy in y.saturating_sub(1)..(y + 2).min(h) {
                    for xx in x.saturating_sub(1)..(x + 2).min(w) {
                        if known[[yy, xx]] {
                            for (c, s) in sum.iter_mut().enumerate() {
                                *s += f64::from(image[[c, yy, xx]]);
                            }
                            n += 1;
                        }
                    }
                }
                if n > 0 {
                    filled.push((y, x, sum.map(|s| (s / n as f64) as f32)));
                }
            }
        }
        if filled.is_empty() {
            return;
        }
        for (y, x, v) in filled {
            for (c, v) in v.into_iter().enumerate() {
                image[[c, y, x]] = v;
            }
            known[[y, x]] = true;
        }
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

    fn at(strength: f64) -> Shading {
        Shading {
            strength,
            shadows: Shadows::Attached,
        }
    }

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
        let full = shading_factor(&h, Edges::Clamp, l, at(1.0)).unwrap();
        let none = shading_factor(&h, Edges::Clamp, l, at(0.0)).unwrap();
        let half = shading_factor(&h, Edges::Clamp, l, at(0.5)).unwrap();
        assert!((full.mean().unwrap() - 1.0).abs() < 1e-12);
        assert!(none.iter().all(|&v| (v - 1.0).abs() < 1e-12));
        for ((f, h), n) in full.iter().zip(&half).zip(&none) {
            assert!((h - 0.5 * (f + n)).abs() < 1e-12);
        }
        // A light below the horizon of a flat map lights nothing.
        let flat = Array2::zeros((8, 8));
        assert!(shading_factor(&flat, Edges::Clamp, light(95.0, 0.0), Shading::LAMBERT).is_none());
    }

    #[test]
    fn removing_the_shading_undoes_it() {
        let h = relief();
        let l = light(50.0, 200.0);
        let f = shading_factor(&h, Edges::Clamp, l, at(0.7)).unwrap();
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
        remove_shading(&mut shaded, &h, l, at(0.7));
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
            let f = shading_factor(&h, Edges::Clamp, l, at(k)).unwrap();
            let photo = &albedo * &f;
            let fit = fit_strength(&photo, &h, l, Shadows::Attached).strength;
            assert!((fit - k).abs() < 0.05, "{k}: fitted {fit}");
        }
        // Out of range is clamped; unlit gives 0.
        let f = shading_factor(&h, Edges::Clamp, l, at(1.0)).unwrap();
        let steep = f.mapv(|v| 1.0 + 2.0 * (v - 1.0));
        assert_eq!(
            fit_strength(&steep, &h, l, Shadows::Attached).strength,
            MAX_STRENGTH
        );
        let flat = Array2::zeros((8, 8));
        assert_eq!(
            fit_strength(
                &Array2::ones((8, 8)),
                &flat,
                light(95.0, 0.0),
                Shadows::Attached
            )
            .strength,
            0.0
        );
    }
    /// A flat floor with a plateau 8 texels high over columns 20..24 and rows 10..30.
    fn plateau() -> Array2<f64> {
        Array2::from_shape_fn((40, 48), |(y, x)| {
            if (20..24).contains(&x) && (10..30).contains(&y) {
                8.0
            } else {
                0.0
            }
        })
    }

    #[test]
    fn a_plateau_casts_its_shadow_away_from_the_light_as_far_as_its_height_reaches() {
        let h = plateau();
        // From +x (the right) at 45 degrees: the seven floor texels left of the plateau are
        // shadowed (the eighth's ray just clears the plateau's edge sample), everything
        // further and right of it lit.
        let lit = cast_light(&h, Edges::Clamp, light(45.0, 0.0));
        for x in 0..48 {
            let want = if (13..20).contains(&x) { 0.0 } else { 1.0 };
            assert_eq!(lit[[20, x]], want, "column {x}");
        }
        // Rows outside the plateau's span see the light.
        assert!(lit.row(5).iter().all(|&v| v == 1.0));
        // From +y (up the image, towards row 0) at 45 degrees: the rows below it are shadowed.
        let lit = cast_light(&h, Edges::Clamp, light(45.0, 90.0));
        for y in 0..40 {
            let want = if (30..37).contains(&y) { 0.0 } else { 1.0 };
            assert_eq!(lit[[y, 21]], want, "row {y}");
        }
        // The zenith casts nothing; a light under the horizon lights nothing.
        assert!(
            cast_light(&h, Edges::Clamp, [0.0, 0.0, 1.0])
                .iter()
                .all(|&v| v == 1.0)
        );
        assert!(
            cast_light(&h, Edges::Clamp, light(95.0, 0.0))
                .iter()
                .all(|&v| v == 0.0)
        );
        // A gentle slope does not shadow itself.
        let slope = Array2::from_shape_fn((16, 16), |(_, x)| 0.3 * x as f64);
        assert!(
            cast_light(&slope, Edges::Clamp, light(60.0, 180.0))
                .iter()
                .all(|&v| v == 1.0)
        );
    }

    #[test]
    fn a_wrapped_field_casts_across_its_edge() {
        // The plateau moved to the first columns: from the left, its shadow falls right of it;
        // from the right, across the left edge onto the last columns, but only on a torus.
        let h = Array2::from_shape_fn((8, 32), |(_, x)| if x < 3 { 6.0 } else { 0.0 });
        let from_right = light(45.0, 0.0);
        let wrapped = cast_light(&h, Edges::Wrap, from_right);
        let clamped = cast_light(&h, Edges::Clamp, from_right);
        for x in 27..32 {
            assert_eq!(wrapped[[4, x]], 0.0, "column {x}");
            assert_eq!(clamped[[4, x]], 1.0, "column {x}");
        }
        assert_eq!(wrapped[[4, 26]], 1.0);
    }

    #[test]
    fn cast_shadows_are_chosen_by_what_they_explain() {
        // Photographs of a textured floor around the plateau, shaded with cast shadows: the
        // fit with cast shadows leaves less unexplained and recovers the strength.
        let h = plateau();
        let albedo = Array2::from_shape_fn(h.dim(), |(y, x)| {
            0.4 + 0.05 * (((y * 7 + x * 13) % 11) as f64 / 11.0 - 0.5)
        });
        let cast = Shading {
            strength: 0.7,
            shadows: Shadows::Cast,
        };
        for l in [light(45.0, 0.0), light(60.0, 120.0)] {
            let photo = &albedo * &shading_factor(&h, Edges::Clamp, l, cast).unwrap();
            let with = fit_strength(&photo, &h, l, Shadows::Cast);
            let without = fit_strength(&photo, &h, l, Shadows::Attached);
            assert!((with.strength - 0.7).abs() < 0.05, "{with:?}");
            assert!(
                with.residual < 0.5 * without.residual,
                "{with:?} {without:?}"
            );
        }
        // De-shading with cast shadows leaves the shadowed floor at its lit neighbours' level
        // (within the albedo's own spread), not lifted into a bright band.
        let l = light(45.0, 0.0);
        let f = shading_factor(&h, Edges::Clamp, l, cast).unwrap();
        let mut image =
            Array3::from_shape_fn((3, 40, 48), |(_, y, x)| (albedo[[y, x]] * f[[y, x]]) as f32);
        remove_shading(&mut image, &h, l, cast);
        for x in 13..20 {
            let v = f64::from(image[[0, 20, x]]);
            assert!((v - 0.4).abs() < 0.03, "column {x}: {v}");
        }
    }
}
