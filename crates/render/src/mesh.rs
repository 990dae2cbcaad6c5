//! Triangle meshes with tangent frames: sphere, plane, a draped cloth, torus, and OBJ files.
//!
//! World space has y up. Texture coordinates follow the image convention (u along columns,
//! v along rows, v = 0 on the top row), and the tangent frame follows the BTF convention of
//! [`btfmrf::btf::directions`]: x = tangent (direction of increasing u), y = bitangent (image
//! up, the direction of *decreasing* v), z = normal. The bitangent is
//! `tangent.w * cross(normal, tangent)`, so mirrored texture mappings work too.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::{RenderError, Result};

/// One vertex as the shaders read it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    /// Position, world units.
    pub position: [f32; 3],
    /// Unit normal.
    pub normal: [f32; 3],
    /// Unit tangent (increasing u, orthogonal to the normal); `w` = ±1, the bitangent's sign.
    pub tangent: [f32; 4],
    /// Texture coordinates, in repetitions of the (tileable) texture.
    pub uv: [f32; 2],
    /// Blending across the nearest face edge along u and along v: `[angle_u, weight_u,
    /// angle_v, weight_v]`, the frame beyond the edge as a rotation of this one about the
    /// normal (radians) and its raw weight (1 at the edge, 0 from [`SEAM_BAND`] of a face
    /// away; this frame's weight is 1). All zero on meshes whose frames run on continuously.
    pub seam: [f32; 4],
    /// This point's texture coordinates on the face beyond the edge along u, then along v
    /// (that face's mapping continued past its edge), so the shaders can cut between the two
    /// mappings there; `uv` twice where there is no such face.
    pub seam_uv: [f32; 4],
}

/// How far into a face (a fraction of its side) the frame beyond an edge is blended in.
/// Where a tile meets itself turned (6 edges of the inflated-cube sphere) the light's azimuth
/// in the tangent frame jumps by the turn, and a measured material whose images depend on the
/// azimuth (every real RTI capture, whose lamp brightness varies around the dome) showed the
/// edge as a sharp brightness wedge; over this band the shaders cut between the mappings
/// along the relief and turn the brightness gradually (shaders/mrf.wgsl, `seam_cut`).
pub const SEAM_BAND: f32 = 0.25;

/// Rotations below this (radians) are the same frame.
const TURNED: f32 = 1e-3;

/// A rotation (radians) in `(-3 pi / 4, 5 pi / 4]`: a half turn is always `pi`, never `-pi`,
/// so that the angles along one edge (interpolated between vertices) do not pass through 0
/// where rounding flips the sign of `atan2`.
fn canonical_turn(angle: f32) -> f32 {
    use std::f32::consts::{FRAC_PI_4, TAU};
    if angle <= -3.0 * FRAC_PI_4 {
        angle + TAU
    } else if angle > 5.0 * FRAC_PI_4 {
        angle - TAU
    } else {
        angle
    }
}

impl Vertex {
    /// The bitangent (image up): `w * cross(normal, tangent)`.
    pub fn bitangent(&self) -> [f32; 3] {
        let c = cross(
            self.normal,
            [self.tangent[0], self.tangent[1], self.tangent[2]],
        );
        c.map(|x| x * self.tangent[3])
    }

    /// The tangents (with the bitangent sign) of the frames a fragment here blends: its own,
    /// then each frame beyond a nearby edge that is turned against it (the shader's
    /// `turned`).
    pub fn frames(&self) -> impl Iterator<Item = [f32; 4]> + '_ {
        let own = self.tangent;
        let b = self.bitangent();
        let partners = [(self.seam[0], self.seam[1]), (self.seam[2], self.seam[3])];
        std::iter::once(own).chain(
            partners
                .into_iter()
                .filter(|&(angle, weight)| weight > 0.0 && angle.abs() > TURNED)
                .map(move |(angle, _)| {
                    let (sin, cos) = angle.sin_cos();
                    let t = [0, 1, 2].map(|k| cos * own[k] + sin * b[k]);
                    [t[0], t[1], t[2], own[3]]
                }),
        )
    }

    /// The vertex buffer layout matching the shaders' `VertexInput`.
    pub fn layout() -> wgpu::VertexBufferLayout<'static> {
        const ATTRIBUTES: [wgpu::VertexAttribute; 6] = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x4, 3 => Float32x2, 4 => Float32x4, 5 => Float32x4];
        wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Vertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &ATTRIBUTES,
        }
    }
}

/// An indexed triangle mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// The vertices.
    pub vertices: Vec<Vertex>,
    /// Three indices per triangle, counter-clockwise seen from outside.
    pub indices: Vec<u32>,
}

