//! Open3D / Redwood recordings: the `redwood_livingroom1` fixture (5 frames of Open3D's
//! `SampleRedwoodRGBDImages`), read by its files, replayed, and malformed copies of it.

use std::path::{Path, PathBuf};

use glam::{DAffine3, DMat4, Mat4, Vec3};
use relume::rgbd::Intrinsics;
use relume::rgbd::recording::{Layout, Recording, RecordingOptions};

use super::{fixture, gpu, scratch};

fn fixture_dir() -> PathBuf {
    fixture("rgbd/redwood_livingroom1")
}

fn open(dir: &Path) -> Recording {
    Recording::open(dir, &RecordingOptions::default()).unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
}

/// The matrices of `trajectory.log`, read independently of relume's parser: every 5 lines, the
/// last 4 as rows.
fn trajectory_matrices(file: &Path) -> Vec<Mat4> {
    let text = std::fs::read_to_string(file).unwrap();
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines
        .chunks(5)
        .map(|entry| {
            let rows: Vec<f32> =
                entry[1..].iter().flat_map(|l| l.split_whitespace().map(|v| v.parse::<f32>().unwrap())).collect();
            Mat4::from_cols_slice(&rows).transpose()
        })
        .collect()
}

#[test]
fn redwood_fixture_is_detected_and_read() {
    let dir = fixture_dir();
    let recording = open(&dir);
    assert_eq!(recording.layout(), Layout::Redwood);
    assert_eq!(recording.len(), 5);
    assert!(recording.has_groundtruth());
    assert_eq!(
        *recording.intrinsics(),
        Intrinsics { width: 640, height: 480, fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5 }
    );
    assert_eq!(recording.depth_scale(), 1000.0);
    // No timestamps in the layout: frame i at i / 30 s.
    assert_eq!(recording.timestamps()[3], 0.1);

    let matrices = trajectory_matrices(&dir.join("trajectory.log"));
    assert_eq!(matrices.len(), 5);
    for (i, (pose, matrix)) in recording.poses().iter().zip(&matrices).enumerate() {
        // The quaternion round trip of a rotation orthonormal to 1.7e-6 (SOURCE.md) moves
        // entries by a few 1e-6.
        assert!(DMat4::from(*pose).as_mat4().abs_diff_eq(*matrix, 1e-5), "frame {i}: {pose:?} vs {matrix:?}");
    }

    let pixels = 640 * 480;
    for i in 0..recording.len() {
        let frame = recording.frame(i).unwrap();
        assert_eq!((frame.color.len(), frame.depth.len()), (pixels, pixels));
        let valid: Vec<f32> = frame.depth.iter().copied().filter(|&d| d != 0.0).collect();
        let (min, max) = valid.iter().fold((f32::MAX, f32::MIN), |(lo, hi), &d| (lo.min(d), hi.max(d)));
        // SOURCE.md: nonzero 955..2702 mm over all frames, 12.4-13.0 % zero (rounded: frame 0
        // has 13.04 %).
        assert!(min >= 0.955 && max <= 2.702, "frame {i}: depth range {min}..{max} m");
        let zero = 1.0 - valid.len() as f32 / pixels as f32;
        assert!((0.12..0.135).contains(&zero), "frame {i}: zero fraction {zero}");
        let mean: Vec3 =
            frame.color.iter().map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)).sum::<Vec3>() / pixels as f32;
        assert!(mean.min_element() > 20.0 && mean.max_element() < 235.0, "frame {i}: mean colour {mean}");
    }
}

