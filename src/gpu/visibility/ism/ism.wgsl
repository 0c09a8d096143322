// Imperfect shadow maps (paper 004), shared by their passes; after the clusters' header and
// `paraboloid.wgsl`, with ISM_POINTS, PULL_THRESHOLD, PUSH_THRESHOLD, SAMPLE_BLOCK and
// POINT_SEED prepended (`ism/mod.rs`). Map k of resolution n holds n² texels from k n² on, row
// by row; a texel stores `0xffffffff - bits(distance)`, so 0 is empty (a cleared buffer) and
// the nearest point wins by `atomicMax` (distances are positive floats: their bits order like
// them). Rust twin: `twin.rs`.

fn encode_depth(distance: f32) -> u32 {
    return 0xffffffffu - bitcast<u32>(distance);
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
