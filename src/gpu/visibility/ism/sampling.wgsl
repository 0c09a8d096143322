// The VALs the imperfect shadow maps stand for (paper 004 §3: VPLs drawn from the RSM by
// importance): CLUSTER_COUNT VALs drawn by flux luminance, stratified (`flux_draw.wgsl`,
// prepended), each the seed of one group; the clusters' assign and update then give every VAL
// the nearest seed and every group its mean position, normal and radius.
// Rust twin: `twin::flux_seeds`.

@group(0) @binding(3) var<storage, read_write> clusters: array<Cluster>;

// One invocation per group: the VAL drawn for it. Without lit VALs every group is empty
// (count 0: fully visible, no map).
@compute @workgroup_size(WORKGROUP_X)
fn flux_sample(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= CLUSTER_COUNT {
        return;
    }
    let pick = flux_pick(k, CLUSTER_COUNT);
    if pick == 0xffffffffu {
        clusters[k] = Cluster(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 0.0, 1.0), 0.0);
        return;
    }
    let v = vals[pick];
    clusters[k] = Cluster(v.position, 0.0, v.normal, 0.0);
}
