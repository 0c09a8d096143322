// Per (sparse point, cluster): the fraction of the cluster's light reaching the point through
// its shadow map, with percentage-closer soft shadows (paper 001): blocker search, penumbra
// from the cluster's radius and the mean blocker distance (paper 000 Fig. 3), PCF over a
// SHADOW_TAPS² grid. Receiver-plane depths: each tap compares the map's distance with the
// distance along the tap's own ray to the receiver's tangent plane, so a planar receiver never
// shadows itself. Writes `group_visibility[point * CLUSTER_COUNT + k]`. Rust twin:
// `twin::cluster_visibility` (same names). The pass's entry point and its own bindings are in
// `cluster_visibility_main.wgsl`; the lookup alone also serves `gpu/lights/many_lights.wgsl`.

// The maps are binding LOOKUP_MAPS_BINDING, read by `map_depth(k, texel)`: the rasterised
// atlas (`raster_depth.wgsl`) or the imperfect shadow maps (`../ism/ism_lookup.wgsl`),
// prepended. The bindings are 1 and 2 (`clusters::lookup_bindings`) but in the brute force
// through the clusters' maps, whose own bindings come first.

@group(0) @binding(LOOKUP_CLUSTERS_BINDING) var<storage, read> clusters: array<Cluster>;

fn receiver_plane_depth(offset: vec3<f32>, normal: vec3<f32>, v: vec3<f32>) -> f32 {
    let den = dot(v, normal);
    let num = dot(offset, normal);
    if den < -1e-4 && num < 0.0 {
        return num / den;
    }
    return NOTHING;
}

// Cluster c's map frame (`paraboloid.wgsl`); with FOCUS_BOUNDS the meshes' bounding sphere
// follows the clusters (`clusters/mod.rs`, written every frame).
fn frame_of(c: Cluster) -> MapFrame {
    if FOCUS_BOUNDS == 0u {
        return hemisphere_frame(c.normal);
    }
    return cluster_map_frame(c, clusters[CLUSTER_COUNT]);
}

// The blocker's distance at `texel`, or -1 when it holds none.
fn blocker_at(k: u32, c: Cluster, offset: vec3<f32>, normal: vec3<f32>, texel: vec2<i32>) -> f32 {
    let z = map_depth(k, texel);
    if z >= NOTHING {
        return -1.0;
    }
    let f = frame_of(c);
    let v = map_direction(texel_disc(texel), f);
    let zr = min(receiver_plane_depth(offset, normal, v), length(offset) * 4.0);
    // The relative bias is of the depth beyond the map's near distance (`MapFrame`: a cluster a
    // kilometre away, an environment's VALs, sees a small object within centimetres of depth,
    // which 2 % of the whole distance would leave unshadowed), the slope bias of the whole
    // distance, as its texel angles are; `+ near * bias` adds exactly 0 for a hemisphere map.
    let kept = 1.0 - SHADOW_RELATIVE_BIAS - slope_bias(v, f, normal) * depth_spread(z);
    if z < zr * kept + f.near * SHADOW_RELATIVE_BIAS {
        return z;
    }
    return -1.0;
}

// Texels a stored depth stands for: 2^level for an imperfect map's depth made at that pull-push
// level (its lowest 3 bits, `../ism/ism.wgsl`); only multiplies the slope bias, which is 0
// for the rasterised maps.
fn depth_spread(z: f32) -> f32 {
    return f32(1u << (bitcast<u32>(z) & 7u));
}

// Slope-scaled bias for maps whose depths were not taken along each texel's centre ray (the
// imperfect shadow maps' splatted points lie anywhere in their texel): across
// SLOPE_BIAS_TEXELS texels the receiver's plane moves by that many texel angles times the
// tangent of the ray's incidence on it, relative to its distance. 0 for the rasterised maps.
fn slope_bias(v: vec3<f32>, f: MapFrame, receiver_normal: vec3<f32>) -> f32 {
    if SLOPE_BIAS_TEXELS == 0.0 {
        return 0.0;
    }
    let cos_i = clamp(-dot(v, receiver_normal), 1e-3, 1.0);
    let tan_i = min(sqrt(1.0 - cos_i * cos_i) / cos_i, MAX_SLOPE);
    return SLOPE_BIAS_TEXELS * tan_i / map_texels_per_radian(v, f);
}

