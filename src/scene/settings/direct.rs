//! `settings.direct`: shadows and VAL budget of the scene's `lights`, and the RSM views each
//! light kind has.

use serde::{Deserialize, Serialize};

use crate::scene::SceneError;
use crate::scene::validate::{int_in, positive};

use super::MAX_CLUSTER_ATLAS_SIDE;

/// Views of a point light's RSM (a cube's faces) and of a spot's.
pub const POINT_VIEWS: u32 = 6;
pub const SPOT_VIEWS: u32 = 1;

/// Shadows of the direct light from the scene's `lights` (docs/measurements/many-lights.md).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DirectSettings {
    /// `"per_light"` (default: two paraboloid shadow maps per light, one hard-shadow test per
    /// pixel and light) or `"light_cluster"` (paper 003: lights grouped by minimum distance,
    /// two maps per group at a representative light, PCSS). Exact shadow rays are the CPU
    /// reference (`twin::many_lights::direct_exact`), not a GPU mode yet.
    pub shadows: DirectShadows,
    /// LightCluster's initial minimum distance between cluster centres `d_init`, m, in
    /// (0, 1e4]; default 1.
    pub d_init: f32,
    /// LightCluster's maximum view distance `z_far`, m (> 0): the minimum distance shrinks
    /// with a centre's distance `d` from the camera as `d_init (1 - d / z_far)` (paper 003 §3.1.2),
    /// so groups are finer near the camera. Default `null`: `d_init` everywhere (the paper's
    /// advice against flicker).
    pub z_far: Option<f32>,
    /// Side of each of a light's (or group's) two paraboloid shadow maps, texels, in 16..=1024;
    /// default 128. All maps share one atlas of at most [`MAX_CLUSTER_ATLAS_SIDE`] texels per
    /// side, which with `max_lights` bounds this.
    pub shadow_map_resolution: u32,
    /// Most entries `lights` may hold, in 1..=[`MAX_DIRECT_LIGHTS`]; default 128.
    pub max_lights: u32,
    /// VALs the RSMs of `lights` make per frame at most, in 1..=[`MAX_LIGHTS_VAL_BUDGET`];
    /// default 16384 (as many as the scene's `light` makes at its default `rsm_resolution`).
    /// Split among the lights by emitted flux (a spot: one RSM view, a point light: six cube
    /// faces, each light at least one texel per view, so at least 6 per point light and 1 per
    /// spot); the scene's `light` keeps its own `rsm_resolution`².
    pub val_budget: u32,
}

/// Largest `settings.direct.val_budget`.
pub const MAX_LIGHTS_VAL_BUDGET: u32 = 1 << 20;

/// How the shadows of the scene's `lights` are computed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum DirectShadows {
    /// One dual-paraboloid shadow map per light, one hard-shadow test per pixel and light.
    #[default]
    PerLight,
    /// LightCluster (paper 003): one dual-paraboloid map per group, PCSS with the group's
    /// extent as the light's radius; each light keeps its own position and intensity.
    LightCluster,
}

/// Largest `settings.direct.max_lights`.
pub const MAX_DIRECT_LIGHTS: u32 = 1024;

impl Default for DirectSettings {
    fn default() -> Self {
        Self {
            shadows: DirectShadows::PerLight,
            d_init: 1.0,
            z_far: None,
            shadow_map_resolution: 128,
            max_lights: 128,
            val_budget: 16384,
        }
    }
}

impl DirectSettings {
    /// Shadow maps per atlas side when every light has its own two maps (the most there can be).
    pub fn atlas_columns(&self) -> u32 {
        (2.0 * self.max_lights as f64).sqrt().ceil() as u32
    }

    /// Check every field and the bound on the atlas, naming the first bad field under `field`.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        let d_field = format!("{field}.d_init");
        positive(self.d_init, &d_field)?;
        if self.d_init > 1.0e4 {
            return Err(SceneError::field(d_field, format!("must be in (0, 1e4], got {}", self.d_init)));
        }
        if let Some(z_far) = self.z_far {
            positive(z_far, &format!("{field}.z_far"))?;
        }
        int_in(self.shadow_map_resolution, 16, 1024, &format!("{field}.shadow_map_resolution"))?;
        int_in(self.max_lights, 1, MAX_DIRECT_LIGHTS, &format!("{field}.max_lights"))?;
        int_in(self.val_budget, 1, MAX_LIGHTS_VAL_BUDGET, &format!("{field}.val_budget"))?;
        let side = self.atlas_columns() * self.shadow_map_resolution;
        if side > MAX_CLUSTER_ATLAS_SIDE {
            return Err(SceneError::field(
                format!("{field}.shadow_map_resolution"),
                format!(
                    "{} maps of {} texels (two per light of max_lights = {}) need an atlas of {side} texels per side, over {MAX_CLUSTER_ATLAS_SIDE}",
                    2 * self.max_lights,
                    self.shadow_map_resolution,
                    self.max_lights
                ),
            ));
        }
        Ok(())
    }
}
