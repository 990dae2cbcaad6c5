//! Lookup tables that let the shaders interpolate directions and normalise the bump shading
//! exactly as the CPU does, and their CPU mirrors (used to plan what a scene needs, and to
//! test the tables against [`DirectionSet::interpolate`]).
//!
//! **Directions.** A square grid of [`DIRECTION_GRID`]² cells over the azimuthal-equidistant
//! plane `theta * (cos phi, sin phi)`, theta up to 90 degrees, stores per cell the Delaunay
//! triangle that [`DirectionSet::interpolate`] picks at the cell centre. A query takes the
//! triangles of the 2 x 2 cells around it and, like the CPU, the closest point of the nearest
//! one, with its barycentric weights. So the weights are exact wherever one of those four
//! triangles is the CPU's (everywhere for the Bonn sampling, whose triangles are much larger
//! than a cell), not quantised to the grid.
//!
//! **Mean shading.** [`bump_relight`](btfmrf::synthesis::bump_relight) divides by the mean of
//! `max(0, n . l)` (times the cast light, where the range map casts shadows) over the
//! texture; [`MeanShading`] tabulates it on a grid of light directions (bilinear in between).

use ndarray::{Array2, Array3};
use rayon::prelude::*;

use btfmrf::geometry::integrate::Edges;
use btfmrf::geometry::relight::ShadowField;

use btfmrf::btf::directions::{closest_point_in_triangle, project};
use btfmrf::btf::{Direction, DirectionSet};

use super::Result;

/// Cells per side of the direction grid.
pub const DIRECTION_GRID: usize = 128;
/// Nodes per side of the mean-shading grid.
pub const SHADING_GRID: usize = 64;
/// The largest number of normals (a strided subsample) averaged per mean-shading node.
pub const SHADING_SAMPLES: usize = 128 * 128;
/// The same where each sample also marches a shadow ray per node (a relief casting shadows).
pub const SHADOW_SAMPLES: usize = 128 * 128;

const HALF_PI: f64 = std::f64::consts::FRAC_PI_2;

/// Projected coordinates of a unit vector in the tangent frame, theta clamped to `max_theta`
/// radians (the shader's `project_dir`).
pub fn project_vector(v: [f64; 3], max_theta: f64) -> [f64; 2] {
    let theta = v[2].clamp(-1.0, 1.0).acos().min(max_theta);
    let r = (v[0] * v[0] + v[1] * v[1]).sqrt();
    if r < 1e-12 {
        [0.0, 0.0]
    } else {
        [theta * v[0] / r, theta * v[1] / r]
    }
}

/// The direction grid of one [`DirectionSet`].
#[derive(Debug, Clone, PartialEq)]
pub struct DirectionLut {
    /// Projected coordinates of the sampled directions.
    pub points: Vec<[f32; 2]>,
    /// Per cell (row-major, row = y), the triangle's three direction indices and a zero.
    pub cells: Vec<[u32; 4]>,
    /// Where queries are clamped, radians: 90 degrees, or the set's lowest direction if that
    /// lies below the horizon (real RTI domes), as [`DirectionSet::interpolate`] does.
    pub max_theta: f64,
    /// The zenith angle of the set's lowest direction, radians: lights past it fade
    /// ([`DirectionSet::irradiance_beyond_lowest`]).
    pub lowest_theta: f64,
}

impl DirectionLut {
    /// Tabulates `set` (a few milliseconds for the Bonn sampling).
    ///
    /// # Errors
    /// Never for a valid set (interpolation of finite directions does not fail).
    pub fn new(set: &DirectionSet) -> Result<Self> {
        let points = set.iter().map(|d| project(d).map(|x| x as f32)).collect();
        let lowest_theta = set.lowest_theta().to_radians();
        let max_theta = lowest_theta.max(std::f64::consts::FRAC_PI_2);
        let n = DIRECTION_GRID;
        let cells = (0..n * n)
            .into_par_iter()
            .map(|i| {
                let c = cell_centre(i % n, i / n);
                let r = (c[0] * c[0] + c[1] * c[1]).sqrt();
                let d =
                    Direction::new(r.min(max_theta).to_degrees(), c[1].atan2(c[0]).to_degrees());
                let w = set.interpolate(&d)?;
                Ok([w[0].index as u32, w[1].index as u32, w[2].index as u32, 0])
            })
            .collect::<Result<Vec<_>, btfmrf::btf::BtfError>>()
            .map_err(btfmrf::model::ModelError::from)?;
        Ok(Self {
            points,
            cells,
            max_theta,
            lowest_theta,
        })
    }

