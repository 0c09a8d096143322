// Direct light from the scene's `lights` (docs/measurements/many-lights.md), after the clusters
// module's header, `paraboloid.wgsl`, `raster_depth.wgsl` (binding 2) and `cluster_visibility.wgsl`
// (binding 1 `clusters`), whose lookups it reuses: the lights come sorted by group, and every group (one light in the
// `per_light` mode, a LightCluster group of paper 003 otherwise) has two paraboloid maps at its
// centre, `clusters[2g]` looking along +AXIS and `clusters[2g + 1]` along -AXIS. Per pixel, each
// group's visibility is looked up once (one texel in the `per_light` mode, PCSS with the
// group's extent as the light's radius otherwise) and multiplies the sum of its lights' direct
// radiance, each with its own position and intensity (paper 003 §3.2.1). Writes, or with
// ADD_TO_DIRECT adds to, `direct`. Rust twin: `twin::many_lights::direct_shadow_mapped`.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(3) var<storage, read_write> direct: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> lights: array<ManyLight>;
// Per group: (first light, light count) in `lights`.
@group(0) @binding(5) var<storage, read> group_lights: array<vec2<u32>>;

struct ManyLight {
    position: vec3<f32>,
    // Range (m) of the falloff's window; 0: none.
    range: f32,
    direction: vec3<f32>,
    inner_angle: f32,
    intensity: vec3<f32>,
    outer_angle: f32,
}

// `twin::many_lights::light_radiance`: a point light is a spot of half-angle pi.
fn light_radiance(p: vec3<f32>, n: vec3<f32>, material: Material, eye: vec3<f32>, light: ManyLight) -> vec3<f32> {
    let w = range_window(distance(p, light.position), light.range);
    if w == 0.0 {
        return vec3<f32>(0.0);
    }
    let spot = Spot(light.position, light.direction, light.inner_angle, light.outer_angle, light.intensity);
    return direct_radiance(p, n, material, eye, spot) * w;
}

// One texel's test: `cluster_visibility` with SOFT_HARD, without its SHADOW_TAPS² repeats.
fn hard_visibility(k: u32, c: Cluster, offset: vec3<f32>, normal: vec3<f32>) -> f32 {
    let zr = length(offset);
    if c.count == 0.0 || zr <= 0.0 {
        return 1.0;
    }
    let v = offset / zr;
    if dot(v, c.normal) <= 0.0 || dot(normal, v) >= 0.0 {
        return 1.0;
    }
    let centre = disc_texel(paraboloid_project(v, c.normal));
    return select(1.0, 0.0, blocker_at(k, c, offset, normal, vec2<i32>(floor(centre))) >= 0.0);
}

// `twin::many_lights::group_visibility`.
fn light_group_visibility(g: u32, p: vec3<f32>, n: vec3<f32>) -> f32 {
    let offset = p - clusters[2u * g].position;
    let k = select(2u * g + 1u, 2u * g, dot(offset, AXIS) >= 0.0);
    let c = clusters[k];
    if SOFT_SHADOWS == SOFT_HARD {
        return hard_visibility(k, c, offset, n);
    }
    return cluster_visibility(k, c, offset, n);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn shade_lights(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let pixel = id.y * frame.width + id.x;
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id.xy), 0));
    if !hit.covered {
        if !ADD_TO_DIRECT {
            direct[pixel] = vec4<f32>(0.0);
        }
        return;
    }
    // Each light's cosine is the shading normal's; a light below the geometric surface is
    // rejected, and the maps are looked up at the geometric normal (docs/design.md §3, shading
    // and geometric normals), as the spot light's direct pass does.
    let s = facing_viewer(surface_at(hit.triangle, hit.barycentrics), frame.eye);
    var l = vec3<f32>(0.0);
    for (var g = 0u; g < GROUP_COUNT; g++) {
        let range = group_lights[g];
        var lg = vec3<f32>(0.0);
        for (var i = range.x; i < range.x + range.y; i++) {
            let above = above_surface(s.geometric, lights[i].position - s.position);
            lg += light_radiance(s.position, s.normal, s.material, frame.eye, lights[i]) * above;
        }
        if max(lg.x, max(lg.y, lg.z)) > 0.0 {
            l += lg * light_group_visibility(g, s.position, s.geometric);
        }
    }
    if ADD_TO_DIRECT {
        l += direct[pixel].xyz;
    }
    direct[pixel] = vec4<f32>(l, 1.0);
}
