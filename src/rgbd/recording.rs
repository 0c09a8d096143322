//! RGB-D recordings on disk (docs/rgbd.md "Recording layouts"), in three layouts
//! that [`Recording::open`] tells apart by their files:
//!
//! - a TUM RGB-D directory (`rgb.txt`, `depth.txt`; see [`super::tum`]);
//! - an Open3D / Redwood directory (`color/` or `image/` and `depth/`; see [`super::redwood`]);
//! - an MCAP file (ROS 2 / Foxglove bag, `.mcap`; see [`super::rosbag`]).
//!
//! Each layout has its reader (`tum`, `redwood`, `rosbag`), which returns the recording's
//! parts (`reader::Parts`); this file dispatches by layout and assembles them.
//! [`Recording::frame`] loads the images of one frame (`images`: colour 8-bit RGB or RGBA;
//! depth 16-bit grayscale, `depth_scale` units per metre, 0 = none; MCAP: `rosbag`).
//!
//! Errors name the file relative to the recording directory and, for text files, the 1-based
//! line (`groundtruth.txt line 12: expected 8 numbers, got 7`); callers add the directory.

use std::path::{Path, PathBuf};

use glam::DAffine3;

use super::images::{load_colour, load_depth};
use super::reader::{FramePair, Parts};
use super::tum::{DEPTH_FILE, RGB_FILE};
use super::{Intrinsics, RgbdFrame};

// The public names of recordings, wherever their layouts' readers define them.
pub use super::poses::QUATERNION_NORM_TOLERANCE;
pub use super::reader::{
    AssociationStats, DEFAULT_TOLERANCE_S, Layout, McapTopics, RecordingError, RecordingOptions, check_intrinsics,
};
pub use super::tum::{INTRINSICS_FILE, TUM_DEPTH_SCALE};

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

/// Where each frame's images are.
#[derive(Clone, Debug)]
pub(super) enum Frames {
    /// Image files relative to the recording directory, one pair per frame.
    Files(Vec<FramePair>),
    /// Images decoded from an MCAP file, one per frame.
    Mcap(Vec<super::rosbag::FrameImages>),
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
                super::rosbag::open(path, options).map(|parts| Self::from_parts(parts, Frames::Mcap))
            } else {
                Err(not_a_recording("a file, and not an MCAP file (`.mcap`)".to_owned()))
            };
        }
        if !path.is_dir() {
            return Err(not_a_recording("no such file or directory".to_owned()));
        }
        if super::tum::detect(path) {
            return Self::open_tum(path, options);
        }
        if super::redwood::detect(path) {
            return super::redwood::open(path, options).map(|parts| Self::from_parts(parts, Frames::Files));
        }
        Err(not_a_recording(format!(
            "a directory with neither {RGB_FILE}/{DEPTH_FILE} (TUM) nor depth/ beside color/ or image/ (Open3D/Redwood)"
        )))
    }

    /// Reads the TUM recording in `dir` ([`super::tum::open`] says how).
    pub fn open_tum(dir: &Path, options: &RecordingOptions) -> Result<Recording, RecordingError> {
        super::tum::open(dir, options).map(|parts| Self::from_parts(parts, Frames::Files))
    }

    /// Number of frames (depth frames with a colour partner and a pose).
    pub fn len(&self) -> usize {
        self.timestamps.len()
    }

    pub fn is_empty(&self) -> bool {
        self.timestamps.is_empty()
    }

    /// Assembles a recording that a layout's reader has read, its frames made [`Frames`] by
    /// `frames`.
    fn from_parts<F>(parts: Parts<F>, frames: impl FnOnce(F) -> Frames) -> Recording {
        let Parts { dir, intrinsics, depth_scale, has_groundtruth, timestamps, poses, frames: read, stats, layout } =
            parts;
        let frames = frames(read);
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