    /// The tangent-frame `z` at and below which a direction lies beyond the set's lowest
    /// direction: 0 (the horizon) unless the set reaches below it.
    pub fn horizon_z(&self) -> f64 {
        if self.max_theta > HALF_PI {
            self.max_theta.cos()
        } else {
            0.0
        }
    }

    /// The tangent-frame `z` of the set's lowest direction where lights past it fade
    /// (`cos theta_lowest`), or 0 where none do (the set reaches the horizon or below): the
    /// shader's twin of [`DirectionSet::irradiance_beyond_lowest`] is `min(1, z / this)`.
    pub fn fade_z(&self) -> f64 {
        if self.lowest_theta < HALF_PI {
            self.lowest_theta.cos()
        } else {
            0.0
        }
    }

    /// The CPU mirror of the shader's `interpolate_dir`: three direction indices and weights
    /// for a unit vector in the tangent frame.
    pub fn lookup(&self, v: [f64; 3]) -> ([usize; 3], [f64; 3]) {
        let q = project_vector(v, self.max_theta);
        let n = DIRECTION_GRID as f64;
        let fx = (q[0] + HALF_PI) / std::f64::consts::PI * n - 0.5;
        let fy = (q[1] + HALF_PI) / std::f64::consts::PI * n - 0.5;
        let clamp = |f: f64| (f.floor() as i64).clamp(0, DIRECTION_GRID as i64 - 1) as usize;
        let (x0, y0) = (clamp(fx), clamp(fy));
        let (x1, y1) = (clamp(fx + 1.0), clamp(fy + 1.0));
        let mut best = (f64::INFINITY, [0usize; 3], [1.0, 0.0, 0.0]);
        for (x, y) in [(x0, y0), (x1, y0), (x0, y1), (x1, y1)] {
            if best.0 < 1e-10 {
                break; // inside a triangle already (up to rounding)
            }
            let cell = self.cells[y * DIRECTION_GRID + x];
            let tri = [cell[0], cell[1], cell[2]].map(|i| i as usize);
            let p = tri.map(|i| self.points[i].map(f64::from));
            let (closest, bary) = closest_point_in_triangle(q, p[0], p[1], p[2]);
            let d2 = (closest[0] - q[0]).powi(2) + (closest[1] - q[1]).powi(2);
            if d2 < best.0 - 1e-15 {
                let bary = bary.map(|w| w.max(0.0));
                let sum: f64 = bary.iter().sum();
                best = (d2, tri, bary.map(|w| w / sum));
            }
        }
        (best.1, best.2)
    }
}

fn cell_centre(x: usize, y: usize) -> [f64; 2] {
    let step = std::f64::consts::PI / DIRECTION_GRID as f64;
    [
        -HALF_PI + (x as f64 + 0.5) * step,
        -HALF_PI + (y as f64 + 0.5) * step,
    ]
}

/// Mean of `max(0, n . l)` over a texture's normals, tabulated over light directions on a
/// [`SHADING_GRID`]² node grid spanning the projected plane `[-pi/2, pi/2]^2`.
#[derive(Debug, Clone, PartialEq)]
pub struct MeanShading {
    /// Node values, row-major (row = y).
    pub values: Vec<f32>,
}

impl MeanShading {
    /// Tabulates the mean shading of `normals` (shape (3, rows, cols)), averaging at most
    /// [`SHADING_SAMPLES`] normals (a regular strided subsample; all of them for textures up
    /// to 128 x 128).
    pub fn new(normals: &Array3<f64>) -> Self {
        Self::tabulate(normals, None)
    }

    /// The same with the cast shadows of the tileable `heights` (texels, registered with
    /// `normals`; [`ShadowField`]), over at most [`SHADOW_SAMPLES`] samples, at the nodes up
    /// to `lowest` (the zenith angle of the set's lowest light, degrees) and those a light
    /// above it interpolates from. Beyond, where the shader leaves every fragment black, the
    /// nodes keep the mean without cast shadows: near the horizon every ray marches its
    /// longest, and those nodes took 70 % of the time (about 5 s for the built-in stones).
    pub fn with_cast_shadows(normals: &Array3<f64>, heights: &Array2<f64>, lowest: f64) -> Self {
        // The four nodes around a direction lie within sqrt(2) node spacings of it.
        let spacing = 180.0 / (SHADING_GRID - 1) as f64;
        let reach = (lowest + 2.0 * spacing).to_radians().cos();
        Self::tabulate(
            normals,
            Some((ShadowField::new(heights, Edges::Wrap), reach)),
        )
    }

