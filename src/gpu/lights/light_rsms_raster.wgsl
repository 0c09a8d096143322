// The lights' RSMs (`twin::light_rsms`): every view of every light (a spot's cone, a point
// light's six cube faces) rasterised into its tile of one visibility atlas, as
// `visibility.wgsl` does for one viewpoint. Draw k (instance k) is view k, in its tile's
// viewport and scissor.

@group(0) @binding(0) var<storage, read> rsm_views: array<RsmView>;

struct VertexOutput {
    @builtin(position) clip: vec4<f32>,
    @location(0) barycentrics: vec2<f32>,
    @location(1) @interpolate(flat) triangle: u32,
}

@vertex
fn vs_main(@builtin(vertex_index) vertex_index: u32, @builtin(instance_index) view: u32) -> VertexOutput {
    let corner = vertex_index % 3u;
    let position = vertices[indices[vertex_index]].position;
    var b = vec2<f32>(0.0, 0.0);
    if corner == 1u {
        b = vec2<f32>(1.0, 0.0);
    } else if corner == 2u {
        b = vec2<f32>(0.0, 1.0);
    }
    return VertexOutput(rsm_views[view].world_to_clip * vec4<f32>(position, 1.0), b, vertex_index / 3u);
}

@fragment
fn fs_main(in: VertexOutput) -> @location(0) vec4<u32> {
    return vec4<u32>(in.triangle + 1u, bitcast<u32>(in.barycentrics.x), bitcast<u32>(in.barycentrics.y), 0u);
}
