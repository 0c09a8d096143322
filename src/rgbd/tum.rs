//! The TUM RGB-D layout (docs/rgbd.md "Recording layouts"): a directory holding
//!
//! - `rgb.txt` and `depth.txt`: `timestamp filename` lines (seconds; file names relative to the
//!   directory), `#` starts a comment line;
//! - optionally `groundtruth.txt`: `timestamp tx ty tz qx qy qz qw` lines, the camera-to-world
//!   pose of the colour camera's optical frame (x right, y down, z forward), quaternion w last,
//!   sampled at about 100 Hz and not synchronised with the images;
//! - optionally `intrinsics.json`: `{"width", "height", "fx", "fy", "cx", "cy", "depth_scale"}`
//!   (`depth_scale` optional), the pinhole intrinsics of the registered depth image.
//!
//! [`open`] reads the text files, pairs each depth frame with the colour frame of nearest
//! timestamp and interpolates its pose.

use std::path::{Path, PathBuf};

use glam::DAffine3;
use serde::Deserialize;

use super::Intrinsics;
use super::poses::{PoseSample, interpolate_pose};
use super::reader::{
    Associated, FramePair, Layout, Parts, RecordingError, RecordingOptions, associate, check_depth_scale,
    check_intrinsics, check_tolerance, data_lines, line_error, parse_number, read_text, value_error,
};

/// TUM's depth scale: 16-bit depth units per metre.
pub const TUM_DEPTH_SCALE: f32 = 5000.0;
/// The intrinsics file beside the text files.
pub const INTRINSICS_FILE: &str = "intrinsics.json";
pub(super) const RGB_FILE: &str = "rgb.txt";
pub(super) const DEPTH_FILE: &str = "depth.txt";
const GROUNDTRUTH_FILE: &str = "groundtruth.txt";

/// Whether `dir` holds the text files of a TUM recording.
pub fn detect(dir: &Path) -> bool {
    dir.join(RGB_FILE).exists() || dir.join(DEPTH_FILE).exists()
}

/// Reads the TUM recording in `dir`.
///
/// - Intrinsics: `intrinsics.json` if present, else `options.intrinsics`, else
///   [`Intrinsics::TUM`]; the depth scale likewise from the file's `depth_scale`,
///   `options.depth_scale`, [`TUM_DEPTH_SCALE`].
/// - Each depth frame is paired with the colour frame of nearest timestamp; one without a
///   colour frame within `options.tolerance_s` is skipped. A colour frame may serve two
///   depth frames ([`AssociationStats::shared_colour`](super::reader::AssociationStats::shared_colour)).
/// - The pose at the depth timestamp is interpolated between the two bracketing ground-truth
///   samples (translation lerp, rotation slerp). A frame whose nearest sample is further than
///   the tolerance (outside the trajectory, or in a tracking gap) is skipped; just outside the
///   trajectory, the end sample is used. Without `groundtruth.txt` every pose is the identity.
///
/// Timestamps must increase strictly within each file. Fails when no frame is left.
pub(super) fn open(dir: &Path, options: &RecordingOptions) -> Result<Parts<Vec<FramePair>>, RecordingError> {
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
    let pose_at = |t| {
        let pose = match &groundtruth {
            None => Some(DAffine3::IDENTITY),
            Some(samples) => interpolate_pose(samples, t, tolerance),
        };
        if pose.is_none() {
            tracing::debug!("depth frame {t:.6}: no ground-truth pose within {tolerance} s");
        }
        pose
    };
    let files = |entry: &FrameEntry, c: usize| FramePair { depth: entry.file.clone(), colour: colour[c].file.clone() };
    let depth = depth.iter().map(|entry| (entry.timestamp, entry));
    let Associated { timestamps, poses, frames, stats } =
        associate(dir, depth, &colour_times, tolerance, pose_at, files)?;
    tracing::debug!("{}: {} frames, {stats:?}", dir.display(), timestamps.len());
    Ok(Parts {
        dir: dir.to_path_buf(),
        intrinsics,
        depth_scale,
        has_groundtruth: groundtruth.is_some(),
        timestamps,
        poses,
        frames,
        stats,
        layout: Layout::Tum,
    })
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rgbd::poses::interpolate_pose;
    use glam::DVec3;

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
