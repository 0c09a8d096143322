// Exact visibility (docs/design.md §5): segment queries against the scene's triangles through the
// BVH built on the CPU (`twin::bvh`, whose `occluded` and `ray_triangle` are the twins).

struct BvhNode {
    min: vec3<f32>,
    first: u32,
    max: vec3<f32>,
    count: u32,
}

@group(0) @binding(4) var<storage, read> bvh_nodes: array<BvhNode>;
@group(0) @binding(5) var<storage, read> bvh_triangles: array<u32>;

// Parameter along `d` where `origin + t d` meets the triangle, or -1.
fn ray_triangle(origin: vec3<f32>, d: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> f32 {
    let e1 = b - a;
    let e2 = c - a;
    let p = cross(d, e2);
    let det = dot(e1, p);
    // Relative test: a degenerate (collinear) triangle's det is rounding noise, which FMA
    // contraction turns into phantom hits; grazing rays are treated as misses too.
    if abs(det) <= RAY_PARALLEL_EPSILON * length(e1) * length(e2) * length(d) {
        return -1.0;
    }
    let inv_det = 1.0 / det;
    let s = origin - a;
    let u = dot(s, p) * inv_det;
    if u < 0.0 || u > 1.0 {
        return -1.0;
    }
    let q = cross(s, e1);
    let v = dot(d, q) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return -1.0;
    }
    return dot(e2, q) * inv_det;
}

fn segment_hits_box(origin: vec3<f32>, inv: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> bool {
    let t0 = (lo - origin) * inv;
    let t1 = (hi - origin) * inv;
    let tmin = min(t0, t1);
    let tmax = max(t0, t1);
    let near = max(max(max(tmin.x, tmin.y), tmin.z), 0.0);
    let far = min(min(min(tmax.x, tmax.y), tmax.z), 1.0);
    return near <= far;
}

// A shadow ray's outcome after at most `budget` loop iterations: `complete` is false when the
// budget ran out first (then `hit` means nothing and the ray must be cast again).
struct Traversal {
    hit: bool,
    complete: bool,
    steps: u32,
}

// Stackless: nodes are depth-first, a leaf is followed by `index + 1` and an inner node's
// `first` is its miss link (see `twin::bvh::BvhNode`). One flat loop over nodes and leaf
// triangles, with no early exit from nested loops, of at most `budget` iterations (see
// `EXACT_LOOP_BUDGET` in `exact.wgsl`).
fn occluded(origin: vec3<f32>, target_position: vec3<f32>, budget: u32) -> Traversal {
    let d = target_position - origin;
    let inv = 1.0 / d;
    let n = arrayLength(&bvh_nodes);
    var index = 0u;
    var k = 0u;
    var end = 0u;
    var hit = false;
    var steps = 0u;
    while !hit && (k < end || index < n) && steps < budget {
        steps += 1u;
        if k < end {
            let t = 3u * bvh_triangles[k];
            let a = vertices[indices[t]].position;
            let b = vertices[indices[t + 1u]].position;
            let c = vertices[indices[t + 2u]].position;
            let s = ray_triangle(origin, d, a, b, c);
            hit = s > 0.0 && s < 1.0;
            k += 1u;
        } else {
            let node = bvh_nodes[index];
            let enter = segment_hits_box(origin, inv, node.min, node.max);
            if enter && node.count > 0u {
                k = node.first;
                end = node.first + node.count;
            }
            // The max() makes termination independent of the data (a zero-filled node).
            index = select(max(node.first, index + 1u), index + 1u, enter || node.count > 0u);
        }
    }
    return Traversal(hit, hit || !(k < end || index < n), steps);
}
