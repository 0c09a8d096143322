//! Quality levels resolved per scene: the analysis' decisions on small scenes built for each
//! case, overrides, and `balanced` as the defaults every figure was measured with.

use std::path::Path;

use super::*;
use crate::scene::test_util::{LIGHT_AND_CAMERA, TempDir};
use crate::scene::{DEFAULT_NEIGHBOURS, Scene, SceneDescription, Settings};

/// A unit cube, counter-clockwise seen from outside (a convex object).
const CUBE_OBJ: &str = "\
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";

/// The same cube seen from inside: a convex room.
const ROOM_OBJ: &str = "\
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
f 2 3 4 1\nf 8 7 6 5\nf 5 6 2 1\nf 6 7 3 2\nf 7 8 4 3\nf 8 5 1 4\n";

/// A scene of `meshes` (mesh entry bodies) and `settings`, loaded from a directory holding
/// `cube.obj` and `room.obj`.
fn load(meshes: &[&str], settings: &str) -> Scene {
    let dir = TempDir::new("quality");
    dir.write("cube.obj", CUBE_OBJ);
    dir.write("room.obj", ROOM_OBJ);
    let meshes: Vec<String> = meshes.iter().map(|m| format!("{{{m}}}")).collect();
    let json = format!(r#"{{"meshes": [{}], {LIGHT_AND_CAMERA}, "settings": {settings}}}"#, meshes.join(", "));
    Scene::from_json_str(&json, dir.path()).expect("scene loads")
}

fn choice<'a>(scene: &'a Scene, parameter: &str) -> &'a Choice {
    let found = scene.resolved.choices.iter().find(|c| c.parameter == parameter);
    found.unwrap_or_else(|| panic!("no choice of {parameter} in {:#?}", scene.resolved.choices))
}

const ROOM: &str = r#""obj": "room.obj", "sparse_points": 32"#;
const CUBE: &str = r#""obj": "cube.obj", "sparse_points": 16"#;

