//! CPU twins of every quantity the GPU passes compute (docs/design.md §2-§4).
//!
//! Each function here has a WGSL function of the same name and argument order in
//! `shaders/common.wgsl` (or in the pass's own shader). Tests run both on the same inputs and
//! compare them; the CPU versions are also the readable statement of the maths.
//!
//! Units: positions in metres, flux in W, intensity in W/sr, irradiance in W/m², radiance in
//! W/(m² sr); all colours are linear RGB.

use glam::{Vec2, Vec3};
use std::f32::consts::PI;

pub mod adaptive;
pub mod bounce;
pub mod bvh;
pub mod exact_cpu;
pub mod flat;
pub mod light_rsms;
pub mod many_lights;
pub mod near_field;
pub mod raw;
pub mod rgbd;
pub mod rsm;

/// Squared distance under which a VAL and a receiver are treated as coincident: the direction
/// between them is undefined, so the pair contributes nothing (m²).
pub const COINCIDENT_DISTANCE_SQ: f32 = 1e-24;
/// Added to every averaging weight so an averaged light position stays defined when a receiver
/// gets no light at all (docs/design.md §4 step 1).
pub const GATHER_EPSILON: f32 = 1e-30;
/// Smallest distance (m) at which a renormalised point light is applied; closer lights are
/// pushed out to it so the inverse-square law cannot divide by zero.
pub const MIN_LIGHT_DISTANCE: f32 = 1e-4;
/// Smallest cosine between a receiver normal and its renormalised light direction. A grazing
/// averaged light is rotated toward the normal up to this cosine (docs/design.md §4 step 2).
pub const MIN_RENORMALISE_COSINE: f32 = 0.02;
/// Smallest `cos * lobe^k` a renormalised glossy light may divide by; below it the intensity is
/// capped, which bounds the energy error to views within a few degrees of grazing.
pub const MIN_GLOSSY_RESPONSE: f32 = 0.02;
/// Where the near-field window starts to fall, as a fraction of its radius
/// ([`near_field_weight`]).
pub const NEAR_FIELD_INNER: f32 = 0.5;

/// The share of a VAL at distance `d` (m) from a receiver that the sparse method's near-field
/// pass applies per pixel instead of through the sparse points: 1 up to [`NEAR_FIELD_INNER`]
/// times `radius`, a smoothstep down to 0 at `radius`, 0 everywhere when `radius` is 0 (off).
/// The gather takes the rest, `1 - near_field_weight`, so every VAL counts once in all.
pub fn near_field_weight(d: f32, radius: f32) -> f32 {
    if radius <= 0.0 {
        return 0.0;
    }
    let t = ((d - NEAR_FIELD_INNER * radius) / ((1.0 - NEAR_FIELD_INNER) * radius)).clamp(0.0, 1.0);
    1.0 - t * t * (3.0 - 2.0 * t)
}

