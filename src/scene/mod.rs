//! Scene loading: a JSON scene description, its OBJ/MTL meshes, and the per-mesh data that the
//! sparse model-space shading pipeline precomputes at load (docs/design.md §1 and §4 step 0).
//!
//! Loading a mesh runs, in order:
//!
//! 1. `obj`: parse the OBJ with tobj (triangulated, single index), merge its groups into one
//!    mesh, weld identical vertices (same position, normal and texture coordinates), resolve
//!    MTL and JSON materials into the global table and load their diffuse textures (`texture`).
//! 2. `normals`: keep the OBJ's normals, or compute area-weighted normals with a 45° crease
//!    angle, splitting vertices so each vertex has exactly one normal. Vertices split by a UV
//!    seam share their normal where the surface is smooth across the seam.
//! 3. `subdivide`: split every edge longer than `settings.sparse.subdivision` times the sparse
//!    point spacing `sqrt(model area / sparse_points)` (conforming red-green refinement), so the
//!    per-vertex interpolation of step 4 of the pipeline sees sparse points around every vertex.
//! 4. `sparse`: blue-noise sparse points (weighted sample elimination over area-proportional
//!    candidates), each vertex's 8 nearest sparse points, and each point's occluder radius.
//!
//! Everything a mesh stores is in model space; [`Mesh::model_to_world`] places it in the
//! scene's local world frame.
//!
//! **Floating origin.** A loaded scene's world-space quantities (mesh placements, the light,
//! the camera) are f32 relative to [`Scene::origin`], the centre of the meshes' world-space
//! bounding box, computed in f64 from the description (whose positions are f64). f32 keeps
//! about 7 significant digits: at 100 km from the user's origin its spacing is 7.8 mm, and the
//! RSM's depths, the gather's position sums and second moments and the biases in metres all
//! lost their precision there. Relative to the scene's centre, coordinates are
//! as large as the scene itself, wherever the scene is. Everything a user gives in world
//! coordinates after load (render cameras and lights, stream transforms, RGB-D poses) goes
//! through [`Scene::origin`] too ([`Scene::mesh_to_world`], [`Scene::local_pose`]); images have
//! no positions in them, so nothing the user gets back needs converting.
//!
//! Lengths are metres (or the OBJ's units, scaled by the transform), angles are radians once
//! loaded (the JSON speaks degrees), intensities are W/sr.

mod description;
mod error;
mod gltf;
mod hash;
mod load;
mod mesh;
mod normals;
mod obj;
pub mod settings;
mod sparse;
mod subdivide;
#[cfg(test)]
pub(crate) mod test_util;
#[cfg(test)]
mod tests;
mod texture;
pub(crate) mod validate;

use std::path::PathBuf;

use glam::{DMat4, DVec3, Mat4, Vec3};

pub use self::gltf::{GltfSceneDescription, LUMENS_PER_WATT, MAX_GLTF_BYTES, phong_from_pbr};
pub use description::{
    CameraDescription, LightDescription, LightEntry, MAX_COORDINATE_M, MAX_SCENE_EXTENT_M, MAX_SPARSE_POINTS,
    MESH_SCALE_RANGE, MIN_SCENE_EXTENT_M, MaterialDescription, MeshDescription, PointLightDescription,
    RSM_RESOLUTION_RANGE, ScaleDescription, SceneDescription, SettingsDescription, TransformDescription,
    frame_val_parts, parse_json,
};
pub use error::SceneError;
pub(crate) use load::{Geometry, TriangleBudget};
pub use load::{adaptive_budget, adaptive_candidates, local_pose, surface_area};
pub use mesh::{Mesh, PlacedMesh, SparsePoints};
pub use settings::{
    ADAPTIVE_CANDIDATES, ADAPTIVE_RANGE, ClusterMethod, ClusterSettings, DEFAULT_SUBDIVISION, DifferentialDevice,
    DirectSettings, DirectShadows, EnvironmentDistribution, EnvironmentSettings, EnvironmentSource,
    GlossyInterpolation, InterpolationKernel, IsmSettings, LightBound, MAX_CLUSTER_ATLAS_SIDE, MAX_CLUSTER_RAYS,
    MAX_CLUSTERS, MAX_DIRECT_LIGHTS, MAX_ENVIRONMENT_ROWS, MAX_ISM_POINTS, MAX_ISM_SPLATS, MAX_ISM_TEXELS, MAX_ISMS,
    MAX_KMEANS_ITERATIONS, MAX_LIGHTS_VAL_BUDGET, MrSettings, NEAR_FIELD_INTERLEAVE_SIDES, NEAR_FIELD_RANGE, Occlusion,
    OcclusionRule, OcclusionSetting, POINT_VIEWS, Quality, ResolvedConfig, RgbdSettings, SPOT_VIEWS, SUBDIVISION_RANGE,
    SecondBounceSettings, ShadowMapSource, SoftShadows, SparseShading, Technique, VisibilitySettings,
};
pub use texture::MAX_TEXTURE_SIDE;

