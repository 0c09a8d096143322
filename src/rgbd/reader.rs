//! What the reader of every recording layout (`tum`, `redwood`, `rosbag`) shares: the caller's
//! options, the association statistics, the errors, and the parts a reader assembles into a
//! `Recording`; the checks and text-line helpers they all use.

use std::collections::HashSet;
use std::io::ErrorKind;
use std::path::{Path, PathBuf};

use glam::DAffine3;

use super::Intrinsics;
use super::poses::nearest;

/// Largest timestamp difference (s) for pairing depth with colour and with ground truth, as in
/// TUM's `associate.py`.
pub const DEFAULT_TOLERANCE_S: f64 = 0.02;
/// What the caller (CLI flags) adds to a recording.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordingOptions {
    /// Intrinsics for a recording without an intrinsics file or camera info (when `None`:
    /// [`Intrinsics::TUM`] for a folder; for an MCAP file without camera info, an error).
    pub intrinsics: Option<Intrinsics>,
    /// Depth units per metre when `intrinsics.json` gives none (when `None`: [`super::tum::TUM_DEPTH_SCALE`]
    /// for TUM, 1000 for Open3D/Redwood and MCAP `16UC1`).
    pub depth_scale: Option<f32>,
    /// Largest timestamp difference (s) for pairing depth with colour and with ground truth.
    pub tolerance_s: f64,
    /// The topics of an MCAP recording (defaults when `None`).
    pub mcap: McapTopics,
}

impl Default for RecordingOptions {
    fn default() -> Self {
        Self { intrinsics: None, depth_scale: None, tolerance_s: DEFAULT_TOLERANCE_S, mcap: McapTopics::default() }
    }
}

/// Topics to read from an MCAP file; `None` picks the default (module docs). Also the CLI
/// flags of `relume replay`.
#[derive(Clone, Debug, Default, PartialEq, Eq, clap::Args)]
pub struct McapTopics {
    /// MCAP recording: the colour sensor_msgs/msg/Image topic (default: the one Image topic
    /// that is not the depth topic).
    #[arg(long = "colour-topic")]
    pub colour: Option<String>,
    /// MCAP recording: the depth Image topic, 16UC1 (mm) or 32FC1 (m) (default: the one Image
    /// topic whose name contains `depth`).
    #[arg(long = "depth-topic")]
    pub depth: Option<String>,
    /// MCAP recording: the sensor_msgs/msg/CameraInfo topic (default: `camera_info` beside the
    /// depth topic, else the only one).
    #[arg(long = "camera-info-topic")]
    pub camera_info: Option<String>,
    /// MCAP recording: a geometry_msgs/msg/PoseStamped topic for the camera poses (default: the
    /// only one, else /tf and /tf_static).
    #[arg(long = "pose-topic")]
    pub pose: Option<String>,
}

/// How the frames of the text files were paired (see `Recording::open`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AssociationStats {
    /// Entries of `depth.txt`.
    pub depth_frames: usize,
    /// Entries of `rgb.txt`.
    pub colour_frames: usize,
    /// Depth frames skipped: no colour frame within the tolerance.
    pub without_colour: usize,
    /// Depth frames skipped: no ground-truth sample within the tolerance.
    pub without_pose: usize,
    /// Colour frames that are the partner of more than one kept depth frame.
    pub shared_colour: usize,
}

