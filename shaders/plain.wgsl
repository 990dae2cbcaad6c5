// Plain texturing, the cost baseline: one sample of the first synthesized subspace image, no view or light
// dependence, no relighting.

@vertex
fn vs_main(in: VertexInput) -> VertexOutput {
    return transform(in, in.position);
}

@fragment
fn fs_main(in: VertexOutput) -> @location(0) vec4<f32> {
    return displayed(vec4<f32>(textureSample(subspaces, tex_sampler, in.uv, 0u).rgb, 1.0));
}
