//! CPU twins of the RSMs of the scene's `lights` (`gpu::lights::light_rsms`,
//! docs/measurements/many-lights.md): the split of one VAL budget among the lights by emitted flux, each light's
//! views (a spot: one perspective view over its cone, as the scene's `light`; a point light: the
//! six 90° faces of a cube around it), a texel's direction and solid angle, and the VAL a texel
//! makes.
//!
//! A cube rather than the many-light shadow maps' two paraboloids: a perspective view keeps a
//! triangle's edges straight, so the scene's visibility raster draws it exactly (watertight,
//! perspective-correct barycentrics) and the texel maths is the spot's; a paraboloid bends edges
//! and needs the shadow-map raster's per-texel ray cast with its slack, which would leave or
//! double texels near the horizon, where a VAL carries flux. The cost: six draws per point light
//! instead of two.
//!
//! Flux per texel: `Phi_t = rho_d * I * falloff * window * Omega_t` (docs/design.md §2), with
//! `Omega_t` the midpoint `side² cos³` rescaled per view so that a view's texels sum to the
//! exact solid angle of its square ([`view_omega_scale`]): the six faces of a point light cover
//! exactly 4 pi sr at any resolution, so a light's reflected flux does not depend on its share.

use super::many_lights::range_window;
use super::rsm::{spot_cone_flux, spot_falloff};
use super::{Val, luminance};
use crate::scene::{Light, SpotLight};
use glam::{Mat4, Vec2, Vec3};
use std::f32::consts::{FRAC_PI_4, PI};

/// Views of a point light's RSM (a cube's faces) and of a spot's.
pub use crate::scene::settings::{POINT_VIEWS, SPOT_VIEWS};

/// How many views a light's RSM has.
pub fn views_of(light: &Light) -> u32 {
    match light {
        Light::Point(_) => POINT_VIEWS,
        Light::Spot(_) => SPOT_VIEWS,
    }
}

/// Luminance of the flux a light emits (W): `4 pi Y(I)` for a point light (its `range` window
/// is not counted), `Y` of the flux into its cone for a spot ([`spot_cone_flux`]).
pub fn emitted_flux(light: &Light) -> f32 {
    match light {
        Light::Point(p) => 4.0 * PI * luminance(p.intensity),
        Light::Spot(s) => luminance(spot_cone_flux(s, 1024)),
    }
}

/// Each light's RSM resolution (texels per view side) for a budget of `budget` VALs, the lights
/// having flux `flux` (luminance, W) and `views` views each: a light's share is `budget` times
/// its fraction of the total flux, and its resolution the largest `r` whose `views r²` texels
/// fit the share. Every light with flux gets at least `r = 1`: lights whose share is below
/// their `views` texels get exactly that, and the others share what is left by flux (repeated
/// until every remaining share holds a texel per view), so the texels never exceed `budget`
/// when it holds a texel per view of every light. Lights without flux get 0 (no VAL).
pub fn split_val_budget(flux: &[f32], views: &[u32], budget: u32) -> Vec<u32> {
    let mut resolution = vec![0u32; flux.len()];
    let mut open: Vec<usize> = (0..flux.len()).filter(|&i| flux[i] > 0.0).collect();
    let mut left = budget as f64;
    loop {
        let total: f64 = open.iter().map(|&i| flux[i] as f64).sum();
        let starved: Vec<usize> =
            open.iter().copied().filter(|&i| left * flux[i] as f64 / total < views[i] as f64).collect();
        if starved.is_empty() {
            break;
        }
        for &i in &starved {
            resolution[i] = 1;
            left -= views[i] as f64;
        }
        open.retain(|i| !starved.contains(i));
    }
    let total: f64 = open.iter().map(|&i| flux[i] as f64).sum();
    for &i in &open {
        let share = left * flux[i] as f64 / total;
        // Largest r with views r² <= share (>= 1 here); the float root is corrected both ways.
        let mut r = (share / views[i] as f64).sqrt().floor() as u32;
        while (views[i] * (r + 1) * (r + 1)) as f64 <= share {
            r += 1;
        }
        while r > 1 && (views[i] * r * r) as f64 > share {
            r -= 1;
        }
        resolution[i] = r.max(1);
    }
    resolution
}

