//! Issue 19 item 8: the renderer does not care where the origin is. A whole scene (meshes,
//! light, camera) moved and turned anywhere within 100 km of the origin renders the same
//! indirect image as at the origin, because everything the GPU sees is relative to the scene's
//! floating origin (`Scene::origin`), composed in f64 on the CPU.
//!
//! Before the floating origin, `cornell_bunny_small.json` at 96², occlusion on, moved by
//! (1000, 0, 1000) m was 26 % rel RMSE from the original and by 100 km 58 %.

use super::{fixture, gpu};
use glam::{DMat4, DVec3, Vec3};
use proptest::prelude::*;
use relume::gpu::Gpu;
use relume::image::{LinearImage, relative_rmse};
use relume::renderer::{Method, Renderer};
use relume::scene::{OcclusionSetting, ScaleDescription, Scene, SceneDescription, TransformDescription};
use std::sync::OnceLock;

/// Image side, pixels: the issue's measurement.
const SIDE: u32 = 96;

/// Largest relative RMSE between the moved and the original indirect image: the issue's
/// target. Measured on lavapipe: a pure move gives a bit-identical image (0, the local
/// coordinates come out the same), a turn about the vertical 0.05-0.8 % at any distance (also
/// 332 m away): the rotated vertices, light direction and depth range round differently in f32,
/// which flips the triangle some silhouette and RSM texels see. A millimetre lost at 100 km
/// (f32 spacing 7.8 mm) gave 58 % before the floating origin.
const TOLERANCE: f64 = 0.01;

fn description() -> SceneDescription {
    let text = std::fs::read_to_string(fixture("scenes/cornell_bunny_small.json")).expect("fixture");
    let mut description = SceneDescription::from_json_str(&text).expect("parses");
    description.settings.occlusion = OcclusionSetting::Disks;
    description
}

/// `description` with every mesh, the light and the camera moved by `rotation` about the
/// vertical, then `translation`: the anchor places the meshes, and the light's and camera's
/// positions and directions are mapped by the same f64 matrix.
///
/// The turn is about the vertical because the spot light's RSM has no roll of its own: its
/// grid's up is world +Y, so a tilt of the whole scene also turns the RSM grid against the
/// scene and resamples the VALs, a different image that is no precision loss.
fn moved(description: &SceneDescription, translation: DVec3, yaw_deg: f32) -> SceneDescription {
    let anchor = TransformDescription {
        translation: translation.to_array(),
        rotation_deg: [0.0, yaw_deg, 0.0],
        scale: ScaleDescription::Uniform(1.0),
    };
    let m: DMat4 = anchor.to_matrix();
    let point = |p: [f64; 3]| m.transform_point3(DVec3::from_array(p)).to_array();
    let vector = |v: [f32; 3]| m.transform_vector3(Vec3::from_array(v).as_dvec3()).as_vec3().to_array();
    let mut d = description.clone();
    assert!(d.anchor.is_none(), "the fixture has no anchor of its own");
    d.anchor = Some(anchor);
    let light = d.light.as_mut().expect("the fixture has a spot light");
    (light.position, light.direction) = (point(light.position), vector(light.direction));
    let camera = &mut d.camera;
    (camera.position, camera.target, camera.up) = (point(camera.position), point(camera.target), vector(camera.up));
    d
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

fn error_when_moved(gpu: &Gpu, translation: DVec3, yaw_deg: f32) -> f64 {
    let (image, origin) = indirect(gpu, &moved(&description(), translation, yaw_deg));
    // The floating origin follows the scene: it sits at the moved scene's centre.
    assert!(origin.distance(translation) < 5.0, "origin {origin} for a scene moved to {translation}");
    let error = relative_rmse(&image, original(gpu));
    eprintln!("moved by {translation} m, turned {yaw_deg}°: indirect rel RMSE {error:.2e}");
    error
}

/// The issue's three measurements: (1, 0, 1) km, 10 km and 100 km along the same diagonal.
#[test]
fn the_issues_far_scenes_render_as_at_the_origin() {
    let gpu = gpu();
    for km in [1.0, 10.0 / std::f64::consts::SQRT_2, 100.0 / std::f64::consts::SQRT_2] {
        let translation = DVec3::new(km * 1e3, 0.0, km * 1e3);
        let error = error_when_moved(&gpu, translation, 0.0);
        assert!(error <= TOLERANCE, "moved by {translation} m: indirect rel RMSE {error} > {TOLERANCE}");
    }
}

proptest! {
    // Each case loads the scene and renders 96² with occlusion on lavapipe (a few seconds).
    // A fixed seed: the same 6 cases every run (turns measured 0.05-0.6 % with it, 0.3-0.8 %
    // with random seeds, against the 1 % bound).
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
        yaw_deg in 0.0f32..360.0,
    ) {
        let direction = DVec3::from_array(direction).try_normalize().unwrap_or(DVec3::X);
        let translation = direction * distance;
        let error = error_when_moved(&gpu(), translation, yaw_deg);
        prop_assert!(error <= TOLERANCE, "moved by {} m, turned {}°: rel RMSE {} > {}", translation, yaw_deg, error, TOLERANCE);
    }
}