/// The PCG hash of Jarzynski and Olano (2020), as `shader/common.wgsl`'s `pcg_hash`.
pub fn pcg_hash(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// A hash's top 24 bits as a float in [0, 1), as `shader/common.wgsl`'s `unit_float`.
pub fn unit_float(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// Luminance of a linear RGB triple (Rec. 709 weights); defined beside the images it is
/// measured on.
pub use crate::image::luminance;

/// Mirror `w` about `n`: `2 dot(n, w) n - w` (both unit; docs/design.md's `reflect`, which is the
/// negation of WGSL's built-in `reflect`).
pub fn mirror(w: Vec3, n: Vec3) -> Vec3 {
    2.0 * n.dot(w) * n - w
}

/// `max(0, c)^k`, defined for every `k >= 0` (0^0 = 1) without NaN from `log2(0)`.
pub fn phong_lobe(cos_r: f32, k: f32) -> f32 {
    if k <= 0.0 {
        1.0
    } else if cos_r <= 0.0 {
        0.0
    } else {
        (k * cos_r.log2()).exp2()
    }
}

/// Log2 of the smallest lobe the gather sums ([`gather_lobe`]).
pub const GATHER_LOBE_CUTOFF_LOG2: f32 = -64.0;

/// The lobe as the gather sums it (`gather_lobe` in `gather.wgsl`): [`phong_lobe`], but 0
/// where it is below `2^GATHER_LOBE_CUTOFF_LOG2`. That leaves out of a point's glossy sum less
/// than 2^-64 of its irradiance, far under float rounding, and keeps the GPU's products of a
/// tiny lobe with a small irradiance out of the subnormal range (slow on CPU adapters).
pub fn gather_lobe(cos_r: f32, k: f32) -> f32 {
    let below_cutoff = k > 0.0 && cos_r > 0.0 && k * cos_r.log2() < GATHER_LOBE_CUTOFF_LOG2;
    if below_cutoff { 0.0 } else { phong_lobe(cos_r, k) }
}

/// Normalised modified-Phong specular factor `(k + 2) / (2 pi)` (1/sr).
pub fn phong_normalisation(k: f32) -> f32 {
    (k + 2.0) / (2.0 * PI)
}

/// Geometric part of one VAL seen from a receiver (docs/design.md §3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValGeometry {
    /// Unit direction from the receiver to the VAL.
    pub direction: Vec3,
    /// `cos_x`: receiver cosine, clamped at 0.
    pub cos_receiver: f32,
    /// `w_j = cos_j / (pi d^2 + a_j)` (1/m²).
    pub weight: f32,
}

/// The point-to-disc form-factor weight of VAL (`val_position`, `val_normal`, `val_area`) at
/// receiver (`x`, `n_x`). Coincident pairs and VALs facing away give zero weight.
pub fn val_geometry(x: Vec3, n_x: Vec3, val_position: Vec3, val_normal: Vec3, val_area: f32) -> ValGeometry {
    let v = val_position - x;
    let d2 = v.length_squared();
    if d2 <= COINCIDENT_DISTANCE_SQ {
        return ValGeometry { direction: n_x, cos_receiver: 0.0, weight: 0.0 };
    }
    let w = v / d2.sqrt();
    let cos_receiver = n_x.dot(w).max(0.0);
    let cos_val = (-val_normal.dot(w)).max(0.0);
    ValGeometry { direction: w, cos_receiver, weight: cos_val / (PI * d2 + val_area.max(0.0)) }
}

/// The unit face normal `face` turned to the side of the shading normal `shading` (WGSL
/// `oriented_face_normal`): the vertex normals decide which side of a triangle is its front
/// (docs/design.md §3, shading and geometric normals).
pub fn oriented_face_normal(face: Vec3, shading: Vec3) -> Vec3 {
    if face.dot(shading) < 0.0 { -face } else { face }
}

/// A surface point's (shading, geometric) normals as a viewer at `eye` sees it (WGSL
/// `facing_viewer`): seen from behind its geometric normal, both are flipped (the back is shaded
/// as a surface of its own).
pub fn facing_viewer(position: Vec3, normal: Vec3, geometric: Vec3, eye: Vec3) -> (Vec3, Vec3) {
    if geometric.dot(eye - position) < 0.0 { (-normal, -geometric) } else { (normal, geometric) }
}

/// 1 where direction `w` leaves the surface on its geometric normal `n_g`'s side, else 0 (WGSL
/// `above_surface`): light from below the geometric surface would pass through it.
pub fn above_surface(n_g: Vec3, w: Vec3) -> f32 {
    if n_g.dot(w) > 0.0 { 1.0 } else { 0.0 }
}

/// [`val_geometry`] at a receiver with shading normal `n_x` and geometric normal `n_g` (WGSL
/// `val_geometry_sided`): the cosine is the shading normal's, and 0 for a VAL below the
/// geometric surface. Equal to [`val_geometry`] on a flat surface (`n_g = n_x`).
pub fn val_geometry_sided(
    x: Vec3,
    n_x: Vec3,
    n_g: Vec3,
    val_position: Vec3,
    val_normal: Vec3,
    val_area: f32,
) -> ValGeometry {
    let mut geo = val_geometry(x, n_x, val_position, val_normal, val_area);
    geo.cos_receiver *= above_surface(n_g, geo.direction);
    geo
}

/// [`val_geometry`]'s `weight * cos_receiver` (1/m²), with the two cosines' `1/d` folded into
/// the denominator: `(n_x . v)(-n_j . v) / (d² (pi d² + a_j))` for `v` the VAL's offset, `d` its
/// length; no square root and one division (the differential passes' sums; twin of WGSL
/// `val_form_factor`). 0 for a coincident pair, and a VAL behind the receiver or facing away.
#[inline]
pub fn val_form_factor(x: Vec3, n_x: Vec3, val_position: Vec3, val_normal: Vec3, val_area: f32) -> f32 {
    let v = val_position - x;
    // The cosines times d.
    let (receiver_d, val_d) = (n_x.dot(v), -val_normal.dot(v));
    let d2 = v.length_squared();
    if receiver_d <= 0.0 || val_d <= 0.0 || d2 <= COINCIDENT_DISTANCE_SQ {
        return 0.0;
    }
    receiver_d * val_d / (d2 * (PI * d2 + val_area.max(0.0)))
}

/// Irradiance (W/m²) at `x` from one Lambertian disc VAL of flux `flux` (W).
pub fn val_irradiance(x: Vec3, n_x: Vec3, val: &Val) -> Vec3 {
    let g = val_geometry(x, n_x, val.position, val.normal, val.area);
    val.flux * (g.weight * g.cos_receiver)
}

/// One virtual area light, a plain data type every layer exchanges (defined in [`crate::val`]).
pub use crate::val::Val;

/// The twins take a receiver's material as [`crate::scene::Material`] with its diffuse texture
/// already sampled into `diffuse` (`diffuse_texture` is not read), as WGSL's `Material.material`.
pub use crate::scene::Material;
pub use crate::scene::{InterpolationKernel, LightBound};

/// What the gather accumulates at one sparse point (docs/design.md §4 step 1).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Gathered {
    /// `E_x`: irradiance (W/m²).
    pub irradiance: Vec3,
    /// `l'_d`: luminance-and-geometry weighted mean VAL position (m).
    pub diffuse_position: Vec3,
    /// The same weighted mean of the squared VAL positions, per axis (m²).
    pub diffuse_second_moment: Vec3,
    /// `G_x`: irradiance weighted by the Phong lobe toward the eye (W/m²).
    pub glossy_irradiance: Vec3,
    /// `l'_s`: lobe-weighted mean VAL position (m).
    pub glossy_position: Vec3,
}