/// The smallest budget that gives every light with flux a texel per view.
pub fn minimum_val_budget(lights: &[Light]) -> u32 {
    lights.iter().filter(|l| emitted_flux(l) > 0.0).map(views_of).sum()
}

/// One view of a light's RSM: a square perspective image `resolution` texels a side over the
/// half-angle `atan(tan_half)` around `frame.direction` (rows across `frame.up`, as
/// [`SpotLight::world_to_light`]), its texels' flux from `frame` (intensity, falloff) and the
/// point light's `range` window.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RsmView {
    /// Position, axis, up, intensity, and the falloff's angles (a point light's face: a cone
    /// of half-angle pi, falloff 1 everywhere).
    pub frame: SpotLight,
    /// Half-extent of the image on the unit-distance plane: `tan(outer_angle)` for a spot, 1
    /// for a cube face.
    pub tan_half: f32,
    pub resolution: u32,
    /// [`view_omega_scale`] of `tan_half` and `resolution`.
    pub omega_scale: f32,
    /// The point light's range (m), for [`range_window`]; `None` for a spot or no range.
    pub range: Option<f32>,
}

/// The cube's faces: axis and up (`SpotLight::default_up` of the axis).
pub const CUBE_FACES: [(Vec3, Vec3); 6] = [
    (Vec3::X, Vec3::Y),
    (Vec3::NEG_X, Vec3::Y),
    (Vec3::Y, Vec3::Z),
    (Vec3::NEG_Y, Vec3::Z),
    (Vec3::Z, Vec3::Y),
    (Vec3::NEG_Z, Vec3::Y),
];

/// A light's views at `resolution` texels a side: a spot's one view over its outer cone, or a
/// point light's six cube faces.
pub fn light_views(light: &Light, resolution: u32) -> Vec<RsmView> {
    match *light {
        Light::Spot(s) => {
            let tan_half = s.outer_angle.tan();
            vec![RsmView {
                frame: s,
                tan_half,
                resolution,
                omega_scale: view_omega_scale(tan_half, resolution),
                range: None,
            }]
        }
        Light::Point(p) => CUBE_FACES
            .iter()
            .map(|&(direction, up)| RsmView {
                frame: SpotLight {
                    position: p.position,
                    direction,
                    inner_angle: PI,
                    outer_angle: PI,
                    intensity: p.intensity,
                    up,
                },
                tan_half: 1.0,
                resolution,
                omega_scale: view_omega_scale(1.0, resolution),
                range: p.range,
            })
            .collect(),
    }
}

/// World to the view's clip space: a square perspective over its half-angle, near and far
/// `depth` (the twin of `SpotVals::light_to_clip` with the view's half-angle).
pub fn view_to_clip(view: &RsmView, depth: (f32, f32)) -> Mat4 {
    let fov = 2.0 * view.tan_half.atan();
    glam::camera::rh::proj::directx::perspective(fov, 1.0, depth.0, depth.1) * view.frame.world_to_light()
}

/// Exact solid angle (sr) of the square `[-t, t]²` on the unit-distance image plane:
/// `4 atan(t² / sqrt(1 + 2 t²))` (2 pi / 3 for a cube face, t = 1).
pub fn square_solid_angle(t: f64) -> f64 {
    4.0 * (t * t / (1.0 + 2.0 * t * t).sqrt()).atan()
}

