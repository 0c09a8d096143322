// A point of the second bounce on the meshes: triangle, barycentrics of corners 1 and 2, and
// the area (m²) it stands for (`gpu/lights/bounce.rs`, `RawBouncePoint`).
struct BouncePoint {
    triangle: u32,
    u: f32,
    v: f32,
    area: f32,
}

// The surface at bounce point `index` (every pass that includes this file binds `bounce_points`).
fn bounce_surface(index: u32) -> Surface {
    let p = bounce_points[index];
    return surface_at(p.triangle, vec2<f32>(p.u, p.v));
}
