//! View and light directions: the Bonn 81-direction sampling and barycentric interpolation
//! between sampled directions (the survey's 3-nearest-direction scheme, seed 001, sec. 7.4).
//!
//! A direction is given by elevation `theta` from the surface normal and azimuth `phi` from the
//! tangent +x axis (counter-clockwise seen from above), in degrees. Its unit vector is
//! `(sin θ cos φ, sin θ sin φ, cos θ)`.

use std::sync::OnceLock;

use super::error::{BtfError, Result};
use crate::io::bytes::{Parse, Reader};

/// Elevations of the Bonn sampling, in degrees.
pub const BONN_THETAS_DEG: [f64; 6] = [0.0, 15.0, 30.0, 45.0, 60.0, 75.0];
/// Number of azimuth steps on each Bonn elevation ring (starting at phi = 0).
pub const BONN_PHI_STEPS: [usize; 6] = [1, 6, 12, 18, 20, 24];

/// One direction on (or slightly below) the hemisphere.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Direction {
    /// Elevation from the surface normal, degrees (0 = straight up).
    pub theta_deg: f64,
    /// Azimuth from the tangent +x axis, degrees in [0, 360).
    pub phi_deg: f64,
}

impl Direction {
    /// A direction from angles in degrees; phi is wrapped into [0, 360).
    pub fn new(theta_deg: f64, phi_deg: f64) -> Self {
        // `rem_euclid` of a tiny negative angle rounds to exactly 360 (fuzzing found a model
        // file whose azimuth read back as 360 and was then written as 0).
        let phi = phi_deg.rem_euclid(360.0);
        Self {
            theta_deg,
            phi_deg: if phi >= 360.0 { 0.0 } else { phi },
        }
    }

    /// The direction of a (not necessarily unit) vector; `None` for a zero or non-finite vector.
    pub fn from_vector(v: [f64; 3]) -> Option<Self> {
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if !len.is_finite() || len <= f64::EPSILON {
            return None;
        }
        let theta = (v[2] / len).clamp(-1.0, 1.0).acos().to_degrees();
        let phi = v[1].atan2(v[0]).to_degrees();
        Some(Self::new(theta, phi))
    }

    /// The unit vector `(sin θ cos φ, sin θ sin φ, cos θ)`.
    pub fn vector(&self) -> [f64; 3] {
        let (st, ct) = self.theta_deg.to_radians().sin_cos();
        let (sp, cp) = self.phi_deg.to_radians().sin_cos();
        [st * cp, st * sp, ct]
    }

    /// The angle between two directions, degrees.
    pub fn angle_to(&self, other: &Direction) -> f64 {
        // atan2 of |a x b| and a . b stays accurate for nearly equal directions, where acos
        // of the dot product loses half the digits.
        let (a, b) = (self.vector(), other.vector());
        let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let cross = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let sin = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
        sin.atan2(dot).to_degrees()
    }

    /// True when both angles are finite.
    pub fn is_finite(&self) -> bool {
        self.theta_deg.is_finite() && self.phi_deg.is_finite()
    }
}

/// One sampled direction and its interpolation weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weighted {
    /// Index into the [`DirectionSet`].
    pub index: usize,
    /// Barycentric weight, in [0, 1]; the three weights of a query sum to 1.
    pub weight: f64,
}

/// An ordered set of sampled directions (the views or the lights of a BTF).
#[derive(Debug, Clone)]
pub struct DirectionSet {
    directions: Vec<Direction>,
    /// Delaunay triangles of the directions in the azimuthal-equidistant plane, built on demand.
    triangles: OnceLock<Vec<[usize; 3]>>,
}

impl PartialEq for DirectionSet {
    fn eq(&self, other: &Self) -> bool {
        self.directions == other.directions
    }
}

impl DirectionSet {
    /// Reads a set as the model files store it (`.btfm`, `.lpca`; docs/FORMAT.md): a `u16`
    /// count, then `theta` and `phi` per direction as finite `f32` degrees. `what` names the
    /// set in errors.
    pub(crate) fn read_le(r: &mut Reader, what: &str) -> Parse<Self> {
        let count = usize::from(r.u16()?);
        r.ensure(count, 8, what)?;
        let dirs = (0..count)
            .map(|_| Ok(Direction::new(r.f32()?, r.f32()?)))
            .collect::<Parse<Vec<_>>>()?;
        DirectionSet::new(dirs).map_err(|e| format!("{what}: {e}"))
    }

