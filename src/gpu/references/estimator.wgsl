// The importance-sampled estimator of the exact reference (docs/design.md §5): per pixel,
// SAMPLES of the VALs drawn in proportion to the luminance of their unoccluded contribution,
// one shadow ray each through the BVH (`bvh.wgsl`), each visible draw weighted by 1 / its
// probability: an unbiased estimate of the exact sum at a small part of its cost.
//
// The draws are systematic: with `total` the sum of every VAL's unoccluded luminance (the
// brute force's image, which the pass before this one left in `indirect`) and `step` =
// total / SAMPLES, the draws are the VALs whose interval of the running sum holds one of the
// thresholds (m + xi) step, m = 0 .. SAMPLES - 1, xi one uniform number per pixel
// (`pixel_offset`). Each VAL is drawn on average SAMPLES lum_i / total times, as with
// independent draws, but the draws cover the distribution evenly. A VAL holding n thresholds
// adds n step / lum_i times its radiance where its shadow ray is free. The walk stops at the
// last threshold. Rust twin: `twin::exact_cpu` with `ValSampling::Systematic`.
//
// Two flat loops per invocation and round: the walk (at most WALK_BUDGET VALs, noting the
// VALs that hold thresholds, SAMPLES at most), then the picks' shadow rays (at most
// TRACE_BUDGET BVH steps). Both budgets together stay under llvmpipe's loop limit, which it
// counts per SIMD vector over every loop of the invocation: a lane runs each loop at most its
// budget, so a vector does too, and the walk, with no traversal inside it, runs as plain SIMD
// over the VALs. In rounds as the exact pass: `progress` is 0 before the first round, then
// 1 + the next VAL to walk; `walk` keeps the pixel's total, running sum and thresholds passed,
// `indirect` its sum so far. A ray cut off by the budget sends the walk back to its VAL.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> indirect: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> vals: array<Val>;
@group(0) @binding(3) var<storage, read> val_count: u32;
// Bindings 4 and 5: `bvh.wgsl`; 6 and 7 (`progress`, `status`): `shader/rounds.wgsl`.
// Per pixel: (total, running sum before the next VAL, thresholds passed, unused).
@group(0) @binding(8) var<storage, read_write> walk: array<vec4<f32>>;

// `twin::exact_cpu::pixel_offset`: the pixel's xi in [0, 1), 24 bits.
fn pixel_offset(pixel: u32) -> f32 {
    return unit_float(pcg_hash(pixel ^ pcg_hash(SEED)));
}

// Thresholds (m + xi) step, m < SAMPLES, below `sum`.
fn thresholds_below(sum: f32, step: f32, xi: f32) -> u32 {
    return u32(clamp(ceil(sum / step - xi), 0.0, f32(SAMPLES)));
}

fn estimate(id: vec2<u32>, glossy: bool) {
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
    var state = walk[pixel];
    var l = indirect[pixel].xyz;
    if start == 0u {
        state = vec4<f32>(luminance(l), 0.0, 0.0, 0.0);
        l = vec3<f32>(0.0);
    }
    let total = state.x;
    if !(total > 0.0) {
        indirect[pixel] = vec4<f32>(0.0, 0.0, 0.0, 1.0);
        progress[pixel] = ROUND_DONE;
        return;
    }
    let s = facing_viewer(surface_at(hit.triangle, hit.barycentrics), frame.eye);
    let w_o = view_direction(s.position, s.normal, frame.eye);
    let spec = s.material.specular * phong_normalisation(s.material.exponent);
    let origin = s.position + s.geometric * RAY_OFFSET;
    let step = total / f32(SAMPLES);
    let xi = pixel_offset(pixel);
    let count = min(val_count, arrayLength(&vals));

    var j = select(start - 1u, 0u, start == 0u);
    var sum = state.y;
    var passed = u32(state.z);
    // The walk: VALs from j until every threshold is passed, every VAL walked or half the
    // round's budget used, each VAL holding thresholds noted with its draws and the running
    // sum before it.
    var picks: array<u32, SAMPLES>;
    var draws_of: array<u32, SAMPLES>;
    var sum_before: array<f32, SAMPLES>;
    var n = 0u;
    var steps = 0u;
    while j < count && passed < SAMPLES && steps < WALK_BUDGET {
        steps += 1u;
        let val = vals[j];
        let geo = val_geometry_sided(s.position, s.normal, s.geometric, val.position, val.normal, val.area);
        let f = geo.weight * geo.cos_receiver;
        var lum = 0.0;
        if f > 0.0 {
            lum = luminance(reflected_radiance(s, spec, w_o, geo.direction, val.flux * f, glossy));
        }
        let after = sum + lum;
        let draws = thresholds_below(after, step, xi) - passed;
        if draws > 0u && lum > 0.0 {
            picks[n] = j;
            draws_of[n] = draws;
            sum_before[n] = sum;
            n += 1u;
        }
        sum = after;
        passed = thresholds_below(sum, step, xi);
        j += 1u;
    }
    // The shadow rays of the picks, in order: one flat loop of BVH steps in the rest of the
    // budget. A ray cut off by it sends the walk back to its VAL for the next round.
    var p = 0u;
    var ray = RayWalk(0u, 0u, 0u, false);
    var d = vec3<f32>(0.0);
    var inv = vec3<f32>(0.0);
    var add = vec3<f32>(0.0);
    var started = false;
    steps = 0u;
    while p < n && steps < TRACE_BUDGET {
        steps += 1u;
        if !started {
            let val = vals[picks[p]];
            let geo = val_geometry_sided(s.position, s.normal, s.geometric, val.position, val.normal, val.area);
            let radiance = reflected_radiance(s, spec, w_o, geo.direction, val.flux * (geo.weight * geo.cos_receiver), glossy);
            add = radiance * (f32(draws_of[p]) * step / luminance(radiance));
            d = val.position + val.normal * RAY_OFFSET - origin;
            inv = 1.0 / d;
            ray = RayWalk(0u, 0u, 0u, false);
            started = true;
        } else {
            ray_step(origin, d, inv, &ray);
        }
        if started && ray_done(ray) {
            if !ray.hit {
                l += add;
            }
            started = false;
            p += 1u;
        }
    }
    if p < n {
        // Cut off at pick p: its VAL is walked again next round.
        j = picks[p];
        sum = sum_before[p];
        passed = thresholds_below(sum, step, xi);
    }
    indirect[pixel] = vec4<f32>(l, 1.0);
    walk[pixel] = vec4<f32>(total, sum, f32(passed), 0.0);
    // Done once every threshold is passed or every VAL walked (and every pick traced).
    let next = select(j + 1u, count + 1u, p >= n && (passed >= SAMPLES || j >= count));
    end_round(pixel, next, count + 1u, start != 0u && next == start);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    estimate(id.xy, false);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    estimate(id.xy, true);
}