/// The grid cells a built-in mesh may have along its longest parameter direction.
pub const DETAIL_RANGE: std::ops::RangeInclusive<u32> = 4..=2048;

/// Which mesh to render.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MeshKind {
    /// A unit sphere (an inflated cube, see [`Mesh::sphere`]).
    Sphere,
    /// A 2 x 2 square in the xz plane, normal +y.
    Plane,
    /// A sheet draped in sine folds.
    Cloth,
    /// A torus (radii 1 and 0.4).
    Torus,
    /// A Wavefront OBJ file (with texture coordinates), centred and scaled to radius 1.
    Obj(PathBuf),
}

impl std::str::FromStr for MeshKind {
    type Err = std::convert::Infallible;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "sphere" => MeshKind::Sphere,
            "plane" => MeshKind::Plane,
            "cloth" => MeshKind::Cloth,
            "torus" => MeshKind::Torus,
            _ => MeshKind::Obj(PathBuf::from(s)),
        })
    }
}

impl std::fmt::Display for MeshKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MeshKind::Sphere => f.write_str("sphere"),
            MeshKind::Plane => f.write_str("plane"),
            MeshKind::Cloth => f.write_str("cloth"),
            MeshKind::Torus => f.write_str("torus"),
            MeshKind::Obj(p) => write!(f, "{}", p.display()),
        }
    }
}

impl MeshKind {
    /// Builds the mesh. `detail` is the number of grid cells along the longest parameter
    /// direction (large for displacement mapping; within [`DETAIL_RANGE`]); `repeats` how
    /// many texture tiles cover the unit of length of the built-in shapes (OBJ files keep
    /// their own coordinates and ignore both).
    ///
    /// # Errors
    /// A `detail` outside [`DETAIL_RANGE`]; an OBJ file that is missing, corrupt, empty or
    /// without texture coordinates.
    pub fn build(&self, detail: u32, repeats: f32) -> Result<Mesh> {
        if !DETAIL_RANGE.contains(&detail) {
            return Err(RenderError::parameter(
                "--detail",
                format!(
                    "{detail} is outside {}..={} grid cells",
                    DETAIL_RANGE.start(),
                    DETAIL_RANGE.end()
                ),
            ));
        }
        let n = detail;
        Ok(match self {
            MeshKind::Sphere => Mesh::sphere((n / 4).max(2), repeats),
            MeshKind::Plane => Mesh::plane(n, repeats),
            MeshKind::Cloth => Mesh::cloth(n, repeats),
            MeshKind::Torus => Mesh::torus(n, (n * 2 / 5).max(3), repeats),
            MeshKind::Obj(path) => Mesh::from_obj(path)?,
        })
    }
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn normalize(a: [f32; 3]) -> Option<[f32; 3]> {
    let len = dot(a, a).sqrt();
    (len.is_finite() && len > 1e-12).then(|| a.map(|x| x / len))
}

impl Mesh {
    /// A grid of `(cols + 1) x (rows + 1)` vertices from a parametric surface `f(s, t)`
    /// (s, t in [0, 1]) returning position and normal; uv = `(s * su, t * sv)`.
    fn grid(
        cols: u32,
        rows: u32,
        (su, sv): (f32, f32),
        f: impl Fn(f32, f32) -> ([f32; 3], [f32; 3]),
    ) -> Self {
        let mut vertices = Vec::with_capacity(((cols + 1) * (rows + 1)) as usize);
        for r in 0..=rows {
            for c in 0..=cols {
                let (s, t) = (c as f32 / cols as f32, r as f32 / rows as f32);
                let (position, normal) = f(s, t);
                vertices.push(Vertex {
                    position,
                    normal,
                    tangent: [0.0; 4],
                    uv: [s * su, t * sv],
                    seam: [0.0; 4],
                    seam_uv: [s * su, t * sv, s * su, t * sv],
                });
            }
        }
        let mut indices = Vec::with_capacity((cols * rows * 6) as usize);
        let at = |c: u32, r: u32| r * (cols + 1) + c;
        for r in 0..rows {
            for c in 0..cols {
                let (a, b, d, e) = (at(c, r), at(c + 1, r), at(c, r + 1), at(c + 1, r + 1));
                indices.extend_from_slice(&[a, d, b, b, d, e]);
            }
        }
        let mut mesh = Self { vertices, indices };
        mesh.orient_outwards();
        mesh.compute_tangents();
        mesh
    }

    /// Flips every triangle whose winding disagrees with its vertex normals, so front faces
    /// are counter-clockwise seen from the side the normals point to.
    fn orient_outwards(&mut self) {
        for tri in self.indices.chunks_exact_mut(3) {
            let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| self.vertices[i as usize]);
            let face = cross(sub(b.position, a.position), sub(c.position, a.position));
            let n = [0, 1, 2].map(|k| a.normal[k] + b.normal[k] + c.normal[k]);
            if dot(face, n) < 0.0 {
                tri.swap(1, 2);
            }
        }
    }

