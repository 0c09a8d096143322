//! The HTTP API's JSON shapes (they are the OpenAPI schemas) and their validation. The scene
//! description itself is [`crate::scene::SceneDescription`], the scene file format.

use serde::{Deserialize, Serialize};

use crate::renderer::Method;
use crate::scene::{
    CameraDescription, GltfSceneDescription, LightDescription, Occlusion, ResolvedConfig, Scene, SceneDescription,
    SceneError,
};

/// The body of `POST /v1/scenes`, for the API description: a scene description, or a whole
/// scene from one glTF file (a JSON object with a top-level `gltf` field). The route reads the
/// body itself (`service::scenes::load`) so that its errors name the field of the form sent.
#[derive(Deserialize, utoipa::ToSchema)]
#[serde(untagged)]
#[allow(dead_code, clippy::large_enum_variant)]
pub enum SceneRequest {
    Scene(SceneDescription),
    Gltf(GltfSceneDescription),
}

/// What `POST /v1/scenes` and `GET /v1/scenes/{id}` answer.
#[derive(Clone, Debug, Serialize, Deserialize, utoipa::ToSchema)]
pub struct SceneInfo {
    /// The scene's id, for the other routes.
    #[schema(example = "3f9a0c27d1e84b65")]
    pub id: String,
    pub meshes: Vec<MeshInfo>,
    /// Triangles over all meshes, after subdivision.
    pub triangles: usize,
    /// Sparse shading points over all meshes.
    pub sparse_points: usize,
    /// Most VALs a frame makes from the scene's own lights, as resolved (`resolved`):
    /// `rsm_resolution²` (with a `light`) plus `direct.val_budget` (with `lights`) plus
    /// `second_bounce.vals` (with two bounces).
    pub max_vals: u32,
    /// Whether frames run the glossy gather.
    pub glossy: bool,
    /// Indirect occlusion of the scene's frames (the scene file's `auto` resolved).
    pub occlusion: Occlusion,
    /// The default camera of renders.
    pub camera: CameraDescription,
    /// The spot light that render `light` overrides start from (none for scenes lit by RGB-D
    /// frames).
    pub light: Option<LightDescription>,
    /// The scene's resolved configuration: its quality level, the technique it asks for, what
    /// the analysis of the loaded scene found, and every parameter with the reason for its
    /// value (the level's choice or the scene file's `settings.tuning`).
    pub resolved: ResolvedConfig,
}

#[derive(Clone, Debug, Serialize, Deserialize, utoipa::ToSchema)]
pub struct MeshInfo {
    /// From the OBJ file's stem.
    pub name: String,
    pub vertices: usize,
    pub triangles: usize,
    pub sparse_points: usize,
}

impl SceneInfo {
    pub fn new(id: &str, scene: &Scene, camera: CameraDescription, light: Option<LightDescription>) -> SceneInfo {
        SceneInfo {
            id: id.to_owned(),
            meshes: scene
                .meshes
                .iter()
                .map(|m| MeshInfo {
                    name: m.name.clone(),
                    vertices: m.positions.len(),
                    triangles: m.triangles.len(),
                    sparse_points: m.sparse.base_len(),
                })
                .collect(),
            triangles: scene.triangle_count(),
            sparse_points: scene.sparse_point_count(),
            max_vals: {
                let s = &scene.settings;
                let second = (s.bounces == 2).then_some(s.second_bounce.vals);
                let parts = crate::scene::frame_val_parts(
                    scene.light.is_some(),
                    !scene.lights.is_empty(),
                    s.rsm_resolution,
                    s.direct.val_budget,
                    second,
                );
                parts.iter().map(|(_, n)| *n).sum::<u64>().min(u64::from(u32::MAX)) as u32
            },
            glossy: scene.needs_glossy(),
            occlusion: scene.settings.visibility.mode,
            camera,
            light,
            resolved: scene.resolved.clone(),
        }
    }
}

/// The body of `POST /v1/scenes/{id}/render`. Every part is optional: `{}` renders the scene's
/// camera and light with the sparse method to a PNG.
#[derive(Clone, Debug, Default, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RenderRequest {
    /// The camera, as in a scene file; default: the scene's. Its `width` and `height` are the
    /// image's size.
    #[serde(default)]
    pub camera: Option<CameraDescription>,
    /// Changes to the scene's spot light for this render only.
    #[serde(default)]
    pub light: Option<LightOverride>,
    #[serde(default)]
    pub quality: Quality,
}