/// Sparse points each vertex interpolates from (paper eqs. 12-13) unless the scene's
/// `settings.interpolation_neighbours` says otherwise.
pub const DEFAULT_NEIGHBOURS: u32 = 8;

/// Most sparse points a vertex may interpolate from.
pub const MAX_NEIGHBOURS: u32 = 16;

/// Most triangles one mesh may have after subdivision; more is an error rather than a
/// machine brought to its knees by a too-large `sparse_points`.
pub const MAX_TRIANGLES_PER_MESH: usize = 4_000_000;

/// A loaded, validated scene: meshes with their precomputed sparse points, the global material
/// table, the spot light, the camera and the render settings.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The meshes, in the order of the description's `meshes` array.
    pub meshes: Vec<Mesh>,
    /// Global material table; [`Mesh::triangle_materials`] indexes into it. One entry per
    /// (mesh, material name) that at least one loaded triangle uses.
    pub materials: Vec<Material>,
    /// Diffuse textures; [`Material::diffuse_texture`] indexes into it. One entry per file
    /// (deduplicated by resolved path), only those of materials in `materials`; empty when no
    /// material has one.
    pub textures: Vec<Texture>,
    /// The spot light whose RSM provides VALs, if any (RGB-D frames may provide them instead).
    pub light: Option<SpotLight>,
    /// The description's `lights`: direct lights beside `light` (no VALs).
    pub lights: Vec<Light>,
    /// The camera the final image is rendered from.
    pub camera: Camera,
    /// Render settings, as resolved from the scene file's quality level and tuning.
    pub settings: Settings,
    /// The quality level, the scene's analysis, and why each parameter of `settings` has its
    /// value.
    pub resolved: ResolvedConfig,
    /// The description's `anchor` (user coordinates), already applied to every mesh's
    /// [`Mesh::model_to_world`]; kept to place a mesh given a new transform
    /// ([`Scene::mesh_to_world`]).
    pub anchor: DMat4,
    /// The floating origin, in the user's world coordinates (m): the centre of the meshes'
    /// world-space bounding box. Every f32 world-space quantity of the scene (and of the GPU
    /// buffers, the twins and the VALs made from it) is relative to it: user = local + origin.
    pub origin: DVec3,
}

/// Normalised modified Phong material (docs/design.md §1):
/// `f = rho_d / pi + rho_s (k + 2) / (2 pi) max(0, dot(reflect(w_i, n), w_o))^k`,
/// with `diffuse + specular <= 1` per channel guaranteed by the loader.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Diffuse albedo `rho_d`, linear RGB, each channel in [0, 1]. With a texture, the albedo
    /// is `diffuse * texture(uv)` (the texture decoded from sRGB to linear): `diffuse` scales
    /// the texture, and `diffuse + specular <= 1` still bounds the energy.
    pub diffuse: Vec3,
    /// Specular albedo `rho_s`, linear RGB, each channel in [0, 1].
    pub specular: Vec3,
    /// Phong exponent `k`, in [0, 1e4].
    pub exponent: f32,
    /// Index into [`Scene::textures`] of the diffuse texture (MTL `map_Kd`), sampled at
    /// [`Mesh::texcoords`].
    pub diffuse_texture: Option<u32>,
}

impl Material {
    /// The material of triangles without one: 50 % grey Lambertian, no specular lobe.
    pub const DEFAULT: Material =
        Material { diffuse: Vec3::splat(0.5), specular: Vec3::ZERO, exponent: 1.0, diffuse_texture: None };

    /// Largest accepted Phong exponent.
    pub const MAX_EXPONENT: f32 = 1.0e4;

    /// Whether this material has a glossy lobe (`rho_s > 0` in any channel).
    pub fn is_glossy(&self) -> bool {
        self.specular.max_element() > 0.0
    }
}

impl Default for Material {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A diffuse texture, as stored in its file.
#[derive(Clone, PartialEq, Eq)]
pub struct Texture {
    /// The file, as resolved from the MTL (its directory joined with the `map_Kd` path) or the
    /// scene file (its directory joined with `diffuse_texture`).
    pub path: PathBuf,
    /// Width, texels, in 1..=[`MAX_TEXTURE_SIDE`].
    pub width: u32,
    /// Height, texels, in 1..=[`MAX_TEXTURE_SIDE`].
    pub height: u32,
    /// `width * height * 4` bytes of RGBA, row-major from the top row, sRGB-encoded as stored
    /// in the file (linear floating-point files are sRGB-encoded); alpha 255 where the file has
    /// none.
    pub rgba8: Vec<u8>,
}

impl std::fmt::Debug for Texture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Texture")
            .field("path", &self.path)
            .field("width", &self.width)
            .field("height", &self.height)
            .field("rgba8", &format_args!("[{} bytes]", self.rgba8.len()))
            .finish()
    }
}

