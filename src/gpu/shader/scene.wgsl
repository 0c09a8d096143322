// The scene bind group (group 1), shared by every pass: per-frame constants and the world-space
// geometry, pulled by index (no vertex buffers). See `src/gpu/scene.rs`.

@group(1) @binding(0) var<uniform> frame: Frame;
@group(1) @binding(1) var<storage, read> vertices: array<Vertex>;
@group(1) @binding(2) var<storage, read> indices: array<u32>;
@group(1) @binding(3) var<storage, read> triangle_materials: array<u32>;
@group(1) @binding(4) var<storage, read> materials: array<Material>;

// Interpolated surface of `triangle` at barycentrics `b` (of corners 1 and 2), with its
// triangle's face normal on the shading normal's side.
fn surface_at(triangle: u32, b: vec2<f32>) -> Surface {
    let v0 = vertices[indices[3u * triangle]];
    let v1 = vertices[indices[3u * triangle + 1u]];
    let v2 = vertices[indices[3u * triangle + 2u]];
    let position = barycentric(b, v0.position, v1.position, v2.position);
    let n = barycentric(b, v0.normal, v1.normal, v2.normal);
    let len2 = dot(n, n);
    let face = normalize(cross(v1.position - v0.position, v2.position - v0.position));
    var normal = face;
    if len2 > 1e-20 {
        normal = n * inverseSqrt(len2);
    }
    var material = materials[triangle_materials[triangle]];
    let st = barycentric(b, vec3<f32>(v0.s, v0.t, 0.0), vec3<f32>(v1.s, v1.t, 0.0), vec3<f32>(v2.s, v2.t, 0.0)).xy;
    material.diffuse = diffuse_albedo(material, st);
    return Surface(position, normal, material, oriented_face_normal(face, normal));
}

// A texel of a visibility buffer: triangle + 1 (0 = nothing), then the barycentrics' bits.
struct Hit {
    covered: bool,
    triangle: u32,
    barycentrics: vec2<f32>,
}

fn decode_visibility(texel: vec4<u32>) -> Hit {
    return Hit(texel.x != 0u, max(texel.x, 1u) - 1u, vec2<f32>(bitcast<f32>(texel.y), bitcast<f32>(texel.z)));
}
