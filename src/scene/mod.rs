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
mod normals;
mod obj;
pub mod settings;
mod sparse;
mod subdivide;
mod texture;
mod validate;

use std::path::{Path, PathBuf};

use glam::{Affine3A, DAffine3, DMat4, DVec3, Mat3, Mat4, Vec2, Vec3};

pub use self::gltf::{GltfSceneDescription, LUMENS_PER_WATT, MAX_GLTF_BYTES, phong_from_pbr};
pub use description::{
    CameraDescription, LightDescription, LightEntry, MAX_COORDINATE_M, MAX_SPARSE_POINTS, MaterialDescription,
    MeshDescription, PointLightDescription, RSM_RESOLUTION_RANGE, ScaleDescription, SceneDescription,
    SettingsDescription, TransformDescription, frame_val_parts, parse_json,
};
pub use error::SceneError;
pub use settings::{
    ADAPTIVE_CANDIDATES, ADAPTIVE_RANGE, ClusterMethod, ClusterSettings, DEFAULT_SUBDIVISION, DifferentialDevice,
    DirectSettings, DirectShadows, EnvironmentDistribution, EnvironmentSettings, EnvironmentSource,
    GlossyInterpolation, InterpolationKernel, IsmSettings, LightBound, MAX_CLUSTER_ATLAS_SIDE, MAX_CLUSTERS,
    MAX_DIRECT_LIGHTS, MAX_ENVIRONMENT_ROWS, MAX_ISM_POINTS, MAX_ISM_SPLATS, MAX_ISM_TEXELS, MAX_ISMS,
    MAX_KMEANS_ITERATIONS, MAX_LIGHTS_VAL_BUDGET, MrSettings, NEAR_FIELD_RANGE, Occlusion, OcclusionRule,
    OcclusionSetting, POINT_VIEWS, RgbdSettings, SPOT_VIEWS, SUBDIVISION_RANGE, SecondBounceSettings, ShadowMapSource,
    SoftShadows, SparseShading,
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
    /// Render settings.
    pub settings: Settings,
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
    /// Whether the glossy gather may run (it still only runs when a material is glossy).
    pub glossy: bool,
    /// Seed of every random choice made at load (sparse point placement).
    pub seed: u64,
    /// Exposure multiplier applied before tone mapping; `None` picks one automatically.
    pub exposure: Option<f32>,
    /// Sparse points each vertex interpolates from, 1..=[`MAX_NEIGHBOURS`].
    pub interpolation_neighbours: u32,
    /// Indirect occlusion by disc occluders (docs/design.md §4 step 3).
    pub occlusion: Occlusion,
    pub occlusion_rule: OcclusionRule,
    /// How RGB-D frames become VALs.
    pub rgbd: RgbdSettings,
    /// Mixed-reality compositing (differential rendering).
    pub mr: MrSettings,
    /// The sparse method's interpolation kernel, light bound and subdivision.
    pub sparse: SparseShading,
    /// The `Clusters` visibility mode's settings.
    pub clusters: ClusterSettings,
    /// The `Ism` visibility mode's settings.
    pub ism: IsmSettings,
    /// Shadows of the direct light from [`Scene::lights`].
    pub direct: DirectSettings,
    /// Bounces of indirect light: 1, or 2 with a second bounce as `second_bounce` says.
    pub bounces: u32,
    pub second_bounce: SecondBounceSettings,
}

/// One mesh: an OBJ file after subdivision and crease splitting, in model space, with its
/// sparse points.
#[derive(Clone, Debug)]
pub struct Mesh {
    /// Name, from the mesh file's stem (OBJ or glTF).
    pub name: String,
    /// Model to the scene's local world frame (world minus [`Scene::origin`]): the
    /// description's transform (scale, then Euler XYZ rotation, then translation) after the
    /// anchor, composed in f64 with the origin's translation and then rounded to f32.
    pub model_to_world: Mat4,
    /// Model-space vertex positions.
    pub positions: Vec<Vec3>,
    /// Model-space unit vertex normals, one per vertex.
    pub normals: Vec<Vec3>,
    /// Texture coordinates, one per vertex, in the OBJ's `vt` convention (v up, as in the
    /// file); zero where the OBJ has none. Vertices at one position with different texture
    /// coordinates (a UV seam) stay separate vertices.
    pub texcoords: Vec<Vec2>,
    /// Triangles as vertex indices, counter-clockwise as in the OBJ.
    pub triangles: Vec<[u32; 3]>,
    /// Per-triangle index into [`Scene::materials`].
    pub triangle_materials: Vec<u32>,
    /// The sparse points of this mesh and the vertex-to-point links.
    pub sparse: SparsePoints,
}

/// Sparse shading points of one mesh (docs/design.md §4 step 0). Points are stored as triangle +
/// barycentrics, so they follow a deformation of the mesh; positions and normals are the
/// model-space evaluation at load.
#[derive(Clone, Debug, Default)]
pub struct SparsePoints {
    /// Triangle index (into [`Mesh::triangles`]) of each point.
    pub triangles: Vec<u32>,
    /// Barycentrics `(b1, b2)` of each point: `p = (1 - b1 - b2) p0 + b1 p1 + b2 p2`.
    pub barycentrics: Vec<glam::Vec2>,
    /// Model-space positions of the points.
    pub positions: Vec<Vec3>,
    /// Model-space unit normals (interpolated vertex normals, renormalised).
    pub normals: Vec<Vec3>,
    /// Model-space occluder-disc radius of each point: the largest distance to a mesh vertex
    /// whose nearest sparse point it is; 0 when no vertex is nearest to it.
    pub occluder_radii: Vec<f32>,
    /// Sparse points per vertex in [`SparsePoints::vertex_neighbours`].
    pub neighbours: usize,
    /// `neighbours` entries per mesh vertex: indices of its nearest sparse points, nearest
    /// first, padded with `u32::MAX` when the mesh has fewer points.
    pub vertex_neighbours: Vec<u32>,
    /// How many of the points, at the end of the arrays, are adaptive candidates
    /// (`settings.sparse.adaptive`): gathered only in the frames that choose them, else given
    /// the light interpolated from their neighbours among the other points. 0 without.
    pub candidates: usize,
    /// `neighbours` entries per candidate: its nearest points that are not candidates, nearest
    /// first, `u32::MAX` padded.
    pub candidate_neighbours: Vec<u32>,
    /// `neighbours` entries per mesh vertex, with candidates only: its nearest candidates (as
    /// indices of the points, so at least `len() - candidates`), nearest first, `u32::MAX`
    /// padded. `vertex_neighbours` then holds the nearest points that are not candidates.
    pub vertex_candidates: Vec<u32>,
}

