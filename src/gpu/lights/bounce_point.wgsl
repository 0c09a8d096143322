// A point of the second bounce on the meshes: triangle, barycentrics of corners 1 and 2, and
// the area (m²) it stands for (`gpu/lights/bounce.rs`, `RawBouncePoint`).
struct BouncePoint {
    triangle: u32,
    u: f32,
    v: f32,
    area: f32,
}
