//! Parsing and validation of scene descriptions, and their error messages.

use glam::{DMat4, DVec3, Vec3};

use super::json::json_path_at;
use super::*;
use crate::scene::settings::*;
use crate::scene::{Settings, SpotLight};

const MINIMAL: &str = r#"{
    "meshes": [{"obj": "a.obj", "sparse_points": 16}],
    "light": {"position": [0, 2, 0], "direction": [0, -1, 0],
              "inner_angle_deg": 20, "outer_angle_deg": 30, "intensity": [1, 1, 1]},
    "camera": {"position": [0, 1, 3], "target": [0, 1, 0], "fov_y_deg": 45,
               "width": 64, "height": 48}
}"#;

/// Parses and validates, returning the error message.
fn error_of(text: &str) -> String {
    match SceneDescription::from_json_str(text).and_then(|d| d.validate()) {
        Ok(()) => panic!("expected an error for {text}"),
        Err(error) => error.to_string(),
    }
}

/// `MINIMAL` with `from` replaced by `to` (which must occur).
fn edit(from: &str, to: &str) -> String {
    assert!(MINIMAL.contains(from), "fixture lacks {from}");
    MINIMAL.replacen(from, to, 1)
}

/// `MINIMAL` with `lights` and `settings.tuning.direct` as given.
fn with_lights(lights: &str, direct: &str) -> String {
    edit(
        r#""meshes""#,
        &format!(r#""lights": [{lights}], "settings": {{"tuning": {{"direct": {{{direct}}}}}}}, "meshes""#),
    )
}

/// The settings resolved at the scene file's level for a scene that can (`self_occluding`) or
/// cannot occlude itself.
fn to_settings(settings: &SettingsDescription, self_occluding: bool) -> Settings {
    let analysis = SceneAnalysis { meshes: if self_occluding { 2 } else { 1 }, ..SceneAnalysis::default() };
    resolve(settings.quality, &analysis, settings).0
}

#[test]
fn lights_parse_spot_and_point_lights() {
    let text = with_lights(
        r#"{"type": "point", "position": [1, 2, 3], "intensity": [4, 5, 6], "range": 7},
           {"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1]},
           {"type": "spot", "position": [0, 2, 0], "direction": [0, -1, 0], "inner_angle_deg": 10,
            "outer_angle_deg": 20, "intensity": [2, 2, 2]}"#,
        r#""shadows": "light_cluster", "d_init": 0.5, "z_far": 30"#,
    );
    let description = SceneDescription::from_json_str(&text).expect("parses");
    description.validate().expect("valid");
    let lights: Vec<super::super::Light> = description.lights.iter().map(|l| l.to_light(DVec3::ZERO)).collect();
    assert_eq!(
        lights[0],
        super::super::Light::Point(super::super::PointLight {
            position: Vec3::new(1.0, 2.0, 3.0),
            intensity: Vec3::new(4.0, 5.0, 6.0),
            range: Some(7.0)
        })
    );
    assert!(matches!(lights[1], super::super::Light::Point(p) if p.range.is_none()));
    assert!(matches!(lights[2], super::super::Light::Spot(s) if (s.outer_angle - 20f32.to_radians()).abs() < 1e-6));
    let direct = description.settings.before_load().direct;
    assert_eq!((direct.shadows, direct.d_init, direct.z_far), (DirectShadows::LightCluster, 0.5, Some(30.0)));
    assert_eq!(
        SceneDescription::from_json_str(MINIMAL).unwrap().settings.before_load().direct,
        DirectSettings::default()
    );
}

#[test]
fn lights_errors_name_the_field() {
    let point = r#"{"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1]}"#;
    for (lights, direct, expected) in [
        (
            r#"{"type": "point", "position": [0, 1, 0], "intensity": [1, -1, 1]}"#.to_owned(),
            "",
            "lights[0].intensity[1]: must be >= 0, got -1",
        ),
        (
            format!(r#"{point}, {{"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1], "range": 0}}"#),
            "",
            "lights[1].range: must be > 0, got 0",
        ),
        (
            format!(
                r#"{point}, {{"type": "spot", "position": [0, 1, 0], "direction": [0, 0, 0], "inner_angle_deg": 1, "outer_angle_deg": 2, "intensity": [1, 1, 1]}}"#
            ),
            "",
            "lights[1].direction: must be nonzero, got [0, 0, 0]",
        ),
        (
            format!("{point}, {point}, {point}"),
            r#""max_lights": 2"#,
            "lights: holds 3 lights, over settings.tuning.direct.max_lights = 2",
        ),
        (point.to_owned(), r#""d_init": 0"#, "settings.tuning.direct.d_init: must be > 0, got 0"),
        (point.to_owned(), r#""z_far": -1"#, "settings.tuning.direct.z_far: must be > 0, got -1"),
        (point.to_owned(), r#""max_lights": 0"#, "settings.tuning.direct.max_lights: must be in 1..=1024, got 0"),
        (point.to_owned(), r#""val_budget": 0"#, "settings.tuning.direct.val_budget: must be in 1..=1048576, got 0"),
        (
            format!("{point}, {point}"),
            r#""val_budget": 11"#,
            "settings.tuning.direct.val_budget: must be at least 12 for these lights (one VAL per RSM view: 6 per point light, 1 per spot), got 11",
        ),
        (
            point.to_owned(),
            r#""shadow_map_resolution": 8"#,
            "settings.tuning.direct.shadow_map_resolution: must be in 16..=1024, got 8",
        ),
    ] {
        let message = error_of(&with_lights(&lights, direct));
        assert_eq!(message, expected);
    }
    // 2 x 1024 maps of 1024 texels: over the atlas.
    let message = error_of(&with_lights(point, r#""max_lights": 1024, "shadow_map_resolution": 1024"#));
    assert!(message.starts_with("settings.tuning.direct.shadow_map_resolution: 2048 maps of 1024 texels"), "{message}");
    let message = error_of(&with_lights(r#"{"type": "area", "position": [0, 1, 0]}"#, ""));
    assert!(message.starts_with("lights[0]"), "{message}");
    let message = error_of(&with_lights(point, r#""shadows": "exact""#));
    assert!(message.starts_with("settings.tuning.direct.shadows"), "{message}");
}

#[test]
fn minimal_scene_gets_defaults() {
    let description = SceneDescription::from_json_str(MINIMAL).expect("parses");
    description.validate().expect("valid");
    assert_eq!(description.settings, SettingsDescription::default());
    let settings = to_settings(&description.settings, false);
    assert_eq!(settings.rsm_resolution, 128);
    assert!(settings.glossy);
    assert_eq!(settings.seed, 1);
    assert_eq!(settings.exposure, None);
    let camera = description.camera.to_camera(DVec3::ZERO);
    assert_eq!(camera.up, Vec3::Y);
    assert!((camera.fov_y - 45f32.to_radians()).abs() < 1e-6);
    let mesh = &description.meshes[0];
    assert_eq!(mesh.transform.to_matrix(), DMat4::IDENTITY);
    assert!(mesh.material.is_none() && mesh.materials.is_empty());
}

#[test]
fn light_is_converted_to_radians_and_unit_direction() {
    let text = edit(r#""direction": [0, -1, 0]"#, r#""direction": [0, -4, 3]"#);
    let light =
        SceneDescription::from_json_str(&text).expect("parses").light.expect("has a light").to_spot_light(DVec3::ZERO);
    assert!(light.direction.abs_diff_eq(Vec3::new(0.0, -0.8, 0.6), 1e-6));
    assert!((light.inner_angle - 20f32.to_radians()).abs() < 1e-6);
    assert!((light.outer_angle - 30f32.to_radians()).abs() < 1e-6);
    // No `up`: the default, world +Y away from vertical, +Z near it.
    assert_eq!(light.up, Vec3::Y);
    assert_eq!(SpotLight::default_up(Vec3::NEG_Y), Vec3::Z);
    let tilted = edit(r#""direction": [0, -1, 0]"#, r#""direction": [0, -1, 0], "up": [2, 0, 0]"#);
    let description = SceneDescription::from_json_str(&tilted).expect("parses");
    description.validate().expect("valid");
    assert_eq!(description.light.expect("has a light").to_spot_light(DVec3::ZERO).up, Vec3::X);
}

#[test]
fn unknown_fields_are_named_with_their_path() {
    let message = error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": 16, "colour": 1"#));
    assert!(message.starts_with("meshes[0].colour: unknown field `colour`"), "{message}");

    let message = error_of(&edit(r#""width": 64"#, r#""width": 64, "zoom": 2"#));
    assert!(message.starts_with("camera.zoom: unknown field"), "{message}");

    let message = error_of(&edit("{\n", "{\n\"extra\": true,\n"));
    assert!(message.starts_with("extra: unknown field"), "{message}");

    let message =
        error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": 16, "transform": {"scale": 2, "shear": 1}"#));
    assert!(message.starts_with("meshes[0].transform.shear: unknown field"), "{message}");
}

#[test]
fn missing_and_mistyped_fields_are_named() {
    let message = error_of(&edit(r#""fov_y_deg": 45,"#, ""));
    assert!(message.starts_with("camera.fov_y_deg: required field is missing"), "{message}");

    let message = error_of(&edit(r#""obj": "a.obj", "#, ""));
    assert!(message.starts_with("meshes[0].obj: required field is missing"), "{message}");

    let message = error_of(&edit(r#""width": 64"#, r#""width": "wide""#));
    assert!(message.starts_with("camera.width: invalid type"), "{message}");

    let message = error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": -3"#));
    assert!(message.starts_with("meshes[0].sparse_points:"), "{message}");

    let message = error_of(&edit(r#""position": [0, 2, 0]"#, r#""position": [0, 2]"#));
    assert!(message.starts_with("light.position"), "{message}");

    let message = error_of(&edit(r#""intensity": [1, 1, 1]"#, r#""intensity": [1, "x", 1]"#));
    assert!(message.starts_with("light.intensity[1]: invalid type"), "{message}");
}

#[test]
fn nan_and_infinity_are_rejected_with_their_path() {
    // JSON has no NaN literal: the parser rejects it, at the field.
    let message = error_of(&edit(r#""fov_y_deg": 45"#, r#""fov_y_deg": NaN"#));
    assert!(message.starts_with("camera.fov_y_deg:"), "{message}");
    // A number too large for f32 becomes infinite and is rejected by validation.
    let message = error_of(&edit(r#""fov_y_deg": 45"#, r#""fov_y_deg": 1e39"#));
    assert_eq!(message, "camera.fov_y_deg: must be a finite number, got inf");
    // Positions are f64, bounded by MAX_COORDINATE_M.
    let message = error_of(&edit(r#""target": [0, 1, 0]"#, r#""target": [0, 1e39, 0]"#));
    assert_eq!(message, "camera.target[1]: must be a finite number within +-1e7 m, got 1e39");
    // Too large for f64: the parser rejects it.
    let message = error_of(&edit(r#""intensity": [1, 1, 1]"#, r#""intensity": [1, 1e999, 1]"#));
    assert!(message.starts_with("light.intensity[1]:"), "{message}");
}

#[test]
fn out_of_range_values_name_the_path() {
    let cases = [
        (
            r#""sparse_points": 16"#,
            r#""sparse_points": 16, "transform": {"scale": -1}"#,
            "meshes[0].transform.scale: must be > 0, got -1",
        ),
        (
            r#""sparse_points": 16"#,
            r#""sparse_points": 16, "transform": {"scale": [1, 0, 1]}"#,
            "meshes[0].transform.scale[1]: must be > 0, got 0",
        ),
        (r#""sparse_points": 16"#, r#""sparse_points": 0"#, "meshes[0].sparse_points: must be in 1..=65536, got 0"),
        (
            r#""sparse_points": 16"#,
            r#""sparse_points": 65537"#,
            "meshes[0].sparse_points: must be in 1..=65536, got 65537",
        ),
        (r#""outer_angle_deg": 30"#, r#""outer_angle_deg": 85"#, "light.outer_angle_deg: must be in (0, 80], got 85"),
        (
            r#""inner_angle_deg": 20"#,
            r#""inner_angle_deg": 35"#,
            "light.inner_angle_deg: must be in [0, outer_angle_deg = 30], got 35",
        ),
        (r#""direction": [0, -1, 0]"#, r#""direction": [0, 0, 0]"#, "light.direction: must be nonzero, got [0, 0, 0]"),
        (r#""intensity": [1, 1, 1]"#, r#""intensity": [1, -1, 1]"#, "light.intensity[1]: must be >= 0, got -1"),
        (
            r#""intensity": [1, 1, 1]"#,
            r#""intensity": [1, 1, 1], "up": [0, 2, 0]"#,
            "light.up: must not be parallel to the light's direction",
        ),
        (r#""intensity": [1, 1, 1]"#, r#""intensity": [1, 1, 1], "up": [0, 0, 0]"#, "light.up: must be nonzero"),
        (r#""fov_y_deg": 45"#, r#""fov_y_deg": 170"#, "camera.fov_y_deg: must be in (1, 170), got 170"),
        (r#""width": 64"#, r#""width": 0"#, "camera.width: must be in 1..=8192, got 0"),
        (r#""height": 48"#, r#""height": 9000"#, "camera.height: must be in 1..=8192, got 9000"),
        (r#""target": [0, 1, 0]"#, r#""target": [0, 1, 3]"#, "camera.target: must differ from the camera position"),
        (
            r#""fov_y_deg": 45"#,
            r#""fov_y_deg": 45, "up": [0, 0, -2]"#,
            "camera.up: must not be parallel to the view direction",
        ),
        (
            r#""meshes": [{"obj": "a.obj", "sparse_points": 16}]"#,
            r#""meshes": []"#,
            "meshes: at least one mesh is required",
        ),
        (r#""obj": "a.obj""#, r#""obj": " ""#, "meshes[0].obj: must name an OBJ file"),
    ];
    for (from, to, expected) in cases {
        let message = error_of(&edit(from, to));
        assert!(message.starts_with(expected), "{to}: got `{message}`, expected `{expected}`");
    }
}

#[test]
fn settings_are_checked() {
    let with_settings = |settings: &str| {
        let text = MINIMAL.trim_end().trim_end_matches('}');
        format!("{text}, \"settings\": {settings}}}")
    };
    let with_tuning = |tuning: &str| with_settings(&format!(r#"{{"tuning": {tuning}}}"#));
    let description = SceneDescription::from_json_str(&with_settings(
        r#"{"glossy": false, "seed": 7, "exposure": 2.5, "tuning": {"rsm_resolution": 256}}"#,
    ))
    .expect("parses");
    description.validate().expect("valid");
    let settings = to_settings(&description.settings, false);
    assert_eq!(
        settings,
        Settings {
            rsm_resolution: 256,
            reference_rsm_resolution: 256,
            glossy: false,
            seed: 7,
            exposure: Some(2.5),
            interpolation_neighbours: 8,
            visibility: VisibilitySettings { mode: Occlusion::Off, rule: OcclusionRule::Product, ..Default::default() },
            rgbd: RgbdSettings::default(),
            mr: MrSettings::default(),
            sparse: SparseShading::default(),
            direct: DirectSettings::default(),
            bounces: 1,
            second_bounce: SecondBounceSettings::default(),
        }
    );
    let s =
        SceneDescription::from_json_str(&with_settings(r#"{"bounces": 2, "tuning": {"second_bounce": {"vals": 64}}}"#))
            .expect("parses");
    s.validate().expect("valid");
    let settings = to_settings(&s.settings, false);
    assert_eq!(settings.bounces, 2);
    assert_eq!(settings.second_bounce, SecondBounceSettings { points: 4096, vals: 64 });
    for (text, want) in [
        (r#"{"bounces": 3}"#, "settings.bounces: must be in 1..=2, got 3"),
        (r#"{"bounces": 0}"#, "settings.bounces: must be in 1..=2, got 0"),
        (
            r#"{"tuning": {"second_bounce": {"vals": 0}}}"#,
            "settings.tuning.second_bounce.vals: must be in 1..=65536, got 0",
        ),
        (
            r#"{"tuning": {"second_bounce": {"points": 8}}}"#,
            "settings.tuning.second_bounce.points: must be in 16..=262144, got 8",
        ),
    ] {
        assert_eq!(error_of(&with_settings(text)), want, "{text}");
    }
    let message = error_of(&with_tuning(r#"{"sparse": {"subdivision": 0.5}}"#));
    assert_eq!(message, "settings.tuning.sparse.subdivision: must be in [1, 16], got 0.5");
    let message = error_of(&with_tuning(r#"{"sparse": {"near_field": 9}}"#));
    assert_eq!(message, "settings.tuning.sparse.near_field: must be in [0, 8], got 9");
    let message = error_of(&with_tuning(r#"{"sparse": {"near_field": -0.5}}"#));
    assert_eq!(message, "settings.tuning.sparse.near_field: must be in [0, 8], got -0.5");
    let message = error_of(&with_tuning(r#"{"sparse": {"near_field_interleave": 3}}"#));
    assert_eq!(message, "settings.tuning.sparse.near_field_interleave: must be one of [1, 2, 4, 8], got 3");
    let message = error_of(&with_tuning(r#"{"sparse": {"near_field_interleave": 0}}"#));
    assert_eq!(message, "settings.tuning.sparse.near_field_interleave: must be one of [1, 2, 4, 8], got 0");
    let message = error_of(&with_tuning(r#"{"sparse": {"points": 1.5}}"#));
    assert_eq!(message, "settings.tuning.sparse.points: must be in [0.0625, 1], got 1.5");
    let message = error_of(&with_tuning(r#"{"sparse": {"points": 0}}"#));
    assert_eq!(message, "settings.tuning.sparse.points: must be in [0.0625, 1], got 0");
    let message = error_of(&with_tuning(r#"{"sparse": {"adaptive": 1.5}}"#));
    assert_eq!(message, "settings.tuning.sparse.adaptive: must be in [0, 1], got 1.5");
    let message = error_of(&with_tuning(r#"{"sparse": {"adaptive": -0.1}}"#));
    assert_eq!(message, "settings.tuning.sparse.adaptive: must be in [0, 1], got -0.1");
    let message = error_of(&with_tuning(r#"{"sparse": {"kernel": "cubic"}}"#));
    assert!(message.starts_with("settings.tuning.sparse.kernel: unknown variant `cubic`"), "{message}");
    let paper =
        r#"{"sparse": {"kernel": "paper", "bound": "off", "subdivision": 1, "glossy_interpolation": "lights"}}"#;
    let description = SceneDescription::from_json_str(&with_tuning(paper)).expect("parses");
    description.validate().expect("valid");
    let sparse = to_settings(&description.settings, false).sparse;
    assert_eq!(
        sparse,
        SparseShading {
            kernel: InterpolationKernel::Paper,
            bound: LightBound::Off,
            subdivision: 1.0,
            near_field: 0.0,
            near_field_interleave: 1,
            glossy_interpolation: GlossyInterpolation::Lights,
            adaptive: 0.0,
            points: 1.0,
        }
    );
    let radiance = r#"{"sparse": {"glossy_interpolation": "radiance"}}"#;
    let description = SceneDescription::from_json_str(&with_tuning(radiance)).expect("parses");
    let sparse = to_settings(&description.settings, false).sparse;
    assert_eq!(sparse.glossy_interpolation, GlossyInterpolation::Radiance);
    let message = error_of(&with_tuning(r#"{"sparse": {"glossy_interpolation": "pixels"}}"#));
    assert!(message.contains("glossy_interpolation") && message.contains("pixels"), "{message}");
    let message = error_of(&with_settings(r#"{"rgbd": {"min_depth": 2, "max_depth": 1}}"#));
    assert_eq!(message, "settings.rgbd.max_depth: must be > min_depth (2), got 1");
    let message = error_of(&with_settings(r#"{"rgbd": {"grid_step": 0}}"#));
    assert_eq!(message, "settings.rgbd.grid_step: must be in 1..=64, got 0");
    // `visibility`, and `occlusion` its deprecated alias; not both.
    for key in ["visibility", "occlusion"] {
        let text = with_tuning(&format!(r#"{{"{key}": "clusters", "clusters": {{"count": 8, "soft": "pcf"}}}}"#));
        let d = SceneDescription::from_json_str(&text).expect("parses");
        d.validate().expect("valid");
        let s = to_settings(&d.settings, true);
        assert_eq!(s.visibility.mode, Occlusion::Clusters, "{key}");
        assert_eq!(
            s.visibility.clusters,
            ClusterSettings { count: 8, soft: SoftShadows::Pcf, ..ClusterSettings::default() }
        );
    }
    assert!(SceneDescription::from_json_str(&with_tuning(r#"{"visibility": "off", "occlusion": "off"}"#)).is_err());
    let message = error_of(&with_tuning(r#"{"clusters": {"count": 0}}"#));
    assert_eq!(message, "settings.tuning.clusters.count: must be in 1..=256, got 0");
    let message = error_of(&with_tuning(r#"{"clusters": {"count": 256, "shadow_map_resolution": 1024}}"#));
    assert!(message.starts_with("settings.tuning.clusters.shadow_map_resolution: 256 maps of 1024"), "{message}");
    let message = error_of(&with_tuning(r#"{"clusters": {"normal_weight": -1}}"#));
    assert_eq!(message, "settings.tuning.clusters.normal_weight: must be in [0, 100], got -1");
    let message = error_of(&with_tuning(r#"{"clusters": {"iterations": 33}}"#));
    assert_eq!(message, "settings.tuning.clusters.iterations: must be in 1..=32, got 33");
    let message = error_of(&with_tuning(r#"{"clusters": {"shadow_maps": "ism", "shadow_map_resolution": 96}}"#));
    assert!(
        message.starts_with("settings.tuning.clusters.shadow_map_resolution: imperfect shadow maps need"),
        "{message}"
    );
    for rays in [0, 65] {
        let message = error_of(&with_tuning(&format!(r#"{{"clusters": {{"shadow_maps": "rays", "rays": {rays}}}}}"#)));
        assert_eq!(message, format!("settings.tuning.clusters.rays: must be in 1..=64, got {rays}"));
    }
    let message = error_of(&with_tuning(r#"{"clusters": {"shadow_maps": "points"}}"#));
    assert!(message.starts_with("settings.tuning.clusters.shadow_maps: unknown variant `points`"), "{message}");
    let text = with_tuning(r#"{"visibility": "ism", "ism": {"count": 16, "resolution": 32, "points": 100}}"#);
    let d = SceneDescription::from_json_str(&text).expect("parses");
    d.validate().expect("valid");
    let s = to_settings(&d.settings, false);
    assert_eq!(s.visibility.mode, Occlusion::Ism);
    assert_eq!(
        s.visibility.ism,
        IsmSettings { count: 16, resolution: 32, points: Some(100), ..IsmSettings::default() }
    );
    // The paper's rule: a quarter of the pi/4 * 128^2 texels of a 128x128 map.
    assert_eq!(IsmSettings::default().points_per_map(), 3217);
    for (ism, want) in [
        (r#"{"count": 0}"#, "settings.tuning.ism.count: must be in 1..=4096, got 0"),
        (r#"{"resolution": 48}"#, "settings.tuning.ism.resolution: must be a power of two in 16..=512, got 48"),
        (r#"{"points": 8}"#, "settings.tuning.ism.points: must be in 16..=65536, got 8"),
        (r#"{"pull_push_levels": 5}"#, "settings.tuning.ism.pull_push_levels: must be in 0..=4, got 5"),
        (r#"{"pull_threshold": 0}"#, "settings.tuning.ism.pull_threshold: must be in (0, 1], got 0"),
        (r#"{"push_threshold": 2}"#, "settings.tuning.ism.push_threshold: must be in (0, 1], got 2"),
        (r#"{"count": 1024, "resolution": 256}"#, "settings.tuning.ism.resolution: 1024 maps of 256x256 texels"),
        (
            r#"{"count": 4096, "resolution": 32, "points": 65536}"#,
            "settings.tuning.ism.points: 4096 maps of 65536 points",
        ),
        (r#"{"spread": 1}"#, "settings.tuning.ism.spread: unknown field"),
        (r#"{"slope_bias": -1}"#, "settings.tuning.ism.slope_bias: must be in [0, 16], got -1"),
    ] {
        let message = error_of(&with_tuning(&format!(r#"{{"ism": {ism}}}"#)));
        assert!(message.starts_with(want), "{ism}: {message}");
    }
    for (settings, field) in [
        (r#"{"environment": {"albedo": 0}}"#, "settings.environment.albedo: must be in (0, 1]"),
        (r#"{"environment": {"albedo": 1.5}}"#, "settings.environment.albedo: must be in (0, 1]"),
        (r#"{"environment": {"source": "auto", "calibrate_map": true}}"#, "settings.environment.calibrate_map"),
    ] {
        let message = error_of(&with_settings(settings));
        assert!(message.starts_with(field), "{settings}: {message}");
    }
    let message = error_of(&with_settings(r#"{"environment": {"distribution": "sideways"}}"#));
    assert!(message.starts_with("settings.environment.distribution: unknown variant `sideways`"), "{message}");
    let text = with_settings(r#"{"environment": {"source": "auto", "distribution": "overcast"}}"#);
    let d = SceneDescription::from_json_str(&text).expect("parses");
    d.validate().expect("valid");
    assert_eq!(d.settings.environment.distribution, EnvironmentDistribution::Overcast);
    let message = error_of(&with_tuning(r#"{"rsm_resolution": 4}"#));
    assert_eq!(message, "settings.tuning.rsm_resolution: must be in 8..=2048, got 4");
    let message = error_of(&with_tuning(r#"{"interpolation_neighbours": 17}"#));
    assert_eq!(message, "settings.tuning.interpolation_neighbours: must be in 1..=16, got 17");
    let message = error_of(&with_settings(r#"{"exposure": 0}"#));
    assert_eq!(message, "settings.exposure: must be > 0, got 0");
    let message = error_of(&with_settings(r#"{"exposure": null, "gamma": 2.2}"#));
    assert!(message.starts_with("settings.gamma: unknown field"), "{message}");
}

#[test]
fn json_materials_are_checked() {
    let with_material = |material: &str| {
        edit(r#""sparse_points": 16"#, &format!(r#""sparse_points": 16, "materials": {{"leftWall": {material}}}"#))
    };
    let message = error_of(&with_material(r#"{"diffuse": [0.5, 1.5, 0.5]}"#));
    assert_eq!(message, "meshes[0].materials.leftWall.diffuse[1]: must be in [0, 1], got 1.5");
    let message = error_of(&with_material(r#"{"diffuse": [0.7, 0.5, 0.5], "specular": [0.4, 0, 0]}"#));
    assert!(
        message.starts_with("meshes[0].materials.leftWall.specular[0]: diffuse + specular must be <= 1"),
        "{message}"
    );
    let message = error_of(&with_material(r#"{"exponent": 20000}"#));
    assert_eq!(message, "meshes[0].materials.leftWall.exponent: must be in [0, 10000], got 20000");
    let message = error_of(&with_material(r#"{"roughness": 0.5}"#));
    assert!(message.starts_with("meshes[0].materials.leftWall.roughness: unknown field"), "{message}");
    // 0.7 + 0.3 is 1 up to rounding: accepted.
    let text = with_material(r#"{"diffuse": [0.7, 0.7, 0.7], "specular": [0.3, 0.3, 0.3], "exponent": 0}"#);
    let description = SceneDescription::from_json_str(&text).expect("parses");
    description.validate().expect("valid");
    let material = description.meshes[0].materials["leftWall"].to_material();
    assert_eq!(material.specular, Vec3::splat(0.3));
    assert_eq!(material.exponent, 0.0);

    let message = error_of(&with_material(r#"{"diffuse_texture": " "}"#));
    assert_eq!(message, "meshes[0].materials.leftWall.diffuse_texture: must name an image file, got an empty string");
    let text = with_material(r#"{"diffuse_texture": "tex/wall.png"}"#);
    let description = SceneDescription::from_json_str(&text).expect("parses");
    description.validate().expect("valid");
    let material = &description.meshes[0].materials["leftWall"];
    assert_eq!(material.diffuse_texture.as_deref(), Some("tex/wall.png"));
    let json = serde_json::to_string(&description).expect("serializes");
    assert_eq!(SceneDescription::from_json_str(&json).expect("parses again"), description);
}

#[test]
fn transform_accepts_uniform_and_per_axis_scale() {
    let text = edit(
        r#""sparse_points": 16"#,
        r#""sparse_points": 16, "transform": {"translation": [1, 2, 3], "rotation_deg": [0, 90, 0], "scale": [1, 2, 3]}"#,
    );
    let description = SceneDescription::from_json_str(&text).expect("parses");
    description.validate().expect("valid");
    let matrix = description.meshes[0].transform.to_matrix();
    // +X scaled by 1 and rotated 90 degrees about Y goes to -Z.
    let x = matrix.transform_vector3(DVec3::X);
    assert!(x.abs_diff_eq(DVec3::NEG_Z, 1e-12), "{x}");
    let y = matrix.transform_vector3(DVec3::Y);
    assert!(y.abs_diff_eq(DVec3::new(0.0, 2.0, 0.0), 1e-12), "{y}");
    assert!(matrix.transform_point3(DVec3::ZERO).abs_diff_eq(DVec3::new(1.0, 2.0, 3.0), 1e-12));

    let message = error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": 16, "transform": {"scale": [1, 2]}"#));
    assert!(message.starts_with("meshes[0].transform.scale"), "{message}");
    let message = error_of(&edit(r#""sparse_points": 16"#, r#""sparse_points": 16, "transform": {"scale": "big"}"#));
    assert!(message.contains("a number or an array [x, y, z]"), "{message}");
}

#[test]
fn syntax_errors_report_the_position() {
    let error = SceneDescription::from_json_str("{\"meshes\": [\n  {\"obj\": }]}").expect_err("bad JSON");
    match error {
        SceneError::Json { field, line, .. } => {
            assert_eq!(field, "meshes[0].obj");
            assert_eq!(line, 2);
        }
        other => panic!("unexpected {other:?}"),
    }
    let message = error_of("");
    assert!(message.starts_with("(root):"), "{message}");
}

#[test]
fn json_path_tracks_nesting() {
    let text = r#"{"a": {"b": [1, {"c": "x,y"}, [2, 3]]}, "d": 4}"#;
    let at = |needle: &str| json_path_at(text, text.find(needle).expect("needle") + needle.len());
    assert_eq!(at(r#""c": "x"#), "a.b[1].c");
    assert_eq!(at("[2"), "a.b[2][0]");
    assert_eq!(at("3"), "a.b[2][1]");
    assert_eq!(at(r#""d": 4"#), "d");
    assert_eq!(json_path_at(r#"{"we ird": 1"#, 12), r#"["we ird"]"#);
}

#[test]
fn descriptions_round_trip_through_json() {
    let text = edit(
        r#""sparse_points": 16"#,
        r#""sparse_points": 16, "transform": {"scale": [1, 2, 3]}, "material": {"exponent": 5}, "skip_groups": ["light"]"#,
    );
    let description = SceneDescription::from_json_str(&text).expect("parses");
    let json = serde_json::to_string(&description).expect("serializes");
    let again = SceneDescription::from_json_str(&json).expect("parses again");
    assert_eq!(description, again);
}

/// A research knob in its old place, directly under `settings`, is an error naming the key and
/// where it moved; under `tuning` it is accepted.
#[test]
fn settings_in_their_old_place_say_where_they_moved() {
    let with_settings = |settings: &str| edit(r#""meshes""#, &format!(r#""settings": {settings}, "meshes""#));
    for (old, value, moved) in [
        ("rsm_resolution", "160", "rsm_resolution"),
        ("interpolation_neighbours", "4", "interpolation_neighbours"),
        ("visibility", r#""disks""#, "visibility"),
        ("occlusion", r#""off""#, "visibility"),
        ("occlusion_rule", r#""sum""#, "occlusion_rule"),
        ("sparse", r#"{"near_field": 4}"#, "sparse"),
        ("clusters", r#"{"count": 8}"#, "clusters"),
        ("ism", r#"{"count": 8}"#, "ism"),
        ("direct", r#"{"max_lights": 8}"#, "direct"),
        ("second_bounce", r#"{"vals": 8}"#, "second_bounce"),
    ] {
        let message = error_of(&with_settings(&format!(r#"{{"glossy": true, "{old}": {value}}}"#)));
        let want = format!("settings.{old}: moved to settings.tuning.{moved} (JSON line");
        assert!(message.starts_with(&want), "{old}: {message}");
        let tuned = with_settings(&format!(r#"{{"tuning": {{"{moved}": {value}}}}}"#));
        SceneDescription::from_json_str(&tuned).and_then(|d| d.validate()).expect("valid under tuning");
    }
    // The moved keys are not written back.
    let description = SceneDescription::from_json_str(MINIMAL).expect("parses");
    let json = serde_json::to_value(&description.settings).expect("serializes");
    assert_eq!(json.as_object().map(|o| o.contains_key("rsm_resolution")), Some(false), "{json}");
}

#[test]
fn quality_and_budget_are_read_and_checked() {
    let with_settings = |settings: &str| edit(r#""meshes""#, &format!(r#""settings": {settings}, "meshes""#));
    let d =
        SceneDescription::from_json_str(&with_settings(r#"{"quality": "fast", "budget_ms": 33.3}"#)).expect("parses");
    d.validate().expect("valid");
    assert_eq!((d.settings.quality, d.settings.budget_ms), (Quality::Fast, Some(33.3)));
    assert_eq!(error_of(&with_settings(r#"{"budget_ms": 0}"#)), "settings.budget_ms: must be in [0.1, 600000], got 0");
    let message = error_of(&with_settings(r#"{"quality": "best"}"#));
    assert!(message.starts_with("settings.quality: unknown variant `best`"), "{message}");
}
