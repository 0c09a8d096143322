// The near field per pixel (`near_field.wgsl`): every VAL of the pixel's subset in the grid's
// buckets around the pixel's near-field centre (and, interleaved, every VAL of the close grid's
// buckets around it), scaled by its near-field share, added to the sparse shading in
// `indirect` (interleaved: the close share so, the rest summed before the pixel's material into
// `near_light` for the filter, `near_field_filter.wgsl`, which adds it). The share is taken at the centre (the pixel's
// interpolated `vertex_centres`: where the sparse points it interpolates lie, weighted as it
// weighs them), not at the pixel, so that a VAL the gather left out at those points is the one
// added here: at a corner, where all of a pixel's sparse points lie on one side of it, the
// pixel's own distance would count some VALs twice and others not at all. The light is the
// pixel's own: its position, normal and material (interleaved, the material comes in the
// filter).
// Rust twin: `twin::near_field::near_field_terms` (`twin::near_field::ValGrid::near_vals`
// visits the same VALs).

override VAL_BEGIN: u32 = 0u;
override VAL_SPAN: u32 = 0xffffffffu;

@group(0) @binding(0) var visibility: texture_2d<u32>;
// Interleaved only (else one element, unused): per pixel, irradiance (w: 1 where covered) and
// lobe, for the filter.
@group(0) @binding(1) var<storage, read_write> near_light: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> grid_counts: array<u32>;
@group(0) @binding(3) var<storage, read> grid_starts: array<u32>;
@group(0) @binding(4) var<storage, read> grid_vals: array<Val>;
@group(0) @binding(5) var<storage, read> vertex_centres: array<vec4<f32>>;
// The close grid (interleaved only; else the grid again, unread): every VAL in cells of
// 2 NEAR_FIELD_CLOSE_RADIUS, no subsets.
@group(0) @binding(6) var<storage, read> close_counts: array<u32>;
@group(0) @binding(7) var<storage, read> close_starts: array<u32>;
@group(0) @binding(8) var<storage, read> close_vals: array<Val>;
// Not interleaved: the light goes straight to the pixel's indirect light.
@group(0) @binding(9) var<storage, read_write> indirect: array<vec4<f32>>;
// Interleaved only (else one element, unused): per pixel, position and geometric normal
// (toward the viewer), for the filter.
@group(0) @binding(10) var<storage, read_write> near_surface: array<vec4<f32>>;

// `twin::near_field::NearTerms`: irradiance and lobe-weighted irradiance.
struct NearTerms {
    irradiance: vec3<f32>,
    lobe: vec3<f32>,
}

// `val`'s terms at `s` times `weight` added to `terms`.
fn add_val(terms: ptr<function, NearTerms>, s: Surface, w_o: vec3<f32>, val: Val, weight: f32, glossy: bool) {
    let geo = val_geometry_sided(s.position, s.normal, s.geometric, val.position, val.normal, val.area);
    let e = val.flux * (geo.weight * geo.cos_receiver * weight);
    (*terms).irradiance += e;
    if glossy {
        (*terms).lobe += phong_lobe(dot(mirror(geo.direction, s.normal), w_o), s.material.exponent) * e;
    }
}

// The part [first, last) of a run of `count` VALs, the next `count` of the visiting order after
// the `seen` before it, that falls in [VAL_BEGIN, `end`); `seen` moves past the run.
fn visit_range(seen: ptr<function, u32>, count: u32, end: u32) -> vec2<u32> {
    let first = max(*seen, VAL_BEGIN) - *seen;
    let last = max(min(*seen + count, end), *seen) - *seen;
    *seen += count;
    return vec2<u32>(first, last);
}

// Whether bucket `bucket`, the `c`-th of a pixel's eight, was among the first `c`.
fn repeated_bucket(visited: ptr<function, array<u32, 8>>, c: u32, bucket: u32) -> bool {
    var repeated = false;
    for (var i = 0u; i < c; i++) {
        repeated = repeated || (*visited)[i] == bucket;
    }
    (*visited)[c] = bucket;
    return repeated;
}

// No bucket: what `visited` holds for a cell whose columns were all read before.
const NO_BUCKET: u32 = 0xffffffffu;