/// A scratch copy of the fixture (`skip` files left out) to break.
fn copy_fixture(name: &str, skip: &[&str]) -> PathBuf {
    let dir = scratch(&format!("redwood_{name}"));
    let from = fixture_dir();
    for sub in ["color", "depth"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    for entry in ["camera_primesense.json", "rgbd.match", "trajectory.log"]
        .into_iter()
        .map(PathBuf::from)
        .chain((0..5).flat_map(|i| [format!("color/{i:05}.jpg"), format!("depth/{i:05}.png")].map(PathBuf::from)))
    {
        if !skip.contains(&entry.to_str().unwrap()) {
            std::fs::copy(from.join(&entry), dir.join(&entry)).unwrap();
        }
    }
    dir
}

fn open_err(dir: &Path) -> String {
    Recording::open(dir, &RecordingOptions::default()).map(|_| ()).unwrap_err().to_string()
}

#[test]
fn redwood_without_optional_files_falls_back() {
    // No rgbd.match: the folders pair by name; no trajectory: identity; no JSON: the options'.
    let dir = copy_fixture("bare", &["rgbd.match", "trajectory.log", "camera_primesense.json"]);
    let k = Intrinsics { width: 640, height: 480, fx: 500.0, fy: 500.0, cx: 320.0, cy: 240.0 };
    let options = RecordingOptions { intrinsics: Some(k), depth_scale: Some(2000.0), ..Default::default() };
    let recording = Recording::open(&dir, &options).unwrap();
    assert_eq!((recording.len(), *recording.intrinsics()), (5, k));
    assert!(!recording.has_groundtruth());
    assert!(recording.poses().iter().all(|p| *p == DAffine3::IDENTITY));
    let scaled = recording.frame(2).unwrap();
    let reference = open(&fixture_dir()).frame(2).unwrap();
    assert_eq!(scaled.color, reference.color, "the same files, paired by name");
    let i = reference.depth.iter().position(|&d| d > 0.0).unwrap();
    assert_eq!(scaled.depth[i], reference.depth[i] / 2.0);
}

#[test]
fn redwood_errors_name_the_file_and_field() {
    let dir = copy_fixture("broken", &["depth/00004.png", "rgbd.match"]);
    let error = open_err(&dir);
    assert!(
        error.ends_with("depth/ has 4 PNGs and color/ 5 images; without rgbd.match they must pair up one to one"),
        "{error}"
    );

    let dir = copy_fixture("short_trajectory", &[]);
    let text = std::fs::read_to_string(dir.join("trajectory.log")).unwrap();
    let four: Vec<&str> = text.lines().take(20).collect();
    std::fs::write(dir.join("trajectory.log"), four.join("\n")).unwrap();
    assert_eq!(open_err(&dir), "trajectory.log line 20: has 4 poses for 5 frames");

    std::fs::write(dir.join("trajectory.log"), text.replacen("0.0 0.0 0.0 1.0", "0.0 0.0 0.5 1.0", 1)).unwrap();
    assert!(open_err(&dir).starts_with("trajectory.log line 5: last matrix row must be 0 0 0 1"), "{}", open_err(&dir));

    std::fs::copy(fixture_dir().join("trajectory.log"), dir.join("trajectory.log")).unwrap();
    std::fs::write(
        dir.join("camera_primesense.json"),
        r#"{"width": 640, "height": 480, "intrinsic_matrix": [525, 0]}"#,
    )
    .unwrap();
    assert!(open_err(&dir).starts_with("camera_primesense.json: invalid length 2"), "{}", open_err(&dir));

    // A colour JPEG that is not one is named when its frame is read.
    std::fs::copy(fixture_dir().join("camera_primesense.json"), dir.join("camera_primesense.json")).unwrap();
    std::fs::write(dir.join("color/00001.jpg"), b"not a jpeg").unwrap();
    let error = open(&dir).frame(1).unwrap_err().to_string();
    assert!(error.starts_with("color/00001.jpg: cannot decode JPG"), "{error}");

    let empty = scratch("redwood_not_a_recording");
    let error = open_err(&empty);
    assert!(error.contains("not a recording: a directory with neither rgb.txt/depth.txt"), "{error}");
}

/// `relume replay` on the Redwood frames: the bunny, placed 1.2 m in front of the first camera,
/// is lit by the room's VALs in every frame and drawn over the camera image.
#[test]
fn redwood_replays() {
    let dir = fixture_dir();
    let first = open(&dir).poses()[0];
    let anchor = first.transform_point3(glam::DVec3::new(0.0, 0.1, 1.2));
    let scene_dir = scratch("redwood_replay_scene");
    let bunny = fixture("meshes/stanford_bunny/stanford-bunny.obj");
    let scene = format!(
        r#"{{"meshes": [{{"obj": {bunny:?}, "transform": {{"rotation_deg": [180, 0, 0], "scale": 1.3}},
             "sparse_points": 512, "material": {{"diffuse": [0.8, 0.8, 0.8]}}}}],
           "anchor": {{"translation": [{}, {}, {}]}},
           "camera": {{"position": [0, 0, 1], "target": [0, 0, 0], "fov_y_deg": 49, "width": 160, "height": 120}},
           "settings": {{"rgbd": {{"grid_step": 16, "radiance_scale": 3.0}}}}}}"#,
        anchor.x, anchor.y, anchor.z
    );
    std::fs::write(scene_dir.join("scene.json"), scene).unwrap();
    let out = scratch("redwood_replay_out");
    let options = relume::mr::replay::ReplayOptions {
        recording: dir,
        recording_options: RecordingOptions::default(),
        scene: scene_dir.join("scene.json"),
        out: out.clone(),
        size: Some((160, 120)),
        frames: None,
        accumulate: None,
        exposure: 1.0,
        progress: false,
        budget_ms: None,
    };
    let summary = relume::mr::replay::replay(&gpu(), &options).unwrap();
    assert_eq!(summary.frames, 5);
    // 40x30 grid cells, 12-13 % of depth missing: about 1,000 VALs.
    assert!(summary.vals_per_frame.iter().all(|&n| n > 800), "{:?}", summary.vals_per_frame);
    for i in 0..5 {
        let composited = image::open(out.join(format!("composited/{i:04}.png"))).unwrap().into_rgb8();
        let indirect = image::open(out.join(format!("indirect/{i:04}.png"))).unwrap().into_rgb8();
        let lit = indirect.pixels().filter(|p| p.0.iter().any(|&c| c > 0)).count();
        assert!(lit > 200, "frame {i}: the bunny receives indirect light at {lit} pixels");
        assert_eq!(composited.dimensions(), (160, 120));
    }
    // The camera moves little: the object's irradiance changes smoothly.
    assert!(summary.mean_irradiance_change < 0.2, "{}", summary.mean_irradiance_change);
}
