//! The lights and the camera of a scene file. The JSON speaks degrees and the loaded types
//! radians; the conversion happens here, once.

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

use super::{FOV_Y_RANGE_DEG, MAX_IMAGE_SIDE, MAX_OUTER_ANGLE_DEG};
use crate::scene::validate::{at_least, coordinates, finite, finite3, int_in, positive};
use crate::scene::{Camera, Light, PointLight, SceneError, SpotLight};

/// The spot light.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LightDescription {
    /// World-space position, m (f64, see [`MAX_COORDINATE_M`]).
    pub position: [f64; 3],
    /// World-space axis direction; normalised on load, must be nonzero.
    pub direction: [f32; 3],
    /// Inner half-angle, degrees, in [0, `outer_angle_deg`].
    pub inner_angle_deg: f32,
    /// Outer half-angle, degrees, in (0, 80].
    pub outer_angle_deg: f32,
    /// Radiant intensity on the axis, W/sr, linear RGB, each >= 0.
    pub intensity: [f32; 3],
    /// World-space up of the light's frame: the RSM grid's rows run across it (as a camera's
    /// `up`); finite, nonzero, not parallel to `direction`. Default: +Y, or +Z for a light
    /// within about 8° of vertical ([`SpotLight::default_up`]). A scene turned as a whole turns
    /// its light's `up` with it, so the RSM grid stays put on the scene.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up: Option<[f32; 3]>,
}

impl LightDescription {
    /// The light, its position relative to `origin` (the scene's [`crate::scene::Scene::origin`];
    /// assumes [`SceneDescription::validate`] passed).
    pub fn to_spot_light(&self, origin: DVec3) -> SpotLight {
        let direction = Vec3::from_array(self.direction).normalize_or(Vec3::NEG_Y);
        SpotLight {
            position: (DVec3::from_array(self.position) - origin).as_vec3(),
            direction,
            inner_angle: self.inner_angle_deg.to_radians(),
            outer_angle: self.outer_angle_deg.to_radians(),
            intensity: Vec3::from_array(self.intensity),
            up: self
                .up
                .and_then(|up| Vec3::from_array(up).try_normalize())
                .unwrap_or_else(|| SpotLight::default_up(direction)),
        }
    }

    /// Checks ranges and consistency; `field` is this value's path (`light`, `camera`).
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        coordinates(self.position, &format!("{field}.position"))?;
        let direction_field = format!("{field}.direction");
        finite3(self.direction, &direction_field)?;
        if Vec3::from_array(self.direction).length() == 0.0 {
            return Err(SceneError::field(direction_field, "must be nonzero, got [0, 0, 0]"));
        }
        let outer_field = format!("{field}.outer_angle_deg");
        finite(self.outer_angle_deg, &outer_field)?;
        if !(self.outer_angle_deg > 0.0 && self.outer_angle_deg <= MAX_OUTER_ANGLE_DEG) {
            return Err(SceneError::field(
                outer_field,
                format!("must be in (0, {MAX_OUTER_ANGLE_DEG}], got {}", self.outer_angle_deg),
            ));
        }
        let inner_field = format!("{field}.inner_angle_deg");
        finite(self.inner_angle_deg, &inner_field)?;
        if !(self.inner_angle_deg >= 0.0 && self.inner_angle_deg <= self.outer_angle_deg) {
            return Err(SceneError::field(
                inner_field,
                format!("must be in [0, outer_angle_deg = {}], got {}", self.outer_angle_deg, self.inner_angle_deg),
            ));
        }
        let intensity_field = format!("{field}.intensity");
        for (i, &value) in self.intensity.iter().enumerate() {
            at_least(value, 0.0, &format!("{intensity_field}[{i}]"))?;
        }
        if let Some(up) = self.up {
            let up_field = format!("{field}.up");
            finite3(up, &up_field)?;
            let Some(unit) = Vec3::from_array(up).try_normalize() else {
                return Err(SceneError::field(up_field, format!("must be nonzero, got {up:?}")));
            };
            // sin of the angle between direction and up; below ~0.06 degrees the frame is
            // ill-defined (as for the camera).
            if Vec3::from_array(self.direction).normalize_or(Vec3::NEG_Y).cross(unit).length() < 1e-3 {
                return Err(SceneError::field(
                    up_field,
                    format!("must not be parallel to the light's direction, got {up:?}"),
                ));
            }
        }
        Ok(())
    }
}

/// One entry of the scene's `lights`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum LightEntry {
    /// A spot light: the fields of `light`.
    Spot(LightDescription),
    /// An omnidirectional point light.
    Point(PointLightDescription),
}

