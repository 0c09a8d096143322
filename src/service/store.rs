//! The scene store (`--scene-store DIR`): how a scene outlives the backend that created it
//! when several `relume serve` run behind one load balancer.
//!
//! Every scene created is also written to the directory the backends share, as the
//! description it was created from (`<id>.json`, written to a temporary file and renamed, so a
//! reader never sees half of one). A request for a scene this process does not hold (a render,
//! a stream, a `GET`) loads it from there under the same id, as `POST /v1/scenes` would have;
//! a `DELETE` removes the file, and a process that still holds a scene whose file is gone
//! drops it at its next request. Mesh paths in a description are relative to `--assets`, so
//! the backends must share the asset directory too (inline OBJ text travels in the file).
//!
//! Ids are 16 lowercase hexadecimal digits (random per process, so two backends do not make
//! the same one); anything else is never looked up on disk. The subdirectory `tickets/` holds
//! the marks of spent stream tickets (`src/service/tickets.rs`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::AppState;
use super::error::ApiError;
use super::scenes::{self, Reservation, SceneEntry};
use crate::service::api::SceneInfo;

/// The directory of scene descriptions shared by the backends.
pub struct SceneStore {
    dir: PathBuf,
}

/// Whether `id` has the form of a scene id (16 lowercase hexadecimal digits).
pub fn is_scene_id(id: &str) -> bool {
    id.len() == 16 && id.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

impl SceneStore {
    /// The store in `dir`, created if missing.
    pub fn open(dir: &Path) -> std::io::Result<SceneStore> {
        std::fs::create_dir_all(dir)?;
        Ok(SceneStore { dir: std::fs::canonicalize(dir)? })
    }

    /// The store's directory, canonical.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The directory where the backends mark spent stream tickets
    /// (`DIR/tickets`, `src/service/tickets.rs`), created if missing.
    pub fn open_tickets(&self) -> std::io::Result<PathBuf> {
        let dir = self.dir.join(super::tickets::SPENT_DIRECTORY);
        std::fs::create_dir_all(&dir)?;
        Ok(dir)
    }

    fn path(&self, id: &str) -> Option<PathBuf> {
        is_scene_id(id).then(|| self.dir.join(format!("{id}.json")))
    }

    /// Writes scene `id`'s description.
    pub fn save(&self, id: &str, description: &[u8]) -> std::io::Result<()> {
        let path = self.path(id).ok_or_else(|| std::io::Error::other(format!("`{id}` is not a scene id")))?;
        let temporary = self.dir.join(format!(".{id}.{}.tmp", std::process::id()));
        std::fs::write(&temporary, description)?;
        std::fs::rename(&temporary, path)
    }

    /// Scene `id`'s description, if the store has it.
    pub fn load(&self, id: &str) -> std::io::Result<Option<Vec<u8>>> {
        let Some(path) = self.path(id) else { return Ok(None) };
        match std::fs::read(path) {
            Ok(bytes) => Ok(Some(bytes)),
            Err(error) if error.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(error) => Err(error),
        }
    }

    /// Whether the store has scene `id`.
    pub fn contains(&self, id: &str) -> bool {
        self.path(id).is_some_and(|path| path.is_file())
    }

    /// Removes scene `id`'s description; false when there was none.
    pub fn remove(&self, id: &str) -> std::io::Result<bool> {
        let Some(path) = self.path(id) else { return Ok(false) };
        match std::fs::remove_file(path) {
            Ok(()) => Ok(true),
            Err(error) if error.kind() == std::io::ErrorKind::NotFound => Ok(false),
            Err(error) => Err(error),
        }
    }
}

/// Loads the scene `description` (a `POST /v1/scenes` body) into the slot `reservation`
/// holds: admits it within the limits, builds it on a GPU worker and registers it. With a
/// store and `save`, writes it there first.
pub async fn load_scene(
    state: &Arc<AppState>,
    reservation: Reservation,
    description: bytes::Bytes,
    save: bool,
) -> Result<Arc<SceneEntry>, ApiError> {
    let id = reservation.id.clone();
    let loader = state.clone();
    let text = description.clone();
    let loaded = tokio::task::spawn_blocking(move || -> Result<scenes::Loaded, ApiError> {
        let text = std::str::from_utf8(&text).map_err(|e| {
            ApiError::new(
                axum::http::StatusCode::BAD_REQUEST,
                super::error::Code::InvalidJson,
                format!("the body is not UTF-8: {e}"),
            )
        })?;
        scenes::load(text, &loader.assets, &loader.config.limits)
    })
    .await
    .map_err(ApiError::internal)?;
    let (parsed, scene, environment) = loaded?;
    let info = SceneInfo::new(&id, &scene, parsed.camera.clone(), parsed.light.clone());
    let entry = SceneEntry {
        camera: parsed.camera,
        light: parsed.light,
        exposure: parsed.settings.exposure,
        mesh_count: scene.meshes.len(),
        settings: scene.settings,
        described: parsed.settings.clone(),
        origin: scene.origin,
        info: info.clone(),
    };
    if save && let Some(store) = &state.store {
        store.save(&id, &description).map_err(|e| ApiError::internal(format!("scene store: {e}")))?;
    }
    if let Err(error) = state.workers.add_scene(&id, scene, environment).await {
        if save && let Some(store) = &state.store {
            let _ = store.remove(&id);
        }
        return Err(error.into());
    }
    tracing::info!(scene = %id, triangles = info.triangles, sparse_points = info.sparse_points, "scene loaded");
    Ok(reservation.commit(entry))
}

/// Scene `id`: held here, or loaded from the store (`None`: neither). A scene held here whose
/// store file is gone was deleted through another backend: it is dropped here too.
pub async fn scene(state: &Arc<AppState>, id: &str) -> Result<Option<Arc<SceneEntry>>, ApiError> {
    let Some(store) = &state.store else { return Ok(state.scenes.get(id)) };
    if let Some(entry) = state.scenes.get(id) {
        if store.contains(id) {
            return Ok(Some(entry));
        }
        tracing::info!(scene = %id, "scene deleted from the store: dropped here");
        state.scenes.remove(id);
        state.workers.remove_scene(id).await?;
        return Ok(None);
    }
    if !is_scene_id(id) {
        return Ok(None);
    }
    // One load at a time, so that concurrent requests for one scene load it once.
    let _loading = state.store_loads.lock().await;
    if let Some(entry) = state.scenes.get(id) {
        return Ok(Some(entry));
    }
    let Some(description) = store.load(id).map_err(|e| ApiError::internal(format!("scene store: {e}")))? else {
        return Ok(None);
    };
    let reservation = state.scenes.reserve_as(id.to_owned())?;
    tracing::info!(scene = %id, "loading a scene from the store");
    load_scene(state, reservation, description.into(), false).await.map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scenes_are_stored_by_id_and_other_names_never_touch_the_disk() {
        let dir = std::env::temp_dir().join(format!("relume-store-test-{}", std::process::id()));
        let store = SceneStore::open(&dir).expect("store");
        let id = "00ff00ff00ff00ff";
        assert!(!store.contains(id));
        store.save(id, b"{}").expect("saved");
        assert!(store.contains(id));
        assert_eq!(store.load(id).expect("read").as_deref(), Some(&b"{}"[..]));
        for bad in ["../00ff00ff00ff00", "00FF00FF00FF00FF", "00ff00ff00ff00f", "00ff00ff00ff00ff0", ""] {
            assert!(!is_scene_id(bad), "{bad}");
            assert_eq!(store.load(bad).expect("not looked up"), None);
            assert!(store.save(bad, b"{}").is_err());
        }
        assert!(store.remove(id).expect("removed"));
        assert!(!store.remove(id).expect("gone"));
        assert_eq!(store.load(id).expect("read"), None);
        std::fs::remove_dir_all(dir).expect("cleaned");
    }
}
