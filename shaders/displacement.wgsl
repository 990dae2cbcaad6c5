// MRF + displacement mapping: a finely tessellated mesh whose vertices move along the normal
// by the range map's height (world units = texels x params.z), shaded like bump mapping.

@vertex
fn vs_main(in: VertexInput) -> VertexOutput {
    let height = textureSampleLevel(relief, tex_sampler, in.uv, 0.0).w;
    let moved = in.position + normalize(in.normal) * height * globals.params.z;
    return transform(in, moved);
}

@fragment
fn fs_main(in: VertexOutput) -> @location(0) vec4<f32> {
    return shade_mrf_blended(in);
}