/// Gather every VAL at sparse point (`x`, `n_x`) with Phong exponent `k`, seen from `eye`.
pub fn gather_point(x: Vec3, n_x: Vec3, k: f32, eye: Vec3, vals: &[Val]) -> Gathered {
    gather_far_field(x, n_x, k, eye, vals, 0.0)
}

/// [`gather_point`] of the far field: every VAL's share scaled by
/// `1 - near_field_weight(distance, near_radius)`, the part the near-field pass does not apply
/// per pixel ([`shade_near_field`]); `near_radius` 0 is [`gather_point`].
pub fn gather_far_field(x: Vec3, n_x: Vec3, k: f32, eye: Vec3, vals: &[Val], near_radius: f32) -> Gathered {
    let w_o = view_direction(x, n_x, eye);
    let (mut e, mut g) = (Vec3::ZERO, Vec3::ZERO);
    let (mut ld, mut ld2, mut ls) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
    let (mut wd, mut ws) = (0.0f32, 0.0f32);
    for val in vals {
        let geo = val_geometry(x, n_x, val.position, val.normal, val.area);
        let far = 1.0 - near_field_weight(val.position.distance(x), near_radius);
        let f = geo.weight * geo.cos_receiver * far;
        let e_j = val.flux * f;
        let lobe = gather_lobe(mirror(geo.direction, n_x).dot(w_o), k);
        let y = luminance(val.flux) * f;
        e += e_j;
        g += e_j * lobe;
        let gd = y + GATHER_EPSILON;
        let gs = y * lobe + GATHER_EPSILON;
        ld += gd * val.position;
        ld2 += gd * val.position * val.position;
        ls += gs * val.position;
        wd += gd;
        ws += gs;
    }
    Gathered {
        irradiance: e,
        diffuse_position: ld / wd,
        diffuse_second_moment: ld2 / wd,
        glossy_irradiance: g,
        glossy_position: ls / ws,
    }
}