#[test]
fn a_convex_room_needs_no_visibility_at_any_level() {
    for quality in ["fast", "balanced", "accurate", "reference"] {
        let scene = load(&[ROOM], &format!(r#"{{"quality": "{quality}"}}"#));
        assert!(!scene.resolved.analysis.self_occluding());
        assert_eq!(scene.settings.visibility.mode, Occlusion::Off, "{quality}");
        let visibility = choice(&scene, "visibility");
        assert_eq!(visibility.value, "\"off\"");
        assert!(visibility.reason.contains("cannot occlude itself"), "{}", visibility.reason);
    }
}

#[test]
fn a_scene_that_can_occlude_itself_gets_the_levels_visibility() {
    let scene = load(&[ROOM, CUBE], "{}");
    assert_eq!(scene.settings.visibility.mode, Occlusion::Disks, "balanced: disks, as `auto` always was");
    assert_eq!(choice(&scene, "visibility").to_string().split(':').next(), Some("visibility = \"disks\""));
    assert!(choice(&scene, "visibility").reason.starts_with("the scene can occlude itself (2 meshes)"));
    let accurate = load(&[ROOM, CUBE], r#"{"quality": "accurate"}"#);
    assert_eq!(accurate.settings.visibility.mode, Occlusion::Clusters);
    assert_eq!(accurate.settings.sparse.near_field, 4.0);
    let fast = load(&[ROOM, CUBE], r#"{"quality": "fast"}"#);
    assert_eq!(fast.settings.visibility.mode, Occlusion::Disks);
    assert_eq!((fast.settings.rsm_resolution, fast.settings.sparse.subdivision), (64, 4.0));
}

/// `fast` places half of each mesh's sparse points (rounded, at least one), the other levels
/// all of them, and `tuning.sparse.points` wins over the level.
#[test]
fn fast_places_half_the_sparse_points_unless_the_tuning_says_otherwise() {
    let placed =
        |settings: &str| load(&[ROOM, CUBE], settings).meshes.iter().map(|m| m.sparse.base_len()).sum::<usize>();
    assert_eq!(placed(r#"{"quality": "balanced"}"#), 32 + 16);
    assert_eq!(placed(r#"{"quality": "accurate"}"#), 32 + 16);
    assert_eq!(placed(r#"{"quality": "fast"}"#), 16 + 8);
    assert_eq!(placed(r#"{"quality": "fast", "tuning": {"sparse": {"points": 1}}}"#), 32 + 16);
    assert_eq!(placed(r#"{"tuning": {"sparse": {"points": 0.0625}}}"#), 2 + 1);
    let fast = load(&[ROOM, CUBE], r#"{"quality": "fast"}"#);
    assert_eq!(choice(&fast, "sparse.points").value, "0.5");
    let one = SparseShading { points: 0.0625, ..SparseShading::default() };
    assert_eq!((one.placed_points(1), one.placed_points(24), one.placed_points(40)), (1, 2, 3));
}

/// A scene lit by RGB-D frames only (no light of its own, as a mixed-reality scene) takes
/// imperfect shadow maps at `accurate` (measured on the TUM replay), where a scene with a light
/// of its own takes clustered shadow maps.
#[test]
fn a_scene_lit_by_rgbd_frames_takes_imperfect_shadow_maps_at_accurate() {
    let dir = TempDir::new("quality-rgbd");
    dir.write("cube.obj", CUBE_OBJ);
    dir.write("room.obj", ROOM_OBJ);
    let camera =
        r#""camera": {"position": [0, 1, 3.5], "target": [0, 1, 0], "fov_y_deg": 40, "width": 64, "height": 64}"#;
    for (quality, mode) in [("balanced", Occlusion::Disks), ("accurate", Occlusion::Ism), ("reference", Occlusion::Ism)]
    {
        let json =
            format!(r#"{{"meshes": [{{{ROOM}}}, {{{CUBE}}}], {camera}, "settings": {{"quality": "{quality}"}}}}"#);
        let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");
        assert!(scene.resolved.analysis.lit_by_rgbd_frames() && scene.resolved.analysis.self_occluding());
        assert_eq!(scene.settings.visibility.mode, mode, "{quality}");
        if quality != "balanced" {
            assert!(choice(&scene, "visibility").reason.contains("lit by RGB-D frames"));
        }
    }
    let lit = load(&[ROOM, CUBE], r#"{"quality": "accurate"}"#);
    assert!(!lit.resolved.analysis.lit_by_rgbd_frames());
    assert_eq!(lit.settings.visibility.mode, Occlusion::Clusters);
}

/// On a scene lit by RGB-D frames the differential pass follows the level: the exact pass at
/// `reference` (beside the exact reference), the fast one below; a method the scene file sets
/// wins at every level; a scene with a light of its own is given no such choice.
#[test]
fn the_differential_method_follows_the_level_unless_the_scene_file_sets_it() {
    let dir = TempDir::new("quality-differential");
    dir.write("cube.obj", CUBE_OBJ);
    let camera =
        r#""camera": {"position": [0, 1, 3.5], "target": [0, 1, 0], "fov_y_deg": 40, "width": 64, "height": 64}"#;
    let scene = |settings: &str| {
        let json = format!(r#"{{"meshes": [{{{CUBE}}}], {camera}, "settings": {settings}}}"#);
        Scene::from_json_str(&json, dir.path()).expect("scene loads")
    };
    for (quality, method) in [("fast", "fast"), ("balanced", "fast"), ("accurate", "fast"), ("reference", "exact")] {
        let s = scene(&format!(r#"{{"quality": "{quality}"}}"#));
        let exact = s.resolved.method == Technique::Exact;
        assert_eq!(s.settings.mr.differential_method, None, "{quality}: left to the frames");
        let resolved = DifferentialMethod::for_frames(s.settings.mr.differential_method, exact, false);
        // On the GPU the frames run the exact pass at every level.
        let on_gpu = DifferentialMethod::for_frames(s.settings.mr.differential_method, exact, true);
        assert_eq!(on_gpu, DifferentialMethod::Exact, "{quality} on the GPU");
        assert_eq!(tuning::json_value(&resolved), format!("\"{method}\""), "{quality}");
        assert_eq!(choice(&s, "mr.differential_method").value, format!("\"{method}\""), "{quality}");
    }
    let set = scene(r#"{"quality": "reference", "mr": {"differential_method": "fast"}}"#);
    assert_eq!(set.settings.mr.differential_method, Some(DifferentialMethod::Fast));
    assert_eq!(
        DifferentialMethod::for_frames(set.settings.mr.differential_method, true, true),
        DifferentialMethod::Fast
    );
    let c = choice(&set, "mr.differential_method");
    assert_eq!(
        (c.value.as_str(), c.reason.as_str()),
        ("\"fast\"", "set in the scene file (reference would choose \"exact\")")
    );
    let lit = load(&[CUBE], r#"{"quality": "reference"}"#);
    assert!(lit.resolved.choices.iter().all(|c| c.parameter != "mr.differential_method"));
}

#[test]
fn a_scene_without_glossy_material_needs_no_glossy_gather() {
    let scene = load(&[CUBE], "{}");
    assert_eq!(scene.resolved.analysis.glossy_materials, 0);
    let glossy = choice(&scene, "glossy gather");
    assert_eq!((glossy.value.as_str(), glossy.reason.as_str()), ("off", "no glossy material"));
    assert!(!scene.needs_glossy());
    let shiny = format!(r#"{CUBE}, "material": {{"diffuse": [0.5, 0.5, 0.5], "specular": [0.2, 0.2, 0.2]}}"#);
    let scene = load(&[&shiny], "{}");
    assert_eq!(choice(&scene, "glossy gather").value, "on");
    assert!(scene.needs_glossy());
    let scene = load(&[&shiny], r#"{"glossy": false}"#);
    assert_eq!(choice(&scene, "glossy gather").reason, "settings.glossy is false");
}

#[test]
fn an_explicit_tuning_value_wins_over_the_level() {
    let settings = r#"{"quality": "fast", "tuning": {"rsm_resolution": 160, "visibility": "ism",
                       "sparse": {"near_field": 2}}}"#;
    let scene = load(&[ROOM, CUBE], settings);
    assert_eq!(scene.settings.rsm_resolution, 160);
    assert_eq!(scene.settings.visibility.mode, Occlusion::Ism);
    // The level keeps what the tuning does not set.
    assert_eq!((scene.settings.sparse.near_field, scene.settings.sparse.subdivision), (2.0, 4.0));
    let rsm = choice(&scene, "tuning.rsm_resolution");
    assert_eq!(rsm.to_string(), "tuning.rsm_resolution = 160: set in the scene file (fast would choose 64)");
    assert_eq!(choice(&scene, "tuning.visibility").value, "\"ism\"");
    assert!(scene.resolved.choices.iter().all(|c| c.parameter != "rsm_resolution"));
}

#[test]
fn reference_asks_for_the_exact_method_with_accurates_parameters() {
    let reference = load(&[ROOM, CUBE], r#"{"quality": "reference", "budget_ms": 40}"#);
    let accurate = load(&[ROOM, CUBE], r#"{"quality": "accurate"}"#);
    assert_eq!(reference.resolved.method, Technique::Exact);
    assert_eq!(accurate.resolved.method, Technique::Sparse);
    assert_eq!(reference.settings, accurate.settings);
    assert_eq!(reference.resolved.budget_ms, Some(40.0));
    assert!(
        reference.resolved.report().starts_with("quality reference, budget 40 ms"),
        "{}",
        reference.resolved.report()
    );
}

/// What the loader and the admission read does not depend on the analysis, so it is final
/// before the meshes are read.
#[test]
fn the_loaders_parameters_depend_on_the_level_and_tuning_only() {
    let loaded = SceneAnalysis {
        meshes: 3,
        concave_meshes: vec!["bunny".to_owned()],
        glossy_materials: 2,
        spot_light: true,
        spot_lights: 1,
        point_lights: 4,
        triangles_per_sparse_point: 9.5,
    };
    for quality in [Quality::Fast, Quality::Balanced, Quality::Accurate, Quality::Reference] {
        let mut settings = SettingsDescription::default();
        settings.quality = quality;
        let (before, _) = resolve(quality, &SceneAnalysis::default(), &settings);
        let (after, _) = resolve(quality, &loaded, &settings);
        let load_time = |s: &Settings| (s.rsm_resolution, s.interpolation_neighbours, s.sparse, s.seed, s.direct);
        assert_eq!(load_time(&before), load_time(&after), "{quality:?}");
        assert_eq!(before.second_bounce, after.second_bounce);
        settings.validate("settings").expect("every level's own values are valid");
    }
}

/// A level's measured parameters (`settings.levels`) replace its rule on that level only, below
/// `tuning`, and say what was measured as their reason; `reference` takes none.
#[test]
fn measured_parameters_replace_the_levels_rule_below_the_tuning() {
    let settings = r#"{"levels": {"balanced": {"measured": "0.07 at 300 ms against 0.08 at 500 ms",
        "rsm_resolution": 32, "visibility": "clusters", "sparse": {"points": 0.5, "subdivision": 4}}},
        "tuning": {"sparse": {"subdivision": 3}}}"#;
    let balanced = load(&[ROOM, CUBE], settings);
    assert_eq!(balanced.settings.rsm_resolution, 32);
    assert_eq!(balanced.settings.visibility.mode, Occlusion::Clusters);
    assert_eq!((balanced.settings.sparse.points, balanced.settings.sparse.subdivision), (0.5, 3.0), "tuning wins");
    let rsm = choice(&balanced, "levels.balanced.rsm_resolution");
    assert_eq!(rsm.value, "32");
    assert_eq!(rsm.reason, "measured on this scene: 0.07 at 300 ms against 0.08 at 500 ms (the rule would choose 128)");
    assert!(choice(&balanced, "levels.balanced.visibility").reason.contains("(the rule would choose \"disks\")"));
    assert!(choice(&balanced, "tuning.sparse.subdivision").reason.starts_with("set in the scene file"));
    assert!(balanced.resolved.choices.iter().all(|c| c.parameter != "levels.balanced.sparse.subdivision"));
    let levels = [
        ("fast", 64, Occlusion::Disks),
        ("accurate", 128, Occlusion::Clusters),
        ("reference", 128, Occlusion::Clusters),
    ];
    for (quality, rsm, visibility) in levels {
        let other = load(&[ROOM, CUBE], &settings.replacen('{', &format!(r#"{{"quality": "{quality}", "#), 1));
        assert_eq!(other.settings.rsm_resolution, rsm, "{quality}");
        assert_eq!(other.settings.sparse.subdivision, 3.0, "{quality}");
        assert_eq!(other.settings.visibility.mode, visibility, "{quality}");
        assert!(other.resolved.choices.iter().all(|c| !c.parameter.starts_with("levels.")), "{quality}");
    }
}

/// A measured level may name the GPU estimator: that level's technique and draws, with the
/// measurement as the reason; the other levels keep theirs.
#[test]
fn a_measured_level_can_name_the_estimator() {
    let settings = r#"{"quality": "accurate", "levels": {"accurate": {"measured": "0.05 against 0.29",
        "technique": "estimator", "draws": 16}}}"#;
    let accurate = load(&[ROOM, CUBE], settings);
    assert_eq!((accurate.resolved.method, accurate.resolved.estimator_draws), (Technique::Estimator, Some(16)));
    let reason = &choice(&accurate, "levels.accurate.technique").reason;
    assert!(reason.starts_with("measured on this scene: 0.05 against 0.29; 16 VALs drawn"), "{reason}");
    assert!(accurate.resolved.report().starts_with("quality accurate: technique estimator"));
    for (quality, method) in [("balanced", Technique::Sparse), ("reference", Technique::Exact)] {
        let other = load(&[ROOM, CUBE], &settings.replacen("accurate", quality, 1));
        assert_eq!((other.resolved.method, other.resolved.estimator_draws), (method, None), "{quality}");
    }
    let default_draws = settings.replace(r#", "draws": 16"#, "");
    assert_eq!(load(&[ROOM, CUBE], &default_draws).resolved.estimator_draws, Some(DEFAULT_ESTIMATOR_DRAWS));
}

/// A measured level may name the brute force through the clusters' maps, or the exact
/// reference over its own VALs (a coarser RSM than the `reference` level's, which stays):
/// that level's technique (no draws), the measurement as the reason, the level's RSM applied;
/// `draws` with the brute force is refused.
#[test]
fn a_measured_level_can_name_the_brute_force_through_the_clusters_or_the_exact_reference() {
    for (technique, rsm, does) in [
        (Technique::BruteForceClusters, 64, "every VAL at every pixel"),
        (Technique::Exact, 16, "a shadow ray per pixel and VAL"),
    ] {
        let name = serde_json::to_value(technique).unwrap();
        let settings = format!(
            r#"{{"quality": "accurate", "levels": {{"accurate": {{"measured": "0.10 against 0.24",
            "technique": {name}, "rsm_resolution": {rsm}}}}}}}"#
        );
        let accurate = load(&[ROOM, CUBE], &settings);
        assert_eq!((accurate.resolved.method, accurate.resolved.estimator_draws), (technique, None));
        assert_eq!(accurate.settings.rsm_resolution, rsm);
        assert_eq!(accurate.settings.reference_rsm_resolution, 128);
        let reason = &choice(&accurate, "levels.accurate.technique").reason;
        assert!(reason.starts_with(&format!("measured on this scene: 0.10 against 0.24; {does}")), "{reason}");
        let report = accurate.resolved.report();
        assert!(report.starts_with(&format!("quality accurate: technique {}", name.as_str().unwrap())), "{report}");
        let balanced = load(&[ROOM, CUBE], &settings.replacen("accurate", "balanced", 1));
        assert_eq!(balanced.resolved.method, Technique::Sparse);
    }
    let levels = r#"{"accurate": {"measured": "m", "technique": "brute_force_clusters", "draws": 8}}"#;
    let json = format!(r#"{{"meshes": [], {LIGHT_AND_CAMERA}, "settings": {{"levels": {levels}}}}}"#);
    let description = SceneDescription::from_json_str(&json).expect("parses");
    let e = description.settings.validate("settings").expect_err("draws without the estimator").to_string();
    assert!(e.contains("settings.levels.accurate.draws") && e.contains("only with technique"), "{e}");
}

/// A measured level is checked where the scene file is, each field named.
#[test]
fn measured_parameters_are_validated_naming_the_field() {
    let error = |levels: &str| {
        let json = format!(r#"{{"meshes": [], {LIGHT_AND_CAMERA}, "settings": {{"levels": {levels}}}}}"#);
        match SceneDescription::from_json_str(&json) {
            Ok(d) => d.settings.validate("settings").expect_err(levels).to_string(),
            Err(e) => e.to_string(),
        }
    };
    assert!(error(r#"{"balanced": {"measured": " "}}"#).contains("settings.levels.balanced.measured"));
    let long = "x".repeat(MAX_MEASURED_CHARS + 1);
    assert!(error(&format!(r#"{{"fast": {{"measured": "{long}"}}}}"#)).contains("settings.levels.fast.measured"));
    assert!(
        error(r#"{"fast": {"measured": "m", "rsm_resolution": 4}}"#).contains("settings.levels.fast.rsm_resolution")
    );
    let points = error(r#"{"accurate": {"measured": "m", "sparse": {"points": 2}}}"#);
    assert!(points.contains("settings.levels.accurate.sparse.points"), "{points}");
    assert!(error(r#"{"reference": {"measured": "m"}}"#).contains("reference"));
    assert!(error(r#"{"fast": {"measured": "m", "visibility": "auto"}}"#).contains("auto"));
    assert!(error(r#"{"fast": {"measured": "m", "near_field": 2}}"#).contains("near_field"));
    for draws in
        [r#""technique": "estimator", "draws": 0"#, r#""technique": "estimator", "draws": 257"#, r#""draws": 8"#]
    {
        let e = error(&format!(r#"{{"balanced": {{"measured": "m", {draws}}}}}"#));
        assert!(e.contains("settings.levels.balanced.draws"), "{draws}: {e}");
    }
}

/// `balanced` resolves to the defaults every image and figure was made with: each knob the
/// scene file's or the old default, and `auto` visibility's rule. Checked on every fixture's
/// settings without their measured parameters (`settings.levels`, tested above), for a scene
/// that can and one that cannot occlude itself.
#[test]
#[allow(clippy::field_reassign_with_default)]
fn balanced_is_the_old_defaults_on_every_fixture() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenes");
    let mut checked = 0;
    for entry in std::fs::read_dir(&fixtures).expect("fixtures") {
        let path = entry.expect("entry").path();
        let text = std::fs::read_to_string(&path).expect("read");
        let Ok(description) = SceneDescription::from_json_str(&text) else {
            continue; // a glTF scene form: its settings are checked through its description below
        };
        let mut s = description.settings;
        s.levels = MeasuredLevels::default();
        let s = &s;
        assert_eq!(s.quality, Quality::Balanced, "{}", path.display());
        let t = &s.tuning;
        for self_occluding in [false, true] {
            let analysis = SceneAnalysis { meshes: if self_occluding { 2 } else { 1 }, ..SceneAnalysis::default() };
            let auto = if self_occluding { Occlusion::Disks } else { Occlusion::Off };
            // Field by field from the default, so that a mode added to the registry (and so a
            // field of `VisibilitySettings`) does not need this test changed.
            let mut old_visibility = VisibilitySettings::default();
            old_visibility.mode = t.visibility.unwrap_or_default().or(auto);
            old_visibility.rule = t.occlusion_rule.unwrap_or(OcclusionRule::Product);
            old_visibility.clusters =
                t.clusters.map_or(ClusterSettings::default(), |o| o.apply(ClusterSettings::default()));
            old_visibility.ism = t.ism.map_or(IsmSettings::default(), |o| o.apply(IsmSettings::default()));
            let old = Settings {
                rsm_resolution: t.rsm_resolution.unwrap_or(128),
                reference_rsm_resolution: t.rsm_resolution.unwrap_or(128),
                glossy: s.glossy,
                seed: s.seed,
                exposure: s.exposure,
                interpolation_neighbours: t.interpolation_neighbours.unwrap_or(DEFAULT_NEIGHBOURS),
                visibility: old_visibility,
                rgbd: s.rgbd,
                mr: s.mr,
                sparse: t.sparse.map_or(SparseShading::default(), |o| o.apply(SparseShading::default())),
                direct: t.direct.map_or(DirectSettings::default(), |o| o.apply(DirectSettings::default())),
                bounces: s.bounces,
                second_bounce: t
                    .second_bounce
                    .map_or(SecondBounceSettings::default(), |o| o.apply(SecondBounceSettings::default())),
            };
            assert_eq!(resolve(Quality::Balanced, &analysis, s).0, old, "{}", path.display());
        }
        checked += 1;
    }
    assert!(checked >= 8, "only {checked} fixtures read");
    // The defaults themselves are the numbers the figures name.
    let defaults = SettingsDescription::default().before_load();
    assert_eq!((defaults.rsm_resolution, defaults.interpolation_neighbours), (128, 8));
    assert_eq!(defaults.sparse, SparseShading::default());
    assert_eq!((defaults.sparse.subdivision, defaults.sparse.near_field, defaults.sparse.adaptive), (2.0, 0.0, 0.0));
}
