// Differential rendering onto real surfaces (Debevec 1998, Knecht et al. 2010): for
// each receiver (a real surface point near the virtual content, from the depth frame), the
// irradiance the virtual content changes. Over `vals[0 .. real_count]` (the real VALs) it sums
// the irradiance of every VAL (`unoccluded`, no visibility: the real light the depth frame's
// surfaces are assumed to receive) and of the VALs a virtual triangle hides (`blocked`, one
// shadow ray each through the BVH of `bvh.wgsl`, which holds the virtual meshes only); over
// `vals[real_count ..]` (the virtual content's own sparse points re-emitting what they gathered)
// the irradiance that reaches the receiver unblocked (`added`). Twin:
// `gpu::differential::twin::receiver_light`.
//
// Resumable in rounds, as `exact.wgsl` and for the same reason (llvmpipe ends all the loops of an
// invocation after 65535 iterations in total, silently): an invocation runs at most
// DIFFERENTIAL_LOOP_BUDGET iterations, keeps its sums in `light` and the next VAL in `progress`,
// and counts itself in `status[0]`; the host dispatches again until no receiver is left.

struct DifferentialParams {
    receiver_count: u32,
    real_count: u32,
    val_count: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<storage, read> params: DifferentialParams;
// Bindings 1 to 3 and the `Receiver` and `ReceiverLight` structs: `receivers.wgsl`; 6 and 7
// (`progress`: per receiver, the next VAL): `shader/rounds.wgsl`.

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y, WORKGROUP_Z)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.receiver_count {
        return;
    }
    let start = progress[i];
    if start == ROUND_DONE {
        return;
    }
    var sums = ReceiverLight(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    if start > 0u {
        sums = light[i];
    }
    let r = receivers[i];
    let origin = r.position + r.normal * RAY_OFFSET;
    let count = min(params.val_count, arrayLength(&vals));
    var j = start;
    var steps = 0u;
    while j < count && steps < DIFFERENTIAL_LOOP_BUDGET {
        steps += 1u;
        let val = vals[j];
        let f = val_form_factor(r.position, r.normal, val.position, val.normal, val.area);
        let e = val.flux * f;
        if f > 0.0 {
            let ray = occluded(origin, val.position + val.normal * RAY_OFFSET, DIFFERENTIAL_LOOP_BUDGET - steps);
            steps += ray.steps;
            if !ray.complete {
                break;
            }
            if j < params.real_count {
                sums.unoccluded += vec4<f32>(e, 0.0);
                if ray.hit {
                    sums.blocked += vec4<f32>(e, 0.0);
                }
            } else if !ray.hit {
                sums.added += vec4<f32>(e, 0.0);
            }
        }
        j += 1u;
    }
    light[i] = sums;
    end_round(i, j, count, j == start);
}
