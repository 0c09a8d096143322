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
