//! Ray-marched rendering of a periodic height field with a spatially varying BRDF.
//!
//! Geometry: texel (row i, column j) has its centre at world (x, y) = (j + 0.5, -(i + 0.5)) in
//! texel units (x right, y up in the image), heights are in texel units too, and everything
//! wraps with the tile period. The camera is orthographic and the light directional, as in a
//! rectified BTF measurement. For a view direction v, texel (i, j) shows the first surface
//! point hit by the ray that crosses the mean height plane at the texel's centre (parallax and
//! masking). That point is lit if the ray from it towards the light leaves the relief without
//! passing under the height field (cast shadows); shading uses the true normal there.

use rayon::prelude::*;

use super::materials::Pattern;

/// Ambient fraction of the albedo, standing in for the inter-reflections we do not trace.
const AMBIENT: f32 = 0.04;
/// Horizontal ray-march step, texels.
const STEP: f32 = 0.5;

/// A material sampled on the texel grid: the ground truth the renderer works from.
#[derive(Debug, Clone)]
pub(crate) struct Surface {
    pub n: usize,
    /// Heights in texel units, row-major, minimum 0.
    pub height: Vec<f32>,
    /// Unit normals (x, y, z) in the world frame.
    pub normal: Vec<[f32; 3]>,
    pub albedo: Vec<[f32; 3]>,
    pub specular: Vec<f32>,
    pub shininess: Vec<f32>,
    pub h_max: f32,
    pub h_mean: f32,
}