// `twin::near_field::column_runs`: the columns [first, end) that an x extent [`lo`, `hi`] (a
// pixel's sphere) reaches in the cells `corner_x` (in xy) and `corner_x + 1` (in zw) along x, of
// side `cell`; the second is empty where the extent ends in the first.
fn column_runs(lo: f32, hi: f32, corner_x: i32, cell: f32) -> vec4<u32> {
    let first = column_of(lo, corner_x, cell);
    if i32(floor(hi / cell)) <= corner_x {
        return vec4<u32>(first, column_of(hi, corner_x, cell) + 1u, 0u, 0u);
    }
    return vec4<u32>(first, NEAR_FIELD_COLUMNS, 0u, column_of(hi, corner_x + 1, cell) + 1u);
}

// The columns [first, end) of bucket `bucket`, the `c`-th of a pixel's eight cells (its x offset
// `c & 1`), still to read: `runs`' for its x offset (`column_runs`), less what an earlier cell in
// the same bucket read (`twin::near_field::ValGrid::runs_around`). Two cells of one x offset
// read the same columns; of the two offsets, the first's run ends the cell and the second's
// starts it, so what is left of either is one run.
fn unread_columns(visited: ptr<function, array<u32, 8>>, c: u32, bucket: u32, runs: vec4<u32>) -> vec2<u32> {
    var seen = vec2<bool>(false, false);
    for (var i = 0u; i < c; i++) {
        if (*visited)[i] == bucket {
            if (i & 1u) == 0u {
                seen.x = true;
            } else {
                seen.y = true;
            }
        }
    }
    let x = c & 1u;
    var run = select(runs.xy, runs.zw, x == 1u);
    if run.x >= run.y || (x == 0u && seen.x) || (x == 1u && seen.y) {
        (*visited)[c] = NO_BUCKET;
        return vec2<u32>(0u, 0u);
    }
    (*visited)[c] = bucket;
    if x == 1u && seen.x {
        run.y = min(run.y, runs.x);
    }
    if x == 0u && seen.y {
        run.x = max(run.x, runs.w);
    }
    return run;
}

// A pixel's near field in two parts (`twin::near_field::NearParts`): interleaved, every VAL's
// close share, which the pixel adds itself, and the rest of its subset's near share times the
// subsets, which the filter averages; not interleaved, everything is the rest.
struct NearParts {
    close: NearTerms,
    rest: NearTerms,
}

