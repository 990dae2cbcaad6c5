//! Camera and light, both placed by (theta, phi) and distance around the origin.
//!
//! A direction (theta, phi) in the world is the one that has those angles in the tangent frame
//! of the [`Mesh::plane`](super::Mesh::plane) (normal +y, tangent +x, image up -z):
//! `(sin θ cos φ, cos θ, -sin θ sin φ)`. So a camera at (0, 0) looks straight down at the plane
//! with the texture upright, and a light at (45, 90) lights the plane from the top of the image.

use nalgebra::{Matrix4, Point3, Vector3};

use btfmrf::btf::Direction;

/// The world unit vector of a direction (see the module documentation).
pub fn world_direction(d: &Direction) -> [f32; 3] {
    let v = d.vector();
    [v[0] as f32, v[2] as f32, -v[1] as f32]
}

/// How the camera projects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Perspective with this vertical field of view, degrees.
    Perspective {
        /// Vertical field of view, degrees.
        fov_y_deg: f32,
    },
    /// Orthographic, showing `half_height` world units above and below the centre.
    Orthographic {
        /// Half the visible height, world units.
        half_height: f32,
    },
}

/// A camera on a sphere around the origin, looking at the origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Where the camera is, seen from the origin.
    pub direction: Direction,
    /// Distance from the origin, world units.
    pub distance: f32,
    /// The projection.
    pub projection: Projection,
}

impl Camera {
    /// A perspective camera (35 degree field of view).
    pub fn orbit(direction: Direction, distance: f32) -> Self {
        Self {
            direction,
            distance,
            projection: Projection::Perspective { fov_y_deg: 35.0 },
        }
    }

    /// The camera position, world units.
    pub fn eye(&self) -> [f32; 3] {
        world_direction(&self.direction).map(|x| x * self.distance)
    }

    /// The shader's `vec4`: the eye position and w = 1 (perspective), or the direction
    /// towards the camera and w = 0 (orthographic: one view direction everywhere).
    pub fn to_vec4(&self) -> [f32; 4] {
        match self.projection {
            Projection::Perspective { .. } => {
                let e = self.eye();
                [e[0], e[1], e[2], 1.0]
            }
            Projection::Orthographic { .. } => {
                let d = world_direction(&self.direction);
                [d[0], d[1], d[2], 0.0]
            }
        }
    }

    /// The column-major world-to-clip matrix for an image of this width / height (wgpu clip
    /// space: depth 0..1). Screen up is world +y, or image up (-z) when looking straight down.
    pub fn view_proj(&self, aspect: f32) -> [[f32; 4]; 4] {
        let eye = self.eye();
        let up = if (self.direction.theta_deg.to_radians()).sin().abs() < 1e-3 {
            Vector3::new(0.0, 0.0, -1.0)
        } else {
            Vector3::new(0.0, 1.0, 0.0)
        };
        let view =
            Matrix4::look_at_rh(&Point3::new(eye[0], eye[1], eye[2]), &Point3::origin(), &up);
        let (near, far) = (
            (self.distance - 3.0).max(self.distance * 0.05),
            self.distance + 3.0,
        );
        let proj = match self.projection {
            Projection::Perspective { fov_y_deg } => {
                let f = 1.0 / (fov_y_deg.to_radians() / 2.0).tan();
                Matrix4::new(
                    f / aspect,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    f,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    far / (near - far),
                    near * far / (near - far),
                    0.0,
                    0.0,
                    -1.0,
                    0.0,
                )
            }
            Projection::Orthographic { half_height } => {
                let hw = half_height * aspect;
                Matrix4::new(
                    1.0 / hw,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    1.0 / half_height,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    1.0 / (near - far),
                    near / (near - far),
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                )
            }
        };
        let m = proj * view;
        std::array::from_fn(|c| std::array::from_fn(|r| m[(r, c)]))
    }
}

/// A point light (or a directional one) placed by (theta, phi) and distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Light {
    /// Where the light is, seen from the origin.
    pub direction: Direction,
    /// Distance from the origin, world units; `None` for a directional light (at infinity).
    /// A point light's irradiance falls off as `(distance / r)^2`, 1 at the origin.
    pub distance: Option<f32>,
}

impl Light {
    /// The shader's `vec4`: position and w = 1 for a point light, direction and w = 0 for a
    /// directional one.
    pub fn to_vec4(&self) -> [f32; 4] {
        let d = world_direction(&self.direction);
        match self.distance {
            Some(r) => [d[0] * r, d[1] * r, d[2] * r, 1.0],
            None => [d[0], d[1], d[2], 0.0],
        }
    }
}

/// Camera, light and image size of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scene {
    /// The camera.
    pub camera: Camera,
    /// The light.
    pub light: Light,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl Scene {
    /// Width / height.
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height.max(1) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn apply(m: &[[f32; 4]; 4], p: [f32; 3]) -> [f32; 3] {
        let v = [p[0], p[1], p[2], 1.0];
        let r: [f32; 4] = std::array::from_fn(|row| (0..4).map(|c| m[c][row] * v[c]).sum());
        [r[0] / r[3], r[1] / r[3], r[2] / r[3]]
    }

    #[test]
    fn a_camera_straight_down_sees_the_plane_upright() {
        let cam = Camera {
            direction: Direction::new(0.0, 0.0),
            distance: 3.0,
            projection: Projection::Orthographic { half_height: 1.0 },
        };
        let m = cam.view_proj(1.0);
        // Plane corner (-1, 0, -1) is the texture's top-left (u = 0, v = 0): clip (-1, +1).
        let c = apply(&m, [-1.0, 0.0, -1.0]);
        assert!(
            (c[0] + 1.0).abs() < 1e-5 && (c[1] - 1.0).abs() < 1e-5,
            "{c:?}"
        );
        assert!((0.0..=1.0).contains(&c[2]));
        let c = apply(&m, [1.0, 0.0, 1.0]);
        assert!(
            (c[0] - 1.0).abs() < 1e-5 && (c[1] + 1.0).abs() < 1e-5,
            "{c:?}"
        );
    }

    #[test]
    fn world_directions_match_the_plane_frame() {
        let d = world_direction(&Direction::new(90.0, 90.0));
        // phi 90 is image up, which is -z on the plane.
        assert!((d[2] + 1.0).abs() < 1e-6 && d[0].abs() < 1e-6, "{d:?}");
        let p = Camera::orbit(Direction::new(30.0, 10.0), 3.0).view_proj(1.5);
        let c = apply(&p, [0.0, 0.0, 0.0]);
        assert!(c[0].abs() < 1e-5 && c[1].abs() < 1e-5 && (0.0..1.0).contains(&c[2]));
    }
}
