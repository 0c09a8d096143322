// The visibility buffer's stages, shared by every visibility raster (`visibility.wgsl`, one
// viewpoint; `lights/light_rsms_raster.wgsl`, every light view in one atlas): vertex pulling
// (no culling) and, per texel, which triangle is nearest and where on it.

struct VertexOutput {
    @builtin(position) clip: vec4<f32>,
    @location(0) barycentrics: vec2<f32>,
    @location(1) @interpolate(flat) triangle: u32,
}

// Vertex `vertex_index` of the index buffer projected by `world_to_clip`, with its corner's
// barycentrics (corners 1 and 2) and its triangle.
fn visibility_vertex(vertex_index: u32, world_to_clip: mat4x4<f32>) -> VertexOutput {
    let corner = vertex_index % 3u;
    let position = vertices[indices[vertex_index]].position;
    var b = vec2<f32>(0.0, 0.0);
    if corner == 1u {
        b = vec2<f32>(1.0, 0.0);
    } else if corner == 2u {
        b = vec2<f32>(0.0, 1.0);
    }
    return VertexOutput(world_to_clip * vec4<f32>(position, 1.0), b, vertex_index / 3u);
}

@fragment
fn fs_main(in: VertexOutput) -> @location(0) vec4<u32> {
    return vec4<u32>(in.triangle + 1u, bitcast<u32>(in.barycentrics.x), bitcast<u32>(in.barycentrics.y), 0u);
}
