// Shared types and the quantities of docs/design.md §2-§4. Every function that computes a quantity
// has a Rust twin of the same name and argument order in `src/twin/`.
// Constants (WORKGROUP_SIZE, TILE_SIZE, NEIGHBOURS, the numerical guards) are prepended by
// `src/gpu/shader.rs` from the Rust definitions, never written here.

const PI: f32 = 3.14159265358979;

// One virtual area light: a Lambertian disc (m, m², W).
struct Val {
    position: vec3<f32>,
    area: f32,
    normal: vec3<f32>,
    _pad0: f32,
    flux: vec3<f32>,
    _pad1: f32,
}

// `twin::near_field_weight`: the share of a VAL at distance `d` (m) from a receiver that the
// sparse method's near-field pass applies per pixel rather than through the sparse points: 1 up
// to NEAR_FIELD_INNER * `radius`, falling smoothly to 0 at `radius`; 0 everywhere when `radius`
// is 0 (the near field off, the paper's form).
fn near_field_weight(d: f32, radius: f32) -> f32 {
    if radius <= 0.0 {
        return 0.0;
    }
    let t = clamp((d - NEAR_FIELD_INNER * radius) / ((1.0 - NEAR_FIELD_INNER) * radius), 0.0, 1.0);
    return 1.0 - t * t * (3.0 - 2.0 * t);
}

// A mesh vertex in world space, with its texture coordinates (t from the top row).
struct Vertex {
    position: vec3<f32>,
    s: f32,
    normal: vec3<f32>,
    t: f32,
}

// Normalised modified Phong (docs/design.md §1).
// `diffuse_texture` is a layer of the scene's texture array, or -1; the albedo is
// `diffuse * texture` (linear).
struct Material {
    diffuse: vec3<f32>,
    exponent: f32,
    specular: vec3<f32>,
    diffuse_texture: i32,
}

// A sparse shading point in world space this frame.
struct SparsePoint {
    position: vec3<f32>,
    occluder_radius: f32,
    normal: vec3<f32>,
    exponent: f32,
    // Its triangle's face normal on the side of `normal`: shadow rays leave along it.
    geometric: vec3<f32>,
    pad: f32,
}

// Gather output for one lobe: summed irradiance (W/m²), averaged VAL position (m) and the
// same average of the squared position (m², per axis: the spread of the light, used by the
// occlusion pass's light sphere).
struct Gathered {
    irradiance: vec3<f32>,
    // The sum of the weights behind `position` (and `second_moment`): what a later VAL range
    // needs to merge its sums in (gpu::gather on CPU adapters).
    weight: f32,
    position: vec3<f32>,
    _pad1: f32,
    second_moment: vec3<f32>,
    _pad2: f32,
}

// A renormalised point light: position (m), intensity (W/sr), and the largest irradiance
// luminance (W/m²) it may deliver at a receiver, 0 for unbounded (`twin::bound_light`).
struct PointLight {
    position: vec3<f32>,
    _pad0: f32,
    intensity: vec3<f32>,
    bound: f32,
}

// Per-frame constants shared by every pass.
struct Frame {
    world_to_clip: mat4x4<f32>,
    light_world_to_clip: mat4x4<f32>,
    eye: vec3<f32>,
    width: u32,
    light_position: vec3<f32>,
    height: u32,
    light_direction: vec3<f32>,
    rsm_resolution: u32,
    light_intensity: vec3<f32>,
    light_inner_angle: f32,
    light_outer_angle: f32,
    sparse_count: u32,
    vertex_count: u32,
    triangle_count: u32,
}

struct ValGeometry {
    direction: vec3<f32>,
    cos_receiver: f32,
    weight: f32,
}

// A point of a surface: `normal` is the shading normal (the vertex normals interpolated),
// `geometric` its triangle's face normal turned to the shading normal's side (docs/design.md §3,
// shading and geometric normals).
struct Surface {
    position: vec3<f32>,
    normal: vec3<f32>,
    material: Material,
    geometric: vec3<f32>,
}

// `twin::pcg_hash`: the PCG hash of Jarzynski and Olano (2020).
fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// `twin::unit_float`: a hash's top 24 bits as a float in [0, 1).
fn unit_float(h: u32) -> f32 {
    return f32(h >> 8u) * (1.0 / 16777216.0);
}

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

// docs/design.md's reflect: 2 dot(n, w) n - w.
fn mirror(w: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return 2.0 * dot(n, w) * n - w;
}

