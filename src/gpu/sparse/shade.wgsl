// Per-pixel sparse shading (DESIGN.md §4 step 5): the per-vertex point lights are interpolated
// across the visible triangle and applied with the pixel's own position, normal and material.
// Rust twin: `twin::shade_sparse`.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> indirect: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> vertex_diffuse: array<PointLight>;
@group(0) @binding(3) var<storage, read> vertex_glossy: array<PointLight>;

fn lerp_light(a: PointLight, b: PointLight, c: PointLight, bary: vec2<f32>) -> PointLight {
    return PointLight(barycentric(bary, a.position, b.position, c.position), 0.0, barycentric(bary, a.intensity, b.intensity, c.intensity), 0.0);
}

// The visible surface at a pixel and where on its triangle.
struct Pixel {
    index: u32,
    covered: bool,
    surface: Surface,
    corners: vec3<u32>,
    barycentrics: vec2<f32>,
}

fn pixel_at(id: vec2<u32>) -> Pixel {
    let index = id.y * frame.width + id.x;
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id), 0));
    let t = 3u * hit.triangle;
    return Pixel(index, hit.covered, surface_at(hit.triangle, hit.barycentrics), vec3<u32>(indices[t], indices[t + 1u], indices[t + 2u]), hit.barycentrics);
}

fn diffuse_radiance(p: Pixel) -> vec3<f32> {
    let c = p.corners;
    let light = lerp_light(vertex_diffuse[c.x], vertex_diffuse[c.y], vertex_diffuse[c.z], p.barycentrics);
    return point_light_radiance(p.surface.position, p.surface.normal, p.surface.material, frame.eye, light, false);
}

fn glossy_radiance(p: Pixel) -> vec3<f32> {
    let c = p.corners;
    let light = lerp_light(vertex_glossy[c.x], vertex_glossy[c.y], vertex_glossy[c.z], p.barycentrics);
    return point_light_radiance(p.surface.position, p.surface.normal, p.surface.material, frame.eye, light, true);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let p = pixel_at(id.xy);
    indirect[p.index] = select(vec4<f32>(0.0), vec4<f32>(diffuse_radiance(p), 1.0), p.covered);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let p = pixel_at(id.xy);
    indirect[p.index] = select(vec4<f32>(0.0), vec4<f32>(diffuse_radiance(p) + glossy_radiance(p), 1.0), p.covered);
}
