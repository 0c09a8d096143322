//! glTF 2.0 input: the Cornell box converted from its OBJ by `scripts/obj-to-gltf.py`
//! (`fixtures/meshes/cornell_box_gltf/`) loads and renders as the OBJ does, as a mesh entry
//! (`.gltf` + `.bin`) and as a whole scene (`.glb` with the spot light and the camera).

use relume::image::{LinearImage, relative_rmse};
use relume::renderer::{Method, Renderer};
use relume::scene::{Scene, SceneDescription};

use super::{fixture, gpu};

/// The Cornell box of `cornell_bunny_small.json` alone (no bunny), with its light, camera and
/// material override, and the settings of `cornell_gltf_small.json` (its tuning and the levels
/// measured on it); `mesh` is the box's file field.
fn cornell_json(mesh: &str) -> String {
    let text = std::fs::read_to_string(fixture("scenes/cornell_gltf_small.json")).expect("fixture");
    let fixture: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let settings = fixture["settings"].to_string();
    format!(
        r#"{{
        "meshes": [{{ {mesh}, "sparse_points": 512, "skip_groups": ["light"],
            "materials": {{ "shortBox": {{ "diffuse": [0.5, 0.5, 0.5], "specular": [0.4, 0.4, 0.4], "exponent": 30 }} }} }}],
        "light": {{ "position": [0.6, 1.6, 0.6], "direction": [-1.6, -0.3, -0.8],
                    "inner_angle_deg": 15, "outer_angle_deg": 25, "intensity": [10, 10, 10] }},
        "camera": {{ "position": [0, 1.0, 3.3], "target": [0, 0.9, 0], "fov_y_deg": 38, "width": 64, "height": 64 }},
        "settings": {settings}
    }}"#
    )
}

fn load(mesh: &str) -> Scene {
    Scene::from_json_str(&cornell_json(mesh), &fixture("meshes")).unwrap_or_else(|e| panic!("{mesh}: {e}"))
}

fn obj_scene() -> Scene {
    load(r#""obj": "cornell_box/CornellBox-Original.obj""#)
}

/// Direct + indirect, sparse method, at the scene camera's size.
fn render(scene: &Scene) -> LinearImage {
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, scene).expect("renderer");
    let frame = renderer.render(&gpu, Method::Sparse, scene.camera.width, scene.camera.height).expect("render");
    frame.direct.add(&frame.indirect)
}

/// The converter keeps tobj's model split, fan triangulation and vertex order, and maps the
/// materials back exactly, so the loader (one weld, the same normals, subdivision and sparse
/// points) gets identical geometry: compared exactly, materials to float rounding (1e-6: the
/// converter writes Kd / (1 - Ks) and 0.04-scaled specular colours in decimal).
#[test]
fn gltf_mesh_loads_the_same_triangles_as_its_obj() {
    let obj = obj_scene();
    let gltf = load(r#""gltf": "cornell_box_gltf/CornellBox-Original.gltf""#);
    let (a, b) = (&obj.meshes[0], &gltf.meshes[0]);
    assert_eq!(a.positions, b.positions);
    assert_eq!(a.triangles, b.triangles);
    assert_eq!(a.normals, b.normals);
    assert_eq!(a.triangle_materials, b.triangle_materials);
    assert_eq!(a.sparse.positions, b.sparse.positions);
    assert_eq!(obj.materials.len(), gltf.materials.len());
    for (m, n) in obj.materials.iter().zip(&gltf.materials) {
        assert!(m.diffuse.abs_diff_eq(n.diffuse, 1e-6), "{m:?} vs {n:?}");
        assert!(m.specular.abs_diff_eq(n.specular, 1e-6), "{m:?} vs {n:?}");
        // Ns 10 of the MTL comes back through roughness (a fourth root and its inverse).
        assert!((m.exponent - n.exponent).abs() <= 1e-3 * m.exponent.max(1.0), "{m:?} vs {n:?}");
    }
    assert!(gltf.materials.iter().any(|m| m.is_glossy()), "the shortBox override applies by glTF material name");
}

/// The same triangles under the same light give the same image; what may differ is the RSM's
/// atomic VAL order (the last bits of every gather sum, seen between two renders of one scene
/// too). Tolerance: relative RMSE 1e-4 of the full image, far below the sparse method's own
/// error against the brute force (0.136 on the Cornell bunny, README) and far above f32 sum
/// reordering (~1e-7).
#[test]
fn gltf_and_obj_cornell_boxes_render_the_same_image() {
    let obj = render(&obj_scene());
    let gltf = render(&load(r#""gltf": "cornell_box_gltf/CornellBox-Original.gltf""#));
    assert!(obj.coverage() > 3000, "the box fills the view");
    let error = relative_rmse(&gltf, &obj);
    eprintln!("glTF vs OBJ Cornell box, 64x64 sparse: relative RMSE {error:.3e}");
    assert!(error < 1e-4, "glTF vs OBJ relative RMSE {error}");
}

/// The whole scene from one .glb: the light and camera come back from their nodes (position,
/// a quaternion, candela / 683) to f32 rounding of the quaternion (1e-5 relative); the image
/// then agrees within relative RMSE 1e-3: a light direction off by ~1e-6 rad moves RSM texel
/// footprints by ~1e-6 of a texel, and the VALs' flux by as little; 1e-3 leaves room for a
/// texel at the edge of a triangle flipping, and is still 100x below the method's own error.
#[test]
fn whole_scene_glb_matches_the_json_scene() {
    let scene = Scene::load(&fixture("scenes/cornell_gltf_small.json")).expect("loads the .glb scene");
    let json: SceneDescription = SceneDescription::from_json_str(&cornell_json(r#""obj": "x.obj""#)).expect("parses");
    let (light, expected) =
        (scene.light.expect("the .glb's spot light"), json.light.expect("light").to_spot_light(scene.origin));
    assert!(light.position.abs_diff_eq(expected.position, 1e-5), "{light:?} vs {expected:?}");
    assert!(light.direction.abs_diff_eq(expected.direction, 1e-5), "{light:?} vs {expected:?}");
    assert!(
        (light.inner_angle - expected.inner_angle).abs() < 1e-6
            && (light.outer_angle - expected.outer_angle).abs() < 1e-6
    );
    assert!(light.intensity.abs_diff_eq(expected.intensity, 1e-5 * 10.0), "{light:?} vs {expected:?}");
    let (camera, expected) = (scene.camera, json.camera.to_camera(scene.origin));
    assert!(camera.position.abs_diff_eq(expected.position, 1e-5), "{camera:?} vs {expected:?}");
    let (view, expected_view) =
        ((camera.target - camera.position).normalize(), (expected.target - expected.position).normalize());
    assert!(view.abs_diff_eq(expected_view, 1e-5), "{camera:?} vs {expected:?}");
    assert!((camera.fov_y - expected.fov_y).abs() < 1e-6 && camera.width == 64 && camera.height == 64);

    let error = relative_rmse(&render(&scene), &render(&obj_scene()));
    eprintln!(".glb whole scene vs JSON + OBJ scene, 64x64 sparse: relative RMSE {error:.3e}");
    assert!(error < 1e-3, ".glb scene vs JSON + OBJ scene: relative RMSE {error}");
}
