use super::super::test_util::{TempDir, scene_json};
use super::scene::POINT_CONE_MARGIN;
use super::*;
use serde_json::{Value, json};

/// A glTF document around `nodes` with one triangle mesh (positions, indices and texture
/// coordinates in one base64 buffer), written as `name` (`.gltf`, or `.glb` with the
/// buffer in the binary chunk); `edit` changes the JSON before it is written.
fn write(dir: &TempDir, name: &str, nodes: Value, edit: impl FnOnce(&mut Value)) {
    let positions: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let texcoords: [[f32; 2]; 3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 0.25]];
    let mut bin: Vec<u8> = positions.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
    bin.extend([0u32, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
    bin.extend(texcoords.iter().flatten().flat_map(|x| x.to_le_bytes()));
    let mut doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.as_array().map_or(0, Vec::len)).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 1, "material": 0}]}],
        "materials": [{"name": "red", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0}}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"},
            {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 12},
            {"buffer": 0, "byteOffset": 48, "byteLength": 24}
        ],
        "buffers": [{"byteLength": bin.len()}]
    });
    edit(&mut doc);
    let path = dir.path().join(name);
    if name.ends_with(".glb") {
        let extra = doc["buffers"][0]["byteLength"].as_u64().unwrap_or(0) as usize;
        bin.resize(bin.len().max(extra), 0);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let mut text = doc.to_string().into_bytes();
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let mut glb = b"glTF".to_vec();
        glb.extend(2u32.to_le_bytes());
        glb.extend(((12 + 8 + text.len() + 8 + bin.len()) as u32).to_le_bytes());
        glb.extend((text.len() as u32).to_le_bytes());
        glb.extend(b"JSON");
        glb.extend(text);
        glb.extend((bin.len() as u32).to_le_bytes());
        glb.extend(b"BIN\0");
        glb.extend(bin);
        std::fs::write(path, glb).expect("write glb");
    } else {
        if doc["buffers"][0].get("uri").is_none() {
            let data = base64::engine::general_purpose::STANDARD.encode(&bin);
            doc["buffers"][0]["uri"] = json!(format!("data:application/octet-stream;base64,{data}"));
        }
        std::fs::write(path, doc.to_string()).expect("write gltf");
    }
}

