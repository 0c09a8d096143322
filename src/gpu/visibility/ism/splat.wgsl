// The imperfect shadow maps' points (paper 004 §3.1): map k splats ISM_POINTS points of its own,
// each on a triangle drawn by area (`triangle_cdf`: running sums of the triangle areas at load)
// with uniform barycentrics, all from a hash of (k, j): a fixed random subset per map that
// follows the meshes as they move (the current vertices). A point in the front hemisphere of
// group k's map frame (`cluster_map_frame`) lands in one texel of its paraboloid map, nearest
// distance kept; points
// nearer than CLUSTER_NEAR_FRACTION x the group's radius (its own surface) are skipped, as in
// the rasterised maps. No far plane: a group's centre is its VALs' and may lie metres from the
// meshes, and a distance of any size is stored as its float's bits (`ism.wgsl`). Rust twin:
// `twin::splat_in`.

@group(0) @binding(0) var<storage, read> clusters: array<Cluster>;
@group(0) @binding(1) var<storage, read> triangle_cdf: array<f32>;
@group(0) @binding(2) var<storage, read_write> ism_atlas: array<atomic<u32>>;

// Point j of map k, in the scene's world frame.
fn ism_point(k: u32, j: u32) -> vec3<f32> {
    let h0 = pcg_hash((k * ISM_POINTS + j) ^ POINT_SEED);
    let h1 = pcg_hash(h0);
    let h2 = pcg_hash(h1);
    let triangles = arrayLength(&triangle_cdf);
    let goal = unit_float(h0) * triangle_cdf[triangles - 1u];
    // The first triangle whose running area passes the goal.
    var lo = 0u;
    var hi = triangles - 1u;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if triangle_cdf[mid] > goal {
            hi = mid;
        } else {
            lo = mid + 1u;
        }
    }
    var u = unit_float(h1);
    var v = unit_float(h2);
    if u + v > 1.0 {
        u = 1.0 - u;
        v = 1.0 - v;
    }
    let p0 = vertices[indices[3u * lo]].position;
    let p1 = vertices[indices[3u * lo + 1u]].position;
    let p2 = vertices[indices[3u * lo + 2u]].position;
    return p0 + (p1 - p0) * u + (p2 - p0) * v;
}

// One invocation per (point, map).
@compute @workgroup_size(WORKGROUP_X)
fn splat(@builtin(global_invocation_id) id: vec3<u32>) {
    let j = id.x;
    let k = id.y;
    if j >= ISM_POINTS || k >= CLUSTER_COUNT {
        return;
    }
    let c = clusters[k];
    if c.count == 0.0 {
        return;
    }
    let d = ism_point(k, j) - c.position;
    let distance = length(d);
    if !(distance > c.radius * CLUSTER_NEAR_FRACTION) || !(distance < NOTHING) {
        return;
    }
    let v = d / distance;
    var f = hemisphere_frame(c.normal);
    if FOCUS_BOUNDS != 0u {
        f = cluster_map_frame(c, clusters[CLUSTER_COUNT]);
    }
    if dot(v, f.axis) <= 0.0 {
        return;
    }
    let t = floor(disc_texel(map_project(v, f)));
    let r = f32(MAP_RESOLUTION);
    if t.x < 0.0 || t.y < 0.0 || t.x >= r || t.y >= r {
        return;
    }
    atomicMax(&ism_atlas[map_texel_index(k, MAP_RESOLUTION, u32(t.x), u32(t.y))], encode_depth(distance));
}
