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
//!   "settings": {"rsm_resolution": 128, "glossy": true, "seed": 1, "exposure": null}
//! }
//! ```
//!
//! Unknown fields are errors. Every error names the field path, e.g.
//! `meshes[0].transform.scale: must be > 0, got -1`.

use std::collections::BTreeMap;
use std::fmt;

use glam::{DMat4, DQuat, DVec3, EulerRot, Vec3};
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use super::settings::{
    ClusterSettings, DEFAULT_BOUNCES, DirectSettings, EnvironmentSettings, IsmSettings, MrSettings, Occlusion,
    OcclusionRule, OcclusionSetting, POINT_VIEWS, RgbdSettings, SPOT_VIEWS, SecondBounceSettings, SparseShading,
};
pub(crate) use super::validate::int_in;
use super::validate::{at_least, coordinates, finite, finite3, in_closed, positive, unit_interval3};
use super::{Camera, Material, SceneError, Settings, SpotLight};

/// Most sparse points one mesh may have.
pub const MAX_SPARSE_POINTS: u32 = 65_536;
/// Largest magnitude of a world-space coordinate (a translation, the light's position, the
/// camera's position and target), m: 10,000 km, the Earth's scale. Positions are held in f64
/// and made relative to the scene's origin before they become f32 (see [`super::Scene::origin`]).
pub const MAX_COORDINATE_M: f64 = 1.0e7;
/// Largest image side, pixels.
pub const MAX_IMAGE_SIDE: u32 = 8192;
/// Smallest and largest RSM side, texels.
pub const RSM_RESOLUTION_RANGE: (u32, u32) = (8, 2048);
/// Largest spot light outer half-angle, degrees.
pub const MAX_OUTER_ANGLE_DEG: f32 = 80.0;
/// Open interval of the vertical field of view, degrees.
pub const FOV_Y_RANGE_DEG: (f32, f32) = (1.0, 170.0);

/// Largest amount by which `diffuse + specular` may exceed 1 before it counts as an error
/// (absorbs decimal-to-binary rounding of values such as 0.7 + 0.3).
const ENERGY_TOLERANCE: f32 = 1e-6;

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
    /// Direct lights beside `light` (README "Many direct lights"): spot lights (`{"type":
    /// "spot"}` and the fields of `light`) and point lights (`{"type": "point"}`,
    /// [`PointLightDescription`]). Each adds direct light (its shadows as
    /// `settings.direct.shadows` says) and VALs from its own RSM, the VAL budget
    /// `settings.direct.val_budget` split among them by emitted flux. At most
    /// `settings.direct.max_lights`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lights: Vec<LightEntry>,
    /// Where the virtual content sits in the world, applied after every mesh's own transform:
    /// in mixed reality, the placement in the recorded room's world frame. Default: identity.
    #[serde(default)]
    pub anchor: Option<TransformDescription>,
    /// The camera (for RGB-D replay and streams, each frame's camera replaces it).
    pub camera: CameraDescription,
    /// Render settings; all have defaults.
    #[serde(default)]
    pub settings: SettingsDescription,
}

/// One mesh entry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MeshDescription {
    /// OBJ file, relative to the scene file's directory. With `obj_text`, only the mesh's name
    /// (its stem) and the name used in messages. Required unless `gltf` is given.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub obj: String,
    /// glTF 2.0 file (`.gltf` or `.glb`) instead of `obj`, relative to the scene file's
    /// directory: every mesh of its default scene, placed by its node transforms, becomes this
    /// one mesh (README "glTF"); `skip_groups` names nodes and `materials` glTF materials.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gltf: Option<String>,
    /// The OBJ file's text inline, instead of reading `obj`. It may not load MTL files
    /// (`mtllib`): give its materials with `material`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obj_text: Option<String>,
    /// Model-to-world transform; identity when absent.
    #[serde(default)]
    pub transform: TransformDescription,
    /// Number of sparse shading points on this mesh, in 1..=65536.
    pub sparse_points: u32,
    /// Replaces every material of the mesh (those from the MTL and the default one).
    #[serde(default)]
    pub material: Option<MaterialDescription>,
    /// Replaces MTL materials by name; wins over `material`. Unknown names are errors.
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialDescription>,
    /// OBJ groups/objects (`g`/`o` names), or glTF nodes (with their children), not to load.
    /// Unknown names are errors.
    #[serde(default)]
    pub skip_groups: Vec<String>,
}

/// Scale, then rotation, then translation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TransformDescription {
    /// Translation, m (f64: a mesh may sit far from the origin, see [`MAX_COORDINATE_M`]).
    #[serde(default)]
    pub translation: [f64; 3],
    /// Euler angles about X, then Y, then Z (glam `EulerRot::XYZ`), degrees.
    #[serde(default)]
    pub rotation_deg: [f32; 3],
    /// Uniform or per-axis scale, each > 0.
    #[serde(default)]
    pub scale: ScaleDescription,
}

impl Default for TransformDescription {
    fn default() -> Self {
        TransformDescription { translation: [0.0; 3], rotation_deg: [0.0; 3], scale: ScaleDescription::default() }
    }
}

/// A scale: a single number, or `[x, y, z]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, utoipa::ToSchema)]
#[serde(untagged)]
pub enum ScaleDescription {
    /// The same factor on every axis.
    Uniform(f32),
    /// One factor per axis.
    PerAxis([f32; 3]),
}

impl Default for ScaleDescription {
    fn default() -> Self {
        ScaleDescription::Uniform(1.0)
    }
}

impl ScaleDescription {
    /// The per-axis factors.
    pub fn to_vec3(self) -> Vec3 {
        match self {
            ScaleDescription::Uniform(s) => Vec3::splat(s),
            ScaleDescription::PerAxis(s) => Vec3::from_array(s),
        }
    }
}

impl<'de> Deserialize<'de> for ScaleDescription {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct ScaleVisitor;

        impl<'de> Visitor<'de> for ScaleVisitor {
            type Value = ScaleDescription;

            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a number or an array [x, y, z]")
            }

            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
                Ok(ScaleDescription::Uniform(v as f32))
            }

            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
                Ok(ScaleDescription::Uniform(v as f32))
            }

            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
                Ok(ScaleDescription::Uniform(v as f32))
            }

            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
                let mut xyz = [0.0f32; 3];
                for (i, value) in xyz.iter_mut().enumerate() {
                    *value = seq.next_element()?.ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                if seq.next_element::<de::IgnoredAny>()?.is_some() {
                    return Err(de::Error::invalid_length(4, &self));
                }
                Ok(ScaleDescription::PerAxis(xyz))
            }
        }

        deserializer.deserialize_any(ScaleVisitor)
    }
}

