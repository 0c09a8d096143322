//! Fuzzing, bounded so it runs in CI: proptest over the stream message decoder, the scene
//! description parser (the service's admission of scenes included) and the glTF reader (mutated
//! `.glb` bytes, and `.gltf` fields replaced). None may panic, and what they accept must be
//! consistent. `PROPTEST_CASES=N` runs more cases locally.

use proptest::prelude::*;
use prost::Message as _;
use relume::service::Limits;
use relume::service::wire::proto::{self, envelope::Body};
use relume::service::wire::{self, ClientMessage, PROTOCOL_VERSION};
use serde_json::Value;

use super::fixture;

const CASES: u32 = 256;

fn limits() -> Limits {
    Limits { max_message_bytes: 1 << 16, max_frame_side: 64, ..Limits::default() }
}

/// A valid frame envelope, `w` x `h`.
fn valid_frame(w: u32, h: u32) -> Vec<u8> {
    let pixels = (w * h) as usize;
    let frame = proto::RgbdFrame {
        frame_id: 1,
        timestamp: 0.5,
        intrinsics: Some(proto::Intrinsics { width: w, height: h, fx: 10.0, fy: 10.0, cx: 1.0, cy: 1.0 }),
        color: Some(proto::Color { data: Some(proto::color::Data::Rgb8(vec![7; pixels * 3])) }),
        depth: Some(proto::Depth { data: Some(proto::depth::Data::F32Metres(1.5f32.to_le_bytes().repeat(pixels))) }),
        camera_to_world: Some(proto::Pose {
            transform: Some(proto::pose::Transform::TranslationRotation(proto::TranslationRotation {
                translation: Some(proto::Vec3 { x: 1.0, y: 2.0, z: 3.0 }),
                rotation: Some(proto::Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }),
            })),
            translation_f64: None,
        }),
    };
    proto::Envelope { version: PROTOCOL_VERSION, body: Some(Body::RgbdFrame(frame)) }.encode_to_vec()
}

/// A valid control envelope touching every part.
fn valid_control() -> Vec<u8> {
    let v = |x, y, z| Some(proto::Vec3 { x, y, z });
    let control = proto::Control {
        request_id: 3,
        camera: Some(proto::Camera {
            position: v(0.0, 1.0, 3.0),
            target: v(0.0, 0.0, 0.0),
            up: None,
            fov_y_deg: 40.0,
            width: 32,
            height: 32,
        }),
        light: Some(proto::LightOverride { intensity: v(1.0, 1.0, 1.0), ..Default::default() }),
        model_transforms: vec![proto::ModelTransform {
            mesh_index: 0,
            translation: v(0.0, 0.0, 0.0),
            rotation_deg: v(0.0, 45.0, 0.0),
            scale: v(1.0, 2.0, 1.0),
        }],
        quality: Some(proto::Quality { method: 1, component: 2, exposure: Some(1.0), format: 1 }),
        rgbd: Some(proto::RgbdSettings { grid_step: Some(4), max_depth: Some(5.0), ..Default::default() }),
        render: Some(proto::RenderSettings {
            occlusion: Some(proto::Occlusion::Disks as i32),
            glossy: Some(false),
            ..Default::default()
        }),
    };
    proto::Envelope { version: PROTOCOL_VERSION, body: Some(Body::Control(control)) }.encode_to_vec()
}

/// What a decoded message must satisfy.
fn check(message: &ClientMessage, limits: &Limits) {
    match message {
        ClientMessage::Frame(m) => {
            let i = m.frame.intrinsics;
            assert!(
                i.width >= 1 && i.height >= 1 && i.width <= limits.max_frame_side && i.height <= limits.max_frame_side
            );
            assert!(i.fx.is_finite() && i.fx > 0.0 && i.fy.is_finite() && i.fy > 0.0);
            let pixels = i.width as usize * i.height as usize;
            assert_eq!((m.frame.color.len(), m.frame.depth.len()), (pixels, pixels));
            assert!(m.frame.depth.iter().all(|d| !d.is_infinite()));
            assert!(m.frame.timestamp.is_finite());
            let pose = m.frame.camera_to_world;
            assert!(pose.is_finite());
            assert!((pose.matrix3.determinant() - 1.0).abs() < 1e-2, "{pose}");
        }
        ClientMessage::Control(c) => {
            if let Some(camera) = &c.camera {
                camera.validate("camera").expect("a decoded camera is valid");
            }
            if let Some(exposure) = c.quality.and_then(|q| q.exposure) {
                assert!(exposure.is_finite() && exposure > 0.0);
            }
        }
    }
}