impl Surface {
    /// Samples `pattern` at every texel centre of an `n` x `n` tile.
    pub(crate) fn sample(pattern: &dyn Pattern, n: usize) -> Self {
        let points: Vec<_> = (0..n * n)
            .into_par_iter()
            .map(|k| {
                let (i, j) = (k / n, k % n);
                pattern.at((j as f32 + 0.5) / n as f32, (i as f32 + 0.5) / n as f32)
            })
            .collect();
        let (lo, hi) = points.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| {
            (lo.min(p.height), hi.max(p.height))
        });
        let range = hi - lo;
        let scale = if range > 1e-12 {
            pattern.relief() * n as f32 / range
        } else {
            0.0
        };
        let height: Vec<f32> = points.iter().map(|p| (p.height - lo) * scale).collect();
        let normal = (0..n * n)
            .map(|k| {
                let (i, j) = (k / n, k % n);
                let at = |di: isize, dj: isize| {
                    let ii = (i as isize + di).rem_euclid(n as isize) as usize;
                    let jj = (j as isize + dj).rem_euclid(n as isize) as usize;
                    height[ii * n + jj]
                };
                // y is up, rows go down: dh/dy = -dh/drow.
                let dhdx = (at(0, 1) - at(0, -1)) * 0.5;
                let dhdy = -(at(1, 0) - at(-1, 0)) * 0.5;
                normalize([-dhdx, -dhdy, 1.0])
            })
            .collect();
        let h_max = height.iter().copied().fold(0.0, f32::max);
        let h_mean = height.iter().sum::<f32>() / height.len() as f32;
        Self {
            n,
            normal,
            albedo: points.iter().map(|p| p.albedo).collect(),
            specular: points.iter().map(|p| p.specular).collect(),
            shininess: points.iter().map(|p| p.shininess).collect(),
            height,
            h_max,
            h_mean,
        }
    }

    /// Bilinear lookup position of world point (x, y): the top-left texel index and weights.
    fn locate(&self, x: f32, y: f32) -> Bilinear {
        let n = self.n as f32;
        let (col, row) = ((x - 0.5).rem_euclid(n), (-y - 0.5).rem_euclid(n));
        let (j0, i0) = (col.floor(), row.floor());
        Bilinear {
            i0: i0 as u32 % self.n as u32,
            j0: j0 as u32 % self.n as u32,
            fx: col - j0,
            fy: row - i0,
        }
    }

    fn height_at(&self, x: f32, y: f32) -> f32 {
        self.locate(x, y).apply(self.n, &self.height)
    }

    /// The world (x, y) of the first surface point seen along view direction `v` through the
    /// mean plane at (x, y).
    fn view_hit(&self, x: f32, y: f32, v: [f32; 3]) -> (f32, f32) {
        let horizontal = (v[0] * v[0] + v[1] * v[1]).sqrt();
        if horizontal < 1e-6 || v[2] <= 1e-6 {
            return (x, y);
        }
        // Ray P(t) = (x, y, mean) + v t; t decreases from the top of the relief to its bottom.
        let point = |t: f32| (x + v[0] * t, y + v[1] * t, self.h_mean + v[2] * t);
        let above = |t: f32| {
            let (px, py, pz) = point(t);
            pz - self.height_at(px, py)
        };
        let t_top = (self.h_max - self.h_mean) / v[2];
        let t_bottom = -self.h_mean / v[2];
        let dt = STEP / horizontal;
        let (mut t_hi, mut t) = (t_top, t_top);
        loop {
            if above(t) <= 0.0 {
                break;
            }
            if t <= t_bottom {
                break;
            }
            t_hi = t;
            t = (t - dt).max(t_bottom);
        }
        // The crossing lies in [t, t_hi]: refine by bisection.
        let mut t_lo = t;
        for _ in 0..10 {
            let mid = 0.5 * (t_lo + t_hi);
            if above(mid) <= 0.0 {
                t_lo = mid;
            } else {
                t_hi = mid;
            }
        }
        let (px, py, _) = point(0.5 * (t_lo + t_hi));
        (px, py)
    }

    /// 1 if the surface point above texel `k` sees the light direction `l`, else 0.
    fn lit(&self, k: usize, l: [f32; 3]) -> f32 {
        if l[2] <= 0.0 {
            return 0.0;
        }
        let horizontal = (l[0] * l[0] + l[1] * l[1]).sqrt();
        if horizontal < 1e-6 {
            return 1.0;
        }
        let (i, j) = (k / self.n, k % self.n);
        let (x, y, z) = (j as f32 + 0.5, -(i as f32 + 0.5), self.height[k]);
        let dt = STEP / horizontal;
        let t_end = (self.h_max - z) / l[2];
        let mut t = dt;
        while t < t_end {
            let (px, py, pz) = (x + l[0] * t, y + l[1] * t, z + l[2] * t);
            // A small tolerance keeps smooth surfaces from shadowing themselves.
            if self.height_at(px, py) > pz + 0.05 {
                return 0.0;
            }
            t += dt;
        }
        1.0
    }

    /// The visibility of light `l` at every texel centre (a shadow map on the tile).
    pub(crate) fn shadow_map(&self, l: [f32; 3]) -> Vec<f32> {
        (0..self.n * self.n)
            .into_par_iter()
            .map(|k| self.lit(k, l))
            .collect()
    }

    /// For view direction `v`, what every texel shows: the surface data interpolated at the
    /// hit point, and where to look up shadow maps.
    pub(crate) fn view_samples(&self, v: [f32; 3]) -> Vec<ViewSample> {
        let n = self.n;
        (0..n * n)
            .into_par_iter()
            .map(|k| {
                let (i, j) = (k / n, k % n);
                let (hx, hy) = self.view_hit(j as f32 + 0.5, -(i as f32 + 0.5), v);
                let at = self.locate(hx, hy);
                let albedo = std::array::from_fn(|c| at.apply_with(n, |q| self.albedo[q][c]));
                let normal = normalize(std::array::from_fn(|c| {
                    at.apply_with(n, |q| self.normal[q][c])
                }));
                ViewSample {
                    normal,
                    albedo,
                    specular: at.apply(n, &self.specular),
                    shininess: at.apply(n, &self.shininess),
                    at,
                }
            })
            .collect()
    }
}

/// What one texel shows under one view.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ViewSample {
    normal: [f32; 3],
    albedo: [f32; 3],
    specular: f32,
    shininess: f32,
    at: Bilinear,
}

#[derive(Debug, Clone, Copy)]
struct Bilinear {
    i0: u32,
    j0: u32,
    fx: f32,
    fy: f32,
}

impl Bilinear {
    fn apply_with(&self, n: usize, f: impl Fn(usize) -> f32) -> f32 {
        let (i0, j0) = (self.i0 as usize, self.j0 as usize);
        let (i1, j1) = ((i0 + 1) % n, (j0 + 1) % n);
        let top = f(i0 * n + j0) * (1.0 - self.fx) + f(i0 * n + j1) * self.fx;
        let bottom = f(i1 * n + j0) * (1.0 - self.fx) + f(i1 * n + j1) * self.fx;
        top * (1.0 - self.fy) + bottom * self.fy
    }

    fn apply(&self, n: usize, values: &[f32]) -> f32 {
        self.apply_with(n, |q| values[q])
    }
}

