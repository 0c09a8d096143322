//! relume's integration tests: one binary (as ripgrep does), one module per concern. GPU tests
//! run on whatever adapter wgpu finds; in CI that is Mesa's lavapipe.

mod accuracy;
mod backends;
mod bench;
mod bounce;
mod cli;
mod clusters;
mod compact;
mod docs;
mod fake_backend;
mod frame;
mod fuzz;
mod gltf;
mod hardening;
mod hardening_origin;
mod ism;
mod layers;
mod layout;
mod light_rsms;
mod many_lights;
mod mcap;
mod mr_differential;
mod recording;
mod redwood;
mod reliability;
mod replay;
mod rgbd;
mod router;
mod rsm;
mod scale;
mod service;
mod stream_mr;
mod stream_visibility;
mod synthetic;
mod textures;
mod twins;
mod workers;

use relume::gpu::Gpu;
use relume::scene::Scene;
use std::path::PathBuf;

pub fn fixture(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures").join(path)
}

pub fn load_scene(name: &str) -> Scene {
    let path = fixture(&format!("scenes/{name}.json"));
    Scene::load(&path).unwrap_or_else(|e| panic!("loading {}: {e}", path.display()))
}

/// The tests' room: `cornell_bunny_small.json` as the tests of one pass against its twin take
/// it, as JSON text (meshes relative to `fixtures/scenes`): visibility off
/// (`settings.tuning.visibility`) and none of the levels measured on the fixture
/// (`settings.levels`, whose balanced level adds the near field), so the passes a test looks at
/// run alone and cheaply. A test that needs a mode replaces `"visibility": "off"`.
pub fn test_room_text() -> String {
    let text = std::fs::read_to_string(fixture("scenes/cornell_bunny_small.json")).expect("fixture scene");
    let mut json: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let settings = json["settings"].as_object_mut().expect("the fixture has settings");
    settings.remove("levels");
    settings["tuning"]["visibility"] = "off".into();
    serde_json::to_string_pretty(&json).expect("JSON")
}

/// [`test_room_text`] loaded.
pub fn load_test_room() -> Scene {
    Scene::from_json_str(&test_room_text(), &fixture("scenes")).expect("the tests' room loads")
}

pub fn gpu() -> Gpu {
    Gpu::new().expect("a GPU adapter (lavapipe in CI: apt-get install mesa-vulkan-drivers)")
}

/// The fixture scene `name` as JSON with its meshes named by absolute path, so that a changed
/// copy can be written anywhere (a test's scratch directory) and still load.
pub fn fixture_scene_json(name: &str) -> serde_json::Value {
    let dir = fixture("scenes");
    let text = std::fs::read_to_string(dir.join(format!("{name}.json"))).expect("fixture scene");
    let mut scene: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    for mesh in scene["meshes"].as_array_mut().expect("meshes") {
        let obj = dir.join(mesh["obj"].as_str().expect("obj"));
        mesh["obj"] = obj.to_str().expect("UTF-8 path").into();
    }
    scene
}

/// A fresh directory under the target dir for a test's files.
pub fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// `|a - b| <= rel * scale + abs` component-wise, with a message naming `what`.
#[track_caller]
pub fn assert_close(a: glam::Vec3, b: glam::Vec3, rel: f32, scale: f32, abs: f32, what: &str) {
    let tol = rel * scale + abs;
    assert!((a - b).abs().max_element() <= tol, "{what}: GPU {a} vs CPU {b} (tolerance {tol})");
}
/// `lights` written in a scene's own coordinates (its meshes' world space), moved to its
/// floating origin (the meshes' centre), where the loader puts a scene's lights.
pub fn local_lights(scene: &relume::scene::Scene, lights: Vec<relume::scene::Light>) -> Vec<relume::scene::Light> {
    use relume::scene::{Light, PointLight, SpotLight};
    let origin = scene.origin.as_vec3();
    lights
        .into_iter()
        .map(|l| match l {
            Light::Point(p) => Light::Point(PointLight { position: p.position - origin, ..p }),
            Light::Spot(s) => Light::Spot(SpotLight { position: s.position - origin, ..s }),
        })
        .collect()
}

/// CPU twin values at every visibility texel that hit geometry, from the receiver a viewer at
/// `eye` sees there (`FlatScene::receiver_at`: shading and geometric normals, facing the eye).
pub fn per_receiver(
    flat: &relume::gpu::scene::FlatScene,
    hits: &[Option<relume::gpu::raster::Hit>],
    eye: glam::Vec3,
    f: impl Fn(&relume::twin::exact_cpu::Receiver) -> glam::Vec3,
) -> Vec<Option<glam::Vec3>> {
    hits.iter().map(|hit| hit.map(|h| f(&flat.receiver_at(h.triangle, h.barycentrics, eye)))).collect()
}

/// CPU twin values at every visibility texel that hit geometry: `f(position, normal, surface)`.
pub fn per_hit(
    flat: &relume::gpu::scene::FlatScene,
    hits: &[Option<relume::gpu::raster::Hit>],
    f: impl Fn(glam::Vec3, glam::Vec3, &relume::twin::Material) -> glam::Vec3,
) -> Vec<Option<glam::Vec3>> {
    hits.iter()
        .map(|hit| {
            hit.map(|h| {
                let (p, n, surface) = flat.surface_at(h.triangle, h.barycentrics);
                f(p, n, &surface)
            })
        })
        .collect()
}
