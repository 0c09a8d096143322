//! The sparse method against the brute-force reference on the small fixture: close, and closer
//! with more sparse points. (The 512² figures in docs/measurements/ come from `relume compare`.)

use super::{fixture, gpu};
use relume::image::relative_rmse;
use relume::renderer::{Method, Renderer};
use relume::scene::Scene;

/// The fixture scene `name` with `settings` (a JSON object) set over its own settings.
fn fixture_with_settings(name: &str, settings: serde_json::Value) -> Scene {
    let dir = fixture("scenes");
    let text = std::fs::read_to_string(dir.join(name)).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    // Research knobs live under `settings.tuning`, what the user wants beside it.
    const TUNING: [&str; 9] = [
        "rsm_resolution",
        "interpolation_neighbours",
        "visibility",
        "occlusion_rule",
        "sparse",
        "clusters",
        "ism",
        "direct",
        "second_bounce",
    ];
    for (key, value) in settings.as_object().expect("settings are an object") {
        match TUNING.contains(&key.as_str()) {
            true => json["settings"]["tuning"][key] = value.clone(),
            false => json["settings"][key] = value.clone(),
        }
    }
    Scene::from_json_str(&json.to_string(), &dir).unwrap()
}

fn rel_rmse_with_sparse_points(box_points: u32, bunny_points: u32, sparse: serde_json::Value) -> f64 {
    let dir = fixture("scenes");
    let text = super::test_room_text()
        .replace("\"sparse_points\": 512", &format!("\"sparse_points\": {box_points}"))
        .replace("\"sparse_points\": 256", &format!("\"sparse_points\": {bunny_points}"));
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["settings"]["tuning"]["sparse"] = sparse;
    let scene = Scene::from_json_str(&json.to_string(), &dir).unwrap();
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let sparse = renderer.render(&gpu, Method::Sparse, 64, 64).unwrap();
    let brute = renderer.render(&gpu, Method::BruteForce, 64, 64).unwrap();
    relative_rmse(&sparse.indirect, &brute.indirect)
}

/// The paper's form (`settings.sparse` kernel "paper", bound "off", subdivision 1, glossy
/// lights), measured on
/// lavapipe: 0.144 with 768 points, 0.096 with 3072. The bounds leave room for other adapters'
/// rounding, not for a regression of the method: a broken interpolation or renormalisation
/// gives errors of order 1. The defaults (smooth kernel, bound, subdivision 2, glossy radiance
/// interpolated), measured: 0.108 with 768 points, 0.0971 with 3072: already closer at 768
/// points, so 4x the points gains less; they must not be worse than the paper's form at either
/// count by more than 5 % (at 3072 points they are 1.4 % worse).
#[test]
fn sparse_converges_toward_brute_force() {
    let paper =
        || serde_json::json!({ "kernel": "paper", "bound": "off", "subdivision": 1, "glossy_interpolation": "lights" });
    let coarse = rel_rmse_with_sparse_points(512, 256, paper());
    let fine = rel_rmse_with_sparse_points(2048, 1024, paper());
    eprintln!("paper's form, relative RMSE: {coarse:.4} with 768 sparse points, {fine:.4} with 3072");
    assert!(coarse < 0.2, "768 sparse points: relative RMSE {coarse}");
    assert!(fine < 0.8 * coarse, "4x the sparse points must cut the error: {fine} vs {coarse}");
    let default_coarse = rel_rmse_with_sparse_points(512, 256, serde_json::json!({}));
    let default_fine = rel_rmse_with_sparse_points(2048, 1024, serde_json::json!({}));
    eprintln!("defaults, relative RMSE: {default_coarse:.4} with 768 sparse points, {default_fine:.4} with 3072");
    assert!(default_coarse <= coarse * 1.05, "defaults at 768 points: {default_coarse} vs the paper's {coarse}");
    assert!(default_fine <= fine * 1.05, "defaults at 3072 points: {default_fine} vs the paper's {fine}");
}

