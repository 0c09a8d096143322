// Per (sparse point, cluster): the fraction of the cluster's light reaching the point, from
// CLUSTER_RAYS shadow rays through the scene's BVH (`../../references/bvh.wgsl`, prepended) to
// that many of the cluster's VALs (`ray_members.wgsl`'s lists). The VALs are drawn
// systematically from the cluster's list: member floor((s + xi) n / CLUSTER_RAYS) of its n for
// ray s, `xi` a hash of the entry. Each ray's outcome weighs as the VAL's unoccluded light at
// the point (its irradiance's luminance, as the gather adds it), so the entry is the
// light-weighted share of the drawn VALs that the meshes leave visible: 1 where no drawn VAL
// lights the point (the gather then adds little from the cluster). Rays leave the point pushed
// along its triangle's face normal (`geometric`, never the interpolated `normal`: bent vertex
// normals would start them inside the neighbouring faces, docs/design.md §3) and end pushed off
// the VAL along its own normal, as the exact reference casts them.
//
// One flat loop of at most RAY_LOOP_BUDGET iterations, each a step of a ray or the draw of the
// next VAL: llvmpipe ends an invocation's loops after a fixed count, shared by the SIMD lanes
// of a vector (see `references/exact.rs`); a ray the budget cuts off does not count. Writes
// `group_visibility[point * CLUSTER_COUNT + k]`. Rust twin: `twin::ray_visibility`.

@group(0) @binding(0) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(1) var<storage, read> vals: array<Val>;
@group(0) @binding(2) var<storage, read> ray_members: array<u32>;
@group(0) @binding(3) var<storage, read_write> group_visibility: array<f32>;
// Bindings 4 and 5: `bvh.wgsl`.

fn ray_visibility(i: u32, k: u32) -> f32 {
    let start = ray_members[CLUSTER_COUNT + k];
    let count = ray_members[CLUSTER_COUNT + k + 1u] - start;
    if count == 0u {
        return 1.0;
    }
    let p = sparse_points[i];
    let origin = p.position + p.geometric * RAY_OFFSET;
    let xi = unit_float(pcg_hash(i * CLUSTER_COUNT + k));
    var s = 0u;
    var tracing = false;
    var w = RayWalk(0u, 0u, 0u, false);
    var d = vec3<f32>(1.0);
    var inv = vec3<f32>(1.0);
    var light = 0.0;
    var seen = 0.0;
    var lit = 0.0;
    var steps = 0u;
    while s < CLUSTER_RAYS && steps < RAY_LOOP_BUDGET {
        steps += 1u;
        if tracing {
            ray_step(origin, d, inv, &w);
            if ray_done(w) {
                seen += light;
                lit += select(light, 0.0, w.hit);
                tracing = false;
                s += 1u;
            }
        } else {
            let m = min(u32((f32(s) + xi) * f32(count) / f32(CLUSTER_RAYS)), count - 1u);
            let val = vals[ray_members[2u * CLUSTER_COUNT + 1u + start + m]];
            let geo = val_geometry(p.position, p.normal, val.position, val.normal, val.area);
            light = luminance(val.flux) * geo.weight * geo.cos_receiver;
            if light > 0.0 {
                d = val.position + val.normal * RAY_OFFSET - origin;
                inv = 1.0 / d;
                w = RayWalk(0u, 0u, 0u, false);
                tracing = true;
            } else {
                s += 1u;
            }
        }
    }
    if seen > 0.0 {
        return lit / seen;
    }
    return 1.0;
}

// One invocation per (sparse point, cluster).
@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let k = id.y;
    if i >= frame.sparse_count || k >= CLUSTER_COUNT {
        return;
    }
    group_visibility[i * CLUSTER_COUNT + k] = ray_visibility(i, k);
}
