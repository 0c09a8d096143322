//! RGB-D recordings on disk (docs/rgbd.md "Recording layouts"), in three layouts
//! that [`Recording::open`] tells apart by their files:
//!
//! - a TUM RGB-D directory (`rgb.txt`, `depth.txt`; below);
//! - an Open3D / Redwood directory (`color/` or `image/` and `depth/`; see [`super::redwood`]);
//! - an MCAP file (ROS 2 / Foxglove bag, `.mcap`; see [`super::rosbag`]).
//!
//! A TUM recording is a directory holding
//!
//! - `rgb.txt` and `depth.txt`: `timestamp filename` lines (seconds; file names relative to the
//!   directory), `#` starts a comment line;
//! - optionally `groundtruth.txt`: `timestamp tx ty tz qx qy qz qw` lines, the camera-to-world
//!   pose of the colour camera's optical frame (x right, y down, z forward), quaternion w last,
//!   sampled at about 100 Hz and not synchronised with the images;
//! - optionally `intrinsics.json`: `{"width", "height", "fx", "fy", "cx", "cy", "depth_scale"}`
//!   (`depth_scale` optional), the pinhole intrinsics of the registered depth image.
//!
//! [`Recording::open`] reads the text files of a TUM directory, pairs each depth frame with the colour frame of
//! nearest timestamp and interpolates its pose; [`Recording::frame`] loads the PNGs of one frame
//! (colour: 8-bit RGB or RGBA; depth: 16-bit grayscale, `depth_scale` units per metre, 0 = none).
//!
//! Errors name the file relative to the recording directory and, for text files, the 1-based
//! line (`groundtruth.txt line 12: expected 8 numbers, got 7`); callers add the directory.

use std::collections::HashSet;
use std::fs::File;
use std::io::{BufReader, ErrorKind};
use std::path::{Path, PathBuf};

use glam::{DAffine3, DQuat, DVec3};
use image::{ColorType, DynamicImage, ImageDecoder, ImageFormat, ImageReader};
use serde::Deserialize;

use super::{Intrinsics, RgbdFrame};

/// TUM's depth scale: 16-bit depth units per metre.
pub const TUM_DEPTH_SCALE: f32 = 5000.0;
/// Largest timestamp difference (s) for pairing depth with colour and with ground truth, as in
/// TUM's `associate.py`.
pub const DEFAULT_TOLERANCE_S: f64 = 0.02;
/// Largest `|‖q‖ - 1|` accepted for a ground-truth quaternion (TUM writes 4 decimals).
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// The intrinsics file beside the text files.
pub const INTRINSICS_FILE: &str = "intrinsics.json";
const RGB_FILE: &str = "rgb.txt";
const DEPTH_FILE: &str = "depth.txt";
const GROUNDTRUTH_FILE: &str = "groundtruth.txt";

/// What the caller (CLI flags) adds to a recording.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordingOptions {
    /// Intrinsics for a recording without an intrinsics file or camera info ([`Intrinsics::TUM`]
    /// when `None`).
    pub intrinsics: Option<Intrinsics>,
    /// Depth units per metre when `intrinsics.json` gives none (when `None`: [`TUM_DEPTH_SCALE`]
    /// for TUM, 1000 for Open3D/Redwood and MCAP `16UC1`).
    pub depth_scale: Option<f32>,
    /// Largest timestamp difference (s) for pairing depth with colour and with ground truth.
    pub tolerance_s: f64,
    /// The topics of an MCAP recording (defaults when `None`).
    pub mcap: super::rosbag::McapTopics,
}

impl Default for RecordingOptions {
    fn default() -> Self {
        Self {
            intrinsics: None,
            depth_scale: None,
            tolerance_s: DEFAULT_TOLERANCE_S,
            mcap: super::rosbag::McapTopics::default(),
        }
    }
}

/// How the frames of the text files were paired (see [`Recording::open`]).
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