/// A material. Each channel in [0, 1], `diffuse + specular <= 1` per channel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MaterialDescription {
    /// Diffuse albedo `rho_d`, linear RGB; default 0.5 grey.
    #[serde(default = "default_diffuse")]
    pub diffuse: [f32; 3],
    /// Specular albedo `rho_s`, linear RGB; default black.
    #[serde(default)]
    pub specular: [f32; 3],
    /// Phong exponent `k`, in [0, 1e4]; default 1.
    #[serde(default = "default_exponent")]
    pub exponent: f32,
    /// Diffuse texture (PNG or OpenEXR), relative to the scene file's directory; the albedo is
    /// `diffuse` times the texture. Default none (the MTL's `map_Kd` is replaced too).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diffuse_texture: Option<String>,
}

fn default_diffuse() -> [f32; 3] {
    Material::DEFAULT.diffuse.to_array()
}

fn default_exponent() -> f32 {
    Material::DEFAULT.exponent
}

impl Default for MaterialDescription {
    fn default() -> Self {
        MaterialDescription {
            diffuse: default_diffuse(),
            specular: [0.0; 3],
            exponent: default_exponent(),
            diffuse_texture: None,
        }
    }
}

impl MaterialDescription {
    /// The material (assumes [`MaterialDescription::validate`] passed), without its texture:
    /// `diffuse_texture` is `None` here and set by the loader, which owns the texture table.
    pub fn to_material(&self) -> Material {
        Material {
            diffuse: Vec3::from_array(self.diffuse),
            specular: Vec3::from_array(self.specular),
            exponent: self.exponent,
            diffuse_texture: None,
        }
    }

    /// Checks ranges and energy conservation; `field` is this material's path.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        unit_interval3(self.diffuse, &format!("{field}.diffuse"))?;
        unit_interval3(self.specular, &format!("{field}.specular"))?;
        in_closed(self.exponent, 0.0, Material::MAX_EXPONENT, &format!("{field}.exponent"))?;
        if self.diffuse_texture.as_ref().is_some_and(|path| path.trim().is_empty()) {
            return Err(SceneError::field(
                format!("{field}.diffuse_texture"),
                "must name an image file, got an empty string",
            ));
        }
        for (channel, name) in ["red", "green", "blue"].iter().enumerate() {
            let (d, s) = (self.diffuse[channel], self.specular[channel]);
            if d + s > 1.0 + ENERGY_TOLERANCE {
                return Err(SceneError::field(
                    format!("{field}.specular[{channel}]"),
                    format!(
                        "diffuse + specular must be <= 1 in every channel (energy conservation), \
                         got {d} + {s} = {} in channel {channel} ({name})",
                        d + s
                    ),
                ));
            }
        }
        Ok(())
    }
}

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
    /// The light, its position relative to `origin` (the scene's [`super::Scene::origin`];
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
    pub fn to_point_light(&self, origin: DVec3) -> super::PointLight {
        super::PointLight {
            position: (DVec3::from_array(self.position) - origin).as_vec3(),
            intensity: Vec3::from_array(self.intensity),
            range: self.range,
        }
    }
}

impl LightEntry {
    /// The light, its position relative to `origin` (assumes validation passed).
    pub fn to_light(&self, origin: DVec3) -> super::Light {
        match self {
            LightEntry::Spot(spot) => super::Light::Spot(spot.to_spot_light(origin)),
            LightEntry::Point(point) => super::Light::Point(point.to_point_light(origin)),
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
    /// [`super::Scene::origin`]; assumes [`SceneDescription::validate`] passed).
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

/// Render settings; every field has a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SettingsDescription {
    /// RSM side, texels, in 8..=2048; default 128.
    #[serde(default = "default_rsm_resolution")]
    pub rsm_resolution: u32,
    /// Allow the glossy gather; default true.
    #[serde(default = "default_glossy")]
    pub glossy: bool,
    /// Seed for sparse point placement; default 1.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Exposure multiplier (> 0) before tone mapping; default `null` (automatic).
    #[serde(default)]
    pub exposure: Option<f32>,
    /// Sparse points each vertex interpolates from (paper eqs. 12-13), 1..=16; default 8.
    #[serde(default = "default_neighbours")]
    pub interpolation_neighbours: u32,
    /// Indirect visibility: `"auto"` (default), `"off"`, `"disks"` (docs/design.md §4 step 3),
    /// `"clusters"` (shadow maps of k-means clusters of the VALs, `clusters` below) or `"ism"`
    /// (imperfect shadow maps of VALs drawn by flux, `ism` below). `"auto"`
    /// is `"disks"` when the scene can occlude itself: more than one mesh, or a mesh that is
    /// neither a convex object nor a convex room ([`crate::scene::Scene`]). The JSON key is
    /// `visibility`; `occlusion` is its deprecated alias (accepted, not both at once).
    #[serde(default, rename = "visibility", alias = "occlusion")]
    pub occlusion: OcclusionSetting,
    /// How disc occluders combine: `"product"` (default: measured closer to exact) or `"sum"`
    /// (the paper's).
    #[serde(default)]
    pub occlusion_rule: OcclusionRule,
    /// How RGB-D frames become VALs (replay and streams); every field has a default.
    #[serde(default)]
    pub rgbd: RgbdSettings,
    /// Mixed-reality compositing (replay and streams): differential rendering onto the real
    /// surfaces; every field has a default.
    #[serde(default)]
    pub mr: MrSettings,
    /// Light from the directions no VAL covers (replay and streams): `source` `"none"`
    /// (default), `"auto"` or `"map"`; `auto`'s `distribution` `"uniform"` or `"overcast"`
    /// (`mr::environment`).
    #[serde(default)]
    pub environment: EnvironmentSettings,
    /// The sparse method's interpolation, light bound and subdivision; every field has a
    /// default.
    #[serde(default)]
    pub sparse: SparseShading,
    /// The `"clusters"` visibility mode; every field has a default.
    #[serde(default)]
    pub clusters: ClusterSettings,
    /// The `"ism"` visibility mode (imperfect shadow maps); every field has a default.
    #[serde(default)]
    pub ism: IsmSettings,
    /// Direct light from the scene's `lights`: how their shadows are computed and the limit
    /// on their count; every field has a default.
    #[serde(default)]
    pub direct: DirectSettings,
    /// Bounces of indirect light, 1 or 2; default 1. With 2, points on the meshes lit by the
    /// first bounce's VALs become second-bounce VALs (paper 004 §4.1, `second_bounce`).
    #[serde(default = "default_bounces")]
    pub bounces: u32,
    /// The second bounce's points and VAL budget (used when `bounces` is 2); every field has a
    /// default.
    #[serde(default)]
    pub second_bounce: SecondBounceSettings,
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
        parts.push(("settings.rsm_resolution", u64::from(rsm_resolution).pow(2)));
    }
    if lights {
        parts.push(("settings.direct.val_budget", u64::from(val_budget)));
    }
    if let Some(vals) = second_bounce_vals {
        parts.push(("settings.second_bounce.vals", u64::from(vals)));
    }
    parts
}

fn default_neighbours() -> u32 {
    super::DEFAULT_NEIGHBOURS
}

fn default_rsm_resolution() -> u32 {
    128
}

fn default_glossy() -> bool {
    true
}

fn default_bounces() -> u32 {
    DEFAULT_BOUNCES
}

fn default_seed() -> u64 {
    1
}

impl Default for SettingsDescription {
    fn default() -> Self {
        SettingsDescription {
            rsm_resolution: default_rsm_resolution(),
            glossy: default_glossy(),
            seed: default_seed(),
            exposure: None,
            interpolation_neighbours: default_neighbours(),
            occlusion: OcclusionSetting::Auto,
            occlusion_rule: OcclusionRule::Product,
            rgbd: RgbdSettings::default(),
            mr: MrSettings::default(),
            environment: EnvironmentSettings::default(),
            sparse: SparseShading::default(),
            clusters: ClusterSettings::default(),
            ism: IsmSettings::default(),
            direct: DirectSettings::default(),
            bounces: default_bounces(),
            second_bounce: SecondBounceSettings::default(),
        }
    }
}

impl SettingsDescription {
    /// The settings (assumes [`SceneDescription::validate`] passed); `self_occluding` resolves
    /// `"auto"` occlusion.
    pub fn to_settings(&self, self_occluding: bool) -> Settings {
        Settings {
            rsm_resolution: self.rsm_resolution,
            glossy: self.glossy,
            seed: self.seed,
            exposure: self.exposure,
            interpolation_neighbours: self.interpolation_neighbours,
            occlusion: match self.occlusion {
                OcclusionSetting::Off => Occlusion::Off,
                OcclusionSetting::Disks => Occlusion::Disks,
                OcclusionSetting::Clusters => Occlusion::Clusters,
                OcclusionSetting::Ism => Occlusion::Ism,
                OcclusionSetting::Auto if self_occluding => Occlusion::Disks,
                OcclusionSetting::Auto => Occlusion::Off,
            },
            occlusion_rule: self.occlusion_rule,
            rgbd: self.rgbd,
            mr: self.mr,
            sparse: self.sparse,
            clusters: self.clusters,
            ism: self.ism,
            direct: self.direct,
            bounces: self.bounces,
            second_bounce: self.second_bounce,
        }
    }

