// The disc occluders' terms (docs/design.md §4 step 3, paper §3.3): the light sphere standing
// for what a receiver gathered, shapes projected onto the receiver's tangent plane as squares,
// and one disc's occlusion of the sphere (`disc_term`). Shared by the sparse points' `occlusion`
// pass (`disks.wgsl`) and the second bounce's disc lookup (`disk_lookup.wgsl`).
// OCCLUSION_PRODUCT selects the combination rule. Rust twin: `disks/twin.rs`.

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

// The occlusion of the light sphere `sphere` (projected as `s`) seen from `x` (normal `n`,
// tangent frame `t`, `b`) by the disc at `position` with `normal` and `radius`; 0 where the disc's
// plane does not separate `x` from the sphere's centre or the disc is behind `x`'s horizon.
fn disc_term(x: vec3<f32>, n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, sphere: LightSphere, s: Projected, position: vec3<f32>, normal: vec3<f32>, radius: f32) -> f32 {
    if !separates(x, sphere.centre, position, normal) {
        return 0.0;
    }
    let to_disc = position - x;
    let len2 = dot(to_disc, to_disc);
    var cos_disc = 1.0;
    if len2 > COINCIDENT_DISTANCE_SQ {
        cos_disc = dot(normal, to_disc * inverseSqrt(len2));
    }
    let o = project(x, n, t, b, position, cos_disc, PI * radius * radius);
    if !o.visible {
        return 0.0;
    }
    return min(square_overlap(s, o) / (s.side * s.side), 1.0) * depth_scale(o.distance, s.distance, sphere.radius);
}
