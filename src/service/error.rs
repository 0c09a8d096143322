//! The HTTP API's error: a status and a JSON body `{"error": {"code", "message", "field",
//! "limit"}}`. Internal failures are logged in full and answered with a generic message.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

use crate::scene::SceneError;

/// Machine-readable error codes of the HTTP API.
pub mod code {
    /// The body is not JSON, or has an unknown or missing field or a value of the wrong type.
    pub const INVALID_JSON: &str = "invalid_json";
    /// A value is out of range or inconsistent with another; `field` names it.
    pub const INVALID_FIELD: &str = "invalid_field";
    /// A mesh, material or texture cannot be loaded (missing file, invalid OBJ).
    pub const INVALID_SCENE: &str = "invalid_scene";
    /// A mesh or texture path resolves outside the asset directory.
    pub const PATH_OUTSIDE_ASSETS: &str = "path_outside_assets";
    /// A configured limit was exceeded; `limit` names the setting.
    pub const LIMIT_EXCEEDED: &str = "limit_exceeded";
    /// A server-side recording, or one of its frames, cannot be read.
    pub const INVALID_RECORDING: &str = "invalid_recording";
    pub const NOT_FOUND: &str = "not_found";
    pub const METHOD_NOT_ALLOWED: &str = "method_not_allowed";
    pub const UNAUTHORIZED: &str = "unauthorized";
    /// The render queue is full; retry after `Retry-After` seconds.
    pub const QUEUE_FULL: &str = "queue_full";
    /// The server is shutting down and takes no new work.
    pub const SHUTTING_DOWN: &str = "shutting_down";
    /// The request is not a WebSocket upgrade where one is required.
    pub const UPGRADE_REQUIRED: &str = "upgrade_required";
    pub const INTERNAL: &str = "internal";
}

/// An HTTP error answer.
#[derive(Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub code: &'static str,
    pub message: String,
    pub field: Option<String>,
    pub limit: Option<&'static str>,
    /// Seconds, sent as `Retry-After`.
    pub retry_after: Option<u32>,
}

/// The JSON body of every error answer.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ErrorBody {
    pub error: ErrorDetail,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct ErrorDetail {
    /// One of `invalid_json`, `invalid_field`, `invalid_scene`, `path_outside_assets`,
    /// `limit_exceeded`, `invalid_recording`, `not_found`, `method_not_allowed`,
    /// `unauthorized`, `queue_full`, `shutting_down`, `upgrade_required`, `internal`.
    #[schema(example = "invalid_field")]
    pub code: String,
    /// What is wrong, for people.
    #[schema(example = "camera.fov_y_deg: must be in (1, 170), got 0")]
    pub message: String,
    /// Path of the offending field in the request body, e.g. `meshes[0].obj`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// The setting that was exceeded, e.g. `max_body_bytes`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limit: Option<String>,
}

impl ApiError {
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> ApiError {
        ApiError { status, code, message: message.into(), field: None, limit: None, retry_after: None }
    }

    /// 400 `invalid_field` about `field`; the message is prefixed with the field's path.
    pub fn invalid_field(field: impl Into<String>, message: impl std::fmt::Display) -> ApiError {
        let field = field.into();
        ApiError {
            field: Some(field.clone()),
            ..ApiError::new(StatusCode::BAD_REQUEST, code::INVALID_FIELD, format!("{field}: {message}"))
        }
    }

    /// `limit_exceeded`: 413 for limits in bytes, 400 otherwise.
    pub fn limit(limit: &'static str, field: Option<String>, message: impl Into<String>) -> ApiError {
        let status = if limit.ends_with("_bytes") { StatusCode::PAYLOAD_TOO_LARGE } else { StatusCode::BAD_REQUEST };
        ApiError { field, limit: Some(limit), ..ApiError::new(status, code::LIMIT_EXCEEDED, message) }
    }

    pub fn not_found(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::NOT_FOUND, code::NOT_FOUND, message)
    }

    pub fn shutting_down() -> ApiError {
        ApiError::new(StatusCode::SERVICE_UNAVAILABLE, code::SHUTTING_DOWN, "the server is shutting down")
    }

    /// 500 with a generic message; `detail` goes to the log only.
    pub fn internal(detail: impl std::fmt::Display) -> ApiError {
        tracing::error!("internal error: {detail}");
        ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, code::INTERNAL, "internal error (logged on the server)")
    }

    /// A scene error, as the client should see it: `asset_root` (the server's directory) is
    /// removed from file paths in the message.
    pub fn scene(error: &SceneError, asset_root: &std::path::Path) -> ApiError {
        let code = match error {
            SceneError::Json { .. } => code::INVALID_JSON,
            SceneError::Field { .. } => code::INVALID_FIELD,
            SceneError::Obj { .. } | SceneError::Read { .. } => code::INVALID_SCENE,
        };
        let mut message = error.to_string();
        let root = asset_root.display().to_string();
        for prefix in [format!("{root}{}", std::path::MAIN_SEPARATOR), root] {
            message = message.replace(&prefix, "");
        }
        ApiError {
            field: error.field_path().map(str::to_owned),
            ..ApiError::new(StatusCode::BAD_REQUEST, code, message)
        }
    }
}

impl std::fmt::Display for ApiError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {}: {}", self.status.as_u16(), self.code, self.message)
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = ErrorBody {
            error: ErrorDetail {
                code: self.code.to_owned(),
                message: self.message,
                field: self.field,
                limit: self.limit.map(str::to_owned),
            },
        };
        let mut response = (self.status, axum::Json(body)).into_response();
        if let Some(seconds) = self.retry_after {
            response.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from(seconds));
        }
        if self.status == StatusCode::UNAUTHORIZED {
            response.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        response
    }
}