/// `"occlusion": "auto"` (the default) turns disc occlusion on for the Cornell box + bunny (two
/// meshes; the bunny alone is not convex either) and leaves it off for a convex object.
#[test]
fn auto_occlusion_follows_the_scene() {
    use relume::scene::Occlusion;
    let dir = fixture("scenes");
    let json = std::fs::read_to_string(dir.join("cornell_bunny_small.json")).unwrap();
    assert!(!json.contains("visibility"), "the fixture leaves its visibility to the level");
    let scene = Scene::from_json_str(&json, &dir).unwrap();
    assert_eq!(scene.settings.visibility.mode, Occlusion::Disks);
    assert!(scene.meshes[1].may_occlude_itself(), "the bunny has concave parts (ears, legs)");
}

/// Bounded renormalisation on Sponza (its default sparse points, a 64² RSM to keep the test short, at
/// 64x36 pixels) no pixel of the sparse image is brighter than 1.5x the brightest brute-force
/// pixel with the default `settings.sparse.bound` ("gathered"). The paper's form (bound "off")
/// is rendered beside it and its ratio printed: the issue measured 4.3x at 128².
#[test]
fn sparse_sponza_has_no_fireflies() {
    let gpu = gpu();
    let mut ratios = Vec::new();
    for bound in ["gathered", "off"] {
        let settings = serde_json::json!({ "rsm_resolution": 64, "sparse": { "bound": bound } });
        let scene = fixture_with_settings("sponza_bunny.json", settings);
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        let sparse = renderer.render(&gpu, Method::Sparse, 64, 36).unwrap();
        let brute = renderer.render(&gpu, Method::BruteForce, 64, 36).unwrap();
        let (_, sparse_peak) = sparse.indirect.luminance_sum_and_peak();
        let (_, brute_peak) = brute.indirect.luminance_sum_and_peak();
        assert!(brute_peak > 0.0, "the brute force must light some pixel");
        ratios.push(sparse_peak / brute_peak);
    }
    eprintln!("brightest sparse / brightest brute-force pixel: bound {:.3}, paper {:.3}", ratios[0], ratios[1]);
    assert!(ratios[0] <= 1.5, "bounded: {:.3}x the brightest brute-force pixel", ratios[0]);
}

/// The open-room glossy fixture (`cornell_glossy_open.json`: the Cornell room without its
/// spheres, a glossy floor (k 30) and a glossy bunny (k 60)), small: a 32² RSM at 64x64. Its
/// glossy stages run, the glossy lobe changes the image, and the sparse image stays near the
/// brute force. Measured on lavapipe: 0.105 glossy (0.107 with the paper's glossy lights,
/// `glossy_interpolation: "lights"`), 0.102 all diffuse, the lobe 0.071 of the image. The bound is the measured error with room for other adapters' rounding; a broken
/// glossy path gives errors of order 1.
#[test]
fn the_glossy_open_room_stays_near_the_brute_force() {
    let gpu = gpu();
    let mut errors = Vec::new();
    let mut brutes = Vec::new();
    for glossy in [true, false] {
        let scene = fixture_with_settings(
            "cornell_glossy_open.json",
            serde_json::json!({ "rsm_resolution": 32, "glossy": glossy }),
        );
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        assert_eq!(renderer.glossy(), glossy, "glossy stages run exactly when allowed");
        let sparse = renderer.render(&gpu, Method::Sparse, 64, 64).unwrap();
        let brute = renderer.render(&gpu, Method::BruteForce, 64, 64).unwrap();
        errors.push(relative_rmse(&sparse.indirect, &brute.indirect));
        brutes.push(brute.indirect);
    }
    let lobe = relative_rmse(&brutes[1], &brutes[0]);
    eprintln!(
        "sparse vs brute: glossy {:.4}, all diffuse {:.4}; glossy lobe's share of the image {lobe:.4}",
        errors[0], errors[1]
    );
    assert!(lobe > 0.05, "the glossy lobe must show: {lobe}");
    assert!(errors[0] < 0.15 && errors[1] < 0.15, "{errors:?}");
}
