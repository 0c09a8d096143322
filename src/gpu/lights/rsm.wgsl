// RSM to VALs (docs/design.md §2): every texel of the light's visibility buffer that sees a surface
// becomes a Lambertian disc VAL re-emitting the diffuse part of the flux it receives, a
// candidate in the texel's slot that `compact` (`compact_vals.wgsl`) appends in the texels'
// order. Texels with no flux are not appended. Also writes each texel's distance to the light:
// the shadow map of the direct pass.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> vals: array<Val>;
@group(0) @binding(2) var<storage, read_write> val_count: atomic<u32>;
@group(0) @binding(3) var<storage, read_write> light_distance: array<f32>;
// One candidate per texel, row-major (area -1: none).
@group(0) @binding(4) var<storage, read_write> candidates: array<Val>;

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let r = frame.rsm_resolution;
    if id.x >= r || id.y >= r {
        return;
    }
    let texel = id.y * r + id.x;
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id.xy), 0));
    var val = Val(vec3<f32>(0.0), -1.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if hit.covered {
        let s = surface_at(hit.triangle, hit.barycentrics);
        light_distance[texel] = distance(s.position, frame.light_position);
        let lit = rsm_texel_val(rsm_texel_ndc(id.x, id.y, r), r, frame_spot(frame), s.position, s.normal, s.material.diffuse);
        if max(lit.flux.x, max(lit.flux.y, lit.flux.z)) > 0.0 {
            val = lit;
        }
    } else {
        light_distance[texel] = NO_SURFACE_DISTANCE;
    }
    candidates[texel] = val;
}