fn phong_lobe(cos_r: f32, k: f32) -> f32 {
    if k <= 0.0 {
        return 1.0;
    }
    if cos_r <= 0.0 {
        return 0.0;
    }
    return exp2(k * log2(cos_r));
}

fn phong_normalisation(k: f32) -> f32 {
    return (k + 2.0) / (2.0 * PI);
}

// `twin::reflected_radiance`: what irradiance `e` arriving from unit `direction` reflects at `s`
// toward `w_o`, diffuse plus, when `glossy`, the Phong lobe. `spec` is the material's
// `specular * phong_normalisation(exponent)`, computed once per receiver by the caller.
fn reflected_radiance(s: Surface, spec: vec3<f32>, w_o: vec3<f32>, direction: vec3<f32>, e: vec3<f32>, glossy: bool) -> vec3<f32> {
    var l = s.material.diffuse / PI * e;
    if glossy {
        l += spec * phong_lobe(dot(mirror(direction, s.normal), w_o), s.material.exponent) * e;
    }
    return l;
}

fn val_geometry(x: vec3<f32>, n_x: vec3<f32>, val_position: vec3<f32>, val_normal: vec3<f32>, val_area: f32) -> ValGeometry {
    let v = val_position - x;
    let d2 = dot(v, v);
    if d2 <= COINCIDENT_DISTANCE_SQ {
        return ValGeometry(n_x, 0.0, 0.0);
    }
    let w = v * inverseSqrt(d2);
    let cos_receiver = max(dot(n_x, w), 0.0);
    let cos_val = max(-dot(val_normal, w), 0.0);
    return ValGeometry(w, cos_receiver, cos_val / (PI * d2 + max(val_area, 0.0)));
}

// `twin::val_form_factor`: `val_geometry`'s `weight * cos_receiver`, the two cosines' 1/d
// folded into the denominator (no square root, one division); 0 for a coincident pair, a VAL
// behind the receiver or facing away.
fn val_form_factor(x: vec3<f32>, n_x: vec3<f32>, val_position: vec3<f32>, val_normal: vec3<f32>, val_area: f32) -> f32 {
    let v = val_position - x;
    // The cosines times d.
    let receiver_d = dot(n_x, v);
    let val_d = -dot(val_normal, v);
    let d2 = dot(v, v);
    if receiver_d <= 0.0 || val_d <= 0.0 || d2 <= COINCIDENT_DISTANCE_SQ {
        return 0.0;
    }
    return receiver_d * val_d / (d2 * (PI * d2 + max(val_area, 0.0)));
}

// `twin::oriented_face_normal`: the unit face normal `face` turned to the side of the shading
// normal `shading` (the vertex normals decide which side is the front).
fn oriented_face_normal(face: vec3<f32>, shading: vec3<f32>) -> vec3<f32> {
    return select(face, -face, dot(face, shading) < 0.0);
}

// `twin::facing_viewer`: `s` as a viewer at `eye` sees it: a surface seen from behind its
// geometric normal is shaded as a surface of its own, both normals flipped (two-sided).
fn facing_viewer(s: Surface, eye: vec3<f32>) -> Surface {
    var out = s;
    if dot(s.geometric, eye - s.position) < 0.0 {
        out.normal = -s.normal;
        out.geometric = -s.geometric;
    }
    return out;
}

// `twin::above_surface`: 1 where unit direction `w` leaves the surface on its geometric normal's
// side, else 0: light from below the geometric surface would have to pass through it.
fn above_surface(n_g: vec3<f32>, w: vec3<f32>) -> f32 {
    return select(0.0, 1.0, dot(n_g, w) > 0.0);
}

// `twin::val_geometry_sided`: `val_geometry` at a receiver with shading normal `n_x` and
// geometric normal `n_g`: the cosine is the shading normal's, and 0 for a VAL below the
// geometric surface.
fn val_geometry_sided(x: vec3<f32>, n_x: vec3<f32>, n_g: vec3<f32>, val_position: vec3<f32>, val_normal: vec3<f32>, val_area: f32) -> ValGeometry {
    var geo = val_geometry(x, n_x, val_position, val_normal, val_area);
    geo.cos_receiver *= above_surface(n_g, geo.direction);
    return geo;
}

