// Visibility buffer: rasterise every triangle (vertex pulling, no culling) and store, per
// texel, which triangle is nearest and where on it (`visibility_stages.wgsl`, prepended). Used
// from the camera and from the spot light (the RSM and its shadow map).

@group(0) @binding(0) var<uniform> world_to_clip: mat4x4<f32>;

@vertex
fn vs_main(@builtin(vertex_index) vertex_index: u32) -> VertexOutput {
    return visibility_vertex(vertex_index, world_to_clip);
}
