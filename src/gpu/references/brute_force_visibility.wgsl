// The camera's pixels seen from the groups of a group visibility mode (`brute_force_ism`): the
// clusters' filtered lookup (`../visibility/clusters/cluster_visibility.wgsl`, prepended with
// the maps it reads) at every (pixel, group), the pixel's surface from the camera's visibility
// buffer: the lookup the sparse points get, at every pixel instead. Uncovered pixels get 1.
// Writes `group_visibility[pixel * CLUSTER_COUNT + k]`. Rust twin:
// `clusters::twin::cluster_visibility` at the pixels' surfaces.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(3) var<storage, read_write> group_visibility: array<f32>;

// One invocation per (pixel, group).
@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let k = id.y;
    if i >= frame.width * frame.height || k >= CLUSTER_COUNT {
        return;
    }
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(i32(i % frame.width), i32(i / frame.width)), 0));
    var v = 1.0;
    if hit.covered {
        let s = surface_at(hit.triangle, hit.barycentrics);
        let c = clusters[k];
        v = cluster_visibility(k, c, s.position - c.position, s.normal);
    }
    group_visibility[i * CLUSTER_COUNT + k] = v;
}