impl Mesh {
    /// Whether one part of the mesh can hide another from a third: false for a convex object
    /// (every vertex behind every face's plane) and for a convex room seen from inside (every
    /// vertex in front of or on every plane). Checked on up to 256 faces against up to 4096
    /// vertices, spread evenly; a relative tolerance absorbs flat subdivided faces.
    pub fn may_occlude_itself(&self) -> bool {
        let (lo, hi) = self
            .positions
            .iter()
            .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let tolerance = 1e-4 * (hi - lo).length();
        let faces = self.triangles.iter().step_by(self.triangles.len().div_ceil(256).max(1));
        let vertices: Vec<Vec3> =
            self.positions.iter().step_by(self.positions.len().div_ceil(4096).max(1)).copied().collect();
        let (mut in_front, mut behind) = (false, false);
        for t in faces {
            let [a, b, c] = t.map(|i| self.positions[i as usize]);
            let n = (b - a).cross(c - a).normalize_or_zero();
            for v in &vertices {
                let side = n.dot(*v - a);
                in_front |= side > tolerance;
                behind |= side < -tolerance;
            }
            if in_front && behind {
                return true;
            }
        }
        false
    }
}

impl SparsePoints {
    /// Number of sparse points, adaptive candidates included.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Number of sparse points gathered every frame: all but the adaptive candidates.
    pub fn base_len(&self) -> usize {
        self.positions.len() - self.candidates
    }

    /// Whether there are no sparse points (never the case for a loaded mesh).
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

impl Mesh {
    /// Vertex positions in world space, m.
    pub fn world_positions(&self) -> Vec<Vec3> {
        self.placed(self.model_to_world).positions()
    }

    /// Unit vertex normals in world space.
    pub fn world_normals(&self) -> Vec<Vec3> {
        self.placed(self.model_to_world).normals()
    }

    /// Sparse point positions in world space, m.
    pub fn sparse_world_positions(&self) -> Vec<Vec3> {
        self.placed(self.model_to_world).sparse_positions()
    }

    /// Unit sparse point normals in world space.
    pub fn sparse_world_normals(&self) -> Vec<Vec3> {
        self.placed(self.model_to_world).sparse_normals()
    }

    /// Occluder radii in world space, m (see [`PlacedMesh::occluder_radii`]).
    pub fn world_occluder_radii(&self) -> Vec<f32> {
        self.placed(self.model_to_world).occluder_radii()
    }

    /// This mesh under another model-to-world transform (a moved model: the sparse points,
    /// in model space, move with it).
    pub fn placed(&self, model_to_world: Mat4) -> PlacedMesh<'_> {
        PlacedMesh { mesh: self, model_to_world }
    }
}

/// A mesh under a model-to-world transform: its world-space arrays.
pub struct PlacedMesh<'a> {
    mesh: &'a Mesh,
    model_to_world: Mat4,
}

impl PlacedMesh<'_> {
    pub fn positions(&self) -> Vec<Vec3> {
        transform_points(self.model_to_world, &self.mesh.positions)
    }

    pub fn normals(&self) -> Vec<Vec3> {
        transform_normals(normal_matrix(self.model_to_world), &self.mesh.normals)
    }

    pub fn sparse_positions(&self) -> Vec<Vec3> {
        transform_points(self.model_to_world, &self.mesh.sparse.positions)
    }

    pub fn sparse_normals(&self) -> Vec<Vec3> {
        transform_normals(normal_matrix(self.model_to_world), &self.mesh.sparse.normals)
    }

    /// Occluder radii in world space, m: the model-space radii times the largest axis scale of
    /// the transform (exact for uniform scale, conservative otherwise).
    pub fn occluder_radii(&self) -> Vec<f32> {
        let linear = Mat3::from_mat4(self.model_to_world);
        let scale = linear.x_axis.length().max(linear.y_axis.length()).max(linear.z_axis.length());
        self.mesh.sparse.occluder_radii.iter().map(|r| r * scale).collect()
    }
}

/// Matrix that takes model-space normals to world space (inverse transpose of the upper 3x3
/// of `model_to_world`); results need renormalising.
fn normal_matrix(model_to_world: Mat4) -> Mat3 {
    Mat3::from_mat4(model_to_world).inverse().transpose()
}

fn transform_points(matrix: Mat4, points: &[Vec3]) -> Vec<Vec3> {
    points.iter().map(|&p| matrix.transform_point3(p)).collect()
}

fn transform_normals(normal_matrix: Mat3, normals: &[Vec3]) -> Vec<Vec3> {
    normals.iter().map(|&n| (normal_matrix * n).normalize_or(n)).collect()
}

impl Scene {
    /// Parses and validates scene JSON and loads every mesh it names; OBJ paths are relative to
    /// `base_dir`.
    /// A JSON object with a top-level `gltf` field is a [`GltfSceneDescription`]: the whole
    /// scene from one glTF file (its meshes, spot light and camera) with relume's settings.
    pub fn from_json_str(text: &str, base_dir: &Path) -> Result<Scene, SceneError> {
        if GltfSceneDescription::is_one(text) {
            let description = GltfSceneDescription::from_json_str(text)?.to_scene_description(base_dir)?;
            return Self::from_description(&description, base_dir)
                .map_err(|e| e.with_field(GltfSceneDescription::field_in_form));
        }
        Self::from_description(&SceneDescription::from_json_str(text)?, base_dir)
    }

