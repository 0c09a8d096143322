//! Open3D / Redwood RGB-D recordings (docs/rgbd.md "Recording layouts"): the layout
//! of Open3D's `SampleRedwoodRGBDImages` and of its reconstruction system's datasets.
//!
//! A recording is a directory holding
//!
//! - `depth/` and `color/` (or `image/`): one depth PNG (16-bit grayscale, millimetres: scale
//!   [`REDWOOD_DEPTH_SCALE`], 0 = none) and one colour JPEG or PNG per frame;
//! - optionally `rgbd.match`: `depth/<file> color/<file>` lines pairing them; without it the
//!   two folders' files, sorted by name, pair up in order (as Open3D's `get_rgbd_file_lists`);
//! - optionally `camera_intrinsic.json` or `camera_primesense.json`: Open3D's
//!   `PinholeCameraIntrinsic` JSON `{"width", "height", "intrinsic_matrix": [9 numbers]}`, the
//!   matrix column-major; without it the options' intrinsics or [`Intrinsics::TUM`] (which is
//!   Open3D's PrimeSense default, fx = fy = 525, cx = 319.5, cy = 239.5);
//! - optionally `trajectory.log`: Open3D's trajectory format, per frame a line of three
//!   integers (metadata) and four lines of a 4x4 camera-to-world matrix (optical axes), in
//!   frame order; without it every pose is the identity.
//!
//! The layout has no timestamps: frame `i` is at `i /` [`REDWOOD_FRAME_RATE_HZ`] seconds.

use std::path::{Path, PathBuf};

use glam::{DAffine3, DMat3, DMat4, DVec4};
use serde::Deserialize;

use super::Intrinsics;
use super::reader::{
    AssociationStats, FramePair, Layout, Parts, RecordingError, RecordingOptions, check_depth_scale, check_intrinsics,
    data_lines, io_error, line_error, parse_number, read_text, value_error,
};

/// Open3D's depth scale: 16-bit depth units (mm) per metre.
pub const REDWOOD_DEPTH_SCALE: f32 = 1000.0;
/// The frame rate the timestamps assume (PrimeSense, Redwood's sensor, at 30 Hz).
pub const REDWOOD_FRAME_RATE_HZ: f64 = 30.0;
/// Largest entry of `|R Rᵀ - I|` accepted for a `trajectory.log` rotation block (Open3D writes
/// about 16 digits; the shared sample's worst is 1.7e-6).
pub const ROTATION_TOLERANCE: f64 = 1e-3;

const DEPTH_DIR: &str = "depth";
/// Colour folder names, in order of preference.
const COLOUR_DIRS: [&str; 2] = ["color", "image"];
const MATCH_FILE: &str = "rgbd.match";
/// Intrinsics file names, in order of preference.
const INTRINSICS_FILES: [&str; 2] = ["camera_intrinsic.json", "camera_primesense.json"];
const TRAJECTORY_FILE: &str = "trajectory.log";

/// Whether `dir` has the folders of a Redwood recording.
pub fn detect(dir: &Path) -> bool {
    dir.join(DEPTH_DIR).is_dir() && COLOUR_DIRS.iter().any(|name| dir.join(name).is_dir())
}