fn tap(centre: vec2<f32>, radius: f32, i: u32) -> vec2<i32> {
    let s = vec2<f32>(f32(i % SHADOW_TAPS), f32(i / SHADOW_TAPS)) / f32(SHADOW_TAPS - 1u) * 2.0 - 1.0;
    return vec2<i32>(floor(centre + s * radius));
}

// Mean distance of the blockers among the taps, or -1 when there are none.
fn blocker_search(k: u32, c: Cluster, offset: vec3<f32>, normal: vec3<f32>, centre: vec2<f32>, radius: f32) -> f32 {
    var sum = 0.0;
    var n = 0u;
    for (var i = 0u; i < SHADOW_TAPS * SHADOW_TAPS; i++) {
        let z = blocker_at(k, c, offset, normal, tap(centre, radius, i));
        if z >= 0.0 {
            sum += z;
            n += 1u;
        }
    }
    if n == 0u {
        return -1.0;
    }
    return sum / f32(n);
}

fn pcf(k: u32, c: Cluster, offset: vec3<f32>, normal: vec3<f32>, centre: vec2<f32>, radius: f32) -> f32 {
    var blocked = 0u;
    for (var i = 0u; i < SHADOW_TAPS * SHADOW_TAPS; i++) {
        if blocker_at(k, c, offset, normal, tap(centre, radius, i)) >= 0.0 {
            blocked += 1u;
        }
    }
    return 1.0 - f32(blocked) / f32(SHADOW_TAPS * SHADOW_TAPS);
}

fn penumbra_angle(radius: f32, z_blocker: f32, z_receiver: f32) -> f32 {
    return radius * max(z_receiver - z_blocker, 0.0) / (z_blocker * z_receiver);
}

fn texels_per_radian(cos_theta: f32) -> f32 {
    return f32(MAP_RESOLUTION) * 0.5 / (1.0 + cos_theta);
}

// Texels per radian of map frame `f` in direction `v`.
fn map_texels_per_radian(v: vec3<f32>, f: MapFrame) -> f32 {
    return texels_per_radian(dot(v, f.axis)) / f.scale;
}

fn cluster_visibility(k: u32, c: Cluster, offset: vec3<f32>, normal: vec3<f32>) -> f32 {
    let zr = length(offset);
    if c.count == 0.0 || zr <= 0.0 {
        return 1.0;
    }
    let v = offset / zr;
    let cos_theta = dot(v, c.normal);
    if cos_theta <= 0.0 || dot(normal, v) >= 0.0 {
        return 1.0;
    }
    let f = frame_of(c);
    let centre = disc_texel(map_project(v, f));
    let per_radian = map_texels_per_radian(v, f);
    let max_texels = MAX_SHADOW_FILTER_ANGLE * per_radian;
    if SOFT_SHADOWS == SOFT_HARD {
        return pcf(k, c, offset, normal, centre, 0.0);
    }
    if SOFT_SHADOWS == SOFT_PCF {
        return pcf(k, c, offset, normal, centre, PCF_RADIUS_TEXELS);
    }
    let near = max(c.radius * CLUSTER_NEAR_FRACTION, 1e-4 * zr);
    let search = min(penumbra_angle(c.radius, near, zr) * per_radian, max_texels);
    let zb = blocker_search(k, c, offset, normal, centre, search);
    if zb < 0.0 {
        return 1.0;
    }
    let w = min(penumbra_angle(c.radius, zb, zr) * per_radian, max_texels);
    return pcf(k, c, offset, normal, centre, w);
}
