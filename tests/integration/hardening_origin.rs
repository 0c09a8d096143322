//! The renderer does not care where the origin is. A whole scene (meshes,
//! light, camera, and an RGB-D recording's poses) moved and turned anywhere within 100 km of the
//! origin renders the same indirect image as at the origin, because everything the GPU sees is
//! relative to the scene's floating origin (`Scene::origin`), composed in f64 on the CPU.
//!
//! Before the floating origin, `cornell_bunny_small.json` at 96², occlusion on, moved by
//! (1000, 0, 1000) m was 26 % rel RMSE from the original and by 100 km 58 %.

use super::{fixture, gpu, scratch};
use glam::{DAffine3, DMat4, DQuat, DVec3, EulerRot, Vec3};
use proptest::prelude::*;
use relume::gpu::Gpu;
use relume::image::{LinearImage, relative_rmse};
use relume::mr::{MrOptions, MrRenderer};
use relume::renderer::{Method, Renderer};
use relume::rgbd::recording::{Recording, RecordingOptions};
use relume::scene::{OcclusionSetting, ScaleDescription, Scene, SceneDescription, TransformDescription};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Image side, pixels: the issue's measurement.
const SIDE: u32 = 96;

/// Largest relative RMSE between the moved and the original indirect image: the issue's
/// target. Measured on lavapipe: a pure move gives a bit-identical image (0, the local
/// coordinates come out the same), a turn about the vertical 0.13-0.47 % and a tilt
/// 0.21-0.65 %, the same at any distance, the origin included: what is left is the disc
/// occluders' dependence on the world axes (without occlusion turns give 1e-6, see the tilt
/// test below), not precision. A millimetre lost at 100 km (f32 spacing 7.8 mm) gave 58 %
/// before the floating origin.
const TOLERANCE: f64 = 0.01;

fn read_description(name: &str) -> SceneDescription {
    let text = std::fs::read_to_string(fixture(&format!("scenes/{name}.json"))).expect("fixture");
    SceneDescription::from_json_str(&text).expect("parses")
}

fn description() -> SceneDescription {
    let mut description = read_description("cornell_bunny_small");
    description.settings.tuning.visibility = Some(OcclusionSetting::Disks);
    description
}

/// `description` with every mesh, the light and the camera moved by `rotation` about the
/// user's origin, then by `translation`; returns it with that move as an f64 transform (which
/// the test applies to a recording's poses too). The anchor (composed with the scene's own, if
/// any) places the meshes, and the light's and camera's positions and directions are mapped by
/// the same f64 matrix, the light's `up` too (its default when it has none), so the RSM grid
/// turns with the scene.
fn moved(description: &SceneDescription, translation: DVec3, rotation: DQuat) -> (SceneDescription, DAffine3) {
    let old = description.anchor.as_ref().map_or(DMat4::IDENTITY, TransformDescription::to_matrix);
    let (scale, old_rotation, old_translation) = old.to_scale_rotation_translation();
    assert!(scale.abs_diff_eq(DVec3::ONE, 1e-9), "the fixture's anchor is rigid");
    let (x, y, z) = (rotation * old_rotation).to_euler(EulerRot::XYZ);
    let anchor = TransformDescription {
        translation: (rotation * old_translation + translation).to_array(),
        rotation_deg: [x, y, z].map(|a| a.to_degrees() as f32),
        scale: ScaleDescription::Uniform(1.0),
    };
    // The move as the renderer will place the meshes: the new anchor after the old one undone
    // (the angles are f32 degrees, so this is `rotation` to within f32).
    let m = DAffine3::from_mat4(anchor.to_matrix() * old.inverse());
    let point = |p: [f64; 3]| m.transform_point3(DVec3::from_array(p)).to_array();
    let vector = |v: [f32; 3]| m.transform_vector3(Vec3::from_array(v).as_dvec3()).as_vec3().to_array();
    let mut d = description.clone();
    d.anchor = Some(anchor);
    if let Some(light) = d.light.as_mut() {
        let up = light.up.unwrap_or_else(|| light.to_spot_light(DVec3::ZERO).up.to_array());
        (light.position, light.direction, light.up) =
            (point(light.position), vector(light.direction), Some(vector(up)));
    }
    let camera = &mut d.camera;
    (camera.position, camera.target, camera.up) = (point(camera.position), point(camera.target), vector(camera.up));
    (d, m)
}