/// Unit direction from `x` toward the eye; the normal when the eye sits on `x`.
pub fn view_direction(x: Vec3, n_x: Vec3, eye: Vec3) -> Vec3 {
    let v = eye - x;
    let d2 = v.length_squared();
    if d2 <= COINCIDENT_DISTANCE_SQ { n_x } else { v / d2.sqrt() }
}

/// A point light with intensity (W/sr, RGB): a renormalised averaged VPL.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct PointLight {
    pub position: Vec3,
    pub intensity: Vec3,
    /// The largest irradiance luminance (W/m²) the light may deliver at a receiver
    /// ([`bound_light`]); 0 is unbounded (the paper's form, `settings.sparse.bound: "off"`).
    pub bound: f32,
}

/// Direction from `x` toward `target`, rotated toward `n` so that its cosine with `n` is at
/// least [`MIN_RENORMALISE_COSINE`]; returns (unit direction, distance clamped to
/// [`MIN_LIGHT_DISTANCE`]).
pub fn renormalise_direction(x: Vec3, n: Vec3, target: Vec3) -> (Vec3, f32) {
    let v = target - x;
    let d = v.length();
    let w = if d * d > COINCIDENT_DISTANCE_SQ { v / d } else { n };
    let c = n.dot(w);
    if c >= MIN_RENORMALISE_COSINE {
        return (w, d.max(MIN_LIGHT_DISTANCE));
    }
    let tangent = w - c * n;
    let t2 = tangent.length_squared();
    let t = if t2 > 1e-12 { tangent / t2.sqrt() } else { any_perpendicular(n) };
    let s = (1.0 - MIN_RENORMALISE_COSINE * MIN_RENORMALISE_COSINE).sqrt();
    (t * s + n * MIN_RENORMALISE_COSINE, d.max(MIN_LIGHT_DISTANCE))
}

/// A unit vector perpendicular to unit `n`.
pub fn any_perpendicular(n: Vec3) -> Vec3 {
    let a = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    n.cross(a).normalize()
}

/// Diffuse renormalisation (docs/design.md §4 step 2, paper eq. 11): a point light that, applied at
/// `x`, reproduces the gathered irradiance `e` exactly. Finite and non-negative for every input.
/// Its bound is the luminance of `e`: what the sparse point saw.
pub fn renormalise_diffuse(x: Vec3, n: Vec3, e: Vec3, averaged_position: Vec3) -> PointLight {
    let (w, d) = renormalise_direction(x, n, averaged_position);
    let cos = n.dot(w);
    PointLight { position: x + w * d, intensity: (e * (d * d / cos)).max(Vec3::ZERO), bound: luminance(e).max(0.0) }
}

/// Glossy renormalisation: a point light that, applied at `x` with the Phong lobe toward
/// `eye`, reproduces the gathered `g` (up to the [`MIN_GLOSSY_RESPONSE`] cap). Its bound is
/// 0 here; the renormalise pass bounds it by the point's diffuse irradiance `E_x`
/// (`G_x <= E_x`: a lobe is at most 1), as [`with_bound`] does.
pub fn renormalise_glossy(x: Vec3, n: Vec3, k: f32, eye: Vec3, g: Vec3, averaged_position: Vec3) -> PointLight {
    let w_o = view_direction(x, n, eye);
    let (mut w, d) = renormalise_direction(x, n, averaged_position);
    let mut response = n.dot(w) * phong_lobe(mirror(w, n).dot(w_o), k);
    if response < MIN_GLOSSY_RESPONSE && n.dot(w_o) > 0.0 {
        // The averaged position misses the lobe: put the light in the mirror direction of the
        // view instead, where the lobe is 1.
        let (r, _) = renormalise_direction(x, n, x + mirror(w_o, n));
        let r_response = n.dot(r) * phong_lobe(mirror(r, n).dot(w_o), k);
        if r_response > response {
            w = r;
            response = r_response;
        }
    }
    let intensity = if n.dot(w_o) > 0.0 { g * (d * d / response.max(MIN_GLOSSY_RESPONSE)) } else { Vec3::ZERO };
    PointLight { position: x + w * d, intensity: intensity.max(Vec3::ZERO), bound: 0.0 }
}