    /// The table; with `shadows` (the field and the smallest light z it marches for), cast
    /// shadows included.
    fn tabulate(normals: &Array3<f64>, shadows: Option<(ShadowField, f64)>) -> Self {
        let (_, h, w) = normals.dim();
        let most = if shadows.is_some() {
            SHADOW_SAMPLES
        } else {
            SHADING_SAMPLES
        };
        let stride = ((h * w) as f64 / most as f64).sqrt().ceil().max(1.0) as usize;
        let samples: Vec<(usize, usize, [f64; 3])> = (0..h)
            .step_by(stride)
            .flat_map(|y| {
                (0..w)
                    .step_by(stride)
                    .map(move |x| (y, x, [0, 1, 2].map(|c| normals[[c, y, x]])))
            })
            .collect();
        let n = SHADING_GRID;
        let values = (0..n * n)
            .into_par_iter()
            .map(|i| {
                let l = node_vector(i % n, i / n);
                let march = shadows
                    .filter(|&(_, reach)| l[2] >= reach)
                    .and_then(|(f, _)| f.towards(l));
                let sum: f64 = samples
                    .iter()
                    .map(|&(y, x, s)| {
                        let shade = (s[0] * l[0] + s[1] * l[1] + s[2] * l[2]).max(0.0);
                        match &march {
                            Some(m) if shade > 0.0 && !m.lit(y, x) => 0.0,
                            _ => shade,
                        }
                    })
                    .sum();
                (sum / samples.len().max(1) as f64) as f32
            })
            .collect();
        Self { values }
    }

    /// The CPU mirror of the shader's `mean_shading`: bilinear between nodes.
    pub fn lookup(&self, l: [f64; 3]) -> f64 {
        let q = project_vector(l, HALF_PI);
        let n = SHADING_GRID;
        let f = |c: f64| {
            ((c + HALF_PI) / std::f64::consts::PI * (n - 1) as f64).clamp(0.0, (n - 1) as f64)
        };
        let (fx, fy) = (f(q[0]), f(q[1]));
        let (x0, y0) = (
            (fx.floor() as usize).min(n - 2),
            (fy.floor() as usize).min(n - 2),
        );
        let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
        let v = |x: usize, y: usize| f64::from(self.values[y * n + x]);
        (v(x0, y0) * (1.0 - tx) + v(x0 + 1, y0) * tx) * (1.0 - ty)
            + (v(x0, y0 + 1) * (1.0 - tx) + v(x0 + 1, y0 + 1) * tx) * ty
    }
}

