// The VALs the imperfect shadow maps stand for (paper 004 §3: VPLs drawn from the RSM by
// importance): CLUSTER_COUNT VALs drawn by flux luminance, stratified (`(k + 0.5) / count` of
// the running sum), each the seed of one group; the clusters' assign and update then give every
// VAL the nearest seed and every group its mean position, normal and radius. Three steps: the
// flux of each block of SAMPLE_BLOCK VALs, their running sums (one invocation), the draw.
// Rust twin: `twin::flux_seeds` (same order of sums).

@group(0) @binding(0) var<storage, read> vals: array<Val>;
@group(0) @binding(1) var<storage, read> val_count: u32;
@group(0) @binding(2) var<storage, read_write> flux_prefix: array<f32>;
@group(0) @binding(3) var<storage, read_write> clusters: array<Cluster>;

fn frame_val_count() -> u32 {
    return min(val_count, arrayLength(&vals));
}

fn frame_blocks() -> u32 {
    return min((frame_val_count() + SAMPLE_BLOCK - 1u) / SAMPLE_BLOCK, arrayLength(&flux_prefix) - 1u);
}

fn val_weight(v: Val) -> f32 {
    return max(luminance(v.flux), 0.0);
}

// One invocation per block: its flux into flux_prefix[block + 1].
@compute @workgroup_size(WORKGROUP_X)
fn flux_blocks(@builtin(global_invocation_id) id: vec3<u32>) {
    let b = id.x;
    if b >= frame_blocks() {
        return;
    }
    let end = min((b + 1u) * SAMPLE_BLOCK, frame_val_count());
    var sum = 0.0;
    for (var i = b * SAMPLE_BLOCK; i < end; i++) {
        sum += val_weight(vals[i]);
    }
    flux_prefix[b + 1u] = sum;
}

// One invocation: flux_prefix[b] becomes the flux of the VALs before block b.
@compute @workgroup_size(WORKGROUP_X)
fn flux_scan(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x != 0u {
        return;
    }
    let blocks = frame_blocks();
    flux_prefix[0] = 0.0;
    var sum = 0.0;
    for (var b = 0u; b < blocks; b++) {
        sum += flux_prefix[b + 1u];
        flux_prefix[b + 1u] = sum;
    }
}

// One invocation per group: the VAL whose share of the running sum holds (k + 0.5) / count of
// the total. Without lit VALs every group is empty (count 0: fully visible, no map).
@compute @workgroup_size(WORKGROUP_X)
fn flux_sample(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= CLUSTER_COUNT {
        return;
    }
    let blocks = frame_blocks();
    let n = frame_val_count();
    if blocks == 0u || !(flux_prefix[blocks] > 0.0) {
        clusters[k] = Cluster(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 0.0, 1.0), 0.0);
        return;
    }
    let goal = (f32(k) + 0.5) / f32(CLUSTER_COUNT) * flux_prefix[blocks];
    // The last block that starts at or before the goal.
    var lo = 0u;
    var hi = blocks - 1u;
    while lo < hi {
        let mid = (lo + hi + 1u) / 2u;
        if flux_prefix[mid] <= goal {
            lo = mid;
        } else {
            hi = mid - 1u;
        }
    }
    var sum = flux_prefix[lo];
    var pick = 0xffffffffu;
    var last_lit = 0xffffffffu;
    let end = min((lo + 1u) * SAMPLE_BLOCK, n);
    for (var i = lo * SAMPLE_BLOCK; i < end; i++) {
        let w = val_weight(vals[i]);
        if w > 0.0 {
            last_lit = i;
            sum += w;
            if sum > goal {
                pick = i;
                break;
            }
        }
    }
    // Rounding may leave the goal past the block's last sum: its last lit VAL.
    if pick == 0xffffffffu {
        pick = last_lit;
    }
    if pick == 0xffffffffu {
        clusters[k] = Cluster(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 0.0, 1.0), 0.0);
        return;
    }
    let v = vals[pick];
    clusters[k] = Cluster(v.position, 0.0, v.normal, 0.0);
}