    fn validate(&self, field: &str) -> Result<(), SceneError> {
        let (lo, hi) = RSM_RESOLUTION_RANGE;
        int_in(self.rsm_resolution, lo, hi, &format!("{field}.rsm_resolution"))?;
        int_in(self.interpolation_neighbours, 1, super::MAX_NEIGHBOURS, &format!("{field}.interpolation_neighbours"))?;
        if let Some(exposure) = self.exposure {
            positive(exposure, &format!("{field}.exposure"))?;
        }
        self.sparse.validate(&format!("{field}.sparse"))?;
        self.rgbd.validate(&format!("{field}.rgbd"))?;
        self.mr.validate(&format!("{field}.mr"))?;
        self.environment.validate(&format!("{field}.environment"))?;
        self.clusters.validate(&format!("{field}.clusters"))?;
        self.ism.validate(&format!("{field}.ism"))?;
        self.direct.validate(&format!("{field}.direct"))?;
        int_in(self.bounces, 1, 2, &format!("{field}.bounces"))?;
        self.second_bounce.validate(&format!("{field}.second_bounce"))
    }
}

impl TransformDescription {
    /// The model-to-world matrix: scale, then rotation, then translation, in f64 so that
    /// composing it with an anchor and the scene's origin keeps millimetres at 10,000 km.
    pub fn to_matrix(&self) -> DMat4 {
        let [x, y, z] = self.rotation_deg.map(|d| f64::from(d).to_radians());
        DMat4::from_scale_rotation_translation(
            self.scale.to_vec3().as_dvec3(),
            DQuat::from_euler(EulerRot::XYZ, x, y, z),
            DVec3::from_array(self.translation),
        )
    }

    /// Checks that every number is finite and every scale factor positive; `field` is this
    /// transform's path.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        coordinates(self.translation, &format!("{field}.translation"))?;
        finite3(self.rotation_deg, &format!("{field}.rotation_deg"))?;
        let scale_field = format!("{field}.scale");
        match self.scale {
            ScaleDescription::Uniform(s) => positive(s, &scale_field),
            ScaleDescription::PerAxis(s) => {
                for (i, &value) in s.iter().enumerate() {
                    positive(value, &format!("{scale_field}[{i}]"))?;
                }
                Ok(())
            }
        }
    }
}

