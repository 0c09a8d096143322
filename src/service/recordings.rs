//! Recordings the server holds, for clients (the viewer) to play on a stream:
//! `GET /v1/recordings` lists the TUM RGB-D recordings under the asset directory's
//! `recordings/`, and `GET /v1/recordings/{name}/frames/{index}` answers one frame as the
//! stream's own message, an encoded `Envelope { RgbdFrame }` that a client forwards as is.
//! Names are plain directory names (no separators, no leading dot) and must resolve inside
//! `recordings/`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use axum::Json;
use axum::extract::rejection::PathRejection;
use axum::extract::{Path as UrlPath, State};
use axum::http::{HeaderValue, StatusCode, Uri, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

use crate::rgbd::recording::{Recording, RecordingOptions};

use super::AppState;
use super::error::{ApiError, Code};
use super::wire;

/// The folder of the asset directory that holds recordings.
pub const RECORDINGS_DIR: &str = "recordings";

/// Largest `downscale` factor of a frame request.
pub const MAX_DOWNSCALE: u32 = 16;

/// The media type of an encoded protobuf `Envelope`.
pub const PROTOBUF_CONTENT_TYPE: &str = "application/x-protobuf";

/// A recording's summary.
#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct RecordingInfo {
    /// Directory name under the asset directory's `recordings/`.
    #[schema(example = "tum_fr1_xyz")]
    pub name: String,
    /// Frames with colour, depth and pose; indices `0..frames`.
    pub frames: usize,
    /// Full-size frame width and height, pixels.
    pub width: u32,
    pub height: u32,
    /// From the first frame to the last, seconds.
    pub duration_s: f64,
}

#[derive(Clone, Debug, Serialize, utoipa::ToSchema)]
pub struct RecordingList {
    /// By name.
    pub recordings: Vec<RecordingInfo>,
}

/// The recordings directory and the recordings opened so far (their frame lists and poses).
pub struct Recordings {
    /// `<assets>/recordings`, which may not exist.
    dir: PathBuf,
    opened: Mutex<HashMap<String, Arc<Recording>>>,
}

impl Recordings {
    pub fn new(assets: &Path) -> Recordings {
        Recordings { dir: assets.join(RECORDINGS_DIR), opened: Mutex::new(HashMap::new()) }
    }

    /// Every directory of `recordings/` that opens as a recording; the others are logged and
    /// left out. Blocking (reads the text files of recordings not opened yet).
    fn list(&self) -> Vec<RecordingInfo> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else { return Vec::new() };
        let mut names: Vec<String> = entries
            .filter_map(Result::ok)
            .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
            .filter_map(|e| e.file_name().into_string().ok())
            .filter(|name| check_name(name).is_ok())
            .collect();
        names.sort();
        names
            .into_iter()
            .filter_map(|name| match self.open(&name) {
                Ok(recording) => Some(info(&name, &recording)),
                Err(error) => {
                    tracing::warn!(recording = name, "not a usable recording: {}", error.message);
                    None
                }
            })
            .collect()
    }

    /// The recording `name`, opened once. Blocking.
    fn open(&self, name: &str) -> Result<Arc<Recording>, ApiError> {
        check_name(name)?;
        let lock = || self.opened.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some(recording) = lock().get(name) {
            return Ok(recording.clone());
        }
        let unknown = || ApiError::not_found(format!("no recording named `{name}`"));
        let root = std::fs::canonicalize(&self.dir).map_err(|_| unknown())?;
        let dir = std::fs::canonicalize(root.join(name)).map_err(|_| unknown())?;
        if !dir.starts_with(&root) || !dir.is_dir() {
            return Err(unknown());
        }
        let recording = Recording::open(&dir, &RecordingOptions::default()).map_err(|error| {
            ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                Code::InvalidRecording,
                format!("recording `{name}`: {error}"),
            )
        })?;
        let recording = Arc::new(recording);
        lock().insert(name.to_owned(), recording.clone());
        Ok(recording)
    }
}

fn info(name: &str, recording: &Recording) -> RecordingInfo {
    let timestamps = recording.timestamps();
    let k = recording.intrinsics();
    RecordingInfo {
        name: name.to_owned(),
        frames: recording.len(),
        width: k.width,
        height: k.height,
        duration_s: timestamps.last().zip(timestamps.first()).map_or(0.0, |(last, first)| last - first),
    }
}

/// A recording name: 1 to 128 of `A-Z a-z 0-9 _ - .`, not starting with a dot.
fn check_name(name: &str) -> Result<(), ApiError> {
    let ok = !name.is_empty()
        && name.len() <= 128
        && !name.starts_with('.')
        && name.bytes().all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.'));
    if ok {
        Ok(())
    } else {
        Err(ApiError::invalid_field(
            "name",
            "a recording name is 1 to 128 of A-Z a-z 0-9 _ - . and does not start with a dot",
        ))
    }
}

/// `downscale` from the query (default 1); any other parameter is refused.
fn downscale(uri: &Uri) -> Result<u32, ApiError> {
    let mut factor = 1;
    for pair in uri.query().unwrap_or("").split('&').filter(|p| !p.is_empty()) {
        let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
        if key != "downscale" {
            return Err(ApiError::invalid_field(key, "unknown query parameter (the only one is `downscale`)"));
        }
        factor = value.parse::<u32>().ok().filter(|f| (1..=MAX_DOWNSCALE).contains(f)).ok_or_else(|| {
            ApiError::invalid_field("downscale", format!("must be an integer in 1..={MAX_DOWNSCALE}, got `{value}`"))
        })?;
    }
    Ok(factor)
}