/// Reads the Redwood recording in `dir`. Intrinsics: the camera JSON, else
/// `options.intrinsics`, else [`Intrinsics::TUM`]; depth scale: `options.depth_scale`, else
/// [`REDWOOD_DEPTH_SCALE`]. `options.tolerance_s` is not used (nothing to associate).
pub(super) fn open(dir: &Path, options: &RecordingOptions) -> Result<Parts<Vec<FramePair>>, RecordingError> {
    let intrinsics = resolve_intrinsics(dir, options)?;
    let depth_scale = match options.depth_scale {
        Some(scale) => {
            check_depth_scale(scale).map_err(|message| value_error("recording options", "depth_scale", message))?;
            scale
        }
        None => REDWOOD_DEPTH_SCALE,
    };
    let pairs = match read_text(dir, MATCH_FILE) {
        Ok(text) => parse_match(&text)?,
        Err(RecordingError::Missing { .. }) => pair_by_name(dir)?,
        Err(e) => return Err(e),
    };
    if pairs.is_empty() {
        return Err(RecordingError::NoFrames { stats: AssociationStats::default() });
    }
    let (poses, has_groundtruth) = match read_text(dir, TRAJECTORY_FILE) {
        Ok(text) => {
            let poses = parse_trajectory(&text)?;
            if poses.len() != pairs.len() {
                return Err(RecordingError::Line {
                    file: PathBuf::from(TRAJECTORY_FILE),
                    line: text.lines().count(),
                    message: format!("has {} poses for {} frames", poses.len(), pairs.len()),
                });
            }
            (poses, true)
        }
        Err(RecordingError::Missing { .. }) => {
            tracing::warn!("{}: no {TRAJECTORY_FILE}; every frame gets the identity pose", dir.display());
            (vec![DAffine3::IDENTITY; pairs.len()], false)
        }
        Err(e) => return Err(e),
    };
    let n = pairs.len();
    Ok(Parts {
        dir: dir.to_path_buf(),
        intrinsics,
        depth_scale,
        has_groundtruth,
        timestamps: (0..n).map(|i| i as f64 / REDWOOD_FRAME_RATE_HZ).collect(),
        poses,
        frames: pairs,
        stats: AssociationStats { depth_frames: n, colour_frames: n, ..Default::default() },
        layout: Layout::Redwood,
    })
}

/// Open3D's `PinholeCameraIntrinsic` JSON; sizes as numbers so a bad one is named.
#[derive(Deserialize)]
struct IntrinsicsFile {
    width: f64,
    height: f64,
    intrinsic_matrix: [f32; 9],
}

fn resolve_intrinsics(dir: &Path, options: &RecordingOptions) -> Result<Intrinsics, RecordingError> {
    for name in INTRINSICS_FILES {
        match read_text(dir, name) {
            Ok(text) => return parse_intrinsics(name, &text),
            Err(RecordingError::Missing { .. }) => {}
            Err(e) => return Err(e),
        }
    }
    let intrinsics = options.intrinsics.unwrap_or(Intrinsics::TUM);
    check_intrinsics(&intrinsics).map_err(|(field, message)| value_error("recording options", field, message))?;
    Ok(intrinsics)
}

/// The camera JSON `name`: `intrinsic_matrix` column-major `[fx 0 0, 0 fy 0, cx cy 1]`.
fn parse_intrinsics(name: &'static str, text: &str) -> Result<Intrinsics, RecordingError> {
    let file: IntrinsicsFile =
        serde_json::from_str(text).map_err(|source| RecordingError::Json { file: PathBuf::from(name), source })?;
    let size = |field: &'static str, value: f64| {
        if value.fract() == 0.0 && (1.0..=f64::from(u32::MAX)).contains(&value) {
            Ok(value as u32)
        } else {
            Err(value_error(name, field, format!("must be a whole number >= 1, got {value}")))
        }
    };
    let m = file.intrinsic_matrix;
    for (index, expected) in [(1, 0.0), (2, 0.0), (3, 0.0), (5, 0.0), (8, 1.0)] {
        if m[index] != expected {
            return Err(value_error(
                name,
                "intrinsic_matrix",
                format!(
                    "must be a pinhole matrix without skew, column-major [fx 0 0 0 fy 0 cx cy 1]; entry {index} is {}, not {expected}",
                    m[index]
                ),
            ));
        }
    }
    let intrinsics = Intrinsics {
        width: size("width", file.width)?,
        height: size("height", file.height)?,
        fx: m[0],
        fy: m[4],
        cx: m[6],
        cy: m[7],
    };
    check_intrinsics(&intrinsics).map_err(|(field, message)| value_error(name, field, message))?;
    Ok(intrinsics)
}

