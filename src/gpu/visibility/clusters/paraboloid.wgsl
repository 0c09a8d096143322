// One cluster of VALs and the paraboloid projection of its shadow map around its normal
// (paper 000 §4.2): the front hemisphere fills the unit disc. Shared by the clustering, the
// shadow-map raster and the visibility pass; the constants (`clusters/mod.rs`) come first.
// Rust twin: `twin.rs` (same names).

// No depth: outside a map, or nothing drawn there.
const NOTHING: f32 = 3.0e38;

struct Cluster {
    // Mean position of its lit VALs (m).
    position: vec3<f32>,
    // Lit VALs assigned to it (0: empty).
    count: f32,
    normal: vec3<f32>,
    // Radius of the disc light standing for it (m).
    radius: f32,
}

fn paraboloid_project(v: vec3<f32>, normal: vec3<f32>) -> vec2<f32> {
    let t = any_perpendicular(normal);
    let b = cross(normal, t);
    return vec2<f32>(dot(v, t), dot(v, b)) / max(1.0 + dot(v, normal), 1e-6);
}

fn paraboloid_direction(q: vec2<f32>, normal: vec3<f32>) -> vec3<f32> {
    let t = any_perpendicular(normal);
    let b = cross(normal, t);
    let r2 = dot(q, q);
    let vn = (1.0 - r2) / (1.0 + r2);
    let s = 1.0 + vn;
    return normalize(t * q.x * s + b * q.y * s + normal * vn);
}

// A map's frame: its axis, and the disc's scale, tan of half the widest angle from the axis it
// holds (1: the hemisphere, the paraboloid of paper 000); and `near`, the distance before which
// it holds nothing (0 for the hemisphere; for a map focused on the meshes' bounding sphere, the
// distance to that sphere): the shadow test's relative bias is taken of the depth beyond it.
struct MapFrame {
    axis: vec3<f32>,
    scale: f32,
    near: f32,
}

// The hemisphere around `normal` (Rust twin: `MapFrame::hemisphere`).
fn hemisphere_frame(normal: vec3<f32>) -> MapFrame {
    return MapFrame(normal, 1.0, 0.0);
}

// The frame of cluster `c`'s map: the hemisphere around its normal; or with FOCUS_BOUNDS, when
// the centre lies outside the meshes' bounding sphere `bounds` (position and radius), the cone
// around the direction to the sphere that just holds it, so the map's texels all go to the
// meshes (a room's VALs metres from a small virtual object). Rust twin: `twin::map_frame`.
fn cluster_map_frame(c: Cluster, bounds: Cluster) -> MapFrame {
    let d = bounds.position - c.position;
    let distance = length(d);
    let r = bounds.radius * FOCUS_MARGIN;
    if FOCUS_BOUNDS == 0u || !(distance > r) {
        return hemisphere_frame(c.normal);
    }
    let s = r / distance;
    return MapFrame(d / distance, s / (1.0 + sqrt(max(1.0 - s * s, 0.0))), distance - r);
}

// `paraboloid_project` around the frame's axis, scaled to its disc.
fn map_project(v: vec3<f32>, f: MapFrame) -> vec2<f32> {
    return paraboloid_project(v, f.axis) / f.scale;
}

// Inverse of `map_project`.
fn map_direction(q: vec2<f32>, f: MapFrame) -> vec3<f32> {
    return paraboloid_direction(q * f.scale, f.axis);
}

fn texel_disc(texel: vec2<i32>) -> vec2<f32> {
    let r = f32(MAP_RESOLUTION);
    return vec2<f32>((f32(texel.x) + 0.5) / r * 2.0 - 1.0, 1.0 - (f32(texel.y) + 0.5) / r * 2.0);
}

fn disc_texel(q: vec2<f32>) -> vec2<f32> {
    let r = f32(MAP_RESOLUTION);
    return vec2<f32>((q.x + 1.0) * 0.5 * r, (1.0 - q.y) * 0.5 * r);
}

// Top-left texel of cluster `k`'s map in the atlas.
fn atlas_origin(k: u32) -> vec2<u32> {
    return vec2<u32>(k % ATLAS_COLUMNS, k / ATLAS_COLUMNS) * MAP_RESOLUTION;
}
