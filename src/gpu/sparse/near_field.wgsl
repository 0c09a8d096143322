// The sparse method's near field (docs/measurements/sparse-real-scenes.md): a VAL closer to a
// receiver than NEAR_FIELD_RADIUS lights it per pixel, with the pixel's own position, normal
// and material, instead of through the sparse points (the gather leaves that share out:
// `gather.wgsl`). The pixel finds those VALs in a uniform grid of cells NEAR_FIELD_CELL = 2 x
// the radius wide, hashed into the buckets of `grid_counts` / `grid_starts`, which the grid
// entry points rebuild every frame by a counting sort: `grid_count` (each VAL's bucket and its
// slot in it), `grid_scan` (the buckets' starts, one workgroup), `grid_scatter` (the VALs in
// bucket order). A sphere of the radius around a pixel lies in the 2 x 2 x 2 cells around the
// cell corner nearest to it, and within them in the columns (NEAR_FIELD_COLUMNS slices of a
// cell along x) that its x extent reaches; a bucket shared by two of those cells is read once,
// and VALs of other cells in a visited bucket are farther than the radius (weight 0).
// Rust twins: `twin::near_field::ValGrid` (the grid), `twin::shade_near_field` (the sum).
//
//
// Interleaved over blocks NEAR_FIELD_SIDE pixels wide (`settings.sparse.near_field_interleave`),
// each cell bucket holds NEAR_FIELD_SUBSETS = side² slots, one per VAL subset (`val_subset`: a
// hash of the VAL's index), and a pixel visits its own subset's slots only (`pixel_subset`);
// `near_field_filter.wgsl` adds the subsets of the pixel's block up again.
//
// CPU adapters end a shader's loops after a fixed iteration count (llvmpipe), so there one
// dispatch takes the pixel's near VALs [VAL_BEGIN, VAL_BEGIN + VAL_SPAN) in visiting order and
// the next adds the following ones; GPUs take them all at once.
// This file holds what all share; NEAR_FIELD_RADIUS, NEAR_FIELD_CELL, NEAR_FIELD_SIDE and
// NEAR_FIELD_SUBSETS are prepended
// (`near_field::head`), the grid passes (`near_field_grid.wgsl`), the per-pixel pass
// (`near_field_shade.wgsl`) or the filter (`near_field_filter.wgsl`) follow.

// `twin::near_field::cell_of`: the grid cell holding `p`.
fn cell_of(p: vec3<f32>) -> vec3<i32> {
    return vec3<i32>(floor(p / NEAR_FIELD_CELL));
}

// `twin::near_field::bucket_of`: a cell's bucket among `buckets` (a power of two).
fn bucket_of(cell: vec3<i32>, buckets: u32) -> u32 {
    let u = bitcast<vec3<u32>>(cell);
    return ((u.x * 73856093u) ^ (u.y * 19349663u) ^ (u.z * 83492791u)) & (buckets - 1u);
}


// `twin::near_field::val_subset`: the subset VAL `index` of the frame falls in.
fn val_subset(index: u32) -> u32 {
    return pcg_hash(index) & (NEAR_FIELD_SUBSETS - 1u);
}

// `twin::near_field::pixel_subset`: the subset pixel `id` sums.
fn pixel_subset(id: vec2<u32>) -> u32 {
    return id.x % NEAR_FIELD_SIDE + NEAR_FIELD_SIDE * (id.y % NEAR_FIELD_SIDE);
}

// `twin::near_field::COLUMNS`: each cell is split along x into this many columns, and each of
// a bucket's subsets into one slot per column, in column order, so that the VALs of a run of
// columns are one run of the grid's VALs: a pixel reads only the columns its sphere reaches.
const NEAR_FIELD_COLUMNS: u32 = 8u;

// `twin::near_field::column_of`: the column of the cell (of side `cell`, index `cell_x` on x)
// that the x coordinate `x` falls in, clamped to the cell's.
fn column_of(x: f32, cell_x: i32, cell: f32) -> u32 {
    let columns = f32(NEAR_FIELD_COLUMNS);
    return u32(clamp(floor(x / (cell / columns)) - f32(cell_x) * columns, 0.0, columns - 1.0));
}

// The slot among `slots` of the frame's VAL `index` at `position`: its cell's bucket, its
// subset, its column (`twin::near_field::ValGrid::build`).
fn grid_slot(position: vec3<f32>, index: u32, slots: u32) -> u32 {
    let cell = cell_of(position);
    let bucket = bucket_of(cell, slots / (NEAR_FIELD_SUBSETS * NEAR_FIELD_COLUMNS));
    let column = column_of(position.x, cell.x, NEAR_FIELD_CELL);
    return (bucket * NEAR_FIELD_SUBSETS + val_subset(index)) * NEAR_FIELD_COLUMNS + column;
}