/// Shades one image: planar RGB (3 * n * n values), linear, for view `v` and light `l`.
///
/// Radiance per unit irradiance: `albedo * (AMBIENT + vis * cos_l)` plus a white normalised
/// Blinn-Phong lobe `vis * cos_l * ks * (s + 8) / 8 * cos_h^s`.
pub(crate) fn shade(
    samples: &[ViewSample],
    shadow: &[f32],
    n: usize,
    v: [f32; 3],
    l: [f32; 3],
) -> Vec<f32> {
    let half = normalize([l[0] + v[0], l[1] + v[1], l[2] + v[2]]);
    let plane = n * n;
    let mut out = vec![0.0f32; 3 * plane];
    for (k, s) in samples.iter().enumerate() {
        let vis = s.at.apply(n, shadow);
        let cos_l = dot(s.normal, l).max(0.0);
        let cos_h = dot(s.normal, half).max(0.0);
        let direct = vis * cos_l;
        let lobe = s.specular * (s.shininess + 8.0) / 8.0 * cos_h.powf(s.shininess);
        for c in 0..3 {
            out[c * plane + k] = s.albedo[c] * (AMBIENT + direct) + direct * lobe;
        }
    }
    out
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn normalize(a: [f32; 3]) -> [f32; 3] {
    let len = dot(a, a).sqrt();
    if len > 0.0 {
        a.map(|x| x / len)
    } else {
        [0.0, 0.0, 1.0]
    }
}

#[cfg(test)]
mod tests {
    use super::super::materials::SurfacePoint;
    use super::*;

    /// A single square plateau of height 1 (x relief) on a flat floor.
    struct Plateau;
    impl Pattern for Plateau {
        fn at(&self, u: f32, v: f32) -> SurfacePoint {
            let inside = (0.25..0.75).contains(&u) && (0.25..0.75).contains(&v);
            SurfacePoint {
                height: if inside { 1.0 } else { 0.0 },
                albedo: [0.5; 3],
                specular: 0.0,
                shininess: 1.0,
            }
        }
        fn relief(&self) -> f32 {
            0.25
        }
    }

    struct Flat;
    impl Pattern for Flat {
        fn at(&self, _: f32, _: f32) -> SurfacePoint {
            SurfacePoint {
                height: 0.3,
                albedo: [0.8, 0.4, 0.2],
                specular: 0.0,
                shininess: 1.0,
            }
        }
        fn relief(&self) -> f32 {
            0.1
        }
    }

    #[test]
    fn flat_lambertian_surface_follows_the_cosine_law() {
        let s = Surface::sample(&Flat, 8);
        assert!(s.height.iter().all(|&h| h == 0.0));
        for theta in [0.0f32, 30.0, 60.0, 75.0] {
            let t = theta.to_radians();
            let l = [t.sin(), 0.0, t.cos()];
            let v = [0.0, (0.5f32).sin(), (0.5f32).cos()];
            let im = shade(&s.view_samples(v), &s.shadow_map(l), 8, v, l);
            let expected = 0.8 * (AMBIENT + t.cos());
            assert!(
                (im[0] - expected).abs() < 1e-5,
                "{theta}: {} vs {expected}",
                im[0]
            );
        }
    }

    #[test]
    fn plateau_casts_a_shadow_on_the_side_away_from_the_light() {
        let n = 32;
        let s = Surface::sample(&Plateau, n);
        // Light from +x at 45 degrees: the plateau (8 texels high) shadows the floor on its
        // -x side; the floor on its +x side is 14 texels from the next tile's plateau, lit.
        let t = 45f32.to_radians();
        let map = s.shadow_map([t.sin(), 0.0, t.cos()]);
        let row = n / 2;
        let left_of_plateau = map[row * n + n / 4 - 2];
        let right_of_plateau = map[row * n + 3 * n / 4 + 2];
        let on_top = map[row * n + n / 2];
        assert_eq!((left_of_plateau, right_of_plateau, on_top), (0.0, 1.0, 1.0));
    }

    #[test]
    fn grazing_view_sees_the_plateau_wall_shifted_by_parallax() {
        let n = 32;
        let s = Surface::sample(&Plateau, n);
        // Looking from +x at 60 degrees, a floor texel just right of the plateau sees the
        // floor; just left of it the view ray hits the plateau's top or wall instead.
        let t = 60f32.to_radians();
        let v = [t.sin(), 0.0, t.cos()];
        let samples = s.view_samples(v);
        let row = n / 2;
        let j_left = n / 4 - 2;
        let hit = samples[row * n + j_left].at;
        // The hit lies to the +x side (towards the viewer) of the texel itself.
        assert!(hit.j0 as usize > j_left, "{hit:?}");
    }
}