// What the near VALs [VAL_BEGIN, VAL_BEGIN + VAL_SPAN) of the visiting order around `centre`
// deliver at `s` before its material (`twin::near_field::near_field_terms`): first, interleaved,
// every VAL's close share through the close grid, then the rest of the near share of the VALs
// of `subset` through the grid's slots, times the subsets.
fn near_field(s: Surface, centre: vec3<f32>, subset: u32, glossy: bool) -> NearParts {
    let w_o = view_direction(s.position, s.normal, frame.eye);
    var visited: array<u32, 8>;
    var seen = 0u;
    let end = VAL_BEGIN + min(VAL_SPAN, 0xffffffffu - VAL_BEGIN);
    var close = NearTerms(vec3<f32>(0.0), vec3<f32>(0.0));
    if NEAR_FIELD_CLOSE_RADIUS > 0.0 {
        let buckets = arrayLength(&close_starts) / NEAR_FIELD_COLUMNS;
        let corner = vec3<i32>(floor((centre - vec3<f32>(NEAR_FIELD_CLOSE_RADIUS)) / NEAR_FIELD_CLOSE_CELL));
        let runs = column_runs(
            centre.x - NEAR_FIELD_CLOSE_RADIUS,
            centre.x + NEAR_FIELD_CLOSE_RADIUS,
            corner.x,
            NEAR_FIELD_CLOSE_CELL,
        );
        for (var c = 0u; c < 8u; c++) {
            let bucket = bucket_of(corner + vec3<i32>(vec3<u32>(c & 1u, (c >> 1u) & 1u, c >> 2u)), buckets);
            let columns = unread_columns(&visited, c, bucket, runs);
            if columns.x >= columns.y {
                continue;
            }
            // The columns' slots are one run of `close_vals`.
            let first = bucket * NEAR_FIELD_COLUMNS + columns.x;
            let last = bucket * NEAR_FIELD_COLUMNS + columns.y - 1u;
            let start = close_starts[first];
            let count = close_starts[last] + close_counts[last] - start;
            let range = visit_range(&seen, count, end);
            for (var k = range.x; k < range.y; k++) {
                let val = close_vals[start + k];
                let weight = near_field_weight(distance(val.position, centre), NEAR_FIELD_CLOSE_RADIUS);
                if weight > 0.0 {
                    add_val(&close, s, w_o, val, weight, glossy);
                }
            }
        }
    }
    let buckets = arrayLength(&grid_starts) / (NEAR_FIELD_SUBSETS * NEAR_FIELD_COLUMNS);
    // The 2 x 2 x 2 cells from the one holding `position - radius` on every axis, the columns of
    // each that the sphere's x extent reaches.
    let corner = cell_of(centre - vec3<f32>(NEAR_FIELD_RADIUS));
    let runs = column_runs(centre.x - NEAR_FIELD_RADIUS, centre.x + NEAR_FIELD_RADIUS, corner.x, NEAR_FIELD_CELL);
    var rest = NearTerms(vec3<f32>(0.0), vec3<f32>(0.0));
    for (var c = 0u; c < 8u; c++) {
        let bucket = bucket_of(corner + vec3<i32>(vec3<u32>(c & 1u, (c >> 1u) & 1u, c >> 2u)), buckets);
        let columns = unread_columns(&visited, c, bucket, runs);
        if columns.x >= columns.y {
            continue;
        }
        // The subset's slots of these columns are one run of `grid_vals`, [seen, seen + count)
        // of the visiting order.
        let slots = (bucket * NEAR_FIELD_SUBSETS + subset) * NEAR_FIELD_COLUMNS;
        let start = grid_starts[slots + columns.x];
        let last = slots + columns.y - 1u;
        let count = grid_starts[last] + grid_counts[last] - start;
        let range = visit_range(&seen, count, end);
        for (var k = range.x; k < range.y; k++) {
            let val = grid_vals[start + k];
            let d = distance(val.position, centre);
            let weight = near_field_weight(d, NEAR_FIELD_RADIUS) - near_field_weight(d, NEAR_FIELD_CLOSE_RADIUS);
            if weight > 0.0 {
                add_val(&rest, s, w_o, val, weight, glossy);
            }
        }
    }
    let scale = f32(NEAR_FIELD_SUBSETS);
    return NearParts(close, NearTerms(scale * rest.irradiance, scale * rest.lobe));
}

// The rest of the near share (past the close share, which the shade added) of every near VAL
// [VAL_BEGIN, VAL_BEGIN + VAL_SPAN) of the visiting order around `centre` at `s`, through the
// grid's buckets whole (a bucket's subsets' slots are one run of `grid_vals`): what a pixel the
// filter leaves to the redo adds (with the close share, `twin::near_field::terms_over`).
fn near_field_whole(s: Surface, centre: vec3<f32>, glossy: bool) -> NearTerms {
    let w_o = view_direction(s.position, s.normal, frame.eye);
    var visited: array<u32, 8>;
    var seen = 0u;
    let end = VAL_BEGIN + min(VAL_SPAN, 0xffffffffu - VAL_BEGIN);
    let slots = NEAR_FIELD_SUBSETS * NEAR_FIELD_COLUMNS;
    let buckets = arrayLength(&grid_starts) / slots;
    let corner = cell_of(centre - vec3<f32>(NEAR_FIELD_RADIUS));
    var terms = NearTerms(vec3<f32>(0.0), vec3<f32>(0.0));
    for (var c = 0u; c < 8u; c++) {
        let bucket = bucket_of(corner + vec3<i32>(vec3<u32>(c & 1u, (c >> 1u) & 1u, c >> 2u)), buckets);
        if repeated_bucket(&visited, c, bucket) {
            continue;
        }
        let last_slot = (bucket + 1u) * slots - 1u;
        let start = grid_starts[bucket * slots];
        let count = grid_starts[last_slot] + grid_counts[last_slot] - start;
        let range = visit_range(&seen, count, end);
        for (var k = range.x; k < range.y; k++) {
            let val = grid_vals[start + k];
            let d = distance(val.position, centre);
            let weight = near_field_weight(d, NEAR_FIELD_RADIUS) - near_field_weight(d, NEAR_FIELD_CLOSE_RADIUS);
            if weight > 0.0 {
                add_val(&terms, s, w_o, val, weight, glossy);
            }
        }
    }
    return terms;
}

