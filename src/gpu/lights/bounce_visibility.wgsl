// The second bounce's points seen from the first bounce's groups (`bounce2_visibility`): the
// clusters' filtered lookup (`../visibility/clusters/cluster_visibility.wgsl`, prepended with
// the maps it reads: rasterised, or the imperfect shadow maps) at every (bounce point, group),
// the point placed on this frame's surface. The lookup is the one the sparse points get; only
// the receivers differ. Writes `group_visibility[point * CLUSTER_COUNT + k]`. Rust twin:
// `clusters::twin::cluster_visibility` at `twin::bounce`'s surfaces.

// Binding 0, `bounce_points`: `bounce_point.wgsl` (prepended).
@group(0) @binding(3) var<storage, read_write> group_visibility: array<f32>;

// One invocation per (bounce point, group).
@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let k = id.y;
    if i >= arrayLength(&bounce_points) || k >= CLUSTER_COUNT {
        return;
    }
    let s = bounce_surface(i);
    let c = clusters[k];
    group_visibility[i * CLUSTER_COUNT + k] = cluster_visibility(k, c, s.position - c.position, s.normal);
}
