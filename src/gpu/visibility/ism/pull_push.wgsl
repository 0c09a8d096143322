// Pull-push hole filling of the imperfect shadow maps (paper 004 §3.1, after Marroquim et al.
// 2007). `LEVEL` (an override) is the finer of the two levels a dispatch joins; level l of a map
// has MAP_RESOLUTION >> l texels per side. Pull: a coarse texel averages its four children's
// depths that lie within PULL_THRESHOLD x 2^LEVEL of the nearest of them (empty when all four
// are). Push, from the coarsest level down: a fine texel that is empty, or whose depth differs
// from its coarse parent's by more than PUSH_THRESHOLD x 2^LEVEL, takes the parent's. Rust
// twin: `twin::pull` and `twin::push`.

override LEVEL: u32 = 0u;

@group(0) @binding(0) var<storage, read_write> fine: array<u32>;
@group(0) @binding(1) var<storage, read_write> coarse: array<u32>;

// The finer level's side; the coarser one's is half of it.
fn fine_side() -> u32 {
    return MAP_RESOLUTION >> LEVEL;
}

// One invocation per (coarse texel, map).
@compute @workgroup_size(WORKGROUP_X)
fn pull(@builtin(global_invocation_id) id: vec3<u32>) {
    let fine_res = fine_side();
    let coarse_res = fine_res / 2u;
    let i = id.x;
    let k = id.y;
    if i >= coarse_res * coarse_res || k >= CLUSTER_COUNT {
        return;
    }
    let x = i % coarse_res;
    let y = i / coarse_res;
    var z: array<f32, 4>;
    var nearest = NOTHING;
    for (var c = 0u; c < 4u; c++) {
        z[c] = decode_depth(fine[map_texel_index(k, fine_res, 2u * x + c % 2u, 2u * y + c / 2u)]);
        nearest = min(nearest, z[c]);
    }
    var out = 0u;
    if nearest < NOTHING {
        let limit = nearest + PULL_THRESHOLD * f32(1u << LEVEL);
        var sum = 0.0;
        var n = 0.0;
        for (var c = 0u; c < 4u; c++) {
            if z[c] <= limit {
                sum += z[c];
                n += 1.0;
            }
        }
        out = encode_depth_at(sum / n, LEVEL + 1u);
    }
    coarse[map_texel_index(k, coarse_res, x, y)] = out;
}

// One invocation per (fine texel, map).
@compute @workgroup_size(WORKGROUP_X)
fn push(@builtin(global_invocation_id) id: vec3<u32>) {
    let fine_res = fine_side();
    let i = id.x;
    let k = id.y;
    if i >= fine_res * fine_res || k >= CLUSTER_COUNT {
        return;
    }
    let x = i % fine_res;
    let y = i / fine_res;
    let parent = coarse[map_texel_index(k, fine_res / 2u, x / 2u, y / 2u)];
    if parent == 0u {
        return;
    }
    let index = map_texel_index(k, fine_res, x, y);
    let zf = decode_depth(fine[index]);
    let zc = decode_depth(parent);
    if zf >= NOTHING || abs(zf - zc) > PUSH_THRESHOLD * f32(1u << LEVEL) {
        fine[index] = parent;
    }
}
