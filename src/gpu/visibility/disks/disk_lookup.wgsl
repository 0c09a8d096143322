// The disc occluders' visibility of a light sphere (docs/design.md §4 step 3, paper §3.3), shared
// by the sparse points' `occlusion` pass (`disks.wgsl`) and the second bounce's
// `bounce2_occlusion` (`gpu/lights/bounce_occlusion.wgsl`): every sparse point is a disc that
// may hide part of the sphere standing for the light a receiver gathered. A disc occludes only
// when its plane separates the receiver from the sphere's centre (`separates`). Sparse points
// stream through workgroup memory in tiles (the includer binds `sparse_points`).
// OCCLUSION_PRODUCT selects the combination rule. Rust twin: `disks/twin.rs`.

var<workgroup> occluders: array<SparsePoint, TILE_SIZE>;

struct LightSphere {
    centre: vec3<f32>,
    radius: f32,
}

struct Projected {
    centre: vec2<f32>,
    side: f32,
    distance: f32,
    visible: bool,
}

fn light_sphere(mean: vec3<f32>, second: vec3<f32>) -> LightSphere {
    let variance = max(second - mean * mean, vec3<f32>(0.0));
    return LightSphere(mean, sqrt(max(variance.x, max(variance.y, variance.z))));
}

fn project(x: vec3<f32>, n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, centre: vec3<f32>, cos_shape: f32, area: f32) -> Projected {
    let v = centre - x;
    let d2 = dot(v, v);
    if d2 <= COINCIDENT_DISTANCE_SQ {
        return Projected(vec2<f32>(0.0), 0.0, 0.0, false);
    }
    let d = sqrt(d2);
    let u = v / d;
    let cos_x = dot(n, u);
    if cos_x <= 0.0 {
        return Projected(vec2<f32>(0.0), 0.0, 0.0, false);
    }
    let form_factor = cos_x * abs(cos_shape) * area / (PI * d2 + area);
    return Projected(vec2<f32>(dot(u, t), dot(u, b)), sqrt(PI * form_factor), d, true);
}

// Whether the disc's plane strictly separates x from the light's centre c.
fn separates(x: vec3<f32>, c: vec3<f32>, disc_position: vec3<f32>, disc_normal: vec3<f32>) -> bool {
    return dot(disc_normal, x - disc_position) * dot(disc_normal, c - disc_position) < 0.0;
}

fn depth_scale(d: f32, d_s: f32, r: f32) -> f32 {
    if d >= d_s {
        return 0.0;
    }
    if d <= d_s - r || r <= 0.0 {
        return 1.0;
    }
    return (d_s - d) / r;
}

fn square_overlap(a: Projected, b: Projected) -> f32 {
    let lo = max(a.centre - vec2<f32>(a.side * 0.5), b.centre - vec2<f32>(b.side * 0.5));
    let hi = min(a.centre + vec2<f32>(a.side * 0.5), b.centre + vec2<f32>(b.side * 0.5));
    let o = max(hi - lo, vec2<f32>(0.0));
    return o.x * o.y;
}

// 1 - occlusion of the light sphere of a receiver at `x` with normal `n` whose VALs' weighted
// first and second position moments are `mean` and `second`, by every sparse point but the
// `skip`-th (the receiver itself when it is one). `has_receiver`: whether this invocation has a
// receiver (uniform control flow for the barriers: every invocation walks the tiles).
fn disc_visibility(x: vec3<f32>, n: vec3<f32>, mean: vec3<f32>, second: vec3<f32>, skip: u32, has_receiver: bool, local: u32) -> f32 {
    let count = frame.sparse_count;
    let sphere = light_sphere(mean, second);
    let t = any_perpendicular(n);
    let b = cross(n, t);
    let s = project(x, n, t, b, sphere.centre, 1.0, PI * sphere.radius * sphere.radius);
    let occludable = has_receiver && s.visible && s.side > 0.0;
    var sum = 0.0;
    var product = 1.0;
    for (var base = 0u; base < count; base += TILE_SIZE) {
        if base + local < count {
            occluders[local] = sparse_points[base + local];
        }
        workgroupBarrier();
        let in_tile = min(TILE_SIZE, count - base);
        if occludable {
            for (var j = 0u; j < in_tile; j++) {
                if base + j == skip {
                    continue;
                }
                let d = occluders[j];
                if !separates(x, sphere.centre, d.position, d.normal) {
                    continue;
                }
                let to_disc = d.position - x;
                let len2 = dot(to_disc, to_disc);
                var cos_disc = 1.0;
                if len2 > COINCIDENT_DISTANCE_SQ {
                    cos_disc = dot(d.normal, to_disc * inverseSqrt(len2));
                }
                let o = project(x, n, t, b, d.position, cos_disc, PI * d.occluder_radius * d.occluder_radius);
                if o.visible {
                    let occ = min(square_overlap(s, o) / (s.side * s.side), 1.0) * depth_scale(o.distance, s.distance, sphere.radius);
                    sum += occ;
                    product *= 1.0 - occ;
                }
            }
        }
        workgroupBarrier();
    }
    if !occludable {
        return 1.0;
    }
    if OCCLUSION_PRODUCT {
        return product;
    }
    return 1.0 - clamp(sum, 0.0, 1.0);
}