    /// A unit sphere as an inflated cube: each of the 6 faces a `cells` x `cells` grid,
    /// spaced by equal angles so that texels keep nearly one size everywhere (a latitude-
    /// longitude grid squeezes the texture into a point at the poles). Each face holds a
    /// whole number of texture repetitions, about `repeats` per 2 units of length like the
    /// plane, so the tileable texture runs on seamlessly across the 4 faces around the
    /// equator and from the front one (+z) onto the top and bottom; across the other 6 edges
    /// the tile meets itself turned by a quarter or half turn. Within a quarter of a face of
    /// every edge a fragment sees both faces' mappings ([`Vertex::seam`],
    /// [`Vertex::seam_uv`]): the shaders cut between them along the relief and turn the
    /// brightness gradually, so neither the shading, nor the texture's layout, nor (under
    /// displacement) the surface steps at the edge.
    pub fn sphere(cells: u32, repeats: f32) -> Self {
        use std::f32::consts::FRAC_PI_4;
        // A face edge is a quarter of the equator, pi / 2 long.
        let k = (repeats * FRAC_PI_4).round().max(1.0);
        let side = |phi: f32| {
            let (sp, cp) = phi.to_radians().sin_cos();
            ([cp, 0.0, -sp], [-sp, 0.0, -cp], [0.0, -1.0, 0.0])
        };
        // (centre, u axis, v axis) per face: the 4 around the equator (u eastwards, v down),
        // then top and bottom, joined without a seam to the side face at +z (the one the
        // default camera, phi = 270, looks at).
        let faces = [
            side(0.0),
            side(90.0),
            side(180.0),
            side(270.0),
            ([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            ([0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]),
        ];
        let mut mesh = Mesh {
            vertices: Vec::new(),
            indices: Vec::new(),
        };
        for (n, u, v) in faces {
            let face = Self::grid(cells, cells, (k, k), |s, t| {
                let a = (FRAC_PI_4 * (2.0 * s - 1.0)).tan();
                let b = (FRAC_PI_4 * (2.0 * t - 1.0)).tan();
                let p = normalize([0, 1, 2].map(|i| n[i] + a * u[i] + b * v[i])).unwrap_or(n);
                (p, p)
            });
            let base = mesh.vertices.len() as u32;
            mesh.vertices.extend(face.vertices);
            mesh.indices.extend(face.indices.iter().map(|i| base + i));
        }
        // Face f's texture coordinates of a point p on the sphere (the inverse of the grid's
        // equal-angle mapping, continued past the face's edges), where p lies in front of it.
        let uv_on = |f: usize, p: [f32; 3]| -> Option<[f32; 2]> {
            let (n, u, v) = faces[f];
            let depth = dot(p, n);
            let coordinate = |axis: [f32; 3]| (dot(p, axis) / depth).atan() / FRAC_PI_4;
            (depth > 1e-3).then(|| {
                [
                    0.5 * (coordinate(u) + 1.0) * k,
                    0.5 * (coordinate(v) + 1.0) * k,
                ]
            })
        };
        mesh.blend_face_edges(cells, uv_on);
        mesh
    }

    /// Fills [`Vertex::seam`] for a mesh of square faces, each a `cells` x `cells` grid
    /// (as [`Mesh::grid`] lays them out, one after another): per vertex, towards the nearest
    /// edge along u and along v, the rotation of the frame on the face beyond (measured at the
    /// coincident vertex on that edge, in the same row or column), weighted by the distance.
    /// Across an edge both sides then blend the same two frames; at the 8 corners, where three
    /// faces meet, nearly the same.
    fn blend_face_edges(
        &mut self,
        cells: u32,
        uv_on: impl Fn(usize, [f32; 3]) -> Option<[f32; 2]>,
    ) {
        let side = cells as usize + 1;
        let per_face = side * side;
        let last = cells as usize;
        // Vertices by position (to 1e-5 units): the coincident vertex across an edge.
        let key = |p: [f32; 3]| p.map(|x| (x * 1e5).round() as i64);
        let mut by_position: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, v) in self.vertices.iter().enumerate() {
            by_position.entry(key(v.position)).or_default().push(i);
        }
        let vertices = &self.vertices;
        // The face beyond edge vertex i, and the rotation from i's frame to the frame of its
        // coincident vertex there.
        let beyond = |i: usize| -> Option<(usize, f32)> {
            let a = &vertices[i];
            let &j = by_position[&key(a.position)]
                .iter()
                .find(|&&j| j / per_face != i / per_face)?;
            let t = [a.tangent[0], a.tangent[1], a.tangent[2]];
            let g = &vertices[j];
            let tg = [g.tangent[0], g.tangent[1], g.tangent[2]];
            let angle = dot(tg, a.bitangent()).atan2(dot(tg, t));
            Some((j / per_face, canonical_turn(angle)))
        };
        // Off the corners, where the vertex on the edge has two faces beyond it.
        let inner = |k: usize| if last >= 2 { k.clamp(1, last - 1) } else { k };
        // The nearer edge along one axis and the distance to it (a fraction of the side).
        let nearer = |k: usize| {
            let s = k as f32 / cells as f32;
            if s < 0.5 { (0, s) } else { (last, 1.0 - s) }
        };
        let weight = |d: f32| (1.0 - d / SEAM_BAND).max(0.0);
        let seams: Vec<([f32; 4], [f32; 4])> = (0..vertices.len())
            .map(|i| {
                let (face, r, c) = (i / per_face, (i % per_face) / side, i % side);
                let v = &vertices[i];
                // Angle, weight and texture coordinates beyond the nearer edge of one axis.
                let partner = |edge_vertex: usize, d: f32| -> (f32, f32, [f32; 2]) {
                    let Some((g, angle)) = beyond(edge_vertex) else {
                        return (0.0, 0.0, v.uv);
                    };
                    match uv_on(g, v.position) {
                        Some(uv) => (angle, weight(d), uv),
                        None => (angle, 0.0, v.uv),
                    }
                };
                let (edge_c, du) = nearer(c);
                let (edge_r, dv) = nearer(r);
                let (au, wu, uv_u) = partner(face * per_face + inner(r) * side + edge_c, du);
                let (av, wv, uv_v) = partner(face * per_face + edge_r * side + inner(c), dv);
                ([au, wu, av, wv], [uv_u[0], uv_u[1], uv_v[0], uv_v[1]])
            })
            .collect();
        for (v, (seam, seam_uv)) in self.vertices.iter_mut().zip(seams) {
            v.seam = seam;
            v.seam_uv = seam_uv;
        }
    }

    /// A 2 x 2 square in the xz plane facing +y, `cells` x `cells` quads; u along +x, v along
    /// +z, the texture repeating `repeats` times across.
    pub fn plane(cells: u32, repeats: f32) -> Self {
        Self::grid(cells, cells, (repeats, repeats), |s, t| {
            ([2.0 * s - 1.0, 0.0, 2.0 * t - 1.0], [0.0, 1.0, 0.0])
        })
    }

    /// A 2 x 2 sheet draped in sine folds (heights up to about 0.3).
    pub fn cloth(cells: u32, repeats: f32) -> Self {
        let height = |x: f32, z: f32| {
            0.18 * (3.0 * x + 0.4).sin() * (1.3 * z).cos() + 0.08 * (5.0 * z + 2.0 * x).sin()
                - 0.12 * x * x
        };
        Self::grid(cells, cells, (repeats, repeats), |s, t| {
            let (x, z) = (2.0 * s - 1.0, 2.0 * t - 1.0);
            let e = 1e-3;
            let dx = (height(x + e, z) - height(x - e, z)) / (2.0 * e);
            let dz = (height(x, z + e) - height(x, z - e)) / (2.0 * e);
            let n = normalize([-dx, 1.0, -dz]).unwrap_or([0.0, 1.0, 0.0]);
            ([x, height(x, z), z], n)
        })
    }

    /// A torus around the y axis, radii 1 (ring) and 0.4 (tube); `segments` around the ring,
    /// `sides` around the tube. The texture repeats a whole number of times both ways (about
    /// `repeats` per unit of length), so both seams are seamless.
    pub fn torus(segments: u32, sides: u32, repeats: f32) -> Self {
        use std::f32::consts::PI;
        let (big, small) = (1.0f32, 0.4f32);
        let tau = 2.0 * PI;
        Self::grid(
            segments,
            sides,
            (
                (tau * big * repeats / 2.0).round().max(1.0),
                (tau * small * repeats / 2.0).round().max(1.0),
            ),
            |s, t| {
                let (sa, ca) = (tau * s).sin_cos();
                let (sb, cb) = (tau * t).sin_cos();
                let n = [cb * ca, sb, -cb * sa];
                let p = [
                    (big + small * cb) * ca,
                    small * sb,
                    -(big + small * cb) * sa,
                ];
                (p, n)
            },
        )
    }

    /// Reads a Wavefront OBJ file (all its models), centred on the origin and scaled to fit
    /// a unit sphere. Normals are computed when missing; tangents always.
    ///
    /// # Errors
    /// A missing or corrupt file, no triangles, no texture coordinates, or non-finite values.
    pub fn from_obj(path: &Path) -> Result<Self> {
        let err = |reason: String| RenderError::Mesh {
            path: path.to_path_buf(),
            reason,
        };
        let (models, _) = tobj::load_obj(
            path,
            &tobj::LoadOptions {
                single_index: true,
                triangulate: true,
                ignore_points: true,
                ignore_lines: true,
            },
        )
        .map_err(|e| err(format!("not a readable OBJ file ({e})")))?;
        let mut mesh = Mesh {
            vertices: Vec::new(),
            indices: Vec::new(),
        };
        let mut missing_normals = false;
        for m in &models {
            let m = &m.mesh;
            let count = m.positions.len() / 3;
            if m.texcoords.len() < 2 * count {
                return Err(err(
                    "no texture coordinates (they are needed to map the material)".into(),
                ));
            }
            missing_normals |= m.normals.len() < 3 * count;
            let base = mesh.vertices.len() as u32;
            for i in 0..count {
                let normal = if m.normals.len() >= 3 * count {
                    [m.normals[3 * i], m.normals[3 * i + 1], m.normals[3 * i + 2]]
                } else {
                    [0.0; 3]
                };
                // OBJ's v grows upwards; ours grows down the image.
                let uv = [m.texcoords[2 * i], 1.0 - m.texcoords[2 * i + 1]];
                mesh.vertices.push(Vertex {
                    position: [
                        m.positions[3 * i],
                        m.positions[3 * i + 1],
                        m.positions[3 * i + 2],
                    ],
                    normal,
                    tangent: [0.0; 4],
                    uv,
                    seam: [0.0; 4],
                    seam_uv: [uv[0], uv[1], uv[0], uv[1]],
                });
            }
            for &i in &m.indices {
                if i as usize >= count {
                    return Err(err(format!("face index {} beyond {count} vertices", i + 1)));
                }
                mesh.indices.push(base + i);
            }
        }
        if mesh.indices.len() < 3 {
            return Err(err("no triangles".into()));
        }
        let finite = mesh.vertices.iter().all(|v| {
            v.position
                .iter()
                .chain(&v.normal)
                .chain(&v.uv)
                .all(|x| x.is_finite())
        });
        if !finite {
            return Err(err("non-finite coordinates".into()));
        }
        if missing_normals {
            mesh.compute_normals();
        }
        for v in &mut mesh.vertices {
            v.normal = normalize(v.normal).unwrap_or([0.0, 1.0, 0.0]);
        }
        mesh.fit_unit_sphere();
        mesh.compute_tangents();
        Ok(mesh)
    }

    /// Centres the mesh on its bounding-box centre and scales it to radius 1.
    fn fit_unit_sphere(&mut self) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for v in &self.vertices {
            for k in 0..3 {
                lo[k] = lo[k].min(v.position[k]);
                hi[k] = hi[k].max(v.position[k]);
            }
        }
        let centre = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
        let radius = self
            .vertices
            .iter()
            .map(|v| dot(sub(v.position, centre), sub(v.position, centre)).sqrt())
            .fold(0.0f32, f32::max);
        let scale = if radius > 0.0 { 1.0 / radius } else { 1.0 };
        for v in &mut self.vertices {
            v.position = [0, 1, 2].map(|k| (v.position[k] - centre[k]) * scale);
        }
    }

