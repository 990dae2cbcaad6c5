// MRF + displacement mapping: a finely tessellated mesh whose vertices move along the normal
// by the range map's height (world units = texels x params.z), shaded like bump mapping.

@vertex
fn vs_main(in: VertexInput) -> VertexOutput {
    // Blended across turned face edges like the shading, so both sides of an edge move alike.
    let w = seam_weights(in.seam);
    let height = w.x * textureSampleLevel(relief, tex_sampler, in.uv, 0.0).w
        + w.y * textureSampleLevel(relief, tex_sampler, in.seam_uv.xy, 0.0).w
        + w.z * textureSampleLevel(relief, tex_sampler, in.seam_uv.zw, 0.0).w;
    let moved = in.position + normalize(in.normal) * height * globals.params.z;
    return transform(in, moved);
}

@fragment
fn fs_main(in: VertexOutput) -> @location(0) vec4<f32> {
    return displayed(shade_mrf_blended(in));
}
