// The MRF material's bindings and shading, shared by its pipelines (bump, displacement,
// plain), after common.wgsl. The CPU reference is src/synthesis.rs (image_from_cache,
// bump_relight); the buffers are built in crates/render/src/mrf.rs.
//
// Globals.params here: y = the tile's side in texels when the model has a range map (0
// without), z = displacement scale (world units per height texel). Globals.relief: x, y = the
// highest and lowest relief heights (tile texels from the mean), z = 1 when the range map
// casts shadows (0 when it does not). VIEW_PARALLAX (set before this file): the relief's view
// parallax is marched (bump mapping).
// Lights at or beyond the set's lowest light (globals.limits.z) leave a fragment black; past
// a set's lowest light they fade (tangent_directions).

const SHADING_GRID: u32 = 64u;
// Most one-texel steps of a shadow ray (the CPU's MAX_SHADOW_STEPS).
const MAX_SHADOW_STEPS: u32 = 256u;
// Height a sample must rise above a shadow ray to block it (the CPU's SHADOW_TOLERANCE).
const SHADOW_TOLERANCE: f32 = 0.05;
// A view ray's march (geometry::parallax on the CPU): step, bisection steps, longest stretch,
// in height-texture texels.
const VIEW_STEP: f32 = 0.5;
const REFINE_STEPS: u32 = 6u;
const MAX_VIEW_SPAN: f32 = 256.0;
const NO_LAYER: u32 = 0xffffffffu;

// The synthesized subspace images (tileable), one layer per synthesized cluster.
@group(0) @binding(1) var subspaces: texture_2d_array<f32>;
// Range map: xyz = unit normal in the tangent frame, w = height in texels (mean 0).
@group(0) @binding(2) var relief: texture_2d<f32>;
@group(0) @binding(3) var tex_sampler: sampler;
// (view * lights + light) -> x: the texture layer of its cluster, NO_LAYER when not
// synthesized; y: the layer of its finish in `finishes`, NO_LAYER when it has none or it was
// not planned.
@group(0) @binding(8) var<storage, read> pair_layer: array<vec2<u32>>;
// Mean of max(0, n . l) over the texture, on a SHADING_GRID^2 node grid of light directions.
@group(0) @binding(9) var<storage, read> mean_shade: array<f32>;
// Per measured light, the bump strength k of the shading factor 1 + k (s - 1).
@group(0) @binding(10) var<storage, read> light_strength: array<f32>;
// Per (view * lights + light): x, the measured pair's gain (MaterialModel::pair_gain); yzw,
// its mean colour (x times its cluster's tile mean, plus its finish's mean when planned).
@group(0) @binding(11) var<storage, read> pair_shade: array<vec4<f32>>;
// The range map's heights (tile texels above their mean) in single precision, read unfiltered
// for the view parallax and the cast shadows (1 x 1 without a range map).
@group(0) @binding(12) var ray_heights: texture_2d<f32>;
// What the measured pairs with parts of their own (light tables, a light's own exemplar
// detail or period) add to their relit subspace image (MaterialModel::pair_finish), one layer
// per planned pair.
@group(0) @binding(13) var finishes: texture_2d_array<f32>;

// Mean of max(0, n . l) over the texture for the projected tangent-frame light direction q
// (bilinear in the table).
fn mean_shading(q: vec2<f32>) -> f32 {
    let last = f32(SHADING_GRID - 1u);
    let f = clamp((q + vec2<f32>(HALF_PI)) / PI * last, vec2<f32>(0.0), vec2<f32>(last));
    let x0 = min(u32(floor(f.x)), SHADING_GRID - 2u);
    let y0 = min(u32(floor(f.y)), SHADING_GRID - 2u);
    let t = f - vec2<f32>(f32(x0), f32(y0));
    let i = y0 * SHADING_GRID + x0;
    let top = mix(mean_shade[i], mean_shade[i + 1u], t.x);
    let bottom = mix(mean_shade[i + SHADING_GRID], mean_shade[i + SHADING_GRID + 1u], t.x);
    return mix(top, bottom, t.y);
}

