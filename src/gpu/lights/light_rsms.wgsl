// The lights' RSMs to VALs (docs/design.md §2, docs/measurements/many-lights.md): one invocation per
// texel of every view (the views' texels numbered one after the other, `first_texel`); a texel
// that sees a surface becomes a Lambertian disc VAL re-emitting the diffuse part of the flux
// its light sends into the texel's solid angle: a candidate in the texel's slot, which
// `compact` (`compact_vals.wgsl`) appends in the texels' order. Texels with no flux are not
// appended. Rust twin: `twin::light_rsms::view_texel_val`.

@group(0) @binding(0) var atlas: texture_2d<u32>;
@group(0) @binding(1) var<storage, read> rsm_views: array<RsmView>;
@group(0) @binding(2) var<storage, read_write> vals: array<Val>;
@group(0) @binding(3) var<storage, read_write> val_count: atomic<u32>;
// One candidate per texel of every view, in the flat numbering (area -1: none).
@group(0) @binding(4) var<storage, read_write> candidates: array<Val>;

// `twin::light_rsms::view_texel_solid_angle`: (solid angle in sr, cosine off the axis).
fn view_texel_solid_angle(ndc: vec2<f32>, view: RsmView) -> vec2<f32> {
    let side = 2.0 * view.tan_half / f32(view.resolution);
    let q = ndc * view.tan_half;
    let cos_theta = inverseSqrt(1.0 + dot(q, q));
    return vec2<f32>(view.omega_scale * side * side * cos_theta * cos_theta * cos_theta, cos_theta);
}

// `twin::light_rsms::view_texel_val`.
fn view_texel_val(ndc: vec2<f32>, view: RsmView, y: vec3<f32>, n_y: vec3<f32>, rho_d: vec3<f32>) -> Val {
    let sa = view_texel_solid_angle(ndc, view);
    let falloff = spot_falloff(sa.y, view.inner_angle, view.outer_angle);
    let to_light = view.position - y;
    let window = range_window(length(to_light), view.range);
    var normal = n_y;
    if dot(n_y, to_light) < 0.0 {
        normal = -n_y;
    }
    return Val(y, dot(to_light, to_light) * sa.x, normal, 0.0, rho_d * view.intensity * (falloff * window * sa.x), 0.0);
}

// The view holding flat texel `i`: the last whose `first_texel` is at most `i`.
fn view_of_texel(i: u32) -> u32 {
    var lo = 0u;
    var hi = arrayLength(&rsm_views);
    while hi - lo > 1u {
        let mid = (lo + hi) / 2u;
        if rsm_views[mid].first_texel <= i {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y, WORKGROUP_Z)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let k = view_of_texel(i);
    let view = rsm_views[k];
    let r = view.resolution;
    let local = i - view.first_texel;
    if local >= r * r {
        return;
    }
    let texel = vec2<u32>(local % r, local / r);
    let hit = decode_visibility(textureLoad(atlas, vec2<i32>(view.origin + texel), 0));
    var val = Val(vec3<f32>(0.0), -1.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if hit.covered {
        let s = surface_at(hit.triangle, hit.barycentrics);
        let lit = view_texel_val(rsm_texel_ndc(texel.x, texel.y, r), view, s.position, s.normal, s.material.diffuse);
        if max(lit.flux.x, max(lit.flux.y, lit.flux.z)) > 0.0 {
            val = lit;
        }
    }
    candidates[i] = val;
}
