// Declarations and helpers every pipeline shares, prepended to each pipeline's WGSL at load
// time (crates/render/src/pipeline.rs): the uniforms (binding 0), the direction tables
// (bindings 4..7), the vertex transform, the tangent frame and the direction interpolation.
// A material's own bindings live in its own file (mrf.wgsl, lpca.wgsl). The CPU reference is
// src/btf/directions.rs (DirectionSet::interpolate); the tables are built in
// crates/render/src/lut.rs.

const PI: f32 = 3.14159265358979;
const HALF_PI: f32 = 1.57079632679490;
const DIRECTION_GRID: u32 = 128u;

struct Globals {
    view_proj: mat4x4<f32>,
    // xyz: camera position (w = 1, perspective) or direction towards the camera (w = 0,
    // orthographic).
    camera: vec4<f32>,
    // xyz: light position (w = 1) or direction towards the light (w = 0).
    light: vec4<f32>,
    // x: squared light distance from the origin (point light falloff, 1 at the origin),
    // y, z, w: the material's own (see mrf.wgsl).
    params: vec4<f32>,
    // x: measured views, y: measured lights.
    counts: vec4<u32>,
    // x, y: where view and light directions are clamped (radians; 90 degrees, or the set's
    // lowest direction if below the horizon, as the CPU's DirectionSet::interpolate), z: the
    // tangent-frame z at and below which the light is beyond the set's lowest light, w: the
    // z of the set's lowest light where lights past it fade (0: none do; see
    // DirectionSet::irradiance_beyond_lowest on the CPU).
    limits: vec4<f32>,
    // The material's relief heights (see mrf.wgsl).
    relief: vec4<f32>,
}

@group(0) @binding(0) var<uniform> globals: Globals;
// Per direction-grid cell: the Delaunay triangle (3 direction indices).
@group(0) @binding(4) var<storage, read> view_cells: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read> light_cells: array<vec4<u32>>;
// Projected coordinates of the measured directions.
@group(0) @binding(6) var<storage, read> view_points: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read> light_points: array<vec2<f32>>;
struct VertexInput {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    // The frames beyond the nearest face edges: (angle_u, weight_u, angle_v, weight_v), see
    // Vertex::seam in crates/render/src/mesh.rs.
    @location(4) seam: vec4<f32>,
    // This point's texture coordinates on those faces (u edge: xy, v edge: zw).
    @location(5) seam_uv: vec4<f32>,
}

struct VertexOutput {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    @location(4) seam: vec4<f32>,
    @location(5) seam_uv: vec4<f32>,
}

// Azimuthal-equidistant projection of a unit tangent-frame vector, theta clamped to max_theta
// radians (globals.limits.x for views, .y for lights).
fn project_dir(v: vec3<f32>, max_theta: f32) -> vec2<f32> {
    let theta = min(acos(clamp(v.z, -1.0, 1.0)), max_theta);
    let r = length(v.xy);
    if (r < 1e-7) {
        return vec2<f32>(0.0, 0.0);
    }
    return theta * v.xy / r;
}

struct Closest {
    point: vec2<f32>,
    bary: vec3<f32>,
}

// The point of triangle (a, b, c) closest to p and its barycentric coordinates (Ericson,
// Real-Time Collision Detection, 5.1.5): the same function as the CPU's.
fn closest_in_triangle(p: vec2<f32>, a: vec2<f32>, b: vec2<f32>, c: vec2<f32>) -> Closest {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) {
        return Closest(a, vec3<f32>(1.0, 0.0, 0.0));
    }
    let bp = p - b;
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) {
        return Closest(b, vec3<f32>(0.0, 1.0, 0.0));
    }
    let vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
        let v = d1 / (d1 - d3);
        return Closest(a + v * ab, vec3<f32>(1.0 - v, v, 0.0));
    }
    let cp = p - c;
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) {
        return Closest(c, vec3<f32>(0.0, 0.0, 1.0));
    }
    let vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
        let w = d2 / (d2 - d6);
        return Closest(a + w * ac, vec3<f32>(1.0 - w, 0.0, w));
    }
    let va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return Closest(b + w * (c - b), vec3<f32>(0.0, 1.0 - w, w));
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    return Closest(a + ab * v + ac * w, vec3<f32>(1.0 - v - w, v, w));
}

struct Interpolated {
    index: vec3<u32>,
    weight: vec3<f32>,
}

