//! Scenes held by the service: admitting a description (parse, validate, limits, paths confined
//! to the asset directory) and the registry of loaded scenes with the `max_scenes` limit.

use std::collections::HashMap;
use std::hash::BuildHasher;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use axum::http::StatusCode;

use crate::mr::environment::{Environment, EnvironmentError, EnvironmentSettings, MAX_MAP_SIDE};
use crate::scene::{CameraDescription, GltfSceneDescription, LightDescription, Scene, SceneDescription};

use super::api::SceneInfo;
use super::config::{Limits, limit};
use super::error::{ApiError, Code};

/// A scene admitted and loaded: its description, the scene, and the environment its stream
/// frames are lit by (`settings.environment`, its map read).
pub type Loaded = (SceneDescription, Scene, Environment);

/// Admits a scene description sent by a client ([`admit`]) and loads it within the limits:
/// the description, its scene and its environment. Errors about a whole glTF scene name its
/// fields ([`GltfSceneDescription::field_in_form`]).
pub fn load(text: &str, assets: &Path, limits: &Limits) -> Result<Loaded, ApiError> {
    if GltfSceneDescription::is_one(text) {
        let load = || {
            let whole = GltfSceneDescription::from_json_str(text).map_err(|e| ApiError::scene(&e, assets))?;
            let file = confine(assets, &whole.gltf, "gltf")?;
            check_file_bytes(file_size(&file), "gltf", "mesh", limits)?;
            let description = whole.to_scene_description(assets).map_err(|e| ApiError::scene(&e, assets))?;
            load_description(description, assets, limits)
        };
        return load().map_err(|e| e.with_field(GltfSceneDescription::field_in_form));
    }
    let description = SceneDescription::from_json_str(text).map_err(|e| ApiError::scene(&e, assets))?;
    load_description(description, assets, limits)
}

fn load_description(description: SceneDescription, assets: &Path, limits: &Limits) -> Result<Loaded, ApiError> {
    admit(&description, assets, limits)?;
    let scene = Scene::from_description_within(&description, assets, limits.max_triangles)
        .map_err(|e| ApiError::scene(&e, assets))?;
    let environment = load_environment(&description.settings.environment, assets, limits)?;
    Ok((description, scene, environment))
}

/// The field of `settings.environment` that names a file.
const ENVIRONMENT_MAP_FIELD: &str = "settings.environment.map";

/// The environment `settings` ask for, its map (confined to `assets` by [`admit`]) read with at
/// most `max_pixels` pixels; a map that cannot be read is a 400 naming
/// `settings.environment.map`, without the server's directory in the message.
fn load_environment(settings: &EnvironmentSettings, assets: &Path, limits: &Limits) -> Result<Environment, ApiError> {
    let relative = settings.map.as_deref().unwrap_or_default();
    Environment::from_settings_within(settings, assets, limits.max_pixels).map_err(|error| match error {
        EnvironmentError::TooManyPixels { width, height, max_pixels, .. } => ApiError::limit(
            limit::MAX_PIXELS,
            Some(ENVIRONMENT_MAP_FIELD.to_owned()),
            format!("{ENVIRONMENT_MAP_FIELD}: `{relative}` is {width}x{height}, over the limit of {max_pixels} pixels"),
        ),
        EnvironmentError::TooLarge { width, height, .. } => ApiError::limit(
            limit::MAX_PIXELS,
            Some(ENVIRONMENT_MAP_FIELD.to_owned()),
            format!(
                "{ENVIRONMENT_MAP_FIELD}: `{relative}` is {width}x{height}; maps up to {MAX_MAP_SIDE} pixels a side \
                 are read"
            ),
        ),
        EnvironmentError::Read { .. } | EnvironmentError::Missing => ApiError {
            field: Some(ENVIRONMENT_MAP_FIELD.to_owned()),
            ..ApiError::new(
                StatusCode::BAD_REQUEST,
                Code::InvalidScene,
                format!("{ENVIRONMENT_MAP_FIELD}: `{relative}` is not an equirectangular map the server can read"),
            )
        },
    })
}