    /// Reads a scene file; OBJ paths are relative to the directory that holds it.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| SceneError::Read { path: path.to_path_buf(), source })?;
        let base_dir = path.parent().unwrap_or_else(|| Path::new("."));
        Self::from_json_str(&text, base_dir)
    }

    /// Validates a parsed description and loads every mesh it names; OBJ paths are relative to
    /// `base_dir`.
    pub fn from_description(description: &SceneDescription, base_dir: &Path) -> Result<Scene, SceneError> {
        Self::from_description_within(description, base_dir, usize::MAX)
    }

    /// [`Scene::from_description`] with at most `max_triangles` triangles after subdivision,
    /// all meshes together (and [`MAX_TRIANGLES_PER_MESH`] per mesh): each OBJ's triangles are
    /// checked as soon as it is parsed, and subdivision stops as soon as it would go over
    /// ([`SceneError::TooManyTriangles`]).
    pub fn from_description_within(
        description: &SceneDescription,
        base_dir: &Path,
        max_triangles: usize,
    ) -> Result<Scene, SceneError> {
        description.validate()?;
        let mut settings = description.settings.to_settings(false);
        let mut materials = Vec::new();
        let mut textures = texture::Textures::default();
        let mut meshes = Vec::with_capacity(description.meshes.len());
        let anchor = description.anchor.as_ref().map_or(DMat4::IDENTITY, |a| a.to_matrix());
        let mut triangles = 0usize;
        for (index, mesh_description) in description.meshes.iter().enumerate() {
            let budget = TriangleBudget { left: max_triangles.saturating_sub(triangles), total: max_triangles };
            let mesh = load_mesh(mesh_description, index, base_dir, &settings, &budget, &mut materials, &mut textures)?;
            triangles += mesh.triangles.len();
            meshes.push(mesh);
        }
        let user_to_world: Vec<DMat4> = description.meshes.iter().map(|m| anchor * m.transform.to_matrix()).collect();
        let origin = floating_origin(&meshes, &user_to_world, &description.camera);
        for (mesh, transform) in meshes.iter_mut().zip(&user_to_world) {
            mesh.model_to_world = local_matrix(origin, *transform);
        }
        if description.settings.occlusion == OcclusionSetting::Auto {
            let self_occluding = meshes.len() > 1 || meshes.iter().any(Mesh::may_occlude_itself);
            settings.occlusion = if self_occluding { Occlusion::Disks } else { Occlusion::Off };
        }
        Ok(Scene {
            meshes,
            materials,
            textures: textures.textures,
            light: description.light.as_ref().map(|l| l.to_spot_light(origin)),
            lights: description.lights.iter().map(|l| l.to_light(origin)).collect(),
            camera: description.camera.to_camera(origin),
            settings,
            anchor,
            origin,
        })
    }

    /// Model-to-local-world of mesh `index` given a replacement for its description's
    /// `transform` in user coordinates (`None`: the loaded one): the anchor still applies, as in
    /// the scene file, and the result is relative to [`Scene::origin`].
    pub fn mesh_to_world(&self, index: usize, transform: Option<DMat4>) -> Mat4 {
        match transform {
            Some(t) => local_matrix(self.origin, self.anchor * t),
            None => self.meshes[index].model_to_world,
        }
    }

    /// A pose given in the user's world coordinates (an RGB-D frame's camera-to-world, f64)
    /// made relative to [`Scene::origin`], the subtraction done in f64.
    pub fn local_pose(&self, pose: &DAffine3) -> Affine3A {
        local_pose(self.origin, pose)
    }

    /// Whether the glossy gather is needed: glossy is enabled and some triangle's material has
    /// `rho_s > 0` in any channel.
    pub fn needs_glossy(&self) -> bool {
        self.settings.glossy
            && self.meshes.iter().any(|mesh| {
                mesh.triangle_materials.iter().any(|&m| self.materials.get(m as usize).is_some_and(Material::is_glossy))
            })
    }

    /// Sparse points gathered every frame over all meshes (without the adaptive candidates).
    pub fn sparse_point_count(&self) -> usize {
        self.meshes.iter().map(|m| m.sparse.base_len()).sum()
    }

    /// The largest world-space sparse point spacing over the meshes (m): `sqrt(area / points)`
    /// of each mesh as placed (its transform applied), the length the near-field radius
    /// (`settings.sparse.near_field`) is measured in. 0 for a scene without meshes.
    pub fn sparse_spacing(&self) -> f32 {
        self.meshes
            .iter()
            .filter(|m| !m.sparse.is_empty())
            .map(|m| {
                let area = surface_area(&m.placed(m.model_to_world).positions(), &m.triangles);
                (area / m.sparse.base_len() as f64).sqrt() as f32
            })
            .fold(0.0, f32::max)
    }

    /// Triangles over all meshes (after subdivision).
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.triangles.len()).sum()
    }

    /// Vertices over all meshes (after subdivision and crease splitting).
    pub fn vertex_count(&self) -> usize {
        self.meshes.iter().map(|m| m.positions.len()).sum()
    }
}

/// Triangles a mesh may have after subdivision: what the scene's meshes before it left of the
/// scene's `total`.
pub(crate) struct TriangleBudget {
    pub left: usize,
    pub total: usize,
}

impl TriangleBudget {
    pub(crate) fn exceeded(&self, field: String, what: &str) -> SceneError {
        let message = if self.left < self.total {
            format!("{what} over the {} triangles left of the scene's limit of {}", self.left, self.total)
        } else {
            format!("{what} over the scene's limit of {} triangles", self.total)
        };
        SceneError::TooManyTriangles { field, limit: self.total, message }
    }
}

/// Loads mesh `index` of the description: OBJ, normals, subdivision, sparse points. Its
/// materials are appended to `materials`, their textures to `textures`.
/// The scene's floating origin ([`Scene::origin`]): the centre of the bounding box of every
/// vertex in user world coordinates, computed in f64. The meshes are what the precision-critical
/// sums (RSM depths, the gather's moments, occluder discs) run over, so their centre keeps every
/// such coordinate as small as the scene; the camera and the light usually sit near or inside it.
/// A scene without vertices uses the camera's position.
fn floating_origin(meshes: &[Mesh], user_to_world: &[DMat4], camera: &CameraDescription) -> DVec3 {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for (mesh, transform) in meshes.iter().zip(user_to_world) {
        for p in &mesh.positions {
            let world = transform.transform_point3(p.as_dvec3());
            (lo, hi) = (lo.min(world), hi.max(world));
        }
    }
    if lo.cmple(hi).all() { (lo + hi) * 0.5 } else { DVec3::from_array(camera.position) }
}

/// `pose` (user coordinates, f64) relative to `origin`: the translation subtracted in f64, and
/// only then everything rounded to f32.
pub fn local_pose(origin: DVec3, pose: &DAffine3) -> Affine3A {
    Affine3A::from_mat3_translation(pose.matrix3.as_mat3(), (pose.translation - origin).as_vec3())
}

/// `model_to_world` (user coordinates, f64) relative to `origin`, rounded to f32.
fn local_matrix(origin: DVec3, model_to_world: DMat4) -> Mat4 {
    (DMat4::from_translation(-origin) * model_to_world).as_mat4()
}

