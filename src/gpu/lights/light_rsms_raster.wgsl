// The lights' RSMs (`twin::light_rsms`): every view of every light (a spot's cone, a point
// light's six cube faces) rasterised into its tile of one visibility atlas, with the stages of
// `raster/visibility_stages.wgsl` (prepended), as `visibility.wgsl` does for one viewpoint.
// Draw k (instance k) is view k, in its tile's viewport and scissor.

@group(0) @binding(0) var<storage, read> rsm_views: array<RsmView>;

@vertex
fn vs_main(@builtin(vertex_index) vertex_index: u32, @builtin(instance_index) view: u32) -> VertexOutput {
    return visibility_vertex(vertex_index, rsm_views[view].world_to_clip);
}