/// Validates a parsed scene description sent by a client, and checks what the scene module
/// does not: the service's limits, and that every file it names is inside `assets`
/// (canonical). Reads no mesh; touches the file system only to resolve paths.
pub fn admit(description: &SceneDescription, assets: &Path, limits: &Limits) -> Result<(), ApiError> {
    description.validate().map_err(|e| ApiError::scene(&e, assets))?;
    // The frame's VALs from the scene's own lights, part by part: the first part that takes
    // the sum over the limit is the field named.
    let mut sum = 0u64;
    let mut terms = Vec::new();
    for (field, vals) in description.frame_vals() {
        sum += vals;
        terms.push(format!("{field} {vals}"));
        if sum > limits.max_vals as u64 {
            let what = match terms.len() {
                1 if field == "settings.tuning.rsm_resolution" => {
                    let r = description.settings.before_load().rsm_resolution;
                    format!("{r}² = {vals} VALs per frame")
                }
                1 => format!("{vals} VALs per frame"),
                _ => format!("{} = {sum} VALs per frame", terms.join(" + ")),
            };
            return Err(ApiError::limit(
                limit::MAX_VALS,
                Some(field.to_owned()),
                format!("{field}: {what} is over the limit of {}", limits.max_vals),
            ));
        }
    }
    limits.check_image(description.camera.width, description.camera.height, "camera")?;
    let sparse_points: u64 = description.meshes.iter().map(|m| m.sparse_points as u64).sum();
    // Adaptive candidates are sparse points the scene holds too.
    let adaptive = description.settings.before_load().sparse.adaptive;
    let candidates: u64 = description
        .meshes
        .iter()
        .map(|m| crate::scene::adaptive_candidates(m.sparse_points as usize, adaptive) as u64)
        .sum();
    if sparse_points + candidates > limits.max_sparse_points as u64 {
        let what = if candidates > 0 {
            format!(
                "{} sparse points over all meshes ({sparse_points} and {candidates} adaptive candidates, \
                 settings.tuning.sparse.adaptive)",
                sparse_points + candidates
            )
        } else {
            format!("{sparse_points} sparse points over all meshes")
        };
        return Err(ApiError::limit(
            limit::MAX_SPARSE_POINTS,
            Some("meshes".to_owned()),
            format!("meshes: {what} is over the limit of {}", limits.max_sparse_points),
        ));
    }
    for (i, mesh) in description.meshes.iter().enumerate() {
        let field = format!("meshes[{i}]");
        match &mesh.obj_text {
            Some(text) => check_file_bytes(text.len() as u64, &format!("{field}.obj_text"), "mesh", limits)?,
            None => {
                // A glTF's own buffers and images are confined to its directory by its reader.
                let (file_field, relative) = match &mesh.gltf {
                    Some(gltf) => (format!("{field}.gltf"), gltf),
                    None => (format!("{field}.obj"), &mesh.obj),
                };
                check_file_bytes(file_size(&confine(assets, relative, &file_field)?), &file_field, "mesh", limits)?;
            }
        }
        let materials = mesh
            .material
            .iter()
            .map(|m| (format!("{field}.material"), m))
            .chain(mesh.materials.iter().map(|(name, m)| (format!("{field}.materials[{name:?}]"), m)));
        for (material_field, material) in materials {
            if let Some(texture) = &material.diffuse_texture {
                confine(assets, texture, &format!("{material_field}.diffuse_texture"))?;
            }
        }
    }
    // An environment map: in the asset directory, and at most `max_mesh_bytes` on disk
    // (its pixels are checked when it is read).
    if let Some(map) = &description.settings.environment.map {
        let bytes = file_size(&confine(assets, map, ENVIRONMENT_MAP_FIELD)?);
        check_file_bytes(bytes, ENVIRONMENT_MAP_FIELD, "map", limits)?;
    }
    Ok(())
}

