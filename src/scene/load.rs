//! Loading a scene: the description validated, every mesh read, normals, subdivision and sparse
//! points, and the scene placed about its floating origin.

use std::path::Path;

use glam::{Affine3A, DAffine3, DMat4, DVec3, Mat4, Vec2, Vec3};

use super::description::{CameraDescription, LightEntry, MeshDescription, SceneDescription};
use super::settings::{ADAPTIVE_CANDIDATES, Quality, ResolvedConfig, SceneAnalysis, resolve};
use super::{
    GltfSceneDescription, MAX_TRIANGLES_PER_MESH, Material, Mesh, Scene, SceneError, Settings, gltf, normals, obj,
    sparse, subdivide, texture,
};

impl Scene {
    /// Parses and validates scene JSON and loads every mesh it names; OBJ paths are relative to
    /// `base_dir`.
    /// A JSON object with a top-level `gltf` field is a [`GltfSceneDescription`]: the whole
    /// scene from one glTF file (its meshes, spot light and camera) with relume's settings.
    pub fn from_json_str(text: &str, base_dir: &Path) -> Result<Scene, SceneError> {
        Self::from_json_str_at(text, base_dir, None)
    }

    /// [`Scene::from_json_str`] at `quality` instead of the scene file's `settings.quality`
    /// (`None`: the file's).
    pub fn from_json_str_at(text: &str, base_dir: &Path, quality: Option<Quality>) -> Result<Scene, SceneError> {
        let at = |mut description: SceneDescription| {
            if let Some(quality) = quality {
                description.settings.quality = quality;
            }
            description
        };
        if GltfSceneDescription::is_one(text) {
            let description = GltfSceneDescription::from_json_str(text)?.to_scene_description(base_dir)?;
            return Self::from_description(&at(description), base_dir)
                .map_err(|e| e.with_field(GltfSceneDescription::field_in_form));
        }
        Self::from_description(&at(SceneDescription::from_json_str(text)?), base_dir)
    }