/// The recordings the server holds.
///
/// The TUM RGB-D recordings (docs/rgbd.md) under the asset directory's `recordings/`;
/// directories that do not open as one are left out (and logged).
#[utoipa::path(
    get,
    path = "/v1/recordings",
    tag = "recordings",
    responses(
        (status = 200, description = "The recordings, by name", body = RecordingList),
        super::error::Unauthorized,
    ),
    security((), ("bearer" = []))
)]
pub async fn list_recordings(State(state): State<Arc<AppState>>) -> Result<Json<RecordingList>, ApiError> {
    let lister = state.clone();
    let recordings = tokio::task::spawn_blocking(move || lister.recordings.list()).await.map_err(ApiError::internal)?;
    Ok(Json(RecordingList { recordings }))
}

/// One frame of a recording, as a stream message.
///
/// The answer is a protobuf `relume.v1.Envelope` (proto/relume.proto) whose body is the frame
/// as an `RgbdFrame` (`frame_id` = `index`, raw RGB8 colour, f32 depth in metres, pose as a
/// column-major matrix with its translation also in f64, `translation_f64`): send it unchanged
/// on a stream. `downscale` shrinks it first (colour
/// averaged, depth the median of valid measurements, intrinsics scaled).
#[utoipa::path(
    get,
    path = "/v1/recordings/{name}/frames/{index}",
    tag = "recordings",
    params(
        ("name" = String, Path, description = "The recording's name"),
        ("index" = u64, Path, description = "The frame, from 0"),
        ("downscale" = Option<u32>, Query, description = "Integer factor in 1..=16 dividing width and height; default 1"),
    ),
    responses(
        (status = 200, description = "The encoded `Envelope { RgbdFrame }`",
            content(("application/x-protobuf")),
            headers(
                ("X-Relume-Frame-Count" = u64, description = "Frames in the recording"),
                ("X-Relume-Width" = u32, description = "Frame width after downscaling, pixels"),
                ("X-Relume-Height" = u32, description = "Frame height after downscaling, pixels"),
            )),
        (status = 400, description = "Invalid name, index or query (`field` names it)", body = super::error::ErrorBody),
        super::error::Unauthorized,
        (status = 404, description = "No such recording, or no such frame", body = super::error::ErrorBody),
        (status = 422, description = "The recording or this frame's images cannot be read", body = super::error::ErrorBody),
    ),
    security((), ("bearer" = []))
)]
pub async fn recording_frame(
    State(state): State<Arc<AppState>>,
    path: Result<UrlPath<(String, String)>, PathRejection>,
    uri: Uri,
) -> Result<Response, ApiError> {
    let UrlPath((name, index)) = path.map_err(|_| ApiError::not_found("no such recording frame"))?;
    let index: usize = index
        .parse()
        .map_err(|_| ApiError::invalid_field("index", format!("must be a frame number, got `{index}`")))?;
    let factor = downscale(&uri)?;
    let loader = state.clone();
    let (bytes, count, width, height) = tokio::task::spawn_blocking(move || {
        let recording = loader.recordings.open(&name)?;
        let count = recording.len();
        if index >= count {
            return Err(ApiError::not_found(format!(
                "recording `{name}` has {count} frames (0..{count}); no frame {index}"
            )));
        }
        let frame = recording.frame(index).map_err(|error| {
            ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                Code::InvalidRecording,
                format!("recording `{name}`: {error}"),
            )
        })?;
        let frame = frame.downsampled(factor);
        let k = frame.intrinsics;
        Ok((wire::encode_rgbd_frame(index as u64, &frame), count, k.width, k.height))
    })
    .await
    .map_err(ApiError::internal)??;
    let headers = [
        (header::CONTENT_TYPE, HeaderValue::from_static(PROTOBUF_CONTENT_TYPE)),
        (header::HeaderName::from_static("x-relume-frame-count"), HeaderValue::from(count)),
        (header::HeaderName::from_static("x-relume-width"), HeaderValue::from(width)),
        (header::HeaderName::from_static("x-relume-height"), HeaderValue::from(height)),
    ];
    Ok((StatusCode::OK, headers, bytes).into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_plain_directory_names() {
        for good in ["tum_fr1_xyz", "a", "room-2.v1"] {
            assert!(check_name(good).is_ok(), "{good}");
        }
        for bad in ["", ".", "..", ".hidden", "a/b", "..%2F", "a\\b", "é", &"x".repeat(129)] {
            assert!(check_name(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn downscale_is_the_only_query_parameter() {
        let uri = |q: &str| q.parse::<Uri>().expect("uri");
        assert_eq!(downscale(&uri("/f")).ok(), Some(1));
        assert_eq!(downscale(&uri("/f?downscale=4")).ok(), Some(4));
        for bad in ["/f?downscale=0", "/f?downscale=17", "/f?downscale=x", "/f?downscale", "/f?scale=2"] {
            assert!(downscale(&uri(bad)).is_err(), "{bad}");
        }
    }
}
