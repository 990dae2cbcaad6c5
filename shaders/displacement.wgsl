// MRF + displacement mapping: a finely tessellated mesh whose vertices move along the normal
// by the range map's height (world units = texels x params.z), shaded like bump mapping.

@vertex
fn vs_main(in: VertexInput) -> VertexOutput {
    // Cut across turned face edges like the shading (seam_cut), so both sides of an edge move
    // alike and the surface follows the texture the fragments show.
    let h = vec3<f32>(
        textureSampleLevel(relief, tex_sampler, in.uv, 0.0).w,
        textureSampleLevel(relief, tex_sampler, in.seam_uv.xy, 0.0).w,
        textureSampleLevel(relief, tex_sampler, in.seam_uv.zw, 0.0).w,
    );
    let f = vec3<f32>(height_feature(h.x), height_feature(h.y), height_feature(h.z));
    let height = dot(seam_cut(seam_weights(in.seam), f), h);
    let moved = in.position + normalize(in.normal) * height * globals.params.z;
    return transform(in, moved);
}

@fragment
fn fs_main(in: VertexOutput) -> @location(0) vec4<f32> {
    return displayed(shade_mrf_blended(in));
}
