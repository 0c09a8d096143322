// The near field per pixel (`near_field.wgsl`): every VAL of the grid's buckets around the
// pixel's near-field centre, scaled by its near-field share, added to the sparse shading in
// `indirect`. The share is taken at the centre (the pixel's interpolated `vertex_centres`: where
// the sparse points it interpolates lie, weighted as it weighs them), not at the pixel, so that
// a VAL the gather left out at those points is the one added here: at a corner, where all of a
// pixel's sparse points lie on one side of it, the pixel's own distance would count some VALs
// twice and others not at all. The light is the pixel's own: its position, normal, material.
// Rust twin: `twin::shade_near_field` over `twin::near_field::ValGrid::near_vals` (the buckets
// around the centre).

override VAL_BEGIN: u32 = 0u;
override VAL_SPAN: u32 = 0xffffffffu;

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> indirect: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> grid_counts: array<u32>;
@group(0) @binding(3) var<storage, read> grid_starts: array<u32>;
@group(0) @binding(4) var<storage, read> grid_vals: array<Val>;
@group(0) @binding(5) var<storage, read> vertex_centres: array<vec4<f32>>;

// The radiance the near VALs [VAL_BEGIN, VAL_BEGIN + VAL_SPAN) of the visiting order around
// `centre` reflect at `s` toward the eye.
fn near_field(s: Surface, centre: vec3<f32>, glossy: bool) -> vec3<f32> {
    let buckets = arrayLength(&grid_starts);
    let w_o = view_direction(s.position, s.normal, frame.eye);
    let spec = s.material.specular * phong_normalisation(s.material.exponent);
    // The 2 x 2 x 2 cells from the one holding `position - radius` on every axis.
    let corner = cell_of(centre - vec3<f32>(NEAR_FIELD_RADIUS));
    var visited: array<u32, 8>;
    var seen = 0u;
    var l = vec3<f32>(0.0);
    let end = VAL_BEGIN + min(VAL_SPAN, 0xffffffffu - VAL_BEGIN);
    for (var c = 0u; c < 8u; c++) {
        let bucket = bucket_of(corner + vec3<i32>(vec3<u32>(c & 1u, (c >> 1u) & 1u, c >> 2u)), buckets);
        var repeated = false;
        for (var i = 0u; i < c; i++) {
            repeated = repeated || visited[i] == bucket;
        }
        visited[c] = bucket;
        if repeated {
            continue;
        }
        // This bucket's VALs are [seen, seen + count) of the visiting order.
        let count = grid_counts[bucket];
        let first = max(seen, VAL_BEGIN) - seen;
        let last = max(min(seen + count, end), seen) - seen;
        seen += count;
        let start = grid_starts[bucket];
        for (var k = first; k < last; k++) {
            let val = grid_vals[start + k];
            let weight = near_field_weight(distance(val.position, centre), NEAR_FIELD_RADIUS);
            if weight <= 0.0 {
                continue;
            }
            let geo = val_geometry_sided(s.position, s.normal, s.geometric, val.position, val.normal, val.area);
            l += reflected_radiance(s, spec, w_o, geo.direction, val.flux * (geo.weight * geo.cos_receiver * weight), glossy);
        }
    }
    return l;
}

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
    let before = indirect[i];
    indirect[i] = vec4<f32>(before.rgb + near_field(facing_viewer(surface_at(hit.triangle, hit.barycentrics), frame.eye), centre, glossy), before.a);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    shade(id.xy, false);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    shade(id.xy, true);
}