fn indirect(gpu: &Gpu, description: &SceneDescription) -> (LinearImage, DVec3) {
    let scene = Scene::from_description(description, &fixture("scenes")).expect("loads");
    let mut renderer = Renderer::new(gpu, &scene).expect("renderer");
    let frame = renderer.render(gpu, Method::Sparse, SIDE, SIDE).expect("renders");
    (frame.indirect, scene.origin)
}

/// The fixture at the origin, rendered once for every case.
fn original(gpu: &Gpu) -> &'static LinearImage {
    static ORIGINAL: OnceLock<LinearImage> = OnceLock::new();
    ORIGINAL.get_or_init(|| indirect(gpu, &description()).0)
}

fn error_when_moved(gpu: &Gpu, translation: DVec3, rotation: DQuat) -> f64 {
    let (image, origin) = indirect(gpu, &moved(&description(), translation, rotation).0);
    // The floating origin follows the scene: it sits at the moved scene's centre.
    assert!(origin.distance(translation) < 5.0, "origin {origin} for a scene moved to {translation}");
    let error = relative_rmse(&image, original(gpu));
    let (axis, angle) = rotation.to_axis_angle();
    eprintln!(
        "moved by {translation} m, turned {:.1}° about {axis:.3}: indirect rel RMSE {error:.2e}",
        angle.to_degrees()
    );
    error
}

/// The issue's three measurements: (1, 0, 1) km, 10 km and 100 km along the same diagonal.
#[test]
fn the_issues_far_scenes_render_as_at_the_origin() {
    let gpu = gpu();
    for km in [1.0, 10.0 / std::f64::consts::SQRT_2, 100.0 / std::f64::consts::SQRT_2] {
        let translation = DVec3::new(km * 1e3, 0.0, km * 1e3);
        let error = error_when_moved(&gpu, translation, DQuat::IDENTITY);
        assert!(error <= TOLERANCE, "moved by {translation} m: indirect rel RMSE {error} > {TOLERANCE}");
    }
}

// ---------------------------------------------------------------------------------------------
// An RGB-D recording far from the origin
// ---------------------------------------------------------------------------------------------

/// The mixed-reality fixture (`mr_bunny.json`: the bunny anchored in the TUM fr1/xyz room, no
/// spot light), lit by the recording's first frame, as `replay.rs` renders it: 160x120, one VAL
/// per 16x16 depth pixels, no differential rendering, no environment; `occlusion` as given (the
/// fixture's `auto` is disc occluders for the bunny).
fn recording_description(occlusion: OcclusionSetting) -> SceneDescription {
    let mut description = read_description("mr_bunny");
    description.settings.rgbd.grid_step = 16;
    description.settings.mr.differential = false;
    description.settings.tuning.visibility = Some(occlusion);
    description
}

const RECORDING: &str = "recordings/tum_fr1_xyz";

/// The fixture recording with every ground-truth pose moved by `m`, in a scratch directory
/// (its frame lists name the fixture's images by absolute path). The moved poses are written
/// with every digit an f64 holds (Rust's shortest round-trip form).
fn moved_recording(name: &str, m: &DAffine3) -> PathBuf {
    let source = fixture(RECORDING);
    let dir = scratch(name);
    for list in ["rgb.txt", "depth.txt"] {
        let text = std::fs::read_to_string(source.join(list)).expect("frame list");
        let absolute: String = text
            .lines()
            .map(|line| match line.split_whitespace().collect::<Vec<_>>()[..] {
                [t, file] if !line.starts_with('#') => format!("{t} {}\n", source.join(file).display()),
                _ => format!("{line}\n"),
            })
            .collect();
        std::fs::write(dir.join(list), absolute).expect("writes");
    }
    let turn = DQuat::from_mat3(&m.matrix3).normalize();
    let text = std::fs::read_to_string(source.join("groundtruth.txt")).expect("ground truth");
    let mut moved = String::new();
    for line in text.lines() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if line.starts_with('#') || fields.len() != 8 {
            moved.push_str(line);
        } else {
            let v: Vec<f64> = fields[1..].iter().map(|f| f.parse().expect("number")).collect();
            let t = m.transform_point3(DVec3::new(v[0], v[1], v[2]));
            let q = turn * DQuat::from_xyzw(v[3], v[4], v[5], v[6]).normalize();
            moved.push_str(&format!("{} {} {} {} {} {} {} {}", fields[0], t.x, t.y, t.z, q.x, q.y, q.z, q.w));
        }
        moved.push('\n');
    }
    std::fs::write(dir.join("groundtruth.txt"), moved).expect("writes");
    dir
}

