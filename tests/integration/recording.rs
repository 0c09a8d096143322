//! TUM RGB-D recordings: the `tum_fr1_xyz` fixture, and malformed recordings written to a
//! scratch directory.

use std::path::{Path, PathBuf};

use glam::{DAffine3, DMat3, DQuat, DVec3, Vec3};
use relume::rgbd::Intrinsics;
use relume::rgbd::recording::{Recording, RecordingError, RecordingOptions};

use super::{fixture, scratch};

fn open_fixture() -> Recording {
    let dir = fixture("recordings/tum_fr1_xyz");
    Recording::open(&dir, &RecordingOptions::default()).unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
}

/// `timestamp` fields of a TUM list, read independently of relume's parser.
fn timestamps_in(file: &Path) -> Vec<f64> {
    std::fs::read_to_string(file)
        .unwrap()
        .lines()
        .filter(|line| !line.trim().is_empty() && !line.starts_with('#'))
        .map(|line| line.split_whitespace().next().unwrap().parse().unwrap())
        .collect()
}

#[test]
fn recording_fixture_associates_every_depth_frame() {
    let recording = open_fixture();
    let dir = fixture("recordings/tum_fr1_xyz");
    // Brute force: depth frames with a colour frame within 0.02 s and a ground-truth sample
    // within 0.02 s.
    let colour = timestamps_in(&dir.join("rgb.txt"));
    let depth = timestamps_in(&dir.join("depth.txt"));
    let groundtruth = timestamps_in(&dir.join("groundtruth.txt"));
    let within = |t: f64, list: &[f64]| list.iter().any(|&u| (u - t).abs() <= 0.02);
    let expected: Vec<f64> = depth.iter().copied().filter(|&t| within(t, &colour) && within(t, &groundtruth)).collect();
    assert_eq!(expected.len(), 37, "all 37 depth frames of the fixture have partners");
    assert_eq!(recording.len(), expected.len());
    assert_eq!(recording.timestamps(), &expected[..]);

    let stats = recording.stats();
    assert_eq!((stats.depth_frames, stats.colour_frames), (37, 37));
    assert_eq!((stats.without_colour, stats.without_pose), (0, 0));
    // Depth runs 12-17 ms ahead of colour with jitter: for five depth frames the previous
    // colour frame is nearer than the next, so five colour frames serve two depth frames.
    assert_eq!(stats.shared_colour, 5);
    assert!(recording.has_groundtruth());
    assert_eq!(*recording.intrinsics(), Intrinsics::TUM);
    assert_eq!(recording.depth_scale(), 5000.0);
}

#[test]
fn recording_fixture_poses_are_rigid_and_smooth() {
    let recording = open_fixture();
    let poses = recording.poses();
    for (i, pose) in poses.iter().enumerate() {
        let r: DMat3 = pose.matrix3;
        assert!((r * r.transpose()).abs_diff_eq(DMat3::IDENTITY, 1e-12), "frame {i}: rotation not orthonormal");
        assert!((r.determinant() - 1.0).abs() < 1e-12, "frame {i}: determinant {}", r.determinant());
        let q = DQuat::from_mat3(&r);
        assert!((q.length() - 1.0).abs() < 1e-12);
    }
    // fr1/xyz moves about 0.3 m/s and turns slowly: at ~30 Hz the largest steps are 14 mm and
    // 1.2 degrees.
    for (i, pair) in poses.windows(2).enumerate() {
        let step = (pair[1].translation - pair[0].translation).length();
        let (_, q0, _) = pair[0].to_scale_rotation_translation();
        let (_, q1, _) = pair[1].to_scale_rotation_translation();
        let angle = q0.angle_between(q1).to_degrees();
        assert!(step < 0.03 && angle < 3.0, "frames {i}-{}: moved {step} m, turned {angle} deg", i + 1);
    }
    // First frame (depth 1305031102.160407) against the ground truth lines around it, lerped
    // and normalised by hand.
    let first = poses[0];
    let expected_translation = DVec3::new(1.34437, 0.62721, 1.66173);
    assert!(first.translation.abs_diff_eq(expected_translation, 1e-4), "{}", first.translation);
    let (_, rotation, _) = first.to_scale_rotation_translation();
    let expected = DQuat::from_xyzw(0.658250, 0.611042, -0.294449, -0.326548);
    assert!(rotation.abs_diff_eq(expected, 1e-5) || rotation.abs_diff_eq(-expected, 1e-5), "{rotation}");
}