// The ray heights at texel coordinates p (texel centres at integers), bilinear between
// the four texels around it, wrapped (the CPU's ShadowMarch reads its heights so).
fn ray_height(p: vec2<f32>) -> f32 {
    let n = vec2<i32>(textureDimensions(ray_heights));
    let f = floor(p);
    let t = p - f;
    let i = vec2<i32>(f);
    let h = array<f32, 4>(
        textureLoad(ray_heights, ((i % n) + n) % n, 0).r,
        textureLoad(ray_heights, ((i + vec2<i32>(1, 0)) % n + n) % n, 0).r,
        textureLoad(ray_heights, ((i + vec2<i32>(0, 1)) % n + n) % n, 0).r,
        textureLoad(ray_heights, ((i + vec2<i32>(1, 1)) % n + n) % n, 0).r,
    );
    return mix(mix(h[0], h[1], t.x), mix(h[2], h[3], t.x), t.y);
}

// 1 where the tangent-frame light l reaches the relief at uv, 0 where the relief casts a
// shadow on it (ShadowMarch on the CPU): one-texel steps towards the light over the heights,
// until the ray rises above the highest one.
fn cast_light(uv: vec2<f32>, l: vec3<f32>) -> f32 {
    let top = globals.relief.x;
    let horizontal = length(l.xy);
    if (globals.relief.z < 0.5 || horizontal < 1e-6) {
        return 1.0;
    }
    let size = f32(textureDimensions(ray_heights).x);
    // uv's v runs down the rows, the light's y up; heights are in tile texels.
    let dir = vec2<f32>(l.x, -l.y) / horizontal;
    let rise = l.z / horizontal * globals.params.y / size;
    let p = uv * size - vec2<f32>(0.5);
    let z = ray_height(p) + SHADOW_TOLERANCE;
    let steps = min(u32(size), MAX_SHADOW_STEPS);
    for (var t = 1u; t <= steps; t++) {
        let ray = z + f32(t) * rise;
        if (ray >= top) {
            return 1.0;
        }
        if (ray_height(p + f32(t) * dir) > ray) {
            return 0.0;
        }
    }
    return 1.0;
}