/// A recording's frame list, poses and intrinsics; frames' images are read on demand.
#[derive(Clone, Debug)]
pub struct Recording {
    dir: PathBuf,
    intrinsics: Intrinsics,
    depth_scale: f32,
    has_groundtruth: bool,
    /// Depth timestamps (s) of the kept frames, increasing.
    timestamps: Vec<f64>,
    /// Camera-to-world (optical axes) at each timestamp, in f64 as recorded (a recording far
    /// from the origin keeps its millimetres; [`crate::scene::local_pose`] rounds to f32).
    poses: Vec<DAffine3>,
    frames: Frames,
    stats: AssociationStats,
    layout: Layout,
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

/// Where each frame's images are.
#[derive(Clone, Debug)]
pub(super) enum Frames {
    /// Image files relative to the recording directory, one pair per frame.
    Files(Vec<FramePair>),
    /// Images decoded from an MCAP file, one per frame.
    Mcap(Vec<super::rosbag::FrameImages>),
}

/// The two images of one frame, relative to the recording directory.
#[derive(Clone, Debug)]
pub(super) struct FramePair {
    pub depth: PathBuf,
    pub colour: PathBuf,
}

/// A recording as a layout's reader assembles it.
pub(super) struct Parts {
    pub dir: PathBuf,
    pub intrinsics: Intrinsics,
    pub depth_scale: f32,
    pub has_groundtruth: bool,
    pub timestamps: Vec<f64>,
    pub poses: Vec<DAffine3>,
    pub frames: Frames,
    pub stats: AssociationStats,
    pub layout: Layout,
}

impl Recording {
    /// Reads the recording at `path`, whatever its layout: an MCAP file (`.mcap`,
    /// [`super::rosbag::open`]), a TUM directory (it holds `rgb.txt` or `depth.txt`:
    /// [`Recording::open_tum`]) or an Open3D/Redwood directory (it holds `depth/` and
    /// `color/` or `image/`: [`super::redwood::open`]).
    pub fn open(path: &Path, options: &RecordingOptions) -> Result<Recording, RecordingError> {
        let not_a_recording = |message: String| RecordingError::NotARecording { path: path.to_path_buf(), message };
        if path.is_file() {
            return if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("mcap")) {
                super::rosbag::open(path, options)
            } else {
                Err(not_a_recording("a file, and not an MCAP file (`.mcap`)".to_owned()))
            };
        }
        if !path.is_dir() {
            return Err(not_a_recording("no such file or directory".to_owned()));
        }
        if path.join(RGB_FILE).exists() || path.join(DEPTH_FILE).exists() {
            return Self::open_tum(path, options);
        }
        if super::redwood::detect(path) {
            return super::redwood::open(path, options);
        }
        Err(not_a_recording(format!(
            "a directory with neither {RGB_FILE}/{DEPTH_FILE} (TUM) nor depth/ beside color/ or image/ (Open3D/Redwood)"
        )))
    }

