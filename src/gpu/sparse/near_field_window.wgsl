// The interleaved near field's window over a pixel's block (`near_field.wgsl`), shared by the
// filter (`near_field_filter.wgsl`) and the shade's redo entries (`near_field_shade.wgsl`),
// which must agree on which pixels the filter leaves to the redo, and the light they add: the
// including file declares `near_light`, `near_surface` (two per pixel each:
// `near_field_shade.wgsl`) and `indirect`.

// `twin::near_field::FILTER_NORMAL_COS`, `FILTER_PLANE`, `FILTER_DISTANCE`, `FILTER_REDO_BELOW`.
const FILTER_NORMAL_COS: f32 = 0.9;
const FILTER_PLANE: f32 = 0.1;
const FILTER_DISTANCE: f32 = 0.25;
const FILTER_REDO_BELOW: f32 = 0.5;

// `twin::near_field::NearTerms::radiance` at `s`, added to pixel `i` of `indirect` (which the
// including file declares too).
fn add_near_light(i: u32, s: Surface, irradiance: vec3<f32>, lobe: vec3<f32>, glossy: bool) {
    var l = s.material.diffuse / PI * irradiance;
    if glossy {
        l += s.material.specular * phong_normalisation(s.material.exponent) * lobe;
    }
    let before = indirect[i];
    indirect[i] = vec4<f32>(before.rgb + l, before.a);
}

// `twin::near_field::window_weight`.
fn window_weight(o: i32, half: i32) -> f32 {
    return select(1.0, 0.5, half > 0 && abs(o) == half);
}

// `twin::near_field::filter_weight`: 1 where neighbour `j` lies on the surface of the pixel at
// `p` with normal `n`, else 0 (and 0 where `j` is not covered).
fn filter_weight(p: vec3<f32>, n: vec3<f32>, j: u32) -> f32 {
    if near_light[2u * j].w == 0.0 {
        return 0.0;
    }
    let d = near_surface[2u * j].xyz - p;
    let same = dot(n, near_surface[2u * j + 1u].xyz) >= FILTER_NORMAL_COS
        && abs(dot(n, d)) <= FILTER_PLANE * length(d)
        && dot(d, d) <= (FILTER_DISTANCE * NEAR_FIELD_RADIUS) * (FILTER_DISTANCE * NEAR_FIELD_RADIUS);
    return select(0.0, 1.0, same);
}

// The weighted sums of pixel `id`'s window (`twin::near_field::filter`): irradiance, lobe, and in
// `w` of the first the window's weight.
struct Window {
    irradiance: vec4<f32>,
    lobe: vec3<f32>,
}

fn window_at(id: vec2<u32>) -> Window {
    let i = id.y * frame.width + id.x;
    let p = near_surface[2u * i].xyz;
    let n = near_surface[2u * i + 1u].xyz;
    let half = i32(NEAR_FIELD_SIDE / 2u);
    var irradiance = vec3<f32>(0.0);
    var lobe = vec3<f32>(0.0);
    var total = 0.0;
    for (var dy = -half; dy <= half; dy++) {
        for (var dx = -half; dx <= half; dx++) {
            let q = vec2<i32>(id) + vec2<i32>(dx, dy);
            if q.x < 0 || q.y < 0 || q.x >= i32(frame.width) || q.y >= i32(frame.height) {
                continue;
            }
            let j = u32(q.y) * frame.width + u32(q.x);
            let w = window_weight(dx, half) * window_weight(dy, half) * filter_weight(p, n, j);
            if w > 0.0 {
                irradiance += w * near_light[2u * j].xyz;
                lobe += w * near_light[2u * j + 1u].xyz;
                total += w;
            }
        }
    }
    return Window(vec4<f32>(irradiance, total), lobe);
}

// Whether the filter leaves covered pixel `id` to the redo: its window holds under
// FILTER_REDO_BELOW of the block's subsets on its surface.
fn redone(window: Window) -> bool {
    return window.irradiance.w < FILTER_REDO_BELOW * f32(NEAR_FIELD_SUBSETS);
}