#[test]
fn recording_fixture_frame_loads_in_metres() {
    let recording = open_fixture();
    let frame = recording.frame(0).unwrap();
    let pixels = 640 * 480;
    assert_eq!((frame.color.len(), frame.depth.len()), (pixels, pixels));
    assert_eq!(frame.timestamp, recording.timestamps()[0]);
    assert_eq!(frame.camera_to_world, recording.poses()[0]);
    let valid: Vec<f32> = frame.depth.iter().copied().filter(|&d| d != 0.0).collect();
    let (min, max) = valid.iter().fold((f32::MAX, f32::MIN), |(lo, hi), &d| (lo.min(d), hi.max(d)));
    // SOURCE.md: raw 2839..19422 over all frames (0.57..3.88 m); 23-27 % of pixels invalid.
    assert!(min >= 0.5 && max <= 4.0, "depth range {min}..{max} m");
    let invalid = 1.0 - valid.len() as f32 / pixels as f32;
    assert!((0.2..0.3).contains(&invalid), "invalid fraction {invalid}");
    assert!(frame.depth.iter().all(|d| d.is_finite() && *d >= 0.0));
    let mean: Vec3 =
        frame.color.iter().map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)).sum::<Vec3>() / pixels as f32;
    assert!(mean.min_element() > 20.0 && mean.max_element() < 235.0, "mean colour {mean}");
    let last = recording.frames().last().unwrap().unwrap();
    assert_eq!(last.timestamp, *recording.timestamps().last().unwrap());
    assert!(matches!(recording.frame(37), Err(RecordingError::FrameIndex { index: 37, len: 37 })));
}

/// A small recording: 4x3 images, `intrinsics.json`, three frames at 1.00, 1.03, 1.06 s with
/// colour 5 ms after depth, and ground truth every 10 ms moving along +x at 1 m/s.
struct Synthetic {
    dir: PathBuf,
}

impl Synthetic {
    const WIDTH: u32 = 4;
    const HEIGHT: u32 = 3;