fn load_scene(dir: &TempDir, file: &str) -> Result<super::super::Scene, SceneError> {
    let text = scene_json(&format!(r#""gltf": "{file}", "sparse_points": 4"#));
    super::super::Scene::from_json_str(&text, dir.path())
}

fn error(dir: &TempDir, file: &str) -> String {
    load_scene(dir, file).map(|_| ()).expect_err("an error").to_string()
}

#[test]
fn pbr_maps_to_energy_conserving_phong() {
    let dielectric = phong_from_pbr(Pbr { base_color: Vec3::splat(0.8), metallic: 0.0, ..Pbr::default() });
    assert!(dielectric.specular.abs_diff_eq(Vec3::splat(0.04), 1e-6), "{dielectric:?}");
    assert!(dielectric.diffuse.abs_diff_eq(Vec3::splat(0.8 * 0.96), 1e-6), "{dielectric:?}");
    assert_eq!(dielectric.exponent, 0.0, "roughness 1 is the widest lobe");
    let gold = Vec3::new(1.0, 0.77, 0.34);
    let metal = phong_from_pbr(Pbr { base_color: gold, roughness: 0.5, ..Pbr::default() });
    assert_eq!(metal.diffuse, Vec3::ZERO);
    assert!(metal.specular.abs_diff_eq(gold, 1e-6));
    // alpha = 0.25: Blinn-Phong 2 / alpha^2 - 2 = 30, over 4 for the reflected lobe.
    assert!((metal.exponent - 7.5).abs() < 1e-4, "{metal:?}");
    assert_eq!(phong_from_pbr(Pbr { roughness: 0.0, ..Pbr::default() }).exponent, Material::MAX_EXPONENT);
    let matte = phong_from_pbr(Pbr { base_color: Vec3::splat(0.5), metallic: 0.0, specular: 0.0, ..Pbr::default() });
    assert_eq!((matte.diffuse, matte.specular), (Vec3::splat(0.5), Vec3::ZERO), "specularFactor 0 is Lambertian");
    for i in 0..=10 {
        for j in 0..=10 {
            let (t, u) = (i as f32 / 10.0, j as f32 / 10.0);
            let m = phong_from_pbr(Pbr {
                base_color: Vec3::new(1.0, t, u),
                metallic: t,
                roughness: u,
                specular_color: Vec3::splat(30.0 * u),
                ior: 1.0 + 3.0 * t,
                ..Pbr::default()
            });
            assert!((m.diffuse + m.specular).max_element() <= 1.0 + 1e-6, "{t} {u}: {m:?}");
            assert!(m.diffuse.min_element() >= 0.0 && m.specular.min_element() >= 0.0);
        }
    }
}

#[test]
fn node_transforms_are_baked_and_mirrors_keep_facing() {
    let dir = TempDir::new("gltf-nodes");
    let nodes = json!([
        {"name": "parent", "translation": [10, 0, 0], "children": [1]},
        {"name": "mirrored", "scale": [-2, 2, 2], "mesh": 0}
    ]);
    write(&dir, "t.gltf", nodes, |doc| doc["scenes"][0]["nodes"] = json!([0]));
    let scene = load_scene(&dir, "t.gltf").expect("loads");
    let mesh = &scene.meshes[0];
    let (lo, hi) = mesh.positions.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    assert!(lo.abs_diff_eq(Vec3::new(8.0, 0.0, 0.0), 1e-6) && hi.abs_diff_eq(Vec3::new(10.0, 2.0, 0.0), 1e-6));
    // The file's triangle faces +Z; mirrored in x it still faces +Z once its winding flips.
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
        assert!((b - a).cross(c - a).z > 0.0, "winding kept facing +Z: {t:?}");
    }
    assert!(mesh.normals.iter().all(|n| n.abs_diff_eq(Vec3::Z, 1e-6)));
    let material = scene.materials[mesh.triangle_materials[0] as usize];
    assert!(material.diffuse.abs_diff_eq(Vec3::new(0.8, 0.1, 0.1) * 0.96, 1e-6));
    // v flipped to the OBJ convention: the vertex at glTF v = 0.25 has v = 0.75.
    assert!(mesh.texcoords.iter().any(|t| t.abs_diff_eq(Vec2::new(0.0, 0.75), 1e-6)));
}

#[test]
fn embedded_glb_texture_is_loaded() {
    let dir = TempDir::new("gltf-texture");
    let mut png = Vec::new();
    image::RgbaImage::from_pixel(2, 2, image::Rgba([10, 200, 30, 255]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .expect("encode PNG");
    let png_len = png.len();
    let nodes = json!([{"mesh": 0}]);
    write(&dir, "t.glb", nodes, |doc| {
        doc["buffers"][0]["byteLength"] = json!(72 + png_len);
        doc["bufferViews"]
            .as_array_mut()
            .expect("views")
            .push(json!({"buffer": 0, "byteOffset": 72, "byteLength": png_len}));
        doc["images"] = json!([{"bufferView": 3, "mimeType": "image/png"}]);
        doc["textures"] = json!([{"source": 0}]);
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    });
    // The PNG goes where the writer zero-filled the declared length.
    let mut bytes = std::fs::read(dir.path().join("t.glb")).expect("read");
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().expect("4 bytes")) as usize;
    let bin_start = 20 + json_len + 8;
    bytes[bin_start + 72..bin_start + 72 + png_len].copy_from_slice(&png);
    std::fs::write(dir.path().join("t.glb"), bytes).expect("write");
    let scene = load_scene(&dir, "t.glb").expect("loads");
    assert_eq!(scene.textures.len(), 1);
    assert_eq!(&scene.textures[0].rgba8[..4], &[10, 200, 30, 255]);
    assert!(scene.textures[0].path.to_string_lossy().ends_with("t.glb#images[0]"));
    assert_eq!(scene.materials[0].diffuse_texture, Some(0));
}

#[test]
fn malformed_files_name_the_object_and_field() {
    let dir = TempDir::new("gltf-errors");
    let mesh_node = || json!([{"name": "thing", "mesh": 0}]);
    // (file, how to break it, what the error must say)
    type Case<'a> = (&'a str, Box<dyn FnOnce(&mut Value)>, &'a str);
    let cases: Vec<Case> = vec![
        (
            "index.gltf",
            Box::new(|d| d["accessors"][1]["count"] = json!(6)),
            "accessors[1] (indices): byteOffset 0 + 6 elements",
        ),
        (
            "type.gltf",
            Box::new(|d| d["accessors"][0]["componentType"] = json!(5123)),
            "accessors[0] (POSITION).componentType",
        ),
        ("mode.gltf", Box::new(|d| d["meshes"][0]["primitives"][0]["mode"] = json!(1)), "meshes[0].primitives[0].mode"),
        (
            "climb.gltf",
            Box::new(|d| d["buffers"][0]["uri"] = json!("../secret.bin")),
            "buffers[0].uri: `../secret.bin` is not a relative path",
        ),
        (
            "short.gltf",
            Box::new(|d| d["buffers"][0]["byteLength"] = json!(4096)),
            "buffers[0].byteLength: declares 4096 bytes, the data has 72",
        ),
        ("cycle.gltf", Box::new(|d| d["nodes"][0]["children"] = json!([0])), "nodes[0] (`thing`): reached twice"),
        (
            "sparse.gltf",
            Box::new(|d| {
                d["accessors"][0]["sparse"] = json!({"count": 1, "indices": {"bufferView": 1, "componentType": 5125}, "values": {"bufferView": 0}})
            }),
            "accessors[0] (POSITION).sparse",
        ),
    ];
    for (file, edit, expected) in cases {
        write(&dir, file, mesh_node(), edit);
        let message = error(&dir, file);
        assert!(message.starts_with("meshes[0].gltf: "), "{file}: {message}");
        assert!(message.contains(expected), "{file}: expected `{expected}` in `{message}`");
    }
    // An index past the vertices is found when the indices are read.
    write(&dir, "range.gltf", mesh_node(), |_| {});
    let mut doc: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("range.gltf")).expect("read")).expect("JSON");
    let mut bin = base64::engine::general_purpose::STANDARD
        .decode(doc["buffers"][0]["uri"].as_str().expect("uri").split(',').nth(1).expect("payload"))
        .expect("base64");
    bin[40..44].copy_from_slice(&7u32.to_le_bytes());
    let data = base64::engine::general_purpose::STANDARD.encode(&bin);
    doc["buffers"][0]["uri"] = json!(format!("data:application/octet-stream;base64,{data}"));
    std::fs::write(dir.path().join("range.gltf"), doc.to_string()).expect("write");
    let message = error(&dir, "range.gltf");
    assert!(
        message.contains("nodes[0] (`thing`) meshes[0].primitives[0]: index 7 is out of range (3 vertices)"),
        "{message}"
    );

    let text = scene_json(r#""gltf": "range.gltf", "sparse_points": 4, "skip_groups": ["lamp"]"#);
    let message =
        super::super::Scene::from_json_str(&text, dir.path()).map(|_| ()).expect_err("unknown node").to_string();
    assert!(
        message.starts_with("meshes[0].skip_groups[0]: ")
            && message.contains("no node named `lamp` (the file has: thing)"),
        "{message}"
    );
    let message = error(&dir, "missing.gltf");
    assert!(message.starts_with("meshes[0].gltf: ") && message.contains("cannot read"), "{message}");
    std::fs::write(dir.path().join("junk.glb"), b"glTF\x02\0\0\0\xff\xff\xff\xff").expect("write");
    let message = error(&dir, "junk.glb");
    assert!(message.contains("not a valid glTF 2.0 file"), "{message}");
}

#[test]
fn triangles_are_counted_against_the_limit_before_reading() {
    let dir = TempDir::new("gltf-budget");
    // Four instances of the one-triangle mesh; the buffer's data is never read because
    // the count is over before (its uri names a file that does not exist).
    let nodes = json!([{"mesh": 0}, {"mesh": 0}, {"mesh": 0}, {"mesh": 0}]);
    write(&dir, "many.gltf", nodes, |d| d["buffers"][0]["uri"] = json!("absent.bin"));
    let text = scene_json(r#""gltf": "many.gltf", "sparse_points": 4"#);
    let description = SceneDescription::from_json_str(&text).expect("parses");
    let error =
        super::super::Scene::from_description_within(&description, dir.path(), 3).map(|_| ()).expect_err("over");
    assert!(matches!(error, SceneError::TooManyTriangles { limit: 3, .. }), "{error}");
    assert!(error.to_string().contains("at least 4 triangles"), "{error}");
    let message =
        super::super::Scene::from_description_within(&description, dir.path(), 4).map(|_| ()).expect_err("absent");
    assert!(message.to_string().contains("buffers[0].uri: cannot read"), "{message}");
}

#[test]
fn whole_scene_lights_and_cameras_are_checked() {
    let dir = TempDir::new("gltf-scene");
    let scene = |file: &str| {
        let text = format!(r#"{{"gltf": "{file}", "sparse_points": 4, "width": 32, "height": 16}}"#);
        GltfSceneDescription::from_json_str(&text).expect("parses").to_scene_description(dir.path())
    };
    let lights = |kind: &str| {
        let mut light = json!({"type": kind, "intensity": 683, "color": [1, 0.5, 0.5]});
        if kind == "spot" {
            light["spot"] = json!({"outerConeAngle": 0.5});
        }
        json!({"KHR_lights_punctual": {"lights": [light]}})
    };
    let nodes = json!([
        {"mesh": 0},
        {"name": "lamp", "translation": [0, 3, 0], "rotation": [-0.70710677, 0, 0, 0.70710677], "extensions": {"KHR_lights_punctual": {"light": 0}}},
        {"name": "eye", "translation": [0, 1, 5], "camera": 0}
    ]);
    let camera = json!([{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.1}}]);
    for (file, kind, cameras, expected) in [
        (
            "sun.gltf",
            "directional",
            camera.clone(),
            Some("nodes[1] (`lamp`): its KHR_lights_punctual light (`lights[0]`): a directional light"),
        ),
        (
            "spot.gltf",
            "spot",
            json!([{"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 9}}]),
            Some("nodes[2] (`eye`): cameras[0]: an orthographic camera"),
        ),
        ("good.gltf", "spot", camera.clone(), None),
    ] {
        write(&dir, file, nodes.clone(), |d| {
            d["extensionsUsed"] = json!(["KHR_lights_punctual"]);
            d["extensions"] = lights(kind);
            d["cameras"] = cameras;
        });
        match (scene(file), expected) {
            (Err(error), Some(expected)) => {
                let message = error.to_string();
                assert!(message.starts_with("gltf: ") && message.contains(expected), "{file}: {message}");
            }
            (Ok(description), None) => {
                let light = description.light.as_ref().expect("the spot light");
                assert!(glam::DVec3::from(light.position).abs_diff_eq(glam::DVec3::new(0.0, 3.0, 0.0), 1e-6));
                assert!(Vec3::from(light.direction).abs_diff_eq(Vec3::NEG_Y, 1e-6), "{light:?}");
                let up = Vec3::from(light.up.expect("the node's +Y"));
                assert!(up.abs_diff_eq(Vec3::NEG_Z, 1e-6), "the lamp's +Y turned with it: {up}");
                assert!((light.outer_angle_deg - 0.5f32.to_degrees()).abs() < 1e-4);
                assert_eq!(light.intensity, [1.0, 0.5, 0.5], "683 cd is 1 W/sr");
                let camera = &description.camera;
                assert_eq!(
                    (camera.position, camera.target, camera.width, camera.height),
                    ([0.0, 1.0, 5.0], [0.0, 1.0, 4.0], 32, 16)
                );
                assert!((camera.fov_y_deg - 0.7f32.to_degrees()).abs() < 1e-4);
                assert_eq!(description.meshes[0].gltf.as_deref(), Some(file));
                description.validate().expect("valid");
            }
            (other, expected) => panic!("{file}: expected {expected:?}, got {other:?}"),
        }
    }
    // A point light outside the meshes' bounds is the spot light aimed at their bounding
    // sphere with no falloff over it: every vertex inside its cone, the same intensity.
    let with_point_light = |d: &mut Value| {
        d["extensionsUsed"] = json!(["KHR_lights_punctual"]);
        d["extensions"] = lights("point");
        d["cameras"] = camera.clone();
    };
    write(&dir, "point.gltf", nodes.clone(), with_point_light);
    let light = scene("point.gltf").expect("a point light outside the meshes").light.expect("a light");
    assert_eq!(light.intensity, [1.0, 0.5, 0.5], "683 cd is 1 W/sr");
    assert_eq!(light.inner_angle_deg, light.outer_angle_deg, "no falloff inside the cone");
    // The triangle (0,0,0) (1,0,0) (0,1,0): bounding sphere centre (0.5, 0.5, 0), radius
    // 0.5·√2, seen from the lamp at (0, 3, 0).
    let (apex, axis) = (glam::DVec3::from(light.position).as_vec3(), Vec3::from(light.direction));
    assert!(apex.abs_diff_eq(Vec3::new(0.0, 3.0, 0.0), 1e-6));
    let centre = Vec3::new(0.5, 0.5, 0.0);
    assert!(axis.abs_diff_eq((centre - apex).normalize(), 1e-6), "aimed at the centre: {axis}");
    let sphere_deg = (0.5f32.sqrt() / (centre - apex).length()).asin().to_degrees();
    assert!((light.outer_angle_deg - sphere_deg * POINT_CONE_MARGIN).abs() < 1e-3, "{light:?}");
    for vertex in [Vec3::ZERO, Vec3::X, Vec3::Y] {
        let angle = (vertex - apex).angle_between(axis).to_degrees();
        assert!(angle < light.outer_angle_deg, "vertex {vertex} at {angle}° outside the cone");
    }
    let mut near = nodes.clone();
    near[1]["translation"] = json!([0.3, 0.3, 0.0]);
    write(&dir, "inside.gltf", near.clone(), with_point_light);
    let message = scene("inside.gltf").expect_err("inside the meshes").to_string();
    assert!(message.contains("a point light inside the meshes' bounding sphere"), "{message}");
    near[1]["translation"] = json!([0.5, 0.5, 0.71]);
    write(&dir, "near.gltf", near, with_point_light);
    let message = scene("near.gltf").expect_err("too near the meshes").to_string();
    assert!(message.contains("so near") && message.contains("make it a spot light"), "{message}");

    write(&dir, "blind.gltf", json!([{"mesh": 0}]), |_| {});
    let message = scene("blind.gltf").expect_err("no camera").to_string();
    assert!(message.contains("no camera node"), "{message}");

    // Errors found once the whole scene is a scene description name the fields as written.
    let text = r#"{"gltf": "good.gltf", "sparse_points": 4, "width": 32, "height": 16, "skip_groups": ["x"]}"#;
    let error = super::super::Scene::from_json_str(text, dir.path()).map(|_| ()).expect_err("no node x");
    assert_eq!(error.field_path(), Some("skip_groups[0]"), "{error}");
    assert!(error.to_string().starts_with("skip_groups[0]: "), "{error}");
    let text = r#"{"gltf": "good.gltf", "sparse_points": 4, "width": 0, "height": 16}"#;
    let error = super::super::Scene::from_json_str(text, dir.path()).map(|_| ()).expect_err("no pixels");
    assert_eq!(error.to_string(), "width: must be in 1..=8192, got 0");
}
