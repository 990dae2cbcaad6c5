// LPCA decoding (Müller, Meseth and Klein 2003): per fragment, the texel's 3 x 3 nearest
// measured (view, light) pairs are rebuilt from its cluster's mean and eigen-ABRDFs and its
// own weights, then blended with the barycentric weights of common.wgsl's direction tables.
// The CPU reference is LpcaModel::reconstruct / reconstruct_direction (src/lpca/mod.rs); the
// buffers are built in crates/render/src/lpca.rs. After common.wgsl (uniforms, direction
// tables); its own bindings are 10..13.

// x: texture width, y: height (texels), z: components C, w: 1 for PCA RF (one factorization
// per view), 0 for LPCA (one factorization, K clusters).
@group(0) @binding(10) var<uniform> lpca: vec4<u32>;
// The cluster of every texel, row-major (LPCA; unused for PCA RF).
@group(0) @binding(11) var<storage, read> texel_cluster: array<u32>;
// C weights per texel (LPCA) or per (view, texel) (PCA RF).
@group(0) @binding(12) var<storage, read> texel_weights: array<f32>;
// Per (group, pair): the mean then the C eigen-ABRDF values, rgb. LPCA: group = cluster,
// pair = view * lights + light; PCA RF: group = view, pair = light.
@group(0) @binding(13) var<storage, read> eigen: array<vec4<f32>>;

// Where row `row` (0: the mean, 1..=C: eigen-ABRDF) of pair `pair` of `group` sits in
// `eigen`: the formula of eigen_slot in crates/render/src/lpca.rs.
fn eigen_slot(group: u32, pair: u32, row: u32, pairs: u32, c: u32) -> u32 {
    return (group * pairs + pair) * (c + 1u) + row;
}

// Image (view v, light l) at a texel, negative values clamped to 0 like the CPU's.
fn lpca_value(texel: u32, v: u32, l: u32) -> vec3<f32> {
    let c = lpca.z;
    let n = lpca.x * lpca.y;
    let nl = globals.counts.y;
    var group = texel_cluster[texel];
    var pair = v * nl + l;
    var pairs = globals.counts.x * nl;
    var wbase = texel * c;
    if (lpca.w == 1u) {
        group = v;
        pair = l;
        pairs = nl;
        wbase = (v * n + texel) * c;
    }
    var acc = eigen[eigen_slot(group, pair, 0u, pairs, c)].xyz;
    for (var t = 0u; t < c; t++) {
        acc += texel_weights[wbase + t] * eigen[eigen_slot(group, pair, t + 1u, pairs, c)].xyz;
    }
    return max(acc, vec3<f32>(0.0));
}

@vertex
fn vs_main(in: VertexInput) -> VertexOutput {
    return transform(in, in.position);
}

// The LPCA BTF at a fragment: the measured tile's nearest texel, its 3 x 3 nearest measured
// (view, light) pairs blended.
fn shade_lpca(in: VertexOutput) -> vec4<f32> {
    let dirs = tangent_directions(in);
    let v = dirs.v;
    let l = dirs.l;
    let falloff = dirs.falloff;
    if (l.z <= globals.limits.z) {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    // Nearest texel, the measured tile repeating over the mesh's texture coordinates.
    let uv = fract(in.uv);
    let x = min(u32(uv.x * f32(lpca.x)), lpca.x - 1u);
    let y = min(u32(uv.y * f32(lpca.y)), lpca.y - 1u);
    let texel = y * lpca.x + x;
    let iv = interpolate_dir(project_dir(v, globals.limits.x), true);
    let il = interpolate_dir(project_dir(l, globals.limits.y), false);
    var sum = vec3<f32>(0.0);
    for (var a = 0; a < 3; a++) {
        for (var b = 0; b < 3; b++) {
            let w = iv.weight[a] * il.weight[b];
            if (w > 0.0) {
                sum += w * lpca_value(texel, iv.index[a], il.index[b]);
            }
        }
    }
    return vec4<f32>(sum * falloff, 1.0);
}

// shade_lpca blended across turned face edges (seam_weights).
@fragment
fn fs_main(in: VertexOutput) -> @location(0) vec4<f32> {
    let w = seam_weights(in.seam);
    var colour = w.x * shade_lpca(in);
    if (w.y > 0.0) {
        colour += w.y * shade_lpca(turned(in, in.seam.x, in.seam_uv.xy));
    }
    if (w.z > 0.0) {
        colour += w.z * shade_lpca(turned(in, in.seam.z, in.seam_uv.zw));
    }
    return displayed(colour);
}