    /// Area-weighted vertex normals from the faces.
    pub fn compute_normals(&mut self) {
        let mut acc = vec![[0.0f32; 3]; self.vertices.len()];
        for tri in self.indices.chunks_exact(3) {
            let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| self.vertices[i as usize].position);
            let face = cross(sub(b, a), sub(c, a));
            for &i in tri {
                for k in 0..3 {
                    acc[i as usize][k] += face[k];
                }
            }
        }
        for (v, n) in self.vertices.iter_mut().zip(acc) {
            v.normal = normalize(n).unwrap_or([0.0, 1.0, 0.0]);
        }
    }

    /// Tangent frames from the texture-coordinate derivatives of the faces (accumulated per
    /// vertex, made orthogonal to the normal; the bitangent sign from `-dP/dv`). Vertices
    /// whose faces have degenerate texture coordinates get an arbitrary orthonormal frame.
    pub fn compute_tangents(&mut self) {
        let mut du = vec![[0.0f32; 3]; self.vertices.len()];
        let mut dv = vec![[0.0f32; 3]; self.vertices.len()];
        for tri in self.indices.chunks_exact(3) {
            let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| self.vertices[i as usize]);
            let (e1, e2) = (sub(b.position, a.position), sub(c.position, a.position));
            let (s1, t1) = (b.uv[0] - a.uv[0], b.uv[1] - a.uv[1]);
            let (s2, t2) = (c.uv[0] - a.uv[0], c.uv[1] - a.uv[1]);
            let det = s1 * t2 - s2 * t1;
            if det.abs() < 1e-20 {
                continue;
            }
            // dP/du and dP/dv of the face, weighted by its uv area (det) so that large faces
            // count more: (e1 t2 - e2 t1) sign(det), (e2 s1 - e1 s2) sign(det).
            let sign = det.signum();
            let pu = [0, 1, 2].map(|k| (e1[k] * t2 - e2[k] * t1) * sign);
            let pv = [0, 1, 2].map(|k| (e2[k] * s1 - e1[k] * s2) * sign);
            for &i in tri {
                for k in 0..3 {
                    du[i as usize][k] += pu[k];
                    dv[i as usize][k] += pv[k];
                }
            }
        }
        for ((v, pu), pv) in self.vertices.iter_mut().zip(du).zip(dv) {
            let n = v.normal;
            let t = normalize(sub(pu, n.map(|x| x * dot(n, pu))))
                .or_else(|| {
                    // No u derivative: take one perpendicular to the v derivative, else any.
                    normalize(cross(pv, n))
                })
                .unwrap_or_else(|| {
                    let helper = if n[0].abs() < 0.9 {
                        [1.0, 0.0, 0.0]
                    } else {
                        [0.0, 1.0, 0.0]
                    };
                    normalize(cross(helper, n)).unwrap_or([1.0, 0.0, 0.0])
                });
            let w = if dot(cross(n, t), pv) > 0.0 {
                -1.0
            } else {
                1.0
            };
            v.tangent = [t[0], t[1], t[2], w];
        }
    }

    /// World units per texture repetition: `sqrt(world area / uv area)` over all faces.
    pub fn world_per_uv(&self) -> f32 {
        let (mut world, mut uv) = (0.0f64, 0.0f64);
        for tri in self.indices.chunks_exact(3) {
            let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| self.vertices[i as usize]);
            let f = cross(sub(b.position, a.position), sub(c.position, a.position));
            world += 0.5 * f64::from(dot(f, f).sqrt());
            let (s1, t1) = (b.uv[0] - a.uv[0], b.uv[1] - a.uv[1]);
            let (s2, t2) = (c.uv[0] - a.uv[0], c.uv[1] - a.uv[1]);
            uv += 0.5 * f64::from((s1 * t2 - s2 * t1).abs());
        }
        if uv > 0.0 {
            (world / uv).sqrt() as f32
        } else {
            1.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every frame orthonormal, right-handed with the bitangent sign, and agreeing with the
    /// texture derivatives of the faces around it.
    fn check_frames(mesh: &Mesh, name: &str) {
        for (i, v) in mesh.vertices.iter().enumerate() {
            let t = [v.tangent[0], v.tangent[1], v.tangent[2]];
            let b = v.bitangent();
            assert!((dot(v.normal, v.normal) - 1.0).abs() < 1e-4, "{name} {i}");
            assert!((dot(t, t) - 1.0).abs() < 1e-4, "{name} {i}");
            assert!((dot(b, b) - 1.0).abs() < 1e-4, "{name} {i}");
            assert!(dot(t, v.normal).abs() < 1e-4, "{name} {i}");
            assert!(dot(b, v.normal).abs() < 1e-4, "{name} {i}");
            assert!(dot(t, b).abs() < 1e-4, "{name} {i}");
            assert!(v.tangent[3].abs() == 1.0);
        }
        // Per face: the tangent follows dP/du and the bitangent -dP/dv (non-degenerate faces).
        let mut checked = 0;
        for tri in mesh.indices.chunks_exact(3) {
            let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| mesh.vertices[i as usize]);
            let (e1, e2) = (sub(b.position, a.position), sub(c.position, a.position));
            let (s1, t1) = (b.uv[0] - a.uv[0], b.uv[1] - a.uv[1]);
            let (s2, t2) = (c.uv[0] - a.uv[0], c.uv[1] - a.uv[1]);
            let det = s1 * t2 - s2 * t1;
            let shortest = [e1, e2, sub(c.position, b.position)]
                .map(|e| dot(e, e).sqrt())
                .into_iter()
                .fold(f32::INFINITY, f32::min);
            if det.abs() < 1e-9 || shortest < 1e-5 {
                continue;
            }
            // Faces with a degenerate edge (at the sphere's poles) have no derivatives.
            let (Some(pu), Some(pv)) = (
                normalize([0, 1, 2].map(|k| (e1[k] * t2 - e2[k] * t1) / det)),
                normalize([0, 1, 2].map(|k| (e2[k] * s1 - e1[k] * s2) / det)),
            ) else {
                continue;
            };
            for v in [a, b, c] {
                let t = [v.tangent[0], v.tangent[1], v.tangent[2]];
                assert!(
                    dot(t, pu) > 0.5,
                    "{name}: tangent {t:?} against dP/du {pu:?}"
                );
                assert!(
                    dot(v.bitangent(), pv) < -0.5,
                    "{name}: bitangent along dP/dv"
                );
            }
            // Front faces counter-clockwise seen from the normal's side.
            let face = cross(e1, e2);
            assert!(dot(face, a.normal) > 0.0, "{name}: winding");
            checked += 1;
        }
        assert!(
            checked > mesh.indices.len() / 3 / 2,
            "{name}: {checked} faces"
        );
    }

    #[test]
    fn built_in_meshes_have_orthonormal_frames_consistent_with_uv() {
        for kind in [
            MeshKind::Sphere,
            MeshKind::Plane,
            MeshKind::Cloth,
            MeshKind::Torus,
        ] {
            let mesh = kind.build(24, 2.0).unwrap();
            check_frames(&mesh, &kind.to_string());
        }
    }

    #[test]
    fn closed_meshes_wrap_a_whole_number_of_tiles() {
        for repeats in [0.7f32, 1.0, 2.3] {
            for mesh in [Mesh::sphere(4, repeats), Mesh::torus(16, 8, repeats)] {
                let max_u = mesh.vertices.iter().map(|v| v.uv[0]).fold(0.0f32, f32::max);
                assert!(max_u >= 1.0 && max_u.fract() == 0.0, "{max_u}");
            }
            let torus = Mesh::torus(16, 8, repeats);
            let max_v = torus
                .vertices
                .iter()
                .map(|v| v.uv[1])
                .fold(0.0f32, f32::max);
            assert!(max_v >= 1.0 && max_v.fract() == 0.0, "{max_v}");
        }
    }

    /// Texture repetitions per world unit over the sphere's triangles: a mapping that
    /// collapses (latitude-longitude at the poles) makes this spread without bound.
    #[test]
    fn the_sphere_texture_keeps_nearly_one_scale_everywhere() {
        let mesh = Mesh::sphere(16, 1.0);
        let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
        for tri in mesh.indices.chunks_exact(3) {
            let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| mesh.vertices[i as usize]);
            let f = cross(sub(b.position, a.position), sub(c.position, a.position));
            let world = dot(f, f).sqrt();
            let (s1, t1) = (b.uv[0] - a.uv[0], b.uv[1] - a.uv[1]);
            let (s2, t2) = (c.uv[0] - a.uv[0], c.uv[1] - a.uv[1]);
            let density = ((s1 * t2 - s2 * t1).abs() / world).sqrt();
            lo = lo.min(density);
            hi = hi.max(density);
        }
        assert!(hi / lo < 1.6, "texture density from {lo} to {hi} per unit");
        for v in &mesh.vertices {
            assert!((dot(v.position, v.position) - 1.0).abs() < 1e-5);
        }
    }

    /// The frames a vertex blends, as (world tangent, normalised weight), frames whose
    /// tangents' dot product exceeds `same` merged (the shader's `seam_weights`).
    fn blended_frames(v: &Vertex, same: f32) -> Vec<([f32; 3], f32)> {
        let total = 1.0 + v.seam[1] + v.seam[3];
        let mut out: Vec<([f32; 3], f32)> = Vec::new();
        let weights = [1.0, v.seam[1], v.seam[3]];
        let angles = [0.0, v.seam[0], v.seam[2]];
        for (angle, weight) in angles.into_iter().zip(weights) {
            let (sin, cos) = angle.sin_cos();
            let b = v.bitangent();
            let t = [0, 1, 2].map(|k| cos * v.tangent[k] + sin * b[k]);
            match out.iter_mut().find(|(u, _)| dot(*u, t) > same) {
                Some((_, w)) => *w += weight / total,
                None => out.push((t, weight / total)),
            }
        }
        out.retain(|&(_, w)| w > 1e-6);
        out
    }

    #[test]
    fn the_sphere_blends_the_same_frames_on_both_sides_of_every_edge() {
        let mesh = Mesh::sphere(8, 1.0);
        let (mut pairs, mut turned) = (0, 0);
        for (i, a) in mesh.vertices.iter().enumerate() {
            for b in &mesh.vertices[i + 1..] {
                let d = sub(a.position, b.position);
                if dot(d, d) > 1e-10 {
                    continue;
                }
                // At the 8 corners three faces meet with frames that are not quarter turns
                // of each other; the blend there is close, not exact.
                if a.position.iter().all(|x| (x.abs() - 0.57735).abs() < 1e-3) {
                    continue;
                }
                pairs += 1;
                let t = |v: &Vertex| [v.tangent[0], v.tangent[1], v.tangent[2]];
                turned += usize::from(dot(t(a), t(b)) < 0.99);
                // On the edge, the texture coordinates beyond it are the other face's own.
                for (p, q) in [(a, b), (b, a)] {
                    let beyond = if p.seam[1] >= 1.0 {
                        [p.seam_uv[0], p.seam_uv[1]]
                    } else {
                        [p.seam_uv[2], p.seam_uv[3]]
                    };
                    let d = (beyond[0] - q.uv[0]).abs() + (beyond[1] - q.uv[1]).abs();
                    assert!(d < 1e-4, "{:?}: {beyond:?} vs {:?}", p.position, q.uv);
                }
                // Exact where only the edge's two faces take part; within a band of a
                // corner the third face's frame comes in, measured a step away on its edge
                // (within 25 degrees).
                let near_corner = a.seam[1] > 0.0 && a.seam[3] > 0.0;
                let same = if near_corner { 0.9 } else { 0.9999 };
                let (fa, fb) = (blended_frames(a, same), blended_frames(b, same));
                assert_eq!(fa.len(), fb.len(), "{fa:?} vs {fb:?}");
                for (ta, wa) in &fa {
                    let wb = fb.iter().find(|(tb, _)| dot(*ta, *tb) > same).map(|f| f.1);
                    assert!(
                        wb.is_some_and(|wb| (wb - wa).abs() < 1e-5),
                        "{:?}: {fa:?} vs {fb:?}",
                        a.position
                    );
                }
            }
        }
        // 12 edges of 7 vertices between the corners.
        assert_eq!(pairs, 12 * 7, "coincident pairs");
        assert!(turned > 0, "no turned edge to test");
        // Neighbouring vertices of a face blend nearly the same rotation (no half turn written
        // once as pi and once as -pi, which the shader would interpolate through 0).
        let side = 9;
        for (i, v) in mesh.vertices.iter().enumerate() {
            if i % side + 1 < side {
                let w = mesh.vertices[i + 1];
                for k in [0, 2] {
                    if v.seam[k + 1] > 0.0 || w.seam[k + 1] > 0.0 {
                        let step = (v.seam[k] - w.seam[k]).abs();
                        assert!(step < 1.0, "{:?} vs {:?}", v.seam, w.seam);
                    }
                }
            }
        }
        // Away from the edges a fragment keeps its own frame alone.
        let centre = &mesh.vertices[4 * 9 + 4];
        assert_eq!(blended_frames(centre, 0.9999).len(), 1);
        assert_eq!(centre.frames().count(), 1);
    }

    #[test]
    fn plane_frame_is_the_btf_frame() {
        let mesh = Mesh::plane(2, 1.0);
        let v = mesh.vertices[0];
        assert_eq!(v.normal, [0.0, 1.0, 0.0]);
        assert!((v.tangent[0] - 1.0).abs() < 1e-6);
        // Image up is -z: the row index grows along +z.
        let b = v.bitangent();
        assert!((b[2] + 1.0).abs() < 1e-6, "{b:?}");
        assert!((mesh.world_per_uv() - 2.0).abs() < 1e-5);
    }

    #[test]
    fn obj_files_load_with_computed_tangents_and_bad_ones_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let good = dir.path().join("quad.obj");
        std::fs::write(
            &good,
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n",
        )
        .unwrap();
        let mesh = Mesh::from_obj(&good).unwrap();
        assert_eq!(mesh.indices.len(), 6);
        check_frames(&mesh, "quad.obj");
        // Normals computed (the quad faces +z), tangent +x, image up +y (OBJ v grows up).
        let v = mesh.vertices[0];
        assert!((v.normal[2] - 1.0).abs() < 1e-5);
        assert!((v.bitangent()[1] - 1.0).abs() < 1e-5);

        let no_uv = dir.path().join("no_uv.obj");
        std::fs::write(&no_uv, "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n").unwrap();
        let e = Mesh::from_obj(&no_uv).unwrap_err().to_string();
        assert!(
            e.contains("no_uv.obj") && e.contains("texture coordinates"),
            "{e}"
        );

        let corrupt = dir.path().join("corrupt.obj");
        std::fs::write(&corrupt, "v 0 0 zero\nf 1 2 9\n").unwrap();
        let e = Mesh::from_obj(&corrupt).unwrap_err().to_string();
        assert!(e.contains("corrupt.obj"), "{e}");

        let missing = dir.path().join("missing.obj");
        let e = Mesh::from_obj(&missing).unwrap_err().to_string();
        assert!(e.contains("missing.obj"), "{e}");
    }
}