/// `light` bounded by the irradiance `e` (W/m², RGB): the renormalise pass's glossy light.
pub fn with_bound(light: PointLight, e: Vec3) -> PointLight {
    PointLight { bound: luminance(e).max(0.0), ..light }
}

/// Interpolation weights of a vertex's sparse neighbours (docs/design.md §4 step 4) for the
/// `kernel`. `offsets` are the neighbours' positions minus the vertex's, nearest first (as the
/// k-d tree returns them), `normals` theirs. The result always sums to > 0 when `offsets` is
/// non-empty.
pub fn interpolation_weights(kernel: InterpolationKernel, n_v: Vec3, offsets: &[Vec3], normals: &[Vec3]) -> Vec<f32> {
    let d_max = offsets.iter().map(|o| o.length()).fold(0.0f32, f32::max);
    let mut w: Vec<f32> = offsets
        .iter()
        .zip(normals)
        .map(|(&o, n)| {
            let facing = facing(n_v, *n);
            match kernel {
                InterpolationKernel::Paper => paper_weight(o.length(), d_max) * facing,
                InterpolationKernel::Smooth => smooth_weight(n_v, *n, o, d_max) * facing,
            }
        })
        .collect();
    if w.iter().sum::<f32>() <= 0.0 && !w.is_empty() {
        let fallback = normals.iter().position(|n| n_v.dot(*n) > FACING_EPSILON).unwrap_or(0);
        w[fallback] = 1.0;
    }
    w
}

/// Cosines between a vertex's and a neighbour's normals at or below this count as facing
/// away. Surfaces that meet at a right angle (a box on a floor, a room's corners) have cosines
/// of exactly 0 as modelled, but a few 1e-8 either side once the scene is turned by an angle
/// that is not a multiple of 90°: with a threshold of 0, a vertex whose other neighbours weigh
/// nothing (or whose bound comes from its neighbours of positive weight) took the light of its
/// perpendicular neighbours or not depending on how the scene was turned (up to 15 % of a
/// pixel's indirect light in `hardening_origin`'s turned Cornell box).
pub const FACING_EPSILON: f32 = 1e-4;

/// The normal factor of a neighbour's interpolation weight: the cosine between the vertex's
/// normal `n_v` and the neighbour's `n`, shifted down by [`FACING_EPSILON`] and rescaled so
/// that it is 0 up to the threshold, 1 for parallel normals, and continuous in between.
pub fn facing(n_v: Vec3, n: Vec3) -> f32 {
    ((n_v.dot(n) - FACING_EPSILON) / (1.0 - FACING_EPSILON)).clamp(0.0, 1.0)
}

/// Paper eq. 12's spatial weight `1 - d / d_max` (1 when every neighbour sits at the vertex).
/// Continuous as the neighbour set changes (a point enters or leaves at `d = d_max`, weight
/// 0), but its gradient jumps there and at every neighbour, which draws the sparse spacing.
pub fn paper_weight(d: f32, d_max: f32) -> f32 {
    if d_max > 0.0 { (1.0 - d / d_max).max(0.0) } else { 1.0 }
}

/// Depth behind the smooth surface through a vertex and a neighbour, as a fraction of `d_max`,
/// at which the smooth kernel's weight reaches zero: points there lie on the other side of thin
/// geometry or on a parallel surface, not on this surface curving away.
pub const PLANE_FALLOFF: f32 = 0.25;