impl MeshDescription {
    fn validate(&self, field: &str) -> Result<(), SceneError> {
        match (&self.gltf, self.obj.is_empty()) {
            (None, true) => {
                return Err(SceneError::field(
                    format!("{field}.obj"),
                    "required field is missing: give `obj` (an OBJ file) or `gltf` (a glTF 2.0 file)",
                ));
            }
            (None, false) if self.obj.trim().is_empty() => {
                return Err(SceneError::field(format!("{field}.obj"), "must name an OBJ file, got an empty string"));
            }
            (Some(_), false) => {
                return Err(SceneError::field(format!("{field}.gltf"), "give `obj` or `gltf`, not both"));
            }
            (Some(gltf), true) if gltf.trim().is_empty() => {
                return Err(SceneError::field(format!("{field}.gltf"), "must name a glTF file, got an empty string"));
            }
            (Some(_), true) if self.obj_text.is_some() => {
                return Err(SceneError::field(format!("{field}.obj_text"), "only with `obj`, not with `gltf`"));
            }
            _ => {}
        }
        self.transform.validate(&format!("{field}.transform"))?;
        int_in(self.sparse_points, 1, MAX_SPARSE_POINTS, &format!("{field}.sparse_points"))?;
        if let Some(material) = &self.material {
            material.validate(&format!("{field}.material"))?;
        }
        for (name, material) in &self.materials {
            material.validate(&key_path(&format!("{field}.materials"), name))?;
        }
        Ok(())
    }
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
    /// RSM is also its direct shadow map, README "VALs from every light's RSM"), and the second
    /// bounce's (`second_bounce.vals`, only with `bounces: 2`). VALs uploaded or from an RGB-D
    /// frame come on top.
    pub fn frame_vals(&self) -> Vec<(&'static str, u64)> {
        let s = &self.settings;
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
        let max = self.settings.direct.max_lights;
        if self.lights.len() > max as usize {
            return Err(SceneError::field(
                "lights",
                format!("holds {} lights, over settings.direct.max_lights = {max}", self.lights.len()),
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
        let budget = self.settings.direct.val_budget;
        if budget < minimum {
            return Err(SceneError::field(
                "settings.direct.val_budget",
                format!(
                    "must be at least {minimum} for these lights (one VAL per RSM view: 6 per point light, 1 per spot), got {budget}"
                ),
            ));
        }
        Ok(())
    }
}

/// Parses JSON text into any `T`, with the errors of [`SceneDescription::from_json_str`]: a
/// [`SceneError::Json`] naming the field path, line and column.
pub fn parse_json<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, SceneError> {
    serde_json::from_str(text).map_err(|error| json_error(text, &error))
}

/// `parent.key`, or `parent["key"]` when the key is not a plain identifier.
pub(crate) fn key_path(parent: &str, key: &str) -> String {
    let plain = !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    match (parent.is_empty(), plain) {
        (true, true) => key.to_owned(),
        (false, true) => format!("{parent}.{key}"),
        (_, false) => format!("{parent}[{key:?}]"),
    }
}

/// Turns a serde_json error into a [`SceneError::Json`] naming the field path at the error's
/// position.
fn json_error(text: &str, error: &serde_json::Error) -> SceneError {
    let (line, column) = (error.line(), error.column());
    let mut message = error.to_string();
    let suffix = format!(" at line {line} column {column}");
    if let Some(stripped) = message.strip_suffix(&suffix) {
        message = stripped.to_owned();
    }
    let mut offset = byte_offset(text, line, column);
    // Syntax errors point at the offending character (which may close an object); data errors
    // point just past what was read.
    if error.is_syntax() {
        offset = offset.saturating_sub(1);
    }
    let mut field = json_path_at(text, offset);
    // serde reports a missing field at the end of the object that lacks it.
    if let Some(name) = backticked_after(&message, "missing field ") {
        field = key_path(&field, &name);
        message = "required field is missing".to_owned();
    }
    if field.is_empty() {
        field = "(root)".to_owned();
    }
    SceneError::Json { field, message, line, column }
}

/// The text between backticks right after `prefix` at the start of `message`.
fn backticked_after(message: &str, prefix: &str) -> Option<String> {
    let rest = message.strip_prefix(prefix)?.strip_prefix('`')?;
    rest.split_once('`').map(|(name, _)| name.to_owned())
}

/// Byte offset just past the 1-based (line, column) character serde_json reports.
fn byte_offset(text: &str, line: usize, column: usize) -> usize {
    let line_start: usize = text.split_inclusive('\n').take(line.saturating_sub(1)).map(str::len).sum();
    (line_start + column).min(text.len())
}

/// One step of a JSON path.
enum Frame {
    Object { key: Option<String>, expecting_key: bool },
    Array { index: usize },
}

/// The path (`meshes[0].transform.scale`) of the value being read when a parser has consumed
/// the first `offset` bytes of `text`. A small tokenizer that tracks the open objects and
/// arrays; it does not validate.
fn json_path_at(text: &str, offset: usize) -> String {
    let bytes = &text.as_bytes()[..offset.min(text.len())];
    let mut stack: Vec<Frame> = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'{' => stack.push(Frame::Object { key: None, expecting_key: true }),
            b'[' => stack.push(Frame::Array { index: 0 }),
            b'}' | b']' => {
                stack.pop();
            }
            b',' => match stack.last_mut() {
                Some(Frame::Object { key, expecting_key }) => {
                    *key = None;
                    *expecting_key = true;
                }
                Some(Frame::Array { index }) => *index += 1,
                None => {}
            },
            b'"' => {
                let start = i + 1;
                let mut end = start;
                while end < bytes.len() && bytes[end] != b'"' {
                    end += if bytes[end] == b'\\' { 2 } else { 1 };
                }
                if let Some(Frame::Object { key, expecting_key: expecting_key @ true }) = stack.last_mut() {
                    let raw = &bytes[start..end.min(bytes.len())];
                    *key = Some(String::from_utf8_lossy(raw).into_owned());
                    *expecting_key = false;
                }
                i = end;
            }
            _ => {}
        }
        i += 1;
    }
    let mut path = String::new();
    for frame in &stack {
        match frame {
            Frame::Object { key: Some(key), .. } => path = key_path(&path, key),
            Frame::Object { key: None, .. } => {}
            Frame::Array { index } => path.push_str(&format!("[{index}]")),
        }
    }
    path
}

#[cfg(test)]
mod tests {
    use super::super::settings::*;
    use super::*;

    const MINIMAL: &str = r#"{
        "meshes": [{"obj": "a.obj", "sparse_points": 16}],
        "light": {"position": [0, 2, 0], "direction": [0, -1, 0],
                  "inner_angle_deg": 20, "outer_angle_deg": 30, "intensity": [1, 1, 1]},
        "camera": {"position": [0, 1, 3], "target": [0, 1, 0], "fov_y_deg": 45,
                   "width": 64, "height": 48}
    }"#;

    /// Parses and validates, returning the error message.
    fn error_of(text: &str) -> String {
        match SceneDescription::from_json_str(text).and_then(|d| d.validate()) {
            Ok(()) => panic!("expected an error for {text}"),
            Err(error) => error.to_string(),
        }
    }

    /// `MINIMAL` with `from` replaced by `to` (which must occur).
    fn edit(from: &str, to: &str) -> String {
        assert!(MINIMAL.contains(from), "fixture lacks {from}");
        MINIMAL.replacen(from, to, 1)
    }

