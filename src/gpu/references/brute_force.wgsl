// Brute-force reference (docs/design.md §5): every VAL applied to every visible pixel through §3,
// no sparse points, no interpolation. VALs stream through workgroup memory as in the gather, in
// tiles and per-dispatch ranges (`shader/val_tiles.wgsl`, prepended), each range after the first
// adding to the radiance the earlier ones wrote. `pixel_val_visibility(receiver, slot, val)`
// (prepended, after `prepare_visibility` ran on the invocation's receivers) is 1 for the brute
// force (no visibility), the group's entry of the table at the pixel for `brute_force_ism`
// (`visibility/group.wgsl`), and its cluster's lookup at the pixel, made in this pass, for
// `brute_force_clusters` (`brute_force_lookup.wgsl`). Each invocation shades PIXELS consecutive
// pixels of a row (prepended by `brute_force.rs` with `add_to_pixels`, the per-VAL statement
// written out once per pixel, as the gather's `add_to_receivers`): every VAL read from the tile
// serves that many pixels. Rust twin: `twin::shade_brute_force`.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> indirect: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> vals: array<Val>;
@group(0) @binding(3) var<storage, read> val_count: u32;

// A pixel an invocation shades: its surface (a dummy outside the image or where nothing is),
// turned to face the viewer, and its shading normal as the mesh gives it (the clusters' lookup
// takes that one, as at the sparse points).
struct Receiver {
    surface: Surface,
    given_normal: vec3<f32>,
    w_o: vec3<f32>,
    spec: vec3<f32>,
    pixel: u32,
    inside: bool,
    covered: bool,
}

fn receiver(x: u32, y: u32) -> Receiver {
    let inside = x < frame.width && y < frame.height;
    var hit = Hit(false, 0u, vec2<f32>(0.0));
    if inside {
        hit = decode_visibility(textureLoad(visibility, vec2<i32>(vec2<u32>(x, y)), 0));
    }
    var s = Surface(vec3<f32>(0.0), vec3<f32>(0.0, 1.0, 0.0), Material(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), -1), vec3<f32>(0.0, 1.0, 0.0));
    var given_normal = s.normal;
    if hit.covered {
        let given = surface_at(hit.triangle, hit.barycentrics);
        given_normal = given.normal;
        s = facing_viewer(given, frame.eye);
    }
    let w_o = view_direction(s.position, s.normal, frame.eye);
    let spec = s.material.specular * phong_normalisation(s.material.exponent);
    return Receiver(s, given_normal, w_o, spec, y * frame.width + x, inside, hit.covered);
}

// `l` plus the radiance VAL `val` (the `val_index`-th) reflects at pixel `r`, the
// invocation's `slot`-th.
fn add_val(l: vec3<f32>, r: Receiver, slot: u32, val: Val, val_index: u32, glossy: bool) -> vec3<f32> {
    let s = r.surface;
    let geo = val_geometry_sided(s.position, s.normal, s.geometric, val.position, val.normal, val.area);
    let f = geo.weight * geo.cos_receiver * pixel_val_visibility(r, slot, val_index);
    return l + reflected_radiance(s, r.spec, r.w_o, geo.direction, val.flux * f, glossy);
}

fn brute_force(id: vec2<u32>, local: u32, glossy: bool) {
    var receivers: array<Receiver, PIXELS>;
    var ls: array<vec3<f32>, PIXELS>;
    for (var r = 0u; r < PIXELS; r++) {
        receivers[r] = receiver(id.x * PIXELS + r, id.y);
        ls[r] = vec3<f32>(0.0);
    }
    prepare_visibility(&receivers);
    let end = val_range_end();
    for (var base = VAL_BEGIN; base < end; base += TILE_SIZE) {
        let n = load_tile(base, local, end);
        for (var j = 0u; j < n; j++) {
            add_to_pixels(&ls, &receivers, tile[j], base + j, glossy);
        }
        workgroupBarrier();
    }
    for (var r = 0u; r < PIXELS; r++) {
        let p = receivers[r];
        if p.inside {
            var before = vec4<f32>(0.0);
            if VAL_BEGIN > 0u {
                before = indirect[p.pixel];
            }
            indirect[p.pixel] = select(vec4<f32>(0.0), vec4<f32>(before.rgb + ls[r], 1.0), p.covered);
        }
    }
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    brute_force(id.xy, local, false);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    brute_force(id.xy, local, true);
}
