//! The scene module's error type. Every message names the offending JSON field path
//! (`meshes[0].transform.scale`) and, for mesh files, the file and line.

use std::fmt;
use std::path::{Path, PathBuf};

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file itself could not be read.
    #[error("cannot read scene file {}: {source}", path.display())]
    Read {
        /// The scene file.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },
    /// The JSON is malformed, has an unknown field, misses a required one, or has a value of
    /// the wrong type.
    #[error("{field}: {message} (JSON line {line}, column {column})")]
    Json {
        /// Path of the offending field, e.g. `meshes[0].transform.scale`; `(root)` for the
        /// document itself.
        field: String,
        /// What is wrong.
        message: String,
        /// 1-based line in the JSON text.
        line: usize,
        /// 1-based column in the JSON text.
        column: usize,
    },
    /// A value is out of range or inconsistent with another.
    #[error("{field}: {message}")]
    Field {
        /// Path of the offending field, e.g. `camera.fov_y_deg`.
        field: String,
        /// What is wrong, with the value found.
        message: String,
    },
    /// A mesh, material or texture file named by the scene cannot be used.
    #[error("{field}: {}: {message}", FileLine(file, *line))]
    Obj {
        /// Path of the scene field that led to the file, e.g. `meshes[0].obj`.
        field: String,
        /// The OBJ, MTL or texture file.
        file: PathBuf,
        /// 1-based line in `file`, when the problem is on one line.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// The scene would have more triangles than the loader was allowed (after subdivision,
    /// all meshes together).
    #[error("{field}: {message}")]
    TooManyTriangles {
        /// The mesh, `meshes[i].obj` (its OBJ alone is over) or `meshes[i].sparse_points`
        /// (subdividing it would be).
        field: String,
        /// The most triangles allowed.
        limit: usize,
        message: String,
    },
}

impl SceneError {
    /// A [`SceneError::Field`].
    pub(crate) fn field(field: impl Into<String>, message: impl Into<String>) -> SceneError {
        SceneError::Field { field: field.into(), message: message.into() }
    }

    /// The same error about `rename(field)`: for a description made from another form of
    /// input, whose fields sit elsewhere ([`super::GltfSceneDescription::field_in_form`]).
    pub fn with_field(mut self, rename: impl FnOnce(&str) -> String) -> SceneError {
        match &mut self {
            SceneError::Read { .. } => {}
            SceneError::Json { field, .. }
            | SceneError::Field { field, .. }
            | SceneError::Obj { field, .. }
            | SceneError::TooManyTriangles { field, .. } => *field = rename(field),
        }
        self
    }

    /// The JSON field path the error is about.
    pub fn field_path(&self) -> Option<&str> {
        match self {
            SceneError::Read { .. } => None,
            SceneError::Json { field, .. }
            | SceneError::Field { field, .. }
            | SceneError::Obj { field, .. }
            | SceneError::TooManyTriangles { field, .. } => Some(field),
        }
    }
}

/// Displays `file:line`, or `file` when there is no line.
struct FileLine<'a>(&'a Path, Option<usize>);

impl fmt::Display for FileLine<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.1 {
            Some(line) => write!(f, "{}:{line}", self.0.display()),
            None => write!(f, "{}", self.0.display()),
        }
    }
}