/// `bytes` with `edits` applied: (position, kind, byte) overwrite, insert, delete or truncate.
fn mutate(mut bytes: Vec<u8>, edits: &[(usize, u8, u8)]) -> Vec<u8> {
    for &(at, kind, byte) in edits {
        if bytes.is_empty() {
            bytes.push(byte);
            continue;
        }
        let at = at % bytes.len();
        match kind % 4 {
            0 => bytes[at] = byte,
            1 => bytes.insert(at, byte),
            2 => {
                bytes.remove(at);
            }
            _ => bytes.truncate(at),
        }
    }
    bytes
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    #[test]
    fn decoding_arbitrary_bytes_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
        let limits = limits();
        if let Ok(message) = wire::decode(&bytes, &limits) {
            check(&message, &limits);
        }
    }

    #[test]
    fn decoding_mutated_envelopes_never_panics(
        which in 0..3usize,
        w in 1..6u32,
        h in 1..6u32,
        edits in proptest::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..8),
    ) {
        let limits = limits();
        let valid = match which {
            0 => valid_frame(w, h),
            1 => valid_control(),
            _ => {
                let mut frame = proto::Envelope::decode(valid_frame(w, h).as_slice()).expect("valid");
                if let Some(Body::RgbdFrame(f)) = &mut frame.body {
                    f.color = Some(proto::Color { data: Some(proto::color::Data::Png(vec![0x89, b'P', b'N', b'G'])) });
                }
                frame.encode_to_vec()
            }
        };
        if which < 2 {
            prop_assert!(wire::decode(&valid, &limits).is_ok());
        }
        if let Ok(message) = wire::decode(&mutate(valid, &edits), &limits) {
            check(&message, &limits);
        }
    }

    #[test]
    fn decoding_arbitrary_field_values_never_panics(
        width in 0..80u32,
        height in 0..80u32,
        fx in any::<f32>(),
        timestamp in any::<f64>(),
        color_len in 0..2000usize,
        depth_len in 0..2000usize,
        units_per_metre in any::<f32>(),
        quaternion in any::<[f32; 4]>(),
        matrix in proptest::collection::vec(any::<f32>(), 0..20),
        use_matrix in any::<bool>(),
    ) {
        let transform = if use_matrix {
            proto::pose::Transform::Matrix(proto::Matrix4 { column_major: matrix })
        } else {
            let [x, y, z, w] = quaternion;
            proto::pose::Transform::TranslationRotation(proto::TranslationRotation {
                translation: Some(proto::Vec3 { x: 0.0, y: 0.0, z: 0.0 }),
                rotation: Some(proto::Quaternion { x, y, z, w }),
            })
        };
        let frame = proto::RgbdFrame {
            frame_id: 9,
            timestamp,
            intrinsics: Some(proto::Intrinsics { width, height, fx, fy: 10.0, cx: 0.0, cy: 0.0 }),
            color: Some(proto::Color { data: Some(proto::color::Data::Rgb8(vec![1; color_len])) }),
            depth: Some(proto::Depth {
                data: Some(proto::depth::Data::U16(proto::DepthU16 { data: vec![2; depth_len], units_per_metre })),
            }),
            camera_to_world: Some(proto::Pose { transform: Some(transform), translation_f64: None }),
        };
        let bytes = proto::Envelope { version: PROTOCOL_VERSION, body: Some(Body::RgbdFrame(frame)) }.encode_to_vec();
        let limits = limits();
        match wire::decode(&bytes, &limits) {
            Ok(message) => check(&message, &limits),
            Err(error) => {
                prop_assert!(!error.message.is_empty());
                prop_assert_eq!(error.frame_id, Some(9));
            }
        }
    }
}

/// Keys of the scene format, so that generated objects reach past the first unknown field.
const KEYS: &[&str] = &[
    "meshes",
    "light",
    "camera",
    "settings",
    "tuning",
    "quality",
    "obj",
    "obj_text",
    "sparse_points",
    "transform",
    "material",
    "materials",
    "skip_groups",
    "position",
    "direction",
    "target",
    "up",
    "fov_y_deg",
    "width",
    "height",
    "inner_angle_deg",
    "outer_angle_deg",
    "intensity",
    "rsm_resolution",
    "diffuse",
    "specular",
    "exponent",
    "diffuse_texture",
    "scale",
    "translation",
    "rotation_deg",
    "exposure",
    "glossy",
    "seed",
    "occlusion",
];

fn json_value() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::Bool),
        any::<i64>().prop_map(Value::from),
        any::<f64>().prop_map(|f| serde_json::Number::from_f64(f).map_or(Value::Null, Value::Number)),
        prop_oneof![Just("../Cargo.toml".to_owned()), Just("meshes".to_owned()), ".{0,12}"].prop_map(Value::String),
    ];
    leaf.prop_recursive(4, 64, 6, |inner| {
        prop_oneof![
            proptest::collection::vec(inner.clone(), 0..6).prop_map(Value::Array),
            proptest::collection::vec((proptest::sample::select(KEYS), inner), 0..6)
                .prop_map(|entries| Value::Object(entries.into_iter().map(|(k, v)| (k.to_owned(), v)).collect())),
        ]
    })
}

