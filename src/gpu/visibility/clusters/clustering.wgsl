// k-means clustering of the frame's VALs (paper 000 §5.1): seed empty clusters, assign every
// VAL to the nearest centre (position distance in units of the scene's diagonal plus
// NORMAL_WEIGHT x the normal angle), sum each cluster's lit VALs per block of PARTIAL_BLOCK
// VALs, reduce the blocks into the new centres. The centres stay in `clusters` from frame to
// frame: each frame starts from the last one's (temporal coherence, §5.2). Rust twin: `twin.rs`.

@group(0) @binding(0) var<storage, read> vals: array<Val>;
@group(0) @binding(1) var<storage, read> val_count: u32;
@group(0) @binding(2) var<storage, read_write> clusters: array<Cluster>;
@group(0) @binding(3) var<storage, read_write> group_of_val: array<u32>;
@group(0) @binding(4) var<storage, read_write> cluster_partials: array<ClusterSums>;

struct ClusterSums {
    offset: vec3<f32>,
    count: f32,
    normal: vec3<f32>,
    offset_sq: f32,
}

fn frame_val_count() -> u32 {
    return min(val_count, arrayLength(&vals));
}

fn cluster_distance(position: vec3<f32>, normal: vec3<f32>, c: Cluster) -> f32 {
    let angle = acos(clamp(dot(normal, c.normal), -1.0, 1.0));
    return length(position - c.position) * POSITION_SCALE + NORMAL_WEIGHT * angle;
}

fn val_is_lit(v: Val) -> bool {
    return luminance(v.flux) > 0.0;
}

fn kmeans_centre(old: Cluster, s: ClusterSums) -> Cluster {
    if s.count == 0.0 {
        return Cluster(old.position, 0.0, old.normal, 0.0);
    }
    let mean = s.offset / s.count;
    let variance = max(s.offset_sq / s.count - dot(mean, mean), 0.0);
    var normal = old.normal;
    if dot(s.normal, s.normal) > 1e-12 {
        normal = normalize(s.normal);
    }
    return Cluster(old.position + mean, s.count, normal, sqrt(2.0 * variance));
}

// One invocation per cluster: an empty one takes VAL k n / m's place (000 §5.2: no cluster
// stays lost).
@compute @workgroup_size(WORKGROUP_X)
fn kmeans_seed(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    let n = frame_val_count();
    if k >= CLUSTER_COUNT || n == 0u {
        return;
    }
    if clusters[k].count == 0.0 {
        let v = vals[k * n / CLUSTER_COUNT];
        clusters[k] = Cluster(v.position, 0.0, v.normal, 0.0);
    }
}

// One invocation per VAL: the nearest centre (the first on ties).
@compute @workgroup_size(WORKGROUP_X)
fn kmeans_assign(@builtin(global_invocation_id) id: vec3<u32>) {
    let j = id.x;
    if j >= frame_val_count() {
        return;
    }
    let v = vals[j];
    var best = 3.0e38;
    var best_k = 0u;
    for (var k = 0u; k < CLUSTER_COUNT; k++) {
        let d = cluster_distance(v.position, v.normal, clusters[k]);
        if d < best {
            best = d;
            best_k = k;
        }
    }
    group_of_val[j] = best_k;
}

// One invocation per (cluster, block of VALs): the cluster's sums over the block's lit VALs,
// offsets from the centre before the update.
@compute @workgroup_size(WORKGROUP_X)
fn kmeans_partial(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    let b = id.y;
    let n = frame_val_count();
    if k >= CLUSTER_COUNT || b * PARTIAL_BLOCK >= n {
        return;
    }
    let centre = clusters[k].position;
    var s = ClusterSums(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    let end = min(n, (b + 1u) * PARTIAL_BLOCK);
    for (var j = b * PARTIAL_BLOCK; j < end; j++) {
        let v = vals[j];
        if group_of_val[j] == k && val_is_lit(v) {
            let d = v.position - centre;
            s.offset += d;
            s.count += 1.0;
            s.normal += v.normal;
            s.offset_sq += dot(d, d);
        }
    }
    cluster_partials[b * CLUSTER_COUNT + k] = s;
}

// One invocation per cluster: its blocks' sums, then the new centre.
@compute @workgroup_size(WORKGROUP_X)
fn kmeans_reduce(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    let n = frame_val_count();
    if k >= CLUSTER_COUNT || n == 0u {
        return;
    }
    var s = ClusterSums(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    let blocks = (n + PARTIAL_BLOCK - 1u) / PARTIAL_BLOCK;
    for (var b = 0u; b < blocks; b++) {
        let p = cluster_partials[b * CLUSTER_COUNT + k];
        s.offset += p.offset;
        s.count += p.count;
        s.normal += p.normal;
        s.offset_sq += p.offset_sq;
    }
    clusters[k] = kmeans_centre(clusters[k], s);
}
