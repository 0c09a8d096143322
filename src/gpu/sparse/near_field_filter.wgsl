// The interleaved near field's filter (`near_field.wgsl`): each covered pixel averages the
// terms of the rest of the near share (past the close share, which the shade added itself)
// that `near_field_shade.wgsl` left in `near_light` over the window of its block (2 side/2 + 1
// pixels a side, the two end rows and columns at half weight, so that every subset weighs 1)
// among the pixels on its own surface (by the geometric normals: the facet's plane), then adds
// them, through its material, to `indirect`.
// Where the whole window lies on the pixel's surface, every subset counts once: the whole near
// field. A pixel whose window holds under half the subsets on its surface (corners, image
// edges) is left to the shade's redo entries, which add the rest of every near VAL's share
// (`redone`, `near_field_window.wgsl`).
// Rust twin: `twin::near_field::filter`, then `twin::near_field::NearTerms::radiance`.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> indirect: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> near_light: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> near_surface: array<vec4<f32>>;

fn filter_pixel(id: vec2<u32>, glossy: bool) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let i = id.y * frame.width + id.x;
    if near_light[2u * i].w == 0.0 {
        return;
    }
    let window = window_at(id);
    if redone(window) {
        return;
    }
    let total = window.irradiance.w;
    let irradiance = window.irradiance.xyz;
    let lobe = window.lobe;
    // `total` holds the pixel's own weight, 1.
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id), 0));
    add_near_light(i, surface_at(hit.triangle, hit.barycentrics), irradiance / total, lobe / total, glossy);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    filter_pixel(id.xy, false);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    filter_pixel(id.xy, true);
}
