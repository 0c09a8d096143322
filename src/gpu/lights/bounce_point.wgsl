// A point of the second bounce on the meshes: triangle, barycentrics of corners 1 and 2, and
// the area (m²) it stands for (`gpu/lights/bounce.rs`, `RawBouncePoint`).
struct BouncePoint {
    triangle: u32,
    u: f32,
    v: f32,
    area: f32,
}

// Binding 0 of every pass that includes this file.
@group(0) @binding(0) var<storage, read> bounce_points: array<BouncePoint>;

// The surface at bounce point `index`.
fn bounce_surface(index: u32) -> Surface {
    let p = bounce_points[index];
    return surface_at(p.triangle, vec2<f32>(p.u, p.v));
}

// `bounce_surface`, or for an invocation past the last point (which still takes part in its
// workgroup's barriers) a black placeholder at the origin facing +z.
fn bounce_surface_or_placeholder(index: u32) -> Surface {
    if index >= arrayLength(&bounce_points) {
        let up = vec3<f32>(0.0, 0.0, 1.0);
        return Surface(vec3<f32>(0.0), up, Material(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), -1), up);
    }
    return bounce_surface(index);
}