fn view_direction(x: vec3<f32>, n_x: vec3<f32>, eye: vec3<f32>) -> vec3<f32> {
    let v = eye - x;
    let d2 = dot(v, v);
    if d2 <= COINCIDENT_DISTANCE_SQ {
        return n_x;
    }
    return v * inverseSqrt(d2);
}

fn any_perpendicular(n: vec3<f32>) -> vec3<f32> {
    var a = vec3<f32>(0.0, 1.0, 0.0);
    if abs(n.x) < 0.9 {
        a = vec3<f32>(1.0, 0.0, 0.0);
    }
    return normalize(cross(n, a));
}

struct Direction {
    direction: vec3<f32>,
    distance: f32,
}

fn renormalise_direction(x: vec3<f32>, n: vec3<f32>, target_position: vec3<f32>) -> Direction {
    let v = target_position - x;
    let d = length(v);
    var w = n;
    if d * d > COINCIDENT_DISTANCE_SQ {
        w = v / d;
    }
    let c = dot(n, w);
    if c >= MIN_RENORMALISE_COSINE {
        return Direction(w, max(d, MIN_LIGHT_DISTANCE));
    }
    let tangent = w - c * n;
    let t2 = dot(tangent, tangent);
    var t = any_perpendicular(n);
    if t2 > 1e-12 {
        t = tangent * inverseSqrt(t2);
    }
    let s = sqrt(1.0 - MIN_RENORMALISE_COSINE * MIN_RENORMALISE_COSINE);
    return Direction(t * s + n * MIN_RENORMALISE_COSINE, max(d, MIN_LIGHT_DISTANCE));
}

// Irradiance `e` with the weight sum `w` of the weighted position sums `l` and `l2`, added to
// `before` (the earlier VAL ranges' result; zero for the first range): how a VAL range after
// the first merges into what the earlier ones gathered (`gather.wgsl`, `bounce_moments.wgsl`).
fn merge_gathered(before: Gathered, e: vec3<f32>, w: f32, l: vec3<f32>, l2: vec3<f32>) -> Gathered {
    let total = before.weight + w;
    let norm = max(total, GATHER_EPSILON);
    return Gathered(
        before.irradiance + e,
        total,
        (before.position * before.weight + l) / norm,
        0.0,
        (before.second_moment * before.weight + l2) / norm,
        0.0,
    );
}

fn renormalise_diffuse(x: vec3<f32>, n: vec3<f32>, e: vec3<f32>, averaged_position: vec3<f32>) -> PointLight {
    let r = renormalise_direction(x, n, averaged_position);
    let cos = dot(n, r.direction);
    return PointLight(x + r.direction * r.distance, 0.0, max(e * (r.distance * r.distance / cos), vec3<f32>(0.0)), max(luminance(e), 0.0));
}

fn renormalise_glossy(x: vec3<f32>, n: vec3<f32>, k: f32, eye: vec3<f32>, g: vec3<f32>, averaged_position: vec3<f32>) -> PointLight {
    let w_o = view_direction(x, n, eye);
    let r = renormalise_direction(x, n, averaged_position);
    var w = r.direction;
    var response = dot(n, w) * phong_lobe(dot(mirror(w, n), w_o), k);
    if response < MIN_GLOSSY_RESPONSE && dot(n, w_o) > 0.0 {
        let m = renormalise_direction(x, n, x + mirror(w_o, n));
        let m_response = dot(n, m.direction) * phong_lobe(dot(mirror(m.direction, n), w_o), k);
        if m_response > response {
            w = m.direction;
            response = m_response;
        }
    }
    var intensity = vec3<f32>(0.0);
    if dot(n, w_o) > 0.0 {
        intensity = g * (r.distance * r.distance / max(response, MIN_GLOSSY_RESPONSE));
    }
    return PointLight(x + w * r.distance, 0.0, max(intensity, vec3<f32>(0.0)), 0.0);
}

// Radiance toward `eye` from one point light through the diffuse (glossy = false) or the
// specular (glossy = true) lobe.
fn point_light_radiance(p: vec3<f32>, n: vec3<f32>, material: Material, eye: vec3<f32>, light: PointLight, glossy: bool) -> vec3<f32> {
    let v = light.position - p;
    let d2 = max(dot(v, v), MIN_LIGHT_DISTANCE * MIN_LIGHT_DISTANCE);
    let w = v * inverseSqrt(d2);
    let e = light.intensity * (max(dot(n, w), 0.0) / d2);
    if glossy {
        let w_o = view_direction(p, n, eye);
        return material.specular * phong_normalisation(material.exponent) * phong_lobe(dot(mirror(w, n), w_o), material.exponent) * e;
    }
    return material.diffuse / PI * e;
}