/// Why a recording or one of its frames cannot be read. File names are relative to the
/// recording directory.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    #[error("{}: no such file", file.display())]
    Missing { file: PathBuf },
    #[error("{}: {source}", file.display())]
    Read { file: PathBuf, source: std::io::Error },
    /// A line of `rgb.txt`, `depth.txt` or `groundtruth.txt` is malformed.
    #[error("{} line {line}: {message}", file.display())]
    Line {
        file: PathBuf,
        /// 1-based.
        line: usize,
        message: String,
    },
    /// `intrinsics.json` is not valid JSON, misses a field or has an unknown one.
    #[error("{}: {source}", file.display())]
    Json { file: PathBuf, source: serde_json::Error },
    /// An intrinsics value (from `intrinsics.json` or the options) is out of range.
    #[error("{origin}: {field} {message}")]
    Value {
        /// `intrinsics.json` or `recording options`.
        origin: &'static str,
        field: &'static str,
        message: String,
    },
    /// A PNG cannot be decoded or has the wrong pixel format.
    #[error("{}: {message}", file.display())]
    Image { file: PathBuf, message: String },
    #[error("{}: image is {width}x{height}, intrinsics say {expected_width}x{expected_height}", file.display())]
    ImageSize { file: PathBuf, width: u32, height: u32, expected_width: u32, expected_height: u32 },
    #[error(
        "no usable frame: of {} depth frames, {} have no colour frame and {} no pose within the tolerance",
        stats.depth_frames,
        stats.without_colour,
        stats.without_pose
    )]
    NoFrames { stats: AssociationStats },
    #[error("frame {index} out of range: the recording has {len} frames")]
    FrameIndex { index: usize, len: usize },
    /// The path is neither a TUM nor an Open3D/Redwood directory nor an MCAP file.
    #[error("{}: not a recording: {message}", path.display())]
    NotARecording { path: PathBuf, message: String },
    /// A record of an MCAP file is malformed or misses a field (`record` names the record:
    /// topic, message type and index on its channel).
    #[error("{}: {record}: {message}", file.display())]
    Record { file: PathBuf, record: String, message: String },
}

/// The on-disk layout a recording was read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// TUM RGB-D: `rgb.txt`, `depth.txt`, `groundtruth.txt`.
    Tum,
    /// Open3D / Redwood: `color/`, `depth/`, `trajectory.log`, camera JSON.
    Redwood,
    /// An MCAP file of ROS 2 messages.
    Mcap,
}

/// The two images of one frame, relative to the recording directory.
#[derive(Clone, Debug)]
pub(super) struct FramePair {
    pub depth: PathBuf,
    pub colour: PathBuf,
}

/// A recording as a layout's reader assembles it.
pub(super) struct Parts<F> {
    pub dir: PathBuf,
    pub intrinsics: Intrinsics,
    pub depth_scale: f32,
    pub has_groundtruth: bool,
    pub timestamps: Vec<f64>,
    pub poses: Vec<DAffine3>,
    pub frames: F,
    pub stats: AssociationStats,
    pub layout: Layout,
}

/// The frames [`associate`] kept, in the depth frames' order, and how it paired them.
pub(super) struct Associated<F> {
    pub timestamps: Vec<f64>,
    pub poses: Vec<DAffine3>,
    pub frames: Vec<F>,
    pub stats: AssociationStats,
}

/// Pairs each depth frame `(t, depth)` with the colour frame of nearest timestamp in the sorted
/// `colour_times` and with the pose `pose_at(t)`, leaving out (and counting) one without a colour
/// frame within `tolerance` s or without a pose; a kept frame is `frame(depth, colour index)`.
/// Fails when no frame is left; warns of the frames left out of the recording at `path`.
pub(super) fn associate<D, F>(
    path: &Path,
    depth: impl ExactSizeIterator<Item = (f64, D)>,
    colour_times: &[f64],
    tolerance: f64,
    mut pose_at: impl FnMut(f64) -> Option<DAffine3>,
    mut frame: impl FnMut(D, usize) -> F,
) -> Result<Associated<F>, RecordingError> {
    let mut stats =
        AssociationStats { depth_frames: depth.len(), colour_frames: colour_times.len(), ..Default::default() };
    let (mut timestamps, mut poses, mut frames) = (Vec::new(), Vec::new(), Vec::new());
    let mut used_colour = HashSet::new();
    for (t, depth) in depth {
        let Some(c) = nearest(colour_times, t).filter(|&c| (colour_times[c] - t).abs() <= tolerance) else {
            tracing::debug!("depth frame {t:.6}: no colour frame within {tolerance} s");
            stats.without_colour += 1;
            continue;
        };
        let Some(pose) = pose_at(t) else {
            stats.without_pose += 1;
            continue;
        };
        if !used_colour.insert(c) {
            stats.shared_colour += 1;
        }
        timestamps.push(t);
        poses.push(pose);
        frames.push(frame(depth, c));
    }
    if timestamps.is_empty() {
        return Err(RecordingError::NoFrames { stats });
    }
    warn_skipped(path, &stats, tolerance);
    Ok(Associated { timestamps, poses, frames, stats })
}