/// The unit vector of mean-shading node (x, y).
fn node_vector(x: usize, y: usize) -> [f64; 3] {
    let step = std::f64::consts::PI / (SHADING_GRID - 1) as f64;
    let q = [-HALF_PI + x as f64 * step, -HALF_PI + y as f64 * step];
    let r = (q[0] * q[0] + q[1] * q[1]).sqrt();
    let d = Direction::new(r.min(HALF_PI).to_degrees(), q[1].atan2(q[0]).to_degrees());
    d.vector()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The largest difference between the CPU's interpolation weights of `d` and the
    /// table's, compared as sparse weight vectors over direction indices.
    fn weight_difference(set: &DirectionSet, lut: &DirectionLut, d: &Direction) -> f64 {
        let mut diff = vec![0.0f64; set.len()];
        for c in set.interpolate(d).unwrap() {
            diff[c.index] += c.weight;
        }
        let (idx, w) = lut.lookup(d.vector());
        for k in 0..3 {
            diff[idx[k]] -= w[k];
        }
        diff.iter().map(|x| x.abs()).fold(0.0, f64::max)
    }

    #[test]
    fn the_direction_table_reproduces_cpu_interpolation() {
        let set = DirectionSet::bonn();
        let lut = DirectionLut::new(&set).unwrap();
        let (mut worst, mut count) = (0.0f64, 0);
        for t in 0..=45 {
            for p in 0..72 {
                let d = Direction::new(t as f64 * 2.0, p as f64 * 5.0 + 1.3);
                worst = worst.max(weight_difference(&set, &lut, &d));
                count += 1;
            }
        }
        assert!(count > 3000);
        assert!(worst < 1e-6, "largest weight difference {worst}");
    }

    #[test]
    fn a_set_reaching_below_the_horizon_is_clamped_at_its_lowest_direction() {
        // The Bonn lights with the last ring moved to 95 degrees, as an RTI dome may list.
        let moved: Vec<Direction> = DirectionSet::bonn()
            .iter()
            .map(|d| {
                let theta = if d.theta_deg > 70.0 {
                    95.0
                } else {
                    d.theta_deg
                };
                Direction::new(theta, d.phi_deg)
            })
            .collect();
        let set = DirectionSet::new(moved).unwrap();
        let lut = DirectionLut::new(&set).unwrap();
        assert!((lut.max_theta.to_degrees() - 95.0).abs() < 1e-9);
        assert!(lut.horizon_z() < -0.08);
        for (theta, phi) in [(92.0, 10.0), (95.0, 200.0), (80.0, 33.0)] {
            let d = Direction::new(theta, phi);
            let worst = weight_difference(&set, &lut, &d);
            assert!(worst < 1e-6, "{d:?}: largest weight difference {worst}");
        }
        assert_eq!(
            DirectionLut::new(&DirectionSet::bonn())
                .unwrap()
                .horizon_z(),
            0.0
        );
    }

    #[test]
    fn mean_shading_matches_the_mean_it_tabulates() {
        // A bumpy normal field.
        let (h, w) = (40, 40);
        let normals = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            let (a, b) = ((x as f64 * 0.4).sin() * 0.5, (y as f64 * 0.3).cos() * 0.4);
            let len = (a * a + b * b + 1.0).sqrt();
            [a, b, 1.0][c] / len
        });
        let table = MeanShading::new(&normals);
        for d in [
            Direction::new(0.0, 0.0),
            Direction::new(37.0, 123.0),
            Direction::new(75.0, 300.0),
        ] {
            let l = d.vector();
            let mut sum = 0.0;
            for y in 0..h {
                for x in 0..w {
                    sum += (normals[[0, y, x]] * l[0]
                        + normals[[1, y, x]] * l[1]
                        + normals[[2, y, x]] * l[2])
                        .max(0.0);
                }
            }
            let exact = sum / (h * w) as f64;
            let got = table.lookup(l);
            assert!(
                (got - exact).abs() < 2e-3 * exact.max(0.1),
                "{d:?}: {got} vs {exact}"
            );
        }
    }
    #[test]
    fn the_shadowed_table_holds_the_cast_light_at_its_nodes() {
        use btfmrf::geometry::integrate::{normals_of_periodic, shading};
        use btfmrf::geometry::relight::cast_light;
        // Ridges tall enough to shadow each other at low lights.
        let heights = ndarray::Array2::from_shape_fn((32, 32), |(y, x)| {
            4.0 * (x as f64 * std::f64::consts::PI / 8.0).sin().max(0.0)
                + 0.5 * (y as f64 * 0.4).cos()
        });
        let normals = normals_of_periodic(&heights);
        let plain = MeanShading::new(&normals);
        let table = MeanShading::with_cast_shadows(&normals, &heights, 75.0);
        let n = SHADING_GRID;
        let mut darker = 0;
        for (x, y) in [(32, 32), (10, 31), (50, 40), (20, 12), (31, 55)] {
            let l = node_vector(x, y);
            let i = y * n + x;
            let exact = (shading(&heights, Edges::Wrap, l) * cast_light(&heights, Edges::Wrap, l))
                .mean()
                .unwrap();
            let got = f64::from(table.values[i]);
            assert!(
                (got - exact).abs() < 1e-5,
                "node ({x}, {y}): {got} vs {exact}"
            );
            if got < f64::from(plain.values[i]) - 1e-3 {
                darker += 1;
            }
        }
        assert!(darker >= 3, "the low lights' shadows darken the mean");
        // Beyond the lowest light's reach the nodes keep the unshadowed mean.
        assert_eq!(table.values[0], plain.values[0]);
    }
}
