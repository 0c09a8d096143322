// The second bounce, step 2 (paper 004 §4.1: "importance sampling is then applied ... to
// generate the second bounce VPLs"): SECOND_BOUNCE_VALS candidates drawn by flux luminance,
// stratified (`visibility/ism/flux_draw.wgsl`, prepended, over the candidates as its `vals`),
// each appended to the frame's VALs with its flux divided by its probability,
// `flux * total / (count * luminance)`, so that the drawn VALs' flux adds up to the
// candidates' (exactly so for grey flux) and the estimate stays unbiased. Its disc area is
// the patch one point stands for (SECOND_BOUNCE_AREA, m²; `twin::bounce::drawn_area` says
// why). VAL k lands at the frame's
// count before the draw plus k (`bounce_count` then adds them), so the order is the twin's.
// Rust twin: `twin::bounce::draw_vals`.

@group(0) @binding(3) var<storage, read_write> all_vals: array<Val>;
@group(0) @binding(4) var<storage, read_write> all_val_count: atomic<u32>;

// One invocation per drawn VAL. Without lit candidates the VALs are dark (zero flux).
@compute @workgroup_size(WORKGROUP_X)
fn bounce_sample(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= SECOND_BOUNCE_VALS {
        return;
    }
    let index = atomicLoad(&all_val_count) + k;
    if index >= arrayLength(&all_vals) {
        return;
    }
    let pick = flux_pick(k, SECOND_BOUNCE_VALS);
    if pick == 0xffffffffu {
        all_vals[index] = Val(vec3<f32>(0.0), SECOND_BOUNCE_AREA, vec3<f32>(0.0, 0.0, 1.0), 0.0, vec3<f32>(0.0), 0.0);
        return;
    }
    let c = vals[pick];
    let scale = flux_total() / (f32(SECOND_BOUNCE_VALS) * val_weight(c));
    all_vals[index] = Val(c.position, SECOND_BOUNCE_AREA, c.normal, 0.0, c.flux * scale, 0.0);
}

// One invocation, after `bounce_sample`: the frame's VALs now include the drawn ones.
@compute @workgroup_size(WORKGROUP_X)
fn bounce_count(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x == 0u {
        atomicAdd(&all_val_count, SECOND_BOUNCE_VALS);
    }
}
