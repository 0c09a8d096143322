// The interleaved near field's filter (`near_field.wgsl`): each covered pixel averages the
// terms `near_field_shade.wgsl` left in `near_light` over the window of its block (2 side/2 + 1
// pixels a side, the two end rows and columns at half weight, so that every subset weighs 1)
// among the pixels on its own surface, then adds them, through its material, to `indirect`.
// Where the whole window lies on the pixel's surface, every subset counts once: the whole near
// field. With NEAR_FIELD_SIDE 1 the window is the pixel.
// Rust twin: `twin::near_field::filter`, then `twin::near_field::NearTerms::radiance`.

@group(0) @binding(0) var visibility: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> indirect: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> near_light: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> near_surface: array<vec4<f32>>;

// `twin::near_field::FILTER_NORMAL_COS`, `FILTER_PLANE`, `FILTER_DISTANCE`.
const FILTER_NORMAL_COS: f32 = 0.9;
const FILTER_PLANE: f32 = 0.1;
const FILTER_DISTANCE: f32 = 0.25;

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

fn filter_pixel(id: vec2<u32>, glossy: bool) {
    if id.x >= frame.width || id.y >= frame.height {
        return;
    }
    let i = id.y * frame.width + id.x;
    if near_light[2u * i].w == 0.0 {
        return;
    }
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
    // `total` holds the pixel's own weight, 1.
    let hit = decode_visibility(textureLoad(visibility, vec2<i32>(id), 0));
    let s = surface_at(hit.triangle, hit.barycentrics);
    var l = s.material.diffuse / PI * (irradiance / total);
    if glossy {
        l += s.material.specular * phong_normalisation(s.material.exponent) * (lobe / total);
    }
    let before = indirect[i];
    indirect[i] = vec4<f32>(before.rgb + l, before.a);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    filter_pixel(id.xy, false);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    filter_pixel(id.xy, true);
}