    /// Writes the set as [`DirectionSet::read_le`] reads it. An azimuth just below 360 rounds
    /// up to 360.0 in single precision, which reads back as 0: that 0 is written, so that
    /// write-read-write is a fixed point (fuzzing found the difference in both formats).
    pub(crate) fn write_le(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&(self.len() as u16).to_le_bytes());
        for d in self {
            let phi = d.phi_deg as f32;
            let phi = if phi >= 360.0 { 0.0 } else { phi };
            out.extend_from_slice(&(d.theta_deg as f32).to_le_bytes());
            out.extend_from_slice(&phi.to_le_bytes());
        }
    }

    /// A set of directions in the given order.
    ///
    /// # Errors
    /// An empty list, or a direction with a non-finite angle or an elevation outside [0, 180].
    pub fn new(directions: Vec<Direction>) -> Result<Self> {
        if directions.is_empty() {
            return Err(BtfError::parameter("directions", "the set is empty"));
        }
        if let Some(bad) = directions
            .iter()
            .find(|d| !d.is_finite() || !(0.0..=180.0).contains(&d.theta_deg))
        {
            return Err(BtfError::parameter(
                "directions",
                format!(
                    "theta={} phi={} is not a direction",
                    bad.theta_deg, bad.phi_deg
                ),
            ));
        }
        Ok(Self {
            directions,
            triangles: OnceLock::new(),
        })
    }

    /// The Bonn sampling: theta 0/15/30/45/60/75 deg with 1/6/12/18/20/24 azimuths from phi 0,
    /// ring by ring; 81 directions.
    pub fn bonn() -> Self {
        let directions = BONN_THETAS_DEG
            .iter()
            .zip(BONN_PHI_STEPS)
            .flat_map(|(&theta, steps)| {
                (0..steps).map(move |k| Direction::new(theta, 360.0 * k as f64 / steps as f64))
            })
            .collect();
        Self {
            directions,
            triangles: OnceLock::new(),
        }
    }

    /// The single direction straight down the normal (the view of an RTI capture).
    pub fn zenith() -> Self {
        Self {
            directions: vec![Direction::new(0.0, 0.0)],
            triangles: OnceLock::new(),
        }
    }

    /// Number of directions.
    pub fn len(&self) -> usize {
        self.directions.len()
    }

    /// Always false: a set holds at least one direction.
    pub fn is_empty(&self) -> bool {
        self.directions.is_empty()
    }

    /// The direction at `index`, if any.
    pub fn get(&self, index: usize) -> Option<&Direction> {
        self.directions.get(index)
    }

    /// All directions in order.
    pub fn as_slice(&self) -> &[Direction] {
        &self.directions
    }

    /// Iterates over the directions in order.
    pub fn iter(&self) -> std::slice::Iter<'_, Direction> {
        self.directions.iter()
    }

    /// Index of the direction within `tolerance_deg` of `d` (the closest one), if any.
    pub fn find(&self, d: &Direction, tolerance_deg: f64) -> Option<usize> {
        self.directions
            .iter()
            .enumerate()
            .map(|(i, s)| (i, s.angle_to(d)))
            .filter(|&(_, a)| a <= tolerance_deg)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }

    /// The zenith angle of the set's lowest direction, degrees.
    pub fn lowest_theta(&self) -> f64 {
        self.directions
            .iter()
            .map(|s| s.theta_deg)
            .fold(0.0, f64::max)
    }

    /// The share of the irradiance of a light at the set's lowest zenith angle that a light
    /// from `d` brings: 1 within the sampled cap, `cos theta / cos theta_lowest` between the
    /// lowest light and the horizon, 0 at and below it. [`DirectionSet::interpolate`]
    /// continues the lowest lights' images past the cap unchanged, and a surface turning away
    /// from a grazing light kept their brightness up to the horizon, then went black at once
    /// (a hard edge like a hole). A set that reaches the horizon or below it (an RTI dome)
    /// fades nothing: below the horizon it stands for its lowest lights. A photograph's one
    /// light at the zenith fades every other light by its cosine, as a flat matte surface
    /// would.
    pub fn irradiance_beyond_lowest(&self, d: &Direction) -> f64 {
        let lowest = self.lowest_theta();
        if lowest >= 90.0 || d.theta_deg <= lowest {
            return 1.0;
        }
        (d.theta_deg.to_radians().cos() / lowest.to_radians().cos()).clamp(0.0, 1.0)
    }

    /// The three sampled directions around `d` and their barycentric weights (>= 0, sum 1).
    ///
    /// The directions are triangulated (Delaunay) in the azimuthal-equidistant projection
    /// `theta * (cos phi, sin phi)`; a query outside the sampled cap (e.g. theta 85 deg for the
    /// Bonn set, whose last ring is 75 deg) is projected onto the nearest triangle, and a query
    /// below the horizon is treated as lying on it, or on the lowest sample if that lies lower
    /// (real RTI domes list lights slightly below the horizon). The weights are continuous in
    /// the query (piecewise linear in the projected plane), and a sampled direction gets
    /// weight 1 on itself.
    ///
    /// # Errors
    /// A direction with a non-finite angle.
    pub fn interpolate(&self, d: &Direction) -> Result<[Weighted; 3]> {
        if !d.is_finite() {
            return Err(BtfError::parameter(
                "direction",
                format!("theta={} phi={} is not finite", d.theta_deg, d.phi_deg),
            ));
        }
        let lowest = self.lowest_theta().max(90.0);
        let q = project(&Direction::new(d.theta_deg.clamp(0.0, lowest), d.phi_deg));
        let points: Vec<[f64; 2]> = self.directions.iter().map(project).collect();
        let triangles = self.triangles.get_or_init(|| triangulate(&points));
        let nearest = |q: [f64; 2]| {
            (0..points.len())
                .min_by(|&a, &b| dist2(points[a], q).total_cmp(&dist2(points[b], q)))
                .unwrap_or(0)
        };
        if triangles.is_empty() {
            // One direction, or all on a line: fall back to the nearest sample alone.
            let i = nearest(q);
            let zero = Weighted {
                index: i,
                weight: 0.0,
            };
            return Ok([
                Weighted {
                    index: i,
                    weight: 1.0,
                },
                zero,
                zero,
            ]);
        }
        let mut best: Option<(f64, [usize; 3], [f64; 3])> = None;
        for tri in triangles {
            let (closest, bary) =
                closest_point_in_triangle(q, points[tri[0]], points[tri[1]], points[tri[2]]);
            let d2 = dist2(closest, q);
            if best.as_ref().is_none_or(|b| d2 < b.0 - 1e-15) {
                best = Some((d2, *tri, bary));
            }
        }
        let (_, tri, bary) = best.expect("at least one triangle");
        // Snap tiny negative round-off and renormalise.
        let bary = bary.map(|w| w.max(0.0));
        let sum: f64 = bary.iter().sum();
        Ok(std::array::from_fn(|k| Weighted {
            index: tri[k],
            weight: bary[k] / sum,
        }))
    }
}