/// The smooth kernel's weight of a neighbour at `offset` with normal `n_j` from a vertex with
/// normal `n_v`: `(1 - (d / d_max)^2)^2` (zero with zero slope at the support radius `d_max`, so
/// the value and its gradient are continuous as the neighbour set changes), times
/// `clamp(1 + dot((n_v + n_j) / 2, offset) / (PLANE_FALLOFF d_max), 0, 1)`.
///
/// `dot((n_v + n_j) / 2, offset)` is the neighbour's depth behind the smooth surface the two
/// normals describe: on a circle of any radius it is exactly 0 (the tangent plane's depth
/// `dot(n_v, offset) = -R (1 - cos phi)` is what the curvature `dot(n_v - n_j, offset) / 2`
/// predicts), so a round pillar's vertex takes the light of the points around its curve, as
/// the vertex normals round it, instead of its facet's alone; a parallel surface behind (equal
/// normals) is as far behind it as behind the tangent plane.
pub fn smooth_weight(n_v: Vec3, n_j: Vec3, offset: Vec3, d_max: f32) -> f32 {
    if d_max <= 0.0 {
        return 1.0;
    }
    let q = (1.0 - offset.length_squared() / (d_max * d_max)).max(0.0);
    let plane = (1.0 + 0.5 * (n_v + n_j).dot(offset) / (PLANE_FALLOFF * d_max)).clamp(0.0, 1.0);
    q * q * plane
}

/// A light whose share of the interpolation weight is at or below this fraction does not
/// lend the result its bound (it lends it no more than that fraction of its light either).
/// With a floor of 0, a neighbour at the support radius (weight exactly 0 at the origin, a
/// few 1e-17 once the scene is turned, from rounding `d / d_max`) lent its bound or not
/// depending on how the scene was turned: up to 15 % of a pixel's indirect light in
/// `hardening_origin`'s turned Cornell box.
pub const BOUND_WEIGHT_FLOOR: f32 = 1e-4;

/// Weighted mean of point lights (positions and intensities), weights from
/// [`interpolation_weights`]. With `bound` [`LightBound::Gathered`] the result's bound is the
/// largest bound among the lights whose share of the weight is over [`BOUND_WEIGHT_FLOOR`],
/// else 0 (unbounded).
pub fn interpolate_lights(weights: &[f32], lights: &[PointLight], bound: LightBound) -> PointLight {
    let total: f32 = weights.iter().sum();
    if total <= 0.0 {
        return PointLight::default();
    }
    let mut out = PointLight::default();
    for (w, l) in weights.iter().zip(lights) {
        out.position += l.position * (w / total);
        out.intensity += l.intensity * (w / total);
        if bound == LightBound::Gathered && *w > BOUND_WEIGHT_FLOOR * total {
            out.bound = out.bound.max(l.bound);
        }
    }
    out
}

/// `light` with its intensity scaled down so that the irradiance luminance it delivers at
/// (`p`, `n`) is at most its bound (unchanged when the bound is 0). This is what keeps an
/// interpolated light that lands close to a surface from making a firefly the gather never
/// saw; the energy it removes is measured by `relume compare` (docs/measurements/).
pub fn bound_light(p: Vec3, n: Vec3, light: &PointLight) -> PointLight {
    if light.bound <= 0.0 {
        return *light;
    }
    let v = light.position - p;
    let d2 = v.length_squared().max(MIN_LIGHT_DISTANCE * MIN_LIGHT_DISTANCE);
    let e = luminance(light.intensity) * n.dot(v / d2.sqrt()).max(0.0) / d2;
    let scale = if e > light.bound { light.bound / e } else { 1.0 };
    PointLight { intensity: light.intensity * scale, ..*light }
}

/// Radiance (W/(m² sr)) toward `eye` from a point light at a receiver (`p`, `n`) through the
/// Phong BRDF. `glossy` selects the specular term, else the diffuse one.
pub fn point_light_radiance(p: Vec3, n: Vec3, surface: &Material, eye: Vec3, light: &PointLight, glossy: bool) -> Vec3 {
    let v = light.position - p;
    let d2 = v.length_squared().max(MIN_LIGHT_DISTANCE * MIN_LIGHT_DISTANCE);
    let w = v / d2.sqrt();
    let cos = n.dot(w).max(0.0);
    let e = light.intensity * (cos / d2);
    if glossy {
        let w_o = view_direction(p, n, eye);
        surface.specular
            * phong_normalisation(surface.exponent)
            * phong_lobe(mirror(w, n).dot(w_o), surface.exponent)
            * e
    } else {
        surface.diffuse / PI * e
    }
}

