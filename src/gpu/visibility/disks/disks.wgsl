// Disc-occluder visibility (DESIGN.md §4 step 3, paper §3.3): every other sparse point is a
// disc that may hide part of the sphere standing for the light a sparse point gathered; the
// gathered irradiance (and glossy irradiance) is scaled by the visible fraction before
// renormalisation. A disc occludes only when its plane separates the point from the sphere's
// centre (`separates`). Sparse points stream through workgroup memory in tiles. Rust twins in
// `disks/twin.rs`. OCCLUSION_PRODUCT selects the combination rule.

@group(0) @binding(0) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(1) var<storage, read_write> gathered_diffuse: array<Gathered>;
@group(0) @binding(2) var<storage, read_write> gathered_glossy: array<Gathered>;

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

@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let visible = visibility(id.x, local);
    if id.x < frame.sparse_count {
        gathered_diffuse[id.x].irradiance *= visible;
    }
}

@compute @workgroup_size(WORKGROUP_X)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let visible = visibility(id.x, local);
    if id.x < frame.sparse_count {
        gathered_diffuse[id.x].irradiance *= visible;
        gathered_glossy[id.x].irradiance *= visible;
    }
}

// 1 - occlusion of sparse point `index`'s light sphere (uniform control flow for barriers).
fn visibility(index: u32, local: u32) -> f32 {
    let count = frame.sparse_count;
    var p = SparsePoint(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0);
    var g = Gathered(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if index < count {
        p = sparse_points[index];
        g = gathered_diffuse[index];
    }
    let sphere = light_sphere(g.position, g.second_moment);
    let t = any_perpendicular(p.normal);
    let b = cross(p.normal, t);
    let s = project(p.position, p.normal, t, b, sphere.centre, 1.0, PI * sphere.radius * sphere.radius);
    let occludable = index < count && s.visible && s.side > 0.0;
    var sum = 0.0;
    var product = 1.0;
    for (var base = 0u; base < count; base += TILE_SIZE) {
        if base + local < count {
            occluders[local] = sparse_points[base + local];
        }
        workgroupBarrier();
        let n = min(TILE_SIZE, count - base);
        if occludable {
            for (var j = 0u; j < n; j++) {
                if base + j == index {
                    continue;
                }
                let d = occluders[j];
                if !separates(p.position, sphere.centre, d.position, d.normal) {
                    continue;
                }
                let to_disc = d.position - p.position;
                let len2 = dot(to_disc, to_disc);
                var cos_disc = 1.0;
                if len2 > COINCIDENT_DISTANCE_SQ {
                    cos_disc = dot(d.normal, to_disc * inverseSqrt(len2));
                }
                let o = project(p.position, p.normal, t, b, d.position, cos_disc, PI * d.occluder_radius * d.occluder_radius);
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