    /// Reads the TUM recording in `dir`.
    ///
    /// - Intrinsics: `intrinsics.json` if present, else `options.intrinsics`, else
    ///   [`Intrinsics::TUM`]; the depth scale likewise from the file's `depth_scale`,
    ///   `options.depth_scale`, [`TUM_DEPTH_SCALE`].
    /// - Each depth frame is paired with the colour frame of nearest timestamp; one without a
    ///   colour frame within `options.tolerance_s` is skipped. A colour frame may serve two
    ///   depth frames ([`AssociationStats::shared_colour`]).
    /// - The pose at the depth timestamp is interpolated between the two bracketing ground-truth
    ///   samples (translation lerp, rotation slerp). A frame whose nearest sample is further than
    ///   the tolerance (outside the trajectory, or in a tracking gap) is skipped; just outside the
    ///   trajectory, the end sample is used. Without `groundtruth.txt` every pose is the identity.
    ///
    /// Timestamps must increase strictly within each file. Fails when no frame is left.
    pub fn open_tum(dir: &Path, options: &RecordingOptions) -> Result<Recording, RecordingError> {
        let (intrinsics, depth_scale) = resolve_intrinsics(dir, options)?;
        let tolerance = check_tolerance(options)?;
        let colour = parse_frame_list(RGB_FILE, &read_text(dir, RGB_FILE)?)?;
        let depth = parse_frame_list(DEPTH_FILE, &read_text(dir, DEPTH_FILE)?)?;
        let groundtruth = match read_text(dir, GROUNDTRUTH_FILE) {
            Ok(text) => Some(parse_groundtruth(&text)?),
            Err(RecordingError::Missing { .. }) => {
                tracing::warn!("{}: no {GROUNDTRUTH_FILE}; every frame gets the identity pose", dir.display());
                None
            }
            Err(e) => return Err(e),
        };
        let colour_times: Vec<f64> = colour.iter().map(|entry| entry.timestamp).collect();

        let mut recording = Recording {
            dir: dir.to_path_buf(),
            intrinsics,
            depth_scale,
            has_groundtruth: groundtruth.is_some(),
            timestamps: Vec::new(),
            poses: Vec::new(),
            frames: Frames::Files(Vec::new()),
            stats: AssociationStats { depth_frames: depth.len(), colour_frames: colour.len(), ..Default::default() },
            layout: Layout::Tum,
        };
        let mut files = Vec::new();
        let mut used_colour = HashSet::new();
        for entry in &depth {
            let t = entry.timestamp;
            let Some(c) = nearest(&colour_times, t).filter(|&c| (colour_times[c] - t).abs() <= tolerance) else {
                tracing::debug!("depth frame {t:.6}: no colour frame within {tolerance} s");
                recording.stats.without_colour += 1;
                continue;
            };
            let pose = match &groundtruth {
                None => Some(DAffine3::IDENTITY),
                Some(samples) => interpolate_pose(samples, t, tolerance),
            };
            let Some(pose) = pose else {
                tracing::debug!("depth frame {t:.6}: no ground-truth pose within {tolerance} s");
                recording.stats.without_pose += 1;
                continue;
            };
            if !used_colour.insert(c) {
                recording.stats.shared_colour += 1;
            }
            recording.timestamps.push(t);
            recording.poses.push(pose);
            files.push(FramePair { depth: entry.file.clone(), colour: colour[c].file.clone() });
        }
        recording.frames = Frames::Files(files);

        let stats = recording.stats;
        if recording.is_empty() {
            return Err(RecordingError::NoFrames { stats });
        }
        warn_skipped(dir, &stats, tolerance);
        tracing::debug!("{}: {} frames, {stats:?}", dir.display(), recording.len());
        Ok(recording)
    }

    /// Number of frames (depth frames with a colour partner and a pose).
    pub fn len(&self) -> usize {
        self.timestamps.len()
    }

    pub fn is_empty(&self) -> bool {
        self.timestamps.is_empty()
    }

    /// Assembles a recording that a layout's reader has read.
    pub(super) fn from_parts(parts: Parts) -> Recording {
        let Parts { dir, intrinsics, depth_scale, has_groundtruth, timestamps, poses, frames, stats, layout } = parts;
        Recording { dir, intrinsics, depth_scale, has_groundtruth, timestamps, poses, frames, stats, layout }
    }

    /// Frame `index`: both images read (or decoded) and checked against the intrinsics, depth
    /// in metres.
    pub fn frame(&self, index: usize) -> Result<RgbdFrame, RecordingError> {
        if index >= self.len() {
            return Err(RecordingError::FrameIndex { index, len: self.len() });
        }
        let (color, depth) = match &self.frames {
            Frames::Files(files) => {
                let files = &files[index];
                let color = load_colour(&self.dir, &files.colour, &self.intrinsics)?;
                let depth = load_depth(&self.dir, &files.depth, &self.intrinsics, self.depth_scale)?;
                (color, depth)
            }
            Frames::Mcap(images) => super::rosbag::decode_frame(&self.dir, &images[index], &self.intrinsics)?,
        };
        Ok(RgbdFrame {
            timestamp: self.timestamps[index],
            intrinsics: self.intrinsics,
            color,
            depth,
            camera_to_world: self.poses[index],
        })
    }