/// An omnidirectional point light of `lights`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PointLightDescription {
    /// World-space position, m (f64, see [`MAX_COORDINATE_M`]).
    pub position: [f64; 3],
    /// Radiant intensity, W/sr, linear RGB, each >= 0.
    pub intensity: [f32; 3],
    /// Range, m, > 0: beyond it the light adds nothing; the inverse-square falloff is windowed
    /// by `(1 - (d / range)^4)^2` (`twin::many_lights::range_window`). Default: none (no window).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<f32>,
}

impl PointLightDescription {
    /// Checks ranges; `field` is this value's path (`lights[3]`).
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        coordinates(self.position, &format!("{field}.position"))?;
        for (i, &value) in self.intensity.iter().enumerate() {
            at_least(value, 0.0, &format!("{field}.intensity[{i}]"))?;
        }
        if let Some(range) = self.range {
            positive(range, &format!("{field}.range"))?;
        }
        Ok(())
    }

    /// The light, its position relative to `origin` (assumes [`Self::validate`] passed).
    pub fn to_point_light(&self, origin: DVec3) -> PointLight {
        PointLight {
            position: (DVec3::from_array(self.position) - origin).as_vec3(),
            intensity: Vec3::from_array(self.intensity),
            range: self.range,
        }
    }
}

impl LightEntry {
    /// The light, its position relative to `origin` (assumes validation passed).
    pub fn to_light(&self, origin: DVec3) -> Light {
        match self {
            LightEntry::Spot(spot) => Light::Spot(spot.to_spot_light(origin)),
            LightEntry::Point(point) => Light::Point(point.to_point_light(origin)),
        }
    }

    /// Checks ranges; `field` is this value's path (`lights[3]`).
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        match self {
            LightEntry::Spot(spot) => spot.validate(field),
            LightEntry::Point(point) => point.validate(field),
        }
    }
}

/// The camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CameraDescription {
    /// World-space eye position, m (f64, see [`MAX_COORDINATE_M`]).
    pub position: [f64; 3],
    /// World-space point looked at, m (f64).
    pub target: [f64; 3],
    /// World-space up direction; default +Y.
    #[serde(default = "default_up")]
    pub up: [f32; 3],
    /// Vertical field of view (full angle), degrees, in (1, 170).
    pub fov_y_deg: f32,
    /// Image width, pixels, in 1..=8192.
    pub width: u32,
    /// Image height, pixels, in 1..=8192.
    pub height: u32,
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}

impl CameraDescription {
    /// The camera, its position and target relative to `origin` (the scene's
    /// [`crate::scene::Scene::origin`]; assumes [`SceneDescription::validate`] passed).
    pub fn to_camera(&self, origin: DVec3) -> Camera {
        Camera {
            position: (DVec3::from_array(self.position) - origin).as_vec3(),
            target: (DVec3::from_array(self.target) - origin).as_vec3(),
            up: Vec3::from_array(self.up).normalize_or(Vec3::Y),
            fov_y: self.fov_y_deg.to_radians(),
            width: self.width,
            height: self.height,
        }
    }

    /// Checks ranges and consistency; `field` is this value's path (`light`, `camera`).
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        coordinates(self.position, &format!("{field}.position"))?;
        let target_field = format!("{field}.target");
        coordinates(self.target, &target_field)?;
        let up_field = format!("{field}.up");
        finite3(self.up, &up_field)?;
        let view = (DVec3::from_array(self.target) - DVec3::from_array(self.position)).as_vec3();
        let Some(view) = view.try_normalize() else {
            return Err(SceneError::field(
                target_field,
                format!("must differ from the camera position, got {:?}", self.target),
            ));
        };
        let Some(up) = Vec3::from_array(self.up).try_normalize() else {
            return Err(SceneError::field(up_field, format!("must be nonzero, got {:?}", self.up)));
        };
        // sin of the angle between view and up; below ~0.06 degrees the basis is ill-defined.
        if view.cross(up).length() < 1e-3 {
            return Err(SceneError::field(
                up_field,
                format!("must not be parallel to the view direction (target - position), got {:?}", self.up),
            ));
        }
        let fov_field = format!("{field}.fov_y_deg");
        finite(self.fov_y_deg, &fov_field)?;
        let (lo, hi) = FOV_Y_RANGE_DEG;
        if !(self.fov_y_deg > lo && self.fov_y_deg < hi) {
            return Err(SceneError::field(fov_field, format!("must be in ({lo}, {hi}), got {}", self.fov_y_deg)));
        }
        int_in(self.width, 1, MAX_IMAGE_SIDE, &format!("{field}.width"))?;
        int_in(self.height, 1, MAX_IMAGE_SIDE, &format!("{field}.height"))?;
        Ok(())
    }
}
