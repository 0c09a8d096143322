//! The HTTP API's error: a status and a JSON body `{"error": {"code", "message", "field",
//! "limit"}}`. Internal failures are logged in full and answered with a generic message.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

use crate::gpu::GpuError;
use crate::scene::SceneError;

use super::config::{LimitExceeded, limit};
use super::gpu_worker::WorkerError;

/// Machine-readable error codes of the HTTP API: the `code` of every error body.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Code {
    /// The request is not valid HTTP/1.1: its request line, a header or its framing (e.g. a
    /// negative `Content-Length`) cannot be parsed.
    BadRequest,
    /// The body is not JSON, or has an unknown or missing field or a value of the wrong type.
    InvalidJson,
    /// A value is out of range or inconsistent with another; `field` names it.
    InvalidField,
    /// A mesh, material or texture cannot be loaded (missing file, invalid OBJ).
    InvalidScene,
    /// A mesh or texture path resolves outside the asset directory.
    PathOutsideAssets,
    /// A configured limit was exceeded; `limit` names the setting.
    LimitExceeded,
    /// A server-side recording, or one of its frames, cannot be read.
    InvalidRecording,
    NotFound,
    MethodNotAllowed,
    Unauthorized,
    /// The render queue is full; retry after `Retry-After` seconds.
    QueueFull,
    /// The request body did not arrive within `body_timeout_seconds`.
    RequestTimeout,
    /// The GPU device was lost during the render; a new one is up: retry.
    DeviceLost,
    /// The server is shutting down and takes no new work.
    ShuttingDown,
    /// The request is not a WebSocket upgrade where one is required.
    UpgradeRequired,
    Internal,
}

impl Code {
    /// The code as it appears in error bodies, e.g. `invalid_json`.
    pub fn as_str(self) -> &'static str {
        match self {
            Code::BadRequest => "bad_request",
            Code::InvalidJson => "invalid_json",
            Code::InvalidField => "invalid_field",
            Code::InvalidScene => "invalid_scene",
            Code::PathOutsideAssets => "path_outside_assets",
            Code::LimitExceeded => "limit_exceeded",
            Code::InvalidRecording => "invalid_recording",
            Code::NotFound => "not_found",
            Code::MethodNotAllowed => "method_not_allowed",
            Code::Unauthorized => "unauthorized",
            Code::QueueFull => "queue_full",
            Code::RequestTimeout => "request_timeout",
            Code::DeviceLost => "device_lost",
            Code::ShuttingDown => "shutting_down",
            Code::UpgradeRequired => "upgrade_required",
            Code::Internal => "internal",
        }
    }
}

/// An HTTP error answer.
#[derive(Debug)]
pub struct ApiError {
    pub status: StatusCode,
    pub code: Code,
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

/// The OpenAPI answer of every route behind the bearer token (`--token`) when it is missing or
/// wrong: one definition, named in each route's `responses(...)`. A documentation type only.
#[derive(utoipa::IntoResponses)]
#[response(status = 401, description = "Missing or wrong bearer token")]
pub struct Unauthorized(pub ErrorBody);

/// The OpenAPI answer of every route under `/v1/scenes/{id}` when there is no such scene. A
/// documentation type only.
#[derive(utoipa::IntoResponses)]
#[response(status = 404, description = "No such scene")]
pub struct UnknownScene(pub ErrorBody);

#[derive(Serialize, utoipa::ToSchema)]
pub struct ErrorDetail {
    pub code: Code,
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
    pub fn new(status: StatusCode, code: Code, message: impl Into<String>) -> ApiError {
        ApiError { status, code, message: message.into(), field: None, limit: None, retry_after: None }
    }

    /// 400 `invalid_field` about `field`; the message is prefixed with the field's path.
    pub fn invalid_field(field: impl Into<String>, message: impl std::fmt::Display) -> ApiError {
        let field = field.into();
        ApiError {
            field: Some(field.clone()),
            ..ApiError::new(StatusCode::BAD_REQUEST, Code::InvalidField, format!("{field}: {message}"))
        }
    }

    /// `limit_exceeded`: 413 for limits in bytes, 400 otherwise.
    pub fn limit(limit: &'static str, field: Option<String>, message: impl Into<String>) -> ApiError {
        let status = if limit.ends_with("_bytes") { StatusCode::PAYLOAD_TOO_LARGE } else { StatusCode::BAD_REQUEST };
        ApiError { field, limit: Some(limit), ..ApiError::new(status, Code::LimitExceeded, message) }
    }

    pub fn not_found(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::NOT_FOUND, Code::NotFound, message)
    }

    pub fn shutting_down() -> ApiError {
        ApiError::new(StatusCode::SERVICE_UNAVAILABLE, Code::ShuttingDown, "the server is shutting down")
    }

