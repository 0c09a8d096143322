// VALs streamed through workgroup memory in tiles of TILE_SIZE (the gather and the brute force;
// the pass declares `vals` and `val_count`). One dispatch takes the VALs
// [VAL_BEGIN, VAL_BEGIN + VAL_SPAN): all of them on GPUs; on CPU adapters (llvmpipe's loop
// limit) ranges, each after the first adding to what the earlier ones wrote
// (`gpu::pass::Kernels::val_ranges`).
override VAL_BEGIN: u32 = 0u;
override VAL_SPAN: u32 = 0xffffffffu;

var<workgroup> tile: array<Val, TILE_SIZE>;

// End (exclusive) of this dispatch's VAL range.
fn val_range_end() -> u32 {
    let count = min(val_count, arrayLength(&vals));
    return min(count, VAL_BEGIN + min(VAL_SPAN, count));
}

// Every invocation of the workgroup loads its VAL of the tile starting at `base`, then waits;
// returns how many VALs the tile holds. The caller waits again before the next tile.
fn load_tile(base: u32, local: u32, end: u32) -> u32 {
    if base + local < end {
        tile[local] = vals[base + local];
    }
    workgroupBarrier();
    return min(TILE_SIZE, end - base);
}