/// Size of `file` on disk (0 when it cannot be read: reading it then names the error).
fn file_size(file: &Path) -> u64 {
    std::fs::metadata(file).map(|m| m.len()).unwrap_or(0)
}

/// A `what` file (`mesh`, `map`) of `bytes` at `field` within `max_mesh_bytes`.
fn check_file_bytes(bytes: u64, field: &str, what: &str, limits: &Limits) -> Result<(), ApiError> {
    if bytes > limits.max_mesh_bytes as u64 {
        return Err(ApiError::limit(
            limit::MAX_MESH_BYTES,
            Some(field.to_owned()),
            format!("{field}: the {what} file is {bytes} bytes, over the limit of {}", limits.max_mesh_bytes),
        ));
    }
    Ok(())
}

/// The file `relative` names inside `root` (canonical), canonical. Refuses absolute paths,
/// `..` that climbs above `root` and links that lead out of it, before looking at the file
/// system, so the answer does not reveal whether a file outside exists.
pub fn confine(root: &Path, relative: &str, field: &str) -> Result<PathBuf, ApiError> {
    let refused = |code: Code, message: String| ApiError {
        field: Some(field.to_owned()),
        ..ApiError::new(StatusCode::BAD_REQUEST, code, message)
    };
    let outside = || {
        refused(
            Code::PathOutsideAssets,
            format!("{field}: `{relative}` is outside the asset directory; paths are relative to it"),
        )
    };
    let mut depth = 0usize;
    for component in Path::new(relative).components() {
        match component {
            Component::Prefix(_) | Component::RootDir => return Err(outside()),
            Component::ParentDir => depth = depth.checked_sub(1).ok_or_else(outside)?,
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
        }
    }
    let missing = || refused(Code::InvalidScene, format!("{field}: no file `{relative}` in the asset directory"));
    let canonical = std::fs::canonicalize(root.join(relative)).map_err(|_| missing())?;
    if !canonical.starts_with(root) {
        return Err(outside());
    }
    if !canonical.is_file() {
        return Err(missing());
    }
    Ok(canonical)
}

/// What the service keeps of a loaded scene (its meshes live on the GPU thread).
#[derive(Clone, Debug)]
pub struct SceneEntry {
    pub info: SceneInfo,
    /// Renders without a `camera` use this one.
    pub camera: CameraDescription,
    /// Render `light` overrides apply to this one (none: the scene has no spot light).
    pub light: Option<LightDescription>,
    /// The scene file's `settings.exposure`.
    pub exposure: Option<f32>,
    pub mesh_count: usize,
    /// The loaded scene's render settings (occlusion resolved): where a stream starts.
    pub settings: crate::scene::Settings,
    /// The scene file's settings, which a render's or a stream's level is resolved from.
    pub described: crate::scene::SettingsDescription,
    /// The loaded scene's floating origin ([`crate::scene::Scene::origin`]): render and
    /// stream cameras and lights, given in user coordinates, are made relative to it.
    pub origin: glam::DVec3,
}

/// The scenes held, and the slots reserved by scenes being loaded.
pub struct SceneRegistry {
    inner: Arc<Mutex<Inner>>,
    max_scenes: usize,
    next: AtomicU64,
    ids: std::collections::hash_map::RandomState,
}

#[derive(Default)]
struct Inner {
    scenes: HashMap<String, Arc<SceneEntry>>,
    reserved: usize,
}

/// A `max_scenes` slot held while a scene loads; released on drop unless committed.
pub struct Reservation {
    inner: Arc<Mutex<Inner>>,
    /// The id the scene will have.
    pub id: String,
    committed: bool,
}