    /// 500 with a generic message; `detail` goes to the log only.
    pub fn internal(detail: impl std::fmt::Display) -> ApiError {
        tracing::error!("internal error: {detail}");
        ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, Code::Internal, "internal error (logged on the server)")
    }

    /// The same error about `rename(field)`, also where its message starts with the field.
    pub fn with_field(mut self, rename: impl Fn(&str) -> String) -> ApiError {
        if let Some(field) = self.field.take() {
            let renamed = rename(&field);
            if let Some(rest) = self.message.strip_prefix(field.as_str()) {
                self.message = format!("{renamed}{rest}");
            }
            self.field = Some(renamed);
        }
        self
    }

    /// A scene error, as the client should see it: `asset_root` (the server's directory) is
    /// removed from file paths in the message.
    pub fn scene(error: &SceneError, asset_root: &std::path::Path) -> ApiError {
        if let SceneError::TooManyTriangles { field, .. } = error {
            return ApiError::limit(limit::MAX_TRIANGLES, Some(field.clone()), error.to_string());
        }
        let code = match error {
            SceneError::Json { .. } => Code::InvalidJson,
            SceneError::Field { .. } => Code::InvalidField,
            SceneError::Obj { .. } | SceneError::Read { .. } => Code::InvalidScene,
            SceneError::TooManyTriangles { .. } => Code::LimitExceeded,
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

impl From<LimitExceeded> for ApiError {
    /// 413 for limits in bytes, 503 for the server's capacity (`max_streams`,
    /// `max_connections`, `max_tickets`), 400 otherwise.
    fn from(e: LimitExceeded) -> ApiError {
        let status = if [limit::MAX_STREAMS, limit::MAX_CONNECTIONS, limit::MAX_TICKETS].contains(&e.limit) {
            StatusCode::SERVICE_UNAVAILABLE
        } else if e.limit.ends_with("_bytes") {
            StatusCode::PAYLOAD_TOO_LARGE
        } else {
            StatusCode::BAD_REQUEST
        };
        ApiError { field: e.field, limit: Some(e.limit), ..ApiError::new(status, Code::LimitExceeded, e.message) }
    }
}

impl From<WorkerError> for ApiError {
    /// The HTTP answer for a failed GPU job; a full queue carries `Retry-After`, the measured
    /// queue wait (at least 1 s).
    fn from(error: WorkerError) -> ApiError {
        match error {
            WorkerError::QueueFull { waiting, limit, retry_after } => ApiError {
                limit: Some(limit),
                retry_after: Some(retry_after.map_or(1, |wait| wait.as_secs_f64().ceil().clamp(1.0, 600.0) as u32)),
                ..ApiError::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    Code::QueueFull,
                    format!("the render queue is full ({waiting} renders waiting, the limit {limit}); retry later"),
                )
            },
            WorkerError::SceneNotFound(id) => ApiError::not_found(format!("no scene with id `{id}`")),
            WorkerError::Stopped => ApiError::shutting_down(),
            error @ WorkerError::DeviceLost => ApiError {
                retry_after: Some(1),
                ..ApiError::new(StatusCode::SERVICE_UNAVAILABLE, Code::DeviceLost, format!("{error}; retry"))
            },
            WorkerError::Gpu(GpuError::TooLarge { what, needed, limit: device }) => ApiError::new(
                StatusCode::BAD_REQUEST,
                Code::LimitExceeded,
                format!("{what} needs {needed} bytes of GPU memory, over the device's limit of {device}"),
            ),
            error @ (WorkerError::Gpu(_) | WorkerError::Panicked(_)) => ApiError::internal(error),
        }
    }
}

impl std::fmt::Display for ApiError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {}: {}", self.status.as_u16(), self.code.as_str(), self.message)
    }
}

impl ApiError {
    /// The JSON body.
    fn body(&self) -> ErrorBody {
        ErrorBody {
            error: ErrorDetail {
                code: self.code,
                message: self.message.clone(),
                field: self.field.clone(),
                limit: self.limit.map(str::to_owned),
            },
        }
    }

    /// The headers that go with the body besides `Content-Type`.
    fn extra_headers(&self) -> Vec<(header::HeaderName, HeaderValue)> {
        let mut headers = Vec::new();
        if let Some(seconds) = self.retry_after {
            headers.push((header::RETRY_AFTER, HeaderValue::from(seconds)));
        }
        if self.status == StatusCode::UNAUTHORIZED {
            headers.push((header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer")));
        }
        headers
    }

    /// The whole answer as HTTP/1.1 bytes, ending with `Connection: close`: for the
    /// connection loop, which answers some requests before (or instead of) hyper.
    pub fn to_http1_bytes(&self) -> Vec<u8> {
        let body = serde_json::to_vec(&self.body()).unwrap_or_default();
        let mut head = format!(
            "HTTP/1.1 {} {}\r\ncontent-type: application/json\r\ncontent-length: {}\r\n",
            self.status.as_u16(),
            self.status.canonical_reason().unwrap_or(""),
            body.len()
        );
        for (name, value) in self.extra_headers() {
            head.push_str(&format!("{name}: {}\r\n", value.to_str().unwrap_or("")));
        }
        head.push_str("connection: close\r\n\r\n");
        [head.into_bytes(), body].concat()
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut response = (self.status, axum::Json(self.body())).into_response();
        for (name, value) in self.extra_headers() {
            response.headers_mut().insert(name, value);
        }
        response
    }
}
