//! The scene file: serde types mirroring the JSON, their validation, and their conversion to the
//! loaded types. The JSON speaks degrees and the loaded types radians; the conversion happens
//! here, once.
//!
//! ```json
//! {
//!   "meshes": [{"obj": "cornell_box/CornellBox-Original.obj", "sparse_points": 1024,
//!               "transform": {"translation": [0, 0, 0], "rotation_deg": [0, 0, 0], "scale": 1},
//!               "material": {"diffuse": [0.5, 0.5, 0.5], "specular": [0, 0, 0], "exponent": 1},
//!               "materials": {"leftWall": {"diffuse": [0.6, 0.1, 0.1]},
//!                             "floor": {"diffuse": [1, 1, 1], "diffuse_texture": "tiles.png"}},
//!               "skip_groups": ["light"]}],
//!   "light": {"position": [0, 1.9, 0], "direction": [0, -1, 0], "inner_angle_deg": 20,
//!             "outer_angle_deg": 30, "intensity": [10, 10, 10]},
//!   "camera": {"position": [0, 1, 3.5], "target": [0, 1, 0], "up": [0, 1, 0], "fov_y_deg": 40,
//!              "width": 512, "height": 512},
//!   "settings": {"quality": "balanced", "glossy": true, "seed": 1, "exposure": null,
//!                "tuning": {"rsm_resolution": 128}}
//! }
//! ```
//!
//! Unknown fields are errors. Every error names the field path, e.g.
//! `meshes[0].transform.scale: must be > 0, got -1`.

mod json;
mod light;
mod mesh;
#[cfg(test)]
mod tests;

use serde::{Deserialize, Serialize};

use super::SceneError;
pub use super::settings::SettingsDescription;
use super::settings::{POINT_VIEWS, SPOT_VIEWS};
pub(crate) use super::validate::int_in;
pub(crate) use json::key_path;
pub use json::parse_json;
pub use light::{CameraDescription, LightDescription, LightEntry, PointLightDescription};
pub use mesh::{MaterialDescription, MeshDescription, ScaleDescription, TransformDescription};

/// Most sparse points one mesh may have.
pub const MAX_SPARSE_POINTS: u32 = 65_536;
/// Largest magnitude of a world-space coordinate (a translation, the light's position, the
/// camera's position and target), m: 10,000 km, the Earth's scale. Positions are held in f64
/// and made relative to the scene's origin before they become f32 (see [`crate::scene::Scene::origin`]).
pub const MAX_COORDINATE_M: f64 = 1.0e7;
/// Smallest diagonal of a scene's extent, m: the bounding box of its meshes' vertices in world
/// space (each mesh's transform and the anchor applied), 1 mm. Below it the renderer's absolute
/// floors are no longer negligible: the spot light's inverse-square law is clamped at
/// `twin::MIN_LIGHT_DISTANCE` (0.1 mm), which turned `cornell_bunny_small.json` scaled by
/// 1e-5 (a 35 µm box) black in its direct light, and the camera's far plane at 1 mm
/// (`twin::flat::depth_range_around`) clipped the whole image at 1e-8. The 1/s² law holds
/// within 1 % down to a 0.35 mm box (scale 1e-4; `tests/integration/scale.rs`).
pub const MIN_SCENE_EXTENT_M: f64 = 1.0e-3;
/// Largest diagonal of a scene's extent (as [`MIN_SCENE_EXTENT_M`]), m: 1,000 km. The 1/s² law
/// holds within 1 % up to a 5,200 km box (`cornell_bunny_small.json` scaled by 1.5e6); from
/// 5,900 km (scale 1.7e6) its indirect image is 8-11 % too bright and its direct 1 % too dark.
pub const MAX_SCENE_EXTENT_M: f64 = 1.0e6;
/// Smallest and largest factor of a mesh's (and the anchor's) `transform.scale`, each axis:
/// 1e-7 to 1e7, a metre of model made 0.1 µm to [`MAX_COORDINATE_M`]. Wide enough that the
/// extent's bounds ([`MIN_SCENE_EXTENT_M`], [`MAX_SCENE_EXTENT_M`]), not this, limit a scene
/// scaled as a whole; narrow enough to name the field of a unit mistake such as 1e30, which
/// loaded and rendered black before.
pub const MESH_SCALE_RANGE: (f32, f32) = (1.0e-7, 1.0e7);
/// Largest image side, pixels.
pub const MAX_IMAGE_SIDE: u32 = 8192;
/// Smallest and largest RSM side, texels.
pub const RSM_RESOLUTION_RANGE: (u32, u32) = (8, 2048);
/// Largest spot light outer half-angle, degrees.
pub const MAX_OUTER_ANGLE_DEG: f32 = 80.0;
/// Open interval of the vertical field of view, degrees.
pub const FOV_Y_RANGE_DEG: (f32, f32) = (1.0, 170.0);