/// The factor that makes the midpoint solid angles `side² cos³` of a view's `resolution`²
/// texels sum to [`square_solid_angle`] of its half-extent `tan_half` (computed in f64).
pub fn view_omega_scale(tan_half: f32, resolution: u32) -> f32 {
    let t = tan_half as f64;
    let r = resolution as f64;
    let side = 2.0 * t / r;
    let mut sum = 0.0f64;
    for iy in 0..resolution {
        for ix in 0..resolution {
            let x = ((ix as f64 + 0.5) / r * 2.0 - 1.0) * t;
            let y = ((iy as f64 + 0.5) / r * 2.0 - 1.0) * t;
            sum += side * side / (1.0 + x * x + y * y).powf(1.5);
        }
    }
    (square_solid_angle(t) / sum) as f32
}

/// World-space unit direction from the light through the centre of the view's texel at `ndc`
/// (`twin::rsm::rsm_texel_ndc`): [`crate::twin::rsm::rsm_texel_direction`] with the view's
/// half-extent.
pub fn view_texel_direction(ndc: Vec2, view: &RsmView) -> Vec3 {
    let forward = view.frame.direction.normalize();
    let right = forward.cross(view.frame.up).normalize();
    let up = right.cross(forward);
    (forward + (ndc.x * right + ndc.y * up) * view.tan_half).normalize()
}

/// (solid angle in sr, cosine off the view's axis) of the view's texel centred at `ndc`:
/// `omega_scale * side² * cos³`.
pub fn view_texel_solid_angle(ndc: Vec2, view: &RsmView) -> (f32, f32) {
    let side = 2.0 * view.tan_half / view.resolution as f32;
    let cos_theta = 1.0 / (1.0 + (ndc * view.tan_half).length_squared()).sqrt();
    (view.omega_scale * side * side * cos_theta * cos_theta * cos_theta, cos_theta)
}

/// The VAL made from the view's texel at `ndc` that sees surface point `y` (normal `n_y`,
/// diffuse albedo `rho_d`): `Phi = rho_d * I * falloff * window(|y - p_L|) * Omega`,
/// `a = |y - p_L|² Omega`, normal toward the light (docs/design.md §2).
pub fn view_texel_val(ndc: Vec2, view: &RsmView, y: Vec3, n_y: Vec3, rho_d: Vec3) -> Val {
    let (omega, cos_theta) = view_texel_solid_angle(ndc, view);
    let s = &view.frame;
    let falloff = spot_falloff(cos_theta, s.inner_angle, s.outer_angle);
    let to_light = s.position - y;
    let window = range_window(to_light.length(), view.range);
    let normal = if n_y.dot(to_light) < 0.0 { -n_y } else { n_y };
    Val {
        position: y,
        normal,
        area: to_light.length_squared() * omega,
        flux: rho_d * s.intensity * (falloff * window * omega),
    }
}