    /// Reads a scene file; OBJ paths are relative to the directory that holds it.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        Self::load_at(path, None)
    }

    /// [`Scene::load`] at `quality` instead of the file's `settings.quality` (`None`: the
    /// file's).
    pub fn load_at(path: &Path, quality: Option<Quality>) -> Result<Scene, SceneError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| SceneError::Read { path: path.to_path_buf(), source })?;
        let base_dir = path.parent().unwrap_or_else(|| Path::new("."));
        Self::from_json_str_at(&text, base_dir, quality)
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
        // What the loader reads depends on the level and the tuning only (`resolve`).
        let load_settings = description.settings.before_load();
        let mut materials = Vec::new();
        let mut textures = texture::Textures::default();
        let mut meshes = Vec::with_capacity(description.meshes.len());
        let anchor = description.anchor.as_ref().map_or(DMat4::IDENTITY, |a| a.to_matrix());
        let mut triangles = 0usize;
        for (index, mesh_description) in description.meshes.iter().enumerate() {
            let budget = TriangleBudget { left: max_triangles.saturating_sub(triangles), total: max_triangles };
            let mesh =
                load_mesh(mesh_description, index, base_dir, &load_settings, &budget, &mut materials, &mut textures)?;
            triangles += mesh.triangles.len();
            meshes.push(mesh);
        }
        let user_to_world: Vec<DMat4> = description.meshes.iter().map(|m| anchor * m.transform.to_matrix()).collect();
        let boxes: Vec<_> = meshes.iter().zip(&user_to_world).map(|(m, t)| world_bounds(m, t)).collect();
        // A mesh that alone spans more than the renderer resolves (or is the whole scene) is
        // named; otherwise the meshes together.
        for (index, &(lo, hi)) in boxes.iter().enumerate().filter_map(|(i, b)| b.as_ref().map(|b| (i, b))) {
            if meshes.len() == 1 || lo.distance(hi) > super::description::MAX_SCENE_EXTENT_M {
                super::validate::scene_extent(lo.distance(hi), &format!("meshes[{index}]"))?;
            }
        }
        let bounds = boxes.into_iter().flatten().reduce(|(lo, hi), (l, h)| (lo.min(l), hi.max(h)));
        if let Some((lo, hi)) = bounds {
            super::validate::scene_extent(lo.distance(hi), "meshes")?;
        }
        let origin = floating_origin(bounds, &description.camera);
        for (mesh, transform) in meshes.iter_mut().zip(&user_to_world) {
            mesh.model_to_world = local_matrix(origin, *transform);
        }
        let analysis = analyse(&meshes, &materials, description);
        let quality = description.settings.quality;
        let (settings, choices) = resolve(quality, &analysis, &description.settings);
        debug_assert_eq!(
            (settings.sparse, settings.interpolation_neighbours, settings.seed),
            (load_settings.sparse, load_settings.interpolation_neighbours, load_settings.seed),
            "the loader's parameters do not depend on the analysis"
        );
        let (method, estimator_draws) = super::settings::technique(quality, &description.settings);
        let budget_ms = description.settings.budget_ms;
        let resolved = ResolvedConfig { quality, budget_ms, method, estimator_draws, analysis, choices };
        Ok(Scene {
            meshes,
            materials,
            textures: textures.textures,
            light: description.light.as_ref().map(|l| l.to_spot_light(origin)),
            lights: description.lights.iter().map(|l| l.to_light(origin)).collect(),
            camera: description.camera.to_camera(origin),
            settings,
            resolved,
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

/// What the quality levels look at in a loaded scene (its meshes placed, its materials
/// resolved).
fn analyse(meshes: &[Mesh], materials: &[Material], description: &SceneDescription) -> SceneAnalysis {
    let used_glossy = materials
        .iter()
        .enumerate()
        .filter(|(i, m)| m.is_glossy() && meshes.iter().any(|mesh| mesh.triangle_materials.contains(&(*i as u32))))
        .count();
    let triangles: usize = meshes.iter().map(|m| m.triangles.len()).sum();
    let points: usize = meshes.iter().map(|m| m.sparse.base_len()).sum();
    let spot_lights = description.lights.iter().filter(|l| matches!(l, LightEntry::Spot(_))).count();
    SceneAnalysis {
        meshes: meshes.len(),
        concave_meshes: meshes.iter().filter(|m| m.may_occlude_itself()).map(|m| m.name.clone()).collect(),
        glossy_materials: used_glossy,
        spot_light: description.light.is_some(),
        spot_lights,
        point_lights: description.lights.len() - spot_lights,
        triangles_per_sparse_point: if points == 0 { 0.0 } else { triangles as f32 / points as f32 },
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

/// The bounding box (min, max corner) of `mesh`'s vertices placed by `user_to_world` (user
/// world coordinates), computed in f64; `None` for a mesh without vertices.
fn world_bounds(mesh: &Mesh, user_to_world: &DMat4) -> Option<(DVec3, DVec3)> {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for p in &mesh.positions {
        let world = user_to_world.transform_point3(p.as_dvec3());
        (lo, hi) = (lo.min(world), hi.max(world));
    }
    lo.cmple(hi).all().then_some((lo, hi))
}

/// The scene's floating origin ([`Scene::origin`]): the centre of `bounds`, the bounding box of
/// every mesh's vertices in user world coordinates ([`world_bounds`]). The meshes are what the
/// precision-critical sums (RSM depths, the gather's moments, occluder discs) run over, so their
/// centre keeps every such coordinate as small as the scene; the camera and the light usually
/// sit near or inside it. A scene without vertices uses the camera's position.
fn floating_origin(bounds: Option<(DVec3, DVec3)>, camera: &CameraDescription) -> DVec3 {
    bounds.map_or_else(|| DVec3::from_array(camera.position), |(lo, hi)| (lo + hi) * 0.5)
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
    let sparse_count = settings.sparse.placed_points(description.sparse_points);
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

/// Total area of `triangles` (corner indices into `positions`), in f64 as [`triangle_area`].
pub fn surface_area(positions: &[Vec3], triangles: &[[u32; 3]]) -> f64 {
    triangles.iter().map(|t| triangle_area(t.map(|i| positions[i as usize]))).sum()
}

/// Area of a triangle, computed in f64 so that large flat triangles keep their precision.
pub(crate) fn triangle_area([a, b, c]: [Vec3; 3]) -> f64 {
    let (a, b, c) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    0.5 * (b - a).cross(c - a).length()
}
