// The rasterised shadow maps as the visibility pass reads them: one depth atlas, distances
// beyond the map's near distance stored as t / (t + DEPTH_SCALE) (`shadow_maps.wgsl`,
// `encode_map_depth`); after `cluster_visibility.wgsl`'s `clusters` and `frame_of`. Bound as an unfilterable float texture,
// not `texture_depth_2d`, whose `textureLoad` does not translate to GLSL (the GL backend).

@group(0) @binding(LOOKUP_MAPS_BINDING) var shadow_atlas: texture_2d<f32>;

// Distance (m) in cluster k's map at `texel`; NOTHING outside the map or where nothing was drawn.
fn map_depth(k: u32, texel: vec2<i32>) -> f32 {
    let r = i32(MAP_RESOLUTION);
    if texel.x < 0 || texel.y < 0 || texel.x >= r || texel.y >= r {
        return NOTHING;
    }
    let beyond = decode_map_depth(textureLoad(shadow_atlas, vec2<i32>(atlas_origin(k)) + texel, 0).x);
    return beyond + frame_of(clusters[k]).near;
}

// The distance (m) of a stored depth; NOTHING for 1 (nothing drawn). Rust twin:
// `twin::decode_map_depth`.
fn decode_map_depth(d: f32) -> f32 {
    if d >= 1.0 {
        return NOTHING;
    }
    return DEPTH_SCALE * d / (1.0 - d);
}