    /// Every frame in order, each loaded when the iterator reaches it.
    pub fn frames(&self) -> impl Iterator<Item = Result<RgbdFrame, RecordingError>> + '_ {
        (0..self.len()).map(|index| self.frame(index))
    }

    /// Depth timestamp (s) of each frame, strictly increasing.
    pub fn timestamps(&self) -> &[f64] {
        &self.timestamps
    }

    /// Camera-to-world pose (optical axes: x right, y down, z forward) of each frame, f64.
    pub fn poses(&self) -> &[DAffine3] {
        &self.poses
    }

    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// Depth units per metre.
    pub fn depth_scale(&self) -> f32 {
        self.depth_scale
    }

    /// Whether poses come from the recording (`groundtruth.txt`, `trajectory.log`, the MCAP's
    /// transforms); else all are the identity.
    pub fn has_groundtruth(&self) -> bool {
        self.has_groundtruth
    }

    pub fn stats(&self) -> &AssociationStats {
        &self.stats
    }

    /// The directory (or, for MCAP, the file) the recording was read from.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn layout(&self) -> Layout {
        self.layout
    }
}

/// Logs the depth frames that association left out, if any.
pub(super) fn warn_skipped(path: &Path, stats: &AssociationStats, tolerance: f64) {
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

/// `intrinsics.json` as written; sizes as numbers so a negative or fractional one is reported
/// by name.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct IntrinsicsFile {
    width: f64,
    height: f64,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    #[serde(default)]
    depth_scale: Option<f32>,
}

/// Intrinsics and depth scale, by precedence `intrinsics.json`, options, TUM defaults.
fn resolve_intrinsics(dir: &Path, options: &RecordingOptions) -> Result<(Intrinsics, f32), RecordingError> {
    const OPTIONS: &str = "recording options";
    if let Some(intrinsics) = &options.intrinsics {
        check_intrinsics(intrinsics).map_err(|(field, message)| value_error(OPTIONS, field, message))?;
    }
    if let Some(scale) = options.depth_scale {
        check_depth_scale(scale).map_err(|message| value_error(OPTIONS, "depth_scale", message))?;
    }
    let file = match read_text(dir, INTRINSICS_FILE) {
        Ok(text) => Some(parse_intrinsics_file(&text)?),
        Err(RecordingError::Missing { .. }) => None,
        Err(e) => return Err(e),
    };
    let Some((intrinsics, file_scale)) = file else {
        return Ok((options.intrinsics.unwrap_or(Intrinsics::TUM), options.depth_scale.unwrap_or(TUM_DEPTH_SCALE)));
    };
    if options.intrinsics.is_some_and(|given| given != intrinsics) {
        tracing::warn!("{}: {INTRINSICS_FILE} overrides the intrinsics given in the options", dir.display());
    }
    if file_scale.is_some() && options.depth_scale.is_some_and(|given| Some(given) != file_scale) {
        tracing::warn!("{}: {INTRINSICS_FILE} overrides the depth scale given in the options", dir.display());
    }
    let depth_scale = file_scale.or(options.depth_scale).unwrap_or(TUM_DEPTH_SCALE);
    Ok((intrinsics, depth_scale))
}

fn parse_intrinsics_file(text: &str) -> Result<(Intrinsics, Option<f32>), RecordingError> {
    let file: IntrinsicsFile = serde_json::from_str(text)
        .map_err(|source| RecordingError::Json { file: PathBuf::from(INTRINSICS_FILE), source })?;
    let size = |field: &'static str, value: f64| {
        if value.fract() == 0.0 && (1.0..=f64::from(u32::MAX)).contains(&value) {
            Ok(value as u32)
        } else {
            Err(value_error(INTRINSICS_FILE, field, format!("must be a whole number >= 1, got {value}")))
        }
    };
    let intrinsics = Intrinsics {
        width: size("width", file.width)?,
        height: size("height", file.height)?,
        fx: file.fx,
        fy: file.fy,
        cx: file.cx,
        cy: file.cy,
    };
    check_intrinsics(&intrinsics).map_err(|(field, message)| value_error(INTRINSICS_FILE, field, message))?;
    if let Some(scale) = file.depth_scale {
        check_depth_scale(scale).map_err(|message| value_error(INTRINSICS_FILE, "depth_scale", message))?;
    }
    Ok((intrinsics, file.depth_scale))
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

