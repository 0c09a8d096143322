// The imperfect shadow maps as the visibility pass (`../clusters/cluster_visibility.wgsl`)
// reads them, after `ism.wgsl`: the finest level after pull-push.

@group(0) @binding(LOOKUP_MAPS_BINDING) var<storage, read> ism_atlas: array<u32>;

// Distance (m) in map k at `texel`; NOTHING outside the map or where it is empty.
fn map_depth(k: u32, texel: vec2<i32>) -> f32 {
    let r = i32(MAP_RESOLUTION);
    if texel.x < 0 || texel.y < 0 || texel.x >= r || texel.y >= r {
        return NOTHING;
    }
    return decode_depth(ism_atlas[map_texel_index(k, MAP_RESOLUTION, u32(texel.x), u32(texel.y))]);
}