fn load_mesh(
    description: &MeshDescription,
    index: usize,
    base_dir: &Path,
    settings: &Settings,
    budget: &TriangleBudget,
    materials: &mut Vec<Material>,
    textures: &mut texture::Textures,
) -> Result<Mesh, SceneError> {
    let started = std::time::Instant::now();
    let field = format!("meshes[{index}]");
    // glTF checks its triangle count against the budget before it reads any vertex data.
    let (loaded, file_field) = match description.gltf {
        Some(_) => (gltf::load(description, &field, base_dir, budget, textures)?, format!("{field}.gltf")),
        None => (obj::load(description, &field, base_dir, textures)?, format!("{field}.obj")),
    };
    if loaded.triangles.len() > budget.left {
        let what = format!("the OBJ has {} triangles,", loaded.triangles.len());
        return Err(budget.exceeded(file_field, &what));
    }
    let file = loaded.file.clone();
    let loaded_at = started.elapsed();
    let material_offset = u32::try_from(materials.len()).map_err(|_| SceneError::Field {
        field: field.clone(),
        message: "too many materials in the scene".to_owned(),
    })?;
    materials.extend(loaded.materials.iter().copied());
    let triangle_materials: Vec<u32> = loaded.triangle_materials.iter().map(|&m| m + material_offset).collect();

    let mut geometry = match loaded.normals {
        Some(normals) => normals::with_given_normals(loaded.positions, normals, loaded.texcoords, loaded.triangles),
        None => normals::crease_normals(
            &loaded.positions,
            &loaded.texcoords,
            &loaded.triangles,
            normals::CREASE_ANGLE_DEG.to_radians(),
        ),
    };
    geometry.triangle_materials = triangle_materials;

    let area = geometry.area();
    if area <= 0.0 || !area.is_finite() {
        return Err(SceneError::Obj {
            field: file_field,
            file,
            line: None,
            message: format!("the mesh has no usable surface area (total {area} square units)"),
        });
    }
    let sparse_count = description.sparse_points as usize;
    let spacing = (area / sparse_count as f64).sqrt() as f32;
    let original_triangles = geometry.triangles.len();
    let normals_at = started.elapsed();
    let cap = budget.left.min(MAX_TRIANGLES_PER_MESH);
    let max_edge = spacing * settings.sparse.subdivision;
    subdivide::subdivide(&mut geometry, max_edge, cap).map_err(|limit| {
        let what =
            format!("subdividing to {max_edge} ({} sparse point spacings) would go", settings.sparse.subdivision);
        if limit < MAX_TRIANGLES_PER_MESH {
            budget.exceeded(format!("{field}.sparse_points"), &what)
        } else {
            SceneError::Obj {
                field: format!("{field}.sparse_points"),
                file: file.clone(),
                line: None,
                message: format!("{what} over {limit} triangles per mesh; use fewer sparse points"),
            }
        }
    })?;

    let subdivided_at = started.elapsed();
    let stream = index as u64;
    let neighbours = settings.interpolation_neighbours as usize;
    let candidates = adaptive_candidates(sparse_count, settings.sparse.adaptive);
    let sparse = sparse::build(&geometry, sparse_count, candidates, neighbours, settings.seed, stream)
        .map_err(|message| SceneError::Obj { field: field.clone(), file: file.clone(), line: None, message })?;

    let name = file.file_stem().map_or_else(|| format!("mesh{index}"), |s| s.to_string_lossy().into_owned());
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    tracing::debug!(
        mesh = %name,
        obj_ms = ms(loaded_at),
        normals_ms = ms(normals_at - loaded_at),
        subdivide_ms = ms(subdivided_at - normals_at),
        sparse_ms = ms(started.elapsed() - subdivided_at),
        "mesh load steps"
    );
    tracing::info!(
        mesh = %name,
        vertices = geometry.positions.len(),
        triangles = geometry.triangles.len(),
        obj_triangles = original_triangles,
        sparse_points = sparse.base_len(),
        adaptive_candidates = sparse.candidates,
        spacing,
        elapsed_ms = ms(started.elapsed()),
        "loaded mesh"
    );
    Ok(Mesh {
        name,
        // Placed relative to the scene's origin once every mesh is loaded.
        model_to_world: Mat4::IDENTITY,
        positions: geometry.positions,
        normals: geometry.normals,
        texcoords: geometry.texcoords,
        triangles: geometry.triangles,
        triangle_materials: geometry.triangle_materials,
        sparse,
    })
}

/// Indexed triangle geometry with one normal and one texture coordinate per vertex, as passed
/// between the load steps.
#[derive(Clone, Debug, Default)]
pub(crate) struct Geometry {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub texcoords: Vec<Vec2>,
    pub triangles: Vec<[u32; 3]>,
    /// Per triangle; any meaning (local or global material index), carried through untouched.
    pub triangle_materials: Vec<u32>,
}

impl Geometry {
    /// Corner positions of triangle `t`.
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        self.triangles[t].map(|v| self.positions[v as usize])
    }

    /// Area of triangle `t`, square model units.
    pub fn triangle_area(&self, t: usize) -> f64 {
        triangle_area(self.corners(t))
    }

    /// Total surface area, square model units.
    pub fn area(&self) -> f64 {
        surface_area(&self.positions, &self.triangles)
    }
}

/// Total area of `triangles` (corner indices into `positions`), in f64 as [`triangle_area`].
/// The adaptive points a mesh of `sparse_points` may gather in a frame at
/// `settings.sparse.adaptive` = `fraction`: its share of the scene's budget.
pub fn adaptive_budget(sparse_points: usize, fraction: f32) -> usize {
    (sparse_points as f64 * f64::from(fraction)).round() as usize
}

/// The adaptive candidates a mesh of `sparse_points` holds at `fraction`:
/// [`ADAPTIVE_CANDIDATES`] per point of its budget, at most what the placement's elimination
/// removes (`sparse::OVERSAMPLING - 1` per point).
pub fn adaptive_candidates(sparse_points: usize, fraction: f32) -> usize {
    let most = sparse_points * (sparse::OVERSAMPLING - 1);
    (adaptive_budget(sparse_points, fraction) * ADAPTIVE_CANDIDATES).min(most)
}

pub fn surface_area(positions: &[Vec3], triangles: &[[u32; 3]]) -> f64 {
    triangles.iter().map(|t| triangle_area(t.map(|i| positions[i as usize]))).sum()
}

/// Area of a triangle, computed in f64 so that large flat triangles keep their precision.
pub(crate) fn triangle_area([a, b, c]: [Vec3; 3]) -> f64 {
    let (a, b, c) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    0.5 * (b - a).cross(c - a).length()
}