/// Checks that timestamps increase strictly, line by line.
struct Increasing<'a> {
    file: &'a str,
    previous: Option<f64>,
}

impl Increasing<'_> {
    fn check(&mut self, line: usize, t: f64) -> Result<(), RecordingError> {
        if let Some(previous) = self.previous.filter(|&previous| t <= previous) {
            return Err(line_error(
                self.file,
                line,
                format!("timestamp {t} is not after the previous line's {previous}"),
            ));
        }
        self.previous = Some(t);
        Ok(())
    }
}

/// One line of `rgb.txt` or `depth.txt`.
#[derive(Clone, Debug, PartialEq)]
struct FrameEntry {
    timestamp: f64,
    file: PathBuf,
}

fn parse_frame_list(file: &str, text: &str) -> Result<Vec<FrameEntry>, RecordingError> {
    let mut increasing = Increasing { file, previous: None };
    data_lines(text)
        .map(|(line, fields)| {
            let [timestamp, name] = fields[..] else {
                return Err(line_error(
                    file,
                    line,
                    format!("expected `timestamp filename`, got {} fields", fields.len()),
                ));
            };
            let timestamp = parse_number(file, line, "timestamp", timestamp)?;
            increasing.check(line, timestamp)?;
            Ok(FrameEntry { timestamp, file: PathBuf::from(name) })
        })
        .collect()
}

/// One line of `groundtruth.txt` (or one transform of an MCAP file): camera-to-world at
/// `timestamp`, in f64 as recorded (f32 keeps 7.8 mm at 100 km from the origin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct PoseSample {
    pub timestamp: f64,
    pub translation: DVec3,
    /// Unit.
    pub rotation: DQuat,
}

impl PoseSample {
    /// A sample from a translation and a quaternion `[x, y, z, w]` as recorded (f64), the
    /// quaternion normalised; an error when its norm is off 1 by more than
    /// [`QUATERNION_NORM_TOLERANCE`].
    pub fn new(timestamp: f64, translation: [f64; 3], quaternion: [f64; 4]) -> Result<PoseSample, String> {
        let norm = quaternion.iter().map(|c| c * c).sum::<f64>().sqrt();
        if norm.is_nan() || (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
            return Err(format!("quaternion (x y z w) has norm {norm}, not 1 (within {QUATERNION_NORM_TOLERANCE})"));
        }
        let q = quaternion.map(|c| c / norm);
        Ok(PoseSample {
            timestamp,
            translation: DVec3::from_array(translation),
            rotation: DQuat::from_array(q).normalize(),
        })
    }
}

fn parse_groundtruth(text: &str) -> Result<Vec<PoseSample>, RecordingError> {
    const FILE: &str = GROUNDTRUTH_FILE;
    const NAMES: [&str; 8] = ["timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"];
    let mut increasing = Increasing { file: FILE, previous: None };
    data_lines(text)
        .map(|(line, fields)| {
            if fields.len() != NAMES.len() {
                return Err(line_error(FILE, line, format!("expected 8 numbers, got {}", fields.len())));
            }
            let mut v = [0.0f64; 8];
            for ((value, field), name) in v.iter_mut().zip(&fields).zip(NAMES) {
                *value = parse_number(FILE, line, name, field)?;
            }
            increasing.check(line, v[0])?;
            PoseSample::new(v[0], [v[1], v[2], v[3]], [v[4], v[5], v[6], v[7]])
                .map_err(|message| line_error(FILE, line, message.replace("(x y z w)", "(qx qy qz qw)")))
        })
        .collect()
}

/// Index of the value of increasing `sorted` nearest to `t` (the earlier one on a tie).
pub(super) fn nearest(sorted: &[f64], t: f64) -> Option<usize> {
    let after = sorted.partition_point(|&x| x < t);
    match (after.checked_sub(1), (after < sorted.len()).then_some(after)) {
        (Some(before), Some(after)) => Some(if t - sorted[before] <= sorted[after] - t { before } else { after }),
        (before, after) => before.or(after),
    }
}