fn barycentric(b: vec2<f32>, a: vec3<f32>, bb: vec3<f32>, c: vec3<f32>) -> vec3<f32> {
    return a * (1.0 - b.x - b.y) + bb * b.x + c * b.y;
}

fn spot_falloff(cos_theta: f32, inner_angle: f32, outer_angle: f32) -> f32 {
    // atan2 rather than acos: lavapipe's acos is off by ~5e-4 rad near 1.
    let c = clamp(cos_theta, -1.0, 1.0);
    let theta = atan2(sqrt(max(1.0 - c * c, 0.0)), c);
    if outer_angle - inner_angle <= 1e-6 {
        return select(0.0, 1.0, theta <= outer_angle);
    }
    return clamp((outer_angle - theta) / (outer_angle - inner_angle), 0.0, 1.0);
}

struct Spot {
    position: vec3<f32>,
    direction: vec3<f32>,
    inner_angle: f32,
    outer_angle: f32,
    intensity: vec3<f32>,
}

fn frame_spot(f: Frame) -> Spot {
    return Spot(f.light_position, f.light_direction, f.light_inner_angle, f.light_outer_angle, f.light_intensity);
}

// `twin::many_lights::range_window`: a point light's window on the inverse-square falloff
// (range 0: none). Used by the many-light direct pass and the lights' RSMs.
fn range_window(d: f32, range: f32) -> f32 {
    if range <= 0.0 {
        return 1.0;
    }
    let x = d / range;
    let w = clamp(1.0 - x * x * x * x, 0.0, 1.0);
    return w * w;
}

fn rsm_texel_ndc(ix: u32, iy: u32, resolution: u32) -> vec2<f32> {
    let r = f32(resolution);
    return vec2<f32>((f32(ix) + 0.5) / r * 2.0 - 1.0, 1.0 - (f32(iy) + 0.5) / r * 2.0);
}

// (solid angle in sr, cosine off the axis) of the RSM texel centred at `ndc`.
fn rsm_texel_solid_angle(ndc: vec2<f32>, outer_angle: f32, resolution: u32) -> vec2<f32> {
    let t = tan(outer_angle);
    let side = 2.0 * t / f32(resolution);
    let q = ndc * t;
    let cos_theta = inverseSqrt(1.0 + dot(q, q));
    return vec2<f32>(side * side * cos_theta * cos_theta * cos_theta, cos_theta);
}

fn rsm_texel_val(ndc: vec2<f32>, resolution: u32, spot: Spot, y: vec3<f32>, n_y: vec3<f32>, rho_d: vec3<f32>) -> Val {
    let sa = rsm_texel_solid_angle(ndc, spot.outer_angle, resolution);
    let falloff = spot_falloff(sa.y, spot.inner_angle, spot.outer_angle);
    let to_light = spot.position - y;
    var normal = n_y;
    if dot(n_y, to_light) < 0.0 {
        normal = -n_y;
    }
    return Val(y, dot(to_light, to_light) * sa.x, normal, 0.0, rho_d * spot.intensity * (falloff * sa.x), 0.0);
}

fn spot_irradiance(p: vec3<f32>, n: vec3<f32>, spot: Spot) -> vec3<f32> {
    let v = spot.position - p;
    let d2 = max(dot(v, v), MIN_LIGHT_DISTANCE * MIN_LIGHT_DISTANCE);
    let w = v * inverseSqrt(d2);
    let falloff = spot_falloff(dot(-w, spot.direction), spot.inner_angle, spot.outer_angle);
    return spot.intensity * (falloff * max(dot(n, w), 0.0) / d2);
}

fn direct_radiance(p: vec3<f32>, n: vec3<f32>, material: Material, eye: vec3<f32>, spot: Spot) -> vec3<f32> {
    let e = spot_irradiance(p, n, spot);
    var w = n;
    let v = spot.position - p;
    if dot(v, v) > 0.0 {
        w = normalize(v);
    }
    let w_o = view_direction(p, n, eye);
    let brdf = material.diffuse / PI + material.specular * phong_normalisation(material.exponent) * phong_lobe(dot(mirror(w, n), w_o), material.exponent);
    return brdf * e;
}
