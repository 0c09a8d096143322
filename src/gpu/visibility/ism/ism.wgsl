// Imperfect shadow maps (paper 004), shared by their passes; after the clusters' header and
// `paraboloid.wgsl`, with ISM_POINTS, PULL_THRESHOLD, PUSH_THRESHOLD, SAMPLE_BLOCK and
// POINT_SEED prepended (`ism/mod.rs`). Map k of resolution n holds n² texels from k n² on, row
// by row; a texel stores `0xffffffff - bits(distance)`, so 0 is empty (a cleared buffer) and
// the nearest point wins by `atomicMax` (distances are positive floats: their bits order like
// them). Rust twin: `twin.rs`.

// The lowest 3 bits of a stored distance (3 ulps of it) say at which level it was made: 0 for
// a splatted point, l + 1 for a pull of level l's texels (pushed down unchanged). The lookup
// widens its slope-scaled bias by 2^level (`cluster_visibility.wgsl`, `depth_spread`): a
// pulled depth stands for a block of 2^level texels.
fn encode_depth_at(distance: f32, level: u32) -> u32 {
    return 0xffffffffu - ((bitcast<u32>(distance) & ~7u) | level);
}

fn encode_depth(distance: f32) -> u32 {
    return encode_depth_at(distance, 0u);
}

// Distance (m) of an encoded texel; NOTHING where it is empty.
fn decode_depth(e: u32) -> f32 {
    if e == 0u {
        return NOTHING;
    }
    return bitcast<f32>(0xffffffffu - e);
}

fn map_texel_index(k: u32, resolution: u32, x: u32, y: u32) -> u32 {
    return (k * resolution + y) * resolution + x;
}
