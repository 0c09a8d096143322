// Direct light (docs/design.md §4 step 6): the spot light through the Phong BRDF, shadowed by the
// RSM's distance-to-light map. Rust twin (without the shadow test): `twin::rsm::direct_radiance`
// times `twin::above_surface`.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> direct: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> light_distance: array<f32>;

// 1 where the RSM texel that `p` projects to sees no nearer surface, else 0.
fn lit(p: vec3<f32>, n: vec3<f32>) -> f32 {
    let clip = frame.light_world_to_clip * vec4<f32>(p, 1.0);
    if clip.w <= 0.0 {
        return 0.0;
    }
    let ndc = clip.xy / clip.w;
    let r = f32(frame.rsm_resolution);
    let texel = vec2<i32>(floor(vec2<f32>((ndc.x * 0.5 + 0.5) * r, (0.5 - ndc.y * 0.5) * r)));
    if any(texel < vec2<i32>(0)) || any(texel >= vec2<i32>(i32(frame.rsm_resolution))) {
        return 0.0;
    }
    let d = distance(p, frame.light_position);
    let to_light = (frame.light_position - p) / max(d, MIN_LIGHT_DISTANCE);
    // Bias: SHADOW_BIAS_TEXELS texel footprints, stretched at grazing incidence.
    let footprint = d * 2.0 * tan(frame.light_outer_angle) / r;
    let bias = SHADOW_BIAS_TEXELS * footprint / max(abs(dot(n, to_light)), 0.2);
    return select(0.0, 1.0, d <= light_distance[u32(texel.y) * frame.rsm_resolution + u32(texel.x)] + bias);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let pixel = id.y * frame.width + id.x;
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id.xy), 0));
    if !hit.covered {
        direct[pixel] = vec4<f32>(0.0);
        return;
    }
    // The light's cosine is the shading normal's; light from below the geometric surface is
    // rejected, and the shadow bias follows the geometric surface (docs/design.md §3, shading
    // and geometric normals).
    let s = facing_viewer(surface_at(hit.triangle, hit.barycentrics), frame.eye);
    let above = above_surface(s.geometric, frame.light_position - s.position);
    let l = direct_radiance(s.position, s.normal, s.material, frame.eye, frame_spot(frame)) * (above * lit(s.position, s.geometric));
    direct[pixel] = vec4<f32>(l, 1.0);
}