/// `rgbd.match`: `depth colour` file pairs, one a line.
fn parse_match(text: &str) -> Result<Vec<FramePair>, RecordingError> {
    data_lines(text)
        .map(|(line, fields)| match fields[..] {
            [depth, colour] => Ok(FramePair { depth: PathBuf::from(depth), colour: PathBuf::from(colour) }),
            _ => Err(line_error(
                MATCH_FILE,
                line,
                format!("expected `depth_file colour_file`, got {} fields", fields.len()),
            )),
        })
        .collect()
}

/// The files of `depth/` and of the colour folder, sorted by name, paired in order.
fn pair_by_name(dir: &Path) -> Result<Vec<FramePair>, RecordingError> {
    let colour_dir = COLOUR_DIRS.into_iter().find(|name| dir.join(name).is_dir()).unwrap_or(COLOUR_DIRS[0]);
    let list = |folder: &str, extensions: &[&str]| -> Result<Vec<PathBuf>, RecordingError> {
        let entries = std::fs::read_dir(dir.join(folder)).map_err(|e| io_error(Path::new(folder), e))?;
        let mut files = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| io_error(Path::new(folder), e))?;
            let name = PathBuf::from(entry.file_name());
            let wanted = name
                .extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| extensions.iter().any(|x| e.eq_ignore_ascii_case(x)));
            if wanted {
                files.push(Path::new(folder).join(name));
            }
        }
        files.sort();
        Ok(files)
    };
    let depth = list(DEPTH_DIR, &["png"])?;
    let colour = list(colour_dir, &["jpg", "jpeg", "png"])?;
    if depth.len() != colour.len() {
        return Err(RecordingError::NotARecording {
            path: dir.to_path_buf(),
            message: format!(
                "{DEPTH_DIR}/ has {} PNGs and {colour_dir}/ {} images; without {MATCH_FILE} they must pair up one to one",
                depth.len(),
                colour.len()
            ),
        });
    }
    Ok(depth.into_iter().zip(colour).map(|(depth, colour)| FramePair { depth, colour }).collect())
}