// Interleaved, after the filter: a covered pixel whose window the filter left to the redo
// (`redone`, `near_field_window.wgsl`) adds the rest of every near VAL's share, through its
// material, to `indirect` (the shade added the close share).
fn redo(id: vec2<u32>, glossy: bool) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let i = id.y * frame.width + id.x;
    if near_light[2u * i].w == 0.0 || !redone(window_at(id)) {
        return;
    }
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id), 0));
    let t = 3u * hit.triangle;
    let c = vec3<u32>(indices[t], indices[t + 1u], indices[t + 2u]);
    let centre = barycentric(hit.barycentrics, vertex_centres[c.x].xyz, vertex_centres[c.y].xyz, vertex_centres[c.z].xyz);
    let s = facing_viewer(surface_at(hit.triangle, hit.barycentrics), frame.eye);
    let terms = near_field_whole(s, centre, glossy);
    add_near_light(i, s, terms.irradiance, terms.lobe, glossy);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_redo(@builtin(global_invocation_id) id: vec3<u32>) {
    redo(id.xy, false);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_redo_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    redo(id.xy, true);
}

// Not interleaved, the light through the pixel's material is added to `indirect`; interleaved,
// the close share's light too, and the rest's terms go to `near_light` (cleared by the stage)
// and the surface point to `near_surface`, for the filter. Each VAL range adds its share.
fn shade(id: vec2<u32>, glossy: bool) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id), 0));
    if !hit.covered {
        return;
    }
    let i = id.y * frame.width + id.x;
    let t = 3u * hit.triangle;
    let c = vec3<u32>(indices[t], indices[t + 1u], indices[t + 2u]);
    let centre = barycentric(hit.barycentrics, vertex_centres[c.x].xyz, vertex_centres[c.y].xyz, vertex_centres[c.z].xyz);
    let s = facing_viewer(surface_at(hit.triangle, hit.barycentrics), frame.eye);
    let parts = near_field(s, centre, pixel_subset(id), glossy);
    if NEAR_FIELD_SIDE == 1u {
        add_near_light(i, s, parts.rest.irradiance, parts.rest.lobe, glossy);
        return;
    }
    add_near_light(i, s, parts.close.irradiance, parts.close.lobe, glossy);
    near_light[2u * i] = vec4<f32>(near_light[2u * i].xyz + parts.rest.irradiance, 1.0);
    near_light[2u * i + 1u] = vec4<f32>(near_light[2u * i + 1u].xyz + parts.rest.lobe, 0.0);
    near_surface[2u * i] = vec4<f32>(s.position, 1.0);
    near_surface[2u * i + 1u] = vec4<f32>(s.geometric, 0.0);
}

// The pixel invocation `id` shades. Interleaved, the image is walked as NEAR_FIELD_SIDE²
// sub-images, one per subset, each of every NEAR_FIELD_SIDE-th pixel (Segovia et al.'s
// deinterleaving): the invocations of a workgroup then take the same subset at nearby pixels,
// so they walk the same slots of the same buckets. The dispatch covers NEAR_FIELD_SIDE x
// ceil(size / NEAR_FIELD_SIDE) invocations on each axis; the workgroups' invocations past them
// map past the image (and are skipped there).
fn pixel_of(id: vec2<u32>) -> vec2<u32> {
    let sub = (vec2<u32>(frame.width, frame.height) + NEAR_FIELD_SIDE - 1u) / NEAR_FIELD_SIDE;
    if any(id >= sub * NEAR_FIELD_SIDE) {
        return vec2<u32>(frame.width, frame.height);
    }
    return (id % sub) * NEAR_FIELD_SIDE + id / sub;
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    shade(pixel_of(id.xy), false);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    shade(pixel_of(id.xy), true);
}
