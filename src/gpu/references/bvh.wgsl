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

// A shadow ray's place in the traversal: the next node, the leaf's triangles left (`k` to
// `end`), and whether a triangle blocked it.
struct RayWalk {
    index: u32,
    k: u32,
    end: u32,
    hit: bool,
}

// Stackless: nodes are depth-first, a leaf is followed by `index + 1` and an inner node's
// `first` is its miss link (see `twin::bvh::BvhNode`). One step: a triangle of the current
// leaf, else one node. `d` is the segment from `origin` to the target, `inv` its inverse.
fn ray_step(origin: vec3<f32>, d: vec3<f32>, inv: vec3<f32>, w: ptr<function, RayWalk>) {
    if (*w).k < (*w).end {
        let t = 3u * bvh_triangles[(*w).k];
        let a = vertices[indices[t]].position;
        let b = vertices[indices[t + 1u]].position;
        let c = vertices[indices[t + 2u]].position;
        let s = ray_triangle(origin, d, a, b, c);
        (*w).hit = s > 0.0 && s < 1.0;
        (*w).k += 1u;
    } else {
        let node = bvh_nodes[(*w).index];
        let enter = segment_hits_box(origin, inv, node.min, node.max);
        if enter && node.count > 0u {
            (*w).k = node.first;
            (*w).end = node.first + node.count;
        }
        // The max() makes termination independent of the data (a zero-filled node).
        (*w).index = select(max(node.first, (*w).index + 1u), (*w).index + 1u, enter || node.count > 0u);
    }
}

// Whether the ray is decided: blocked, or past the last node and triangle.
fn ray_done(w: RayWalk) -> bool {
    return w.hit || !(w.k < w.end || w.index < arrayLength(&bvh_nodes));
}

// The segment query: one flat loop of `ray_step`s, with no early exit from nested loops, of at
// most `budget` iterations (see `EXACT_LOOP_BUDGET` in `exact.wgsl`).
fn occluded(origin: vec3<f32>, target_position: vec3<f32>, budget: u32) -> Traversal {
    let d = target_position - origin;
    let inv = 1.0 / d;
    var w = RayWalk(0u, 0u, 0u, false);
    var steps = 0u;
    while !ray_done(w) && steps < budget {
        steps += 1u;
        ray_step(origin, d, inv, &w);
    }
    return Traversal(w.hit, ray_done(w), steps);
}
