// The near field's grid, rebuilt every frame (`near_field.wgsl`).

@group(0) @binding(0) var<storage, read> vals: array<Val>;
@group(0) @binding(1) var<storage, read> val_count: u32;
@group(0) @binding(2) var<storage, read_write> grid_counts: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> grid_starts: array<u32>;
@group(0) @binding(4) var<storage, read_write> val_slots: array<u32>;
@group(0) @binding(5) var<storage, read_write> grid_vals: array<Val>;

fn frame_val_count() -> u32 {
    return min(val_count, arrayLength(&vals));
}

@compute @workgroup_size(WORKGROUP_X)
fn grid_count(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame_val_count() {
        return;
    }
    let slot = grid_slot(vals[id.x].position, id.x, arrayLength(&grid_starts));
    val_slots[id.x] = atomicAdd(&grid_counts[slot], 1u);
}

var<workgroup> chunk_sums: array<u32, WORKGROUP_X>;

// One workgroup: each invocation sums its run of slots, the runs' sums are scanned, then
// each invocation writes its run's starts.
@compute @workgroup_size(WORKGROUP_X)
fn grid_scan(@builtin(local_invocation_index) local: u32) {
    let run = arrayLength(&grid_starts) / WORKGROUP_X;
    let first = local * run;
    var sum = 0u;
    for (var b = first; b < first + run; b++) {
        sum += atomicLoad(&grid_counts[b]);
    }
    chunk_sums[local] = sum;
    workgroupBarrier();
    if local == 0u {
        var total = 0u;
        for (var i = 0u; i < WORKGROUP_X; i++) {
            let s = chunk_sums[i];
            chunk_sums[i] = total;
            total += s;
        }
    }
    workgroupBarrier();
    var start = chunk_sums[local];
    for (var b = first; b < first + run; b++) {
        grid_starts[b] = start;
        start += atomicLoad(&grid_counts[b]);
    }
}

@compute @workgroup_size(WORKGROUP_X)
fn grid_scatter(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame_val_count() {
        return;
    }
    let val = vals[id.x];
    let slot = grid_slot(val.position, id.x, arrayLength(&grid_starts));
    grid_vals[grid_starts[slot] + val_slots[id.x]] = val;
}