/// The indirect image of the recording's first frame (read from `recording`, so through the
/// TUM reader and its pose interpolation) on `description`, and the scene's origin.
fn mr_indirect(gpu: &Gpu, description: &SceneDescription, recording: &Path) -> (LinearImage, DVec3) {
    let scene = Scene::from_description(description, &fixture("scenes")).expect("loads");
    let frame = Recording::open(recording, &RecordingOptions::default()).expect("opens").frame(0).expect("frame 0");
    let options = MrOptions { width: 160, height: 120, exposure: 1.0, accumulate: None };
    let mut mr = MrRenderer::new(gpu, &scene, options).expect("renderer");
    (mr.render_frame(gpu, &frame).expect("renders").indirect, scene.origin)
}

/// The recording scene at the origin with disc occluders (`Disks`) or without (`Off`),
/// rendered once for every case.
fn original_recording(gpu: &Gpu, occlusion: OcclusionSetting) -> &'static LinearImage {
    static DISKS: OnceLock<LinearImage> = OnceLock::new();
    static OFF: OnceLock<LinearImage> = OnceLock::new();
    let cell = if occlusion == OcclusionSetting::Off { &OFF } else { &DISKS };
    cell.get_or_init(|| mr_indirect(gpu, &recording_description(occlusion), &fixture(RECORDING)).0)
}

fn recording_error_when_moved(gpu: &Gpu, occlusion: OcclusionSetting, translation: DVec3, rotation: DQuat) -> f64 {
    let (description, m) = moved(&recording_description(occlusion), translation, rotation);
    let recording = moved_recording("hardening_origin_recording", &m);
    let (image, origin) = mr_indirect(gpu, &description, &recording);
    assert!(origin.distance(translation) < 5.0, "origin {origin} for a scene moved to {translation}");
    let covered = (0..image.pixels.len()).filter(|&i| image.covered(i)).count();
    assert!(covered > 100, "the bunny is in view: {covered} pixels");
    let error = relative_rmse(&image, original_recording(gpu, occlusion));
    let (axis, angle) = rotation.to_axis_angle();
    eprintln!(
        "recording ({occlusion:?}) moved by {translation} m, turned {:.1}° about {axis:.3}: indirect rel RMSE {error:.2e}",
        angle.to_degrees()
    );
    error
}

/// A move of `distance` m along `direction` from proptest's numbers (a zero direction stands
/// for +X).
fn offset(direction: [f64; 3], distance: f64) -> DVec3 {
    DVec3::from_array(direction).try_normalize().unwrap_or(DVec3::X) * distance
}

/// A unit axis and an angle from proptest's numbers (a zero axis stands for +Y).
fn turn(axis: [f64; 3], angle_deg: f64) -> DQuat {
    let axis = DVec3::from_array(axis).try_normalize().unwrap_or(DVec3::Y);
    DQuat::from_axis_angle(axis, angle_deg.to_radians())
}

