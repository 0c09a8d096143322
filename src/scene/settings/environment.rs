//! `settings.environment`: light from the directions no VAL covers (`mr::environment`
//! computes it).

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::scene::SceneError;
use crate::scene::validate::{int_in, positive};

/// Largest `rows` (the grid has `2 rows²` cells, each a VAL).
pub const MAX_ENVIRONMENT_ROWS: u32 = 64;

/// Where the environment comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum EnvironmentSource {
    /// No environment (the default).
    #[default]
    None,
    /// The frame's mean observed radiance in the directions no VAL covers (module docs).
    Auto,
    /// A user's equirectangular HDR map (`map`).
    Map,
}

/// How `auto` spreads its level over the unseen directions (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum EnvironmentDistribution {
    /// One radiance in every unseen direction.
    Uniform,
    /// The CIE standard overcast sky about the frame's up: `(1 + 2 cos theta) / 3` of the
    /// zenith's radiance above the horizon, a third of it below (the default: nearer the
    /// truth than `uniform` when the light comes from above, docs/measurements/mixed-reality.md
    /// "Differential rendering and the environment").
    #[default]
    Overcast,
}

/// `settings.environment` of a scene file (replay and the service's streams); every field has
/// a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(default, deny_unknown_fields)]
pub struct EnvironmentSettings {
    pub source: EnvironmentSource,
    /// Path of the equirectangular `.hdr` / `.exr` map (`map`), relative to the scene file; on
    /// the service relative to and confined to its asset directory, at most `max_mesh_bytes`
    /// on disk and `max_pixels` pixels.
    pub map: Option<String>,
    /// Radiance (W/(m² sr)) of a map value of 1; > 0, default 1.
    pub scale: f32,
    /// Turn of the map about `up` (degrees), default 0.
    pub rotation_deg: f32,
    /// World up (the map's top row), default +z (the TUM recordings' world).
    pub up: [f32; 3],
    /// Rows of the direction grid, 2..=64 and even (columns: twice as many); default 8, 128
    /// VALs.
    pub rows: u32,
    /// `auto` only: how the level is spread over the unseen directions; default `overcast`.
    pub distribution: EnvironmentDistribution,
    /// The albedo of the real surfaces around the virtual content, when it is known (a sheet of
    /// white paper: about 0.8), in (0, 1]. With the differential pass's receivers it calibrates
    /// the light from the frame ([`calibrated_level`]): `auto`'s level becomes the one at which
    /// the receivers reflect with this albedo instead of the least at albedo <= 1, and
    /// `calibrate_map` scales a map the same way. Default: unknown.
    pub albedo: Option<f32>,
    /// `map` only: scale the map each frame so that the receivers' brightness is what it
    /// reflects (with `albedo`, or the least scale at albedo <= 1): a light probe in any units
    /// brought to the camera's. Needs the differential pass (its receivers); default false.
    pub calibrate_map: bool,
}

impl Default for EnvironmentSettings {
    fn default() -> Self {
        Self {
            source: EnvironmentSource::None,
            map: None,
            scale: 1.0,
            rotation_deg: 0.0,
            up: [0.0, 0.0, 1.0],
            rows: 8,
            distribution: EnvironmentDistribution::Overcast,
            albedo: None,
            calibrate_map: false,
        }
    }
}

impl EnvironmentSettings {
    /// Ranges of every field and their consistency, naming the field of the first problem.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        let e = self;
        positive(e.scale, &format!("{field}.scale"))?;
        if !e.rotation_deg.is_finite() {
            return Err(SceneError::field(
                format!("{field}.rotation_deg"),
                format!("must be finite, got {}", e.rotation_deg),
            ));
        }
        let up = Vec3::from(e.up);
        if !up.is_finite() || up.length_squared() < 1e-12 {
            return Err(SceneError::field(
                format!("{field}.up"),
                format!("must be a finite non-zero vector, got {up}"),
            ));
        }
        int_in(e.rows, 2, MAX_ENVIRONMENT_ROWS, &format!("{field}.rows"))?;
        if !e.rows.is_multiple_of(2) {
            return Err(SceneError::field(format!("{field}.rows"), format!("must be even, got {}", e.rows)));
        }
        if let Some(albedo) = e.albedo
            && !(albedo > 0.0 && albedo <= 1.0)
        {
            return Err(SceneError::field(format!("{field}.albedo"), format!("must be in (0, 1], got {albedo}")));
        }
        if e.calibrate_map && e.source != EnvironmentSource::Map {
            return Err(SceneError::field(
                format!("{field}.calibrate_map"),
                "calibrates a map: only with source \"map\"".to_owned(),
            ));
        }
        if e.source == EnvironmentSource::Map && e.map.is_none() {
            return Err(SceneError::field(format!("{field}.map"), "source \"map\" needs a map path".to_owned()));
        }
        Ok(())
    }
}