/// `trajectory.log`: per entry a metadata line of three integers, then four rows of the
/// camera-to-world matrix. Each must be rigid: last row `0 0 0 1`, rotation orthonormal within
/// [`ROTATION_TOLERANCE`] with determinant +1. Read in f64, as written (a trajectory far from
/// the origin keeps its millimetres).
fn parse_trajectory(text: &str) -> Result<Vec<DAffine3>, RecordingError> {
    const FILE: &str = TRAJECTORY_FILE;
    let lines: Vec<(usize, Vec<&str>)> = data_lines(text).collect();
    let mut poses = Vec::with_capacity(lines.len() / 5);
    for entry in lines.chunks(5) {
        let (meta_line, meta) = &entry[0];
        if meta.len() != 3 || meta.iter().any(|f| f.parse::<i64>().is_err()) {
            return Err(line_error(FILE, *meta_line, "expected the metadata line of an entry: three integers"));
        }
        if entry.len() < 5 {
            return Err(line_error(FILE, *meta_line, format!("entry has {} of the 4 matrix rows", entry.len() - 1)));
        }
        let mut rows = [DVec4::ZERO; 4];
        for ((line, fields), row) in entry[1..].iter().zip(&mut rows) {
            if fields.len() != 4 {
                return Err(line_error(
                    FILE,
                    *line,
                    format!("expected a matrix row of 4 numbers, got {}", fields.len()),
                ));
            }
            let mut v = [0.0f64; 4];
            for (i, (value, field)) in v.iter_mut().zip(fields).enumerate() {
                *value = parse_number(FILE, *line, &format!("column {}", i + 1), field)?;
            }
            *row = DVec4::from_array(v);
        }
        let last_line = entry[4].0;
        if rows[3] != DVec4::new(0.0, 0.0, 0.0, 1.0) {
            return Err(line_error(FILE, last_line, format!("last matrix row must be 0 0 0 1, got {}", rows[3])));
        }
        let matrix = DMat4::from_cols(rows[0], rows[1], rows[2], rows[3]).transpose();
        let rotation = DMat3::from_mat4(matrix);
        let error = (rotation * rotation.transpose() - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |a, b| a.max(b.abs()));
        let rigid = error <= ROTATION_TOLERANCE && rotation.determinant() > 0.0;
        if !rigid {
            return Err(line_error(
                FILE,
                entry[1].0,
                format!(
                    "the rotation block is not a rotation (max |R Rᵀ - I| = {error}, det = {}; tolerance {ROTATION_TOLERANCE})",
                    rotation.determinant()
                ),
            ));
        }
        let (_, q, t) = matrix.to_scale_rotation_translation();
        poses.push(DAffine3::from_rotation_translation(q.normalize(), t));
    }
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use super::*;

    const POSE: &str = "0 0 1\n1 0 0 2\n0 -1 0 3\n0 0 -1 4\n0 0 0 1\n";

    #[test]
    fn trajectory_entries_become_camera_to_world_poses() {
        let poses = parse_trajectory(&format!("{POSE}{}", POSE.replacen("0 0 1", "1 1 2", 1))).unwrap();
        assert_eq!(poses.len(), 2);
        let p = poses[0].transform_point3(glam::DVec3::new(1.0, 1.0, 1.0));
        assert!(p.abs_diff_eq(glam::DVec3::new(3.0, 2.0, 3.0), 1e-12), "{p}");
    }

    #[test]
    fn trajectory_errors_name_the_line() {
        let cases = [
            ("0 0\n1 0 0 0\n", "trajectory.log line 1: expected the metadata line"),
            ("0 0 1\n1 0 0 0\n0 1 0 0\n", "trajectory.log line 1: entry has 2 of the 4 matrix rows"),
            ("0 0 1\n1 0 0 0\n0 1 0\n0 0 1 0\n0 0 0 1\n", "trajectory.log line 3: expected a matrix row of 4"),
            ("0 0 1\n1 0 0 0\n0 1 0 x\n0 0 1 0\n0 0 0 1\n", "trajectory.log line 3: column 4 `x` is not a number"),
            ("0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n", "trajectory.log line 5: last matrix row"),
            ("0 0 1\n2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "trajectory.log line 2: the rotation block is not"),
            ("0 0 1\n-1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "trajectory.log line 2: the rotation block is not"),
        ];
        for (text, expected) in cases {
            let error = parse_trajectory(text).unwrap_err().to_string();
            assert!(error.starts_with(expected), "{text:?}: {error}");
        }
    }

    #[test]
    fn intrinsics_matrix_is_column_major_and_checked() {
        let json = r#"{"width": 640, "height": 480, "intrinsic_matrix": [525, 0, 0, 0, 520, 0, 319.5, 239.5, 1]}"#;
        let k = parse_intrinsics("camera_primesense.json", json).unwrap();
        assert_eq!(k, Intrinsics { width: 640, height: 480, fx: 525.0, fy: 520.0, cx: 319.5, cy: 239.5 });
        let cases = [
            (json.replace("525, 0, 0", "525, 0, 1"), "intrinsic_matrix must be a pinhole matrix"),
            (json.replace("525, 0, 0", "-525, 0, 0"), "fx must be positive"),
            (json.replace("640", "64.5"), "width must be a whole number"),
            (json.replace(", 1]", "]"), "invalid length 8"),
        ];
        for (text, expected) in cases {
            let error = parse_intrinsics("camera_primesense.json", &text).unwrap_err().to_string();
            assert!(error.starts_with("camera_primesense.json: "), "{error}");
            assert!(error.contains(expected), "{error} should contain {expected}");
        }
    }

    #[test]
    fn match_lines_pair_depth_with_colour() {
        let pairs = parse_match("depth/0.png color/0.jpg\n\ndepth/1.png color/1.jpg\n").unwrap();
        assert_eq!(pairs.len(), 2);
        assert_eq!((pairs[1].depth.to_str(), pairs[1].colour.to_str()), (Some("depth/1.png"), Some("color/1.jpg")));
        let error = parse_match("depth/0.png\n").unwrap_err().to_string();
        assert_eq!(error, "rgbd.match line 1: expected `depth_file colour_file`, got 1 fields");
    }
}