impl SceneRegistry {
    pub fn new(max_scenes: usize) -> SceneRegistry {
        SceneRegistry {
            inner: Arc::default(),
            max_scenes,
            next: AtomicU64::new(0),
            ids: std::collections::hash_map::RandomState::new(),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Holds a slot for a new scene, or refuses when `max_scenes` are held or loading.
    pub fn reserve(&self) -> Result<Reservation, ApiError> {
        // Unguessable ids: a per-process random key hashes a counter.
        let id = format!("{:016x}", self.ids.hash_one(self.next.fetch_add(1, Ordering::Relaxed)));
        self.reserve_as(id)
    }

    /// [`SceneRegistry::reserve`] for a scene whose id is given (one read from the scene
    /// store).
    pub fn reserve_as(&self, id: String) -> Result<Reservation, ApiError> {
        let mut inner = self.lock();
        if inner.scenes.len() + inner.reserved >= self.max_scenes {
            return Err(ApiError::limit(
                limit::MAX_SCENES,
                None,
                format!("{} scenes are held, the limit; delete one first", self.max_scenes),
            ));
        }
        inner.reserved += 1;
        Ok(Reservation { inner: self.inner.clone(), id, committed: false })
    }

    pub fn get(&self, id: &str) -> Option<Arc<SceneEntry>> {
        self.lock().scenes.get(id).cloned()
    }

    pub fn remove(&self, id: &str) -> Option<Arc<SceneEntry>> {
        self.lock().scenes.remove(id)
    }

    pub fn len(&self) -> usize {
        self.lock().scenes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl Reservation {
    /// The scene is loaded: it takes the reserved slot.
    pub fn commit(mut self, entry: SceneEntry) -> Arc<SceneEntry> {
        let entry = Arc::new(entry);
        let mut inner = self.inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        inner.reserved -= 1;
        inner.scenes.insert(self.id.clone(), entry.clone());
        self.committed = true;
        entry
    }
}

impl Drop for Reservation {
    fn drop(&mut self) {
        if !self.committed {
            self.inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).reserved -= 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assets() -> PathBuf {
        std::fs::canonicalize(Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures")).expect("fixtures")
    }

    #[test]
    fn paths_are_confined_to_the_asset_directory() {
        let root = assets();
        let obj = "meshes/cornell_box/CornellBox-Original.obj";
        assert_eq!(confine(&root, obj, "f").expect("inside"), root.join(obj));
        assert!(confine(&root, "meshes/../meshes/./cornell_box/CornellBox-Original.obj", "f").is_ok());
        for outside in ["../Cargo.toml", "/etc/passwd", "meshes/../../Cargo.toml", "../does-not-exist"] {
            let error = confine(&root, outside, "meshes[0].obj").expect_err(outside);
            assert_eq!(error.code, Code::PathOutsideAssets, "{outside}");
            assert_eq!(error.field.as_deref(), Some("meshes[0].obj"));
        }
        let error = confine(&root, "meshes/nope.obj", "f").expect_err("missing");
        assert_eq!(error.code, Code::InvalidScene);
        let error = confine(&root, "meshes", "f").expect_err("a directory");
        assert_eq!(error.code, Code::InvalidScene);
    }

    /// A frame's VALs are the `light`'s RSM plus the `lights`' budget (outside each other) plus
    /// the second bounce's: within the limit the scene is admitted; over it, the part that
    /// crosses the limit is named.
    #[test]
    fn admission_bounds_the_frames_vals_by_every_part() {
        let scene_with = |tuning: &str, lights: bool, bounces: u32| {
            let lights = if lights {
                r#", "lights": [{"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1]}]"#
            } else {
                ""
            };
            let json = format!(
                r#"{{"meshes": [{{"obj": "meshes/cornell_box/CornellBox-Original.obj", "sparse_points": 64}}],
                "light": {{"position": [0, 1.9, 0], "direction": [0, -1, 0], "inner_angle_deg": 30,
                          "outer_angle_deg": 40, "intensity": [1, 1, 1]}}{lights},
                "camera": {{"position": [0, 1, 3], "target": [0, 1, 0], "fov_y_deg": 40, "width": 8, "height": 8}},
                "settings": {{"bounces": {bounces}, "tuning": {tuning}}}}}"#
            );
            SceneDescription::from_json_str(&json).expect("parses")
        };
        let scene = |tuning: &str, lights: bool| scene_with(tuning, lights, 1);
        let limits = Limits { max_vals: 5000, ..Limits::default() };
        let admit = |d: &SceneDescription| admit(d, &assets(), &limits);
        // 64² = 4096 alone, and 4096 + 900 with lights: admitted.
        let ok = scene(r#"{"rsm_resolution": 64, "direct": {"val_budget": 900}}"#, true);
        assert_eq!(
            ok.frame_vals(),
            vec![("settings.tuning.rsm_resolution", 4096), ("settings.tuning.direct.val_budget", 900)]
        );
        admit(&ok).expect("4996 VALs");
        // 4096 + 1000: the budget crosses the limit.
        let e = admit(&scene(r#"{"rsm_resolution": 64, "direct": {"val_budget": 1000}}"#, true)).expect_err("5096");
        assert_eq!((e.limit, e.field.as_deref()), (Some(limit::MAX_VALS), Some("settings.tuning.direct.val_budget")));
        assert!(
            e.message.contains("settings.tuning.rsm_resolution 4096 + settings.tuning.direct.val_budget 1000 = 5096"),
            "{}",
            e.message
        );
        // The same budget without `lights` makes no VALs: admitted.
        admit(&scene(r#"{"rsm_resolution": 64, "direct": {"val_budget": 1000}}"#, false)).expect("4096 VALs");
        // The RSM alone over the limit names it.
        let e = admit(&scene(r#"{"rsm_resolution": 72}"#, false)).expect_err("72²");
        assert_eq!(e.field.as_deref(), Some("settings.tuning.rsm_resolution"));
        assert!(e.message.contains("72² = 5184 VALs per frame"), "{}", e.message);
        // A second bounce's VALs count too.
        let e = admit(&scene_with(r#"{"rsm_resolution": 64, "second_bounce": {"vals": 1024}}"#, false, 2))
            .expect_err("4096 + 1024");
        assert_eq!(e.field.as_deref(), Some("settings.tuning.second_bounce.vals"));
    }

    #[test]
    fn the_registry_counts_loading_scenes_against_the_limit() {
        let registry = SceneRegistry::new(2);
        let a = registry.reserve().expect("first");
        let b = registry.reserve().expect("second");
        assert_ne!(a.id, b.id);
        let error = registry.reserve().err().expect("third is over the limit");
        assert_eq!(error.limit, Some(limit::MAX_SCENES));
        drop(b);
        let c = registry.reserve().expect("a failed load frees its slot");
        assert!(registry.is_empty());
        let info = SceneInfo {
            id: a.id.clone(),
            meshes: Vec::new(),
            triangles: 0,
            sparse_points: 0,
            max_vals: 0,
            glossy: false,
            occlusion: crate::scene::Occlusion::Off,
            camera: serde_json::from_str(
                r#"{"position": [0, 0, 1], "target": [0, 0, 0], "fov_y_deg": 40, "width": 1, "height": 1}"#,
            )
            .expect("camera"),
            light: serde_json::from_str(
                r#"{"position": [0, 1, 0], "direction": [0, -1, 0], "inner_angle_deg": 1,
                    "outer_angle_deg": 2, "intensity": [1, 1, 1]}"#,
            )
            .expect("light"),
            resolved: Default::default(),
        };
        let id = a.id.clone();
        let entry = SceneEntry {
            camera: info.camera.clone(),
            light: info.light.clone(),
            info,
            exposure: None,
            mesh_count: 0,
            settings: crate::scene::SettingsDescription::default().before_load(),
            described: Default::default(),
            origin: glam::DVec3::ZERO,
        };
        a.commit(entry);
        assert_eq!(registry.len(), 1);
        assert!(registry.get(&id).is_some());
        assert!(registry.reserve().is_err(), "one held and one loading");
        drop(c);
        assert!(registry.remove(&id).is_some());
        assert!(registry.get(&id).is_none());
    }
}