/// A spot light: radiant intensity `intensity` on the axis, falling off linearly in angle from
/// 1 at `inner_angle` to 0 at `outer_angle` (docs/design.md §2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotLight {
    /// World-space position of the light, m.
    pub position: Vec3,
    /// World-space unit axis direction.
    pub direction: Vec3,
    /// Inner half-angle (full intensity inside), radians, in [0, `outer_angle`].
    pub inner_angle: f32,
    /// Outer half-angle (zero intensity outside), radians, in (0, 80°].
    pub outer_angle: f32,
    /// Radiant intensity on the axis, W/sr, linear RGB, each channel >= 0.
    pub intensity: Vec3,
    /// World-space unit up of the light's frame (not parallel to `direction`): orients the
    /// RSM's grid about the axis, as a camera's up orients its image.
    pub up: Vec3,
}

impl SpotLight {
    /// The up a light without one gets: world +Y, or +Z when the unit `direction` is within
    /// about 8° of vertical (|y| > 0.99).
    pub fn default_up(direction: Vec3) -> Vec3 {
        if direction.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y }
    }

    /// World to the light's view space (right-handed, looking down -Z along `direction`, +Y
    /// toward `up`): the frame of the RSM's grid.
    pub fn world_to_light(&self) -> Mat4 {
        glam::camera::rh::view::look_at_mat4(self.position, self.position + self.direction, self.up)
    }
}

/// An omnidirectional point light of [`Scene::lights`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    /// World-space position, m.
    pub position: Vec3,
    /// Radiant intensity, W/sr, linear RGB, each channel >= 0.
    pub intensity: Vec3,
    /// Beyond this distance (m) the light adds nothing (`twin::many_lights::range_window`).
    pub range: Option<f32>,
}

/// One of [`Scene::lights`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    Spot(SpotLight),
    Point(PointLight),
}

impl Light {
    pub fn position(&self) -> Vec3 {
        match self {
            Light::Spot(s) => s.position,
            Light::Point(p) => p.position,
        }
    }
}

/// A perspective camera (right-handed, looking from `position` toward `target`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// World-space eye position, m.
    pub position: Vec3,
    /// World-space point looked at, m (differs from `position`).
    pub target: Vec3,
    /// World-space unit up direction (not parallel to the view direction).
    pub up: Vec3,
    /// Vertical field of view (full angle), radians, in (1°, 170°).
    pub fov_y: f32,
    /// Image width, pixels, in 1..=8192.
    pub width: u32,
    /// Image height, pixels, in 1..=8192.
    pub height: u32,
}

impl Camera {
    /// World-to-view matrix (right-handed, the camera looks down -Z in view space).
    pub fn world_to_view(&self) -> Mat4 {
        glam::camera::rh::view::look_at_mat4(self.position, self.target, self.up)
    }

    /// Width over height.
    pub fn aspect_ratio(&self) -> f32 {
        self.width as f32 / self.height as f32
    }
}

/// Render settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Side of the square reflective shadow map, texels, in 8..=2048.
    pub rsm_resolution: u32,
    /// Side of the RSM at the `reference` level (the scene file's `tuning`, else the level's:
    /// measured levels never change it), whose VALs the exact reference of `relume bench
    /// --levels` sums over and the error estimate does too where the frame's are coarser.
    pub reference_rsm_resolution: u32,
    /// Whether the glossy gather may run (it still only runs when a material is glossy).
    pub glossy: bool,
    /// Seed of every random choice made at load (sparse point placement).
    pub seed: u64,
    /// Exposure multiplier applied before tone mapping; `None` picks one automatically.
    pub exposure: Option<f32>,
    /// Sparse points each vertex interpolates from, 1..=[`MAX_NEIGHBOURS`].
    pub interpolation_neighbours: u32,
    /// Indirect visibility: the mode (docs/design.md §4 step 3) and every mode's settings.
    pub visibility: VisibilitySettings,
    /// How RGB-D frames become VALs.
    pub rgbd: RgbdSettings,
    /// Mixed-reality compositing (differential rendering).
    pub mr: MrSettings,
    /// The sparse method's interpolation kernel, light bound and subdivision.
    pub sparse: SparseShading,
    /// Shadows of the direct light from [`Scene::lights`].
    pub direct: DirectSettings,
    /// Bounces of indirect light: 1, or 2 with a second bounce as `second_bounce` says.
    pub bounces: u32,
    pub second_bounce: SecondBounceSettings,
}
