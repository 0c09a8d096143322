// The clusters' visibility pass: `cluster_visibility.wgsl`'s lookup per (sparse point, cluster).

@group(0) @binding(0) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(3) var<storage, read_write> group_visibility: array<f32>;

// One invocation per (sparse point, cluster).
@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let k = id.y;
    if i >= frame.sparse_count || k >= CLUSTER_COUNT {
        return;
    }
    let p = sparse_points[i];
    let c = clusters[k];
    group_visibility[i * CLUSTER_COUNT + k] = cluster_visibility(k, c, p.position - c.position, p.normal);
}