// The 3 measured directions around projected tangent-frame direction q and their barycentric weights
// (DirectionLut::lookup on the CPU): the nearest of the triangles of the 2 x 2 grid cells
// around the query, stopping at the first that contains it.
fn interpolate_dir(q: vec2<f32>, is_view: bool) -> Interpolated {
    let f = (q + vec2<f32>(HALF_PI)) / PI * f32(DIRECTION_GRID) - vec2<f32>(0.5);
    let last = i32(DIRECTION_GRID) - 1;
    let x0 = clamp(i32(floor(f.x)), 0, last);
    let y0 = clamp(i32(floor(f.y)), 0, last);
    let x1 = clamp(i32(floor(f.x + 1.0)), 0, last);
    let y1 = clamp(i32(floor(f.y + 1.0)), 0, last);
    var best = Interpolated(vec3<u32>(0u), vec3<f32>(1.0, 0.0, 0.0));
    var best_d2 = 1e30;
    for (var k = 0; k < 4; k++) {
        // Inside a triangle already (up to rounding): no other can be nearer.
        if (best_d2 < 1e-10) {
            break;
        }
        let x = select(x0, x1, (k & 1) == 1);
        let y = select(y0, y1, (k & 2) == 2);
        let cell = u32(y) * DIRECTION_GRID + u32(x);
        var tri: vec3<u32>;
        var a: vec2<f32>;
        var b: vec2<f32>;
        var c: vec2<f32>;
        if (is_view) {
            tri = view_cells[cell].xyz;
            a = view_points[tri.x];
            b = view_points[tri.y];
            c = view_points[tri.z];
        } else {
            tri = light_cells[cell].xyz;
            a = light_points[tri.x];
            b = light_points[tri.y];
            c = light_points[tri.z];
        }
        let r = closest_in_triangle(q, a, b, c);
        let d = r.point - q;
        let d2 = dot(d, d);
        if (d2 < best_d2 - 1e-12) {
            best_d2 = d2;
            let w = max(r.bary, vec3<f32>(0.0));
            best = Interpolated(tri, w / (w.x + w.y + w.z));
        }
    }
    return best;
}

// The tangent frame (x = tangent, y = bitangent = image up, z = normal) at a fragment.
fn tangent_frame(normal: vec3<f32>, tangent: vec4<f32>) -> mat3x3<f32> {
    let n = normalize(normal);
    let t = normalize(tangent.xyz - n * dot(n, tangent.xyz));
    let b = cross(n, t) * tangent.w;
    return mat3x3<f32>(t, b, n);
}

// The standard vertex transform (no displacement).
fn transform(in: VertexInput, position: vec3<f32>) -> VertexOutput {
    var out: VertexOutput;
    out.clip = globals.view_proj * vec4<f32>(position, 1.0);
    out.world = position;
    out.normal = in.normal;
    out.tangent = in.tangent;
    out.uv = in.uv;
    out.seam = in.seam;
    out.seam_uv = in.seam_uv;
    return out;
}

// Rotations below this (radians) are the same frame (mesh.rs TURNED).
const TURNED: f32 = 1e-3;

// The fragment as the face beyond an edge maps it: its tangent frame turned by `angle`
// radians about the normal (Vertex::frames on the CPU) and that face's texture coordinates.
fn turned(in: VertexOutput, angle: f32, uv: vec2<f32>) -> VertexOutput {
    let frame = tangent_frame(in.normal, in.tangent);
    var out = in;
    out.tangent = vec4<f32>(cos(angle) * frame[0] + sin(angle) * frame[1], in.tangent.w);
    out.uv = uv;
    return out;
}

// Normalised weights of the fragment's own mapping and the mappings of the faces beyond the
// nearest edge along u and along v (`seam` as VertexInput.seam); a face beyond an edge whose
// frame is not turned continues this one's texture and counts as the fragment's own.
fn seam_weights(seam: vec4<f32>) -> vec3<f32> {
    let wu = max(seam.y, 0.0);
    let wv = max(seam.w, 0.0);
    let same_u = abs(seam.x) < TURNED;
    let same_v = abs(seam.z) < TURNED;
    let own = 1.0 + select(0.0, wu, same_u) + select(0.0, wv, same_v);
    return vec3<f32>(own, select(wu, 0.0, same_u), select(wv, 0.0, same_v)) / (1.0 + wu + wv);
}

// View and light of a fragment in its tangent frame (unit vectors), and the point light's
// inverse-square falloff (1 for a directional light) times the fade past the set's lowest
// light (limits.w): what every BTF pipeline starts from.
struct TangentDirections {
    v: vec3<f32>,
    l: vec3<f32>,
    falloff: f32,
}

fn tangent_directions(in: VertexOutput) -> TangentDirections {
    let frame = tangent_frame(in.normal, in.tangent);
    let to_world = transpose(frame);
    var v_world = globals.camera.xyz;
    if (globals.camera.w > 0.5) {
        v_world = globals.camera.xyz - in.world;
    }
    v_world = normalize(v_world);
    var l_world = globals.light.xyz;
    var falloff = 1.0;
    if (globals.light.w > 0.5) {
        l_world = globals.light.xyz - in.world;
        falloff = globals.params.x / max(dot(l_world, l_world), 1e-8);
    }
    let l = to_world * normalize(l_world);
    // Past the set's lowest light the irradiance fades with the light's cosine.
    if (globals.limits.w > 0.0) {
        falloff *= clamp(l.z / globals.limits.w, 0.0, 1.0);
    }
    return TangentDirections(to_world * v_world, l, falloff);
}

// True for colour targets that clip to [0, 1] (an 8-bit window surface): the fragment's colour
// is then brought into range keeping its chromaticity, as the CPU's 8-bit encoding does
// (`color::fit_to_gamut`); float targets keep over-range values. Clipping each channel on its
// own turned over-range highlights into false-colour specks.
override FIT_TO_DISPLAY: bool = false;

fn displayed(colour: vec4<f32>) -> vec4<f32> {
    if (!FIT_TO_DISPLAY) {
        return colour;
    }
    let rgb = max(colour.rgb, vec3<f32>(0.0));
    let peak = max(max(rgb.r, rgb.g), rgb.b);
    return vec4<f32>(rgb / max(peak, 1.0), colour.a);
}