#[cfg(test)]
pub(crate) mod test_util {
    //! Helpers for writing small scene fixtures to a unique temporary directory.

    use std::path::{Path, PathBuf};
    use std::sync::atomic::{AtomicU32, Ordering};

    /// A temporary directory removed on drop.
    pub struct TempDir(PathBuf);

    impl TempDir {
        pub fn new(tag: &str) -> TempDir {
            static COUNTER: AtomicU32 = AtomicU32::new(0);
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let dir = std::env::temp_dir().join(format!("relume-scene-test-{}-{tag}-{n}", std::process::id()));
            std::fs::create_dir_all(&dir).expect("create temp dir");
            TempDir(dir)
        }

        pub fn path(&self) -> &Path {
            &self.0
        }

        pub fn write(&self, name: &str, text: &str) -> PathBuf {
            let path = self.0.join(name);
            std::fs::write(&path, text).expect("write fixture");
            path
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// Light and camera JSON that pass validation, to complete a scene under test.
    pub const LIGHT_AND_CAMERA: &str = r#"
        "light": {"position": [0, 1.9, 0], "direction": [0, -1, 0],
                  "inner_angle_deg": 20, "outer_angle_deg": 30, "intensity": [10, 10, 10]},
        "camera": {"position": [0, 1, 3.5], "target": [0, 1, 0], "fov_y_deg": 40,
                   "width": 64, "height": 64}"#;

    /// A scene JSON with one mesh whose entry is `mesh` (the object body without braces).
    pub fn scene_json(mesh: &str) -> String {
        scene_json_with(mesh, "")
    }

    /// [`scene_json`] with `extra` (e.g. `, "settings": {...}`) appended to the top object.
    pub fn scene_json_with(mesh: &str, extra: &str) -> String {
        format!(r#"{{"meshes": [{{{mesh}}}], {LIGHT_AND_CAMERA}{extra}}}"#)
    }
}

#[cfg(test)]
mod tests {
    use super::test_util::{TempDir, scene_json, scene_json_with};
    use super::*;

    const CUBE_OBJ: &str = "\
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";

    #[test]
    fn loads_a_scene_end_to_end() {
        let dir = TempDir::new("end-to-end");
        dir.write("cube.obj", CUBE_OBJ);
        let json = scene_json(
            r#""obj": "cube.obj", "sparse_points": 64,
               "transform": {"translation": [1, 2, 3], "scale": 2},
               "material": {"diffuse": [0.2, 0.3, 0.4], "specular": [0.5, 0.5, 0.5], "exponent": 30}"#,
        );
        let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");
        assert_eq!(scene.meshes.len(), 1);
        let mesh = &scene.meshes[0];
        assert_eq!(mesh.name, "cube");
        assert_eq!(scene.sparse_point_count(), 64);
        assert_eq!(mesh.normals.len(), mesh.positions.len());
        assert_eq!(mesh.triangle_materials.len(), mesh.triangles.len());
        assert_eq!(mesh.sparse.vertex_neighbours.len(), mesh.positions.len() * DEFAULT_NEIGHBOURS as usize);
        assert_eq!(scene.materials.len(), 1);
        assert_eq!(scene.materials[0].exponent, 30.0);
        assert!(scene.needs_glossy());
        // World transform: the model-space corner (1, 1, 1) lands at 2 * (1, 1, 1) + (1, 2, 3),
        // in user coordinates (local + origin).
        let world = mesh.world_positions();
        let user = |p: &Vec3| p.as_dvec3() + scene.origin;
        assert!(world.iter().any(|p| user(p).abs_diff_eq(DVec3::new(3.0, 4.0, 5.0), 1e-5)));
        for n in mesh.world_normals() {
            assert!((n.length() - 1.0).abs() < 1e-5);
        }
        let radii = mesh.world_occluder_radii();
        for (world, model) in radii.iter().zip(&mesh.sparse.occluder_radii) {
            assert!((world - 2.0 * model).abs() < 1e-5);
        }
    }

    /// A scene 100 km out keeps its millimetres: the floating origin is the meshes' centre,
    /// and the local positions are the user's minus it, exact to f32 at the scene's size
    /// (the user-space f32 spacing there is 7.8 mm).
    #[test]
    fn far_scenes_are_local_to_their_centre() {
        let dir = TempDir::new("far_scene");
        dir.write("cube.obj", CUBE_OBJ);
        let far = r#""obj": "cube.obj", "sparse_points": 8,
                     "transform": {"translation": [100000.001, -70000.002, 30000.003]}"#;
        let json = scene_json(far).replace(
            r#""camera": {"position": [0, 1, 3.5], "target": [0, 1, 0]"#,
            r#""camera": {"position": [100000.501, -69999.502, 30003.503], "target": [100000.501, -69999.502, 30000.503]"#,
        );
        let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");
        let user = DVec3::new(100000.001, -70000.002, 30000.003);
        assert!(scene.origin.abs_diff_eq(user + DVec3::splat(0.5), 1e-9), "origin {}", scene.origin);
        let local = scene.meshes[0].world_positions();
        for (p, model) in local.iter().zip(&scene.meshes[0].positions) {
            assert!(p.abs_diff_eq(*model - Vec3::splat(0.5), 1e-7), "{p} for model {model}");
        }
        assert!(scene.camera.position.abs_diff_eq(Vec3::new(0.0, 0.0, 3.0), 1e-6), "{}", scene.camera.position);
        let moved = DMat4::from_translation(user + DVec3::X);
        assert!(
            scene
                .mesh_to_world(0, Some(moved))
                .transform_point3(Vec3::ZERO)
                .abs_diff_eq(Vec3::new(0.5, -0.5, -0.5), 1e-7)
        );
        // A pose's sub-millimetre survives: f32 would round 100 km to 7.8 mm steps.
        let at = DVec3::new(100000.0012, -70000.0007, 30000.0003);
        let pose = DAffine3::from_rotation_translation(glam::DQuat::from_rotation_y(0.3), at);
        let local = scene.local_pose(&pose);
        assert!(Vec3::from(local.translation).abs_diff_eq((at - scene.origin).as_vec3(), 1e-7));
        assert!(local.matrix3.abs_diff_eq(glam::Mat3A::from_rotation_y(0.3), 1e-7));

        let too_far = scene_json(r#""obj": "cube.obj", "sparse_points": 8, "transform": {"translation": [2e7, 0, 0]}"#);
        let message = Scene::from_json_str(&too_far, dir.path()).expect_err("too far").to_string();
        assert!(message.contains("meshes[0].transform.translation[0]"), "{message}");
    }

    fn mesh_of(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
        let n = positions.len();
        Mesh {
            name: "test".to_owned(),
            model_to_world: Mat4::IDENTITY,
            positions,
            normals: vec![Vec3::Y; n],
            texcoords: vec![Vec2::ZERO; n],
            triangle_materials: vec![0; triangles.len()],
            triangles,
            sparse: SparsePoints::default(),
        }
    }

    /// A unit cube, counter-clockwise seen from outside.
    fn cube() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let p = (0..8).map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32)).collect();
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let t = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        (p, t)
    }

