//! CPU twins of the spot light and its reflective shadow map (docs/design.md §2, §4 step 6).

use super::bvh::TraceBvh;
use super::flat::FlatScene;
use super::{Material, Val, mirror, phong_lobe, phong_normalisation, view_direction};
use crate::scene::SpotLight;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::f32::consts::PI;

/// Falloff of the spot at an angle with cosine `cos_theta` off its axis: 1 inside the inner
/// half-angle, 0 outside the outer one, linear in angle between (a hard edge if they are equal).
pub fn spot_falloff(cos_theta: f32, inner_angle: f32, outer_angle: f32) -> f32 {
    let c = cos_theta.clamp(-1.0, 1.0);
    let theta = (1.0 - c * c).max(0.0).sqrt().atan2(c);
    if outer_angle - inner_angle <= 1e-6 {
        if theta <= outer_angle { 1.0 } else { 0.0 }
    } else {
        ((outer_angle - theta) / (outer_angle - inner_angle)).clamp(0.0, 1.0)
    }
}

/// Centre of RSM texel (`ix`, `iy`) in normalised device coordinates (x right, y up; row 0 is
/// the top of the image, as wgpu rasterises it).
pub fn rsm_texel_ndc(ix: u32, iy: u32, resolution: u32) -> Vec2 {
    let r = resolution as f32;
    Vec2::new((ix as f32 + 0.5) / r * 2.0 - 1.0, 1.0 - (iy as f32 + 0.5) / r * 2.0)
}

/// World-space unit direction from the spot through the centre of the RSM texel at `ndc`: the
/// grid lies in the light's frame ([`SpotLight::world_to_light`]: forward `direction`, right
/// `direction x up`, up completing them) on the image plane at unit distance, whose edges are at
/// `tan(outer_angle)`. The twin of the RSM raster's `light_to_clip`.
pub fn rsm_texel_direction(ndc: Vec2, spot: &SpotLight) -> Vec3 {
    let forward = spot.direction.normalize();
    let right = forward.cross(spot.up).normalize();
    let up = right.cross(forward);
    (forward + (ndc.x * right + ndc.y * up) * spot.outer_angle.tan()).normalize()
}

/// Solid angle (sr) of the RSM texel centred at `ndc` for a square perspective RSM whose
/// half-angle is `outer_angle`: texel area on the unit-distance image plane times `cos^3`.
/// Returns (solid angle, cosine of the texel centre's angle off the axis).
pub fn rsm_texel_solid_angle(ndc: Vec2, outer_angle: f32, resolution: u32) -> (f32, f32) {
    let t = outer_angle.tan();
    let side = 2.0 * t / resolution as f32;
    let cos_theta = 1.0 / (1.0 + (ndc * t).length_squared()).sqrt();
    (side * side * cos_theta * cos_theta * cos_theta, cos_theta)
}

/// The VAL made from the RSM texel at `ndc` that sees surface point `y` with normal `n_y` and
/// diffuse albedo `rho_d`: `Phi = rho_d * I * falloff * Omega`, `a = |y - p_L|^2 * Omega`,
/// normal oriented toward the light.
pub fn rsm_texel_val(ndc: Vec2, resolution: u32, spot: &SpotLight, y: Vec3, n_y: Vec3, rho_d: Vec3) -> Val {
    let (omega, cos_theta) = rsm_texel_solid_angle(ndc, spot.outer_angle, resolution);
    let falloff = spot_falloff(cos_theta, spot.inner_angle, spot.outer_angle);
    let to_light = spot.position - y;
    let normal = if n_y.dot(to_light) < 0.0 { -n_y } else { n_y };
    Val {
        position: y,
        normal,
        area: to_light.length_squared() * omega,
        flux: rho_d * spot.intensity * (falloff * omega),
    }
}

/// The spot light's VALs at `resolution` x `resolution` texels, traced instead of rasterised:
/// a ray from the light through each texel's centre ([`rsm_texel_direction`], where the GPU's
/// raster samples the texel) meets a surface, whose VAL is [`rsm_texel_val`]; texels that see
/// nothing or receive no flux make none. In the texels' row-major order. What `SpotVals` makes
/// at that resolution without drawing an RSM (only a surface nearer the light than the raster's
/// near plane differs), so that the error estimate can sum over the VALs of a resolution the
/// frame did not draw (`renderer::estimate`).
pub fn traced_vals(flat: &FlatScene, bvh: &TraceBvh, spot: &SpotLight, resolution: u32) -> Vec<Val> {
    let r = resolution;
    (0..r * r)
        .into_par_iter()
        .filter_map(|texel| {
            let ndc = rsm_texel_ndc(texel % r, texel / r, r);
            let hit = bvh.closest_hit(spot.position, rsm_texel_direction(ndc, spot))?;
            let (y, n, surface) = flat.surface_at(hit.triangle, hit.barycentrics);
            let val = rsm_texel_val(ndc, r, spot, y, n, surface.diffuse);
            (val.flux.max_element() > 0.0).then_some(val)
        })
        .collect()
}

/// Irradiance (W/m²) at (`p`, `n`) straight from the spot, without visibility.
pub fn spot_irradiance(p: Vec3, n: Vec3, spot: &SpotLight) -> Vec3 {
    let v = spot.position - p;
    let d2 = v.length_squared().max(super::MIN_LIGHT_DISTANCE * super::MIN_LIGHT_DISTANCE);
    let w = v / d2.sqrt();
    let falloff = spot_falloff((-w).dot(spot.direction), spot.inner_angle, spot.outer_angle);
    spot.intensity * (falloff * n.dot(w).max(0.0) / d2)
}

/// Direct radiance (W/(m² sr)) toward `eye` from the spot through the Phong BRDF, without
/// visibility (the GPU multiplies by its shadow-map test).
pub fn direct_radiance(p: Vec3, n: Vec3, surface: &Material, eye: Vec3, spot: &SpotLight) -> Vec3 {
    let e = spot_irradiance(p, n, spot);
    let w = (spot.position - p).normalize_or(n);
    let w_o = view_direction(p, n, eye);
    let brdf = surface.diffuse / PI
        + surface.specular
            * phong_normalisation(surface.exponent)
            * phong_lobe(mirror(w, n).dot(w_o), surface.exponent);
    brdf * e
}

/// The flux a spot sends into its cone, `I * 2 pi * integral_0^outer falloff(theta) sin(theta)
/// dtheta`, by midpoint quadrature with `steps` intervals (W, RGB).
pub fn spot_cone_flux(spot: &SpotLight, steps: u32) -> Vec3 {
    let h = spot.outer_angle / steps as f32;
    let mut s = 0.0f64;
    for i in 0..steps {
        let theta = (i as f32 + 0.5) * h;
        s += (spot_falloff(theta.cos(), spot.inner_angle, spot.outer_angle) * theta.sin()) as f64 * h as f64;
    }
    spot.intensity * (2.0 * std::f64::consts::PI * s) as f32
}