/// Camera-to-world at `t` from increasing `samples`: interpolated between the bracketing pair,
/// the end sample just outside the trajectory; `None` when no sample lies within `tolerance`.
pub(super) fn interpolate_pose(samples: &[PoseSample], t: f64, tolerance: f64) -> Option<DAffine3> {
    let after = samples.partition_point(|s| s.timestamp <= t);
    let (a, b) = match (after.checked_sub(1).map(|i| samples[i]), samples.get(after)) {
        (Some(a), Some(b)) => (a, *b),
        (Some(end), None) | (None, Some(&end)) => (end, end),
        (None, None) => return None,
    };
    if (t - a.timestamp).abs().min((b.timestamp - t).abs()) > tolerance {
        return None;
    }
    let s = if b.timestamp > a.timestamp { (t - a.timestamp) / (b.timestamp - a.timestamp) } else { 0.0 };
    let rotation = a.rotation.slerp(b.rotation, s).normalize();
    Some(DAffine3::from_rotation_translation(rotation, a.translation.lerp(b.translation, s)))
}

/// The format of a recording's image file by its extension: JPEG for `.jpg`/`.jpeg`, else PNG.
fn image_format(file: &Path) -> ImageFormat {
    match file.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("jpg" | "jpeg") => ImageFormat::Jpeg,
        _ => ImageFormat::Png,
    }
}

/// Opens an image of the recording (`format`), checks its size against `intrinsics` before
/// decoding it.
fn decode_image(
    dir: &Path,
    file: &Path,
    format: ImageFormat,
    intrinsics: &Intrinsics,
    accept: impl Fn(ColorType) -> bool,
    wanted: &str,
) -> Result<DynamicImage, RecordingError> {
    let image_error = |message: String| RecordingError::Image { file: file.to_path_buf(), message };
    let name = format.extensions_str().first().map_or("image".to_owned(), |e| e.to_ascii_uppercase());
    let reader = File::open(dir.join(file)).map_err(|source| io_error(file, source))?;
    let decoder = ImageReader::with_format(BufReader::new(reader), format)
        .into_decoder()
        .map_err(|e| image_error(format!("cannot decode {name}: {e}")))?;
    let (width, height) = decoder.dimensions();
    if (width, height) != (intrinsics.width, intrinsics.height) {
        return Err(RecordingError::ImageSize {
            file: file.to_path_buf(),
            width,
            height,
            expected_width: intrinsics.width,
            expected_height: intrinsics.height,
        });
    }
    let color_type = decoder.color_type();
    if !accept(color_type) {
        return Err(image_error(format!("expected {wanted} {name}, got {color_type:?}")));
    }
    DynamicImage::from_decoder(decoder).map_err(|e| image_error(format!("cannot decode {name}: {e}")))
}

