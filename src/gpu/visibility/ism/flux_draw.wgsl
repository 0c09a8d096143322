// A stratified draw by flux (paper 004 §3: VPLs drawn by importance), shared by the imperfect
// shadow maps' VALs (`sampling.wgsl`) and the second bounce's (`gpu/lights/bounce_draw.wgsl`):
// draw k of `count` is the item whose share of the running sum of flux luminance holds
// (k + 0.5) / count of the total. Two steps before the draw: the flux of each block of
// SAMPLE_BLOCK items, then their running sums (one invocation). The items are `vals`, the
// first `val_count` of them. Rust twin: `ism::twin::flux_picks` (same order of sums).

@group(0) @binding(0) var<storage, read> vals: array<Val>;
@group(0) @binding(1) var<storage, read> val_count: u32;
@group(0) @binding(2) var<storage, read_write> flux_prefix: array<f32>;

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

// One invocation: flux_prefix[b] becomes the flux of the items before block b.
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

// The total the draw runs over (after `flux_scan`): 0 without lit items.
fn flux_total() -> f32 {
    let blocks = frame_blocks();
    if blocks == 0u {
        return 0.0;
    }
    return flux_prefix[blocks];
}

// Draw k of `count`: the index of the item holding (k + 0.5) / count of the running sum, or
// 0xffffffff without lit items.
fn flux_pick(k: u32, count: u32) -> u32 {
    let blocks = frame_blocks();
    let n = frame_val_count();
    if blocks == 0u || !(flux_prefix[blocks] > 0.0) {
        return 0xffffffffu;
    }
    let goal = (f32(k) + 0.5) / f32(count) * flux_prefix[blocks];
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
    // Rounding may leave the goal past the block's last sum: its last lit item.
    if pick == 0xffffffffu {
        pick = last_lit;
    }
    return pick;
}