/// Per-pixel sparse shading (docs/design.md §4 step 5): the diffuse and glossy point lights, each
/// bounded ([`bound_light`]), applied with the pixel's own position, normal, material and view
/// direction.
pub fn shade_sparse(
    p: Vec3,
    n: Vec3,
    surface: &Material,
    eye: Vec3,
    diffuse: &PointLight,
    glossy: Option<&PointLight>,
) -> Vec3 {
    let mut l = point_light_radiance(p, n, surface, eye, &bound_light(p, n, diffuse), false);
    if let Some(g) = glossy {
        l += point_light_radiance(p, n, surface, eye, &bound_light(p, n, g), true);
    }
    l
}

/// What a sparse point's gathered glossy sum `g` (the lobe-weighted irradiance toward `eye`)
/// contributes to `glossy_interpolation: "radiance"`: `g`, or 0 where the point faces away
/// from the eye (where [`renormalise_glossy`] makes no light either).
pub fn glossy_toward_eye(x: Vec3, n: Vec3, eye: Vec3, g: Vec3) -> Vec3 {
    if n.dot(view_direction(x, n, eye)) > 0.0 { g.max(Vec3::ZERO) } else { Vec3::ZERO }
}

/// `glossy_interpolation: "radiance"` at a vertex (WGSL `interpolate.wgsl`'s
/// `main_glossy_radiance`): the neighbours' [`glossy_toward_eye`] values averaged with the
/// interpolation `weights` (0 when they sum to 0 or less).
pub fn interpolate_radiance(weights: &[f32], values: &[Vec3]) -> Vec3 {
    let total: f32 = weights.iter().sum();
    if total <= 0.0 {
        return Vec3::ZERO;
    }
    weights.iter().zip(values).map(|(w, v)| *v * (w / total)).sum()
}

/// The glossy radiance at a pixel of `glossy_interpolation: "radiance"` (WGSL `shade.wgsl`'s
/// `main_glossy_radiance`): the interpolated gathered sum `g` through the pixel's specular
/// albedo and Phong normalisation. At a sparse point itself this is exactly the glossy
/// radiance its renormalised light gives there.
pub fn glossy_from_radiance(surface: &Material, g: Vec3) -> Vec3 {
    surface.specular * phong_normalisation(surface.exponent) * g
}

/// Brute-force indirect radiance at a pixel: every VAL through §3, no interpolation.
pub fn shade_brute_force(p: Vec3, n: Vec3, surface: &Material, eye: Vec3, vals: &[Val], glossy: bool) -> Vec3 {
    shade_brute_force_sided(p, n, n, surface, eye, vals, glossy)
}

/// [`shade_brute_force`] at a receiver with geometric normal `n_g` (both normals already facing
/// the viewer, [`facing_viewer`]): the brute-force pass's sum ([`val_radiance_sided`]).
pub fn shade_brute_force_sided(
    p: Vec3,
    n: Vec3,
    n_g: Vec3,
    surface: &Material,
    eye: Vec3,
    vals: &[Val],
    glossy: bool,
) -> Vec3 {
    let w_o = view_direction(p, n, eye);
    vals.iter().map(|val| val_radiance_sided(p, n, n_g, surface, w_o, val, glossy)).sum()
}

/// [`shade_brute_force`] with per-pixel group visibility (WGSL `visibility/group.wgsl`, the
/// method `brute_force_ism`): each VAL's term times its group's entry of the pixel's row
/// `visibility` (`visibility[group_of_val[j]]`, the clusters' lookup of the imperfect shadow
/// maps at the pixel).
#[allow(clippy::too_many_arguments)]
pub fn shade_brute_force_grouped(
    p: Vec3,
    n: Vec3,
    surface: &Material,
    eye: Vec3,
    vals: &[Val],
    group_of_val: &[u32],
    visibility: &[f32],
    glossy: bool,
) -> Vec3 {
    let w_o = view_direction(p, n, eye);
    let last = visibility.len() - 1;
    vals.iter()
        .zip(group_of_val)
        .map(|(val, &g)| val_radiance(p, n, surface, w_o, val, glossy) * visibility[(g as usize).min(last)])
        .sum()
}