/// 8-bit RGB or RGBA PNG, or 8-bit RGB JPEG, to row-major RGB (alpha dropped).
fn load_colour(dir: &Path, file: &Path, intrinsics: &Intrinsics) -> Result<Vec<[u8; 3]>, RecordingError> {
    let accept = |c| matches!(c, ColorType::Rgb8 | ColorType::Rgba8);
    let image = decode_image(dir, file, image_format(file), intrinsics, accept, "an 8-bit RGB or RGBA")?;
    let rgb = match image {
        DynamicImage::ImageRgb8(rgb) => rgb,
        other => other.into_rgb8(),
    };
    Ok(rgb.into_raw().chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
}

/// 16-bit grayscale PNG to row-major depth in metres (`value / depth_scale`; 0 stays 0).
fn load_depth(dir: &Path, file: &Path, intrinsics: &Intrinsics, depth_scale: f32) -> Result<Vec<f32>, RecordingError> {
    let accept = |c| c == ColorType::L16;
    let image = decode_image(dir, file, ImageFormat::Png, intrinsics, accept, "a 16-bit grayscale")?;
    let DynamicImage::ImageLuma16(depth) = image else {
        return Err(RecordingError::Image { file: file.to_path_buf(), message: "decoded as non-16-bit".to_owned() });
    };
    Ok(depth.into_raw().into_iter().map(|v| f32::from(v) / depth_scale).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    fn sample(timestamp: f64, x: f64, angle: f64) -> PoseSample {
        PoseSample { timestamp, translation: DVec3::new(x, 0.0, 0.0), rotation: DQuat::from_rotation_z(angle) }
    }

    #[test]
    fn frame_lists_skip_comments_and_blank_lines() {
        let text = "# color images\n# timestamp filename\n\n1.5 rgb/1.5.png\r\n  2.0   rgb/2.0.png  \n";
        let entries = parse_frame_list("rgb.txt", text).unwrap();
        assert_eq!(
            entries,
            vec![
                FrameEntry { timestamp: 1.5, file: PathBuf::from("rgb/1.5.png") },
                FrameEntry { timestamp: 2.0, file: PathBuf::from("rgb/2.0.png") }
            ]
        );
    }

    #[test]
    fn frame_list_errors_name_file_and_line() {
        let cases = [
            ("# h\n1.0 a.png\n2.0\n", "depth.txt line 3: expected `timestamp filename`, got 1 fields"),
            ("1.0 a.png extra\n", "depth.txt line 1: expected `timestamp filename`, got 3 fields"),
            ("1.0 a.png\nnow b.png\n", "depth.txt line 2: timestamp `now` is not a number"),
            ("inf a.png\n", "depth.txt line 1: timestamp is inf"),
            ("2.0 a.png\n\n2.0 b.png\n", "depth.txt line 3: timestamp 2 is not after the previous line's 2"),
        ];
        for (text, expected) in cases {
            let error = parse_frame_list("depth.txt", text).unwrap_err();
            assert_eq!(error.to_string(), expected, "{text:?}");
        }
    }

    #[test]
    fn groundtruth_normalises_quaternions_and_rejects_bad_ones() {
        let samples = parse_groundtruth("# gt\n1.0 1 2 3 0 0 0 1.0004\n").unwrap();
        assert_eq!(samples.len(), 1);
        assert_eq!(samples[0].translation, DVec3::new(1.0, 2.0, 3.0));
        assert!((samples[0].rotation.length() - 1.0).abs() < 1e-6);

        let cases = [
            ("1.0 0 0 0 0 0 0\n", "groundtruth.txt line 1: expected 8 numbers, got 7"),
            ("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 NaN 1\n", "groundtruth.txt line 2: qz is NaN"),
            ("1.0 0 0 x 0 0 0 1\n", "groundtruth.txt line 1: tz `x` is not a number"),
        ];
        for (text, expected) in cases {
            assert_eq!(parse_groundtruth(text).unwrap_err().to_string(), expected, "{text:?}");
        }
        let error = parse_groundtruth("# gt\n1.0 0 0 0 0 0 0 0.99\n").unwrap_err().to_string();
        assert!(error.starts_with("groundtruth.txt line 2: quaternion (qx qy qz qw) has norm 0.99"), "{error}");
    }

    #[test]
    fn groundtruth_far_from_the_origin_keeps_its_digits() {
        // f32 would round these to 7.8 mm steps; the pose is f64 up to `local_pose`.
        let samples = parse_groundtruth("1.0 100000.0001 -70000.0003 5 0 0 0 1\n").unwrap();
        assert_eq!(samples[0].translation, DVec3::new(100000.0001, -70000.0003, 5.0));
        let pose = interpolate_pose(&samples, 1.0, 0.02).unwrap();
        assert_eq!(pose.translation, samples[0].translation);
    }

    #[test]
    fn nearest_picks_the_closer_neighbour() {
        let times = [1.0, 2.0, 4.0];
        assert_eq!(nearest(&times, 0.0), Some(0));
        assert_eq!(nearest(&times, 1.4), Some(0));
        assert_eq!(nearest(&times, 1.5), Some(0));
        assert_eq!(nearest(&times, 1.6), Some(1));
        assert_eq!(nearest(&times, 3.5), Some(2));
        assert_eq!(nearest(&times, 9.0), Some(2));
        assert_eq!(nearest(&[], 1.0), None);
    }

    #[test]
    fn poses_interpolate_between_bracketing_samples() {
        let samples = [sample(0.0, 0.0, 0.0), sample(0.01, 1.0, FRAC_PI_2)];
        let pose = interpolate_pose(&samples, 0.0025, 0.02).unwrap();
        let (scale, rotation, translation) = pose.to_scale_rotation_translation();
        assert!(scale.abs_diff_eq(DVec3::ONE, 1e-12));
        assert!(translation.abs_diff_eq(DVec3::new(0.25, 0.0, 0.0), 1e-12), "{translation}");
        assert!(rotation.abs_diff_eq(DQuat::from_rotation_z(FRAC_PI_2 / 4.0), 1e-12), "{rotation}");
    }

    #[test]
    fn slerp_takes_the_short_way_across_a_sign_flip() {
        // The second sample is stored as -q: the same rotation, the opposite hemisphere.
        let mut b = sample(0.01, 0.0, 0.2);
        b.rotation = -b.rotation;
        let pose = interpolate_pose(&[sample(0.0, 0.0, 0.0), b], 0.005, 0.02).unwrap();
        let (_, rotation, _) = pose.to_scale_rotation_translation();
        assert!(rotation.abs_diff_eq(DQuat::from_rotation_z(0.1), 1e-12), "{rotation}");
    }

    #[test]
    fn poses_outside_the_trajectory_or_in_gaps_are_missing() {
        let samples = [sample(1.0, 0.0, 0.0), sample(1.01, 1.0, 0.0), sample(2.0, 2.0, 0.0)];
        // Just outside: the end sample.
        let before = interpolate_pose(&samples, 0.99, 0.02).unwrap();
        assert_eq!(before.translation, DVec3::ZERO);
        let after = interpolate_pose(&samples, 2.015, 0.02).unwrap();
        assert_eq!(after.translation, DVec3::new(2.0, 0.0, 0.0));
        // Further outside, or in the middle of a 1 s tracking gap.
        assert!(interpolate_pose(&samples, 0.97, 0.02).is_none());
        assert!(interpolate_pose(&samples, 2.03, 0.02).is_none());
        assert!(interpolate_pose(&samples, 1.5, 0.02).is_none());
        assert!(interpolate_pose(&samples, 1.025, 0.02).is_some());
        assert!(interpolate_pose(&[], 1.0, 0.02).is_none());
    }

    #[test]
    fn intrinsics_file_names_the_bad_field() {
        let ok = r#"{"width":640,"height":480,"fx":525,"fy":525,"cx":319.5,"cy":239.5}"#;
        assert_eq!(parse_intrinsics_file(ok).unwrap(), (Intrinsics::TUM, None));
        let scaled = r#"{"width":640,"height":480,"fx":525,"fy":525,"cx":319.5,"cy":239.5,"depth_scale":1000}"#;
        assert_eq!(parse_intrinsics_file(scaled).unwrap().1, Some(1000.0));

        let cases = [
            (r#"{"width":640,"height":480,"fx":-525,"fy":525,"cx":319.5,"cy":239.5}"#, "fx must be positive"),
            (r#"{"width":-640,"height":480,"fx":525,"fy":525,"cx":319.5,"cy":239.5}"#, "width must be a whole"),
            (r#"{"width":640,"height":480.5,"fx":525,"fy":525,"cx":319.5,"cy":239.5}"#, "height must be a whole"),
            (r#"{"width":640,"height":480,"fx":525,"fy":525,"cx":319.5,"cy":239.5,"fov":1}"#, "unknown field `fov`"),
            (r#"{"width":640,"height":480,"fx":525,"fy":525,"cx":319.5}"#, "missing field `cy`"),
            (r#"{"width":640,"height":480,"fx":525,"fy":525,"cx":319.5,"cy":239.5,"depth_scale":0}"#, "depth_scale"),
        ];
        for (text, expected) in cases {
            let error = parse_intrinsics_file(text).unwrap_err().to_string();
            assert!(error.starts_with("intrinsics.json: "), "{error}");
            assert!(error.contains(expected), "{error} should contain {expected}");
        }
    }
}
