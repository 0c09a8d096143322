// Exact visibility (DESIGN.md §5): segment queries against the scene's triangles through the
// BVH built on the CPU (`reference::bvh`, whose `occluded` and `ray_triangle` are the twins).

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

fn occluded(origin: vec3<f32>, target_position: vec3<f32>) -> bool {
    let d = target_position - origin;
    let inv = 1.0 / d;
    var stack: array<u32, BVH_MAX_DEPTH>;
    var top = 1u;
    stack[0] = 0u;
    var hit = false;
    while top > 0u && !hit {
        top -= 1u;
        let index = stack[top];
        let node = bvh_nodes[index];
        if segment_hits_box(origin, inv, node.min, node.max) {
            if node.count > 0u {
                for (var k = node.first; k < node.first + node.count; k++) {
                    let t = 3u * bvh_triangles[k];
                    let a = vertices[indices[t]].position;
                    let b = vertices[indices[t + 1u]].position;
                    let c = vertices[indices[t + 2u]].position;
                    let s = ray_triangle(origin, d, a, b, c);
                    hit = hit || (s > 0.0 && s < 1.0);
                }
            } else if top + 2u <= BVH_MAX_DEPTH {
                stack[top] = index + 1u;
                stack[top + 1u] = node.first;
                top += 2u;
            }
        }
    }
    return hit;
}