    /// `MINIMAL` with `lights` and `settings.direct` as given.
    fn with_lights(lights: &str, direct: &str) -> String {
        edit(r#""meshes""#, &format!(r#""lights": [{lights}], "settings": {{"direct": {{{direct}}}}}, "meshes""#))
    }

    #[test]
    fn lights_parse_spot_and_point_lights() {
        let text = with_lights(
            r#"{"type": "point", "position": [1, 2, 3], "intensity": [4, 5, 6], "range": 7},
               {"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1]},
               {"type": "spot", "position": [0, 2, 0], "direction": [0, -1, 0], "inner_angle_deg": 10,
                "outer_angle_deg": 20, "intensity": [2, 2, 2]}"#,
            r#""shadows": "light_cluster", "d_init": 0.5, "z_far": 30"#,
        );
        let description = SceneDescription::from_json_str(&text).expect("parses");
        description.validate().expect("valid");
        let lights: Vec<super::super::Light> = description.lights.iter().map(|l| l.to_light(DVec3::ZERO)).collect();
        assert_eq!(
            lights[0],
            super::super::Light::Point(super::super::PointLight {
                position: Vec3::new(1.0, 2.0, 3.0),
                intensity: Vec3::new(4.0, 5.0, 6.0),
                range: Some(7.0)
            })
        );
        assert!(matches!(lights[1], super::super::Light::Point(p) if p.range.is_none()));
        assert!(matches!(lights[2], super::super::Light::Spot(s) if (s.outer_angle - 20f32.to_radians()).abs() < 1e-6));
        let direct = description.settings.direct;
        assert_eq!((direct.shadows, direct.d_init, direct.z_far), (DirectShadows::LightCluster, 0.5, Some(30.0)));
        assert_eq!(SceneDescription::from_json_str(MINIMAL).unwrap().settings.direct, DirectSettings::default());
    }

    #[test]
    fn lights_errors_name_the_field() {
        let point = r#"{"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1]}"#;
        for (lights, direct, expected) in [
            (
                r#"{"type": "point", "position": [0, 1, 0], "intensity": [1, -1, 1]}"#.to_owned(),
                "",
                "lights[0].intensity[1]: must be >= 0, got -1",
            ),
            (
                format!(r#"{point}, {{"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1], "range": 0}}"#),
                "",
                "lights[1].range: must be > 0, got 0",
            ),
            (
                format!(
                    r#"{point}, {{"type": "spot", "position": [0, 1, 0], "direction": [0, 0, 0], "inner_angle_deg": 1, "outer_angle_deg": 2, "intensity": [1, 1, 1]}}"#
                ),
                "",
                "lights[1].direction: must be nonzero, got [0, 0, 0]",
            ),
            (
                format!("{point}, {point}, {point}"),
                r#""max_lights": 2"#,
                "lights: holds 3 lights, over settings.direct.max_lights = 2",
            ),
            (point.to_owned(), r#""d_init": 0"#, "settings.direct.d_init: must be > 0, got 0"),
            (point.to_owned(), r#""z_far": -1"#, "settings.direct.z_far: must be > 0, got -1"),
            (point.to_owned(), r#""max_lights": 0"#, "settings.direct.max_lights: must be in 1..=1024, got 0"),
            (point.to_owned(), r#""val_budget": 0"#, "settings.direct.val_budget: must be in 1..=1048576, got 0"),
            (
                format!("{point}, {point}"),
                r#""val_budget": 11"#,
                "settings.direct.val_budget: must be at least 12 for these lights (one VAL per RSM view: 6 per point light, 1 per spot), got 11",
            ),
            (
                point.to_owned(),
                r#""shadow_map_resolution": 8"#,
                "settings.direct.shadow_map_resolution: must be in 16..=1024, got 8",
            ),
        ] {
            let message = error_of(&with_lights(&lights, direct));
            assert_eq!(message, expected);
        }
        // 2 x 1024 maps of 1024 texels: over the atlas.
        let message = error_of(&with_lights(point, r#""max_lights": 1024, "shadow_map_resolution": 1024"#));
        assert!(message.starts_with("settings.direct.shadow_map_resolution: 2048 maps of 1024 texels"), "{message}");
        let message = error_of(&with_lights(r#"{"type": "area", "position": [0, 1, 0]}"#, ""));
        assert!(message.starts_with("lights[0]"), "{message}");
        let message = error_of(&with_lights(point, r#""shadows": "exact""#));
        assert!(message.starts_with("settings.direct.shadows"), "{message}");
    }

    #[test]
    fn minimal_scene_gets_defaults() {
        let description = SceneDescription::from_json_str(MINIMAL).expect("parses");
        description.validate().expect("valid");
        assert_eq!(description.settings, SettingsDescription::default());
        let settings = description.settings.to_settings(false);
        assert_eq!(settings.rsm_resolution, 128);
        assert!(settings.glossy);
        assert_eq!(settings.seed, 1);
        assert_eq!(settings.exposure, None);
        let camera = description.camera.to_camera(DVec3::ZERO);
        assert_eq!(camera.up, Vec3::Y);
        assert!((camera.fov_y - 45f32.to_radians()).abs() < 1e-6);
        let mesh = &description.meshes[0];
        assert_eq!(mesh.transform.to_matrix(), DMat4::IDENTITY);
        assert!(mesh.material.is_none() && mesh.materials.is_empty());
    }

    #[test]
    fn light_is_converted_to_radians_and_unit_direction() {
        let text = edit(r#""direction": [0, -1, 0]"#, r#""direction": [0, -4, 3]"#);
        let light = SceneDescription::from_json_str(&text)
            .expect("parses")
            .light
            .expect("has a light")
            .to_spot_light(DVec3::ZERO);
        assert!(light.direction.abs_diff_eq(Vec3::new(0.0, -0.8, 0.6), 1e-6));
        assert!((light.inner_angle - 20f32.to_radians()).abs() < 1e-6);
        assert!((light.outer_angle - 30f32.to_radians()).abs() < 1e-6);
        // No `up`: the default, world +Y away from vertical, +Z near it.
        assert_eq!(light.up, Vec3::Y);
        assert_eq!(SpotLight::default_up(Vec3::NEG_Y), Vec3::Z);
        let tilted = edit(r#""direction": [0, -1, 0]"#, r#""direction": [0, -1, 0], "up": [2, 0, 0]"#);
        let description = SceneDescription::from_json_str(&tilted).expect("parses");
        description.validate().expect("valid");
        assert_eq!(description.light.expect("has a light").to_spot_light(DVec3::ZERO).up, Vec3::X);
    }

    #[test]
    fn unknown_fields_are_named_with_their_path() {
        let message = error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": 16, "colour": 1"#));
        assert!(message.starts_with("meshes[0].colour: unknown field `colour`"), "{message}");

        let message = error_of(&edit(r#""width": 64"#, r#""width": 64, "zoom": 2"#));
        assert!(message.starts_with("camera.zoom: unknown field"), "{message}");

        let message = error_of(&edit("{\n", "{\n\"extra\": true,\n"));
        assert!(message.starts_with("extra: unknown field"), "{message}");

        let message =
            error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": 16, "transform": {"scale": 2, "shear": 1}"#));
        assert!(message.starts_with("meshes[0].transform.shear: unknown field"), "{message}");
    }

    #[test]
    fn missing_and_mistyped_fields_are_named() {
        let message = error_of(&edit(r#""fov_y_deg": 45,"#, ""));
        assert!(message.starts_with("camera.fov_y_deg: required field is missing"), "{message}");

        let message = error_of(&edit(r#""obj": "a.obj", "#, ""));
        assert!(message.starts_with("meshes[0].obj: required field is missing"), "{message}");

        let message = error_of(&edit(r#""width": 64"#, r#""width": "wide""#));
        assert!(message.starts_with("camera.width: invalid type"), "{message}");

        let message = error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": -3"#));
        assert!(message.starts_with("meshes[0].sparse_points:"), "{message}");

        let message = error_of(&edit(r#""position": [0, 2, 0]"#, r#""position": [0, 2]"#));
        assert!(message.starts_with("light.position"), "{message}");

        let message = error_of(&edit(r#""intensity": [1, 1, 1]"#, r#""intensity": [1, "x", 1]"#));
        assert!(message.starts_with("light.intensity[1]: invalid type"), "{message}");
    }

    #[test]
    fn nan_and_infinity_are_rejected_with_their_path() {
        // JSON has no NaN literal: the parser rejects it, at the field.
        let message = error_of(&edit(r#""fov_y_deg": 45"#, r#""fov_y_deg": NaN"#));
        assert!(message.starts_with("camera.fov_y_deg:"), "{message}");
        // A number too large for f32 becomes infinite and is rejected by validation.
        let message = error_of(&edit(r#""fov_y_deg": 45"#, r#""fov_y_deg": 1e39"#));
        assert_eq!(message, "camera.fov_y_deg: must be a finite number, got inf");
        // Positions are f64, bounded by MAX_COORDINATE_M.
        let message = error_of(&edit(r#""target": [0, 1, 0]"#, r#""target": [0, 1e39, 0]"#));
        assert_eq!(message, "camera.target[1]: must be a finite number within +-1e7 m, got 1e39");
        // Too large for f64: the parser rejects it.
        let message = error_of(&edit(r#""intensity": [1, 1, 1]"#, r#""intensity": [1, 1e999, 1]"#));
        assert!(message.starts_with("light.intensity[1]:"), "{message}");
    }

    #[test]
    fn out_of_range_values_name_the_path() {
        let cases = [
            (
                r#""sparse_points": 16"#,
                r#""sparse_points": 16, "transform": {"scale": -1}"#,
                "meshes[0].transform.scale: must be > 0, got -1",
            ),
            (
                r#""sparse_points": 16"#,
                r#""sparse_points": 16, "transform": {"scale": [1, 0, 1]}"#,
                "meshes[0].transform.scale[1]: must be > 0, got 0",
            ),
            (r#""sparse_points": 16"#, r#""sparse_points": 0"#, "meshes[0].sparse_points: must be in 1..=65536, got 0"),
            (
                r#""sparse_points": 16"#,
                r#""sparse_points": 65537"#,
                "meshes[0].sparse_points: must be in 1..=65536, got 65537",
            ),
            (
                r#""outer_angle_deg": 30"#,
                r#""outer_angle_deg": 85"#,
                "light.outer_angle_deg: must be in (0, 80], got 85",
            ),
            (
                r#""inner_angle_deg": 20"#,
                r#""inner_angle_deg": 35"#,
                "light.inner_angle_deg: must be in [0, outer_angle_deg = 30], got 35",
            ),
            (
                r#""direction": [0, -1, 0]"#,
                r#""direction": [0, 0, 0]"#,
                "light.direction: must be nonzero, got [0, 0, 0]",
            ),
            (r#""intensity": [1, 1, 1]"#, r#""intensity": [1, -1, 1]"#, "light.intensity[1]: must be >= 0, got -1"),
            (
                r#""intensity": [1, 1, 1]"#,
                r#""intensity": [1, 1, 1], "up": [0, 2, 0]"#,
                "light.up: must not be parallel to the light's direction",
            ),
            (r#""intensity": [1, 1, 1]"#, r#""intensity": [1, 1, 1], "up": [0, 0, 0]"#, "light.up: must be nonzero"),
            (r#""fov_y_deg": 45"#, r#""fov_y_deg": 170"#, "camera.fov_y_deg: must be in (1, 170), got 170"),
            (r#""width": 64"#, r#""width": 0"#, "camera.width: must be in 1..=8192, got 0"),
            (r#""height": 48"#, r#""height": 9000"#, "camera.height: must be in 1..=8192, got 9000"),
            (r#""target": [0, 1, 0]"#, r#""target": [0, 1, 3]"#, "camera.target: must differ from the camera position"),
            (
                r#""fov_y_deg": 45"#,
                r#""fov_y_deg": 45, "up": [0, 0, -2]"#,
                "camera.up: must not be parallel to the view direction",
            ),
            (
                r#""meshes": [{"obj": "a.obj", "sparse_points": 16}]"#,
                r#""meshes": []"#,
                "meshes: at least one mesh is required",
            ),
            (r#""obj": "a.obj""#, r#""obj": " ""#, "meshes[0].obj: must name an OBJ file"),
        ];
        for (from, to, expected) in cases {
            let message = error_of(&edit(from, to));
            assert!(message.starts_with(expected), "{to}: got `{message}`, expected `{expected}`");
        }
    }

    #[test]
    fn settings_are_checked() {
        let with_settings = |settings: &str| {
            let text = MINIMAL.trim_end().trim_end_matches('}');
            format!("{text}, \"settings\": {settings}}}")
        };
        let description = SceneDescription::from_json_str(&with_settings(
            r#"{"rsm_resolution": 256, "glossy": false, "seed": 7, "exposure": 2.5}"#,
        ))
        .expect("parses");
        description.validate().expect("valid");
        let settings = description.settings.to_settings(false);
        assert_eq!(
            settings,
            Settings {
                rsm_resolution: 256,
                glossy: false,
                seed: 7,
                exposure: Some(2.5),
                interpolation_neighbours: 8,
                occlusion: Occlusion::Off,
                occlusion_rule: OcclusionRule::Product,
                rgbd: RgbdSettings::default(),
                mr: MrSettings::default(),
                sparse: SparseShading::default(),
                clusters: ClusterSettings::default(),
                ism: IsmSettings::default(),
                direct: DirectSettings::default(),
                bounces: 1,
                second_bounce: SecondBounceSettings::default(),
            }
        );
        let s = SceneDescription::from_json_str(&with_settings(r#"{"bounces": 2, "second_bounce": {"vals": 64}}"#))
            .expect("parses");
        s.validate().expect("valid");
        let settings = s.settings.to_settings(false);
        assert_eq!(settings.bounces, 2);
        assert_eq!(settings.second_bounce, SecondBounceSettings { points: 4096, vals: 64 });
        for (text, want) in [
            (r#"{"bounces": 3}"#, "settings.bounces: must be in 1..=2, got 3"),
            (r#"{"bounces": 0}"#, "settings.bounces: must be in 1..=2, got 0"),
            (r#"{"second_bounce": {"vals": 0}}"#, "settings.second_bounce.vals: must be in 1..=65536, got 0"),
            (r#"{"second_bounce": {"points": 8}}"#, "settings.second_bounce.points: must be in 16..=262144, got 8"),
        ] {
            assert_eq!(error_of(&with_settings(text)), want, "{text}");
        }
        let message = error_of(&with_settings(r#"{"sparse": {"subdivision": 0.5}}"#));
        assert_eq!(message, "settings.sparse.subdivision: must be in [1, 16], got 0.5");
        let message = error_of(&with_settings(r#"{"sparse": {"near_field": 9}}"#));
        assert_eq!(message, "settings.sparse.near_field: must be in [0, 8], got 9");
        let message = error_of(&with_settings(r#"{"sparse": {"near_field": -0.5}}"#));
        assert_eq!(message, "settings.sparse.near_field: must be in [0, 8], got -0.5");
        let message = error_of(&with_settings(r#"{"sparse": {"adaptive": 1.5}}"#));
        assert_eq!(message, "settings.sparse.adaptive: must be in [0, 1], got 1.5");
        let message = error_of(&with_settings(r#"{"sparse": {"adaptive": -0.1}}"#));
        assert_eq!(message, "settings.sparse.adaptive: must be in [0, 1], got -0.1");
        let message = error_of(&with_settings(r#"{"sparse": {"kernel": "cubic"}}"#));
        assert!(message.starts_with("settings.sparse.kernel: unknown variant `cubic`"), "{message}");
        let paper =
            r#"{"sparse": {"kernel": "paper", "bound": "off", "subdivision": 1, "glossy_interpolation": "lights"}}"#;
        let description = SceneDescription::from_json_str(&with_settings(paper)).expect("parses");
        description.validate().expect("valid");
        let sparse = description.settings.to_settings(false).sparse;
        assert_eq!(
            sparse,
            SparseShading {
                kernel: InterpolationKernel::Paper,
                bound: LightBound::Off,
                subdivision: 1.0,
                near_field: 0.0,
                glossy_interpolation: GlossyInterpolation::Lights,
                adaptive: 0.0,
            }
        );
        let radiance = r#"{"sparse": {"glossy_interpolation": "radiance"}}"#;
        let description = SceneDescription::from_json_str(&with_settings(radiance)).expect("parses");
        let sparse = description.settings.to_settings(false).sparse;
        assert_eq!(sparse.glossy_interpolation, GlossyInterpolation::Radiance);
        let message = error_of(&with_settings(r#"{"sparse": {"glossy_interpolation": "pixels"}}"#));
        assert!(message.contains("glossy_interpolation") && message.contains("pixels"), "{message}");
        let message = error_of(&with_settings(r#"{"rgbd": {"min_depth": 2, "max_depth": 1}}"#));
        assert_eq!(message, "settings.rgbd.max_depth: must be > min_depth (2), got 1");
        let message = error_of(&with_settings(r#"{"rgbd": {"grid_step": 0}}"#));
        assert_eq!(message, "settings.rgbd.grid_step: must be in 1..=64, got 0");
        // `visibility`, and `occlusion` its deprecated alias; not both.
        for key in ["visibility", "occlusion"] {
            let text = with_settings(&format!(r#"{{"{key}": "clusters", "clusters": {{"count": 8, "soft": "pcf"}}}}"#));
            let d = SceneDescription::from_json_str(&text).expect("parses");
            d.validate().expect("valid");
            let s = d.settings.to_settings(true);
            assert_eq!(s.occlusion, Occlusion::Clusters, "{key}");
            assert_eq!(s.clusters, ClusterSettings { count: 8, soft: SoftShadows::Pcf, ..ClusterSettings::default() });
        }
        assert!(
            SceneDescription::from_json_str(&with_settings(r#"{"visibility": "off", "occlusion": "off"}"#)).is_err()
        );
        let message = error_of(&with_settings(r#"{"clusters": {"count": 0}}"#));
        assert_eq!(message, "settings.clusters.count: must be in 1..=256, got 0");
        let message = error_of(&with_settings(r#"{"clusters": {"count": 256, "shadow_map_resolution": 1024}}"#));
        assert!(message.starts_with("settings.clusters.shadow_map_resolution: 256 maps of 1024"), "{message}");
        let message = error_of(&with_settings(r#"{"clusters": {"normal_weight": -1}}"#));
        assert_eq!(message, "settings.clusters.normal_weight: must be in [0, 100], got -1");
        let message = error_of(&with_settings(r#"{"clusters": {"iterations": 33}}"#));
        assert_eq!(message, "settings.clusters.iterations: must be in 1..=32, got 33");
        let message = error_of(&with_settings(r#"{"clusters": {"shadow_maps": "ism", "shadow_map_resolution": 96}}"#));
        assert!(
            message.starts_with("settings.clusters.shadow_map_resolution: imperfect shadow maps need"),
            "{message}"
        );
        let message = error_of(&with_settings(r#"{"clusters": {"shadow_maps": "points"}}"#));
        assert!(message.starts_with("settings.clusters.shadow_maps: unknown variant `points`"), "{message}");
        let text = with_settings(r#"{"visibility": "ism", "ism": {"count": 16, "resolution": 32, "points": 100}}"#);
        let d = SceneDescription::from_json_str(&text).expect("parses");
        d.validate().expect("valid");
        let s = d.settings.to_settings(false);
        assert_eq!(s.occlusion, Occlusion::Ism);
        assert_eq!(s.ism, IsmSettings { count: 16, resolution: 32, points: Some(100), ..IsmSettings::default() });
        // The paper's rule: a quarter of the pi/4 * 128^2 texels of a 128x128 map.
        assert_eq!(IsmSettings::default().points_per_map(), 3217);
        for (ism, want) in [
            (r#"{"count": 0}"#, "settings.ism.count: must be in 1..=4096, got 0"),
            (r#"{"resolution": 48}"#, "settings.ism.resolution: must be a power of two in 16..=512, got 48"),
            (r#"{"points": 8}"#, "settings.ism.points: must be in 16..=65536, got 8"),
            (r#"{"pull_push_levels": 5}"#, "settings.ism.pull_push_levels: must be in 0..=4, got 5"),
            (r#"{"pull_threshold": 0}"#, "settings.ism.pull_threshold: must be in (0, 1], got 0"),
            (r#"{"push_threshold": 2}"#, "settings.ism.push_threshold: must be in (0, 1], got 2"),
            (r#"{"count": 1024, "resolution": 256}"#, "settings.ism.resolution: 1024 maps of 256x256 texels"),
            (r#"{"count": 4096, "resolution": 32, "points": 65536}"#, "settings.ism.points: 4096 maps of 65536 points"),
            (r#"{"spread": 1}"#, "settings.ism.spread: unknown field"),
            (r#"{"slope_bias": -1}"#, "settings.ism.slope_bias: must be in [0, 16], got -1"),
        ] {
            let message = error_of(&with_settings(&format!(r#"{{"ism": {ism}}}"#)));
            assert!(message.starts_with(want), "{ism}: {message}");
        }
        for (settings, field) in [
            (r#"{"environment": {"albedo": 0}}"#, "settings.environment.albedo: must be in (0, 1]"),
            (r#"{"environment": {"albedo": 1.5}}"#, "settings.environment.albedo: must be in (0, 1]"),
            (r#"{"environment": {"source": "auto", "calibrate_map": true}}"#, "settings.environment.calibrate_map"),
        ] {
            let message = error_of(&with_settings(settings));
            assert!(message.starts_with(field), "{settings}: {message}");
        }
        let message = error_of(&with_settings(r#"{"environment": {"distribution": "sideways"}}"#));
        assert!(message.starts_with("settings.environment.distribution: unknown variant `sideways`"), "{message}");
        let text = with_settings(r#"{"environment": {"source": "auto", "distribution": "overcast"}}"#);
        let d = SceneDescription::from_json_str(&text).expect("parses");
        d.validate().expect("valid");
        assert_eq!(d.settings.environment.distribution, EnvironmentDistribution::Overcast);
        let message = error_of(&with_settings(r#"{"rsm_resolution": 4}"#));
        assert_eq!(message, "settings.rsm_resolution: must be in 8..=2048, got 4");
        let message = error_of(&with_settings(r#"{"interpolation_neighbours": 17}"#));
        assert_eq!(message, "settings.interpolation_neighbours: must be in 1..=16, got 17");
        let message = error_of(&with_settings(r#"{"exposure": 0}"#));
        assert_eq!(message, "settings.exposure: must be > 0, got 0");
        let message = error_of(&with_settings(r#"{"exposure": null, "gamma": 2.2}"#));
        assert!(message.starts_with("settings.gamma: unknown field"), "{message}");
    }

    #[test]
    fn json_materials_are_checked() {
        let with_material = |material: &str| {
            edit(r#""sparse_points": 16"#, &format!(r#""sparse_points": 16, "materials": {{"leftWall": {material}}}"#))
        };
        let message = error_of(&with_material(r#"{"diffuse": [0.5, 1.5, 0.5]}"#));
        assert_eq!(message, "meshes[0].materials.leftWall.diffuse[1]: must be in [0, 1], got 1.5");
        let message = error_of(&with_material(r#"{"diffuse": [0.7, 0.5, 0.5], "specular": [0.4, 0, 0]}"#));
        assert!(
            message.starts_with("meshes[0].materials.leftWall.specular[0]: diffuse + specular must be <= 1"),
            "{message}"
        );
        let message = error_of(&with_material(r#"{"exponent": 20000}"#));
        assert_eq!(message, "meshes[0].materials.leftWall.exponent: must be in [0, 10000], got 20000");
        let message = error_of(&with_material(r#"{"roughness": 0.5}"#));
        assert!(message.starts_with("meshes[0].materials.leftWall.roughness: unknown field"), "{message}");
        // 0.7 + 0.3 is 1 up to rounding: accepted.
        let text = with_material(r#"{"diffuse": [0.7, 0.7, 0.7], "specular": [0.3, 0.3, 0.3], "exponent": 0}"#);
        let description = SceneDescription::from_json_str(&text).expect("parses");
        description.validate().expect("valid");
        let material = description.meshes[0].materials["leftWall"].to_material();
        assert_eq!(material.specular, Vec3::splat(0.3));
        assert_eq!(material.exponent, 0.0);

        let message = error_of(&with_material(r#"{"diffuse_texture": " "}"#));
        assert_eq!(
            message,
            "meshes[0].materials.leftWall.diffuse_texture: must name an image file, got an empty string"
        );
        let text = with_material(r#"{"diffuse_texture": "tex/wall.png"}"#);
        let description = SceneDescription::from_json_str(&text).expect("parses");
        description.validate().expect("valid");
        let material = &description.meshes[0].materials["leftWall"];
        assert_eq!(material.diffuse_texture.as_deref(), Some("tex/wall.png"));
        let json = serde_json::to_string(&description).expect("serializes");
        assert_eq!(SceneDescription::from_json_str(&json).expect("parses again"), description);
    }

    #[test]
    fn transform_accepts_uniform_and_per_axis_scale() {
        let text = edit(
            r#""sparse_points": 16"#,
            r#""sparse_points": 16, "transform": {"translation": [1, 2, 3], "rotation_deg": [0, 90, 0], "scale": [1, 2, 3]}"#,
        );
        let description = SceneDescription::from_json_str(&text).expect("parses");
        description.validate().expect("valid");
        let matrix = description.meshes[0].transform.to_matrix();
        // +X scaled by 1 and rotated 90 degrees about Y goes to -Z.
        let x = matrix.transform_vector3(DVec3::X);
        assert!(x.abs_diff_eq(DVec3::NEG_Z, 1e-12), "{x}");
        let y = matrix.transform_vector3(DVec3::Y);
        assert!(y.abs_diff_eq(DVec3::new(0.0, 2.0, 0.0), 1e-12), "{y}");
        assert!(matrix.transform_point3(DVec3::ZERO).abs_diff_eq(DVec3::new(1.0, 2.0, 3.0), 1e-12));

        let message =
            error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": 16, "transform": {"scale": [1, 2]}"#));
        assert!(message.starts_with("meshes[0].transform.scale"), "{message}");
        let message =
            error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": 16, "transform": {"scale": "big"}"#));
        assert!(message.contains("a number or an array [x, y, z]"), "{message}");
    }

    #[test]
    fn syntax_errors_report_the_position() {
        let error = SceneDescription::from_json_str("{\"meshes\": [\n  {\"obj\": }]}").expect_err("bad JSON");
        match error {
            SceneError::Json { field, line, .. } => {
                assert_eq!(field, "meshes[0].obj");
                assert_eq!(line, 2);
            }
            other => panic!("unexpected {other:?}"),
        }
        let message = error_of("");
        assert!(message.starts_with("(root):"), "{message}");
    }

    #[test]
    fn json_path_tracks_nesting() {
        let text = r#"{"a": {"b": [1, {"c": "x,y"}, [2, 3]]}, "d": 4}"#;
        let at = |needle: &str| json_path_at(text, text.find(needle).expect("needle") + needle.len());
        assert_eq!(at(r#""c": "x"#), "a.b[1].c");
        assert_eq!(at("[2"), "a.b[2][0]");
        assert_eq!(at("3"), "a.b[2][1]");
        assert_eq!(at(r#""d": 4"#), "d");
        assert_eq!(json_path_at(r#"{"we ird": 1"#, 12), r#"["we ird"]"#);
    }

    #[test]
    fn descriptions_round_trip_through_json() {
        let text = edit(
            r#""sparse_points": 16"#,
            r#""sparse_points": 16, "transform": {"scale": [1, 2, 3]}, "material": {"exponent": 5}, "skip_groups": ["light"]"#,
        );
        let description = SceneDescription::from_json_str(&text).expect("parses");
        let json = serde_json::to_string(&description).expect("serializes");
        let again = SceneDescription::from_json_str(&json).expect("parses again");
        assert_eq!(description, again);
    }
}