/// Logs the depth frames that association left out, if any.
fn warn_skipped(path: &Path, stats: &AssociationStats, tolerance: f64) {
    if stats.without_colour + stats.without_pose > 0 {
        tracing::warn!(
            "{}: skipped {} of {} depth frames ({} without a colour frame, {} without a pose within {tolerance} s)",
            path.display(),
            stats.without_colour + stats.without_pose,
            stats.depth_frames,
            stats.without_colour,
            stats.without_pose
        );
    }
}

/// `options.tolerance_s`, checked.
pub(super) fn check_tolerance(options: &RecordingOptions) -> Result<f64, RecordingError> {
    let tolerance = options.tolerance_s;
    if tolerance.is_finite() && tolerance >= 0.0 {
        Ok(tolerance)
    } else {
        Err(value_error("recording options", "tolerance_s", format!("must be >= 0, got {tolerance}")))
    }
}

/// Sizes >= 1, focal lengths positive and finite, principal point finite. The error names the
/// field.
pub fn check_intrinsics(intrinsics: &Intrinsics) -> Result<(), (&'static str, String)> {
    let Intrinsics { width, height, fx, fy, cx, cy } = *intrinsics;
    for (field, value) in [("width", width), ("height", height)] {
        if value == 0 {
            return Err((field, "must be >= 1, got 0".to_owned()));
        }
    }
    for (field, value) in [("fx", fx), ("fy", fy)] {
        if !(value.is_finite() && value > 0.0) {
            return Err((field, format!("must be positive and finite, got {value}")));
        }
    }
    for (field, value) in [("cx", cx), ("cy", cy)] {
        if !value.is_finite() {
            return Err((field, format!("must be finite, got {value}")));
        }
    }
    Ok(())
}

pub(super) fn check_depth_scale(scale: f32) -> Result<(), String> {
    if scale.is_finite() && scale > 0.0 { Ok(()) } else { Err(format!("must be positive and finite, got {scale}")) }
}

pub(super) fn value_error(origin: &'static str, field: &'static str, message: String) -> RecordingError {
    RecordingError::Value { origin, field, message }
}

pub(super) fn read_text(dir: &Path, name: &str) -> Result<String, RecordingError> {
    std::fs::read_to_string(dir.join(name)).map_err(|source| io_error(Path::new(name), source))
}

pub(super) fn io_error(file: &Path, source: std::io::Error) -> RecordingError {
    let file = file.to_path_buf();
    if source.kind() == ErrorKind::NotFound {
        RecordingError::Missing { file }
    } else {
        RecordingError::Read { file, source }
    }
}

/// The data lines of a TUM text file with their 1-based numbers: blank lines and `#` comment
/// lines left out, whitespace-separated fields.
pub(super) fn data_lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, line)| {
        let line = line.trim();
        (!line.is_empty() && !line.starts_with('#')).then(|| (i + 1, line.split_whitespace().collect()))
    })
}

pub(super) fn line_error(file: &str, line: usize, message: impl Into<String>) -> RecordingError {
    RecordingError::Line { file: PathBuf::from(file), line, message: message.into() }
}

/// A finite number, or an error naming what it is.
pub(super) fn parse_number(file: &str, line: usize, what: &str, field: &str) -> Result<f64, RecordingError> {
    let value: f64 = field.parse().map_err(|_| line_error(file, line, format!("{what} `{field}` is not a number")))?;
    if value.is_finite() { Ok(value) } else { Err(line_error(file, line, format!("{what} is {value}"))) }
}