/// Overrides of the scene's spot light; absent fields keep the scene's value. The result is
/// validated as a scene file's `light` is.
#[derive(Clone, Debug, Default, PartialEq, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LightOverride {
    /// World-space position, m (f64, as a scene file's `light.position`).
    pub position: Option<[f64; 3]>,
    /// World-space axis direction, nonzero.
    pub direction: Option<[f32; 3]>,
    /// Inner half-angle, degrees, in [0, `outer_angle_deg`].
    pub inner_angle_deg: Option<f32>,
    /// Outer half-angle, degrees, in (0, 80].
    pub outer_angle_deg: Option<f32>,
    /// Radiant intensity on the axis, W/sr, linear RGB, each >= 0.
    pub intensity: Option<[f32; 3]>,
    /// World-space up of the light's frame (orients the RSM grid), as a scene file's
    /// `light.up`: finite, nonzero, not parallel to the direction.
    pub up: Option<[f32; 3]>,
}

impl LightOverride {
    /// `base` with these overrides, validated; errors name fields under `field` (`light`). A
    /// scene without a spot light has nothing to override: an error.
    pub fn apply(&self, base: Option<&LightDescription>, field: &str) -> Result<LightDescription, SceneError> {
        let Some(base) = base else {
            return Err(SceneError::field(
                field,
                "the scene has no spot light to override (it is lit by RGB-D frames)",
            ));
        };
        let light = LightDescription {
            position: self.position.unwrap_or(base.position),
            direction: self.direction.unwrap_or(base.direction),
            inner_angle_deg: self.inner_angle_deg.unwrap_or(base.inner_angle_deg),
            outer_angle_deg: self.outer_angle_deg.unwrap_or(base.outer_angle_deg),
            intensity: self.intensity.unwrap_or(base.intensity),
            up: self.up.or(base.up),
        };
        light.validate(field)?;
        Ok(light)
    }
}

/// How a render is computed and returned.
#[derive(Clone, Copy, Debug, Default, PartialEq, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Quality {
    /// The quality level (default: the scene's `settings.quality`): the level's parameters
    /// resolved for the scene, those a loaded scene can change per frame (visibility mode,
    /// near field) and its technique: `reference` renders the exact reference, as does a level
    /// the scene's `settings.levels` measured as `exact` (over the scene's VALs; the CPU
    /// reference on a CPU adapter), unless `method` is given.
    #[serde(default)]
    pub level: Option<crate::scene::Quality>,
    /// A frame-time budget, ms, in [0.1, 600000] (default: the scene's `settings.budget_ms`).
    /// A render is one frame: nothing adapts to it; the answer says whether the frame met it
    /// (`X-Relume-Budget-Met`). Streams adapt to theirs.
    #[serde(default)]
    pub budget_ms: Option<f32>,
    /// Default: the level's technique (`sparse`, or the exact reference at level `reference`).
    #[serde(default)]
    pub method: Option<RenderMethod>,
    #[serde(default)]
    pub component: Component,
    /// Exposure multiplier before tone mapping (PNG only), > 0; default the scene's
    /// `settings.exposure`, else automatic (99th-percentile luminance maps to 1).
    #[serde(default)]
    pub exposure: Option<f32>,
    #[serde(default)]
    pub format: ImageFormat,
}

/// How the indirect light is computed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum RenderMethod {
    /// The sparse model-space method.
    #[default]
    Sparse,
    /// Every VAL at every visible pixel (the reference; slow).
    BruteForce,
    /// The brute force with every VAL weighted by its group's imperfect-shadow-map lookup at
    /// the pixel (the scene's resolved `ism`, `settings.tuning.ism`): the ISMs' visibility without the sparse
    /// interpolation. Its table of pixels x `ism.count` floats must fit the device's
    /// largest storage buffer binding, else 400 `limit_exceeded`.
    BruteForceIsm,
}

impl From<RenderMethod> for Method {
    fn from(method: RenderMethod) -> Method {
        match method {
            RenderMethod::Sparse => Method::Sparse,
            RenderMethod::BruteForce => Method::BruteForce,
            RenderMethod::BruteForceIsm => Method::BruteForceIsm,
        }
    }
}

pub use crate::renderer::Component;

/// The response body's format.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ImageFormat {
    /// `image/png`: 8-bit sRGB after exposure and clipping.
    #[default]
    Png,
    /// `application/octet-stream`: linear radiance, W/(m² sr), RGBA f32 little-endian, rows
    /// from the top, alpha = coverage.
    F32,
}

impl Quality {
    /// Checks the values serde cannot; errors name fields under `field` (`quality`).
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        if let Some(ms) = self.budget_ms {
            crate::scene::settings::validate_budget_ms(ms, &format!("{field}.budget_ms"))?;
        }
        match self.exposure {
            Some(exposure) => crate::scene::settings::validate_exposure(exposure, &format!("{field}.exposure")),
            None => Ok(()),
        }
    }
}

/// What `GET /healthz` answers.
#[derive(Serialize, Deserialize, utoipa::ToSchema)]
pub struct Health {
    /// `ok`, or `shutting_down` (with status 503).
    #[schema(example = "ok")]
    pub status: String,
    /// The GPU adapter renders run on.
    pub adapter: String,
    pub scenes: usize,
    /// Renders waiting for the GPU.
    pub queue_depth: usize,
    pub limits: crate::service::Limits,
}