// Where the tangent-frame view v sees the relief at uv (view_warp on the CPU): the view ray
// through uv at the mean height is marched down from the highest height in VIEW_STEP texel
// steps until the heights reach it, the hit refined by bisection; uv itself for a frontal
// view, without a range map, or where the mapping shows parallax by its geometry.
fn seen_uv(uv: vec2<f32>, v: vec3<f32>) -> vec2<f32> {
    let horizontal = length(v.xy);
    if (!VIEW_PARALLAX || globals.params.y < 0.5 || v.z <= 0.0 || horizontal < 1e-6) {
        return uv;
    }
    let size = f32(textureDimensions(ray_heights).x);
    // Towards the camera: uv's v runs down the rows, the view's y up; heights in tile texels.
    let dir = vec2<f32>(v.x, -v.y) / horizontal;
    let rise = v.z / horizontal * globals.params.y / size;
    let p = uv * size - vec2<f32>(0.5);
    let first = min(globals.relief.x / rise, MAX_VIEW_SPAN);
    let last = max(globals.relief.y / rise, -MAX_VIEW_SPAN);
    var above = first;
    var s = first;
    var hit = last;
    loop {
        if (ray_height(p + s * dir) >= s * rise) {
            hit = s;
            break;
        }
        if (s <= last) {
            break;
        }
        above = s;
        s = max(s - VIEW_STEP, last);
    }
    var lo = hit;
    var hi = above;
    for (var i = 0u; i < REFINE_STEPS; i++) {
        let mid = 0.5 * (lo + hi);
        if (ray_height(p + mid * dir) >= mid * rise) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return (p + lo * dir + vec2<f32>(0.5)) / size;
}

// The MRF BTF at a fragment (image_from_cache on the CPU): the 3 x 3 nearest measured (view,
// light) pairs blend their clusters' subspace images (each at its pair's gain), then the
// range map's normal relights the blend for the light by the factor 1 + k (s - 1) (floored
// at SHADING_FLOOR, which mrf.rs defines from the CPU's), s = max(0, n . l) (times
// cast_light) / mean shading, so that the subspace images' own average shading is not
// applied twice, k the measured strength (bump_relight, bump_strength); last, the pairs'
// finishes are added with the same weights (exact at a measured pair, blended between).
// Clusters that were not synthesized (outside the planned set) are skipped and the weights
// renormalised.
// `ddx`, `ddy`: the screen derivatives of in.uv (taken by the caller, in uniform control flow).
fn shade_mrf(in: VertexOutput, ddx: vec2<f32>, ddy: vec2<f32>) -> Shaded {
    let dirs = tangent_directions(in);
    let v = dirs.v;
    let l = dirs.l;
    let falloff = dirs.falloff;
    let uv = seen_uv(in.uv, v);
    let relief_here = textureSampleGrad(relief, tex_sampler, uv, ddx, ddy);
    if (l.z <= globals.limits.z) {
        return Shaded(vec4<f32>(0.0, 0.0, 0.0, 1.0), vec3<f32>(0.0));
    }
    let ql = project_dir(l, globals.limits.y);
    let iv = interpolate_dir(project_dir(v, globals.limits.x), true);
    let il = interpolate_dir(ql, false);
    var sum = vec3<f32>(0.0);
    var finish = vec3<f32>(0.0);
    var total = 0.0;
    var mean_colour = vec3<f32>(0.0);
    for (var a = 0; a < 3; a++) {
        for (var b = 0; b < 3; b++) {
            let w = iv.weight[a] * il.weight[b];
            if (w > 0.0) {
                let pair = iv.index[a] * globals.counts.y + il.index[b];
                let layer = pair_layer[pair];
                if (layer.x != NO_LAYER) {
                    let texel = textureSampleGrad(subspaces, tex_sampler, uv, layer.x, ddx, ddy).rgb;
                    sum += w * pair_shade[pair].x * texel;
                    total += w;
                    if (layer.y != NO_LAYER) {
                        finish += w * textureSampleGrad(finishes, tex_sampler, uv, layer.y, ddx, ddy).rgb;
                    }
                    mean_colour += w * pair_shade[pair].yzw;
                }
            }
        }
    }
    var colour = sum / max(total, 1e-12);
    if (globals.params.y > 0.5) {
        let mean = mean_shading(ql);
        if (mean >= 1e-3) {
            // The measured lights' strengths, blended like the images (bump_strength).
            var k = 0.0;
            for (var b = 0; b < 3; b++) {
                k += il.weight[b] * light_strength[il.index[b]];
            }
            let s = max(dot(relief_here.xyz, l), 0.0) * cast_light(uv, l) / mean;
            colour *= max(1.0 + k * (s - 1.0), SHADING_FLOOR);
        }
    }
    colour += finish / max(total, 1e-12);
    return Shaded(vec4<f32>(colour * falloff, 1.0), mean_colour / max(total, 1e-12) * falloff);
}

// A fragment's colour, and its mapping's mean colour: the pairs' mean colours (pair_shade)
// blended with the same weights, unrelit.
struct Shaded {
    colour: vec4<f32>,
    mean: vec3<f32>,
}

// Across a turned face edge the mappings are cut, not cross-faded: each candidate mapping's
// ranking is its seam weight times SEAM_CUT_BIAS plus its feature in [0, 1] (the relief's
// height; without a range map none, and the cut is the face edge: ranked by luminance, the
// brighter texture won everywhere, a band of bright specks on photographs of gravel and
// grass and crossing mortar lines on brick), and the highest wins (a soft
// maximum over SEAM_CUT_SOFTNESS), so the cut runs where a stone of one mapping meets the
// mortar of the other instead of two layouts showing through each other. Where one weight
// leads by more than 1 / SEAM_CUT_BIAS its mapping wins whatever the features: at 4 the cut
// stays within 0.4 of the band's depth on either side of the edge (at 2, tried first, within
// 2/3, and a weave's threads broke over most of the band; stones look alike at either).
const SEAM_CUT_BIAS: f32 = 4.0;
const SEAM_CUT_SOFTNESS: f32 = 0.03;

// The shares of up to 3 mappings (seam_weights `w`, features `f` in [0, 1]): a soft maximum
// of f + SEAM_CUT_BIAS * w over the mappings with a weight.
fn seam_cut(w: vec3<f32>, f: vec3<f32>) -> vec3<f32> {
    let rank = select(vec3<f32>(-1e4), f + SEAM_CUT_BIAS * w, w > vec3<f32>(0.0));
    let top = max(max(rank.x, rank.y), rank.z);
    let e = exp((rank - vec3<f32>(top)) / SEAM_CUT_SOFTNESS);
    return e / (e.x + e.y + e.z);
}

// The relief's height at uv as a feature in [0, 1] (0 at the lowest, 1 at the highest).
fn height_feature(height: f32) -> f32 {
    return clamp((height - globals.relief.y) / max(globals.relief.x - globals.relief.y, 1e-6), 0.0, 1.0);
}

// shade_mrf across turned face edges (seam_weights, seam_cut): each mapping in reach shades
// the fragment in its own frame, and the cut picks one; the winner's colour is scaled by the
// weighted mean of the mappings' mean colours over its own, so that the light's brightness
// in the turned frames (which changes with the light's azimuth on real captures) still
// turns gradually over the band instead of stepping at the cut.
fn shade_mrf_blended(in: VertexOutput) -> vec4<f32> {
    let w = seam_weights(in.seam);
    let ddx = dpdx(vec4<f32>(in.uv, in.seam_uv.xy));
    let ddy = dpdy(vec4<f32>(in.uv, in.seam_uv.xy));
    let ddx_v = dpdx(in.seam_uv.zw);
    let ddy_v = dpdy(in.seam_uv.zw);
    let cut = w.y > 0.0 || w.z > 0.0;
    let own = shade_mrf(in, ddx.xy, ddy.xy);
    if (!cut) {
        return own.colour;
    }
    var colours = array<vec3<f32>, 3>(own.colour.rgb, vec3<f32>(0.0), vec3<f32>(0.0));
    var means = array<vec3<f32>, 3>(own.mean, vec3<f32>(0.0), vec3<f32>(0.0));
    if (w.y > 0.0) {
        let s = shade_mrf(turned(in, in.seam.x, in.seam_uv.xy), ddx.zw, ddy.zw);
        colours[1] = s.colour.rgb;
        means[1] = s.mean;
    }
    if (w.z > 0.0) {
        let s = shade_mrf(turned(in, in.seam.z, in.seam_uv.zw), ddx_v, ddy_v);
        colours[2] = s.colour.rgb;
        means[2] = s.mean;
    }
    // Without a range map the cut is the edge itself.
    var f = vec3<f32>(0.0);
    if (globals.params.y > 0.5) {
        f = vec3<f32>(
            height_feature(textureSampleGrad(relief, tex_sampler, in.uv, ddx.xy, ddy.xy).w),
            height_feature(textureSampleGrad(relief, tex_sampler, in.seam_uv.xy, ddx.zw, ddy.zw).w),
            height_feature(textureSampleGrad(relief, tex_sampler, in.seam_uv.zw, ddx_v, ddy_v).w),
        );
    }
    let shares = seam_cut(w, f);
    let mean = w.x * means[0] + w.y * means[1] + w.z * means[2];
    var colour = vec3<f32>(0.0);
    for (var i = 0; i < 3; i++) {
        let ratio = select(mean / means[i], vec3<f32>(1.0), means[i] <= vec3<f32>(1e-6));
        colour += shares[i] * colours[i] * clamp(ratio, vec3<f32>(0.25), vec3<f32>(4.0));
    }
    return vec4<f32>(colour, 1.0);
}