/// A whole scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SceneDescription {
    /// The meshes (at least one).
    pub meshes: Vec<MeshDescription>,
    /// The spot light whose RSM provides VALs; optional when an RGB-D recording or stream
    /// provides them instead (a scene with neither renders no indirect light).
    #[serde(default)]
    pub light: Option<LightDescription>,
    /// Direct lights beside `light` (docs/measurements/many-lights.md): spot lights (`{"type":
    /// "spot"}` and the fields of `light`) and point lights (`{"type": "point"}`,
    /// [`PointLightDescription`]). Each adds direct light (its shadows as
    /// `settings.tuning.direct.shadows` says) and VALs from its own RSM, the VAL budget
    /// `settings.tuning.direct.val_budget` split among them by emitted flux. At most
    /// `settings.tuning.direct.max_lights`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lights: Vec<LightEntry>,
    /// Where the virtual content sits in the world, applied after every mesh's own transform:
    /// in mixed reality, the placement in the recorded room's world frame. Default: identity.
    #[serde(default)]
    pub anchor: Option<TransformDescription>,
    /// The camera (for RGB-D replay and streams, each frame's camera replaces it).
    pub camera: CameraDescription,
    /// Render settings: a quality level and what the user wants, the research knobs under
    /// `tuning`; all have defaults.
    #[serde(default)]
    pub settings: SettingsDescription,
}

/// [`SceneDescription::frame_vals`] from its parts: whether the scene has a `light` and
/// `lights`, its `rsm_resolution`, `direct.val_budget`, and `second_bounce.vals` when it has two
/// bounces.
pub fn frame_val_parts(
    light: bool,
    lights: bool,
    rsm_resolution: u32,
    val_budget: u32,
    second_bounce_vals: Option<u32>,
) -> Vec<(&'static str, u64)> {
    let mut parts = Vec::new();
    if light {
        parts.push(("settings.tuning.rsm_resolution", u64::from(rsm_resolution).pow(2)));
    }
    if lights {
        parts.push(("settings.tuning.direct.val_budget", u64::from(val_budget)));
    }
    if let Some(vals) = second_bounce_vals {
        parts.push(("settings.tuning.second_bounce.vals", u64::from(vals)));
    }
    parts
}

impl SceneDescription {
    /// Parses scene JSON. Syntax errors, unknown or missing fields and wrong types name the
    /// field path and the line and column. Does not [validate](Self::validate) ranges.
    pub fn from_json_str(text: &str) -> Result<SceneDescription, SceneError> {
        parse_json(text)
    }

    /// The VALs a frame of this scene can make from its own lights, by the setting that
    /// bounds each part, in the order the frame appends them: the `light`'s RSM
    /// (`rsm_resolution`², only with a `light`), the RSMs of `lights` (their shared
    /// `direct.val_budget`, only with `lights`: `light` is not part of that budget, since its
    /// RSM is also its direct shadow map, docs/measurements/many-lights.md "VALs from every light's RSM"), and the second
    /// bounce's (`second_bounce.vals`, only with `bounces: 2`). VALs uploaded or from an RGB-D
    /// frame come on top.
    pub fn frame_vals(&self) -> Vec<(&'static str, u64)> {
        let s = self.settings.before_load();
        let second = (s.bounces == 2).then_some(s.second_bounce.vals);
        frame_val_parts(self.light.is_some(), !self.lights.is_empty(), s.rsm_resolution, s.direct.val_budget, second)
    }

    /// Checks every value's range and the consistency between values, naming the field path
    /// of the first problem found. Does not look at the mesh files.
    pub fn validate(&self) -> Result<(), SceneError> {
        if self.meshes.is_empty() {
            return Err(SceneError::field("meshes", "at least one mesh is required, got none"));
        }
        for (i, mesh) in self.meshes.iter().enumerate() {
            mesh.validate(&format!("meshes[{i}]"))?;
        }
        if let Some(light) = &self.light {
            light.validate("light")?;
        }
        if let Some(anchor) = &self.anchor {
            anchor.validate("anchor")?;
        }
        self.camera.validate("camera")?;
        self.settings.validate("settings")?;
        let direct = self.settings.before_load().direct;
        let max = direct.max_lights;
        if self.lights.len() > max as usize {
            return Err(SceneError::field(
                "lights",
                format!("holds {} lights, over settings.tuning.direct.max_lights = {max}", self.lights.len()),
            ));
        }
        for (i, light) in self.lights.iter().enumerate() {
            light.validate(&format!("lights[{i}]"))?;
        }
        // A texel per RSM view of every light (as `twin::light_rsms::split_val_budget` splits it).
        let minimum: u32 = self
            .lights
            .iter()
            .map(|l| match l {
                LightEntry::Spot(_) => SPOT_VIEWS,
                LightEntry::Point(_) => POINT_VIEWS,
            })
            .sum();
        let budget = direct.val_budget;
        if budget < minimum {
            return Err(SceneError::field(
                "settings.tuning.direct.val_budget",
                format!(
                    "must be at least {minimum} for these lights (one VAL per RSM view: 6 per point light, 1 per spot), got {budget}"
                ),
            ));
        }
        Ok(())
    }
}
