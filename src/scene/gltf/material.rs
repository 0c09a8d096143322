//! glTF's metallic-roughness materials as relume's normalised Phong.

use glam::Vec3;

use super::super::Material;

/// Inputs of [`phong_from_pbr`], as a glTF material gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pbr {
    /// `baseColorFactor` (RGB, linear; alpha is ignored).
    pub base_color: Vec3,
    /// `metallicFactor`, in [0, 1].
    pub metallic: f32,
    /// `roughnessFactor` (perceptual roughness), in [0, 1].
    pub roughness: f32,
    /// `KHR_materials_specular.specularFactor` (1 without the extension).
    pub specular: f32,
    /// `KHR_materials_specular.specularColorFactor` (white without the extension).
    pub specular_color: Vec3,
    /// `KHR_materials_ior.ior` (1.5 without the extension), >= 1.
    pub ior: f32,
}

impl Default for Pbr {
    fn default() -> Self {
        Pbr { base_color: Vec3::ONE, metallic: 1.0, roughness: 1.0, specular: 1.0, specular_color: Vec3::ONE, ior: 1.5 }
    }
}

/// The normalised Phong material standing for a metallic-roughness one (docs/scene-format.md "glTF"):
///
/// - specular albedo `rho_s = mix(F0, baseColor, metallic)`, with the dielectric reflectance
///   at normal incidence `F0 = min(((ior - 1) / (ior + 1))² specularColor, 1) specular`
///   (0.04 for the defaults): the glTF BRDF's Fresnel term at normal incidence, without its
///   rise at grazing angles;
/// - diffuse albedo `rho_d = baseColor (1 - metallic) (1 - rho_s)`, so `rho_d + rho_s <= 1`;
/// - Phong exponent `k = (2 / alpha² - 2) / 4` with `alpha = roughness²`: the Blinn-Phong
///   exponent whose lobe matches GGX of width `alpha` (Walter et al. 2007), divided by 4
///   because relume's lobe is around the reflected direction, where the angle is twice the
///   half-vector's; clamped to [0, [`Material::MAX_EXPONENT`]].
///
/// Inputs are clamped to their ranges first.
pub fn phong_from_pbr(pbr: Pbr) -> Material {
    let unit = |x: f32| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    let base = pbr.base_color.to_array().map(unit);
    let base = Vec3::from_array(base);
    let (metallic, roughness, specular) = (unit(pbr.metallic), unit(pbr.roughness), unit(pbr.specular));
    let ior = if pbr.ior.is_finite() { pbr.ior.max(1.0) } else { 1.5 };
    let f0 = ((ior - 1.0) / (ior + 1.0)).powi(2);
    let specular_color =
        Vec3::from_array(pbr.specular_color.to_array().map(|c| if c.is_finite() { c.max(0.0) } else { 1.0 }));
    let dielectric = (f0 * specular_color).min(Vec3::ONE) * specular;
    let rho_s = dielectric.lerp(base, metallic);
    let rho_d = base * (1.0 - metallic) * (Vec3::ONE - rho_s);
    let alpha = roughness * roughness;
    let exponent = if alpha <= 0.0 {
        Material::MAX_EXPONENT
    } else {
        ((2.0 / (alpha * alpha) - 2.0) / 4.0).clamp(0.0, Material::MAX_EXPONENT)
    };
    Material { diffuse: rho_d, specular: rho_s, exponent, diffuse_texture: None }
}
