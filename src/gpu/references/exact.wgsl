// Exact-visibility reference (docs/design.md §5): the brute force of `brute_force.wgsl` with a
// shadow ray per pixel and VAL through the BVH (`bvh.wgsl`), from the pixel pushed along its
// geometric normal (docs/design.md §3, shading and geometric normals). Every VAL_STRIDE-th VAL is used,
// its flux scaled by VAL_STRIDE: an unbiased subsample, since the VAL list is in no spatial
// order. Unlike the brute force it does not tile VALs through workgroup memory (an earlier tiled
// version lost writes on lavapipe; the culprit was probably the traversal's nested loops, since
// replaced by the flat loop of `bvh.wgsl`, or the loop limit below, but the tiled version has
// not been measured again).
//
// Resumable, in rounds: llvmpipe (lavapipe) ends every loop of an invocation once all its loops
// together have run 65535 iterations (LP_MAX_TGSI_LOOP_ITERATIONS, "shared between every loop
// in a shader"), silently: a pixel whose shadow rays needed more kept only the VALs before that
// point. So an invocation runs at most EXACT_LOOP_BUDGET iterations (VAL loop and traversal
// together), leaves its sum in `indirect` and the next VAL in `progress`, and counts itself in
// `status[0]`; the host dispatches again until no pixel is left (`gpu::references::exact`). A ray cut off
// by the budget is cast again from the start in the next round; `status[1]` counts pixels that
// made no progress at all in a round (one ray longer than the budget), which the host reports.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> indirect: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> vals: array<Val>;
@group(0) @binding(3) var<storage, read> val_count: u32;
// Bindings 6 and 7 (`progress`: per pixel, the next (subsampled) VAL to cast toward):
// `shader/rounds.wgsl`.

fn exact(id: vec2<u32>, glossy: bool) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let pixel = id.y * frame.width + id.x;
    let start = progress[pixel];
    if start == ROUND_DONE {
        return;
    }
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id), 0));
    if !hit.covered {
        indirect[pixel] = vec4<f32>(0.0);
        progress[pixel] = ROUND_DONE;
        return;
    }
    let s = facing_viewer(surface_at(hit.triangle, hit.barycentrics), frame.eye);
    let w_o = view_direction(s.position, s.normal, frame.eye);
    let spec = s.material.specular * phong_normalisation(s.material.exponent);
    let origin = s.position + s.geometric * RAY_OFFSET;
    var l = vec3<f32>(0.0);
    if start > 0u {
        l = indirect[pixel].xyz;
    }
    let count = min(val_count, arrayLength(&vals)) / VAL_STRIDE;
    var j = start;
    var steps = 0u;
    while j < count && steps < EXACT_LOOP_BUDGET {
        steps += 1u;
        let val = vals[j * VAL_STRIDE];
        let geo = val_geometry_sided(s.position, s.normal, s.geometric, val.position, val.normal, val.area);
        let f = geo.weight * geo.cos_receiver;
        if f > 0.0 {
            let ray = occluded(origin, val.position + val.normal * RAY_OFFSET, EXACT_LOOP_BUDGET - steps);
            steps += ray.steps;
            if !ray.complete {
                break;
            }
            if !ray.hit {
                l += reflected_radiance(s, spec, w_o, geo.direction, val.flux * (f * f32(VAL_STRIDE)), glossy);
            }
        }
        j += 1u;
    }
    indirect[pixel] = vec4<f32>(l, 1.0);
    end_round(pixel, j, count, j == start);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    exact(id.xy, false);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    exact(id.xy, true);
}
