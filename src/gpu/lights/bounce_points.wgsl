// The second bounce, step 1 (paper 004 §4.1, imperfect reflective shadow maps: "shaded
// points"): every bounce point (a triangle and barycentrics, spread over the meshes by area at
// load, so it follows moving meshes) is lit by every first-bounce VAL (docs/design.md §3, the disc
// form factor) seen through `val_visibility(point, val)` (prepended: 1 without visibility,
// the first bounce's groups' lookup at the point with the sparse method's `clusters` or `ism`
// mode, `visibility/group.wgsl`) and becomes a candidate VAL (with `disks`, `store_moments`
// also keeps the point's irradiance and light-sphere moments for `bounce2_occlusion`, which
// scales the candidate after every VAL range): a Lambertian disc re-emitting the
// diffuse part of what it receives, flux `rho_d * E * area` (W), `area` the patch it stands
// for. The first-bounce VALs stream through workgroup memory in tiles (`shader/val_tiles.wgsl`,
// prepended), in ranges on CPU adapters, each range after the first adding its flux.
// Rust twin: `twin::bounce::candidate_vals`.

// Binding 0, `bounce_points`: `bounce_point.wgsl` (prepended).
@group(0) @binding(1) var<storage, read> vals: array<Val>;
@group(0) @binding(2) var<storage, read> val_count: u32;
@group(0) @binding(3) var<storage, read_write> candidates: array<Val>;

@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let index = id.x;
    let point = bounce_invocation(index);
    let inside = point.inside;
    let position = point.surface.position;
    let normal = point.surface.normal;
    let geometric = point.surface.geometric;
    let albedo = point.surface.material.diffuse;
    var area = 0.0;
    if inside {
        area = bounce_points[index].area;
    }
    var e = vec3<f32>(0.0);
    // The light sphere's moments, weighted as the gather weighs them (`store_moments` keeps
    // them with `disks` visibility; else they are dropped).
    var l = vec3<f32>(0.0);
    var l2 = vec3<f32>(0.0);
    var w = 0.0;
    let end = val_range_end();
    for (var base = VAL_BEGIN; base < end; base += TILE_SIZE) {
        let n = load_tile(base, local, end);
        for (var j = 0u; j < n; j++) {
            let val = tile[j];
            // The shading normal's cosine, none from below the geometric surface (docs/design.md §3).
            let geo = val_geometry_sided(position, normal, geometric, val.position, val.normal, val.area);
            let f = geo.weight * geo.cos_receiver * val_visibility(index, base + j);
            e += val.flux * f;
            let g = luminance(val.flux) * f + GATHER_EPSILON;
            l += g * val.position;
            l2 += g * val.position * val.position;
            w += g;
        }
        workgroupBarrier();
    }
    if !inside {
        return;
    }
    store_moments(index, e, w, l, l2);
    let flux = albedo * e * area;
    if VAL_BEGIN == 0u {
        candidates[index] = Val(position, area, normal, 0.0, flux, 0.0);
    } else {
        candidates[index].flux += flux;
    }
}