/// The sparse method's near-field radiance at a pixel (`p`, shading normal `n`, geometric
/// normal `n_g`, both facing the viewer): every VAL through §3 scaled
/// by `near_field_weight(distance to centre, near_radius)`, the part [`gather_far_field`] left
/// out at the sparse points the pixel interpolates, whose weighted mean position is `centre`
/// ([`near_field::vertex_centre`] at the pixel's corners, interpolated).
pub fn shade_near_field<'a>(
    p: Vec3,
    n: Vec3,
    n_g: Vec3,
    surface: &Material,
    eye: Vec3,
    centre: Vec3,
    vals: impl IntoIterator<Item = &'a Val>,
    glossy: bool,
    near_radius: f32,
) -> Vec3 {
    let w_o = view_direction(p, n, eye);
    vals.into_iter()
        .map(|val| {
            val_radiance_sided(p, n, n_g, surface, w_o, val, glossy)
                * near_field_weight(val.position.distance(centre), near_radius)
        })
        .sum()
}

/// Radiance (W/(m² sr)) toward `w_o` (unit, toward the eye) that one unoccluded VAL reflects
/// at receiver (`p`, `n`): docs/design.md §3's diffuse term plus, when `glossy`, the Phong term. The
/// term every brute-force and exact-visibility pixel sums over its (visible) VALs.
pub fn val_radiance(p: Vec3, n: Vec3, surface: &Material, w_o: Vec3, val: &Val, glossy: bool) -> Vec3 {
    val_radiance_sided(p, n, n, surface, w_o, val, glossy)
}

/// [`val_radiance`] at a receiver whose geometric normal `n_g` differs from its shading normal
/// `n` ([`val_geometry_sided`]): what the brute force and the exact reference sum per pixel.
pub fn val_radiance_sided(p: Vec3, n: Vec3, n_g: Vec3, surface: &Material, w_o: Vec3, val: &Val, glossy: bool) -> Vec3 {
    let geo = val_geometry_sided(p, n, n_g, val.position, val.normal, val.area);
    reflected_radiance(n, surface, w_o, geo.direction, val.flux * (geo.weight * geo.cos_receiver), glossy)
}

/// Radiance toward `w_o` that irradiance `e` (W/m², RGB) arriving from unit `direction`
/// reflects at a receiver of normal `n`: §3's diffuse term plus, when `glossy`, the Phong term.
pub fn reflected_radiance(n: Vec3, surface: &Material, w_o: Vec3, direction: Vec3, e: Vec3, glossy: bool) -> Vec3 {
    let mut l = surface.diffuse / PI * e;
    if glossy {
        let spec = surface.specular * phong_normalisation(surface.exponent);
        l += spec * phong_lobe(mirror(direction, n).dot(w_o), surface.exponent) * e;
    }
    l
}

/// Bilinear sample of an sRGB-encoded RGBA8 image (`width` x `height`, rows from the top) at
/// texture coordinates `st` (s right, t down, texel centres at (i + 0.5) / size), with repeat
/// addressing; texels are decoded to linear before filtering, as GPUs do for sRGB formats.
pub fn sample_bilinear(rgba8: &[u8], width: u32, height: u32, st: Vec2) -> Vec3 {
    let (w, h) = (width as i64, height as i64);
    let x = st.x * width as f32 - 0.5;
    let y = st.y * height as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let texel = |i: i64, j: i64| {
        let k = 4 * (j.rem_euclid(h) * w + i.rem_euclid(w)) as usize;
        let d = crate::image::decode_srgb;
        Vec3::new(d(rgba8[k]), d(rgba8[k + 1]), d(rgba8[k + 2]))
    };
    let (i, j) = (x0 as i64, y0 as i64);
    let top = texel(i, j).lerp(texel(i + 1, j), fx);
    let bottom = texel(i, j + 1).lerp(texel(i + 1, j + 1), fx);
    top.lerp(bottom, fy)
}

/// Barycentric interpolation `(1 - b.x - b.y) a + b.x b + b.y c`.
pub fn barycentric(b: Vec2, a: Vec3, bb: Vec3, c: Vec3) -> Vec3 {
    a * (1.0 - b.x - b.y) + bb * b.x + c * b.y
}

#[cfg(test)]
mod tests;
