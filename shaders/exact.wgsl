// Exact-visibility reference (DESIGN.md §5): the brute force of `brute_force.wgsl` with a
// shadow ray per pixel and VAL through the BVH (`bvh.wgsl`). Every VAL_STRIDE-th VAL is used,
// its flux scaled by VAL_STRIDE: an unbiased subsample, since the VAL list is in no spatial
// order. Unlike the brute force it does not tile VALs through workgroup memory (an earlier tiled
// version lost writes on lavapipe; the culprit was probably the traversal's nested loops, since
// replaced by the flat loop of `bvh.wgsl`, but the tiled version has not been measured again).

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> indirect: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> vals: array<Val>;
@group(0) @binding(3) var<storage, read> val_count: u32;

fn exact(id: vec2<u32>, glossy: bool) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let pixel = id.y * frame.width + id.x;
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id), 0));
    if !hit.covered {
        indirect[pixel] = vec4<f32>(0.0);
        return;
    }
    let s = surface_at(hit.triangle, hit.barycentrics);
    let w_o = view_direction(s.position, s.normal, frame.eye);
    let spec = s.material.specular * phong_normalisation(s.material.exponent);
    let origin = s.position + s.normal * RAY_OFFSET;
    var l = vec3<f32>(0.0);
    let count = min(val_count, arrayLength(&vals)) / VAL_STRIDE;
    for (var j = 0u; j < count; j++) {
        let val = vals[j * VAL_STRIDE];
        let geo = val_geometry(s.position, s.normal, val.position, val.normal, val.area);
        let f = geo.weight * geo.cos_receiver;
        if f > 0.0 && !occluded(origin, val.position + val.normal * RAY_OFFSET) {
            let e = val.flux * (f * f32(VAL_STRIDE));
            l += s.material.diffuse / PI * e;
            if glossy {
                l += spec * phong_lobe(dot(mirror(geo.direction, s.normal), w_o), s.material.exponent) * e;
            }
        }
    }
    indirect[pixel] = vec4<f32>(l, 1.0);
}

@compute @workgroup_size(EXACT_WORKGROUP_SIDE, EXACT_WORKGROUP_SIDE)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    exact(id.xy, false);
}

@compute @workgroup_size(EXACT_WORKGROUP_SIDE, EXACT_WORKGROUP_SIDE)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    exact(id.xy, true);
}
