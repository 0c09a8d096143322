// Per-pixel sparse shading (docs/design.md §4 step 5): the per-vertex point lights are interpolated
// across the visible triangle, bounded (`bound_light`) and applied with the pixel's own
// position, normal and material. With `glossy_interpolation: "radiance"`
// (`main_glossy_radiance`) the glossy lobe is the vertices' interpolated gathered sums through
// the pixel's specular albedo and normalisation instead. Rust twins: `twin::shade_sparse`,
// `twin::bound_light`, `twin::glossy_from_radiance`.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> indirect: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> vertex_diffuse: array<PointLight>;
@group(0) @binding(3) var<storage, read> vertex_glossy: array<PointLight>;
// Only with `glossy_interpolation: "radiance"`.
@group(0) @binding(4) var<storage, read> vertex_glossy_radiance: array<vec4<f32>>;

fn lerp_light(a: PointLight, b: PointLight, c: PointLight, bary: vec2<f32>) -> PointLight {
    let bound = dot(vec3<f32>(1.0 - bary.x - bary.y, bary.x, bary.y), vec3<f32>(a.bound, b.bound, c.bound));
    return PointLight(barycentric(bary, a.position, b.position, c.position), 0.0, barycentric(bary, a.intensity, b.intensity, c.intensity), bound);
}

// `light` scaled down so that the irradiance luminance it delivers at (`p`, `n`) is at most
// its bound (unchanged when the bound is 0).
fn bound_light(p: vec3<f32>, n: vec3<f32>, light: PointLight) -> PointLight {
    if light.bound <= 0.0 {
        return light;
    }
    let v = light.position - p;
    let d2 = max(dot(v, v), MIN_LIGHT_DISTANCE * MIN_LIGHT_DISTANCE);
    let e = luminance(light.intensity) * max(dot(n, v * inverseSqrt(d2)), 0.0) / d2;
    var out = light;
    if e > light.bound {
        out.intensity = light.intensity * (light.bound / e);
    }
    return out;
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
    return Pixel(index, hit.covered, facing_viewer(surface_at(hit.triangle, hit.barycentrics), frame.eye), vec3<u32>(indices[t], indices[t + 1u], indices[t + 2u]), hit.barycentrics);
}

fn diffuse_radiance(p: Pixel) -> vec3<f32> {
    let c = p.corners;
    let light = lerp_light(vertex_diffuse[c.x], vertex_diffuse[c.y], vertex_diffuse[c.z], p.barycentrics);
    let bounded = bound_light(p.surface.position, p.surface.normal, light);
    return point_light_radiance(p.surface.position, p.surface.normal, p.surface.material, frame.eye, bounded, false);
}

fn glossy_radiance(p: Pixel) -> vec3<f32> {
    let c = p.corners;
    let light = lerp_light(vertex_glossy[c.x], vertex_glossy[c.y], vertex_glossy[c.z], p.barycentrics);
    let bounded = bound_light(p.surface.position, p.surface.normal, light);
    return point_light_radiance(p.surface.position, p.surface.normal, p.surface.material, frame.eye, bounded, true);
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

// `twin::glossy_from_radiance` of the corners' interpolated glossy sums.
fn glossy_from_radiance(p: Pixel) -> vec3<f32> {
    let c = p.corners;
    let g = barycentric(p.barycentrics, vertex_glossy_radiance[c.x].xyz, vertex_glossy_radiance[c.y].xyz, vertex_glossy_radiance[c.z].xyz);
    return p.surface.material.specular * phong_normalisation(p.surface.material.exponent) * g;
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_glossy_radiance(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let p = pixel_at(id.xy);
    indirect[p.index] = select(vec4<f32>(0.0), vec4<f32>(diffuse_radiance(p) + glossy_from_radiance(p), 1.0), p.covered);
}