    /// A convex object and a convex room cannot occlude themselves; two boxes side by side
    /// (one mesh) can.
    #[test]
    fn self_occlusion_test_tells_convex_from_concave() {
        let (p, t) = cube();
        assert!(!mesh_of(p.clone(), t.clone()).may_occlude_itself(), "cube seen from outside");
        let inward: Vec<[u32; 3]> = t.iter().map(|&[a, b, c]| [a, c, b]).collect();
        assert!(!mesh_of(p.clone(), inward).may_occlude_itself(), "room seen from inside");
        let mut p2 = p.clone();
        p2.extend(p.iter().map(|v| *v + Vec3::new(3.0, 0.0, 0.0)));
        let mut t2 = t.clone();
        t2.extend(t.iter().map(|f| f.map(|i| i + 8)));
        assert!(mesh_of(p2, t2).may_occlude_itself(), "two boxes");
    }

    #[test]
    fn world_normals_use_the_inverse_transpose() {
        let n = Vec3::new(1.0, 1.0, 0.0).normalize();
        let mesh = Mesh {
            name: "plane".to_owned(),
            model_to_world: Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0)),
            positions: vec![Vec3::ZERO, Vec3::Z, Vec3::new(1.0, -1.0, 0.0)],
            normals: vec![n; 3],
            texcoords: vec![Vec2::ZERO; 3],
            triangles: vec![[0, 1, 2]],
            triangle_materials: vec![0],
            sparse: SparsePoints {
                positions: vec![Vec3::new(0.5, -0.5, 0.0)],
                normals: vec![n],
                occluder_radii: vec![0.25],
                ..Default::default()
            },
        };
        // The plane x + y = 0 stretched by 2 along y is x + y / 2 = 0: normal (1, 1/2, 0).
        let expected = Vec3::new(1.0, 0.5, 0.0).normalize();
        for world in mesh.world_normals().into_iter().chain(mesh.sparse_world_normals()) {
            assert!(world.abs_diff_eq(expected, 1e-6), "{world}");
        }
        let world = mesh.world_positions();
        let edge = world[2] - world[0];
        assert!(edge.dot(expected).abs() < 1e-6, "the normal stays perpendicular to the surface");
        assert_eq!(mesh.sparse_world_positions(), vec![Vec3::new(0.5, -1.0, 0.0)]);
        assert_eq!(mesh.world_occluder_radii(), vec![0.5]);
    }

    #[test]
    fn glossy_needs_the_setting_and_a_glossy_material() {
        let dir = TempDir::new("glossy");
        dir.write("cube.obj", CUBE_OBJ);
        let diffuse_only = scene_json(r#""obj": "cube.obj", "sparse_points": 8"#);
        let scene = Scene::from_json_str(&diffuse_only, dir.path()).expect("scene loads");
        assert!(!scene.needs_glossy());
        assert_eq!(scene.materials, vec![Material::DEFAULT]);

        let glossy_mesh = r#""obj": "cube.obj", "sparse_points": 8, "material": {"specular": [0, 0.1, 0]}"#;
        let scene = Scene::from_json_str(&scene_json(glossy_mesh), dir.path()).expect("loads");
        assert!(scene.needs_glossy());
        let glossy_off = scene_json_with(glossy_mesh, r#", "settings": {"glossy": false}"#);
        let scene = Scene::from_json_str(&glossy_off, dir.path()).expect("scene loads");
        assert!(!scene.settings.glossy);
        assert!(!scene.needs_glossy());
    }

    #[test]
    fn load_reads_relative_to_the_scene_file() {
        let dir = TempDir::new("load");
        std::fs::create_dir_all(dir.path().join("meshes")).expect("mkdir");
        dir.write("meshes/cube.obj", CUBE_OBJ);
        let scene_path = dir.write("scene.json", &scene_json(r#""obj": "meshes/cube.obj", "sparse_points": 16"#));
        let scene = Scene::load(&scene_path).expect("scene loads");
        assert_eq!(scene.triangle_count(), scene.meshes[0].triangles.len());
        assert_eq!(scene.vertex_count(), scene.meshes[0].positions.len());

        let missing = Scene::load(&dir.path().join("nope.json")).expect_err("missing file");
        assert!(missing.to_string().contains("nope.json"), "{missing}");
    }

    #[test]
    fn missing_obj_names_the_field_and_file() {
        let dir = TempDir::new("missing-obj");
        let json = scene_json(r#""obj": "does-not-exist.obj", "sparse_points": 8"#);
        let error = Scene::from_json_str(&json, dir.path()).expect_err("missing OBJ");
        let message = error.to_string();
        assert!(message.contains("meshes[0].obj"), "{message}");
        assert!(message.contains("does-not-exist.obj"), "{message}");
    }

    /// A 2 x 1 quad in z = 0 whose texture coordinates are `uv = (x / 2, y)`, split into two
    /// groups with materials `left` and `right` (defined in `quad.mtl`).
    const TEXTURED_QUAD_OBJ: &str = "\
mtllib quad.mtl
v 0 0 0\nv 1 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 0 1 0
vt 0 0\nvt 0.5 0\nvt 1 0\nvt 1 1\nvt 0.5 1\nvt 0 1
g left
usemtl left
f 1/1 2/2 5/5 6/6
g right
usemtl right
f 2/2 3/3 4/4 5/5
";

    /// Writes a `width` x `height` RGBA PNG whose texel (x, y) is `[x, y, 7, 200]`.
    fn write_rgba_png(dir: &TempDir, name: &str, width: u32, height: u32) -> std::path::PathBuf {
        let path = dir.path().join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).expect("mkdir");
        }
        image::RgbaImage::from_fn(width, height, |x, y| image::Rgba([x as u8, y as u8, 7, 200]))
            .save(&path)
            .expect("write PNG");
        path
    }

    /// Asserts that every vertex's texture coordinates are `uv(position)`.
    fn assert_uv_is(mesh: &Mesh, uv: impl Fn(Vec3) -> Vec2) {
        assert_eq!(mesh.texcoords.len(), mesh.positions.len());
        for (p, t) in mesh.positions.iter().zip(&mesh.texcoords) {
            assert!(t.abs_diff_eq(uv(*p), 1e-5), "vertex at {p} has uv {t}, expected {}", uv(*p));
        }
    }

    #[test]
    fn map_kd_textures_load_with_their_texcoords() {
        let dir = TempDir::new("map-kd");
        write_rgba_png(&dir, "textures/bricks.png", 3, 2);
        let rgb = dir.path().join("plain.png");
        image::RgbImage::from_pixel(1, 1, image::Rgb([10, 20, 30])).save(&rgb).expect("write PNG");
        dir.write(
            "quad.mtl",
            "newmtl left\nKd 0.5 0.5 0.5\nmap_Kd textures/bricks.png\n\
             newmtl right\nKd 1 1 1\nmap_Kd -s 1 1 1 plain.png\n",
        );
        dir.write("quad.obj", TEXTURED_QUAD_OBJ);
        let json = scene_json(r#""obj": "quad.obj", "sparse_points": 4"#);
        let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");

        assert_eq!(scene.textures.len(), 2);
        let bricks = &scene.textures[0];
        assert_eq!(bricks.path, dir.path().join("textures/bricks.png"));
        assert_eq!((bricks.width, bricks.height), (3, 2));
        assert_eq!(bricks.rgba8.len(), 3 * 2 * 4);
        // Row-major from the top row: texel (x = 2, y = 1) starts at byte 4 * (1 * 3 + 2).
        assert_eq!(&bricks.rgba8[..4], &[0, 0, 7, 200]);
        assert_eq!(&bricks.rgba8[20..24], &[2, 1, 7, 200]);
        let plain = &scene.textures[1];
        assert_eq!(plain.rgba8, vec![10, 20, 30, 255], "alpha 255 when the file has none");

        let mesh = &scene.meshes[0];
        for (t, &m) in mesh.triangle_materials.iter().enumerate() {
            let material = scene.materials[m as usize];
            let centre = mesh.triangles[t].iter().map(|&v| mesh.positions[v as usize]).sum::<Vec3>() / 3.0;
            if centre.x < 1.0 {
                assert_eq!(material.diffuse_texture, Some(0));
                assert_eq!(material.diffuse, Vec3::splat(0.5));
            } else {
                assert_eq!(material.diffuse_texture, Some(1));
            }
        }
        assert_uv_is(mesh, |p| Vec2::new(p.x / 2.0, p.y));
        // The shared edge x = 1 has the same texture coordinates on both sides: welded.
        assert_eq!(mesh.positions.iter().filter(|p| p.x == 1.0 && p.y == 0.0).count(), 1);
    }

    #[test]
    fn materials_sharing_a_png_share_one_texture() {
        let dir = TempDir::new("shared-texture");
        write_rgba_png(&dir, "tex/shared.png", 2, 2);
        std::fs::create_dir_all(dir.path().join("mtl")).expect("mkdir");
        // Two spellings of one file.
        dir.write("mtl/quad.mtl", "newmtl left\nmap_Kd ../tex/shared.png\nnewmtl right\nmap_Kd ../tex/./shared.png\n");
        dir.write("quad.obj", &TEXTURED_QUAD_OBJ.replace("mtllib quad.mtl", "mtllib mtl/quad.mtl"));
        // Two meshes, and a JSON material with the same file: still one texture.
        let mesh = r#"{"obj": "quad.obj", "sparse_points": 4}"#;
        let json_mesh = r#"{"obj": "quad.obj", "sparse_points": 4,
                            "material": {"diffuse_texture": "tex/shared.png"}}"#;
        let json = format!(r#"{{"meshes": [{mesh}, {mesh}, {json_mesh}], {}}}"#, super::test_util::LIGHT_AND_CAMERA);
        let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");
        assert_eq!(scene.textures.len(), 1);
        assert_eq!(scene.textures[0].path, dir.path().join("mtl/../tex/shared.png"));
        // One entry per (mesh, material name), as without textures.
        assert_eq!(scene.materials.len(), 6);
        assert!(scene.materials.iter().all(|m| m.diffuse_texture == Some(0)));
    }

    #[test]
    fn missing_textures_name_the_mtl_and_the_texture() {
        let dir = TempDir::new("missing-texture");
        dir.write("quad.mtl", "newmtl left\nKd 1 1 1\n\nmap_Kd textures/nope.png\nnewmtl right\n");
        dir.write("quad.obj", TEXTURED_QUAD_OBJ);
        let json = scene_json(r#""obj": "quad.obj", "sparse_points": 4"#);
        let message = Scene::from_json_str(&json, dir.path()).expect_err("missing texture").to_string();
        assert!(message.starts_with("meshes[0].obj: "), "{message}");
        assert!(message.contains("quad.mtl:4: material `left`: map_Kd"), "{message}");
        assert!(message.contains("textures/nope.png"), "{message}");

        // An unreadable one (not an image) is an error too.
        std::fs::create_dir_all(dir.path().join("textures")).expect("mkdir");
        dir.write("textures/nope.png", "not a PNG");
        let message = Scene::from_json_str(&json, dir.path()).expect_err("bad texture").to_string();
        assert!(message.contains("nope.png"), "{message}");
        assert!(message.contains("not an image file"), "{message}");

        // A JSON material's missing texture names the field and the file.
        let json = scene_json(r#""obj": "quad.obj", "sparse_points": 4, "material": {"diffuse_texture": "gone.png"}"#);
        let message = Scene::from_json_str(&json, dir.path()).expect_err("missing JSON texture").to_string();
        assert!(message.starts_with("meshes[0].material.diffuse_texture: "), "{message}");
        assert!(message.contains("gone.png"), "{message}");
    }

    #[test]
    fn subdivision_keeps_texcoords_affine_in_position() {
        let dir = TempDir::new("subdivide-uv");
        write_rgba_png(&dir, "t.png", 4, 4);
        dir.write("quad.mtl", "newmtl left\nmap_Kd t.png\nnewmtl right\nmap_Kd t.png\n");
        // The quad scaled to 20 x 10 and sheared in uv: uv = (0.1 + 0.04 x - 0.02 y, 0.05 x + 0.1 y).
        let uv = |p: Vec3| Vec2::new(0.1 + 0.04 * p.x - 0.02 * p.y, 0.05 * p.x + 0.1 * p.y);
        let mut obj = String::from("mtllib quad.mtl\n");
        let corners = [[0, 0], [10, 0], [20, 0], [20, 10], [10, 10], [0, 10]];
        for [x, y] in corners {
            obj.push_str(&format!("v {x} {y} 0\n"));
        }
        for [x, y] in corners {
            let t = uv(Vec3::new(x as f32, y as f32, 0.0));
            obj.push_str(&format!("vt {} {}\n", t.x, t.y));
        }
        obj.push_str("usemtl left\nf 1/1 2/2 5/5 6/6\nusemtl right\nf 2/2 3/3 4/4 5/5\n");
        dir.write("quad.obj", &obj);
        let json = scene_json(r#""obj": "quad.obj", "sparse_points": 512"#);
        let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");
        let mesh = &scene.meshes[0];
        assert!(mesh.triangles.len() > 500, "subdivided: {} triangles", mesh.triangles.len());
        assert_uv_is(mesh, uv);
        assert_eq!(scene.textures.len(), 1);
    }

    #[test]
    fn json_diffuse_texture_replaces_the_mtl_material() {
        let dir = TempDir::new("json-texture");
        write_rgba_png(&dir, "scene-tex/wood.png", 5, 3);
        write_rgba_png(&dir, "mtl-tex.png", 2, 2);
        std::fs::create_dir_all(dir.path().join("meshes")).expect("mkdir");
        dir.write("meshes/quad.mtl", "newmtl left\nmap_Kd ../mtl-tex.png\nnewmtl right\nmap_Kd ../mtl-tex.png\n");
        dir.write("meshes/quad.obj", TEXTURED_QUAD_OBJ);
        let scene_path = dir.write(
            "scene.json",
            &scene_json(
                r#""obj": "meshes/quad.obj", "sparse_points": 4,
                   "materials": {"left": {"diffuse": [0.8, 0.8, 0.8], "diffuse_texture": "scene-tex/wood.png"},
                                 "right": {"diffuse": [0.2, 0.3, 0.4]}}"#,
            ),
        );
        let scene = Scene::load(&scene_path).expect("scene loads");
        // Only the JSON texture: the MTL materials, and their map_Kd, are replaced.
        assert_eq!(scene.textures.len(), 1);
        assert_eq!(scene.textures[0].path, dir.path().join("scene-tex/wood.png"));
        assert_eq!((scene.textures[0].width, scene.textures[0].height), (5, 3));
        let mut materials = scene.materials.clone();
        materials.sort_by(|a, b| b.diffuse.x.total_cmp(&a.diffuse.x));
        assert_eq!(materials[0].diffuse, Vec3::splat(0.8));
        assert_eq!(materials[0].diffuse_texture, Some(0));
        assert_eq!(materials[1].diffuse_texture, None);
        assert_uv_is(&scene.meshes[0], |p| Vec2::new(p.x / 2.0, p.y));
    }

    #[test]
    fn meshes_without_texcoords_get_zeros() {
        let dir = TempDir::new("no-texcoords");
        dir.write("cube.obj", CUBE_OBJ);
        let scene = Scene::from_json_str(&scene_json(r#""obj": "cube.obj", "sparse_points": 32"#), dir.path())
            .expect("scene loads");
        let mesh = &scene.meshes[0];
        assert_eq!(mesh.texcoords, vec![Vec2::ZERO; mesh.positions.len()]);
        assert!(scene.textures.is_empty());
        assert_eq!(scene.materials[0].diffuse_texture, None);
    }

    /// The folder of a mesh shipped with the project (`fixtures/meshes/<name>`, else the shared
    /// data set next to the checkout); `None`, with a note, when neither exists.
    fn mesh_dir(name: &str) -> Option<std::path::PathBuf> {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let found = [root.join("fixtures/meshes").join(name), root.join("../shared/data/meshes").join(name)]
            .into_iter()
            .find(|dir| dir.is_dir());
        if found.is_none() {
            eprintln!("skipping: mesh folder {name} not found");
        }
        found
    }

    #[test]
    fn cornell_box_loads_if_present() {
        let Some(dir) = mesh_dir("cornell_box") else {
            return;
        };
        let dir = dir.as_path();
        let json = scene_json(
            r#""obj": "CornellBox-Original.obj", "sparse_points": 1024,
               "materials": {"tallBox": {"diffuse": [0.5, 0.5, 0.5], "specular": [0.3, 0.3, 0.3], "exponent": 50}}"#,
        );
        let started = std::time::Instant::now();
        let scene = Scene::from_json_str(&json, dir).expect("Cornell box loads");
        let elapsed = started.elapsed();
        assert_eq!(scene.materials.len(), 8, "one entry per named material");
        assert_eq!(scene.sparse_point_count(), 1024);
        assert!(scene.needs_glossy());
        let red = Vec3::new(0.63, 0.065, 0.05);
        assert!(scene.materials.iter().any(|m| m.diffuse == red));
        assert!(elapsed.as_secs_f32() < 10.0, "took {elapsed:?}");

        let skip_light =
            scene_json(r#""obj": "CornellBox-Original.obj", "sparse_points": 256, "skip_groups": ["light"]"#);
        let scene = Scene::from_json_str(&skip_light, dir).expect("Cornell box loads");
        assert_eq!(scene.materials.len(), 7);
        assert!(!scene.needs_glossy());
    }

    #[test]
    fn bunny_loads_fast_if_present() {
        let Some(dir) = mesh_dir("stanford_bunny") else {
            return;
        };
        let dir = dir.as_path();
        let json = scene_json(r#""obj": "stanford-bunny.obj", "sparse_points": 4096"#);
        let started = std::time::Instant::now();
        let scene = Scene::from_json_str(&json, dir).expect("bunny loads");
        let elapsed = started.elapsed();
        eprintln!(
            "bunny: {} vertices, {} triangles, {} sparse points in {elapsed:?}",
            scene.vertex_count(),
            scene.triangle_count(),
            scene.sparse_point_count()
        );
        assert_eq!(scene.sparse_point_count(), 4096);
        assert!(scene.triangle_count() >= 69_451);
        assert!(elapsed.as_secs_f32() < 20.0, "took {elapsed:?}");
    }
}
