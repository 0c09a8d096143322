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

// The point invocation `index` takes: `inside` when there is one, and its surface; an invocation
// past the last point (which still takes part in its workgroup's barriers) gets a black
// placeholder at the origin facing +z.
struct BounceInvocation {
    inside: bool,
    surface: Surface,
}

fn bounce_invocation(index: u32) -> BounceInvocation {
    if index >= arrayLength(&bounce_points) {
        let up = vec3<f32>(0.0, 0.0, 1.0);
        return BounceInvocation(false, Surface(vec3<f32>(0.0), up, Material(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), -1), up));
    }
    return BounceInvocation(true, bounce_surface(index));
}