    fn new(name: &str) -> Synthetic {
        let dir = scratch(&format!("recording_{name}"));
        std::fs::create_dir_all(dir.join("rgb")).unwrap();
        std::fs::create_dir_all(dir.join("depth")).unwrap();
        let mut rgb = String::from("# color images\n# timestamp filename\n");
        let mut depth = String::from("# depth maps\n# timestamp filename\n");
        for i in 0..3 {
            let t = 1.0 + 0.03 * f64::from(i);
            let colour_name = format!("rgb/{:.6}.png", t + 0.005);
            let depth_name = format!("depth/{t:.6}.png");
            rgb += &format!("{:.6} {colour_name}\n", t + 0.005);
            depth += &format!("{t:.6} {depth_name}\n");
            let colour = image::RgbImage::from_fn(Self::WIDTH, Self::HEIGHT, |x, y| image::Rgb([x as u8, y as u8, 7]));
            colour.save(dir.join(&colour_name)).unwrap();
            // Raw depth: 0 (missing) at the first pixel, 1000 * (x + 1) elsewhere.
            let raw = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(Self::WIDTH, Self::HEIGHT, |x, y| {
                image::Luma([if (x, y) == (0, 0) { 0 } else { 1000 * (x as u16 + 1) }])
            });
            raw.save(dir.join(&depth_name)).unwrap();
        }
        std::fs::write(dir.join("rgb.txt"), rgb).unwrap();
        std::fs::write(dir.join("depth.txt"), depth).unwrap();
        let mut groundtruth = String::from("# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n");
        for i in 0..=10 {
            let t = 0.99 + 0.01 * f64::from(i);
            groundtruth += &format!("{t:.4} {:.4} 0 0 0 0 0 1\n", t - 1.0);
        }
        std::fs::write(dir.join("groundtruth.txt"), groundtruth).unwrap();
        let synthetic = Synthetic { dir };
        synthetic.write("intrinsics.json", r#"{"width":4,"height":3,"fx":3,"fy":3,"cx":1.5,"cy":1}"#);
        synthetic
    }

    fn write(&self, file: &str, text: &str) {
        std::fs::write(self.dir.join(file), text).unwrap();
    }

    fn open(&self) -> Result<Recording, RecordingError> {
        Recording::open(&self.dir, &RecordingOptions::default())
    }

    fn open_err(&self) -> String {
        self.open().map(|_| ()).unwrap_err().to_string()
    }
}

#[test]
fn recording_synthetic_loads_and_interpolates() {
    let synthetic = Synthetic::new("ok");
    let recording = synthetic.open().unwrap();
    assert_eq!(recording.len(), 3);
    assert_eq!(recording.stats().shared_colour, 0);
    for (i, pose) in recording.poses().iter().enumerate() {
        let x = 0.03 * i as f64;
        assert!(pose.abs_diff_eq(DAffine3::from_translation(DVec3::new(x, 0.0, 0.0)), 1e-12), "{i}: {pose:?}");
    }
    let frame = recording.frame(1).unwrap();
    assert_eq!(frame.intrinsics.width, 4);
    assert_eq!(frame.color[4 + 2], [2, 1, 7], "row 1, column 2");
    assert_eq!(frame.depth[0], 0.0, "0 stays missing");
    assert_eq!(frame.depth[4 + 2], 3000.0 / 5000.0);

    // intrinsics.json's depth scale wins over the options'; the options' applies without it.
    synthetic.write("intrinsics.json", r#"{"width":4,"height":3,"fx":3,"fy":3,"cx":1.5,"cy":1,"depth_scale":1000}"#);
    let options = RecordingOptions { depth_scale: Some(2000.0), ..RecordingOptions::default() };
    let frame = Recording::open(&synthetic.dir, &options).unwrap().frame(1).unwrap();
    assert_eq!(frame.depth[4 + 2], 3.0);
    std::fs::remove_file(synthetic.dir.join("intrinsics.json")).unwrap();
    let intrinsics = Intrinsics { width: 4, height: 3, fx: 3.0, fy: 3.0, cx: 1.5, cy: 1.0 };
    let options = RecordingOptions { intrinsics: Some(intrinsics), depth_scale: Some(2000.0), ..options };
    let frame = Recording::open(&synthetic.dir, &options).unwrap().frame(1).unwrap();
    assert_eq!(frame.depth[4 + 2], 1.5);
}

#[test]
fn recording_without_groundtruth_has_identity_poses() {
    let synthetic = Synthetic::new("no_groundtruth");
    std::fs::remove_file(synthetic.dir.join("groundtruth.txt")).unwrap();
    let recording = synthetic.open().unwrap();
    assert_eq!(recording.len(), 3);
    assert!(!recording.has_groundtruth());
    assert!(recording.poses().iter().all(|pose| *pose == DAffine3::IDENTITY));
    assert_eq!(recording.frame(2).unwrap().camera_to_world, DAffine3::IDENTITY);
}

#[test]
fn recording_skips_frames_without_partners() {
    let synthetic = Synthetic::new("skips");
    // A depth frame 25 ms from any colour frame, and one 40 ms after the trajectory's end.
    synthetic.write(
        "depth.txt",
        "1.000000 depth/1.000000.png\n1.030000 depth/1.030000.png\n1.080000 depth/1.060000.png\n\
         1.130000 depth/1.060000.png\n",
    );
    synthetic.write(
        "rgb.txt",
        "1.005000 rgb/1.005000.png\n1.035000 rgb/1.035000.png\n1.055000 rgb/1.065000.png\n\
         1.125000 rgb/1.065000.png\n",
    );
    let recording = synthetic.open().unwrap();
    assert_eq!(recording.timestamps(), &[1.0, 1.03]);
    let stats = recording.stats();
    assert_eq!((stats.depth_frames, stats.without_colour, stats.without_pose), (4, 1, 1));

    // Nothing left is an error, not an empty recording.
    synthetic.write("rgb.txt", "5.0 rgb/1.005000.png\n");
    let error = synthetic.open_err();
    assert!(error.starts_with("no usable frame: of 4 depth frames, 4 have no colour frame"), "{error}");
}

#[test]
fn recording_missing_rgb_txt_is_named() {
    let synthetic = Synthetic::new("missing");
    std::fs::remove_file(synthetic.dir.join("rgb.txt")).unwrap();
    assert_eq!(synthetic.open_err(), "rgb.txt: no such file");
}

#[test]
fn recording_bad_lines_name_file_and_line() {
    let synthetic = Synthetic::new("bad_lines");
    synthetic.write("depth.txt", "# depth maps\n1.000000 depth/1.000000.png\n1.03O000 depth/1.030000.png\n");
    assert_eq!(synthetic.open_err(), "depth.txt line 3: timestamp `1.03O000` is not a number");

    let synthetic = Synthetic::new("bad_groundtruth");
    let text = std::fs::read_to_string(synthetic.dir.join("groundtruth.txt")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    lines[4] = "1.0100 0.0100 0 0 0 0 1".to_owned();
    synthetic.write("groundtruth.txt", &lines.join("\n"));
    assert_eq!(synthetic.open_err(), "groundtruth.txt line 5: expected 8 numbers, got 7");
    lines[4] = "1.0100 0.0100 0 0 0 0 0.5 1".to_owned();
    synthetic.write("groundtruth.txt", &lines.join("\n"));
    let error = synthetic.open_err();
    assert!(error.starts_with("groundtruth.txt line 5: quaternion (qx qy qz qw) has norm 1.118"), "{error}");
}

#[test]
fn recording_wrong_image_size_is_named() {
    let synthetic = Synthetic::new("wrong_size");
    image::RgbImage::new(5, 3).save(synthetic.dir.join("rgb/1.035000.png")).unwrap();
    let recording = synthetic.open().unwrap();
    recording.frame(0).unwrap();
    let error = recording.frame(1).unwrap_err().to_string();
    assert_eq!(error, "rgb/1.035000.png: image is 5x3, intrinsics say 4x3");

    // 8-bit depth is not TUM depth.
    image::GrayImage::new(4, 3).save(synthetic.dir.join("depth/1.060000.png")).unwrap();
    let error = recording.frame(2).unwrap_err().to_string();
    assert_eq!(error, "depth/1.060000.png: expected a 16-bit grayscale PNG, got L8");
    std::fs::remove_file(synthetic.dir.join("depth/1.060000.png")).unwrap();
    assert_eq!(recording.frame(2).unwrap_err().to_string(), "depth/1.060000.png: no such file");
}

#[test]
fn recording_bad_intrinsics_json_names_the_field() {
    let synthetic = Synthetic::new("bad_intrinsics");
    synthetic.write("intrinsics.json", r#"{"width":4,"height":3,"fx":3,"fy":3,"cx":1.5,"cy":1,"k1":0.26}"#);
    let error = synthetic.open_err();
    assert!(error.starts_with("intrinsics.json: unknown field `k1`"), "{error}");
    synthetic.write("intrinsics.json", r#"{"width":4,"height":3,"fx":-3,"fy":3,"cx":1.5,"cy":1}"#);
    assert_eq!(synthetic.open_err(), "intrinsics.json: fx must be positive and finite, got -3");

    // Overrides are checked too.
    std::fs::remove_file(synthetic.dir.join("intrinsics.json")).unwrap();
    let options = RecordingOptions { depth_scale: Some(0.0), ..RecordingOptions::default() };
    let error = Recording::open(&synthetic.dir, &options).map(|_| ()).unwrap_err().to_string();
    assert_eq!(error, "recording options: depth_scale must be positive and finite, got 0");
}