impl<'a> IntoIterator for &'a DirectionSet {
    type Item = &'a Direction;
    type IntoIter = std::slice::Iter<'a, Direction>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// Azimuthal-equidistant projection: polar angle becomes radius.
pub fn project(d: &Direction) -> [f64; 2] {
    let r = d.theta_deg.to_radians();
    let (s, c) = d.phi_deg.to_radians().sin_cos();
    [r * c, r * s]
}

fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

fn triangulate(points: &[[f64; 2]]) -> Vec<[usize; 3]> {
    let pts: Vec<delaunator::Point> = points
        .iter()
        .map(|p| delaunator::Point { x: p[0], y: p[1] })
        .collect();
    let t = delaunator::triangulate(&pts);
    t.triangles
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect()
}

/// The point of triangle (a, b, c) closest to `p`, and its barycentric coordinates
/// (Ericson, Real-Time Collision Detection, sec. 5.1.5, in 2D).
pub fn closest_point_in_triangle(
    p: [f64; 2],
    a: [f64; 2],
    b: [f64; 2],
    c: [f64; 2],
) -> ([f64; 2], [f64; 3]) {
    let sub = |u: [f64; 2], v: [f64; 2]| [u[0] - v[0], u[1] - v[1]];
    let dot = |u: [f64; 2], v: [f64; 2]| u[0] * v[0] + u[1] * v[1];
    let at = |u: f64, v: f64, w: f64| {
        (
            [
                u * a[0] + v * b[0] + w * c[0],
                u * a[1] + v * b[1] + w * c[1],
            ],
            [u, v, w],
        )
    };
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return at(1.0, 0.0, 0.0);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return at(0.0, 1.0, 0.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return at(1.0 - v, v, 0.0);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return at(0.0, 0.0, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return at(1.0 - w, 0.0, w);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at(0.0, 1.0 - w, w);
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    at(1.0 - v - w, v, w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn sets_written_and_read_back_are_a_fixed_point() {
        // 359.99999 is below 360 in double precision but 360.0 in single precision.
        let set = DirectionSet::new(vec![
            Direction::new(30.0, 359.99999),
            Direction::new(45.0, -1e-5),
            Direction::new(60.0, 90.0),
        ])
        .unwrap();
        let mut bytes = Vec::new();
        set.write_le(&mut bytes);
        let again = DirectionSet::read_le(&mut Reader::new(&bytes), "lights").unwrap();
        assert!(again.iter().all(|d| (0.0..360.0).contains(&d.phi_deg)));
        assert_eq!(again.get(0).unwrap().phi_deg, 0.0);
        let mut rewritten = Vec::new();
        again.write_le(&mut rewritten);
        assert_eq!(rewritten, bytes);
    }

    #[test]
    fn azimuths_wrap_into_0_to_360_exclusive() {
        for (phi, wrapped) in [
            (-1e-30, 0.0),
            (-5.6e-39, 0.0),
            (360.0, 0.0),
            (-90.0, 270.0),
            (725.0, 5.0),
        ] {
            let d = Direction::new(10.0, phi);
            assert_eq!(d.phi_deg, wrapped, "{phi}");
            assert!((0.0..360.0).contains(&d.phi_deg));
        }
    }

    #[test]
    fn bonn_sampling_has_81_whole_degree_directions() {
        let set = DirectionSet::bonn();
        assert_eq!(set.len(), 81);
        for d in &set {
            assert_eq!(d.theta_deg.fract(), 0.0);
            assert_eq!(d.phi_deg.fract(), 0.0, "{d:?}");
        }
        assert_eq!(set.get(1), Some(&Direction::new(15.0, 0.0)));
        assert_eq!(set.get(80), Some(&Direction::new(75.0, 345.0)));
    }

    #[test]
    fn vectors_round_trip() {
        for d in &DirectionSet::bonn() {
            let back = Direction::from_vector(d.vector()).unwrap();
            assert!(back.angle_to(d) < 1e-9);
        }
        assert!(Direction::from_vector([0.0, 0.0, 0.0]).is_none());
        assert!(Direction::from_vector([f64::NAN, 0.0, 1.0]).is_none());
    }

    #[test]
    fn sampled_directions_interpolate_to_themselves() {
        let set = DirectionSet::bonn();
        for (i, d) in set.iter().enumerate() {
            let w = set.interpolate(d).unwrap();
            let own: f64 = w.iter().filter(|x| x.index == i).map(|x| x.weight).sum();
            assert_abs_diff_eq!(own, 1.0, epsilon = 1e-9);
        }
    }

    #[test]
    fn weights_are_a_partition_of_unity_and_reproduce_the_query() {
        let set = DirectionSet::bonn();
        for t in 0..=18 {
            for p in 0..36 {
                let q = Direction::new(t as f64 * 5.0, p as f64 * 10.0 + 3.0);
                let w = set.interpolate(&q).unwrap();
                let sum: f64 = w.iter().map(|x| x.weight).sum();
                assert_abs_diff_eq!(sum, 1.0, epsilon = 1e-9);
                assert!(w.iter().all(|x| x.weight >= 0.0));
                if q.theta_deg <= 70.0 {
                    // Inside the triangulated cap (the outer ring's chords dip to 74.4 deg)
                    // the weights reproduce the query's projection.
                    let proj = project(&q);
                    let mix = w.iter().fold([0.0, 0.0], |acc, x| {
                        let p = project(set.get(x.index).unwrap());
                        [acc[0] + x.weight * p[0], acc[1] + x.weight * p[1]]
                    });
                    assert!(dist2(mix, proj) < 1e-12, "{q:?}");
                    // And they use nearby samples only.
                    for x in w.iter().filter(|x| x.weight > 1e-9) {
                        assert!(set.get(x.index).unwrap().angle_to(&q) < 25.0);
                    }
                }
            }
        }
    }

    #[test]
    fn samples_below_the_horizon_interpolate_to_themselves() {
        // An RTI dome: a ring at 60 deg, the zenith, and two lights just below the horizon.
        let mut dirs: Vec<Direction> = (0..8)
            .map(|k| Direction::new(60.0, 45.0 * k as f64))
            .collect();
        dirs.extend([
            Direction::new(0.0, 0.0),
            Direction::new(90.07, 16.0),
            Direction::new(91.5, 200.0),
        ]);
        let set = DirectionSet::new(dirs).unwrap();
        for (i, d) in set.iter().enumerate() {
            let w = set.interpolate(d).unwrap();
            let own: f64 = w.iter().filter(|x| x.index == i).map(|x| x.weight).sum();
            assert_abs_diff_eq!(own, 1.0, epsilon = 1e-9);
        }
        // Continuous: a fine sweep (0.01 deg steps) across the set moves every weight by little
        // per step. (The thinnest triangle here, two ring lights and the 90.07 deg one nearly
        // collinear, is 0.006 rad high: 0.03 of weight per step there; a jump would be ~1.)
        let mut last: Option<Vec<f64>> = None;
        for k in 0..=36000 {
            let q = Direction::new(75.0, k as f64 * 0.01);
            let mut full = vec![0.0; set.len()];
            for x in set.interpolate(&q).unwrap() {
                full[x.index] += x.weight;
            }
            if let Some(prev) = &last {
                let jump = full
                    .iter()
                    .zip(prev)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                assert!(jump < 0.05, "step {k}: weights jump by {jump}");
            }
            last = Some(full);
        }
    }

    #[test]
    fn lights_past_the_lowest_fade_with_their_cosine_to_the_horizon() {
        let bonn = DirectionSet::bonn();
        assert_abs_diff_eq!(bonn.lowest_theta(), 75.0, epsilon = 1e-9);
        let fade = |theta: f64| bonn.irradiance_beyond_lowest(&Direction::new(theta, 40.0));
        for theta in [0.0, 30.0, 75.0] {
            assert_eq!(fade(theta), 1.0);
        }
        let cos = |t: f64| t.to_radians().cos();
        assert_abs_diff_eq!(fade(82.0), cos(82.0) / cos(75.0), epsilon = 1e-12);
        assert_abs_diff_eq!(fade(90.0), 0.0, epsilon = 1e-12);
        assert_eq!(fade(100.0), 0.0);
        // Continuous at the lowest light, decreasing past it.
        assert!(fade(75.001) > 0.9999 && fade(80.0) > fade(85.0));
        // A dome that lists lights below the horizon fades nothing.
        let mut dome: Vec<Direction> = bonn.iter().copied().collect();
        dome.push(Direction::new(93.0, 10.0));
        let dome = DirectionSet::new(dome).unwrap();
        assert_eq!(
            dome.irradiance_beyond_lowest(&Direction::new(91.0, 0.0)),
            1.0
        );
    }

    #[test]
    fn degenerate_sets_and_queries() {
        let one = DirectionSet::zenith();
        let w = one.interpolate(&Direction::new(40.0, 10.0)).unwrap();
        assert_eq!((w[0].index, w[0].weight), (0, 1.0));
        assert!(
            DirectionSet::bonn()
                .interpolate(&Direction::new(f64::NAN, 0.0))
                .is_err()
        );
        assert!(DirectionSet::new(vec![]).is_err());
        assert!(DirectionSet::new(vec![Direction::new(f64::INFINITY, 0.0)]).is_err());
    }

    #[test]
    fn find_tolerates_zenith_azimuth() {
        let set = DirectionSet::bonn();
        assert_eq!(set.find(&Direction::new(0.0, 123.0), 0.01), Some(0));
        assert_eq!(set.find(&Direction::new(30.0, 30.0), 0.01), Some(8));
        assert_eq!(set.find(&Direction::new(32.0, 30.0), 0.5), None);
    }
}
