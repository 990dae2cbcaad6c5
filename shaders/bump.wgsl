// MRF + bump mapping: the mesh as it is; per fragment the BTF of the 3 x 3 nearest measured
// pairs, relit by the range map's normals (shade_mrf in mrf.wgsl).

@vertex
fn vs_main(in: VertexInput) -> VertexOutput {
    return transform(in, in.position);
}

@fragment
fn fs_main(in: VertexOutput) -> @location(0) vec4<f32> {
    return displayed(shade_mrf_blended(in));
}