proptest! {
    // Each case loads the scene and renders 96² with occlusion on lavapipe (a few seconds).
    // A fixed seed: the same 6 cases every run (turns about the vertical measured 0.13-0.47 %
    // with it, the same at any distance, against the 1 % bound; 0.21-0.99 % before the
    // interpolation ignored rounding-level weights, see the tilt test below).
    #![proptest_config(ProptestConfig {
        cases: 6,
        failure_persistence: None,
        rng_seed: proptest::test_runner::RngSeed::Fixed(19),
        ..ProptestConfig::default()
    })]

    /// Anywhere within 100 km (any direction, any distance), turned by any angle about the
    /// vertical.
    #[test]
    fn a_scene_moved_anywhere_within_100_km_renders_as_at_the_origin(
        direction in prop::array::uniform3(-1.0f64..1.0),
        distance in 0.0f64..100e3,
        yaw_deg in 0.0f64..360.0,
    ) {
        let translation = offset(direction, distance);
        let error = error_when_moved(&gpu(), translation, turn([0.0, 1.0, 0.0], yaw_deg));
        prop_assert!(error <= TOLERANCE, "moved by {} m, turned {}°: rel RMSE {} > {}", translation, yaw_deg, error, TOLERANCE);
    }

    /// Anywhere within 100 km, turned about any axis (tilts): the light's `up` turns with the
    /// scene, so the RSM grid stays put on it. Measured with this seed 0.21-0.65 % (the first
    /// case 0.21 %; a 273° turn about -Z at the origin 0.08 %), the same at any distance; with
    /// occlusion off 1e-6 (the RSM's VALs, the gathered light and the sparse and vertex lights
    /// agree to 1e-6), but for one pixel where the short box meets the floor, whose depth tie
    /// the turn's rounding decides (0.82 % in three of the twelve cases of both tests). What is
    /// left with occlusion is the disc occluders' world-axis dependence (see the recording test
    /// below).
    ///
    /// Before `light.up` the grid turned against the scene: the first case 2.02 %. Before the
    /// interpolation's `twin::FACING_EPSILON` and `twin::BOUND_WEIGHT_FLOOR`, 0.50-1.08 % (the
    /// 273° turn 1.08 %), 0.8-1.1 % without occlusion: a vertex's neighbours on a perpendicular
    /// surface (cosine exactly 0 at the origin, a few 1e-8 either side turned) and neighbours at
    /// the support radius (weight 0, or 1e-17 turned) weighed nothing or a little, which
    /// switched the all-zero-weight fallback and the largest-bound rule: 15-30 % on a few
    /// pixels of the box's sides and the walls.
    #[test]
    fn a_scene_moved_and_tilted_renders_as_at_the_origin(
        direction in prop::array::uniform3(-1.0f64..1.0),
        distance in 0.0f64..100e3,
        axis in prop::array::uniform3(-1.0f64..1.0),
        angle_deg in 0.0f64..360.0,
    ) {
        let translation = offset(direction, distance);
        let rotation = turn(axis, angle_deg);
        let error = error_when_moved(&gpu(), translation, rotation);
        prop_assert!(error <= TOLERANCE, "moved by {} m, turned {:?}: rel RMSE {} > {}", translation, rotation, error, TOLERANCE);
    }
}

proptest! {
    // Each case loads the bunny, reads the recording's text files and renders its first frame
    // at 160x120 on lavapipe twice (under a second each). A fixed seed: the same 6 cases every
    // run. With the readers' f32 pose translations (before this test) the first case gave
    // 43 %, the others 53-64 %, and the shrunk failure, a pure move of 80.7 km, 45 %.
    #![proptest_config(ProptestConfig {
        cases: 6,
        failure_persistence: None,
        rng_seed: proptest::test_runner::RngSeed::Fixed(19),
        ..ProptestConfig::default()
    })]

    /// The recording scene (the anchored bunny and every ground-truth pose of the recording)
    /// anywhere within 100 km, turned about any axis: the frame's VALs, its pinhole camera and
    /// the bunny move together, so the indirect image is the original's.
    ///
    /// Turned, without occlusion (measured 1e-5: the turn's f32 rounding); moved without a
    /// turn, with the fixture's disc occluders (measured 2e-7). Disc occlusion itself is not
    /// invariant under turns (the light sphere's radius is the largest per-axis standard
    /// deviation, and occluders overlap as squares in a tangent frame picked from the world
    /// axes): the same turns give 0.4-3 % with it at any distance, the origin included.
    #[test]
    fn a_recording_moved_anywhere_within_100_km_renders_as_at_the_origin(
        direction in prop::array::uniform3(-1.0f64..1.0),
        distance in 0.0f64..100e3,
        axis in prop::array::uniform3(-1.0f64..1.0),
        angle_deg in 0.0f64..360.0,
    ) {
        let translation = offset(direction, distance);
        let rotation = turn(axis, angle_deg);
        let error = recording_error_when_moved(&gpu(), OcclusionSetting::Off, translation, rotation);
        prop_assert!(error <= TOLERANCE, "moved by {} m, turned {:?}: rel RMSE {} > {}", translation, rotation, error, TOLERANCE);
        let error = recording_error_when_moved(&gpu(), OcclusionSetting::Disks, translation, DQuat::IDENTITY);
        prop_assert!(error <= TOLERANCE, "moved by {} m with disc occluders: rel RMSE {} > {}", translation, error, TOLERANCE);
    }
}