/// The half-angle of a cube face's frustum (45°).
pub const CUBE_FACE_HALF_ANGLE: f32 = FRAC_PI_4;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::PointLight;
    use crate::twin::rsm::rsm_texel_ndc;

    fn spot(intensity: f32) -> Light {
        Light::Spot(SpotLight {
            position: Vec3::ZERO,
            direction: Vec3::NEG_Y,
            inner_angle: 0.3,
            outer_angle: 0.3,
            intensity: Vec3::splat(intensity),
            up: Vec3::Z,
        })
    }

    fn point(intensity: Vec3, range: Option<f32>) -> Light {
        Light::Point(PointLight { position: Vec3::new(0.5, 1.0, -0.25), intensity, range })
    }

    /// Three spots of flux 1:2:5 and 800 VALs: shares 100, 200 and 500 texels, so 10², 14²
    /// (196) and 22² (484).
    #[test]
    fn budget_split_by_flux_known_answer() {
        let lights = [spot(1.0), spot(2.0), spot(5.0)];
        let flux: Vec<f32> = lights.iter().map(emitted_flux).collect();
        assert!((flux[1] / flux[0] - 2.0).abs() < 1e-5 && (flux[2] / flux[0] - 5.0).abs() < 1e-5);
        assert_eq!(split_val_budget(&flux, &[1, 1, 1], 800), vec![10, 14, 22]);
        // Three point lights 1:2:5 and 4800 VALs: shares of 600, 1200 and 3000 texels over six
        // faces each: 6 x 10², 6 x 14², 6 x 22².
        assert_eq!(split_val_budget(&[1.0, 2.0, 5.0], &[6, 6, 6], 4800), vec![10, 14, 22]);
    }

    /// Shares too small for a texel per view get exactly that, and the rest is split among the
    /// others: 0.2 : 0.2 : 9.6 of 10 VALs (spots) would need 11 texels with a floor of 1 each;
    /// the two small ones take 1 each and the third 2² = 4 of the 8 left (3² = 9 would not fit).
    /// A light without flux gets nothing.
    #[test]
    fn small_shares_get_one_texel_and_the_total_stays_in_budget() {
        let r = split_val_budget(&[0.2, 0.2, 9.6, 0.0], &[1, 1, 1, 6], 10);
        assert_eq!(r, vec![1, 1, 2, 0]);
        for budget in [6u32, 7, 50, 999, 4096, 65_536] {
            let flux = [0.01, 1.0, 3.0, 0.5, 7.0];
            let views = [6, 1, 6, 1, 6];
            let r = split_val_budget(&flux, &views, budget);
            let texels: u32 = r.iter().zip(&views).map(|(r, v)| v * r * r).sum();
            let minimum: u32 = views.iter().sum();
            assert!(texels <= budget.max(minimum), "{budget}: {r:?} -> {texels}");
            assert!(r.iter().all(|&r| r >= 1));
        }
    }

    /// The six faces' texel directions cover the sphere (each the face's own centre direction
    /// and unit), and their solid angles sum to 4 pi at every resolution, a face to 2 pi / 3.
    #[test]
    fn cube_texels_cover_the_sphere() {
        for r in [1u32, 2, 3, 7, 32] {
            let views = light_views(&point(Vec3::ONE, None), r);
            let mut total = 0.0f64;
            for view in &views {
                let mut face = 0.0f64;
                for iy in 0..r {
                    for ix in 0..r {
                        let ndc = rsm_texel_ndc(ix, iy, r);
                        let d = view_texel_direction(ndc, view);
                        assert!((d.length() - 1.0).abs() < 1e-5);
                        // The texel's direction lies on its own face: the largest component is
                        // along the face's axis.
                        let along = d.dot(view.frame.direction);
                        assert!(along >= d.abs().max_element() - 1e-5, "{d} {}", view.frame.direction);
                        face += view_texel_solid_angle(ndc, view).0 as f64;
                    }
                }
                assert!((face - 2.0 * std::f64::consts::PI / 3.0).abs() < 1e-5, "r = {r}: {face}");
                total += face;
            }
            assert!((total - 4.0 * std::f64::consts::PI).abs() < 1e-4, "r = {r}: {total}");
        }
    }

    /// A texel's midpoint solid angle (before rescaling) is close to the exact one of its
    /// square: at r = 64 the rescale is within 1e-3 of 1; at r = 1 the midpoint rule (4 sr for a
    /// face) overstates the face's 2 pi / 3 and the scale corrects it.
    #[test]
    fn omega_scale_is_the_midpoint_rules_correction() {
        assert!((view_omega_scale(1.0, 64) - 1.0).abs() < 1e-3);
        assert!((view_omega_scale(1.0, 1) - (2.0 * PI / 3.0) / 4.0).abs() < 1e-6);
        assert!((square_solid_angle(1.0) - 2.0 * std::f64::consts::PI / 3.0).abs() < 1e-12);
    }

    /// A point light at the centre of a sphere of radius 2 and albedo 0.5: every texel sees the
    /// sphere, and the VALs' flux sums to 0.5 x 4 pi I; their areas sum to the sphere's 16 pi.
    #[test]
    fn point_light_texel_flux_sums_to_its_power() {
        let intensity = Vec3::new(1.0, 2.0, 3.0);
        let light = point(intensity, None);
        let centre = light.position();
        let rho = Vec3::splat(0.5);
        let (mut flux, mut area) = (Vec3::ZERO, 0.0f32);
        for view in light_views(&light, 5) {
            for iy in 0..5 {
                for ix in 0..5 {
                    let ndc = rsm_texel_ndc(ix, iy, 5);
                    let y = centre + 2.0 * view_texel_direction(ndc, &view);
                    let val = view_texel_val(ndc, &view, y, (y - centre).normalize(), rho);
                    assert!(val.normal.dot(centre - y) > 0.0, "the VAL faces the light");
                    flux += val.flux;
                    area += val.area;
                }
            }
        }
        let power = 4.0 * PI * intensity;
        assert!((flux - 0.5 * power).abs().max_element() < 1e-5 * power.max_element(), "{flux} vs {}", 0.5 * power);
        assert!((area - 16.0 * PI).abs() < 1e-4 * 16.0 * PI, "{area}");
    }

    /// The range window takes a point light's VALs to zero from its range on.
    #[test]
    fn range_window_reaches_the_vals() {
        let light = point(Vec3::ONE, Some(1.5));
        let view = light_views(&light, 4)[0];
        let ndc = rsm_texel_ndc(1, 2, 4);
        let d = view_texel_direction(ndc, &view);
        let near = view_texel_val(ndc, &view, light.position() + d, -d, Vec3::ONE);
        let far = view_texel_val(ndc, &view, light.position() + 2.0 * d, -d, Vec3::ONE);
        let (omega, _) = view_texel_solid_angle(ndc, &view);
        assert!((near.flux.x - omega * range_window(1.0, Some(1.5))).abs() < 1e-6);
        assert_eq!(far.flux, Vec3::ZERO);
    }

    /// A spot's view is the scene light's RSM: same directions as `rsm_texel_direction`, and a
    /// texel's flux and area those of `rsm_texel_val` up to the solid angle's rescale.
    #[test]
    fn spot_view_matches_the_scene_lights_rsm() {
        let Light::Spot(s) = spot(3.0) else { unreachable!() };
        let view = light_views(&Light::Spot(s), 16)[0];
        for (ix, iy) in [(0u32, 0u32), (7, 9), (15, 3)] {
            let ndc = rsm_texel_ndc(ix, iy, 16);
            let d = view_texel_direction(ndc, &view);
            assert!((d - crate::twin::rsm::rsm_texel_direction(ndc, &s)).length() < 1e-6);
            let y = d * 3.0;
            let a = view_texel_val(ndc, &view, y, Vec3::Y, Vec3::splat(0.7));
            let b = crate::twin::rsm::rsm_texel_val(ndc, 16, &s, y, Vec3::Y, Vec3::splat(0.7));
            assert!((a.flux - b.flux * view.omega_scale).abs().max_element() < 1e-6 * b.flux.max_element().max(1e-6));
            assert!((a.area - b.area * view.omega_scale).abs() < 1e-5 * b.area);
            assert_eq!(a.normal, b.normal);
        }
    }

    /// The view's clip transform sends each texel's direction to that texel's centre.
    #[test]
    fn view_texels_project_to_their_texels() {
        for view in light_views(&point(Vec3::ONE, None), 8) {
            let clip = view_to_clip(&view, (0.01, 100.0));
            for (ix, iy) in [(0u32, 0u32), (3, 5), (7, 7)] {
                let ndc = rsm_texel_ndc(ix, iy, 8);
                let p = clip.project_point3(view.frame.position + view_texel_direction(ndc, &view));
                assert!((Vec2::new(p.x, p.y) - ndc).length() < 1e-4, "{p} vs {ndc}");
            }
        }
    }
}