/// The small fixture scene, mesh paths relative to `fixtures/`.
fn fixture_scene() -> Value {
    let text = std::fs::read_to_string(fixture("scenes/cornell_bunny_small.json")).expect("fixture");
    serde_json::from_str(&text.replace("\"../meshes/", "\"meshes/")).expect("JSON")
}

/// Every path to a leaf of `value`, as JSON pointers.
fn leaves(value: &Value, at: String, out: &mut Vec<String>) {
    match value {
        Value::Object(map) => map.iter().for_each(|(k, v)| leaves(v, format!("{at}/{k}"), out)),
        Value::Array(items) => items.iter().enumerate().for_each(|(i, v)| leaves(v, format!("{at}/{i}"), out)),
        _ => out.push(at),
    }
}

/// Parses and admits `text` as the service would (no mesh is loaded).
fn admit(text: &str) {
    let assets = std::fs::canonicalize(fixture("")).expect("fixtures");
    let Ok(description) = relume::scene::SceneDescription::from_json_str(text) else { return };
    match relume::service::scenes::admit(&description, &assets, &Limits::default()) {
        Ok(()) => description.validate().expect("an admitted description is valid"),
        Err(error) => assert!(!error.message.is_empty()),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    #[test]
    fn parsing_arbitrary_json_never_panics(value in json_value()) {
        admit(&value.to_string());
    }

    #[test]
    fn parsing_mutated_scenes_never_panics(choice in any::<proptest::sample::Index>(), replacement in json_value()) {
        let mut scene = fixture_scene();
        let mut paths = Vec::new();
        leaves(&scene, String::new(), &mut paths);
        let path = choice.get(&paths);
        *scene.pointer_mut(path).expect("a leaf") = replacement;
        admit(&scene.to_string());
    }

    #[test]
    fn parsing_arbitrary_text_never_panics(text in ".{0,200}") {
        admit(&text);
    }
}

/// Loads `bytes` as the glTF of a one-mesh scene (as `name` in `dir`) and as a whole
/// `.glb` scene: never a panic, and an error names the field that led to the file.
fn load_gltf(dir: &std::path::Path, name: &str, bytes: &[u8]) {
    std::fs::write(dir.join(name), bytes).expect("write");
    let mesh = format!(
        r#"{{"meshes": [{{"gltf": "{name}", "sparse_points": 8}}],
            "camera": {{"position": [0, 1, 3], "target": [0, 1, 0], "fov_y_deg": 40, "width": 8, "height": 8}}}}"#
    );
    if let Err(error) = relume::scene::Scene::from_json_str(&mesh, dir) {
        // The mesh itself (its extent, transforms applied) or one of its fields.
        let error = error.to_string();
        assert!(error.starts_with("meshes[0].") || error.starts_with("meshes[0]: "), "{error}");
    }
    let whole = format!(r#"{{"gltf": "{name}", "sparse_points": 8, "width": 8, "height": 8}}"#);
    if let Err(error) = relume::scene::Scene::from_json_str(&whole, dir) {
        assert!(!error.to_string().is_empty());
    }
}

/// Leaves a glTF field may be replaced by: the values that break naive readers.
fn gltf_value() -> impl Strategy<Value = Value> {
    prop_oneof![
        (0..8u64).prop_map(Value::from),
        any::<i64>().prop_map(Value::from),
        Just(Value::from(u32::MAX)),
        Just(Value::from(u64::MAX)),
        any::<f64>().prop_map(|f| serde_json::Number::from_f64(f).map_or(Value::Null, Value::Number)),
        Just(Value::from(1e39)),
        Just(Value::Null),
        Just(Value::Array(Vec::new())),
        prop_oneof![Just("../Cargo.toml".to_owned()), Just("data:,".to_owned()), ".{0,8}"].prop_map(Value::String),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    #[test]
    fn loading_mutated_glb_never_panics(edits in proptest::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..8)) {
        let dir = super::scratch("fuzz-glb");
        let glb = std::fs::read(fixture("meshes/cornell_box_gltf/CornellBox-Original.glb")).expect("fixture");
        load_gltf(&dir, "box.glb", &mutate(glb, &edits));
    }

    #[test]
    fn loading_gltf_with_a_mutated_field_never_panics(choice in any::<proptest::sample::Index>(), replacement in gltf_value()) {
        let dir = super::scratch("fuzz-gltf");
        std::fs::copy(fixture("meshes/cornell_box_gltf/CornellBox-Original.bin"), dir.join("CornellBox-Original.bin")).expect("copy");
        let text = std::fs::read_to_string(fixture("meshes/cornell_box_gltf/CornellBox-Original.gltf")).expect("fixture");
        let mut gltf: Value = serde_json::from_str(&text).expect("JSON");
        let mut paths = Vec::new();
        leaves(&gltf, String::new(), &mut paths);
        let path = choice.get(&paths);
        *gltf.pointer_mut(path).expect("a leaf") = replacement;
        load_gltf(&dir, "box.gltf", gltf.to_string().as_bytes());
    }
}
